//! Environment names and compositions: which morphologies play in which team, the arena or
//! placement radius `R`, the number of goal balls, and the timing (MEBEN.md sections 2, 3).
//!
//! Built-in names: [`BUILTIN_NAMES`]. Any other composition is configured without code by
//! a string ([`TaskSpec::from_name`]):
//!
//! - `team_reach:agents=ant+claw;R=5;balls=2` (`balls` defaults to the number of agents,
//!   `R` to 5);
//! - `team_sumo:team1=ant+claw;team2=ant+ant;R=3` (`R` defaults to 3).
//!
//! Morphologies are the built-in names of [`crate::brax::morphologies`], or paths to Brax
//! config files (ending in `.txt`) or MJCF files (ending in `.xml`, the subset of
//! [`crate::mjcf_agent`]), e.g. `team_sumo:team1=ant+my/agent.xml;team2=ant+ant`.

use super::error::TaskError;
use serde::{Deserialize, Serialize};

/// The largest arena radius `R` in metres (the paper uses 3 to 5; far beyond, f32
/// observations and the integrator lose the precision to be meaningful).
pub const MAX_RADIUS: f64 = 1000.0;

/// The most agents in one scene, all teams together (the built-in scenes have up to 4; a
/// composition of thousands used to exhaust memory building the collision pairs, whose
/// number grows with the square of the bodies, and abort the process). Scenes of fewer
/// agents with many bodies each are bounded by [`super::scene::MAX_CONTACT_PAIRS`].
pub const MAX_AGENTS: usize = 256;

/// Control step (s): one action per 0.05 s.
pub const CONTROL_DT: f64 = 0.05;
/// Physics steps per control step (the MeBen scenes' 0.01 s time step,
/// [`crate::brax::to_model::BRAX_TIMESTEP`]).
pub const PHYSICS_STEPS_PER_CONTROL: usize = 5;
/// Episode length in control steps.
pub const EPISODE_STEPS: usize = 1000;

/// Which game.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum TaskKind {
    /// Team Reach: one team of N agents covers M fixed balls.
    Reach,
    /// Team Sumo: two teams push each other out of a ring around a centre ball.
    Sumo,
}

/// A complete composition: everything needed to build a scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskSpec {
    /// The name it was made from (built-in or custom string).
    pub name: String,
    /// Which game.
    pub kind: TaskKind,
    /// Morphology names (or Brax-config / MJCF paths) per team: Reach has one team, Sumo two.
    pub teams: Vec<Vec<String>>,
    /// Reach: placement radius of agents and balls (m); Sumo: arena radius (m).
    pub radius: f64,
    /// Number of balls: Reach goal balls (1 ..= agents); Sumo always 1 (the centre ball).
    pub balls: usize,
    /// Episode length in control steps ([`EPISODE_STEPS`]).
    pub episode_steps: usize,
    /// Physics steps per control step ([`PHYSICS_STEPS_PER_CONTROL`]).
    pub physics_steps: usize,
}

/// Every built-in environment name.
pub const BUILTIN_NAMES: [&str; 10] = [
    "team_reach/1_ant",
    "team_reach/1_centipede",
    "team_reach/2_ants",
    "team_reach/2_ant_claw",
    "team_reach/2_unimals",
    "team_reach/3_ant_claw_centipede",
    "team_sumo/1_centipede",
    "team_sumo/2_ants",
    "team_sumo/2_ant_claw",
    "team_sumo/3_ants",
];

fn builtin(name: &str) -> Option<TaskSpec> {
    let (agents, radius): (&[&str], f64) = match name {
        "team_reach/1_ant" => (&["ant"], 5.0),
        "team_reach/1_centipede" => (&["centipede"], 5.0),
        "team_reach/2_ants" => (&["ant", "ant"], 3.0),
        "team_reach/2_ant_claw" => (&["ant", "claw"], 5.0),
        "team_reach/2_unimals" => (&["unimal_1", "unimal_2"], 5.0),
        "team_reach/3_ant_claw_centipede" => (&["ant", "claw", "centipede"], 5.0),
        "team_sumo/1_centipede" => (&["centipede"], 3.0),
        "team_sumo/2_ants" => (&["ant", "ant"], 3.0),
        "team_sumo/2_ant_claw" => (&["ant", "claw"], 3.0),
        "team_sumo/3_ants" => (&["ant", "ant", "ant"], 4.0),
        _ => return None,
    };
    let team: Vec<String> = agents.iter().map(|s| s.to_string()).collect();
    let spec = if name.starts_with("team_reach/") {
        TaskSpec::reach(&team, radius, team.len())
    } else {
        TaskSpec::sumo(&team, &team, radius)
    };
    spec.ok().map(|s| TaskSpec { name: name.to_string(), ..s })
}

