"""Ctrl-C during ``meben.train``: the training stops after its current iteration with a
checkpoint of it, and ``KeyboardInterrupt`` is raised; during ``Policy.evaluate``: the
evaluation is abandoned and ``KeyboardInterrupt`` raised (before, the interrupt waited for
the whole training or evaluation to end). Each runs in a child process, which the test
interrupts with SIGINT.

Each child restores Python's own SIGINT handler first: a process started from a background
job of a shell script inherits SIGINT as ignored, and Python then leaves it ignored, so the
signal the test sends would never arrive (the test sets up its own precondition)."""

import json
import signal
import subprocess
import sys
import time

RESTORE_SIGINT = """
import signal
signal.signal(signal.SIGINT, signal.default_int_handler)
"""

SCRIPT = RESTORE_SIGINT + """
import sys
import meben

try:
    meben.train(
        out=sys.argv[1], env="team_reach/1_ant", model="mlp_hn", steps=800_000, num_envs=8,
        batch_size=4, num_minibatches=4, epochs=1, num_evals=1, eval_episodes=2,
        checkpoint_every=0, threads=1,
    )
except KeyboardInterrupt as e:
    print("KeyboardInterrupt:", e)
    sys.exit(3)
print("finished")
"""


def metrics_rows(run):
    try:
        return len((run / "metrics.csv").read_text().splitlines()) - 1
    except FileNotFoundError:
        return 0


def test_ctrl_c_stops_training_with_a_checkpoint(tmp_path):
    run = tmp_path / "run"
    child = subprocess.Popen(
        [sys.executable, "-c", SCRIPT, str(run)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        # A run of 10,000 tiny iterations (seconds each at most); interrupt it once it has one.
        deadline = time.monotonic() + 120
        while metrics_rows(run) < 1:
            assert child.poll() is None, child.communicate()
            assert time.monotonic() < deadline, "no metrics row within 2 minutes"
            time.sleep(0.01)
        child.send_signal(signal.SIGINT)
        out, err = child.communicate(timeout=120)
    finally:
        child.kill()
    assert child.returncode == 3, (out, err)
    assert "KeyboardInterrupt" in out, (out, err)
    assert "stopping after the current iteration" in err, err
    # The checkpoint holds the last iteration in metrics.csv; the run is not done.
    checkpoint = json.loads((run / "checkpoint.json").read_text())["checkpoint"]
    assert checkpoint["iteration"] == metrics_rows(run) >= 1
    assert not (run / "done.json").exists()


EVALUATE = RESTORE_SIGINT + """
import sys, time
import meben

run = sys.argv[1]
meben.train(out=run, env="team_reach/1_ant", model="mlp_hn", steps=80, num_envs=8, batch_size=4,
            num_minibatches=4, epochs=1, num_evals=1, eval_episodes=2)
policy = meben.Policy.load(run)
print("evaluating", flush=True)
start = time.monotonic()
try:
    # 4096 episodes of up to 1000 steps: minutes, unless interrupted.
    policy.evaluate(episodes=4096, deterministic=False)
except KeyboardInterrupt:
    print(f"KeyboardInterrupt after {time.monotonic() - start:.1f} s", flush=True)
    sys.exit(3)
print("finished")
"""


def test_ctrl_c_abandons_an_evaluation(tmp_path):
    child = subprocess.Popen(
        [sys.executable, "-c", EVALUATE, str(tmp_path / "run")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert child.stdout.readline().strip() == "evaluating", child.communicate()
        time.sleep(1.0)
        interrupted = time.monotonic()
        child.send_signal(signal.SIGINT)
        out, err = child.communicate(timeout=120)
        waited = time.monotonic() - interrupted
    finally:
        child.kill()
    assert child.returncode == 3, (out, err)
    assert "KeyboardInterrupt" in out, (out, err)
    # Stopped by the evaluation's own check (the message), well before its end.
    assert "Policy.evaluate: interrupted: abandoning the evaluation" in err, err
    # The whole evaluation takes about 80 s on the 2-core machine; one control step, 0.1 s.
    assert waited < 20, f"the interrupt took {waited:.1f} s"
