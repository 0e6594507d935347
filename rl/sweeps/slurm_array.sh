#!/bin/bash
# Runs a sweep as a Slurm array job: every array task is one shard of the sweep
# (`--shard k/n` takes the runs whose position i has i % n == k - 1), so the 8 tasks below
# share the runs between them without talking to each other.
#
#   cargo build --release                       # once, on a node that sees the shared disk
#   mkdir -p logs
#   sbatch rl/sweeps/slurm_array.sh             # or: SWEEP=... OUT=... sbatch rl/sweeps/slurm_array.sh
#
# OUT must be on a file system every node sees (every run writes its own directory there;
# the files are written atomically). Restarting is resubmitting: finished runs (done.json)
# are skipped and interrupted ones resume from their last checkpoint, so a task that hit the
# time limit simply continues (`--requeue` below makes Slurm do that after preemption).
# When every task has finished: `target/release/meben report "$OUT"`.
# CI submits this script to a real one-node Slurm, requeueing a task mid-run:
# rl/sweeps/slurm_ci.sh (README, sweeps).
#
# Task ids must run from 1 to the array size (1-based shards): keep `--array=1-N`, not 0-based.
# A 1-8 array has SLURM_ARRAY_TASK_COUNT = 8. More tasks than runs is allowed: the extra
# shards are empty, and their tasks say so (`shard 9/10 of ... is empty: the sweep has 8 runs
# for 10 shards; nothing to do`) and exit 0.
#
#SBATCH --job-name=meben-sweep
#SBATCH --array=1-8
#SBATCH --cpus-per-task=16
#SBATCH --mem=16G
#SBATCH --time=2-00:00:00
#SBATCH --requeue
#SBATCH --output=logs/%x-%A_%a.out

set -euo pipefail

# The sweep file and the output directory (override from the environment at submission).
SWEEP=${SWEEP:-rl/sweeps/team_reach_table.toml}
OUT=${OUT:-$PWD/runs/team_reach_table}
# The release binary, built once beforehand (never `cargo run` from many tasks at once).
MEBEN=${MEBEN:-$PWD/target/release/meben}

echo "task ${SLURM_ARRAY_TASK_ID} of ${SLURM_ARRAY_TASK_COUNT} on $(hostname): ${SWEEP} -> ${OUT}"
# Training uses every core Slurm gives the task (threads = 0 in the configuration).
srun --cpus-per-task="${SLURM_CPUS_PER_TASK:-1}" "$MEBEN" ablate \
    --sweep "$SWEEP" \
    --out "$OUT" \
    --shard "${SLURM_ARRAY_TASK_ID}/${SLURM_ARRAY_TASK_COUNT}"
