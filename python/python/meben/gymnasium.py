"""Gymnasium adapters (``pip install meben[gymnasium]``): ``GymVecEnv``, Gymnasium's
vector-env API over the batched core, and ``GymEnv``, one environment as a ``gymnasium.Env``.

Both take the same arguments: the environment ``name``, ``seed=0`` (the environments' random
streams; ``reset(seed=s)`` restarts them from ``s``), ``team=0``, ``flatten=False`` and
``make``'s options; ``GymVecEnv`` also takes ``num_envs``.

The reward is one team's (``team``, default 0; ``info["team_reward"]`` has every team's).
Auto-reset is Gymnasium's ``SAME_STEP`` mode: an ended environment's observation is already
its next episode's first, and ``info["final_obs"]`` (with the mask ``info["_final_obs"]``)
holds the true last observation.

Observations are a ``Dict`` space of ``vectors [N, 3, 3]``, ``scalars [N, S]`` and ``heading
[A]`` (``meben.types.Observation``), or, with ``flatten=True``, one float32 ``Box`` of ``D =
9 N + S N + A`` entries (batched: ``[num_envs, D]``), which the MLP policies of
Stable-Baselines3 (``MlpPolicy``) and CleanRL take as they are. Its layout (``flat_layout``;
N nodes, S = 10 scalars per node, A agents, as in ``env.spec``), row-major::

    [0, 9N)            vectors: node n's position, linear velocity, angular velocity
                       (x, y, z each) at 9n .. 9n + 8
    [9N, 9N + SN)      scalars: node n's S scalars at 9N + S n .. 9N + S n + S - 1
    [9N + SN, D)       heading: agent a's heading at 9N + SN + a

``flatten_obs`` and ``unflatten_obs`` (or the adapters' ``unflatten`` method) convert between
the two, for one environment or a batch, exactly (the same float32 values). The order is not
that of Gymnasium's ``FlattenObservation`` wrapper (which sorts the keys).
"""

from typing import Any, Dict, Mapping, Optional, Tuple

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from . import make
from ._spaces import action_space, observation_space
from .types import Observation, Spec

__all__ = ["OBS_KEYS", "GymEnv", "GymVecEnv", "flat_layout", "flatten_obs", "unflatten_obs"]

# Observations and actions as Gymnasium's spaces type them: its ``Dict`` space is a
# ``Space[dict[str, Space]]``, so an observation (the float32 arrays of ``Observation``) is a
# ``dict[str, Any]`` to a type checker, or one float32 array with ``flatten=True``; its
# ``Box`` holds arrays of any float or int dtype.
Obs = Any
Act = NDArray[Any]

#: The observation's arrays in the order of the flat layout.
OBS_KEYS = ("vectors", "scalars", "heading")


def flat_layout(spec: Spec) -> Dict[str, Tuple[slice, Tuple[int, ...]]]:
    """Where each array of one environment's observation lies in the flat one: ``{key:
    (slice, shape)}`` for ``vectors``, ``scalars`` and ``heading`` in that order (module
    docs); the flat length is the last slice's stop."""
    n, s, a = spec["num_nodes"], spec["num_scalars"], spec["num_agents"]
    shapes = {"vectors": (n, 3, 3), "scalars": (n, s), "heading": (a,)}
    layout: Dict[str, Tuple[slice, Tuple[int, ...]]] = {}
    start = 0
    for key in OBS_KEYS:
        stop = start + int(np.prod(shapes[key]))
        layout[key] = (slice(start, stop), shapes[key])
        start = stop
    return layout


def _real_array(name: str, value: Any) -> NDArray[Any]:
    """``value`` as an array of real numbers (float or integer dtype), else ``ValueError``
    naming ``name`` and the dtype."""
    a = np.asarray(value)
    if a.dtype.kind not in "fiu":
        raise ValueError(f"bad {name} = an array of dtype {a.dtype}: expected real numbers (float32)")
    return a


def _dims(lead: Tuple[int, ...], *rest: Any) -> str:
    """A shape for messages: ``[2, N, 3, 3]``."""
    return "[" + ", ".join(str(d) for d in lead + rest) + "]"


