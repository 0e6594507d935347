#!/usr/bin/env bash
# The test command of the README (CI runs it through .ci/run): the Rust tests, the sweep's
# Slurm array script on a one-node Slurm cluster, then the Python package built and
# installed into a virtual environment under target/ and its pytest tests. Needs a Rust
# toolchain and Python >= 3.9 (`python3`, or set PYTHON).
set -euo pipefail
cd "$(dirname "$0")"
venv=target/pyenv
# Cargo's target directory, where the programs the Slurm and Python tests run are built
# (CARGO_TARGET_DIR when set; relative to this directory, as cargo reads it here).
cargo_target=${CARGO_TARGET_DIR:-target}
case "$cargo_target" in /*) ;; *) cargo_target=$PWD/$cargo_target ;; esac
if [ ! -x "$venv/bin/python" ]; then
    "${PYTHON:-python3}" -m venv "$venv"
fi
export PATH="$PWD/$venv/bin:$PATH"
# The build backend and the test dependencies (gymnasium and pettingzoo: the adapters' API
# checks; mypy: the type stubs' and annotations' checks; safetensors: reading policy files
# and checkpoint tensors as other tools do).
python -m pip install --quiet --disable-pip-version-check "maturin>=1.9.4,<2" "numpy>=1.21" "pytest>=7" \
    "gymnasium>=1.0" "pettingzoo>=1.24" "mypy>=1.10,<3" "safetensors>=0.4"
# The HTML player's test runs its page in headless Chromium; here a missing browser is a
# failure, not a skip (MEBEN_REQUIRE_BROWSER), so install Debian's package when it is absent.
if ! command -v chromium >/dev/null 2>&1 && ! command -v chromium-browser >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        export DEBIAN_FRONTEND=noninteractive
        apt-get install -y chromium || { apt-get update && apt-get install -y chromium; }
    else
        echo "test.sh: Chromium is missing; install it (Debian: sudo apt-get install chromium) and run again" >&2
        exit 1
    fi
fi
export MEBEN_REQUIRE_BROWSER=1
# The GPU device's tests run on whatever Vulkan adapter the machine has; CI has no GPU, so
# they run on Mesa's lavapipe (a Vulkan device on the CPU: Debian's mesa-vulkan-drivers).
# Installed here when absent; a missing Vulkan driver fails the GPU tests, never skips them.
if ! ls /usr/share/vulkan/icd.d/*.json >/dev/null 2>&1 || ! ldconfig -p 2>/dev/null | grep -q libvulkan.so.1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        export DEBIAN_FRONTEND=noninteractive
        apt-get install -y mesa-vulkan-drivers libvulkan1 || { apt-get update && apt-get install -y mesa-vulkan-drivers libvulkan1; }
    else
        echo "test.sh: no Vulkan driver; install one (Debian: sudo apt-get install mesa-vulkan-drivers libvulkan1) and run again" >&2
        exit 1
    fi
fi
# Mesa warns when this is unset (harmless); give it a private directory.
if [ -z "${XDG_RUNTIME_DIR:-}" ]; then
    XDG_RUNTIME_DIR="$(mktemp -d)"
    export XDG_RUNTIME_DIR
fi
# The Python tests' optional dependencies (gymnasium, pettingzoo, mypy), installed above, are
# required too: a missing one fails its tests instead of skipping them.
export MEBEN_REQUIRE_TEST_DEPS=1
cargo test --workspace --release
# The GPU device (feature `gpu`): every op, every model and short trainings on the GPU
# against the CPU (docs/TENSOR.md). The tests fail when no adapter is found.
# (Each crate's integration tests are one binary, `integration`; its GPU modules are named gpu_*.)
cargo test --release -p tensor --features gpu
cargo test --release -p models --features gpu --test integration gpu_models::
cargo test --release -p nn --features gpu --test integration -- gpu_optim:: gpu_determinism::
cargo test --release -p rl --features gpu --test integration gpu_training::
# The Rust programs the Python tests compare with (already built by cargo test; cheap).
cargo build --release -p rl --bin meben -p envs --example replay_actions
# The sweep's Slurm array script (rl/sweeps/slurm_array.sh) against a real one-node Slurm on
# localhost: Debian's slurm-wlm and munge, installed when absent (as root), then required.
# Three array tasks, one requeued mid-run and resumed; every run finished and reported; every
# daemon it started stopped again (about 20 s; the README's paragraph on sweeps).
MEBEN="$cargo_target/release/meben" rl/sweeps/slurm_ci.sh
python -m pip install --quiet --disable-pip-version-check --no-build-isolation --no-deps --force-reinstall ./python
# No cache provider: pytest would write .pytest_cache into the source tree.
python -m pytest -q -p no:cacheprovider python/tests
