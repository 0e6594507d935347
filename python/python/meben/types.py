"""The dicts the package returns, as ``TypedDict`` types for annotations and type checkers
(``mypy``, ``pyright``): observations, step info, the scene spec, evaluation and run
summaries. At run time they are plain dicts; these classes only name their keys.

>>> import meben
>>> from meben.types import Observation
>>> env = meben.make("team_reach/1_ant", num_envs=4)
>>> obs: Observation = env.reset()
"""

from typing import List, Optional, Tuple, TypedDict

import numpy as np
from numpy.typing import NDArray

__all__ = ["AssignmentSensitivity", "EvalSummary", "Observation", "RunSummary", "Spec", "StepInfo"]


class Observation(TypedDict):
    """One observation of ``B`` environments (``env.reset()``, ``env.step()``), float32: per
    node, in the world frame, its position, linear and angular velocity (``vectors [B, N, 3,
    3]``), its invariant scalars (``scalars [B, N, S]``), and each agent's heading
    (``heading [B, A]``); docs/TASKS.md gives every entry. The PettingZoo adapter's views
    of one environment have the same keys without the ``B`` axis."""

    vectors: NDArray[np.float32]
    scalars: NDArray[np.float32]
    heading: NDArray[np.float32]


class StepInfo(TypedDict):
    """The ``info`` of ``env.step()``, one entry per environment: the true last observation
    of an episode that ended (``final_obs``), its outcome code (``outcome``, an index into
    ``meben.OUTCOMES``), ``success`` (Team Reach), the winning team or -1 (``win``, Team
    Sumo), ``draw``, the episode's length so far (``episode_len``), and the curriculum
    factor the step used."""

    final_obs: Observation
    outcome: NDArray[np.int8]
    success: NDArray[np.bool_]
    win: NDArray[np.int8]
    draw: NDArray[np.bool_]
    episode_len: NDArray[np.uint32]
    curriculum_alpha: float


class Spec(TypedDict):
    """``env.spec``: what a scene is made of. Node, agent and team indices are positions in
    the observation arrays; ``node_agent``, ``node_team`` and ``node_parent`` are -1 where
    they do not apply (a ball; a root)."""

    name: str
    kind: str
    num_nodes: int
    num_scalars: int
    num_agents: int
    num_teams: int
    num_balls: int
    total_dof: int
    radius: float
    episode_steps: int
    control_dt: float
    agent_morphology: List[str]
    agent_team: List[int]
    agent_dof: List[int]
    agent_action_offset: List[int]
    agent_action_slice: List[Tuple[int, int]]
    agent_root_node: List[int]
    team_agents: List[List[int]]
    entity_root_node: List[int]
    node_agent: List[int]
    node_team: List[int]
    node_parent: List[int]
    node_is_root: List[bool]


class AssignmentSensitivity(TypedDict):
    """How much a team's actions depend on its task assignment (``Policy.evaluate(...,
    assignment_sensitivity=True)``, ``meben eval --assignment-sensitivity``): per
    scene-step, the KL divergence in nats from the action distribution under the
    assignment acted on to that under each other one-to-one assignment."""

    team: int
    steps: int
    alternatives: float
    mean_kl: float
    median_kl: float
    p90_kl: float
    early_mean_kl: float


class _EvalSummaryMeasuredOnRequest(TypedDict, total=False):
    assignment_sensitivity: List[AssignmentSensitivity]


class EvalSummary(_EvalSummaryMeasuredOnRequest):
    """One evaluation (``Policy.evaluate``; ``meben eval``'s ``eval.json``): rates are
    fractions in [0, 1]; ``win_rate`` and ``mean_return`` have one entry per team;
    ``translation`` is ``[x, y]`` in m; ``assignment_sensitivity`` only when asked for."""

    episodes: int
    success_rate: float
    win_rate: List[float]
    draw_rate: float
    mean_return: List[float]
    mean_length: float
    sampled: bool
    rotation_deg: float
    translation: List[float]


class RunSummary(TypedDict):
    """A finished training run (``meben.train``; the run's ``done.json``)."""

    iterations: int
    env_steps: int
    wall_s: float
    final_eval: Optional[EvalSummary]
    final_eval_rotated: List[EvalSummary]
