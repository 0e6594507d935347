"""Gymnasium adapters (``pip install meben[gymnasium]``): ``GymVecEnv``, Gymnasium's
vector-env API over the batched core, and ``GymEnv``, one environment as a ``gymnasium.Env``.

The reward is one team's (``team``, default 0; ``info["team_reward"]`` has every team's).
Auto-reset is Gymnasium's ``SAME_STEP`` mode: an ended environment's observation is already
its next episode's first, and ``info["final_obs"]`` (with the mask ``info["_final_obs"]``)
holds the true last observation.
"""

from typing import Any, Dict, Optional, Tuple

import gymnasium
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from . import make
from ._spaces import action_space, observation_space
from .types import Observation

# Observations and actions as Gymnasium's spaces type them: its ``Dict`` space is a
# ``Space[dict[str, Space]]``, so an observation (the float32 arrays of ``Observation``) is a
# ``dict[str, Any]`` to a type checker; its ``Box`` holds arrays of any float or int dtype.
Obs = Dict[str, Any]
Act = NDArray[Any]


def _plain(obs: Observation, row: Optional[int] = None) -> Obs:
    """``obs`` as a plain dict; with ``row``, that environment's arrays only."""
    if row is None:
        return {"vectors": obs["vectors"], "scalars": obs["scalars"], "heading": obs["heading"]}
    return {"vectors": obs["vectors"][row], "scalars": obs["scalars"][row], "heading": obs["heading"][row]}


class GymVecEnv(VectorEnv[Obs, Act, NDArray[Any]]):
    """``num_envs`` MeBen environments of ``name`` with Gymnasium's vector-env API."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, name: str, num_envs: int = 1, seed: int = 0, team: int = 0, **options: Any) -> None:
        self._name, self._options, self._team = name, options, team
        self._env = make(name, num_envs, seed, **options)
        spec = self._env.spec
        if not 0 <= team < spec["num_teams"]:
            raise ValueError(f"bad team = {team}: {name} has {spec['num_teams']} team(s)")
        self.num_envs = num_envs
        self.single_observation_space = observation_space(spec)
        self.single_action_space = action_space(spec["total_dof"])
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.spec_meben = spec

    def reset(
        self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None
    ) -> Tuple[Obs, Dict[str, Any]]:
        """New episodes everywhere; ``seed`` restarts the environments' random streams."""
        if seed is not None:
            self._env = make(self._name, self.num_envs, seed, **self._options)
        return _plain(self._env.reset()), {}

    def step(self, actions: Act) -> Tuple[Obs, NDArray[Any], NDArray[Any], NDArray[Any], Dict[str, Any]]:
        """One step of every environment (actions ``[num_envs, total_dof]``)."""
        obs, reward, terminated, truncated, info = self._env.step(np.asarray(actions, np.float32))
        out: Dict[str, Any] = {**info, "team_reward": reward, "_final_obs": terminated | truncated}
        return _plain(obs), reward[:, self._team].copy(), terminated, truncated, out


class GymEnv(gymnasium.Env[Obs, Act]):
    """One MeBen environment as a ``gymnasium.Env`` (episodes end; ``reset`` begins the next)."""

    metadata = {"render_modes": []}

    def __init__(self, name: str, team: int = 0, **options: Any) -> None:
        self._name, self._options, self._team = name, options, team
        self._env = make(name, 1, 0, auto_reset=False, **options)
        spec = self._env.spec
        if not 0 <= team < spec["num_teams"]:
            raise ValueError(f"bad team = {team}: {name} has {spec['num_teams']} team(s)")
        self.observation_space = observation_space(spec)
        self.action_space = action_space(spec["total_dof"])

    def reset(
        self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None
    ) -> Tuple[Obs, Dict[str, Any]]:
        """A new episode; ``seed`` restarts the random stream."""
        super().reset(seed=seed)
        if seed is not None:
            self._env = make(self._name, 1, seed, auto_reset=False, **self._options)
        return _plain(self._env.reset(), 0), {}

    def step(self, action: Act) -> Tuple[Obs, float, bool, bool, Dict[str, Any]]:
        """One control step with ``action`` (``[total_dof]``)."""
        a = np.asarray(action, np.float32).reshape(1, -1)
        obs, reward, terminated, truncated, info = self._env.step(a)
        out = {"outcome": int(info["outcome"][0]), "team_reward": reward[0]}
        return _plain(obs, 0), float(reward[0, self._team]), bool(terminated[0]), bool(truncated[0]), out
