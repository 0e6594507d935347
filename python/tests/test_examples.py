"""The examples run as their docstrings say, and print what they claim."""

import re
import subprocess
import sys

from conftest import ROOT


def test_success_rates_example_agrees_with_policy_evaluate(tmp_path):
    # Without a run directory the example trains a tiny run under its working directory.
    out = subprocess.run(
        [sys.executable, ROOT / "python" / "examples" / "success_rates.py"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    rates = dict(re.findall(r"^team_reach/1_ant: (.+?) success rate ([0-9.]+)$", out, re.M))
    assert set(rates) == {"random policy", "trained mlp_hn (target/example_run)", "policy.evaluate"}, out
    # The hand-written episode loop and the one-call evaluation play the same episodes.
    assert rates["trained mlp_hn (target/example_run)"] == rates["policy.evaluate"], out
    assert re.search(r"^  after 160 env steps: evaluation success rate [0-9.]+$", out, re.M), out
    assert (tmp_path / "target" / "example_run" / "done.json").is_file()
