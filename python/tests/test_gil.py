"""Stepping releases the GIL: another Python thread runs while a batch steps; an env or policy
that another thread is using raises an error that says so."""

import sys
import threading

import numpy as np

import meben


def test_another_thread_runs_while_environments_step():
    env = meben.make("team_reach/3_ant_claw_centipede", num_envs=512, seed=0)
    env.reset()
    actions = np.zeros((env.num_envs, env.num_actions), np.float32)
    env.step(actions)  # warm up
    counts = {"during": 0}
    stepping = threading.Event()
    done = threading.Event()

    def count():
        stepping.wait()
        while not done.is_set():
            counts["during"] += 1

    old = sys.getswitchinterval()
    sys.setswitchinterval(1e-4)
    try:
        t = threading.Thread(target=count)
        t.start()
        stepping.set()
        for _ in range(5):
            env.step(actions)
        done.set()
        t.join()
    finally:
        sys.setswitchinterval(old)
    # With the GIL held through each step the counter could only move in the moments
    # between steps (a few 0.1 ms switch intervals); released, it runs for the whole of
    # the steps (measured here: about 3.0M increments over the five steps).
    assert counts["during"] > 100_000, counts


def test_an_env_used_by_two_threads_says_so():
    # Environments are one thread's each: a step while another thread steps the same env
    # raises a RuntimeError that says so (it used to be PyO3's bare "Already borrowed"),
    # and changes nothing: the env has stepped exactly as often as the steps that returned.
    env = meben.make("team_reach/2_ants", num_envs=256, seed=0)
    twin = meben.make("team_reach/2_ants", num_envs=256, seed=0)
    actions = np.full((env.num_envs, env.num_actions), 0.2, np.float32)
    steps = {"other": 0, "main": 0}  # one counter per thread: no lost updates
    errors, done = [], threading.Event()

    def step_some():
        # Either thread can be the one refused: this one retries until 20 of its steps ran.
        try:
            while steps["other"] < 20:
                try:
                    env.step(actions)
                    steps["other"] += 1
                except RuntimeError as e:
                    errors.append(str(e))
        finally:
            done.set()

    old = sys.getswitchinterval()
    sys.setswitchinterval(1e-4)
    try:
        t = threading.Thread(target=step_some)
        t.start()
        while not done.is_set():
            try:
                env.step(actions)
                steps["main"] += 1
            except RuntimeError as e:
                errors.append(str(e))
                # What does not change with steps is still readable meanwhile.
                assert env.num_envs == 256 and repr(env).startswith("VecEnv(")
        t.join()
    finally:
        sys.setswitchinterval(old)
    assert errors, "the two threads never met"
    assert all("in use by another thread" in e and "each thread needs its own env" in e for e in errors), errors
    assert steps["other"] == 20
    for _ in range(steps["other"] + steps["main"]):
        expected, *_ = twin.step(actions)
    assert np.array_equal(env.observation()["vectors"], expected["vectors"])
