#!/usr/bin/env bash
# Prepares what rl/benches/gpu.sh runs on a GPU machine that has no Rust toolchain and no
# package registry (docs/PERFORMANCE.md, "On a GPU"): portable release binaries built with
# the `gpu` feature, stripped and gzipped, in gpu-carry/ (ignored by git), and the Vulkan loader's
# Debian packages in .gl/ (the machine has NVIDIA's driver but may lack libvulkan).
#
#   rl/benches/gpu_build.sh            # x86-64-v3 (AVX2); V=v4 for AVX-512
#   BEFORE=a51293d rl/benches/gpu_build.sh   # also `meben` as of that commit (gpu.sh's `before`)
#
# It also copies the JAX peer of ../shared/bench (peers/jax_step.py) for gpu.sh's `peers`.
#
# The workspace builds with -C target-cpu=native, which may not run on another CPU: these
# binaries target a named x86-64 level instead, in their own target directory.
set -euo pipefail
cd "$(dirname "$0")/../.."
LEVEL=x86-64-${V:-v3}
TARGET=target-portable-$LEVEL
export CARGO_TARGET_DIR=$PWD/$TARGET RUSTFLAGS="-C target-cpu=$LEVEL"
mkdir -p gpu-carry
rm -f gpu-carry/meben_before.gz gpu-carry/BEFORE
# The baseline first, from a worktree of that commit sharing the target directory (its
# dependencies are built once): the build of this checkout below then leaves its own `meben`.
if [ -n "${BEFORE:-}" ]; then
    wt=$(mktemp -d /tmp/gpu-before.XXXXXX)
    git worktree add --detach "$wt" "$BEFORE" >/dev/null
    (cd "$wt" && cargo build --release -p rl --features gpu --bin meben)
    cp "$TARGET/release/meben" gpu-carry/meben_before
    git -C "$wt" rev-parse --short HEAD > gpu-carry/BEFORE
    git worktree remove --force "$wt"
fi
cargo build --release -p rl --features gpu --bin meben
cp "$TARGET/release/meben" gpu-carry/meben
if [ -e gpu-carry/meben_before ] && cmp -s gpu-carry/meben gpu-carry/meben_before; then
    echo "gpu_build.sh: meben of $(git rev-parse --short HEAD) is byte-identical to that of $BEFORE" >&2
    exit 1
fi
cargo bench --no-run -p tensor --features gpu --bench matmul_rate
cargo bench --no-run -p tensor --features gpu --bench launch_overhead
cargo bench --no-run -p tensor --features gpu --bench reductions
cargo bench --no-run -p envs --bench tasks
cargo bench --no-run -p rl --features gpu --bench train_throughput
cargo bench --no-run -p nn --features gpu --bench train_step
newest() { ls -t "$TARGET"/release/deps/"$1"-* | grep -v '\.d$' | head -1; }
# Each crate's integration tests are one binary, `integration` (gpu.sh runs its gpu_*
# modules); the two crates' share the name, so each is found by what cargo reports.
test_exe() {
    cargo test --no-run --release "$@" --message-format=json \
        | grep -o '"executable":"[^"]*"' | tail -1 | cut -d'"' -f4
}
cp "$(test_exe -p tensor --features gpu --test integration)" gpu-carry/gpu_ops
cargo test --no-run --release -p tensor --features gpu --lib
cp "$(test_exe -p models --features gpu --test integration)" gpu-carry/gpu_models
cp "$(newest matmul_rate)" gpu-carry/matmul_rate
cp "$(newest launch_overhead)" gpu-carry/launch_overhead
cp "$(newest reductions)" gpu-carry/reductions
cp "$(newest tasks)" gpu-carry/tasks
cp "$(newest train_throughput)" gpu-carry/train_throughput
cp "$(newest train_step)" gpu-carry/train_step
rm -rf gpu-carry/peers
if [ -e ../shared/bench/peers/jax_step.py ]; then
    mkdir -p gpu-carry/peers && cp ../shared/bench/peers/jax_step.py gpu-carry/peers/
else
    echo "gpu_build.sh: no ../shared/bench/peers/jax_step.py; gpu.sh's peers section will say so" >&2
fi
# The library's unit tests (gpu.sh runs those of the device's kernels: `gpu::`).
cp "$(newest tensor)" gpu-carry/gpu_unit
BINS="meben matmul_rate launch_overhead reductions tasks train_throughput train_step gpu_ops gpu_unit gpu_models"
[ -e gpu-carry/meben_before ] && BINS="$BINS meben_before"
# Stripped and compressed (about 3x), so they and the tree stay well inside the 64 MiB a
# call carries; gpu.sh unpacks them.
for b in $BINS; do strip "gpu-carry/$b"; gzip -9 -f "gpu-carry/$b"; done
{ git rev-parse --short HEAD; git diff --quiet HEAD || echo "+ uncommitted changes"; } | paste -sd' ' > gpu-carry/COMMIT
echo "$LEVEL" > gpu-carry/LEVEL
# The Vulkan loader and GLVND as .debs, unpacked there by gpu.sh (NVIDIA's Vulkan driver
# is libGLX_nvidia, which needs libGLdispatch from libglvnd0: without it no adapter is found).
if ! ls .gl/libglvnd0_*.deb >/dev/null 2>&1; then
    grep -qx '/.gl/' .git/info/exclude 2>/dev/null || echo /.gl/ >> .git/info/exclude
    mkdir -p .gl /tmp/amd64/partial
    o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
    # shellcheck disable=SC2086
    apt-get $o update >/dev/null
    # shellcheck disable=SC2086
    (cd .gl && apt-get $o download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
fi
du -ch gpu-carry .gl | tail -1
