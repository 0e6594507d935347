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
    ) -> VecEnv: ...
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
    def reset(self) -> Observation: ...
    def step(
        self, actions: NDArray[np.float32]
    ) -> Tuple[Observation, NDArray[np.float32], NDArray[np.bool_], NDArray[np.bool_], StepInfo]: ...
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
    def auto_reset(self) -> bool: ...
    def __repr__(self) -> str: ...

@final
class Policy:
    @staticmethod
    def load(run: _Path, seed: int = 0) -> Policy: ...
    def act(self, obs: Observation, deterministic: bool = True) -> NDArray[np.float32]: ...
    def evaluate(
        self,
        episodes: int = 1024,
        seed: int = ...,
        deterministic: Optional[bool] = None,
        fixed: bool = False,
        rotation_deg: Optional[float] = None,
        translation: Optional[Tuple[float, float]] = None,
    ) -> EvalSummary: ...
    @property
    def run(self) -> pathlib.Path: ...
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
) -> str: ...
def read_metrics(path: _Path) -> Dict[str, NDArray[np.float64]]: ...
