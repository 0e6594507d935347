#!/usr/bin/env bash
# Runs the reproduction's sweeps (issue 15, docs/RESULTS.md) as two workers of one thread
# each, cheap runs first, then exports their evidence into results/ and regenerates the
# reports. Run directories live outside the work tree; restarting a worker resumes where it
# stopped (finished runs are skipped, interrupted ones resume bit-identically).
#
#   rl/sweeps/repro_run.sh A &  rl/sweeps/repro_run.sh B &    # the two workers
#   rl/sweeps/repro_run.sh export                             # evidence -> results/, reports
#
# OUT (default /tmp/runs/repro) holds the runs; BIN (default target/release/meben) is the
# program (build it first: cargo build --release).
set -uo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/target/release/meben}
OUT=${OUT:-/tmp/runs/repro}
SWEEPS=$ROOT/rl/sweeps
EXPERIMENTS="reach_1_ant reach_2_ants equivariance sumo"

run() { # <experiment> <pattern>...: the sweep's runs whose names contain a pattern
  local exp=$1; shift
  local only=()
  for p in "$@"; do only+=(--only "$p"); done
  echo "== $(date -Is) $exp ${only[*]}"
  "$BIN" ablate --sweep "$SWEEPS/repro_$exp.toml" --out "$OUT/$exp" --threads 1 --quiet "${only[@]}"
}

# Each worker's own list, then the other's: a run being trained by the other worker is
# refused by its directory lock (logged as "failed: ... locked", and the sweep goes on to
# its next run), so a worker that finishes early takes the other's remaining runs.
list_a() {
  run equivariance /mlp/ /mlp_hn/
  run reach_1_ant /mlp_hn/
  run reach_2_ants /mlp_hn/
  run reach_1_ant /shnn/
  run sumo /shnn/
}
list_b() {
  run equivariance /shnn/
  run reach_2_ants /shnn/
}

case "${1:-}" in
  A)
    list_a
    list_b
    ;;
  B)
    list_b
    list_a
    ;;
  export)
    for exp in $EXPERIMENTS; do
      [ -d "$OUT/$exp" ] || continue
      "$BIN" export "$OUT/$exp" "$ROOT/results/$exp" && "$BIN" report "$ROOT/results/$exp" > /dev/null
    done
    du -sh "$ROOT/results"
    ;;
  *)
    echo "usage: $0 A | B | export" >&2
    exit 2
    ;;
esac
