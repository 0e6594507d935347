#!/usr/bin/env python3
"""What a learned task assignment (`assignment=learned`, issue 79) learned, from finished runs.

For each run directory (it must still hold its checkpoint: run directories outside the work
tree, not the committed evidence) this prints, as Markdown:

1. the learned scores s(d) = f_θ(d, Δh) - λ d of an (agent, ball) pair at distances d and
   Δh = -0.42 m (a ball 0.1 m high, an ant's root about 0.52 m), from the checkpoint's
   `team0.assign.*` parameters, and the chance that a ball picks the nearer of two agents
   whose distances differ by 1 m;
2. over episodes recorded by `meben render` (episode seeds 0..N-1), with the most likely
   assignment (mean actions, the run's deterministic evaluation) and with sampled actions
   and assignments (`--stochastic`, as in training and the paper preset's evaluation): the
   share of steps on which the learned assignment equals Algorithm 1's (recomputed from the
   recorded root and ball positions: balls in order, each taking its nearest free agent)
   and the matching of least total distance (every one-to-one matching tried), and how many
   times per 1000 steps the learned assignment and Algorithm 1's change;
3. how much the actions depend on the assignment, from `meben eval --assignment-sensitivity`
   over `--sensitivity-episodes` episodes with sampled actions (the run's policy written to a
   scratch file by `meben export-policy` first, so nothing is written to the run): the KL
   divergence (nats) from the action distribution under the assignment acted on to that
   under the other one-to-one assignment, per scene-step (mean, median, 90th percentile, and
   the mean over each episode's first 100 steps), beside the evaluation's success rate.

Standard library only (the HTML player's data and the safetensors header are JSON).

    rl/sweeps/assignment_diagnostics.py --bin target/release/meben --episodes 8 <run dir>...
"""

import argparse
import contextlib
import io
import itertools
import json
import math
import os
import re
import struct
import subprocess
import sys
import tempfile
from array import array

# The height of a ball's centre above an ant's root at rest (0.1 m against about 0.52 m).
DH = -0.42


def refuse(message):
    """Stops with `message` on stderr, named by the script running (this one, or
    `sensitivity_trace.py`, which imports it), and exit status 1 (bad input: no traceback)."""
    sys.exit(f"{os.path.basename(sys.argv[0])}: {message}")


def load_scorer(run):
    """The scorer's layers [(weight rows, bias)] from the run's checkpoint, and λ."""
    if not os.path.isdir(run):
        refuse(f"{run}: not a run directory")
    files = [f for f in os.listdir(run) if f.startswith("checkpoint.") and f.endswith(".safetensors")]
    if len(files) != 1:
        refuse(f"{run}: expected one checkpoint.*.safetensors, found {len(files)}")
    layers = scorer_layers(os.path.join(run, files[0]))
    if not layers:
        refuse(f"{run}: no team0.assign.* parameters (not an assignment=learned run?)")
    try:
        config = open(os.path.join(run, "config.toml")).read()
    except OSError as e:
        refuse(f"{run}: no readable config.toml ({e})")
    return layers, prior_of(config)


def prior_of(config):
    """λ of the model string in a configuration's text (`assign_prior=`; default 1)."""
    prior = re.search(r"assign_prior=([0-9.eE+-]+)", config)
    return float(prior.group(1)) if prior else 1.0


def scorer_layers(path):
    """The scorer's layers [(weight rows, bias)] in the safetensors file `path` (a checkpoint
    or a policy file: tensors `team0.assign.mlp.<i>.{weight,bias}`); [] when it has none."""
    try:
        blob = open(path, "rb").read()
        (n,) = struct.unpack("<Q", blob[:8])
        header = json.loads(blob[8 : 8 + n])
    except (OSError, struct.error, ValueError) as e:
        refuse(f"{path}: not a readable safetensors file ({e})")
    tensors = {}
    for name, t in header.items():
        if not name.startswith("team0.assign."):
            continue
        if not isinstance(t, dict) or t.get("dtype") != "F32":
            refuse(f"{path}: tensor {name} is not F32 ({t!r:.80})")
        start, end = t["data_offsets"]
        data_bytes = len(blob) - 8 - n
        if not (0 <= start <= end <= data_bytes) or (end - start) % 4:
            refuse(f"{path}: tensor {name} has data offsets {start}..{end} outside its {data_bytes} data bytes")
        values = array("f")
        values.frombytes(blob[8 + n + start : 8 + n + end])
        tensors[name] = (t["shape"], list(values))
    layers = []
    i = 0
    while f"team0.assign.mlp.{i}.weight" in tensors:
        (rows, cols), w = tensors[f"team0.assign.mlp.{i}.weight"]
        bias = f"team0.assign.mlp.{i}.bias"
        if bias not in tensors or rows * cols != len(w):
            refuse(f"{path}: layer {i} of the scorer has no bias or a weight of another size")
        layers.append(([w[r * cols : (r + 1) * cols] for r in range(rows)], tensors[bias][1]))
        i += 1
    return layers


