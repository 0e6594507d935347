#!/usr/bin/env python3
"""How a training run's dependence on its task assignment grows (issue 79), traced while it trains.

Whenever a run's checkpoint holds an iteration not yet traced, its policy is written to a
scratch file (`meben export-policy`, which reads the checkpoint; nothing is written to the
run) and evaluated with `meben eval --episodes N --stochastic --assignment-sensitivity`, and
one CSV row is appended to --out:

    run, iteration, env_steps, success, kl_mean, kl_median, kl_p90, kl_early, p_nearer

(`success`: of that evaluation, in [0, 1]; `kl_*`: the KL divergence in nats from the
action distribution under the assignment acted on to that under the other ones, per
scene-step, TRAINING.md; `kl_early` over each episode's first 100 steps; `p_nearer`: for a
learned assignment, a ball's chance of picking the nearer of two agents at 2 and 3 m from
the policy file's scorer, as `assignment_diagnostics.py` gives it; empty otherwise). The
iteration and env steps are the policy file's. Rows already in --out are not traced again,
so a restarted trace goes on where it stopped. With --every S it looks again every S
seconds until interrupted; without it, once. --table prints the trace at --out as a Markdown
table (each run's rows together, by iteration; success and p_nearer as percents) and exits.

    rl/sweeps/sensitivity_trace.py --bin target/release/meben --out trace.csv [--every 1200] <run dir>...
    rl/sweeps/sensitivity_trace.py --out trace.csv --table
"""

import argparse
import csv
import json
import os
import struct
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from assignment_diagnostics import export_policy, p_nearer, policy_sensitivity, prior_of, refuse, scorer_layers  # noqa: E402

COLUMNS = ["run", "iteration", "env_steps", "success", "kl_mean", "kl_median", "kl_p90", "kl_early", "p_nearer"]


def metadata(path):
    """The `__metadata__` of the safetensors file `path`."""
    try:
        with open(path, "rb") as f:
            (n,) = struct.unpack("<Q", f.read(8))
            return json.loads(f.read(n)).get("__metadata__", {})
    except (OSError, struct.error, ValueError) as e:
        refuse(f"{path}: not a readable policy file ({e})")


def traced(out):
    """(run, iteration) pairs already in the CSV `out`."""
    if not os.path.exists(out):
        return set()
    with open(out, newline="") as f:
        rows = list(csv.reader(f))
    if not rows or rows[0] != COLUMNS:
        refuse(f"--out {out}: not a trace of this script (its header is not {','.join(COLUMNS)})")
    return {(r[0], int(r[1])) for r in rows[1:] if len(r) == len(COLUMNS)}


def trace(meben, run, episodes, tmp, seen):
    """One row for the run's current checkpoint (module doc), or None when its iteration is in
    `seen` or the checkpoint is being replaced (the next look reads the new one)."""
    policy = os.path.join(tmp, "policy.safetensors")
    failed = export_policy(meben, run, policy)
    if failed:
        if not os.path.isdir(run):
            refuse(f"{run}: not a run directory")
        print(f"sensitivity_trace.py: {run}: `meben export-policy` failed, trying at the next look: {failed}", file=sys.stderr)
        return None
    meta = metadata(policy)
    if (run, int(meta["iteration"])) in seen:
        return None
    success, s = policy_sensitivity(meben, run, policy, episodes, os.path.join(tmp, "eval.json"))
    layers = scorer_layers(policy)
    p = f"{p_nearer(layers, prior_of(meta.get('config', ''))):.4f}" if layers else ""
    return [
        run,
        int(meta["iteration"]),
        int(meta["env_steps"]),
        f"{success:.4f}",
        f"{s['mean_kl']:.4f}",
        f"{s['median_kl']:.4f}",
        f"{s['p90_kl']:.4f}",
        f"{s['early_mean_kl']:.4f}",
        p,
    ]


def print_table(out):
    """The trace at `out` as a Markdown table: each run's rows together (runs in the order they
    first appear), by iteration."""
    if not os.path.exists(out):
        refuse(f"--out {out}: no such trace")
    traced(out)  # refuses another file
    with open(out, newline="") as f:
        rows = list(csv.reader(f))[1:]
    first = {}
    for r in rows:
        first.setdefault(r[0], len(first))
    rows.sort(key=lambda r: (first[r[0]], int(r[1])))
    print("| run | iteration | env steps | success | KL mean | KL median | KL 90th percentile | KL mean, first 100 steps | P(nearer) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        pct = lambda x: f"{100 * float(x):.1f}%" if x else "–"  # noqa: E731
        steps = f"{int(r[2]) / 1e6:.2f}M"
        print(f"| `{r[0]}` | {r[1]} | {steps} | {pct(r[3])} | " + " | ".join(f"{float(x):.2f}" for x in r[4:8]) + f" | {pct(r[8])} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default="target/release/meben", help="the meben program (with --assignment-sensitivity)")
    ap.add_argument("--out", required=True, help="the CSV to append to")
    ap.add_argument("--episodes", type=int, default=32, help="episodes of each evaluation")
    ap.add_argument("--every", type=float, help="look again every this many seconds (default: once)")
    ap.add_argument("--table", action="store_true", help="print the trace at --out as Markdown and exit")
    ap.add_argument("runs", nargs="*", help="run directories (training or finished)")
    a = ap.parse_args()
    if a.table:
        print_table(a.out)
        return
    if not a.runs:
        ap.error("no run directories")
    if a.episodes < 1:
        ap.error(f"--episodes {a.episodes}: at least 1")
    if a.every is not None and not a.every > 0:
        ap.error(f"--every {a.every}: more than 0 seconds")
    if not (os.path.isfile(a.bin) and os.access(a.bin, os.X_OK)):
        refuse(f"--bin {a.bin}: not an executable file (build it: cargo build --release -p rl)")
    for run in a.runs:
        if not os.path.isdir(run):
            refuse(f"{run}: not a run directory")
    seen = traced(a.out)
    while True:
        with tempfile.TemporaryDirectory() as tmp:
            for run in a.runs:
                row = trace(a.bin, run, a.episodes, tmp, seen)
                if row is None:
                    continue
                new = not os.path.exists(a.out)
                with open(a.out, "a", newline="") as f:
                    w = csv.writer(f)
                    if new:
                        w.writerow(COLUMNS)
                    w.writerow(row)
                seen.add((run, row[1]))
        if a.every is None:
            return
        time.sleep(a.every)


if __name__ == "__main__":
    main()
