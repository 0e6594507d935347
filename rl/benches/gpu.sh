#!/usr/bin/env bash
# The GPU machine's one script (issue 42; docs/PERFORMANCE.md, "On a GPU"): correctness
# first, then the figures, each line naming the machine and the device. Run it from the
# repository root with gpu-carry/ and .gl/ carried (rl/benches/gpu_build.sh makes them):
#
#   rl/benches/gpu.sh                          # every section, in the order below
#   SECTIONS="correct matmul gpu" rl/benches/gpu.sh
#   QUICK=1 rl/benches/gpu.sh                  # tiny sizes: a smoke test, e.g. on lavapipe
#
# Sections (SECTIONS, space separated; default all):
#   correct   every op and every model on the GPU against the CPU
#   matmul    the WGSL matmul rate on the shapes of `shnn` training
#   gpu       env steps/s of training on the GPU (paper preset), shnn and mlp_hn on
#             3_ant_claw_centipede, 2_ants, 1_ant, with each iteration's stage timings (the
#             act step on the GPU, the default act_device)
#   act_cpu   `gpu`'s shnn pair with the act step on the CPU threads (act_device = cpu),
#             for the act step's ratio on one machine
#   before    `gpu`'s shnn pair with the baseline binary (gpu_build.sh's BEFORE), in the same
#             call, for a ratio on one machine
#   peers     the training-step workloads of ../shared/bench (mlp_step, shnn_step) on the GPU
#             against the JAX peer on the same GPU (the machine's own JAX), in alternating
#             rounds, then both on the CPU alone
#   reduce    reductions at paper sizes (bias gradients, means) with the kernel's lanes
#             and with one thread per output (TENSOR_GPU_REDUCE_LANES=1), alternated; then
#             the paper-size `shnn` minibatch pass with each, for the ratio in one call
#   tile      the tiled product's 128 x 64 tile against the 64 x 64 one
#             (TENSOR_GPU_MATMUL_TILE; the same bits): the matmul rate with each, alternated
#             twice, then the paper-size `shnn` minibatch pass and a two-iteration training
#             run with each
#   profile   one `shnn` minibatch's forward and backward on the GPU, op by op
#   timeline  the host's cost of one launch (launch_overhead); the same minibatch pass,
#             `shnn_step`, and a training iteration's update, on the
#             GPU's own clock without waiting between ops (GPU_TIMING, MEBEN_TIMINGS=gpu):
#             kernels' busy time against the span, by kernel and op
#   sim       the simulator's scaling from 1 thread to every core
#   cpu       env steps/s of training on the CPU alone at every core (one iteration each)
# DEADLINE (seconds, default 540) skips what would start after it, so the machine's time
# is never overrun; everything printed is also written to $OUT/gpu-bench.log when OUT is set.
set -uo pipefail
cd "$(dirname "$0")/../.."
# The carried binaries (gzipped by gpu_build.sh), unpacked outside the tree.
C=/tmp/gpu-carry-bin
mkdir -p $C
cp gpu-carry/COMMIT gpu-carry/LEVEL $C/
[ -e gpu-carry/BEFORE ] && cp gpu-carry/BEFORE $C/
for f in gpu-carry/*.gz; do gzip -dc "$f" > "$C/$(basename "$f" .gz)" && chmod +x "$C/$(basename "$f" .gz)"; done
RUNS=${RUNS:-/tmp/gpu-bench}
SECTIONS=${SECTIONS:-correct matmul gpu act_cpu before peers reduce tile profile timeline gpu_more sim cpu}
DEADLINE=${DEADLINE:-540}
mkdir -p "$RUNS"
if [ -n "${OUT:-}" ]; then exec > >(tee "$OUT/gpu-bench.log") 2>&1; fi
# The Vulkan loader and GLVND (NVIDIA's Vulkan driver, libGLX_nvidia, needs libGLdispatch),
# and NVIDIA's Vulkan driver manifest.
if ls .gl/*.deb >/dev/null 2>&1; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
if [ -z "${VK_DRIVER_FILES:-}" ]; then
    for f in /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json /usr/share/vulkan/icd.d/nvidia_icd.json \
        /etc/vulkan/icd.d/nvidia_icd.json; do
        if [ -e "$f" ]; then export VK_DRIVER_FILES=$f; break; fi
    done
fi
CORES=$(nproc)
MACHINE="$(lscpu | sed -n 's/^Model name: *//p' | head -1), $CORES cores"
GPU=$(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null | head -1)
echo "machine: $MACHINE; GPU: ${GPU:-none reported}; commit $(cat $C/COMMIT) built for $(cat $C/LEVEL);" \
    "Vulkan driver: ${VK_DRIVER_FILES:-default}"
