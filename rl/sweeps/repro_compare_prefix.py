#!/usr/bin/env python3
"""Compares the first rows of a longer run with a shorter run of the same configuration
(issue 78: a 50M run's first rows are the committed 10M or 20M run's).

    python3 rl/sweeps/repro_compare_prefix.py SHORTER/metrics.csv LONGER/metrics.csv

Every column but the wall-time ones (`wall_s`, `steps_per_s`) is compared on the rows both
files have: the training columns on every row, the evaluation columns (`eval_*`) where both
rows evaluate (the two budgets' evaluation schedules may round to different iterations).
Exit status 0: identical; 1: a difference (the first ones are printed); 2: bad usage.
"""
import csv
import sys

TIMING = {"wall_s", "steps_per_s"}


def main(argv):
    if len(argv) != 3:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    try:
        rows = [list(csv.DictReader(open(path, newline=""))) for path in argv[1:]]
    except OSError as e:
        print(f"{sys.argv[0]}: {e}", file=sys.stderr)
        return 2
    short, long = rows
    n = min(len(short), len(long))
    training, evaluated, differ = 0, 0, []
    for a, b in zip(short[:n], long[:n]):
        keys = [k for k in a if k not in TIMING]
        if any(k not in b for k in keys):
            print(f"{argv[2]} lacks columns of {argv[1]}", file=sys.stderr)
            return 2
        both_evaluate = bool(a.get("eval_episodes")) and bool(b.get("eval_episodes"))
        for k in keys:
            if k.startswith("eval_") and not both_evaluate:
                continue
            if a[k] != b[k]:
                differ.append((a["iteration"], k, a[k], b[k]))
        training += 1
        evaluated += both_evaluate
    for it, k, x, y in differ[:10]:
        print(f"iteration {it}: {k} {x} in {argv[1]}, {y} in {argv[2]}")
    verdict = "identical" if not differ else f"{len(differ)} values differ"
    print(f"{n} rows compared ({evaluated} with an evaluation in both): {verdict}")
    return 0 if not differ else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
