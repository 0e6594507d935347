#!/usr/bin/env bash
# Checks that a committed run is reproducible: re-trains its `config.toml` in a scratch
# directory with the given program and compares the `metrics.csv` rows with the committed
# ones, wall-time columns (`wall_s`, `steps_per_s`) aside. With ITERATIONS, it stops the
# re-run once that many rows are written and compares those; without, it trains the whole
# budget and compares every row.
#
#   rl/sweeps/repro_check.sh results/equivariance/team_reach_1_centipede/mlp/seed0 7
#
# BIN (default target/release/meben) is the program; THREADS (default 1) its worker
# threads, which change nothing but the speed. Exit status 0: the rows are identical;
# 1: they differ (the first differing row is printed); 2: bad usage or the run failed.
set -uo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/target/release/meben}
THREADS=${THREADS:-1}

usage() { echo "usage: $0 <run directory with config.toml and metrics.csv> [iterations]" >&2; exit 2; }
[ $# -ge 1 ] && [ $# -le 2 ] || usage
RUN=$1
WANT=${2:-}
[ -f "$RUN/config.toml" ] || { echo "$0: $RUN/config.toml: no such file" >&2; exit 2; }
[ -f "$RUN/metrics.csv" ] || { echo "$0: $RUN/metrics.csv: no such file" >&2; exit 2; }
[ -x "$BIN" ] || { echo "$0: $BIN: no such program (cargo build --release, or set BIN)" >&2; exit 2; }
if [ -n "$WANT" ] && ! [[ "$WANT" =~ ^[1-9][0-9]*$ ]]; then
  echo "$0: iterations = '$WANT': expected a positive integer" >&2
  exit 2
fi
COMMITTED_ROWS=$(($(wc -l < "$RUN/metrics.csv") - 1))
if [ -n "$WANT" ] && [ "$WANT" -gt "$COMMITTED_ROWS" ]; then
  echo "$0: iterations = $WANT, but $RUN/metrics.csv has only $COMMITTED_ROWS rows" >&2
  exit 2
fi

SCRATCH=$(mktemp -d "${TMPDIR:-/tmp}/repro_check.XXXXXX")
trap 'rm -rf "$SCRATCH"' EXIT
"$BIN" train --config "$RUN/config.toml" --threads "$THREADS" --out "$SCRATCH/run" --quiet \
  > "$SCRATCH/train.log" 2>&1 &
PID=$!

rows() { [ -f "$SCRATCH/run/metrics.csv" ] && echo $(($(wc -l < "$SCRATCH/run/metrics.csv") - 1)) || echo 0; }
if [ -n "$WANT" ]; then
  while kill -0 "$PID" 2> /dev/null && [ "$(rows)" -lt "$WANT" ]; do sleep 2; done
  # At once: a plain SIGTERM would let it train one more iteration (meben stops after the
  # current one), and the scratch run is thrown away.
  kill -KILL "$PID" 2> /dev/null
  { wait "$PID"; } 2> /dev/null
else
  if ! wait "$PID"; then
    echo "$0: the re-run failed:" >&2
    tail -n 20 "$SCRATCH/train.log" >&2
    exit 2
  fi
  WANT=$COMMITTED_ROWS
fi
if [ "$(rows)" -lt "$WANT" ]; then
  echo "$0: the re-run wrote $(rows) rows, fewer than $WANT:" >&2
  tail -n 20 "$SCRATCH/train.log" >&2
  exit 2
fi

# Columns 3 and 4 are wall_s and steps_per_s; every other column must match bit for bit
# (the CSV holds each float's shortest round-trip text, so equal text is equal bits).
strip() { head -n $((WANT + 1)) "$1" | cut -d, -f1,2,5-; }
if cmp -s <(strip "$RUN/metrics.csv") <(strip "$SCRATCH/run/metrics.csv"); then
  echo "identical: $WANT rows of $RUN/metrics.csv (wall-time columns aside)"
  exit 0
fi
echo "DIFFERENT: $RUN/metrics.csv and its re-run, first differing row:"
diff <(strip "$RUN/metrics.csv") <(strip "$SCRATCH/run/metrics.csv") | head -n 4
exit 1
