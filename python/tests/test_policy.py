"""Training from Python writes the run directory `meben` writes; the policy loaded from it
acts in Python exactly as the Rust evaluation (`meben eval`) does: replaying the evaluation
in Python gives the same returns, lengths and success rate, to the last bit."""

import json
import subprocess
import sys
import threading

import numpy as np
import pytest
from conftest import in_forked_child

import meben

TINY = dict(batch_size=4, num_minibatches=4, epochs=1, num_evals=1, eval_episodes=2, num_envs=8, steps=160)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "reach"
    summary = meben.train(out=out, env="team_reach/1_ant", model="mlp_hn", seed=3, **TINY)
    assert summary["env_steps"] >= 160 and summary["final_eval"]["episodes"] == 2
    for f in ("config.toml", "metrics.csv", "checkpoint.json", "done.json"):
        assert (out / f).is_file(), f
    return out


@pytest.fixture(scope="module")
def sumo_run(tmp_path_factory):
    """A tiny shnn run of Team Sumo (two teams, the other model family)."""
    out = tmp_path_factory.mktemp("runs") / "sumo"
    meben.train(out=out, env="team_sumo/2_ants", model="shnn", seed=3, **TINY)
    return out


@pytest.fixture(scope="module")
def learned_run(tmp_path_factory):
    """A tiny run of MLP+HN with a learned task assignment (two ants: two assignments)."""
    out = tmp_path_factory.mktemp("runs") / "learned"
    meben.train(out=out, env="team_reach/2_ants", model="mlp_hn:assignment=learned", seed=3, **TINY)
    return out


def python_evaluation(policy, episodes, seed, deterministic):
    """rl::evaluate replayed with the Python API: one episode per environment."""
    env = meben.make_eval(policy.env, episodes, seed)
    teams = env.spec["num_teams"]
    obs = env.observation()
    alive = np.ones(episodes, bool)
    returns = np.zeros((episodes, teams), np.float64)
    outcome, length = np.zeros(episodes, np.int8), np.zeros(episodes, np.uint32)
    for _ in range(env.spec["episode_steps"] + 1):
        if not alive.any():
            break
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, deterministic=deterministic))
        for e in np.flatnonzero(alive):
            for k in range(teams):
                returns[e, k] += float(reward[e, k])  # f64 sums of f32 rewards, as Rust
            if terminated[e] or truncated[e]:
                alive[e] = False
                outcome[e], length[e] = info["outcome"][e], info["episode_len"][e]
    n = episodes
    return {
        "success_rate": float(np.sum(outcome == 1)) / n,
        "mean_return": [sum(returns[e, k] for e in range(n)) / n for k in range(teams)],
        "mean_length": sum(float(x) for x in length) / n,
    }


def rust_evaluation(meben_cli, run, episodes, seed, deterministic):
    """What `meben eval` writes for the run (mean or sampled actions)."""
    flag = "--mean" if deterministic else "--stochastic"
    subprocess.run(
        [meben_cli, "eval", "--run", run, "--episodes", str(episodes), "--seed", str(seed), flag],
        check=True,
        capture_output=True,
    )
    return json.loads((run / "eval.json").read_text())


@pytest.mark.parametrize("deterministic", [True, False])
def test_loaded_policy_acts_as_the_rust_evaluation(run, meben_cli, deterministic):
    episodes, seed = 3, 5
    rust = rust_evaluation(meben_cli, run, episodes, seed, deterministic)
    policy = meben.Policy.load(run, seed=seed)
    assert policy.env == "team_reach/1_ant" and policy.model == "mlp_hn"
    python = python_evaluation(policy, episodes, seed, deterministic)
    assert rust["sampled"] == (not deterministic)
    assert python == {k: rust[k] for k in python}, (python, rust)


@pytest.mark.parametrize("deterministic", [True, False])
def test_a_learned_assignment_acts_in_python_as_in_the_rust_evaluation(learned_run, meben_cli, deterministic):
    """The assignment drawn (or, deterministic, the most likely one) from the policy's own
    seeded stream: Python's episodes are Rust's to the bit."""
    episodes, seed = 2, 4
    rust = rust_evaluation(meben_cli, learned_run, episodes, seed, deterministic)
    policy = meben.Policy.load(learned_run, seed=seed)
    assert policy.model == "mlp_hn:assignment=learned"
    python = python_evaluation(policy, episodes, seed, deterministic)
    assert python == {k: rust[k] for k in python}, (python, rust)