grep -o -w 'avx512f' /proc/cpuinfo | head -1 | sed 's/^/cpu flag: /'
# Stop at once, with the loader's account, if no GPU adapter answers.
if [ -z "${QUICK:-}" ] && ! timeout 60 $C/meben train --device gpu --env team_reach/1_ant --steps 80 --num-envs 16 \
    --set batch_size=8 --set num_minibatches=2 --set num_evals=0 --quiet --out "$RUNS/adapter" > "$RUNS/adapter.log" 2>&1
then
    cat "$RUNS/adapter.log"
    VK_LOADER_DEBUG=error,warn,driver timeout 60 $C/meben train --device gpu --env team_reach/1_ant --steps 80 \
        --num-envs 16 --quiet --out "$RUNS/adapter2" 2>&1 | grep -v '^$' | head -40
    exit 1
fi
grep -o 'training on GPU: .*' "$RUNS/adapter.log" 2>/dev/null
want() { [ "$SECONDS" -lt "$DEADLINE" ]; }
# The seconds a step may take: its own limit, or what is left before the deadline.
limit() { local left=$((DEADLINE - SECONDS)); [ "$left" -lt "$1" ] && echo $((left > 10 ? left : 10)) || echo "$1"; }

correct() {
    echo "== correctness: every op and every model on the GPU against the CPU"
    timeout 120 $C/gpu_ops gpu_ops:: --test-threads 1 2>&1 | grep -E '^test result|FAILED|panicked|adapter' | head -20
    timeout 120 $C/gpu_unit gpu:: 2>&1 | grep -E '^test result|FAILED|panicked|adapter' | head -20
    timeout 120 $C/gpu_models gpu_models:: 2>&1 | grep -E '^test result|FAILED|panicked|adapter' | head -20
}

matmul() {
    echo "== matmul rate (f32, GPU)"
    # QUICK: the first shapes only (lavapipe takes minutes for the large square product).
    MM_LIMIT=120
    [ -n "${QUICK:-}" ] && MM_LIMIT=60
    timeout -s KILL "$(limit $MM_LIMIT)" $C/matmul_rate --device gpu 2>&1 | grep -E 'matmul|rate|GPU'
}

if [ -n "${QUICK:-}" ]; then
    SIZE=(--num-envs 16 --set batch_size=8 --set num_minibatches=2); ITER=320
else
    SIZE=(); ITER=163840
