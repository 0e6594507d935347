"""Bad input raises a clear exception (naming the argument and the value) and leaves the
environment usable: after the error it steps exactly as a twin that never saw the error."""

import numpy as np
import pytest

import meben

NAME = "team_reach/2_ants"


def twins():
    return meben.make(NAME, num_envs=2, seed=9), meben.make(NAME, num_envs=2, seed=9)


def good(env):
    return np.full((env.num_envs, env.num_actions), 0.3, np.float32)


def nan_actions(env):
    a = good(env)
    a[1, 3] = np.nan
    return a


@pytest.mark.parametrize(
    "make_bad,match",
    [
        (lambda env: np.zeros((env.num_envs, env.num_actions + 1), np.float32), r"bad actions = an array of shape \[2, 17\]: expected shape \[2, 16\]"),
        (lambda env: np.zeros(env.num_envs * env.num_actions, np.float32), r"shape \[32\]"),
        (lambda env: np.zeros((env.num_envs, env.num_actions), np.float64), r"dtype float64|dtype <f8"),
        (lambda env: [[0.0] * env.num_actions] * env.num_envs, r"bad actions = a list: expected a numpy float32 array"),
        (nan_actions, r"actions\[19\] \(environment 1, action 3\) = NaN"),
    ],
)
def test_bad_actions_raise_and_change_nothing(make_bad, match):
    env, twin = twins()
    env.step(good(env))
    twin.step(good(twin))
    with pytest.raises(ValueError, match=match):
        env.step(make_bad(env))
    a, b = env.step(good(env)), twin.step(good(twin))
    for key in ("vectors", "scalars", "heading"):
        assert np.array_equal(a[0][key], b[0][key])
    assert np.array_equal(a[1], b[1])


def test_bad_names_and_arguments():
    with pytest.raises(ValueError, match=r'unknown environment "team_reach/9_ants"; known environments: team_reach/1_ant'):
        meben.make("team_reach/9_ants")
    with pytest.raises(ValueError, match=r'morphology "octopus"'):
        meben.make("team_reach:agents=ant+octopus")
    with pytest.raises(ValueError, match=r"bad num_envs = 0: must be at least 1"):
        meben.make(NAME, num_envs=0)
    # An impossible size is an error, not an aborted interpreter (it used to abort when the
    # allocation failed).
    with pytest.raises(ValueError, match=r"bad num_envs = 1099511627776: must be at most 1048576"):
        meben.make(NAME, num_envs=2**40)
    with pytest.raises(ValueError, match=r"bad num_envs = 1099511627776: must be at most 1048576"):
        meben.make_eval(NAME, num_envs=2**40)
    # Issue 44 item 2: a batch the machine cannot hold (team_sumo/3_ants, about 0.4 MB an
    # environment: some 400 GB) was accepted and the interpreter aborted in the allocator.
    # Refused before anything is allocated, with the estimate and the machine's memory.
    with pytest.raises(ValueError, match=r"bad num_envs = 1048576: 1048576 environments of team_sumo/3_ants at about [0-9.]+ KB each needs about [0-9.]+ GB, more than this (machine's [0-9.]+ GB (available|in all) \((MemAvailable|MemTotal) in /proc/meminfo\)|process's limit: [0-9.]+ GB left)"):
        meben.make("team_sumo/3_ants", num_envs=2**20)
    with pytest.raises(ValueError, match=r"field `episodes` = \"1048576\": 1048576 environments of team_sumo/3_ants at about"):
        meben.make_eval("team_sumo/3_ants", num_envs=2**20)
    with pytest.raises(ValueError, match=r"bad seed = -1"):
        meben.make(NAME, seed=-1)
    # Issue 77: seeds of 2^63 or more raised OverflowError.
    with pytest.raises(ValueError, match=r"bad seed = 9223372036854775808: must be an integer in 0 ..= 9223372036854775807"):
        meben.make(NAME, seed=2**63)
    with pytest.raises(ValueError, match=r"bad seed = 18446744073709551616"):
        meben.make_eval(NAME, num_envs=1, seed=2**64)
    with pytest.raises(ValueError, match=r"bad fixed_start = 9223372036854775808"):
        meben.make(NAME, fixed_start=2**63)
    with pytest.raises(ValueError, match=r"bad seed = 18446744073709551616: must be an integer in 0 ..= 18446744073709551615"):
        meben.Policy.pretrained("team_reach/1_ant", "shnn", seed=2**64)
    # Issue 77 item 9: thousands of agents aborted the interpreter while the scene's
    # collision pairs were built; refused before building, naming the count.
    with pytest.raises(ValueError, match=r'bad agents "3000": at most 256 agents in a scene'):
        meben.make("team_reach:agents=" + "+".join(["ant"] * 3000) + ";balls=1")
    # Issue 77: an empty path loaded the working directory as a run.
    with pytest.raises(ValueError, match=r"bad run = '': expected a run directory or a policy file"):
        meben.Policy.load("")
    with pytest.raises(ValueError, match=r"bad path = .*expected a file name ending in .html, .gif or .csv"):
        meben.make(NAME, record=True).render("episode.mp4")


def test_malformed_morphology_file(tmp_path):
    bad = tmp_path / "broken.txt"
    bad.write_text("bodies { name: 'torso' colliders { capsule { radius: oops")
    with pytest.raises(ValueError, match=r"morphology \".*broken.txt\""):
        meben.make(f"team_reach:agents={bad}")
    # Nothing is left broken: other environments still build and step.
    env = meben.make(NAME, num_envs=1)
    env.step(good(env))
