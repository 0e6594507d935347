"""MeBen from Python: batched Team Reach and Team Sumo environments, trained policies and
training, backed by the Rust crates of meben-rs (the extension module ``meben._core``).

>>> import meben, numpy as np
>>> env = meben.make("team_reach/2_ants", num_envs=256, seed=0)
>>> obs = env.reset()
>>> actions = np.zeros((env.num_envs, env.num_actions), np.float32)
>>> obs, reward, terminated, truncated, info = env.step(actions)

A trained run: ``meben.Policy.load(run)`` acts (``policy.act(obs)``) and evaluates
(``policy.evaluate(episodes=1024, rotation_deg=180)``: the summary ``meben eval`` writes);
``run`` is a run directory or a policy file (``meben export-policy --run DIR --out
FILE.safetensors``: the weights as safetensors, which ``safetensors.numpy.load_file`` also
reads). ``meben.Policy.pretrained("team_reach/2_ants", "shnn")`` loads a shipped pretrained
policy (``meben/policies/index.toml``). ``meben.read_metrics(run)`` gives a run's
``metrics.csv`` as float64 numpy columns.

Adapters: ``meben.gymnasium.GymVecEnv`` (Gymnasium's vector-env API), ``GymEnv`` (one
``gymnasium.Env``; both take ``seed=``, and ``flatten=True`` for one flat ``Box``
observation, as Stable-Baselines3's and CleanRL's MLP policies take it) and
``meben.pettingzoo.ParallelEnv`` (PettingZoo's parallel API); they import their packages
only when used.

``meben.__version__`` is the package version and ``meben.BUILD_COMMIT`` the git commit the
Rust core was built from (``+modified`` if its sources differed, ``unknown`` outside git);
a run directory's ``builds.csv`` names it for every training session, as ``meben --version``
does for the command line.

The package is typed (``py.typed``): the returned dicts are the ``TypedDict`` types of
``meben.types`` (``Observation``, ``StepInfo``, ``Spec``, ``EvalSummary``, ``RunSummary``).
"""

from typing import Any

from . import types
from ._core import BUILD_COMMIT, BUILTIN_NAMES, OUTCOMES, Policy, VecEnv, __version__, read_metrics
from ._train import train

__all__ = [
    "BUILD_COMMIT",
    "BUILTIN_NAMES",
    "OUTCOMES",
    "Policy",
    "VecEnv",
    "make",
    "make_eval",
    "read_metrics",
    "train",
    "types",
]


def make(name: str, num_envs: int = 1, seed: int = 0, **options: Any) -> VecEnv:
    """``num_envs`` environments of ``name``, a built-in name (``meben.BUILTIN_NAMES``) or a
    composition such as ``"team_reach:agents=ant+claw;R=5;balls=2"`` (a morphology may be a
    Brax-config ``.txt`` file or an MJCF ``.xml`` file, e.g.
    ``"team_reach:agents=ant+my/agent.xml"``), seeded with ``seed``. A bad name or a
    malformed morphology file raises ``ValueError`` naming it (for a file: its line, element,
    attribute and value). So does a ``num_envs`` the machine cannot hold: each scene's
    memory per environment is estimated (from about 30 KB for ``team_reach/1_ant`` to 0.4 MB
    for ``team_sumo/3_ants``) and compared with the machine's available memory before
    anything is allocated; the message gives both.

    Options (keywords): ``auto_reset=True`` (an ended environment begins its next episode in
    the same step; ``info["final_obs"]`` holds the true last observation), ``fixed_start=None``
    (a seed: every episode starts from the start drawn with it), ``rotation_deg=0.0`` and
    ``point=(0, 0)`` (the fixed start rotated about the vertical through ``point``),
    ``record=False`` (record environment 0 for ``env.render(path)``).

    ``auto_reset=False`` does not reset an ended environment, nor freeze it: each later
    ``step`` goes on simulating the same scene from where the episode ended, with the new
    actions, ``info["episode_len"]`` counting past the end, and judges it afresh as during
    the episode. Team Reach pays the success bonus again (outcome success, ``terminated``) at
    every step on which the balls are still covered; Team Sumo's win or draw is judged on
    each new state; after the time limit every step not terminated is ``truncated`` (outcome
    ``time_limit``); a diverged environment stays diverged (zero reward, ``terminated``).
    Only ``env.reset()`` begins new episodes (in every environment), so stop stepping an
    environment, or ignore its rows, once it has ended.

    An environment is one thread's: a call while another thread is stepping or resetting it
    raises ``RuntimeError`` (make one per thread). In a process forked after ``meben`` was
    used (``multiprocessing``'s ``fork`` start method) the environments step on a thread pool
    of that process's own.
    """
    return VecEnv(name, num_envs, seed, **options)


def make_eval(name: str, num_envs: int, seed: int = 0, **options: Any) -> VecEnv:
    """The environments of ``meben eval``: one episode each, auto-reset off, starts drawn as
    the Rust evaluation draws them. Options: ``fixed_start=None`` (a seed), ``rotation_deg``
    (about the vertical through the origin), ``translation=(0, 0)``, ``record=False``.
    """
    return VecEnv.evaluation(name, num_envs, seed, **options)