/// Whether a morphology name names a file, a Brax config (`.txt`) or an MJCF file (`.xml`),
/// rather than a built-in morphology: the scene builder reads such a name as a path.
pub fn is_morphology_file(name: &str) -> bool {
    name.ends_with(".txt") || name.ends_with(".xml")
}

fn bad(what: &str, value: &str, message: &str) -> TaskError {
    TaskError::BadSpec { what: what.to_string(), value: value.to_string(), message: message.to_string() }
}

fn parse_team(what: &str, value: &str) -> Result<Vec<String>, TaskError> {
    let team: Vec<String> = value.split('+').map(|s| s.trim().to_string()).collect();
    if team.iter().any(|s| s.is_empty()) {
        return Err(bad(what, value, "expected morphology names joined by '+', e.g. ant+claw"));
    }
    Ok(team)
}

fn parse_radius(value: &str) -> Result<f64, TaskError> {
    value.trim().parse::<f64>().map_err(|_| bad("R", value, "expected a number of metres"))
}

impl TaskSpec {
    /// A Team Reach composition: `agents` (one team), placement radius `radius`, `balls` goal
    /// balls (1 ..= number of agents).
    pub fn reach(agents: &[String], radius: f64, balls: usize) -> Result<TaskSpec, TaskError> {
        let spec = TaskSpec {
            name: format!("team_reach:agents={};R={radius};balls={balls}", agents.join("+")),
            kind: TaskKind::Reach,
            teams: vec![agents.to_vec()],
            radius,
            balls,
            episode_steps: EPISODE_STEPS,
            physics_steps: PHYSICS_STEPS_PER_CONTROL,
        };
        spec.validate()?;
        Ok(spec)
    }

    /// A Team Sumo composition: `team1` against `team2` in an arena of radius `radius`.
    pub fn sumo(team1: &[String], team2: &[String], radius: f64) -> Result<TaskSpec, TaskError> {
        let spec = TaskSpec {
            name: format!("team_sumo:team1={};team2={};R={radius}", team1.join("+"), team2.join("+")),
            kind: TaskKind::Sumo,
            teams: vec![team1.to_vec(), team2.to_vec()],
            radius,
            balls: 1,
            episode_steps: EPISODE_STEPS,
            physics_steps: PHYSICS_STEPS_PER_CONTROL,
        };
        spec.validate()?;
        Ok(spec)
    }

