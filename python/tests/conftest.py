"""Shared fixtures: the repository root and the Rust programs the tests compare with
(built by ./test.sh before pytest runs)."""

import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def rust_program(relative):
    """A program under target/release; a missing one fails the test (run ./test.sh)."""
    path = ROOT / "target" / "release" / relative
    if not path.is_file():
        pytest.fail(f"{path} is missing: run ./test.sh (it builds the Rust programs first)")
    return path


@pytest.fixture
def replay_actions():
    """The Rust example that replays an action file in a VecEnv."""
    return rust_program("examples/replay_actions")


@pytest.fixture
def meben_cli():
    """The `meben` program."""
    return rust_program("meben")
