"""Random-action stepping in Brax on this CPU: the figure a Brax user compares with
``python python/bench.py`` (MeBen from Python) and ``cargo bench -p envs --bench tasks``.

Brax's own ``ant`` (MeBen's scenes are not part of Brax; its ant is the morphology of
``team_reach/1_ant``, without the goal ball), 256 environments stepped together by
``jit(vmap(env.step))``, uniform random actions from a pool of 16 batches, cycled; compile
and 10 warm-up steps first, then ``STEPS`` (default 200) steps timed, ``ROUNDS`` (default 3)
times; the median is printed with every round:

    python3 -m venv /tmp/brax-venv && /tmp/brax-venv/bin/pip install brax
    /tmp/brax-venv/bin/python python/bench_brax.py          # BACKENDS=generalized,positional,spring

Needs only ``brax`` (and its ``jax``), not the ``meben`` package.
"""

import os
import statistics
import time

import jax
import jax.numpy as jnp
from brax import envs


def rate(backend, nenv, steps):
    """Env steps per second of one timed round of ``backend``'s ant."""
    env = envs.get_environment("ant", backend=backend)
    step = jax.jit(jax.vmap(env.step))
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), nenv))
    keys = jax.random.split(jax.random.PRNGKey(1), 16)
    pool = [jax.random.uniform(k, (nenv, env.action_size), minval=-1.0, maxval=1.0) for k in keys]
    for a in pool[:10]:
        state = step(state, a)
    jax.block_until_ready(state.obs)
    t = time.perf_counter()
    for s in range(steps):
        state = step(state, pool[s % len(pool)])
    jax.block_until_ready(state.obs)
    return nenv * steps / (time.perf_counter() - t)


def main():
    nenv = int(os.environ.get("NENV", 256))
    steps = int(os.environ.get("STEPS", 200))
    rounds = int(os.environ.get("ROUNDS", 3))
    for backend in os.environ.get("BACKENDS", "generalized,positional,spring").split(","):
        rates = [rate(backend, nenv, steps) for _ in range(rounds)]
        shown = " ".join(f"{r:.0f}" for r in rates)
        print(
            f"brax/ant backend={backend} env_steps_per_s={statistics.median(rates):.0f} "
            f"rounds=[{shown}] envs={nenv} steps={steps} jax={jax.__version__} devices={jax.devices()[0].platform}"
        )


if __name__ == "__main__":
    main()