def flatten_obs(obs: Mapping[str, Any]) -> NDArray[np.float32]:
    """An observation dict (one environment's: ``heading [A]``; or a batch's: ``heading [B,
    A]``) as one float32 array ``[D]`` or ``[B, D]`` in the flat layout (module docs). Arrays
    whose leading (batch) shapes or node counts disagree, or that do not hold real numbers,
    raise ``ValueError`` naming the array and the shapes."""
    for key in OBS_KEYS:
        if key not in obs:
            raise ValueError(f"bad obs = a dict without {key!r}: expected the keys vectors, scalars, heading")
    heading = _real_array("obs['heading']", obs["heading"])
    vectors = _real_array("obs['vectors']", obs["vectors"])
    scalars = _real_array("obs['scalars']", obs["scalars"])
    if heading.ndim not in (1, 2):
        raise ValueError(f"bad obs['heading'] = an array of shape {list(heading.shape)}: expected [A] or [B, A]")
    lead = tuple(heading.shape[:-1])
    k = len(lead)
    if vectors.ndim != k + 3 or tuple(vectors.shape[:k]) != lead or tuple(vectors.shape[-2:]) != (3, 3):
        raise ValueError(
            f"bad obs['vectors'] = an array of shape {list(vectors.shape)}: expected {_dims(lead, 'N', 3, 3)} "
            f"(obs['heading'] has shape {list(heading.shape)})"
        )
    n = vectors.shape[-3]
    if scalars.ndim != k + 2 or tuple(scalars.shape[:k]) != lead or scalars.shape[-2] != n:
        raise ValueError(
            f"bad obs['scalars'] = an array of shape {list(scalars.shape)}: expected {_dims(lead, n, 'S')} "
            f"(obs['vectors'] has shape {list(vectors.shape)}, obs['heading'] {list(heading.shape)})"
        )
    parts = [a.astype(np.float32, copy=False).reshape(lead + (-1,)) for a in (vectors, scalars, heading)]
    return np.concatenate(parts, axis=-1)


def unflatten_obs(flat: NDArray[Any], spec: Spec) -> Observation:
    """The observation dict of ``flat`` (``[D]`` or ``[B, D]``, the flat layout of ``spec``'s
    scene): ``flatten_obs`` undone, the same float32 values. Another shape, or an array that
    does not hold real numbers, raises ``ValueError``."""
    x = _real_array("flat", flat).astype(np.float32, copy=False)
    layout = flat_layout(spec)
    d = layout["heading"][0].stop
    if x.ndim not in (1, 2) or x.shape[-1] != d:
        raise ValueError(
            f"bad flat = an array of shape {list(x.shape)}: expected [{d}] or [B, {d}] "
            f"(the flat observation of {spec['name']})"
        )
    lead = x.shape[:-1]
    out = {key: np.ascontiguousarray(x[..., sl].reshape(lead + shape)) for key, (sl, shape) in layout.items()}
    return {"vectors": out["vectors"], "scalars": out["scalars"], "heading": out["heading"]}


def _flat_space(space: spaces.Dict) -> spaces.Box:
    """The flat ``Box`` of one environment's ``Dict`` observation space (bounds in the flat
    layout)."""
    boxes = [space[key] for key in OBS_KEYS]
    low = np.concatenate([np.asarray(b.low, np.float32).ravel() for b in boxes if isinstance(b, spaces.Box)])
    high = np.concatenate([np.asarray(b.high, np.float32).ravel() for b in boxes if isinstance(b, spaces.Box)])
    return spaces.Box(low, high, low.shape, np.float32)


def _check_team(name: str, spec: Spec, team: int) -> None:
    """Raises ``ValueError`` unless ``team`` is an integer index of one of ``spec``'s teams
    (``True`` is not: it used to pass as 1 and fail every step)."""
    if isinstance(team, bool) or not isinstance(team, (int, np.integer)):
        raise ValueError(f"bad team = {team!r}: expected an integer team index (0 ..= {spec['num_teams'] - 1})")
    if not 0 <= team < spec["num_teams"]:
        raise ValueError(f"bad team = {team}: {name} has {spec['num_teams']} team(s)")


def _plain(obs: Observation, row: Optional[int] = None) -> Dict[str, Any]:
    """``obs`` as a plain dict; with ``row``, that environment's arrays only."""
    if row is None:
        return {"vectors": obs["vectors"], "scalars": obs["scalars"], "heading": obs["heading"]}
    return {"vectors": obs["vectors"][row], "scalars": obs["scalars"][row], "heading": obs["heading"][row]}