def p_nearer(layers, prior):
    """A ball's chance of picking the nearer of two agents at 2 and 3 m (at Δh = DH)."""
    s2, s3 = score(layers, prior, 2, DH), score(layers, prior, 3, DH)
    # The logistic of s(2 m) - s(3 m), kept from overflowing where the scores rise steeply.
    return 1 / (1 + math.exp(min(s3 - s2, 700.0)))


def score(layers, prior, d, dh):
    """s = f_θ([d, Δh]) - λ d (tanh hidden layers, a linear output)."""
    x = [d, dh]
    for k, (w, b) in enumerate(layers):
        x = [sum(x[r] * w[r][c] for r in range(len(x))) + b[c] for c in range(len(b))]
        if k + 1 < len(layers):
            x = [math.tanh(v) for v in x]
    return x[0] - prior * d


def greedy(roots, balls):
    """Algorithm 1: balls in order, each taking its nearest free agent; agent -> ball."""
    free = list(range(len(roots)))
    out = [None] * len(roots)
    for j, b in enumerate(balls):
        i = min(free, key=lambda a: math.dist(roots[a], b))
        out[i] = j
        free.remove(i)
    return out


def least_total_distance(roots, balls):
    """The one-to-one matching of least summed distance (all tried); agent -> ball."""
    best = min(
        itertools.permutations(range(len(balls)), len(roots)),
        key=lambda p: sum(math.dist(roots[i], balls[j]) for i, j in enumerate(p)),
    )
    return list(best)


def episode(meben, run, seed, stochastic, path):
    """(steps, steps equal to Algorithm 1, steps equal to the least-distance matching,
    learned changes, Algorithm 1 changes)."""
    cmd = [meben, "render", "--run", run, "--out", path, "--seed", str(seed)]
    if stochastic:
        cmd.append("--stochastic")
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if done.returncode != 0:
        said = done.stderr.strip() or "no message"
        refuse(f"{run}: `meben render --seed {seed}` failed with exit status {done.returncode}:\n{said}")
    html = open(path).read()
    marker = html.find("const D = ")
    if marker < 0:
        refuse(f"{run}: the episode `meben render --seed {seed}` wrote holds no player data (const D)")
    start = marker + len("const D = ")
    data, _ = json.JSONDecoder().raw_decode(html[start:])
    agree = nearest = changes = greedy_changes = 0
    prev = prev_greedy = None
    for marks, caption in zip(data["marks"], data["captions"]):
        per_agent = sorted((marks[k : k + 7] for k in range(0, len(marks), 7)), key=lambda m: m[0])
        roots = [m[1:4] for m in per_agent]
        learned = [int(j) for j in re.findall(r"ball (\d+)", caption)]
        # Each agent's mark ends at its ball; the ball positions by index.
        balls = [None] * len(learned)
        for m, j in zip(per_agent, learned):
            balls[j] = m[4:7]
        g = greedy(roots, balls)
        agree += g == learned
        nearest += least_total_distance(roots, balls) == learned
        changes += prev is not None and learned != prev
        greedy_changes += prev_greedy is not None and g != prev_greedy
        prev, prev_greedy = learned, g
    return len(data["captions"]), agree, nearest, changes, greedy_changes


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default="target/release/meben", help="the meben program")
    ap.add_argument("--episodes", type=int, default=8, help="episode seeds 0..N-1")
    ap.add_argument(
        "--sensitivity-episodes", type=int, default=32, help="episodes of the assignment-sensitivity evaluation"
    )
    ap.add_argument("runs", nargs="+", help="run directories with their checkpoints")
    a = ap.parse_args()
    if a.episodes < 1:
        ap.error(f"--episodes {a.episodes}: at least 1")
    if a.sensitivity_episodes < 1:
        ap.error(f"--sensitivity-episodes {a.sensitivity_episodes}: at least 1")
    if not (os.path.isfile(a.bin) and os.access(a.bin, os.X_OK)):
        refuse(f"--bin {a.bin}: not an executable file (build it: cargo build --release -p rl)")
    # Every run is read first, and the tables are printed only once every episode has been
    # rendered: bad input stops with its message and no partial table.
    scorers = [load_scorer(run) for run in a.runs]
    tables = io.StringIO()
    with contextlib.redirect_stdout(tables):
        write_tables(a, scorers)
    sys.stdout.write(tables.getvalue())


def export_policy(meben, run, policy):
    """Writes the run's policy to the file `policy` (`meben export-policy`, which reads the
    checkpoint and writes nothing to the run); None, or what `meben` said when it failed."""
    cmd = [meben, "export-policy", "--run", run, "--out", policy]
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if done.returncode == 0:
        return None
    return f"exit status {done.returncode}:\n{done.stderr.strip() or 'no message'}"


