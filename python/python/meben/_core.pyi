# Types of the Rust extension module (python/src/*.rs), for type checkers; the docstrings
# are the Rust ones, at run time. python/tests/test_typing.py checks this file against the
# built module (mypy's stubtest) and type-checks the example with it.
import os
import pathlib
from typing import Dict, List, Optional, Sequence, Tuple, Union, final

import numpy as np
from numpy.typing import NDArray

from meben.types import EvalSummary, Observation, Spec, StepInfo

__all__ = ["BUILD_COMMIT", "BUILTIN_NAMES", "OUTCOMES", "Policy", "VecEnv", "__version__", "read_metrics", "train"]

_Path = Union[str, "os.PathLike[str]"]

__version__: str
BUILD_COMMIT: str
BUILTIN_NAMES: List[str]
OUTCOMES: Tuple[str, ...]

@final
class VecEnv:
    """Batched MeBen environments (see ``meben.make``). One thread's at a time: a call while
    another thread is stepping or resetting it raises ``RuntimeError``."""

    def __new__(
        cls,
        name: str,
        num_envs: int = 1,
        seed: int = 0,
        *,
        auto_reset: bool = True,
        fixed_start: Optional[int] = None,
        rotation_deg: float = 0.0,
        point: Tuple[float, float] = ...,  # (0.0, 0.0)
        record: bool = False,
    ) -> VecEnv:
        """``num_envs`` environments of ``name`` seeded with ``seed`` (``meben.make``).

        ``auto_reset=True``: an ended environment begins its next episode in the same step.
        ``auto_reset=False``: it is not reset, nor frozen: each later ``step`` goes on
        simulating the same scene from where it ended, with the new actions,
        ``episode_len`` counting past the end, and judges it afresh as during the episode:
        Team Reach pays the success bonus again (outcome success, ``terminated``) at every
        step on which the balls are still covered, Team Sumo's win or draw is judged on each
        new state, after the time limit every step not terminated is ``truncated`` (outcome
        time_limit), and a diverged environment stays diverged (zero reward,
        ``terminated``). Only ``reset()`` begins new episodes (in every environment).
        """
    @staticmethod
    def evaluation(
        name: str,
        num_envs: int,
        seed: int = 0,
        *,
        fixed_start: Optional[int] = None,
        rotation_deg: float = 0.0,
        translation: Tuple[float, float] = ...,  # (0.0, 0.0)
        record: bool = False,
    ) -> VecEnv: ...
    def reset(self) -> Observation:
        """Begins a new episode in every environment; returns the first observations."""
    def step(
        self, actions: NDArray[np.float32]
    ) -> Tuple[Observation, NDArray[np.float32], NDArray[np.bool_], NDArray[np.bool_], StepInfo]:
        """One control step with ``actions`` (float32 ``[num_envs, total_dof]``): ``(obs,
        reward, terminated, truncated, info)``. Bad actions raise ``ValueError`` and change
        nothing; a step while another thread uses the env raises ``RuntimeError``."""
    def observation(self) -> Observation: ...
    def render(self, path: str) -> int: ...
    @property
    def spec(self) -> Spec: ...
    @property
    def num_envs(self) -> int: ...
    @property
    def num_actions(self) -> int: ...
    @property
    def curriculum_alpha(self) -> float: ...
    @curriculum_alpha.setter
    def curriculum_alpha(self, alpha: float) -> None: ...
    @property
    def auto_reset(self) -> bool:
        """Whether ended environments begin their next episode at once (off: they go on
        from their last state until ``reset``; see ``VecEnv()``)."""
    def __repr__(self) -> str: ...

@final
class Policy:
    @staticmethod
    def load(
        run: _Path, seed: int = 0, assignment: str | None = None, assignment_hold: int | None = None
    ) -> Policy:
        """The trained teams of ``run``: a run directory (``config.toml`` and checkpoint) or
        a policy file (``meben export-policy``, ``.safetensors``). A damaged, truncated or
        foreign file raises ``ValueError`` naming it. ``assignment`` (``"greedy"``,
        ``"hungarian"`` or ``"stochastic"``) acts and evaluates with that task-assignment
        rule in place of the run's own, on the same parameters (``meben eval
        --assignment``; a run that learned its assignment takes ``"greedy"`` only, Algorithm 1
        in place of its scorer's draws); one the run's models cannot take raises
        ``ValueError``.
        ``assignment_hold=k`` holds each random assignment for ``k`` steps (``meben eval
        --assignment-hold``)."""
    @staticmethod
    def pretrained(
        env: str, model: str, seed: int = 0, assignment: str | None = None, assignment_hold: int | None = None
    ) -> Policy:
        """A shipped pretrained policy (``meben/policies/index.toml``), e.g.
        ``Policy.pretrained("team_reach/2_ants", "shnn")``; one not shipped raises
        ``ValueError`` listing the shipped ones."""
    def act(self, obs: Observation, deterministic: bool = True) -> NDArray[np.float32]:
        """Actions ``[B, total_dof]`` for ``obs``: the means if ``deterministic``, else
        samples. Arrays of the wrong dtype or shape, with no row, or holding NaN or infinity
        raise ``ValueError`` naming the array (and the first non-finite entry); a call while
        another thread is acting with this policy raises ``RuntimeError``."""
    def end_episodes(self, ended: Union[Sequence[bool], NDArray[np.bool_]]) -> None:
        """Marks the rows whose episode ended at the last ``act`` (e.g. ``terminated |
        truncated``): a learned task assignment held per episode (``assignment_hold_episode``)
        is drawn again for them at the next ``act``. No effect on other runs. Another length
        than the last ``act``'s rows raises ``ValueError``."""
    def evaluate(
        self,
        episodes: int = 1024,
        seed: int = ...,
        deterministic: Optional[bool] = None,
        fixed: bool = False,
        rotation_deg: Optional[float] = None,
        translation: Optional[Tuple[float, float]] = None,
        assignment_sensitivity: bool = False,
        assignment_values: bool = False,
    ) -> EvalSummary: ...
    @property
    def run(self) -> pathlib.Path:
        """The run directory or policy file it was loaded from."""
    @property
    def recorded_eval(self) -> Optional[EvalSummary]:
        """The run's last evaluation as its checkpoint or policy file records it."""
    @property
    def env(self) -> str: ...
    @property
    def model(self) -> str: ...
    @property
    def config(self) -> str: ...
    def __repr__(self) -> str: ...

def train(
    out: _Path,
    overrides: Sequence[Tuple[str, str]],
    preset: Optional[str] = None,
    config: Optional[_Path] = None,
    progress: bool = False,
) -> str:
    """Trains into the run directory ``out`` (``meben.train``); returns ``done.json``'s text.
    An empty ``out`` raises ``ValueError`` before anything is written."""
def read_metrics(path: _Path) -> Dict[str, NDArray[np.float64]]: ...
