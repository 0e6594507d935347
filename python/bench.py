"""Env steps per second from Python against the Rust benchmark, on the three environments of
``cargo bench -p envs --bench tasks`` at 256 environments with uniform random actions (a
pool of 16 action batches, cycled; 10 warm-up steps), one line each with the ratio.

    python python/bench.py            # STEPS=200 NENV=256 by default, as the Rust bench

``ROUNDS`` (default 3) rounds alternate the Rust bench and the Python steps (a shared
machine's load moves between runs); the medians give the ratio, every round is printed.
Brax's own figure on this CPU: ``python/bench_brax.py``.

Run from the repository with the package installed (./test.sh installs it into
target/pyenv). The Python figure includes building the observation, reward and info arrays.
"""

import os
import re
import statistics
import subprocess
import sys
import time

import numpy as np

import meben

ENVS = ["team_reach/1_ant", "team_reach/3_ant_claw_centipede", "team_sumo/2_ants"]


def python_rate(name, nenv, steps):
    """Env steps per second of ``env.step`` from Python."""
    env = meben.make(name, num_envs=nenv, seed=0)
    rng = np.random.default_rng(1)
    pool = [rng.uniform(-1, 1, (nenv, env.num_actions)).astype(np.float32) for _ in range(16)]
    for a in pool[:10]:
        env.step(a)
    t = time.perf_counter()
    for s in range(steps):
        env.step(pool[s % len(pool)])
    return nenv * steps / (time.perf_counter() - t)


def rust_rates(nenv, steps):
    """Env steps per second of the Rust benchmark, by environment name."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, NENV=str(nenv), STEPS=str(steps), ENVS=",".join(ENVS))
    out = subprocess.run(
        ["cargo", "bench", "-q", "-p", "envs", "--bench", "tasks"], cwd=root, env=env, check=True,
        capture_output=True, text=True,
    ).stdout
    return {m[1]: float(m[2]) for m in re.finditer(r"^(\S+) env_steps_per_s=([0-9.]+)", out, re.M)}


def main():
    nenv, steps = int(os.environ.get("NENV", 256)), int(os.environ.get("STEPS", 200))
    rounds = int(os.environ.get("ROUNDS", 3))
    rust = {name: [] for name in ENVS}
    py = {name: [] for name in ENVS}
    for _ in range(rounds):
        measured = rust_rates(nenv, steps)
        for name in ENVS:
            if name not in measured:
                sys.exit(f"error: the Rust bench printed no line for {name}")
            rust[name].append(measured[name])
            py[name].append(python_rate(name, nenv, steps))
    for name in ENVS:
        p, r = statistics.median(py[name]), statistics.median(rust[name])
        print(
            f"{name} python_env_steps_per_s={p:.0f} rust_env_steps_per_s={r:.0f} ratio={p / r:.3f} "
            f"python_rounds=[{' '.join(f'{x:.0f}' for x in py[name])}] "
            f"rust_rounds=[{' '.join(f'{x:.0f}' for x in rust[name])}] envs={nenv} steps={steps}"
        )


if __name__ == "__main__":
    main()
