"""Stepping releases the GIL: another Python thread runs while a batch steps."""

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
