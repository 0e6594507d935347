"""The Gymnasium and PettingZoo adapters pass the checks those packages ship (skipped only
where the packages are not installed, and never under ./test.sh, which installs them and
requires them: conftest.optional_module)."""

import numpy as np
import pytest
from conftest import optional_module


# The observations (positions, velocities) are unbounded by nature, so the spaces' bounds
# are infinite, which check_env reports as a warning, not an error.
@pytest.mark.filterwarnings("ignore:.*Box observation space (minimum|maximum) value is:UserWarning")
def test_gymnasium_single_env_passes_check_env():
    gymnasium = optional_module("gymnasium")
    from gymnasium.utils.env_checker import check_env

    from meben.gymnasium import GymEnv

    env = GymEnv("team_reach/1_ant")
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=1)
    assert env.observation_space.contains(obs)
    assert isinstance(gymnasium.Env, type)


def test_gymnasium_vector_env_follows_the_vector_api():
    gymnasium = optional_module("gymnasium")
    from gymnasium.utils.env_checker import data_equivalence

    from meben.gymnasium import GymVecEnv

    env = GymVecEnv("team_sumo/2_ants", num_envs=4, team=1)
    assert isinstance(env, gymnasium.vector.VectorEnv)
    obs, info = env.reset(seed=3)
    again, _ = env.reset(seed=3)
    assert data_equivalence(obs, again, exact=True)
    assert env.observation_space.contains(obs)
    env.action_space.seed(0)
    for _ in range(3):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        assert reward.shape == (4,) and np.array_equal(reward, info["team_reward"][:, 1])
        assert terminated.shape == truncated.shape == info["_final_obs"].shape == (4,)
    with pytest.raises(ValueError, match="bad team = 2"):
        GymVecEnv("team_sumo/2_ants", team=2)


@pytest.mark.parametrize("name", ["team_reach/2_ants", "team_sumo/2_ants"])
def test_pettingzoo_parallel_env_passes_parallel_api_test(name):
    optional_module("pettingzoo")
    from pettingzoo.test import parallel_api_test

    from meben.pettingzoo import ParallelEnv

    env = ParallelEnv(name)
    parallel_api_test(env, num_cycles=1000)
    obs, _ = env.reset(seed=2)
    assert set(obs) == set(env.possible_agents)
    if name.startswith("team_sumo"):
        # Team 1 sees the scene from its side: own and opponent columns swapped.
        a0, a2 = obs["agent_0"]["scalars"], obs["agent_2"]["scalars"]
        root0 = env._spec["agent_root_node"][0]
        assert a0[root0, 0] == 1 and a2[root0, 1] == 1
