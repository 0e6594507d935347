#!/usr/bin/env bash
# Runs the reproduction's sweeps (issue 15, docs/RESULTS.md; the second wave, issue 45, as
# workers C and D) as two workers of one thread each, cheap runs first, then exports their evidence into results/ and regenerates the
# reports. Run directories live outside the work tree; restarting a worker resumes where it
# stopped (finished runs are skipped, interrupted ones resume bit-identically).
#
#   nice -n 19 rl/sweeps/repro_run.sh A &  nice -n 19 rl/sweeps/repro_run.sh B &    # the two workers
#   nice -n 19 rl/sweeps/repro_run.sh C &  nice -n 19 rl/sweeps/repro_run.sh D &    # the second wave's
#   nice -n 19 rl/sweeps/repro_run.sh E &  nice -n 19 rl/sweeps/repro_run.sh F &    # the third wave's
#   nice -n 19 rl/sweeps/repro_run.sh H &  nice -n 19 rl/sweeps/repro_run.sh H &    # its item 3 (two workers)
#   nice -n 19 rl/sweeps/repro_run.sh G &                                            # issue 79
#   nice -n 19 rl/sweeps/repro_run.sh I &                                            # issue 79, assign_prior=10
#   nice -n 19 rl/sweeps/repro_run.sh J &                                            # issue 79, Team Sumo
#   nice -n 19 rl/sweeps/repro_run.sh K &                                            # issue 79, no assignment bonus
#   nice -n 19 rl/sweeps/repro_run.sh L &                                            # issue 79, a warm-up
#   nice -n 19 rl/sweeps/repro_run.sh M &                                            # issue 79, a held draw
#   nice -n 19 rl/sweeps/repro_run.sh N &                                            # issue 79, a draw per episode
#   nice -n 19 rl/sweeps/repro_run.sh O &                                            # issue 79, a value reading it
#   nice -n 19 rl/sweeps/repro_run.sh P &                                            # issue 79, the expected gradient
#   nice -n 19 rl/sweeps/repro_run.sh Q &                                            # issue 79, its value fitted at the draw
#   nice -n 19 rl/sweeps/repro_run.sh R &                                            # issue 79, a draw credited per episode
#   rl/sweeps/repro_run.sh export                             # evidence -> results/, reports
#   rl/sweeps/repro_run.sh restore                            # finished runs <- results/ (A and B do it first)
#   rl/sweeps/repro_run.sh status                             # every run's progress and hours left
#
# Ctrl-C or SIGTERM to a worker's `meben` stops its run after the current iteration with a
# checkpoint (exit 130), and the worker with it.
#
# OUT (default /tmp/runs/repro) holds the runs; BIN (default target/release/meben) is the
# program (build it first: cargo build --release); REPORT_BIN (default BIN) the one that
# redraws the reports at a matched budget (results/<exp>/at_<N>/: it must know
# `meben report --at-steps`, which binaries before 0445b8f do not); THREADS (default 1) the threads a run
# uses: 2 for a worker left alone on the 2-core machine (its last runs), whose rows are the
# same at any thread count (docs/PERFORMANCE.md). Start the workers under `nice` as shown,
# so that builds and tests run beside them at full speed: every thread a worker creates
# inherits its niceness, while `renice` of a running process id reaches only its main thread.
set -uo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/target/release/meben}
OUT=${OUT:-/tmp/runs/repro}
THREADS=${THREADS:-1}
SWEEPS=$ROOT/rl/sweeps
EXPERIMENTS="reach_1_ant reach_2_ants equivariance sumo reach_2_ants_no_assignment reach_2_ants_per_slot_starts transformer_1_ant centipede reach_2_ants_50m reach_1_ant_50m equivariance_2_ants learned_assignment learned_assignment_prior learned_assignment_sumo learned_assignment_entropy learned_assignment_warmup learned_assignment_hold learned_assignment_episode learned_assignment_critic learned_assignment_expected learned_assignment_value_at_draw learned_assignment_episode_credit"

