"""``meben.train``: the trainer of ``meben train`` with its configuration fields as keywords."""

import json
import math
import os
from typing import Any, Optional, Union

from . import _core
from .types import RunSummary


def _toml_value(field: str, value: Any) -> str:
    """``value`` as the TOML text ``meben train --set field=...`` takes."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"bad {field} = {value}: must be finite")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a valid TOML basic string
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(field, v) for v in value) + "]"
    raise ValueError(f"bad {field} = {value!r}: expected a bool, number, string or list")


def train(
    *,
    out: Union[str, "os.PathLike[str]"],
    preset: Optional[str] = None,
    config: Union[str, "os.PathLike[str]", None] = None,
    progress: bool = False,
    **fields: Any,
) -> RunSummary:
    """Trains as ``meben train`` does and returns the run summary (the ``done.json`` dict).

    ``out`` is the run directory (a run with a checkpoint there resumes; an empty path raises
    ``ValueError`` before anything is written); ``preset`` is
    ``"quick"`` (default) or ``"paper"``; ``config`` a TOML file; every other keyword is a
    field of the Rust ``TrainConfig`` (``env``, ``model``, ``steps``, ``seed``, ``num_envs``,
    ...), applied last like ``--set field=value``. Unknown fields and bad values raise
    ``ValueError`` naming them.
    """
    overrides = [(k, _toml_value(k, v)) for k, v in fields.items()]
    config_path = os.fspath(config) if config is not None else None
    summary: RunSummary = json.loads(_core.train(os.fspath(out), overrides, preset, config_path, progress))
    return summary