def test_a_learned_assignment_in_its_warmup_acts_as_the_greedy_policy(tmp_path):
    """A run still in its assignment warm-up (`assignment_warmup_steps` past its env steps)
    is the greedy model's run, and loaded in Python acts as that run's policy: Algorithm 1's
    assignment, the scorer unused."""
    warm, greedy = tmp_path / "warm", tmp_path / "greedy"
    meben.train(out=warm, env="team_reach/2_ants", model="mlp_hn:assignment=learned", seed=3,
                assignment_warmup_steps=10**6, **TINY)
    meben.train(out=greedy, env="team_reach/2_ants", model="mlp_hn", seed=3, **TINY)
    for deterministic in (True, False):
        episodes = [python_evaluation(meben.Policy.load(r, seed=4), 2, 4, deterministic) for r in (warm, greedy)]
        assert episodes[0] == episodes[1], (deterministic, episodes)


def test_a_learned_policy_given_greedy_acts_and_evaluates_as_meben_eval_assignment_greedy(learned_run, meben_cli):
    """`assignment="greedy"` on a run that learned its assignment is `meben eval --assignment
    greedy`: Algorithm 1 in place of its scorer's draws, the same episodes in Python's replay,
    in `Policy.evaluate` and in Rust; the other rules are refused naming the argument."""
    episodes, seed = 2, 4
    subprocess.run(
        [meben_cli, "eval", "--run", learned_run, "--episodes", str(episodes), "--seed", str(seed), "--stochastic",
         "--assignment", "greedy"],
        check=True,
        capture_output=True,
    )
    rust = json.loads((learned_run / "eval_assignment-greedy.json").read_text())
    assert rust["assignment"] == "greedy"
    policy = meben.Policy.load(learned_run, seed=seed, assignment="greedy")
    python = python_evaluation(policy, episodes, seed, False)
    assert python == {k: rust[k] for k in python}, (python, rust)
    own = python_evaluation(meben.Policy.load(learned_run, seed=seed), episodes, seed, False)
    assert own != python, "the scorer's own draws played Algorithm 1's episodes"
    for rule in ("hungarian", "stochastic"):
        with pytest.raises(ValueError, match=rf'bad assignment = "{rule}".*only greedy'):
            meben.Policy.load(learned_run, assignment=rule)


def test_a_held_learned_assignment_acts_in_python_as_in_the_rust_evaluation(tmp_path, meben_cli):
    """A learned assignment held for 3 steps (`assignment_hold_steps`): the policy loaded in
    Python holds its draws from its first `act` as `meben eval` does from each episode's
    start, so its episodes are Rust's to the bit."""
    held = tmp_path / "held"
    meben.train(out=held, env="team_reach/2_ants", model="mlp_hn:assignment=learned", seed=3,
                assignment_hold_steps=3, **TINY)
    assert "assignment_hold_steps = 3" in (held / "config.toml").read_text()
    episodes, seed = 2, 4
    rust = rust_evaluation(meben_cli, held, episodes, seed, False)
    python = python_evaluation(meben.Policy.load(held, seed=seed), episodes, seed, False)
    assert python == {k: rust[k] for k in python}, (python, rust)


def test_a_learned_assignment_held_per_episode_acts_in_python_as_in_rust(tmp_path, meben_cli):
    """A learned assignment held per episode (`assignment_hold_episode`): the policy loaded in
    Python draws at its first `act` and holds, as `meben eval` does from each episode's start
    (Rust's episodes to the bit); `end_episodes` redraws the rows it marks, and only those."""
    held = tmp_path / "held"
    meben.train(out=held, env="team_reach/2_ants", model="mlp_hn:assignment=learned", seed=3,
                assignment_hold_episode=True, **TINY)
    assert "assignment_hold_episode = true" in (held / "config.toml").read_text()
    episodes, seed = 2, 4
    rust = rust_evaluation(meben_cli, held, episodes, seed, False)
    python = python_evaluation(meben.Policy.load(held, seed=seed), episodes, seed, False)
    assert python == {k: rust[k] for k in python}, (python, rust)
    # Two policies of one seed act alike until one is told that episodes ended.
    obs = meben.make("team_reach/2_ants", num_envs=8, seed=0).reset()
    marked, kept = meben.Policy.load(held, seed=5), meben.Policy.load(held, seed=5)
    assert np.array_equal(marked.act(obs, deterministic=False), kept.act(obs, deterministic=False))
    ended = np.arange(8) % 2 == 0
    marked.end_episodes(ended)
    kept.end_episodes(np.zeros(8, bool))
    a, b = marked.act(obs, deterministic=False), kept.act(obs, deterministic=False)
    assert np.array_equal(a[~ended], b[~ended]), "rows not marked kept their assignment"
    assert not np.array_equal(a[ended], b[ended]), "no marked row drew another assignment"
    with pytest.raises(ValueError, match=r"bad ended = 3 values: expected one per row of the last act \(8 rows\)"):
        marked.end_episodes([True, False, True])