# The sweep file of an experiment: rl/sweeps/repro_<exp>.toml, or rl/sweeps/<exp>.toml for
# the experiments that are not reproductions (issue 79's learned_assignment,
# learned_assignment_prior, learned_assignment_sumo, learned_assignment_entropy,
# learned_assignment_warmup, learned_assignment_hold, learned_assignment_episode,
# learned_assignment_critic, learned_assignment_expected, learned_assignment_value_at_draw and
# learned_assignment_episode_credit).
sweep_file() {
  if [ -f "$SWEEPS/repro_$1.toml" ]; then echo "$SWEEPS/repro_$1.toml"; else echo "$SWEEPS/$1.toml"; fi
}

run() { # <experiment> <pattern>...: the sweep's runs whose names contain a pattern
  local exp=$1; shift
  local only=()
  for p in "$@"; do only+=(--only "$p"); done
  echo "== $(date -Is) $exp ${only[*]}"
  "$BIN" ablate --sweep "$(sweep_file "$exp")" --out "$OUT/$exp" --threads "$THREADS" --quiet "${only[@]}"
  # 130: stopped by Ctrl-C or SIGTERM after an iteration, with a checkpoint; the worker
  # stops too instead of starting the next sweep (the same command resumes it).
  local rc=$?
  if [ $rc -eq 130 ]; then
    echo "== $(date -Is) interrupted: worker stops"
    exit 130
  fi
  # A run that finished goes into results/ at once (the work tree, not yet a commit): a
  # machine that is not handed back loses its run directories, and so lost a finished,
  # unexported run once (docs/RESULTS.md, the warm-up seed 0).
  [ $rc -eq 0 ] && export_experiment "$exp"
}

# Copies an experiment's evidence into results/<exp> and redraws its reports, those at a
# matched budget (results/<exp>/at_<N>/) included.
export_experiment() {
  local exp=$1 at
  "$BIN" export "$OUT/$exp" "$ROOT/results/$exp" && (cd "$ROOT" && "$BIN" report "results/$exp" --paper results/paper.toml > /dev/null)
  for at in "$ROOT/results/$exp"/at_*/; do
    [ -d "$at" ] || continue
    at=${at%/}
    (cd "$ROOT" && "${REPORT_BIN:-$BIN}" report "results/$exp" --paper results/paper.toml --at-steps "${at##*/at_}" > /dev/null)
  done
}

