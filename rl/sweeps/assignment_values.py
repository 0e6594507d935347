#!/usr/bin/env python3
"""Does the value that reads a learned assignment rank the assignments as their returns do
(issue 79)?

`assignment_gradient = "expected"` moves a scorer along the held value's ranking of the
assignments at each episode's first step. For each run directory of
`assignment=learned;assign_critic=held` held per episode (`assignment_hold_episode`; it must
still hold its checkpoint), its configuration and checkpoint are copied to a scratch run
directory (the value network is read, which a policy file does not hold; nothing is written
to the run) and evaluated twice from the same starts and seeds with `--assignment-values`
(sampled actions):

- with its own draws, held per episode as it trained;
- with Algorithm 1's assignment of each episode's first step held to its end
  (`--assignment greedy --assignment-hold 1000`).

Both begin episode `e` from the same state `s_0`, and read there `V(s_0, σ)` and `π(σ | s_0)`
for every assignment `σ`; each gives the episode's discounted return `G` in the value's
units (`rl::mappo::assignment_values`). Paired by episode:

- where the scorer drew another assignment than Algorithm 1's: how many; the value's mean
  difference `V(s_0, drawn) - V(s_0, Algorithm 1's)` (what the expected gradient follows),
  and the realised mean difference `G(drawn) - G(Algorithm 1's)` with its 95% interval (the
  normal one of a mean of paired differences), and the same of the undiscounted return and of
  success (in points);
- where it drew Algorithm 1's: how many, and the realised mean difference (a control: the
  two evaluations play the same action noise, so such an episode may replay exactly);
- over every episode: the share where the value ranks Algorithm 1's assignment first, the
  scorer's mean `π(Algorithm 1's | s_0)`, and under Algorithm 1 held the mean `V(s_0, σ)`,
  the mean `G`, their correlation, and the mean `V(s_0)` read without an assignment (what the
  value is trained on at a drawing step unless `assignment_value_at_draw`).

    rl/sweeps/assignment_values.py --bin target/release/meben [--episodes 1024] <run dir>...
"""

import math
import os
import shutil
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from assignment_diagnostics import eval_summary, load_scorer, refuse  # noqa: E402
from assignment_substitution import EPISODE, evaluation_arguments, held_per_episode  # noqa: E402


def scratch_copy(run, to):
    """A run directory `to` holding `run`'s config.toml, checkpoint.json and checkpoint
    tensors (what `meben eval --run` reads), so that its evaluations write nothing to `run`."""
    if os.path.isdir(to):
        shutil.rmtree(to)
    os.makedirs(to)
    names = ["config.toml", "checkpoint.json"]
    names += [f for f in os.listdir(run) if f.startswith("checkpoint.") and f.endswith(".safetensors")]
    for name in names:
        try:
            shutil.copy(os.path.join(run, name), os.path.join(to, name))
        except OSError as e:
            refuse(f"{run}: cannot copy {name} ({e})")


def values_of(meben, run, copy, episodes, seed, extra, summary):
    """Team 0's `assignment_values` entry of `meben eval --run <copy> --episodes <episodes>
    --seed <seed> --stochastic --assignment-values <extra>` (`copy` a scratch copy of `run`)."""
    args = ["--episodes", str(episodes), "--seed", str(seed), "--stochastic", "--assignment-values"] + extra
    e = eval_summary(meben, run, ["--run", copy], args, summary)
    try:
        v = next(x for x in e["assignment_values"] if x["team"] == 0)
        if len(v["episodes"]) != episodes:
            raise ValueError(f"{len(v['episodes'])} episodes, not {episodes}")
        return v
    except (KeyError, TypeError, StopIteration, ValueError) as err:
        refuse(f"{run}: the evaluation summary holds no assignment values of team 0's {episodes} episodes ({err!r})")


def mean_and_interval(xs):
    """The mean of `xs` and the half-width of its normal 95% interval (0 for fewer than 2)."""
    n = len(xs)
    if n == 0:
        return float("nan"), float("nan")
    m = sum(xs) / n
    if n < 2:
        return m, 0.0
    sd = math.sqrt(sum((x - m) ** 2 for x in xs) / (n - 1))
    return m, 1.959964 * sd / math.sqrt(n)


def correlation(xs, ys):
    """Pearson's correlation of `xs` and `ys` (0 where either is constant)."""
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxy = sum((x - mx) * (y - my) for x, y in zip(xs, ys))
    sx, sy = sum((x - mx) ** 2 for x in xs), sum((y - my) ** 2 for y in ys)
    return sxy / math.sqrt(sx * sy) if sx > 0 and sy > 0 else 0.0


