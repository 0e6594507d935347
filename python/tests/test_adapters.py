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


def test_gymnasium_adapters_take_the_same_seed_argument():
    optional_module("gymnasium")
    from meben.gymnasium import GymEnv, GymVecEnv

    # GymEnv("...", seed=0) used to raise "make() got multiple values for argument 'seed'".
    single = GymEnv("team_reach/1_ant", seed=4)
    vector = GymVecEnv("team_reach/1_ant", num_envs=2, seed=4)
    obs, _ = single.reset()
    batch, _ = vector.reset()
    # Environment 0's random stream depends on the seed only: the same first episode.
    for key in ("vectors", "scalars", "heading"):
        assert np.array_equal(obs[key], batch[key][0])
    again, _ = GymEnv("team_reach/1_ant").reset(seed=4)
    other, _ = GymEnv("team_reach/1_ant", seed=5).reset()
    assert np.array_equal(obs["vectors"], again["vectors"])
    assert not np.array_equal(obs["vectors"], other["vectors"])
    with pytest.raises(ValueError, match="bad team = 1"):
        GymEnv("team_reach/1_ant", seed=0, team=1)


@pytest.mark.filterwarnings("ignore:.*Box observation space (minimum|maximum) value is:UserWarning")
@pytest.mark.parametrize("name", ["team_reach/1_ant", "team_sumo/2_ants"])
def test_flat_observations_pass_check_env_and_round_trip(name):
    gymnasium = optional_module("gymnasium")
    from gymnasium.utils.env_checker import check_env

    from meben.gymnasium import GymEnv, flat_layout, flatten_obs, unflatten_obs

    flat_env = GymEnv(name, seed=1, flatten=True)
    check_env(flat_env, skip_render_check=True)
    spec = flat_env.spec_meben
    n, s, a = spec["num_nodes"], spec["num_scalars"], spec["num_agents"]
    d = 9 * n + s * n + a
    # One flat float32 Box: what the MLP policies of SB3 and CleanRL take (the Dict space's
    # vectors [N, 3, 3] looked like an image to SB3, which put a CNN on it).
    space = flat_env.observation_space
    assert isinstance(space, gymnasium.spaces.Box) and space.shape == (d,) and space.dtype == np.float32
    layout = flat_layout(spec)
    assert [(k, sl.start, sl.stop) for k, (sl, _) in layout.items()] == [
        ("vectors", 0, 9 * n),
        ("scalars", 9 * n, 9 * n + s * n),
        ("heading", 9 * n + s * n, d),
    ]
    # The flat twin of a structured environment sees the same values in the documented layout.
    structured = GymEnv(name, seed=1)
    flat, _ = flat_env.reset(seed=2)
    obs, _ = structured.reset(seed=2)
    rng = np.random.default_rng(0)
    for _ in range(5):
        assert flat.shape == (d,) and flat.dtype == np.float32 and space.contains(flat)
        assert np.array_equal(flat, flatten_obs(obs))
        back = flat_env.unflatten(flat)
        for key in ("vectors", "scalars", "heading"):
            assert back[key].shape == obs[key].shape and np.array_equal(back[key], obs[key])
            sl, shape = layout[key]
            assert np.array_equal(flat[sl].reshape(shape), obs[key])
        # Node 1's linear velocity is at 9 + 3 .. 9 + 5; agent 0's heading right after the scalars.
        assert np.array_equal(flat[12:15], obs["vectors"][1, 1]) and flat[9 * n + s * n] == obs["heading"][0]
        action = rng.uniform(-1, 1, flat_env.action_space.shape).astype(np.float32)
        flat, reward, *_ = flat_env.step(action)
        obs, reward_s, *_ = structured.step(action)
        assert reward == reward_s
    with pytest.raises(ValueError, match=rf"bad flat = an array of shape \[{d + 1}\]: expected \[{d}\] or \[B, {d}\]"):
        unflatten_obs(np.zeros(d + 1, np.float32), spec)


