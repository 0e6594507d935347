"""The package's types: the stub of the Rust core (``meben/_core.pyi``) agrees with the built
module, and the installed package and the example type-check under ``mypy --strict``
(python/pyproject.toml's ``[tool.mypy]``); a program with a type error is rejected, so the
types are read, not silently ``Any``."""

import subprocess
import sys
import textwrap

from conftest import ROOT, optional_module

CONFIG = ROOT / "python" / "pyproject.toml"


def run(args, cwd):
    """Runs ``python -m <args>`` in ``cwd`` (outside the source tree, so that the installed
    package is the one checked); returns (exit code, output)."""
    done = subprocess.run([sys.executable, "-m", *args], cwd=cwd, capture_output=True, text=True, timeout=600)
    return done.returncode, done.stdout + done.stderr


def mypy(tmp_path, *targets):
    optional_module("mypy")
    return run(["mypy", "--config-file", str(CONFIG), "--cache-dir", str(tmp_path / "cache"), *targets], tmp_path)


def test_stub_matches_the_extension_module(tmp_path):
    optional_module("mypy")
    code, out = run(["mypy.stubtest", "meben._core"], tmp_path)
    assert code == 0, out


def test_package_and_example_type_check(tmp_path):
    code, out = mypy(tmp_path, "-p", "meben")
    assert code == 0, out
    code, out = mypy(tmp_path, str(ROOT / "python" / "examples" / "success_rates.py"))
    assert code == 0, out


def test_type_errors_are_caught(tmp_path):
    program = tmp_path / "wrong.py"
    program.write_text(
        textwrap.dedent(
            """
            import meben

            env = meben.make("team_reach/1_ant", num_envs="4")
            obs = env.reset()
            obs["vector"]
            count: str = env.num_envs
            summary = meben.Policy.load("run").evaluate(episodes=8)
            summary["success"]
            """
        )
    )
    code, out = mypy(tmp_path, str(program))
    assert code == 1, out
    expected = [
        'wrong.py:4: error: Argument "num_envs" to "make" has incompatible type "str"; expected "int"',
        'wrong.py:6: error: TypedDict "Observation" has no key "vector"',
        "wrong.py:7: error: Incompatible types in assignment",
        'wrong.py:9: error: TypedDict "EvalSummary" has no key "success"',
    ]
    for line in expected:
        assert line in out, out
