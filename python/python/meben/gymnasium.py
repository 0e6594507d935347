"""Gymnasium adapters (``pip install meben[gymnasium]``): ``GymVecEnv``, Gymnasium's
vector-env API over the batched core, and ``GymEnv``, one environment as a ``gymnasium.Env``.

The reward is one team's (``team``, default 0; ``info["team_reward"]`` has every team's).
Auto-reset is Gymnasium's ``SAME_STEP`` mode: an ended environment's observation is already
its next episode's first, and ``info["final_obs"]`` (with the mask ``info["_final_obs"]``)
holds the true last observation.
"""

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from . import make
from ._spaces import action_space, observation_space


class GymVecEnv(VectorEnv):
    """``num_envs`` MeBen environments of ``name`` with Gymnasium's vector-env API."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, name, num_envs=1, seed=0, team=0, **options):
        self._name, self._options, self._team = name, options, team
        self._env = make(name, num_envs, seed, **options)
        spec = self._env.spec
        if not 0 <= team < spec["num_teams"]:
            raise ValueError(f"bad team = {team}: {name} has {spec['num_teams']} team(s)")
        self.num_envs = num_envs
        self.single_observation_space = observation_space(spec, spaces)
        self.single_action_space = action_space(spec["total_dof"], spaces)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.spec_meben = spec

    def reset(self, *, seed=None, options=None):
        """New episodes everywhere; ``seed`` restarts the environments' random streams."""
        if seed is not None:
            self._env = make(self._name, self.num_envs, seed, **self._options)
        return self._env.reset(), {}

    def step(self, actions):
        """One step of every environment (actions ``[num_envs, total_dof]``)."""
        obs, reward, terminated, truncated, info = self._env.step(np.asarray(actions, np.float32))
        info = dict(info, team_reward=reward, _final_obs=terminated | truncated)
        return obs, reward[:, self._team].copy(), terminated, truncated, info


class GymEnv(gymnasium.Env):
    """One MeBen environment as a ``gymnasium.Env`` (episodes end; ``reset`` begins the next)."""

    metadata = {"render_modes": []}

    def __init__(self, name, team=0, **options):
        self._name, self._options, self._team = name, options, team
        self._env = make(name, 1, 0, auto_reset=False, **options)
        spec = self._env.spec
        if not 0 <= team < spec["num_teams"]:
            raise ValueError(f"bad team = {team}: {name} has {spec['num_teams']} team(s)")
        self.observation_space = observation_space(spec, spaces)
        self.action_space = action_space(spec["total_dof"], spaces)

    @staticmethod
    def _row(obs):
        return {k: v[0] for k, v in obs.items()}

    def reset(self, *, seed=None, options=None):
        """A new episode; ``seed`` restarts the random stream."""
        super().reset(seed=seed)
        if seed is not None:
            self._env = make(self._name, 1, seed, auto_reset=False, **self._options)
        return self._row(self._env.reset()), {}

    def step(self, action):
        """One control step with ``action`` (``[total_dof]``)."""
        a = np.asarray(action, np.float32).reshape(1, -1)
        obs, reward, terminated, truncated, info = self._env.step(a)
        info = {"outcome": int(info["outcome"][0]), "team_reward": reward[0]}
        return self._row(obs), float(reward[0, self._team]), bool(terminated[0]), bool(truncated[0]), info
