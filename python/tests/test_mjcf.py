"""MJCF morphology files in compositions: MeBen's ant written as MJCF (envs/tests/data/ant.xml)
makes, resets and steps like the built-in Brax ant; a malformed or unsupported MJCF file
raises ValueError naming the file (and line, element, attribute, value) and breaks nothing."""

import pathlib

import numpy as np
import pytest

import meben

ANT_XML = pathlib.Path(__file__).resolve().parents[2] / "envs" / "tests" / "data" / "ant.xml"


def test_an_mjcf_morphology_makes_resets_and_steps():
    env = meben.make(f"team_reach:agents={ANT_XML}+claw;R=5", num_envs=4, seed=0)
    spec = env.spec
    assert spec["agent_morphology"] == [str(ANT_XML), "claw"]
    assert spec["agent_dof"] == [8, 16] and spec["agent_action_slice"] == [(0, 8), (8, 24)]
    # Nodes: each agent's root and one per DoF, then the two balls.
    assert spec["num_nodes"] == (1 + 8) + (1 + 16) + 2
    obs = env.reset()
    n = spec["num_nodes"]
    assert obs["vectors"].shape == (4, n, 3, 3) and obs["scalars"].shape == (4, n, 10)
    assert obs["heading"].shape == (4, 2)
    rng = np.random.default_rng(0)
    for _ in range(5):
        actions = rng.uniform(-1, 1, (4, env.num_actions)).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(actions)
    assert obs["vectors"].shape == (4, n, 3, 3) and reward.shape == (4, 1)
    assert terminated.shape == truncated.shape == (4,)
    assert np.isfinite(obs["vectors"]).all()


def test_the_mjcf_ant_has_the_brax_ants_spec_and_first_observation():
    # The same composition with the Brax ant: the same layout, and from the same seed the
    # same first observation up to f32 rounding (envs/tests/integration/tasks_mjcf.rs holds the models
    # equal to 1e-12 and the trajectories equal until an MJCF knee cap touches the ground).
    name = "team_sumo:team1=claw+{};team2={}+ant;R=3"
    brax = meben.make(name.format("ant", "ant"), num_envs=8, seed=3)
    mjcf = meben.make(name.format(ANT_XML, ANT_XML), num_envs=8, seed=3)
    for key, value in brax.spec.items():
        if key not in ("name", "agent_morphology"):
            assert mjcf.spec[key] == value, key
    a, b = brax.reset(), mjcf.reset()
    for key in ("vectors", "scalars", "heading"):
        np.testing.assert_allclose(a[key], b[key], rtol=0, atol=1e-6)


@pytest.mark.parametrize(
    "text,match",
    [
        # Not XML at all: the parser's line.
        ("<mujoco><worldbody><body>", r"broken\.xml:1: malformed XML"),
        # Valid XML outside the supported subset: file, line, element, attribute, value.
        (
            ANT_XML.read_text().replace('range="-30 30"/>', 'range="-30 30" stiffness="5"/>', 1),
            r"broken\.xml:\d+: <joint> attribute 'stiffness' value \"5\": only 0 is supported",
        ),
        (
            ANT_XML.read_text().replace("<actuator>", "<tendon/><actuator>"),
            r"broken\.xml:\d+: <tendon>: <tendon> is not supported in an agent morphology",
        ),
    ],
)
def test_a_malformed_mjcf_file_raises_value_error_and_breaks_nothing(tmp_path, text, match):
    env = meben.make("team_reach/2_ants", num_envs=2, seed=9)
    twin = meben.make("team_reach/2_ants", num_envs=2, seed=9)
    bad = tmp_path / "broken.xml"
    bad.write_text(text)
    with pytest.raises(ValueError, match=r"morphology \".*broken\.xml\": .*" + match):
        meben.make(f"team_reach:agents=ant+{bad}")
    # The process is usable: environments made before step as their twin, new ones build,
    # and the same file loads once fixed.
    actions = np.full((2, env.num_actions), 0.3, np.float32)
    a, b = env.step(actions), twin.step(actions)
    assert np.array_equal(a[0]["vectors"], b[0]["vectors"]) and np.array_equal(a[1], b[1])
    bad.write_text(ANT_XML.read_text())
    fixed = meben.make(f"team_reach:agents=ant+{bad}", num_envs=1)
    fixed.step(np.zeros((1, fixed.num_actions), np.float32))


def test_a_missing_mjcf_file_is_a_file_that_cannot_be_read(tmp_path):
    with pytest.raises(ValueError, match=r"missing\.xml\": cannot read the morphology file"):
        meben.make(f"team_reach:agents={tmp_path / 'missing.xml'}")
