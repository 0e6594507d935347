//! The paper-versus-here table of an experiment (`meben report DIR --paper FILE`): each of
//! the report's groups ([`crate::app::report::aggregate`]) beside the paper's figure for the same environment, model, start and
//! evaluation rotation, from a committed data file of the paper's figures
//! (`results/paper.toml`), written to `DIR/paper.md`. Nothing is typed by hand: the file is
//! generated from the runs' records and the data file alone, and `docs/RESULTS.md` quotes it.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::app::report::{GroupReport, StartKind};
use crate::error::{Result, RlError};

/// The paper's figures (the file's module docs, `results/paper.toml`).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PaperFigures {
    /// Every figure.
    pub figure: Vec<PaperFigure>,
}

/// One figure of the paper: a final success (or win) rate in percent.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PaperFigure {
    /// The paper's table (its `\label`).
    pub table: String,
    /// The environment (`team_reach/2_ants`).
    pub env: String,
    /// The model's name as this library names it.
    pub model: String,
    /// `random` (every start drawn at random, the default) or `fixed` (one fixed start).
    #[serde(default = "random_start")]
    pub start: String,
    /// The evaluation's rotation of the scene about the vertical, degrees.
    #[serde(default)]
    pub rotation_deg: i64,
    /// The mean over seeds, percent.
    pub mean: f64,
    /// The paper's `±` over seeds, percent.
    pub spread: f64,
    /// The paper's budget in env steps (default 50M, Team Reach's).
    #[serde(default = "paper_budget")]
    pub steps: u64,
}

fn random_start() -> String {
    "random".into()
}

fn paper_budget() -> u64 {
    50_000_000
}

impl PaperFigures {
    /// Reads and checks `path` (errors name the file and the field).
    pub fn load(path: &Path) -> Result<PaperFigures> {
        let text = std::fs::read_to_string(path).map_err(|e| RlError::file(path, e.to_string()))?;
        let figures: PaperFigures = toml::from_str(&text).map_err(|e| RlError::file(path, e.to_string()))?;
        for f in &figures.figure {
            if f.start != "random" && f.start != "fixed" {
                return Err(RlError::config(
                    path.display().to_string(),
                    "start",
                    &f.start,
                    "expected `random` or `fixed`",
                ));
            }
            if !(0.0..=100.0).contains(&f.mean) || !f.spread.is_finite() || f.spread < 0.0 {
                return Err(RlError::config(
                    path.display().to_string(),
                    "mean",
                    format!("{} ± {}", f.mean, f.spread),
                    format!("{} {}: a rate in percent with a non-negative spread", f.env, f.model),
                ));
            }
        }
        Ok(figures)
    }

    /// The figure for `env`, `model`, `start` and `rotation_deg`, if the paper has one.
    pub fn find(&self, env: &str, model: &str, start: &str, rotation_deg: i64) -> Option<&PaperFigure> {
        self.figure
            .iter()
            .find(|f| f.env == env && f.model == model && f.start == start && f.rotation_deg == rotation_deg)
    }
}

/// A percentage as the paper writes it: at least two decimals, more where the paper gives
/// more (`1.399`).
fn paper_number(x: f64) -> String {
    let two = format!("{x:.2}");
    if two.parse::<f64>() == Ok(x) { two } else { format!("{x}") }
}

/// Env steps in millions: two decimals (`20.15M`), none for whole millions (`50M`).
fn millions(steps: f64) -> String {
    if steps % 1e6 == 0.0 { format!("{}M", steps / 1e6) } else { format!("{:.2}M", steps / 1e6) }
}

/// Env steps reached by a group: its fewest (`10.16M`), and the budget when some run is
/// still short of it (`1.15M of 10M`: still training, or stopped).
fn steps_reached(g: &GroupReport) -> String {
    let reached = millions(g.env_steps.0 as f64);
    if g.env_steps.0 < g.target_steps { format!("{reached} of {}", millions(g.target_steps as f64)) } else { reached }
}

/// The table of the report's `groups` against `paper` (module docs), as Markdown. A Team
/// Reach group is matched by environment, model, rotation and start (`random (per slot)`,
/// the release's reset, matches the paper's `random` figures, which that reset produced);
/// Team Sumo's figures are not in the data file.
pub fn paper_table(groups: &[GroupReport], paper: &PaperFigures) -> String {
    let mut out = String::from(
        "| env | model | start | evaluated | here: % (mean ± s.e.) | seeds | env steps | paper: % (mean ± its spread) | \
         paper's env steps | paper's table |\n|---|---|---|---|---:|---:|---:|---:|---:|---|\n",
    );
    for g in groups {
        let what = if g.metric.starts_with("eval_win_rate") { "win" } else { "success" };
        let model =
            if g.opponent.is_empty() { format!("`{}`", g.model) } else { format!("`{}` vs `{}`", g.model, g.opponent) };
        let rotation = g.rotation_deg as i64;
        let evaluated = if rotation == 0 { what.to_string() } else { format!("{what}, rotated {rotation}°") };
        let key = if g.start == StartKind::Fixed { "fixed" } else { "random" };
        let figure = if g.opponent.is_empty() { paper.find(&g.env, &g.model, key, rotation) } else { None };
        let (p, p_steps, p_table) = match figure {
            Some(f) => (
                format!("{} ± {}", paper_number(f.mean), paper_number(f.spread)),
                millions(f.steps as f64),
                f.table.clone(),
            ),
            None => ("–".into(), "–".into(), "not in the paper's tables".into()),
        };
        out.push_str(&format!(
            "| `{}` | {model} | {} | {evaluated} | {:.2} ± {:.2} | {} | {} | {p} | {p_steps} | {p_table} |\n",
            g.env,
            g.start.label(),
            g.mean,
            g.se,
            g.runs.len(),
            steps_reached(g)
        ));
    }
    out
}

