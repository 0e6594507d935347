#!/usr/bin/env bash
# The test command of the README (CI runs it through .ci/run): the Rust tests, then the
# Python package built and installed into a virtual environment under target/ and its
# pytest tests. Needs a Rust toolchain and Python >= 3.9 (`python3`, or set PYTHON).
set -euo pipefail
cd "$(dirname "$0")"
venv=target/pyenv
if [ ! -x "$venv/bin/python" ]; then
    "${PYTHON:-python3}" -m venv "$venv"
fi
export PATH="$PWD/$venv/bin:$PATH"
# The build backend and the test dependencies (gymnasium and pettingzoo: the adapters' API checks).
python -m pip install --quiet --disable-pip-version-check "maturin>=1.9.4,<2" "numpy>=1.21" "pytest>=7" \
    "gymnasium>=1.0" "pettingzoo>=1.24"
cargo test --workspace --release
# The Rust programs the Python tests compare with (already built by cargo test; cheap).
cargo build --release -p rl --bin meben -p envs --example replay_actions
python -m pip install --quiet --disable-pip-version-check --no-build-isolation --no-deps --force-reinstall ./python
# No cache provider: pytest would write .pytest_cache into the source tree.
python -m pytest -q -p no:cacheprovider python/tests