def eval_summary(meben, run, source, args, summary):
    """The summary (JSON) of `meben eval <source> <args> --out <summary>` (`source` the flags
    naming what is evaluated: `--policy <file>` or `--run <dir>`); a failure is refused naming
    `run` (the evaluated run) and the flags `args`."""
    cmd = [meben, "eval"] + source + args + ["--out", summary]
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if done.returncode != 0:
        said = done.stderr.strip() or "no message"
        refuse(f"{run}: `meben eval {' '.join(args)}` failed with exit status {done.returncode}:\n{said}")
    try:
        return json.load(open(summary))
    except (OSError, ValueError) as err:
        refuse(f"{run}: the evaluation summary {summary} is not readable JSON ({err!r})")


def eval_policy(meben, run, policy, args, summary):
    """`eval_summary` of the policy file `policy` (written from `run`)."""
    return eval_summary(meben, run, ["--policy", policy], args, summary)


def policy_sensitivity(meben, run, policy, episodes, summary):
    """The success rate and team 0's `assignment_sensitivity` entry of `meben eval --policy
    <policy> --episodes <episodes> --stochastic --assignment-sensitivity` (its summary
    written to the file `summary`); `run` names the policy's run in a refusal."""
    args = ["--episodes", str(episodes), "--stochastic", "--assignment-sensitivity"]
    e = eval_policy(meben, run, policy, args, summary)
    try:
        s = next(x for x in e["assignment_sensitivity"] if x["team"] == 0)
        return e["success_rate"], s
    except (KeyError, TypeError, StopIteration) as err:
        refuse(f"{run}: the evaluation summary holds no assignment sensitivity of team 0 ({err!r})")


def sensitivity(meben, run, episodes, tmp):
    """The success rate and team 0's `assignment_sensitivity` entry of an evaluation of `run`
    over `episodes` episodes with sampled actions (module doc, table 3)."""
    policy = os.path.join(tmp, "policy.safetensors")
    failed = export_policy(meben, run, policy)
    if failed:
        refuse(f"{run}: `meben export-policy` failed with {failed}")
    return policy_sensitivity(meben, run, policy, episodes, os.path.join(tmp, "eval.json"))


def write_tables(a, scorers):
    """The three tables (module doc) of the runs `a.runs` with their `scorers`, to stdout."""
    distances = [1, 2, 3, 4, 5, 6]
    print(f"Learned scores s(d) = f_θ(d, Δh) - λ d at Δh = {DH} m; P(nearer): a ball's chance")
    print("of picking the nearer of two agents at 2 and 3 m.\n")
    print("| run | λ | " + " | ".join(f"s({d} m)" for d in distances) + " | P(nearer) |")
    print("|---|---:|" + "---:|" * len(distances) + "---:|")
    for run, (layers, prior) in zip(a.runs, scorers):
        s = [score(layers, prior, d, DH) for d in distances]
        p = p_nearer(layers, prior)
        print(f"| `{run}` | {prior:g} | " + " | ".join(f"{v:.2f}" for v in s) + f" | {p:.2f} |")

    print(f"\nOver episode seeds 0-{a.episodes - 1} (`meben render`): the share of steps on which the")
    print("learned assignment is Algorithm 1's and the least-total-distance matching, and changes per")
    print("1000 steps of the learned assignment and of Algorithm 1's.\n")
    print(
        "| run | actions and assignment | steps | learned = Algorithm 1 | learned = least distance "
        "| learned changes /1000 | Algorithm 1 changes /1000 |"
    )
    print("|---|---|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "episode.html")
        for run in a.runs:
            for stochastic in (False, True):
                totals = [0, 0, 0, 0, 0]
                for seed in range(a.episodes):
                    totals = [t + x for t, x in zip(totals, episode(a.bin, run, seed, stochastic, path))]
                steps, agree, nearest, changes, greedy_changes = totals
                mode = "sampled" if stochastic else "most likely (mean actions)"
                print(
                    f"| `{run}` | {mode} | {steps} | {100 * agree / steps:.1f}% | {100 * nearest / steps:.1f}% | "
                    f"{1000 * changes / steps:.1f} | {1000 * greedy_changes / steps:.1f} |"
                )

        n = a.sensitivity_episodes
        print(f"\nHow much the actions depend on the assignment (`meben eval --episodes {n} --stochastic")
        print("--assignment-sensitivity`): per scene-step, KL(π(·|s,σ) ‖ π(·|s,σ')) in nats from the action")
        print("distribution under the assignment acted on, σ, to that under the other one, σ', over the")
        print("steps of every episode and over each episode's first 100 steps.\n")
        print("| run | evaluation | success | scene-steps | KL mean | KL median | KL 90th percentile | KL mean, first 100 steps |")
        print("|---|---|---:|---:|---:|---:|---:|---:|")
        for run in a.runs:
            success, s = sensitivity(a.bin, run, n, tmp)
            print(
                f"| `{run}` | {n} episodes, sampled actions | {100 * success:.1f}% | {s['steps']} | {s['mean_kl']:.2f} | "
                f"{s['median_kl']:.2f} | {s['p90_kl']:.2f} | {s['early_mean_kl']:.2f} |"
            )


if __name__ == "__main__":
    main()
