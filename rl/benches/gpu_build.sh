#!/usr/bin/env bash
# Prepares what rl/benches/gpu.sh runs on a GPU machine that has no Rust toolchain and no
# package registry (docs/PERFORMANCE.md, "On a GPU"): portable release binaries built with
# the `gpu` feature, stripped, in gpu-carry/ (ignored by git), and the Vulkan loader's
# Debian packages in .gl/ (the machine has NVIDIA's driver but may lack libvulkan).
#
#   rl/benches/gpu_build.sh            # x86-64-v3 (AVX2); V=v4 for AVX-512
#
# The workspace builds with -C target-cpu=native, which may not run on another CPU: these
# binaries target a named x86-64 level instead, in their own target directory.
set -euo pipefail
cd "$(dirname "$0")/../.."
LEVEL=x86-64-${V:-v3}
TARGET=target-portable-$LEVEL
export CARGO_TARGET_DIR=$TARGET RUSTFLAGS="-C target-cpu=$LEVEL"
cargo build --release -p rl --features gpu --bin meben
cargo bench --no-run -p tensor --features gpu --bench matmul_rate
cargo bench --no-run -p envs --bench tasks
cargo test --no-run --release -p tensor --features gpu --test gpu_ops
cargo test --no-run --release -p models --features gpu --test gpu_models
mkdir -p gpu-carry
cp "$TARGET/release/meben" gpu-carry/meben
newest() { ls -t "$TARGET"/release/deps/"$1"-* | grep -v '\.d$' | head -1; }
cp "$(newest matmul_rate)" gpu-carry/matmul_rate
cp "$(newest tasks)" gpu-carry/tasks
cp "$(newest gpu_ops)" gpu-carry/gpu_ops
cp "$(newest gpu_models)" gpu-carry/gpu_models
strip gpu-carry/*
git rev-parse --short HEAD > gpu-carry/COMMIT
echo "$LEVEL" > gpu-carry/LEVEL
# The Vulkan loader (and nothing else) as .debs, unpacked there by gpu.sh.
if ! ls .gl/libvulkan1_*.deb >/dev/null 2>&1; then
    grep -qx '/.gl/' .git/info/exclude 2>/dev/null || echo /.gl/ >> .git/info/exclude
    mkdir -p .gl /tmp/amd64/partial
    o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
    # shellcheck disable=SC2086
    apt-get $o update >/dev/null
    # shellcheck disable=SC2086
    (cd .gl && apt-get $o download libvulkan1)
fi
du -ch gpu-carry .gl | tail -1