def test_the_expected_assignment_gradient_trains_from_python_and_its_policy_acts_as_in_rust(tmp_path, meben_cli):
    """`assignment_gradient="expected"` (TRAINING.md) is a keyword of `train`, written to the
    run's `config.toml`; a model without the held critic is refused naming the field and the
    option it lacks; the trained policy acts in Python as `meben eval` does."""
    with pytest.raises(ValueError, match=r'field `model` = "mlp_hn:assignment=learned".*add assign_critic=held'):
        meben.train(out=tmp_path / "refused", env="team_reach/2_ants", model="mlp_hn:assignment=learned",
                    assignment_hold_episode=True, assignment_gradient="expected", **TINY)
    assert not (tmp_path / "refused" / "checkpoint.json").exists()
    out = tmp_path / "expected"
    meben.train(out=out, env="team_reach/2_ants", model="mlp_hn:assignment=learned;assign_critic=held", seed=3,
                assignment_hold_episode=True, assignment_gradient="expected", **TINY)
    assert 'assignment_gradient = "expected"' in (out / "config.toml").read_text()
    episodes, seed = 2, 4
    rust = rust_evaluation(meben_cli, out, episodes, seed, False)
    python = python_evaluation(meben.Policy.load(out, seed=seed), episodes, seed, False)
    assert python == {k: rust[k] for k in python}, (python, rust)
    # The values of both assignments at each episode's start, as `meben eval --assignment-values`.
    summary = tmp_path / "values.json"
    flags = ["--episodes", "2", "--seed", "4", "--stochastic", "--assignment-values", "--out", str(summary)]
    subprocess.run([meben_cli, "eval", "--run", str(out), *flags], check=True, capture_output=True)
    values = meben.Policy.load(out).evaluate(episodes=2, seed=4, deterministic=False, assignment_values=True)
    assert values == json.loads(summary.read_text())
    (v,) = values["assignment_values"]
    assert len(v["support"]) == 2 and len(v["episodes"]) == 2
    assert all(abs(sum(e["probability"]) - 1.0) < 1e-5 for e in v["episodes"])
    # A policy file holds no value network: refused, naming the file.
    policy_file = tmp_path / "policy.safetensors"
    subprocess.run([meben_cli, "export-policy", "--run", str(out), "--out", str(policy_file)], check=True,
                   capture_output=True)
    with pytest.raises(ValueError, match=r"assignment_values=True reads the value network.*policy.safetensors"):
        meben.Policy.load(policy_file).evaluate(episodes=2, assignment_values=True)


def test_the_run_names_the_build_that_trained_it(run, meben_cli):
    commit = meben.BUILD_COMMIT
    sha = commit.split("+")[0]
    assert commit == "unknown" or (len(sha) == 40 and all(c in "0123456789abcdef" for c in sha)), commit
    header, *rows = (run / "builds.csv").read_text().splitlines()
    assert header == "from_iteration,version,commit,unix_time_s"
    assert [r.split(",")[:3] for r in rows] == [["0", meben.__version__, commit]]
    # The command line built from the same checkout names the same commit.
    out = subprocess.run([meben_cli, "--version"], capture_output=True, text=True, check=True).stdout
    assert out.strip() == f"meben {meben.__version__} (commit {commit})"


def test_policy_actions_are_deterministic_and_bounded(run):
    policy = meben.Policy.load(run)
    obs = meben.make("team_reach/1_ant", num_envs=4, seed=0).reset()
    a, b = policy.act(obs), policy.act(obs)
    assert a.shape == (4, 8) and a.dtype == np.float32
    assert np.array_equal(a, b) and np.all(np.abs(a) <= 1)
    with pytest.raises(ValueError, match=r'bad obs\["vectors"\] = an array of shape \[4, 9, 3, 3\]'):
        policy.act({**obs, "vectors": obs["vectors"][:, :9]})
    with pytest.raises(ValueError, match="without \"scalars\""):
        policy.act({"vectors": obs["vectors"], "heading": obs["heading"]})
    assert np.array_equal(policy.act(obs), a)


