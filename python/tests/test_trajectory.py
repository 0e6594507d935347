"""The same trajectory from Python and from Rust for a fixed action sequence, bit for bit:
the Rust example `replay_actions` replays the actions this test writes and dumps every array
the Rust VecEnv returned."""

import subprocess

import numpy as np
import pytest

import meben


def flat_obs(obs):
    return [obs["vectors"].ravel(), obs["scalars"].ravel(), obs["heading"].ravel()]


@pytest.mark.parametrize("name", ["team_reach/2_ants", "team_sumo/2_ant_claw", "team_reach:agents=ant+claw;R=2;balls=1"])
def test_python_and_rust_trajectories_are_bit_identical(tmp_path, replay_actions, name):
    num_envs, seed, steps = 3, 11, 40
    env = meben.make(name, num_envs=num_envs, seed=seed)
    rng = np.random.default_rng(1)
    # Beyond [-1, 1] too: both sides clip.
    actions = rng.uniform(-1.5, 1.5, (steps, num_envs, env.num_actions)).astype(np.float32)
    trace = flat_obs(env.reset())
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        trace += flat_obs(obs) + [reward.ravel()] + flat_obs(info["final_obs"])
        trace += [terminated.astype(np.float32), truncated.astype(np.float32)]
    python = np.concatenate(trace).astype("<f4")
    (tmp_path / "actions.bin").write_bytes(actions.astype("<f4").tobytes())
    subprocess.run(
        [replay_actions, name, str(num_envs), str(seed), tmp_path / "actions.bin", tmp_path / "rust.bin"],
        check=True,
    )
    rust = np.frombuffer((tmp_path / "rust.bin").read_bytes(), "<f4")
    assert rust.shape == python.shape
    # Bit for bit: the float32 words compared as integers (NaN-safe, -0.0 != 0.0).
    assert np.array_equal(rust.view("<u4"), python.view("<u4"))