/// Writes [`paper_table`] of the report's `groups` to `root/paper.md` (atomically) and
/// returns its path.
pub fn write_paper_table(root: &Path, groups: &[GroupReport], paper_file: &Path) -> Result<PathBuf> {
    let paper = PaperFigures::load(paper_file)?;
    let path = root.join("paper.md");
    nn::write_atomic(&path, paper_table(groups, &paper).as_bytes()).map_err(|e| RlError::file(&path, e.to_string()))?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<PaperFigures> {
        static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!("meben-paper-{}-{call}.toml", std::process::id()));
        std::fs::write(&path, text).unwrap();
        let r = PaperFigures::load(&path);
        std::fs::remove_file(&path).unwrap();
        r
    }

    #[test]
    fn figures_default_to_random_starts_unrotated_at_50m_and_are_found_by_all_four_keys() {
        let p = parse("[[figure]]\ntable = \"t\"\nenv = \"e\"\nmodel = \"m\"\nmean = 5.0\nspread = 1.399\n").unwrap();
        assert_eq!(
            (p.figure[0].start.as_str(), p.figure[0].rotation_deg, p.figure[0].steps),
            ("random", 0, 50_000_000)
        );
        assert!(p.find("e", "m", "random", 0).is_some());
        assert!(p.find("e", "m", "fixed", 0).is_none() && p.find("e", "m", "random", 180).is_none());
        assert_eq!(
            (paper_number(5.0), paper_number(1.399), paper_number(15.5)),
            ("5.00".into(), "1.399".into(), "15.50".into())
        );
        assert_eq!((millions(50e6), millions(20_152_320.0)), ("50M".to_string(), "20.15M".to_string()));
    }

    #[test]
    fn unknown_fields_starts_and_rates_are_errors_naming_them() {
        let e = parse("[[figure]]\ntable = \"t\"\nenv = \"e\"\nmodel = \"m\"\nmean = 5.0\nspread = 1.0\nseeds = 3\n");
        assert!(e.unwrap_err().to_string().contains("seeds"));
        let e = parse(
            "[[figure]]\ntable = \"t\"\nenv = \"e\"\nmodel = \"m\"\nstart = \"rotated\"\nmean = 5.0\nspread = 1.0\n",
        );
        assert!(e.unwrap_err().to_string().contains("rotated"));
        let e = parse("[[figure]]\ntable = \"t\"\nenv = \"e\"\nmodel = \"m\"\nmean = 500.0\nspread = 1.0\n");
        assert!(e.unwrap_err().to_string().contains("500"));
    }

    fn group(model: &str, start: StartKind, steps: (u64, u64)) -> GroupReport {
        GroupReport {
            env: "team_reach/1_ant".into(),
            model: model.into(),
            opponent: String::new(),
            variant: format!("team_reach_1_ant/{model}"),
            label: model.into(),
            metric: "eval_success_rate".into(),
            rotation_deg: 0.0,
            start,
            from_train: false,
            runs: vec!["seed0".into(), "seed1".into()],
            seed_list: vec![0, 1],
            finals: vec![10.0, 20.0],
            final_steps: vec![steps.0, steps.0],
            mean: 15.0,
            se: 5.0,
            iqm: 15.0,
            mean_ci: (10.0, 20.0),
            iqm_ci: (10.0, 20.0),
            draw: None,
            lose: None,
            env_steps: steps,
            target_steps: 10_000_000,
            machine_hours: 1.0,
            curve: Vec::new(),
            curve_lose: Vec::new(),
            curve_draw: Vec::new(),
        }
    }

    #[test]
    fn groups_meet_the_figure_of_their_start_and_unfinished_ones_say_their_budget() {
        let p = parse(
            "[[figure]]\ntable = \"r\"\nenv = \"team_reach/1_ant\"\nmodel = \"shnn\"\nmean = 60.0\nspread = 3.0\n\
             [[figure]]\ntable = \"f\"\nenv = \"team_reach/1_ant\"\nmodel = \"shnn\"\nstart = \"fixed\"\nmean = 70.0\nspread = 4.0\n",
        )
        .unwrap();
        let groups = [
            group("shnn", StartKind::Fixed, (10_158_080, 10_158_080)),
            group("shnn", StartKind::RandomPerSlot, (1_146_880, 10_158_080)),
            group("mlp", StartKind::Random, (10_158_080, 10_158_080)),
        ];
        let table = paper_table(&groups, &p);
        let rows: Vec<&str> = table.lines().skip(2).collect();
        assert_eq!(rows.len(), 3);
        assert_eq!(
            rows[0],
            "| `team_reach/1_ant` | `shnn` | fixed | success | 15.00 ± 5.00 | 2 | 10.16M | 70.00 ± 4.00 | 50M | f |"
        );
        assert_eq!(
            rows[1],
            "| `team_reach/1_ant` | `shnn` | random (per slot) | success | 15.00 ± 5.00 | 2 | 1.15M of 10M | \
             60.00 ± 3.00 | 50M | r |"
        );
        assert!(rows[2].ends_with("| – | – | not in the paper's tables |"), "{}", rows[2]);
    }
}