    /// A built-in environment ([`BUILTIN_NAMES`]) or a custom composition string (module
    /// docs). An unknown name is an error listing the built-in names.
    pub fn from_name(name: &str) -> Result<TaskSpec, TaskError> {
        if let Some(spec) = builtin(name) {
            return Ok(spec);
        }
        let unknown = || TaskError::UnknownEnv {
            name: name.to_string(),
            known: BUILTIN_NAMES.iter().map(|s| s.to_string()).collect(),
        };
        let (kind, rest) = name.split_once(':').ok_or_else(unknown)?;
        let mut keys: Vec<(&str, &str)> = Vec::new();
        for part in rest.split(';').filter(|p| !p.trim().is_empty()) {
            let (k, v) = part
                .split_once('=')
                .ok_or_else(|| bad("setting", part, "expected key=value (keys: agents, team1, team2, R, balls)"))?;
            let k = k.trim();
            if keys.iter().any(|(old, _)| *old == k) {
                return Err(bad(k, v, "given twice"));
            }
            keys.push((k, v.trim()));
        }
        let get = |k: &str| keys.iter().find(|(key, _)| *key == k).map(|(_, v)| *v);
        let allowed: &[&str] = match kind {
            "team_reach" => &["agents", "R", "balls"],
            "team_sumo" => &["team1", "team2", "R"],
            _ => return Err(unknown()),
        };
        if let Some((k, v)) = keys.iter().find(|(k, _)| !allowed.contains(k)) {
            return Err(bad(k, v, &format!("unknown setting for {kind}; accepted: {}", allowed.join(", "))));
        }
        let spec = if kind == "team_reach" {
            let agents = parse_team("agents", get("agents").ok_or_else(|| bad("agents", "", "missing"))?)?;
            let radius = get("R").map(parse_radius).transpose()?.unwrap_or(5.0);
            let balls = match get("balls") {
                Some(v) => v.parse::<usize>().map_err(|_| bad("balls", v, "expected a whole number"))?,
                None => agents.len(),
            };
            TaskSpec::reach(&agents, radius, balls)?
        } else {
            let team1 = parse_team("team1", get("team1").ok_or_else(|| bad("team1", "", "missing"))?)?;
            let team2 = parse_team("team2", get("team2").ok_or_else(|| bad("team2", "", "missing"))?)?;
            let radius = get("R").map(parse_radius).transpose()?.unwrap_or(3.0);
            TaskSpec::sumo(&team1, &team2, radius)?
        };
        Ok(TaskSpec { name: name.to_string(), ..spec })
    }

    /// The morphology files the composition names ([`is_morphology_file`]), each once, in
    /// order of first appearance (team 0's agents first).
    pub fn morphology_files(&self) -> Vec<&str> {
        let mut files: Vec<&str> = Vec::new();
        for name in self.teams.iter().flatten().filter(|n| is_morphology_file(n)) {
            if !files.contains(&name.as_str()) {
                files.push(name);
            }
        }
        files
    }

    /// This composition with every morphology file name replaced by `rename(name)` (another
    /// path to the same file, say), the rest as it is; its `name` is the composition string
    /// that builds it. Errors when a new path cannot stand in a composition string (it holds
    /// `+` or `;`, or does not end in the same `.txt` or `.xml`).
    pub fn with_files_renamed(&self, rename: impl Fn(&str) -> String) -> Result<TaskSpec, TaskError> {
        let mut teams = self.teams.clone();
        for name in teams.iter_mut().flatten().filter(|n| is_morphology_file(n)) {
            let new = rename(name);
            if new.contains(['+', ';']) || new.trim() != new || new.rsplit('.').next() != name.rsplit('.').next() {
                return Err(bad(
                    "morphology path",
                    &new,
                    &format!(
                        "cannot stand for {name} in a composition string (no '+', ';' or surrounding spaces, the same extension)"
                    ),
                ));
            }
            *name = new;
        }
        let spec = match self.kind {
            TaskKind::Reach => TaskSpec::reach(&teams[0], self.radius, self.balls)?,
            TaskKind::Sumo => TaskSpec::sumo(&teams[0], &teams[1], self.radius)?,
        };
        Ok(TaskSpec { episode_steps: self.episode_steps, physics_steps: self.physics_steps, ..spec })
    }