def compare(own, greedy):
    """The run's figures (module doc) from the two evaluations' `assignment_values`."""
    if own["support"] != greedy["support"]:
        refuse("the two evaluations' scorers have different supports")
    other, same = [], []
    for o, g in zip(own["episodes"], greedy["episodes"]):
        a1, drawn = g["acted"], o["acted"]
        if drawn == a1:
            same.append(o["discounted_return"] - g["discounted_return"])
        else:
            # The value read in the own evaluation's s_0 (the same state as the other's).
            other.append(
                (
                    o["value"][drawn] - o["value"][a1],
                    o["discounted_return"] - g["discounted_return"],
                    o["return"] - g["return"],
                    100.0 * (int(o["success"]) - int(g["success"])),
                )
            )
    episodes = greedy["episodes"]
    first = sum(1 for g in episodes if max(g["value"]) <= g["value"][g["acted"]])
    v = [g["value"][g["acted"]] for g in episodes]
    ret = [g["discounted_return"] for g in episodes]
    n = len(episodes)
    return {
        "n": n,
        "other": len(other),
        "value_gap": sum(x[0] for x in other) / len(other) if other else float("nan"),
        "discounted": mean_and_interval([x[1] for x in other]),
        "return": mean_and_interval([x[2] for x in other]),
        "success": mean_and_interval([x[3] for x in other]),
        "same": len(same),
        "control": mean_and_interval(same),
        "value_prefers_a1": first / n,
        "pi_a1": sum(g["probability"][g["acted"]] for g in episodes) / n,
        "value_a1": sum(v) / n,
        "return_a1": sum(ret) / n,
        "correlation": correlation(v, ret),
        "unheld": sum(g["unheld_value"] for g in episodes) / n,
    }


def interval(m, digits=2):
    """A mean and its 95% half-width as two cells (dashes where there is none)."""
    return f"{m[0]:.{digits}f} | ±{m[1]:.{digits}f}" if not math.isnan(m[0]) else "– | –"


def paired_row(run, f):
    """The row of `run`'s paired figures `f` (the first table)."""
    gap = f"{f['value_gap']:.2f}" if not math.isnan(f["value_gap"]) else "–"
    return (
        f"| `{run}` | {f['other']} | {100 * f['other'] / f['n']:.1f}% | {gap} | {interval(f['discounted'])} "
        f"| {interval(f['return'], 1)} | {interval(f['success'], 1)} | {f['same']} | {interval(f['control'])} |"
    )


def value_row(run, f):
    """The row of `run`'s figures over every episode `f` (the second table)."""
    return (
        f"| `{run}` | {100 * f['value_prefers_a1']:.1f}% | {f['pi_a1']:.2f} | {f['value_a1']:.2f} "
        f"| {f['return_a1']:.2f} | {f['correlation']:.2f} | {f['unheld']:.2f} |"
    )


def main():
    a = evaluation_arguments(
        __doc__.split("\n\n")[0], "run directories of assignment=learned;assign_critic=held, held per episode"
    )
    # Every run is read before anything is evaluated: bad input stops with its message.
    for run in a.runs:
        load_scorer(run)
        if not held_per_episode(run):
            refuse(f"{run}: its draws were not held per episode (assignment_hold_episode = true)")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        copy, summary = os.path.join(tmp, "run"), os.path.join(tmp, "eval.json")
        for run in a.runs:
            scratch_copy(run, copy)
            ev = lambda extra: values_of(a.bin, run, copy, a.episodes, a.seed, extra, summary)  # noqa: E731
            own = ev([])
            greedy = ev(["--assignment", "greedy", "--assignment-hold", str(EPISODE)])
            rows.append((run, compare(own, greedy)))
            print(f"{run}: done", file=sys.stderr, flush=True)
    print(f"Over {a.episodes} episodes (`meben eval --stochastic --seed {a.seed} --assignment-values`), paired by")
    print("episode: the scorer's own draws against Algorithm 1's assignment of each episode's first step held")
    print(f"(`--assignment greedy --assignment-hold {EPISODE}`). Values and discounted returns `G` are in the")
    print("value's units (the run's discount and reward scaling); returns are undiscounted; intervals are 95%")
    print("normal ones of paired means. Where the scorer drew otherwise than Algorithm 1, and where it drew as it:\n")
    print(
        "| run | episodes drawn otherwise | share | value: V(drawn) - V(Alg. 1) | G(drawn) - G(Alg. 1) | 95% "
        "| return(drawn) - return(Alg. 1) | 95% | success(drawn) - success(Alg. 1), points | 95% "
        "| episodes drawn as Alg. 1 | G difference there | 95% |"
    )
    print("|---|" + "---:|" * 12)
    for run, f in rows:
        print(paired_row(run, f))
    print("\nOver every episode, at its first step: the share where the value ranks Algorithm 1's assignment")
    print("first, the scorer's mean probability of it, and under Algorithm 1 held the mean value, the mean")
    print("discounted return, their correlation over episodes, and the mean value read without an assignment.\n")
    print("| run | the value ranks Alg. 1 first | π(Alg. 1) | V(s0, Alg. 1) | G, Alg. 1 held | their correlation | V(s0), no assignment |")
    print("|---|" + "---:|" * 6)
    for run, f in rows:
        print(value_row(run, f))


if __name__ == "__main__":
    main()