@pytest.mark.parametrize("which", ["run", "sumo_run"])
@pytest.mark.parametrize(
    "key,index,value,shown",
    [
        ("vectors", (1, 3, 0, 2), np.nan, "NaN"),
        ("scalars", (0, 4, 7), np.inf, "inf"),
        ("heading", (0, 0), -np.inf, "-inf"),
    ],
)
def test_non_finite_observations_raise_and_change_nothing(request, which, key, index, value, shown):
    # They used to give finite actions without a word (issue 44, item 3).
    run = request.getfixturevalue(which)
    policy, twin = meben.Policy.load(run, seed=1), meben.Policy.load(run, seed=1)
    obs = meben.make(policy.env, num_envs=2, seed=0).reset()
    bad = {k: v.copy() for k, v in obs.items()}
    bad[key][index] = value
    bad[key].reshape(-1)[-1] = np.nan  # a later one: the first is named
    where = ", ".join(map(str, index))
    for deterministic in (True, False):
        with pytest.raises(ValueError, match=rf'bad obs\["{key}"\]\[{where}\] = {shown}: must be finite'):
            policy.act(bad, deterministic=deterministic)
    # The noise streams did not move: the policy samples as its twin that saw no error.
    assert np.array_equal(policy.act(obs, deterministic=False), twin.act(obs, deterministic=False))


def test_observations_of_no_environment_raise_value_error(run):
    policy = meben.Policy.load(run)
    obs = meben.make("team_reach/1_ant", num_envs=2, seed=0).reset()
    # It used to be a RuntimeError from the model.
    with pytest.raises(ValueError, match=r'bad obs\["heading"\] = an array of shape \[0, 1\]: expected at least one row'):
        policy.act({k: v[:0] for k, v in obs.items()})


def act_and_evaluate(run):
    """What a policy loaded in this process does: actions, then a short evaluation."""
    policy = meben.Policy.load(run, seed=2)
    obs = meben.make(policy.env, num_envs=8, seed=0).reset()
    return policy.act(obs), policy.act(obs, deterministic=False), policy.evaluate(episodes=2, seed=1)


@pytest.mark.filterwarnings("ignore:.*multi-threaded.*fork:DeprecationWarning")
def test_a_forked_child_acts_and_evaluates_as_its_parent(run):
    # The parent's pool has run (training, acting) before the fork; the child used to hang
    # (issue 44, item 1; the environments: test_fork.py).
    parent = act_and_evaluate(run)
    child = in_forked_child(act_and_evaluate, run)
    assert np.array_equal(parent[0], child[0]) and np.array_equal(parent[1], child[1])
    assert parent[2] == child[2]


def test_a_policy_used_by_two_threads_says_so(run):
    policy = meben.Policy.load(run)
    obs = meben.make("team_reach/1_ant", num_envs=4096, seed=0).reset()
    errors, done = [], threading.Event()

    def act():
        try:
            for _ in range(10):
                policy.act(obs)
        finally:
            done.set()

    old = sys.getswitchinterval()
    sys.setswitchinterval(1e-4)
    try:
        t = threading.Thread(target=act)
        t.start()
        while not done.is_set():
            try:
                policy.act(obs)
            except RuntimeError as e:
                errors.append(str(e))
        t.join()
    finally:
        sys.setswitchinterval(old)
    # It used to be PyO3's bare "Already borrowed".
    assert errors, "the two threads never met"
    assert all("in use by another thread" in e and "each thread needs its own Policy" in e for e in errors), errors
    assert np.array_equal(policy.act(obs), meben.Policy.load(run).act(obs))


def test_an_empty_run_directory_is_refused_before_touching_the_disk(tmp_path, monkeypatch):
    # It used to leave a `lock` file in the working directory and raise a confusing OSError.
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match=r"bad out = '': expected the run directory's path"):
        meben.train(out="", env="team_reach/1_ant", **TINY)
    assert list(tmp_path.iterdir()) == []


def test_bad_runs_and_configurations(tmp_path):
    with pytest.raises(OSError, match="not a run directory"):
        meben.Policy.load(tmp_path)
    with pytest.raises(ValueError, match="num_envz"):
        meben.train(out=tmp_path / "x", num_envz=8)
    with pytest.raises(ValueError, match=r"steps = nan: must be finite"):
        meben.train(out=tmp_path / "x", steps=float("nan"))
    # A value of the wrong type names its field, its value and where it came from.
    with pytest.raises(ValueError, match=r'built-in \+ meben.train keywords: field `steps` = "-1": invalid value'):
        meben.train(out=tmp_path / "x", steps=-1)
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    "flags,kwargs,file",
    [
        (["--mean"], dict(deterministic=True), "eval.json"),
        (["--stochastic"], dict(deterministic=False), "eval.json"),
        (["--rotate", "90"], dict(rotation_deg=90.0), "eval_rotate90.json"),
        (["--fixed"], dict(fixed=True), "eval_fixed.json"),
    ],
)
def test_policy_evaluate_returns_what_meben_eval_writes(run, meben_cli, flags, kwargs, file):
    episodes, seed = 3, 7
    subprocess.run(
        [meben_cli, "eval", "--run", run, "--episodes", str(episodes), "--seed", str(seed), *flags],
        check=True,
        capture_output=True,
    )
    rust = json.loads((run / file).read_text())
    python = meben.Policy.load(run).evaluate(episodes=episodes, seed=seed, **kwargs)
    assert python == rust
    assert python["episodes"] == episodes and python["rotation_deg"] == kwargs.get("rotation_deg", 0.0)


