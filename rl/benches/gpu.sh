#!/usr/bin/env bash
# The GPU machine's one script (issue 42; docs/PERFORMANCE.md, "On a GPU"): correctness
# first, then every figure, each line naming the machine and the device. Run it from the
# repository root with gpu-carry/ and .gl/ carried (rl/benches/gpu_build.sh makes them):
#
#   rl/benches/gpu.sh                 # the full set (about 8 minutes on an H100 machine)
#   QUICK=1 rl/benches/gpu.sh         # tiny sizes: a smoke test, e.g. on lavapipe
#
# Figures: the WGSL matmul rate on the shapes of `shnn` training; env steps/s of `shnn` and
# `mlp_hn` training on team_reach/1_ant, 2_ants and 3_ant_claw_centipede (paper preset) on
# the GPU and on the CPU alone at every core; where an iteration goes (collection against
# update, from the runs' metrics); the simulator's scaling from 1 to all threads.
set -uo pipefail
cd "$(dirname "$0")/../.."
C=gpu-carry
OUT=${OUT:-/tmp/gpu-bench}
mkdir -p "$OUT"
# The Vulkan loader, if the machine lacks it.
if ! ldconfig -p | grep -q libvulkan.so.1 && ls .gl/*.deb >/dev/null 2>&1; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
if [ -e /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
    export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
fi
CORES=$(nproc)
MACHINE="$(lscpu | sed -n 's/^Model name: *//p' | head -1), $CORES cores"
GPU=$(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null | head -1)
echo "machine: $MACHINE; GPU: ${GPU:-none reported}; commit $(cat $C/COMMIT) built for $(cat $C/LEVEL)"
grep -o -w 'avx512f' /proc/cpuinfo | head -1 | sed 's/^/cpu flag: /'

echo "== correctness: every op and every model on the GPU against the CPU"
$C/gpu_ops --test-threads 1 2>&1 | tail -3
$C/gpu_models 2>&1 | tail -3

echo "== matmul rate (f32, GPU)"
# QUICK: the first shapes only (lavapipe takes minutes for the large square product).
MM_LIMIT=300
[ -n "${QUICK:-}" ] && MM_LIMIT=60
timeout "$MM_LIMIT" $C/matmul_rate --device gpu 2>&1 | grep -E 'matmul|rate|GPU'

if [ -n "${QUICK:-}" ]; then STEPS=1024; NENVS=16; SET="--set batch_size=8 --set num_minibatches=2"; else STEPS=0; NENVS=0; SET=""; fi
train() { # <device> <threads> <env> <model>: env steps/s of a short paper-preset training
  local dir="$OUT/$1-$2-${3//\//_}-$4" steps=${STEPS} extra=()
  rm -rf "$dir"
  # Paper preset: 163,840 env steps an iteration; 3 iterations, the first a warm-up.
  [ "$steps" = 0 ] && steps=491520
  [ "$NENVS" != 0 ] && extra=(--num-envs "$NENVS")
  # shellcheck disable=SC2086
  timeout 300 $C/meben train --preset paper --device "$1" --threads "$2" --env "$3" --model "$4" \
      --steps "$steps" "${extra[@]}" --set num_evals=0 --set eval_episodes=1 $SET --quiet --out "$dir" > "$dir.log" 2>&1
  local rc=$?
  # iteration rows: env_steps (col 2) and wall_s (col 3); the rate after the first iteration.
  awk -F, -v dev="$1" -v th="$2" -v env="$3" -v model="$4" -v rc=$rc -v m="$MACHINE" -v g="${GPU:-}" '
    NR > 1 && $1 != "" { s[NR] = $2; w[NR] = $3; n = NR }
    END {
      if (n < 3) { printf "train %s %s device=%s threads=%s: no rate (exit %s)\n", env, model, dev, th, rc; exit }
      printf "train %s %s device=%s threads=%s env_steps_per_s=%.0f (iterations 2..%d; %s; %s)\n",
        env, model, dev, th, (s[n] - s[2]) / (w[n] - w[2]), n - 1, m, (dev == "gpu" ? g : "CPU only")
    }' "$dir/metrics.csv" 2>/dev/null || echo "train $3 $4 device=$1: failed (exit $rc), see $dir.log"
}
echo "== training throughput (paper preset; GPU update with the simulator on $CORES threads, and CPU only)"
for env in team_reach/1_ant team_reach/2_ants team_reach/3_ant_claw_centipede; do
    for model in mlp_hn shnn; do
        train gpu 0 "$env" "$model"
        train cpu 0 "$env" "$model"
    done
done

echo "== the simulator's scaling (random actions, 256 environments)"
for t in 1 2 4 8 16; do
    [ "$t" -le "$CORES" ] || continue
    if [ -n "${QUICK:-}" ]; then sizes=(STEPS=100 NENV=32); else sizes=(); fi
    env RAYON_NUM_THREADS="$t" "${sizes[@]}" $C/tasks 2>&1 | grep env_steps_per_s | sed "s/\$/ ($MACHINE)/"
done
