"""A random policy, then a trained one, each stepping 256 environments of Team Reach for one
episode, printing success rates; then the same evaluation in one call (``Policy.evaluate``)
and the run's learning curve (``meben.read_metrics``).

    python python/examples/success_rates.py [RUN_DIR]

RUN_DIR is a run directory the ``meben`` program (or ``meben.train``) wrote, e.g.
``runs/team_reach_1_ant-shnn-seed0`` after ``cargo run --release``. Without it, the example
trains a tiny run (a few seconds; it will not have learned much) into target/example_run.
"""

import sys
from typing import Callable

import numpy as np
from numpy.typing import NDArray

import meben
from meben.types import Observation


def success_rate(env: meben.VecEnv, act: Callable[[Observation], NDArray[np.float32]]) -> float:
    """Plays one episode in every environment with ``act(obs)``; the fraction that succeeded."""
    obs = env.observation()
    alive = np.ones(env.num_envs, bool)
    success = np.zeros(env.num_envs, bool)
    while alive.any():
        obs, _, terminated, truncated, info = env.step(act(obs))
        success |= alive & info["success"]
        alive &= ~(terminated | truncated)
    return float(success.mean())


def main() -> None:
    run = sys.argv[1] if len(sys.argv) > 1 else None
    if run is None:
        run = "target/example_run"
        meben.train(
            out=run,
            env="team_reach/1_ant",
            model="mlp_hn",
            steps=160,
            num_envs=8,
            batch_size=4,
            num_minibatches=4,
            epochs=1,
            num_evals=1,
            eval_episodes=2,
        )
    policy = meben.Policy.load(run)
    rng = np.random.default_rng(0)
    env = meben.make_eval(policy.env, 256, seed=1)
    rate = success_rate(env, lambda obs: rng.uniform(-1, 1, (env.num_envs, env.num_actions)).astype(np.float32))
    print(f"{policy.env}: random policy success rate {rate:.3f}")
    env = meben.make_eval(policy.env, 256, seed=1)
    rate = success_rate(env, lambda obs: policy.act(obs, deterministic=True))
    print(f"{policy.env}: trained {policy.model} ({run}) success rate {rate:.3f}")
    # The same evaluation in one call (meben eval's, on the same starts with the same actions).
    summary = policy.evaluate(episodes=256, seed=1, deterministic=True)
    print(f"{policy.env}: policy.evaluate success rate {summary['success_rate']:.3f}")
    # The run's learning curve, from its metrics.csv.
    metrics = meben.read_metrics(run)
    evaluated = ~np.isnan(metrics["eval_success_rate"])
    for steps, rate in zip(metrics["env_steps"][evaluated], metrics["eval_success_rate"][evaluated]):
        print(f"  after {steps:.0f} env steps: evaluation success rate {rate:.3f}")


if __name__ == "__main__":
    main()