fi
# train <device> <env> <model> <iterations> <limit_s>: env steps/s of a short paper-preset
# training: the last iteration's rate (the first is a warm-up when there are two), and every
# iteration's stage timings (MEBEN_TIMINGS). MEBEN names another binary (its line says which);
# ACT_DEVICE sets act_device (unset: the configuration's default, `same`; binaries before
# 2026-12-01 have no such field).
train() {
    local bin=${MEBEN:-$C/meben} act=${ACT_DEVICE:-same}
    local dir="$RUNS/$1-${2//\//_}-$3-$(basename "$bin")-act_$act"
    local act_set=()
    [ -n "${ACT_DEVICE:-}" ] && act_set=(--set "act_device=$ACT_DEVICE")
    # TRAIN_SET: one more `--set key=value` (the GPU's kernel choices, e.g. gpu_matmul_tile=128).
    [ -n "${TRAIN_SET:-}" ] && act_set+=(--set "$TRAIN_SET")
    rm -rf "$dir"
    # SIGKILL: meben takes SIGTERM as "stop after this iteration", which can take minutes.
    MEBEN_TIMINGS=1 timeout -s KILL "$(limit "$5")" "$bin" train --preset paper --device "$1" --env "$2" --model "$3" \
        --steps $(($4 * ITER)) "${SIZE[@]}" --set num_evals=0 --set eval_episodes=1 "${act_set[@]}" --quiet --out "$dir" \
        > "$dir.log" 2>&1
    local rc=$?
    local where="CPU only, $CORES threads"
    [ "$1" = gpu ] && where="$(grep -o 'training on GPU: .*' "$dir.log" | head -1 | cut -c18-) + $CORES CPU threads"
    [ "$1" = gpu ] && [ -z "${MEBEN:-}" ] && where="$where, act_device $act"
    [ -n "${MEBEN:-}" ] && where="$where; binary $(basename "$bin")"
    awk -F, -v dev="$1" -v env="$2" -v model="$3" -v rc=$rc -v m="$MACHINE" -v where="$where" '
      NR > 1 && $1 != "" { s[NR] = $2; w[NR] = $3; n = NR }
      END {
        if (n < 2) { printf "train %s %s device=%s: no iteration finished (exit %s)\n", env, model, dev, rc; exit }
        p = (n > 2) ? n - 1 : 1; s[1] = 0; w[1] = 0
        printf "train %s %s device=%s env_steps_per_s=%.0f (iteration %d of %d; %s; %s)\n",
          env, model, dev, (s[n] - s[p]) / (w[n] - w[p]), n - 1, n - 1, m, where
      }' "$dir/metrics.csv" 2>/dev/null || echo "train $2 $3 device=$1: failed (exit $rc), see $dir.log"
    grep -E 'took|error|rror:' "$dir.log" | grep -v XDG_RUNTIME_DIR | sed 's/^/    /' | head -6
}

# pairs <device> <iterations> <limit_s> <env:model>...: train each while time is left.
pairs() {
    local dev=$1 its=$2 lim=$3
    shift 3
    for pair in "$@"; do
        want || break
        train "$dev" "${pair%%:*}" "${pair##*:}" "$its" "$lim"
    done
}
gpu() {
    echo "== training on the GPU, 3_ant_claw_centipede (paper preset; act step on the GPU, simulator on $CORES CPU threads)"
    pairs gpu 2 120 team_reach/3_ant_claw_centipede:shnn team_reach/3_ant_claw_centipede:mlp_hn
}
act_cpu() {
    echo "== the same shnn training with the act step on the CPU (act_device = cpu; simulator and act step on $CORES CPU threads)"
    ACT_DEVICE=cpu pairs gpu 2 120 team_reach/3_ant_claw_centipede:shnn
}
gpu_more() {
    echo "== training on the GPU, 2_ants and 1_ant (paper preset; act step on the GPU, simulator on $CORES CPU threads)"
    pairs gpu 2 60 team_reach/2_ants:shnn team_reach/1_ant:shnn team_reach/2_ants:mlp_hn team_reach/1_ant:mlp_hn
}

before() {
    if [ ! -x $C/meben_before ]; then
        echo "== before: skipped (no gpu-carry/meben_before.gz: gpu_build.sh with BEFORE=<commit>)"
        return
    fi
    echo "== training on the GPU with the baseline binary, commit $(cat $C/BEFORE) (the same pair as \`gpu\`'s first)"
    MEBEN=$C/meben_before pairs gpu 2 120 team_reach/3_ant_claw_centipede:shnn
}

