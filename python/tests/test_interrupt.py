"""Ctrl-C during ``meben.train``: the training stops after its current iteration with a
checkpoint of it, and ``KeyboardInterrupt`` is raised (before, the interrupt waited for the
whole training to end). Run in a child process, which the test interrupts with SIGINT."""

import json
import signal
import subprocess
import sys
import time

SCRIPT = """
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
