"""PettingZoo adapter (``pip install meben[pettingzoo]``): one MeBen environment as a
``ParallelEnv`` whose agents are ``agent_0 ... agent_{A-1}`` in the scene's order.

Each agent observes the whole scene (``vectors``, ``scalars``, ``heading``) from its team's
view (Team Sumo: the own/opponent entity columns swapped for team 1, as the Rust
``ObsSpec::to_team_view``), acts on its own slice of the action row and gets its team's
reward.
"""

from typing import Any, Dict, List, Optional, Tuple

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray
from pettingzoo import ParallelEnv as _ParallelEnv

from . import OUTCOMES, make
from ._spaces import action_space, observation_space
from .types import Observation


# PettingZoo ships no type information: its ParallelEnv is `Any` to a type checker.
class ParallelEnv(_ParallelEnv):  # type: ignore[misc]
    """One MeBen environment of ``name`` with PettingZoo's parallel API."""

    metadata = {"name": "meben", "render_modes": []}

    def __init__(self, name: str, seed: int = 0, **options: Any) -> None:
        self._name, self._options = name, options
        self._env = make(name, 1, seed, auto_reset=False, **options)
        spec = self._env.spec
        self._spec = spec
        self.possible_agents = [f"agent_{a}" for a in range(spec["num_agents"])]
        self.agents: List[str] = []
        self._slices = dict(zip(self.possible_agents, spec["agent_action_slice"]))
        self._team = dict(zip(self.possible_agents, spec["agent_team"]))
        obs_space = observation_space(spec)
        self.observation_spaces = {a: obs_space for a in self.possible_agents}
        self.action_spaces = {a: action_space(stop - start) for a, (start, stop) in self._slices.items()}
        self._agent_nodes = np.asarray(spec["node_agent"]) >= 0

    def observation_space(self, agent: str) -> spaces.Dict:
        """The observation space of ``agent``."""
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        """The action space of ``agent``."""
        return self.action_spaces[agent]

    def _views(self, obs: Observation) -> Dict[str, Observation]:
        views: Dict[str, Observation] = {}
        for agent in self.agents:
            scalars = obs["scalars"][0]
            if self._team[agent] == 1:
                scalars = scalars.copy()
                scalars[self._agent_nodes, 0:2] = scalars[self._agent_nodes, 1::-1]
            views[agent] = {"vectors": obs["vectors"][0], "scalars": scalars, "heading": obs["heading"][0]}
        return views

    def reset(
        self, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None
    ) -> Tuple[Dict[str, Observation], Dict[str, Dict[str, Any]]]:
        """A new episode; ``seed`` restarts the random stream."""
        if seed is not None:
            self._env = make(self._name, 1, seed, auto_reset=False, **self._options)
        self.agents = list(self.possible_agents)
        return self._views(self._env.reset()), {a: {} for a in self.agents}

    def step(self, actions: Dict[str, NDArray[np.float32]]) -> Tuple[
        Dict[str, Observation], Dict[str, float], Dict[str, bool], Dict[str, bool], Dict[str, Dict[str, Any]]
    ]:
        """One control step with each live agent's action (missing agents act 0)."""
        row = np.zeros((1, self._spec["total_dof"]), np.float32)
        for agent, a in actions.items():
            start, stop = self._slices[agent]
            row[0, start:stop] = a
        obs, reward, terminated, truncated, info = self._env.step(row)
        views = self._views(obs)
        outcome = OUTCOMES[int(info["outcome"][0])]
        rewards = {a: float(reward[0, self._team[a]]) for a in self.agents}
        terms = {a: bool(terminated[0]) for a in self.agents}
        truncs = {a: bool(truncated[0]) for a in self.agents}
        infos: Dict[str, Dict[str, Any]] = {a: {"outcome": outcome} for a in self.agents}
        if terminated[0] or truncated[0]:
            self.agents = []
        return views, rewards, terms, truncs, infos

    def state(self) -> Observation:
        """The whole scene's current observation (team 0's view)."""
        return self._env.observation()