# On a fresh machine (no run directories under OUT), the finished runs come back from their
# committed evidence (a run with done.json is skipped, so they are not trained again); a run
# that was still training starts over (its checkpoints are never committed).
restore_finished() {
  local done rel
  for exp in $EXPERIMENTS; do
    [ -d "$ROOT/results/$exp" ] || continue
    while IFS= read -r done; do
      rel=${done#"$ROOT/results/$exp/"}
      rel=${rel%/done.json}
      [ -e "$OUT/$exp/$rel" ] && continue
      mkdir -p "$OUT/$exp/$rel" && cp "$ROOT/results/$exp/$rel"/* "$OUT/$exp/$rel/" \
        && echo "== restored the finished run $exp/$rel from results/"
    done < <(find "$ROOT/results/$exp" -name done.json)
  done
}

# Team Sumo (one run, its own experiment) comes before `shnn` on 1_ant so that every
# experiment has a finished run as early as the machine allows. The two diagnostic runs
# (MLP+HN on 2_ants without the assignment, repro_reach_2_ants_no_assignment.toml, and with
# the release's reset, repro_reach_2_ants_per_slot_starts.toml) come before it: each costs
# about what an `mlp_hn` run on 2_ants does (seed 0: 1.3 h) and tests one explanation of a
# disagreement with the paper (docs/RESULTS.md).
# Each worker's own list, then the other's: a run being trained by the other worker is
# refused by its directory lock (logged as "failed: ... in use by process N"; the sweep goes on to
# its next run), so a worker that finishes early takes the other's remaining runs.
list_a() {
  run equivariance /mlp/ /mlp_hn/
  run reach_1_ant /mlp_hn/
  run reach_2_ants /mlp_hn/
  run reach_2_ants_no_assignment /mlp_hn_assignment-none/
  run reach_2_ants_per_slot_starts /mlp_hn/
  run sumo /shnn/
  run reach_1_ant /shnn/
}
list_b() {
  run equivariance /shnn/
  run reach_2_ants /shnn/
}

# The second wave (issue 45): the cheaper model of each pair first, so that both experiments
# have a finished baseline early; then the SHNN-family runs, `shtransformer` the slowest.
list_c() {
  run centipede /mlp_hn/
  run transformer_1_ant /transformer_hn/
  run centipede /shnn/
}
list_d() {
  run transformer_1_ant /shtransformer/
}

# The third wave (issue 78): MLP+HN on 2_ants at the paper's budget and seed count (50M env
# steps, 10 seeds; about 4.5 machine-hours a seed at one thread), seeds in order, so that
# seeds 0-2 re-train the committed 20M rows of results/reach_2_ants first.
list_e() {
  for seed in 0 1 2 3 4 5 6 7 8 9; do
    run reach_2_ants_50m "/seed$seed"
  done
}
# MLP+HN on 1_ant at 50M env steps, 10 seeds (about 1.8 machine-hours a seed: one fits in a
# session beside other work), seeds in order; seeds 0-2 re-train results/reach_1_ant's rows.
list_f() {
  for seed in 0 1 2 3 4 5 6 7 8 9; do
    run reach_1_ant_50m "/seed$seed"
  done
}

# The 2_ants half of the equivariance test (issue 78, runs item 3): MLP and MLP+HN, 3 seeds
# at 10M each (about 1 machine-hour a run at one thread: each fits in a session), a seed of
# each model in turn. Two H workers share the list: each skips the run the other holds.
list_h() {
  for seed in 0 1 2; do
    run equivariance_2_ants "/mlp/seed$seed"
    run equivariance_2_ants "/mlp_hn/seed$seed"
  done
}
# Issue 79's evidence on 2_ants, 3 seeds at 10M each: mlp_hn:assignment=learned first
# (about 1 machine-hour a seed at one thread), then shnn:assignment=learned (about 6.7).
list_g() {
  for seed in 0 1 2; do
    run learned_assignment "mlp_hn_assignment-learned/seed$seed"
  done
  for seed in 0 1 2; do
    run learned_assignment "shnn_assignment-learned/seed$seed"
  done
}

# Issue 79's follow-up: mlp_hn:assignment=learned with the sharper prior assign_prior=10, 3
# seeds at 10M (about 1 machine-hour a seed at one thread); worker I then joins worker G's
# list (a run another worker is training is skipped: its directory is locked).
list_i() {
  for seed in 0 1 2; do
    run learned_assignment_prior "/seed$seed"
  done
}

# Issue 79's Team Sumo run: shnn:assignment=learned against MLP+HN, one seed at 10M (about
# 15 machine-hours at one thread), after the Team Reach seeds of workers G and I.
list_j() {
  run learned_assignment_sumo /shnn_assignment-learned/
}

# Issue 79's second follow-up: mlp_hn:assignment=learned without the assignment's entropy
# bonus (assignment_entropy_scale = 0, a field binaries before it refuse), 3 seeds at 10M
# (about 1 machine-hour a seed at one thread).
list_k() {
  for seed in 0 1 2; do
    run learned_assignment_entropy "/seed$seed"
  done
}

# Issue 79's third follow-up: mlp_hn:assignment=learned with a 16M warm-up as greedy MLP+HN,
# then 10M learning the assignment, 3 seeds (about 1.6 machine-hours a seed at one thread).
list_l() {
  for seed in 0 1 2; do
    run learned_assignment_warmup "/seed$seed"
  done
}

# Issue 79's fourth follow-up: mlp_hn:assignment=learned with each draw held for an unroll
# (assignment_hold_steps = 5, a field binaries before it refuse), 3 seeds at 10M (about half
# a machine-hour a seed at one thread alone on the machine).
list_m() {
  for seed in 0 1 2; do
    run learned_assignment_hold "/seed$seed"
  done
}

# Issue 79's fifth follow-up: mlp_hn:assignment=learned with each draw held for its episode
# (assignment_hold_episode = true, a field binaries before it refuse), 3 seeds at 10M (about
# half a machine-hour a seed at one thread alone on the machine).
list_n() {
  for seed in 0 1 2; do
    run learned_assignment_episode "/seed$seed"
  done
}

# Issue 79's sixth follow-up: held per episode, with a value that reads the held assignment
# (assign_critic=held, a model option binaries before it refuse), 3 seeds at 10M (about 1
# machine-hour a seed at one thread beside other runs).
list_o() {
  for seed in 0 1 2; do
    run learned_assignment_critic "/seed$seed"
  done
}

# Issue 79's seventh follow-up: as the sixth, with the expected assignment gradient
# (assignment_gradient = "expected", a field binaries before it refuse), 3 seeds at 10M
# (about 2 machine-hours a seed at one thread beside other runs).
list_p() {
  for seed in 0 1 2; do
    run learned_assignment_expected "/seed$seed"
  done
}

# Issue 79's eighth follow-up: as the seventh, the held critic fitted at the drawing steps
# too (assignment_value_at_draw = true, a field binaries before it refuse), 3 seeds at 10M
# (about 1 machine-hour a seed at one thread beside other runs).
list_q() {
  for seed in 0 1 2; do
    run learned_assignment_value_at_draw "/seed$seed"
  done
}

# Issue 79's ninth follow-up: the runs held per episode with each draw credited with its
# episode's return (assignment_gradient = "episode", a value binaries before it refuse), 3
# seeds at 10M (about 1 machine-hour a seed at one thread beside other runs). Two workers
# share the seeds (a run the other is training is refused by its lock).
list_r() {
  for seed in 0 1 2; do
    run learned_assignment_episode_credit "/seed$seed"
  done
}

case "${1:-}" in
  R)
    restore_finished
    list_r
    ;;
  Q)
    restore_finished
    list_q
    ;;
  P)
    restore_finished
    list_p
    ;;
  O)
    restore_finished
    list_o
    ;;
  N)
    restore_finished
    list_n
    ;;
  I)
    restore_finished
    list_i
    list_g
    list_j
    ;;
  G)
    restore_finished
    list_g
    list_j
    ;;
  J)
    restore_finished
    list_j
    ;;
  K)
    restore_finished
    list_k
    ;;
  L)
    restore_finished
    list_l
    ;;
  M)
    restore_finished
    list_m
    ;;
  H)
    restore_finished
    list_h
    ;;
  E)
    restore_finished
    list_e
    ;;
  F)
    restore_finished
    list_f
    list_e
    ;;
  C)
    restore_finished
    list_c
    list_d
    ;;
  D)
    restore_finished
    list_d
    list_c
    ;;
  A)
    restore_finished
    list_a
    list_b
    ;;
  B)
    restore_finished
    list_b
    list_a
    ;;
  restore)
    restore_finished
    ;;
  status)
    for exp in $EXPERIMENTS; do
      [ -d "$OUT/$exp" ] || continue
      echo "== $exp"
      "$BIN" status "$OUT/$exp"
    done
    ;;
  export)
    for exp in $EXPERIMENTS; do
      [ -d "$OUT/$exp" ] || continue
      export_experiment "$exp"
    done
    du -sh "$ROOT/results"
    ;;
  *)
    echo "usage: $0 A | B | C | D | E | F | G | H | I | J | K | L | M | N | O | P | Q | R | export | restore | status" >&2
    exit 2
    ;;
esac
