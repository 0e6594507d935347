"""Gymnasium spaces of a MeBen scene (shared by both adapters)."""

import numpy as np
from gymnasium import spaces

from .types import Spec


def observation_space(spec: Spec) -> spaces.Dict:
    """One environment's observation: ``vectors [N, 3, 3]``, ``scalars [N, S]``, ``heading [A]``."""
    n, s, a = spec["num_nodes"], spec["num_scalars"], spec["num_agents"]
    return spaces.Dict(
        {
            "vectors": spaces.Box(-np.inf, np.inf, (n, 3, 3), np.float32),
            "scalars": spaces.Box(-np.inf, np.inf, (n, s), np.float32),
            "heading": spaces.Box(-np.pi, np.pi, (a,), np.float32),
        }
    )


def action_space(dof: int) -> spaces.Box:
    """``dof`` actions in [-1, 1]."""
    return spaces.Box(-1.0, 1.0, (dof,), np.float32)