peers() {
    echo "== training step (../shared/bench/README.md) against the JAX peer, f32, medians of each program's steps"
    local jax=gpu-carry/peers/jax_step.py
    if [ ! -e $jax ]; then
        echo "peers: skipped (no $jax: gpu_build.sh copies it from ../shared/bench/peers)"
        return
    fi
    python3 -c 'import jax; print("JAX", jax.__version__, "devices:", jax.devices())' 2>&1 | tail -1
    for round in 1 2; do
        want || break
        DEVICE=gpu timeout -s KILL "$(limit 60)" $C/train_step 2>&1 | grep -E "step|panicked|rror" | sed "s/\$/ (this library, round $round)/"
        want || break
        timeout -s KILL "$(limit 90)" python3 $jax 2>&1 | grep -E "step|panicked|rror" | sed "s/\$/ (JAX default device, round $round)/"
    done
    want || return
    timeout -s KILL "$(limit 60)" $C/train_step 2>&1 | grep -E "step|panicked|rror" | sed "s/\$/ (this library, $CORES CPU threads)/"
    want || return
    JAX_PLATFORMS=cpu timeout -s KILL "$(limit 90)" python3 $jax 2>&1 | grep -E "step|panicked|rror" | sed "s/\$/ (JAX on the CPU, $CORES cores)/"
}

reduce() {
    echo "== reductions on the GPU: up to 256 threads per output (lanes) against one (TENSOR_GPU_REDUCE_LANES=1)"
    if [ ! -x $C/reductions ]; then
        echo "reduce: skipped (no gpu-carry/reductions.gz: a gpu_build.sh of before 2026-12-01)"
        return
    fi
    local rows=153600 env=team_reach/3_ant_claw_centipede preset=paper
    [ -n "${QUICK:-}" ] && rows=10240 env=team_reach/1_ant preset=quick
    for round in 1 2; do
        for lanes in 256 1; do
            want || return
            N=$rows DEVICE=gpu TENSOR_GPU_REDUCE_LANES=$lanes timeout -s KILL "$(limit 60)" $C/reductions 2>&1 \
                | grep -E "reduce|panicked|rror" | grep -v XDG | sed "s/\$/ (lanes $lanes, round $round)/"
        done
    done
    passes_with TENSOR_GPU_REDUCE_LANES $env $preset 256 1
}

# passes_with <variable> <env> <preset> <value>...: the median of five `shnn` minibatch passes
# (forward and backward) with the variable set to each value in turn.
passes_with() {
    local var=$1 task=$2 preset=$3
    shift 3
    echo "-- one shnn minibatch pass ($task, $preset preset), forward and backward, with each $var"
    for v in "$@"; do
        want || return
        env "$var=$v" DEVICE=gpu PRESET="$preset" ITERATIONS=0 MINIBATCH_REPS=5 BENCH_ENVS="$task" BENCH_MODELS=shnn \
            timeout -s KILL "$(limit 90)" $C/train_throughput 2>&1 | grep -o "minibatch_ms=[0-9.]*" \
            | sed "s/\$/ ($var=$v)/"
    done
}

tile() {
    echo "== the tiled product: 128 x 64 tiles against 64 x 64 (TENSOR_GPU_MATMUL_TILE), alternated"
    local mm_limit=90 env=team_reach/3_ant_claw_centipede preset=paper
    [ -n "${QUICK:-}" ] && mm_limit=30 env=team_reach/1_ant preset=quick
    for round in 1 2; do
        for t in 128 64; do
            want || return
            TENSOR_GPU_MATMUL_TILE=$t timeout -s KILL "$(limit $mm_limit)" $C/matmul_rate --device gpu 2>&1 \
                | grep -E "matmul|rate|panicked|rror" | grep -v XDG | sed "s/\$/ (tile $t, round $round)/"
        done
    done
    passes_with TENSOR_GPU_MATMUL_TILE $env $preset 128 64
    echo "-- shnn training on $env with each tile (the second iteration's rate)"
    for t in 128 64; do
        want || return
        TRAIN_SET=gpu_matmul_tile=$t train gpu $env shnn 2 120 | sed "s/\$/ (tile $t)/"
    done
}

profile() {
    echo "== one shnn minibatch on the GPU, op by op (each op waited for; team_reach/3_ant_claw_centipede)"
    # ITERATIONS=0: one iteration's collection, then the minibatch passes only.
    local env=team_reach/3_ant_claw_centipede preset=paper
    [ -n "${QUICK:-}" ] && env=team_reach/1_ant preset=quick
    DEVICE=gpu PRESET=$preset ITERATIONS=0 MINIBATCH_REPS=3 TENSOR_PROFILE=1 BENCH_ENVS=$env \
        BENCH_MODELS=shnn timeout -s KILL "$(limit 90)" $C/train_throughput 2>&1 | grep -v '^\s*$' | head -70
}