def test_flat_vector_env_round_trips_every_row():
    gymnasium = optional_module("gymnasium")
    from meben.gymnasium import GymVecEnv, flatten_obs, unflatten_obs

    flat_env = GymVecEnv("team_reach/2_ants", num_envs=3, seed=7, flatten=True)
    structured = GymVecEnv("team_reach/2_ants", num_envs=3, seed=7)
    assert isinstance(flat_env.single_observation_space, gymnasium.spaces.Box)
    d = flat_env.single_observation_space.shape[0]
    assert flat_env.observation_space.shape == (3, d)
    flat, _ = flat_env.reset()
    obs, _ = structured.reset()
    actions = np.full((3, structured.single_action_space.shape[0]), 0.3, np.float32)
    for _ in range(3):
        assert flat_env.observation_space.contains(flat) and np.array_equal(flat, flatten_obs(obs))
        back = unflatten_obs(flat, flat_env.spec_meben)
        for key in ("vectors", "scalars", "heading"):
            assert np.array_equal(back[key], obs[key])
        flat, _, _, _, info = flat_env.step(actions)
        obs, _, _, _, info_s = structured.step(actions)
        # The true last observations are flat too.
        assert info["final_obs"].shape == (3, d) and np.array_equal(info["final_obs"], flatten_obs(info_s["final_obs"]))


def test_flatten_obs_refuses_mismatched_batches_and_dtypes():
    # Issue 77 item 13: a [1, ...] vectors array with [2, ...] scalars gave shape (2, 292)
    # where the flat length is 382 (rows of the wrong environments); now every array's leading
    # shape and dtype is checked, naming the array and the shapes.
    optional_module("gymnasium")
    import meben
    from meben.gymnasium import flatten_obs, unflatten_obs

    env = meben.make("team_reach/2_ants", num_envs=2, seed=3)
    obs = env.reset()
    d = flatten_obs(obs).shape[-1]
    assert flatten_obs(obs).shape == (2, d)
    bad = dict(obs, vectors=obs["vectors"][:1])
    with pytest.raises(ValueError, match=r"bad obs\['vectors'\] = an array of shape \[1, \d+, 3, 3\]: expected \[2, N, 3, 3\] \(obs\['heading'\] has shape \[2, 2\]\)"):
        flatten_obs(bad)
    bad = dict(obs, scalars=obs["scalars"][:, :-1])
    with pytest.raises(ValueError, match=r"bad obs\['scalars'\] = an array of shape \[2, \d+, \d+\]: expected \[2, \d+, S\]"):
        flatten_obs(bad)
    with pytest.raises(ValueError, match=r"bad obs\['heading'\] = an array of dtype <U1: expected real numbers"):
        flatten_obs(dict(obs, heading=np.array([["a", "b"], ["c", "d"]])))
    with pytest.raises(ValueError, match=r"bad obs = a dict without 'heading'"):
        flatten_obs({"vectors": obs["vectors"], "scalars": obs["scalars"]})
    with pytest.raises(ValueError, match=rf"bad flat = an array of shape \[1, 2, {d}\]: expected \[{d}\] or \[B, {d}\]"):
        unflatten_obs(np.zeros((1, 2, d), np.float32), env.spec)
    with pytest.raises(ValueError, match=r"bad flat = an array of dtype complex64: expected real numbers"):
        unflatten_obs(np.zeros(d, np.complex64), env.spec)


def test_a_boolean_team_is_refused_at_construction():
    # Issue 77: GymEnv(..., team=True) built (True passed as team 1) and then failed every step.
    optional_module("gymnasium")
    from meben.gymnasium import GymEnv, GymVecEnv

    with pytest.raises(ValueError, match=r"bad team = True: expected an integer team index \(0 ..= 1\)"):
        GymEnv("team_sumo/2_ants", team=True)
    with pytest.raises(ValueError, match=r"bad team = True"):
        GymVecEnv("team_sumo/2_ants", team=True)
    with pytest.raises(ValueError, match=r"bad team = 1.0"):
        GymEnv("team_sumo/2_ants", team=1.0)
    GymEnv("team_sumo/2_ants", team=1)
