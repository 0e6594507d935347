"""Shared fixtures: the repository root and the Rust programs the tests compare with
(built by ./test.sh before pytest runs)."""

import importlib
import os
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def rust_program(relative):
    """A program under target/release; a missing one fails the test (run ./test.sh)."""
    path = ROOT / "target" / "release" / relative
    if not path.is_file():
        pytest.fail(f"{path} is missing: run ./test.sh (it builds the Rust programs first)")
    return path


def optional_module(name):
    """Imports the optional test dependency `name`: a test without it is skipped, except
    under ./test.sh (MEBEN_REQUIRE_TEST_DEPS=1, which installs it), where a missing
    module is a failure, so the test command never passes by skipping."""
    if os.environ.get("MEBEN_REQUIRE_TEST_DEPS") == "1":
        try:
            return importlib.import_module(name)
        except ImportError as e:
            pytest.fail(f"{name} is required here (MEBEN_REQUIRE_TEST_DEPS=1) but does not import: {e}")
    return pytest.importorskip(name)


@pytest.fixture
def replay_actions():
    """The Rust example that replays an action file in a VecEnv."""
    return rust_program("examples/replay_actions")


@pytest.fixture
def meben_cli():
    """The `meben` program."""
    return rust_program("meben")
