"""A process forked after ``meben`` ran parallel work (multiprocessing's ``fork`` start
method) makes, resets and steps environments like its parent (issue 44, item 1): rayon's
global pool does not survive ``fork``, and such a child used to hang for ever in its first
parallel loop (``meben.make`` of more than one environment); it now runs that work on a pool
of its own (python/src/pool.rs). The policies in a forked child: test_policy.py."""

import numpy as np
import pytest
from conftest import in_forked_child

import meben

# Python 3.12+ warns that forking a multi-threaded process may deadlock: the hazard tested here.
pytestmark = pytest.mark.filterwarnings("ignore:.*multi-threaded.*fork:DeprecationWarning")


def rollout(name, num_envs, seed, steps):
    """Observations and rewards of ``steps`` random steps of fresh environments."""
    env = meben.make(name, num_envs, seed)
    rng = np.random.default_rng(0)
    out = [env.reset()["vectors"]]
    for _ in range(steps):
        obs, reward, *_ = env.step(rng.uniform(-1, 1, (num_envs, env.num_actions)).astype(np.float32))
        out += [obs["vectors"], obs["scalars"], reward]
    return out


def same(a, b):
    return len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b))


@pytest.mark.parametrize("name", ["team_reach/1_ant", "team_sumo/2_ants"])
def test_a_forked_child_steps_environments_as_its_parent(name):
    # The parent's global pool runs (8 environments step in parallel) before the fork.
    parent = rollout(name, 8, 1, 10)
    child = in_forked_child(rollout, name, 8, 1, 10)
    assert same(parent, child)
    # The parent is untouched by its child.
    assert same(rollout(name, 8, 1, 10), parent)


def child_then_grandchild():
    """A forked child that uses its own pool, then forks a grandchild of its own."""
    mine = rollout("team_reach/2_ants", 4, 2, 5)
    return mine, in_forked_child(rollout, "team_reach/2_ants", 4, 2, 5)


def test_a_grandchild_forked_from_a_forked_child_works_too():
    parent = rollout("team_reach/2_ants", 4, 2, 5)
    child, grandchild = in_forked_child(child_then_grandchild)
    assert same(parent, child) and same(parent, grandchild)