def test_policy_evaluate_measures_the_assignment_sensitivity_as_meben_eval_does(tmp_path, meben_cli):
    # The shipped 2_ants SHNN: two ants, two balls, so one other assignment a step.
    out = tmp_path / "eval.json"
    flags = ["--episodes", "2", "--seed", "3", "--stochastic", "--assignment-sensitivity", "--out", str(out)]
    subprocess.run([meben_cli, "eval", "--policy", "pretrained:team_reach/2_ants/shnn", *flags], check=True, capture_output=True)
    policy = meben.Policy.pretrained("team_reach/2_ants", "shnn")
    python = policy.evaluate(episodes=2, seed=3, deterministic=False, assignment_sensitivity=True)
    assert python == json.loads(out.read_text())
    (s,) = python["assignment_sensitivity"]
    assert s["team"] == 0 and s["alternatives"] == 1.0
    assert s["steps"] == round(2 * python["mean_length"]) and s["mean_kl"] > 0.0
    # Without the flag the summary has no such key, and the episodes are the same.
    plain = policy.evaluate(episodes=2, seed=3, deterministic=False)
    assert "assignment_sensitivity" not in plain
    assert plain == {k: v for k, v in python.items() if k != "assignment_sensitivity"}


def test_policy_evaluate_rejects_bad_requests_by_name(run):
    policy = meben.Policy.load(run)
    with pytest.raises(ValueError, match="episodes"):
        policy.evaluate(episodes=0)
    with pytest.raises(ValueError, match="finite"):
        policy.evaluate(episodes=1, rotation_deg=float("nan"))
    with pytest.raises(ValueError, match="finite"):
        policy.evaluate(episodes=1, translation=(0.0, float("inf")))
    # Finite but too far for f64 positions to keep the physics (envs MAX_MOTION_M).
    with pytest.raises(ValueError, match=r"translation \[1e\+?300, 0\.0\].*within 1e6 m"):
        policy.evaluate(episodes=1, translation=(1e300, 0.0))
    with pytest.raises(ValueError, match="within 1e6 m"):
        meben.make("team_reach/1_ant", fixed_start=1, rotation_deg=90, point=(0.0, -5e6))


def test_read_metrics_gives_the_runs_columns(run, tmp_path):
    columns = meben.read_metrics(run)
    header, *rows = (run / "metrics.csv").read_text().splitlines()
    assert list(columns) == header.split(",")
    assert all(len(v) == len(rows) and v.dtype == np.float64 for v in columns.values())
    for i, row in enumerate(rows):
        for name, cell in zip(header.split(","), row.split(",")):
            value = columns[name][i]
            assert (np.isnan(value) and cell == "") or value == float(cell), (name, i, cell, value)
    # The one evaluation is at the last iteration; the rows before it have none.
    assert not np.isnan(columns["eval_success_rate"][-1]) and np.isnan(columns["eval_success_rate"][:-1]).all()
    assert meben.read_metrics(run / "metrics.csv").keys() == columns.keys()
    bad = tmp_path / "bad.csv"
    bad.write_text("iteration,loss\n1,0.5\n2,oops\n")
    with pytest.raises(ValueError, match=r"bad\.csv: line 3: column loss"):
        meben.read_metrics(bad)
    with pytest.raises(OSError, match="missing"):
        meben.read_metrics(tmp_path / "missing")


def test_policy_and_env_say_what_they_are(run):
    policy = meben.Policy.load(run)
    assert policy.run == run
    assert repr(policy) == f"Policy(run={str(run)!r}, env='team_reach/1_ant', model='mlp_hn')"
    env = meben.make("team_sumo/2_ants", num_envs=3, auto_reset=False)
    assert repr(env) == f"VecEnv(name='team_sumo/2_ants', num_envs=3, num_actions={env.num_actions}, auto_reset=False)"