    /// Checks the numbers: teams not empty, `R` finite and positive (Sumo: above 2 m, so
    /// that the start ring of radii 1 ..= min(2, R - 1) exists), Reach ball count in
    /// 1 ..= agents, Sumo exactly one ball. Morphology names are checked when the scene is
    /// built.
    pub fn validate(&self) -> Result<(), TaskError> {
        let n_teams = match self.kind {
            TaskKind::Reach => 1,
            TaskKind::Sumo => 2,
        };
        if self.teams.len() != n_teams {
            return Err(bad("teams", &self.teams.len().to_string(), &format!("this game has {n_teams} team(s)")));
        }
        if let Some(t) = self.teams.iter().position(|t| t.is_empty()) {
            return Err(bad(&format!("team{}", t + 1), "", "a team needs at least one agent"));
        }
        let agents = self.n_agents();
        if agents > MAX_AGENTS {
            let what = if self.kind == TaskKind::Reach { "agents" } else { "team1 + team2" };
            return Err(bad(
                what,
                &agents.to_string(),
                &format!("at most {MAX_AGENTS} agents in a scene (the collision pairs grow with their square)"),
            ));
        }
        let r = self.radius;
        let min_r = if self.kind == TaskKind::Sumo { 2.0 } else { 0.0 };
        if !r.is_finite() || r <= min_r || r > MAX_RADIUS {
            return Err(bad(
                "R",
                &format!("{r:?}"),
                &format!("must be a number of metres above {min_r}, at most {MAX_RADIUS}"),
            ));
        }
        match self.kind {
            TaskKind::Reach if self.balls == 0 || self.balls > agents => {
                return Err(bad("balls", &self.balls.to_string(), &format!("Team Reach needs 1 ..= {agents} balls")));
            }
            TaskKind::Sumo if self.balls != 1 => {
                return Err(bad("balls", &self.balls.to_string(), "Team Sumo has exactly one (centre) ball"));
            }
            _ => {}
        }
        if self.episode_steps == 0 || self.physics_steps == 0 {
            return Err(bad("episode length", &self.episode_steps.to_string(), "must be positive"));
        }
        Ok(())
    }

    /// Total number of agents.
    pub fn n_agents(&self) -> usize {
        self.teams.iter().map(|t| t.len()).sum()
    }

    /// Number of teams (1 for Reach, 2 for Sumo).
    pub fn n_teams(&self) -> usize {
        self.teams.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morphology_files_are_listed_once_and_renamed_into_a_composition_that_parses() {
        let spec = TaskSpec::from_name("team_sumo:team1=a/b.xml+ant+a/b.xml;team2=c.txt;R=3.25").unwrap();
        assert_eq!(spec.morphology_files(), ["a/b.xml", "c.txt"]);
        let moved = spec.with_files_renamed(|n| format!("/run/copies/{}", n.replace('/', "_"))).unwrap();
        assert_eq!(
            moved.name,
            "team_sumo:team1=/run/copies/a_b.xml+ant+/run/copies/a_b.xml;team2=/run/copies/c.txt;R=3.25"
        );
        let again = TaskSpec::from_name(&moved.name).unwrap();
        assert_eq!(again, moved);
        assert_eq!((again.radius, again.balls), (spec.radius, spec.balls));
        let reach = TaskSpec::from_name("team_reach:agents=x.xml+ant;R=4;balls=1").unwrap();
        assert_eq!(
            reach.with_files_renamed(|_| "y.xml".into()).unwrap().name,
            "team_reach:agents=y.xml+ant;R=4;balls=1"
        );
        assert!(TaskSpec::from_name("team_reach/1_ant").unwrap().morphology_files().is_empty());
        for bad in ["/a+b/x.xml", "/a;b/x.xml", "x.txt", " x.xml"] {
            let e = reach.with_files_renamed(|_| bad.to_string()).unwrap_err().to_string();
            assert!(e.contains(bad.trim()) && e.contains("x.xml"), "{e}");
        }
    }

    #[test]
    fn scenes_of_more_than_max_agents_are_refused_before_anything_is_built() {
        let many = vec!["ant"; MAX_AGENTS + 1].join("+");
        let e = TaskSpec::from_name(&format!("team_reach:agents={many};R=50;balls=1")).unwrap_err().to_string();
        assert_eq!(e, "bad agents \"257\": at most 256 agents in a scene (the collision pairs grow with their square)");
        let e = TaskSpec::from_name(&format!("team_sumo:team1={many};team2=ant")).unwrap_err().to_string();
        assert!(e.contains("team1 + team2") && e.contains("258"), "{e}");
    }

    #[test]
    fn arena_radii_beyond_the_limit_are_refused_naming_r() {
        for name in
            ["team_reach:agents=ant;R=1e160", "team_sumo:team1=ant;team2=ant;R=1e5", "team_reach:agents=ant;R=inf"]
        {
            let e = TaskSpec::from_name(name).unwrap_err().to_string();
            assert!(e.contains("R") && e.contains("at most 1000"), "{name}: {e}");
        }
        TaskSpec::from_name("team_reach:agents=ant;R=1000").unwrap();
    }
}