class GymVecEnv(VectorEnv[Obs, Act, NDArray[Any]]):
    """``num_envs`` MeBen environments of ``name`` with Gymnasium's vector-env API, seeded
    with ``seed``, rewarded as ``team``; ``flatten=True`` gives each environment's
    observation as one flat ``Box`` row (module docs); other keywords are ``meben.make``'s
    options."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(
        self, name: str, num_envs: int = 1, seed: int = 0, team: int = 0, *, flatten: bool = False, **options: Any
    ) -> None:
        self._name, self._options, self._team, self._flatten = name, options, team, flatten
        self._env = make(name, num_envs, seed, **options)
        spec = self._env.spec
        _check_team(name, spec, team)
        self.num_envs = num_envs
        structured = observation_space(spec)
        self.single_observation_space = _flat_space(structured) if flatten else structured
        self.single_action_space = action_space(spec["total_dof"])
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.spec_meben = spec

    def _obs(self, obs: Observation) -> Obs:
        return flatten_obs(obs) if self._flatten else _plain(obs)

    def unflatten(self, flat: NDArray[Any]) -> Observation:
        """A flat observation (``[D]`` or ``[num_envs, D]``) as the observation dict."""
        return unflatten_obs(flat, self.spec_meben)

    def reset(
        self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None
    ) -> Tuple[Obs, Dict[str, Any]]:
        """New episodes everywhere; ``seed`` restarts the environments' random streams."""
        if seed is not None:
            self._env = make(self._name, self.num_envs, seed, **self._options)
        return self._obs(self._env.reset()), {}

    def step(self, actions: Act) -> Tuple[Obs, NDArray[Any], NDArray[Any], NDArray[Any], Dict[str, Any]]:
        """One step of every environment (actions ``[num_envs, total_dof]``)."""
        obs, reward, terminated, truncated, info = self._env.step(np.asarray(actions, np.float32))
        out: Dict[str, Any] = {**info, "team_reward": reward, "_final_obs": terminated | truncated}
        out["final_obs"] = self._obs(info["final_obs"])
        return self._obs(obs), reward[:, self._team].copy(), terminated, truncated, out


class GymEnv(gymnasium.Env[Obs, Act]):
    """One MeBen environment of ``name`` as a ``gymnasium.Env`` (episodes end; ``reset``
    begins the next), seeded with ``seed``, rewarded as ``team``; ``flatten=True`` gives the
    observation as one flat ``Box`` (module docs); other keywords are ``meben.make``'s
    options. The arguments after ``name`` are keywords (as ``GymVecEnv``'s, without
    ``num_envs``)."""

    metadata = {"render_modes": []}

    def __init__(self, name: str, *, seed: int = 0, team: int = 0, flatten: bool = False, **options: Any) -> None:
        self._name, self._options, self._team, self._flatten = name, options, team, flatten
        self._env = make(name, 1, seed, auto_reset=False, **options)
        spec = self._env.spec
        _check_team(name, spec, team)
        self.spec_meben = spec
        structured = observation_space(spec)
        self.observation_space = _flat_space(structured) if flatten else structured
        self.action_space = action_space(spec["total_dof"])

    def _obs(self, obs: Observation) -> Obs:
        return flatten_obs(obs)[0] if self._flatten else _plain(obs, 0)

    def unflatten(self, flat: NDArray[Any]) -> Observation:
        """A flat observation (``[D]``) as the observation dict (without the batch axis)."""
        return unflatten_obs(flat, self.spec_meben)

    def reset(
        self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None
    ) -> Tuple[Obs, Dict[str, Any]]:
        """A new episode; ``seed`` restarts the random stream."""
        super().reset(seed=seed)
        if seed is not None:
            self._env = make(self._name, 1, seed, auto_reset=False, **self._options)
        return self._obs(self._env.reset()), {}

    def step(self, action: Act) -> Tuple[Obs, float, bool, bool, Dict[str, Any]]:
        """One control step with ``action`` (``[total_dof]``)."""
        a = np.asarray(action, np.float32).reshape(1, -1)
        obs, reward, terminated, truncated, info = self._env.step(a)
        out = {"outcome": int(info["outcome"][0]), "team_reward": reward[0]}
        return self._obs(obs), float(reward[0, self._team]), bool(terminated[0]), bool(truncated[0]), out