timeline() {
    echo "== the host's cost of a launch (a chain of tiny ops; wall and the calling thread's CPU time)"
    DEVICE=gpu timeout -s KILL "$(limit 30)" $C/launch_overhead 2>&1 | grep -E "launch_overhead|panicked|rror" \
        | grep -v XDG | sed "s/\$/ ($MACHINE)/"
    want || return
    echo "== one shnn minibatch pass and one shnn_step on the GPU's clock (timestamp queries, no waits between ops)"
    local env=team_reach/3_ant_claw_centipede preset=paper
    [ -n "${QUICK:-}" ] && env=team_reach/1_ant preset=quick
    DEVICE=gpu PRESET=$preset ITERATIONS=0 MINIBATCH_REPS=3 GPU_TIMING=1 BENCH_ENVS=$env BENCH_MODELS=shnn \
        timeout -s KILL "$(limit 90)" $C/train_throughput > "$RUNS/timeline-pass.log" 2>&1
    local rc=$?
    grep -v '^\s*$' "$RUNS/timeline-pass.log" | sed -n '/gpu-timed/,/^team_reach/p' | head -60
    [ $rc -eq 0 ] || echo "train_throughput: exit $rc (137: stopped at its time limit)"
    want || return
    DEVICE=gpu GPU_TIMING=1 timeout -s KILL "$(limit 60)" $C/train_step shnn_step > "$RUNS/timeline-step.log" 2>&1
    rc=$?
    grep -v '^\s*$' "$RUNS/timeline-step.log" | grep -v XDG | head -45
    [ $rc -eq 0 ] || echo "train_step shnn_step: exit $rc (137: stopped at its time limit)"
    want || return
    # A whole iteration's update (every minibatch, the host's gathers between them, Adam):
    # the second of two, its kernels by kernel and the top op rows.
    echo "-- shnn training on $env, the second iteration on the GPU's clock (MEBEN_TIMINGS=gpu)"
    rm -rf "$RUNS/timeline-train"
    MEBEN_TIMINGS=gpu timeout -s KILL "$(limit 150)" $C/meben train --preset $preset --device gpu --env $env \
        --model shnn "${SIZE[@]}" --steps $((2 * ITER)) --set num_evals=0 --quiet --out "$RUNS/timeline-train" \
        > "$RUNS/timeline-train.log" 2>&1
    rc=$?
    grep -v XDG "$RUNS/timeline-train.log" | sed -n '/iteration 2 took/,$p' | head -40
    [ $rc -eq 0 ] || echo "meben train: exit $rc (137: stopped at its time limit)"
}

sim() {
    echo "== the simulator's scaling (random actions, 1024 environments, team_reach/3_ant_claw_centipede)"
    for t in 1 2 4 8 16; do
        [ "$t" -le "$CORES" ] || continue
        want sim || break
        if [ -n "${QUICK:-}" ]; then sizes=(STEPS=10 NENV=32); else sizes=(STEPS=10 NENV=1024); fi
        env RAYON_NUM_THREADS="$t" ENVS=team_reach/3_ant_claw_centipede "${sizes[@]}" timeout 60 $C/tasks 2>&1 \
            | grep env_steps_per_s | sed "s/\$/ ($MACHINE)/"
    done
}

cpu() {
    echo "== training on the CPU alone ($CORES threads; one iteration, warm-up included)"
    pairs cpu 1 120 team_reach/3_ant_claw_centipede:mlp_hn team_reach/1_ant:shnn team_reach/1_ant:mlp_hn \
        team_reach/3_ant_claw_centipede:shnn
}

for section in $SECTIONS; do
    if want; then "$section"; else echo "== $section: skipped (deadline ${DEADLINE} s)"; fi
done
echo "== done in ${SECONDS} s"
