"""Shared fixtures: the repository root and the Rust programs the tests compare with
(built by ./test.sh before pytest runs)."""

import importlib
import os
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def target_dir():
    """Cargo's target directory: CARGO_TARGET_DIR when set (relative to the repository
    root), else the root's target/."""
    return ROOT / os.environ.get("CARGO_TARGET_DIR", "target")


def rust_program(relative):
    """A program under the target directory's release/ (`target_dir`); a missing one fails
    the test (run ./test.sh)."""
    path = target_dir() / "release" / relative
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


# A forked child answers within this many seconds or the test fails (a hung child used to
# block the test run for ever).
FORK_TIMEOUT_S = 120


def _send_result(conn, fn, args):
    try:
        conn.send(("ok", fn(*args)))
    except BaseException as e:  # noqa: BLE001 - everything goes back to the parent
        conn.send(("error", f"{type(e).__name__}: {e}"))
    finally:
        conn.close()


def in_forked_child(fn, *args):
    """``fn(*args)`` run in a child process started with multiprocessing's ``fork`` start
    method; returns its result. A child that raises fails the test with its error, one that
    does not answer within ``FORK_TIMEOUT_S`` is killed and fails the test."""
    import multiprocessing

    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("no fork start method on this platform")
    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_send_result, args=(send, fn, args))
    child.start()
    send.close()
    try:
        if not receive.poll(FORK_TIMEOUT_S):
            pytest.fail(f"the forked child did not answer within {FORK_TIMEOUT_S} s: it hangs")
        status, value = receive.recv()
    finally:
        child.kill()
        child.join()
    if status != "ok":
        pytest.fail(f"the forked child raised {value}")
    return value
