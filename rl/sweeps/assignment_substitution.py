#!/usr/bin/env python3
"""Does what a learned task assignment learned help the actions learned with it (issue 79)?

For each run directory of `assignment=learned` (it must still hold its checkpoint: run
directories outside the work tree), its policy is written to a scratch file (`meben
export-policy`; nothing is written to the run) and evaluated three ways on the same episodes
(`meben eval --policy --episodes N --seed S --stochastic`: sampled actions, as in training
and the paper preset's evaluation):

- its own draws (the scorer's assignment, held as the run held it);
- Algorithm 1 in place of the draws at every step (`--assignment greedy`: the paper's greedy
  rule, as in the run's warm-up, the scorer unused);
- for a run that held its draws per episode (`assignment_hold_episode`), Algorithm 1's
  assignment of each episode's first step held to its end (`--assignment greedy
  --assignment-hold 1000`), as the run acted on one assignment an episode.

It prints one Markdown row per run: the scorer's P(nearer) (`assignment_diagnostics.py`),
then each evaluation's success rate (%, two decimals), its 95% Wilson interval and the mean
return. Where Algorithm 1 does
better than the run's own draws, the scorer learned an assignment that the actions do worse
on than on the paper's rule.

    rl/sweeps/assignment_substitution.py --bin target/release/meben [--episodes 1024] <run dir>...
"""

import argparse
import math
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from assignment_diagnostics import eval_policy, export_policy, load_scorer, p_nearer, refuse  # noqa: E402

# Team Reach's episode in steps: a hold this long draws once an episode.
EPISODE = 1000


def wilson(successes, n):
    """The 95% Wilson score interval of a binomial proportion, as (low, high) in [0, 1]."""
    z = 1.959964
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def evaluate(meben, run, policy, episodes, seed, extra, summary):
    """`meben eval --policy <policy> --episodes <episodes> --seed <seed> --stochastic <extra>`;
    (success rate, episodes, team 0's mean return) of its summary (written to `summary`)."""
    args = ["--episodes", str(episodes), "--seed", str(seed), "--stochastic"] + extra
    e = eval_policy(meben, run, policy, args, summary)
    try:
        return e["success_rate"], e["episodes"], e["mean_return"][0]
    except (KeyError, TypeError, IndexError) as err:
        refuse(f"{run}: the evaluation summary has no success rate or mean return ({err!r})")


def held_per_episode(run):
    """Whether the run's config.toml holds its draws per episode."""
    try:
        text = open(os.path.join(run, "config.toml")).read()
    except OSError as e:
        refuse(f"{run}: no readable config.toml ({e})")
    return any(line.replace(" ", "") == "assignment_hold_episode=true" for line in text.splitlines())


def cells(rate, n, mean_return):
    """`rate` as a percent, its 95% Wilson interval over `n` episodes, and the mean return,
    as three cells (each a number or an interval, so that the results' test can read the
    percent back)."""
    low, high = wilson(round(rate * n), n)
    return f"{100 * rate:.2f} | [{100 * low:.2f}, {100 * high:.2f}] | {mean_return:.1f}"


def evaluation_arguments(description, runs_help):
    """The command line of a script that evaluates learned runs (`--bin`, `--episodes`,
    `--seed`, the run directories), checked: `--episodes` at least 1, `--bin` executable."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--bin", default="target/release/meben", help="the meben program")
    ap.add_argument("--episodes", type=int, default=1024, help="episodes of each evaluation")
    ap.add_argument("--seed", type=int, default=12345, help="the evaluations' seed (starts and noise)")
    ap.add_argument("runs", nargs="+", help=runs_help)
    a = ap.parse_args()
    if a.episodes < 1:
        ap.error(f"--episodes {a.episodes}: at least 1")
    if not (os.path.isfile(a.bin) and os.access(a.bin, os.X_OK)):
        refuse(f"--bin {a.bin}: not an executable file (build it: cargo build --release -p rl)")
    return a


def main():
    a = evaluation_arguments(__doc__.split("\n\n")[0], "run directories of assignment=learned with their checkpoints")
    # Every run is read before anything is evaluated: bad input stops with its message.
    scorers = [load_scorer(run) for run in a.runs]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        policy, summary = os.path.join(tmp, "policy.safetensors"), os.path.join(tmp, "eval.json")
        for run, (layers, prior) in zip(a.runs, scorers):
            failed = export_policy(a.bin, run, policy)
            if failed:
                refuse(f"{run}: `meben export-policy` failed with {failed}")
            ev = lambda extra: evaluate(a.bin, run, policy, a.episodes, a.seed, extra, summary)  # noqa: E731
            own = ev([])
            greedy = ev(["--assignment", "greedy"])
            held = ev(["--assignment", "greedy", "--assignment-hold", str(EPISODE)]) if held_per_episode(run) else None
            rows.append(
                f"| `{run}` | {p_nearer(layers, prior):.2f} | {cells(*own)} | {cells(*greedy)} | "
                + (cells(*held) if held else "– | – | –")
                + " |"
            )
            print(f"{run}: done", file=sys.stderr, flush=True)
    print(f"Success (%, its 95% Wilson interval) and team 0's mean return over {a.episodes} episodes (`meben eval")
    print(f"--stochastic --seed {a.seed}`) with the scorer's own draws and with Algorithm 1 in place of them")
    print(f"(`--assignment greedy`; held per episode: `--assignment-hold {EPISODE}`, runs that held their draws")
    print("per episode only).\n")
    print(
        "| run | P(nearer) | own draws | 95% | return | Algorithm 1, every step | 95% | return "
        "| Algorithm 1, held per episode | 95% | return |"
    )
    print("|---|---:|" + "---:|---:|---:|" * 3)
    for r in rows:
        print(r)


if __name__ == "__main__":
    main()
