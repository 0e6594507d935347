//! The paper-versus-here table of an experiment (`meben report DIR --paper FILE`): each group
//! of `DIR/report.csv` beside the paper's figure for the same environment, model, start and
//! evaluation rotation, from a committed data file of the paper's figures
//! (`results/paper.toml`), written to `DIR/paper.md`. Nothing is typed by hand: the file is
//! generated from the report and the data file alone, and `docs/RESULTS.md` quotes it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

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

/// One group of `report.csv`, the columns this table reads.
struct Group {
    env: String,
    model: String,
    opponent: String,
    variant: String,
    metric: String,
    seeds: String,
    mean: f64,
    se: f64,
    steps: f64,
    rotation_deg: i64,
}

/// The groups of `DIR/report.csv`, read by column name.
fn read_groups(csv: &Path) -> Result<Vec<Group>> {
    let text = std::fs::read_to_string(csv).map_err(|e| RlError::file(csv, e.to_string()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let column = |name: &str| {
        header.iter().position(|h| *h == name).ok_or_else(|| RlError::file(csv, format!("no column `{name}`")))
    };
    let cols = [
        "env",
        "model",
        "opponent",
        "variant",
        "metric",
        "seeds",
        "mean_pct",
        "se_pct",
        "env_steps_min",
        "rotation_deg",
    ]
    .map(column);
    let mut at = [0usize; 10];
    for (a, c) in at.iter_mut().zip(cols) {
        *a = c?;
    }
    let mut out = Vec::new();
    for (i, line) in lines.enumerate() {
        let cells: Vec<&str> = line.split(',').collect();
        let cell = |k: usize| cells.get(at[k]).copied().unwrap_or_default();
        let number = |k: usize| {
            cell(k).parse::<f64>().map_err(|_| {
                RlError::file(csv, format!("line {}: column `{}` is `{}`, not a number", i + 2, header[at[k]], cell(k)))
            })
        };
        out.push(Group {
            env: cell(0).into(),
            model: cell(1).into(),
            opponent: cell(2).into(),
            variant: cell(3).into(),
            metric: cell(4).into(),
            seeds: cell(5).into(),
            mean: number(6)?,
            se: number(7)?,
            steps: number(8)?,
            rotation_deg: number(9)? as i64,
        });
    }
    Ok(out)
}

/// The start of the group's runs (their `config.toml`): `fixed` (`fixed_start`), `random`,
/// or `random (per slot)` (`train_starts = "per_slot"`, the release's reset; matched with
/// the paper's `random` figures, which the release's reset produced).
fn group_start(root: &Path, variant: &str) -> Result<&'static str> {
    let dir = root.join(variant);
    let mut runs: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map_err(|e| RlError::file(&dir, e.to_string()))?
        .filter_map(|e| e.ok().map(|e| e.path().join("config.toml")))
        .filter(|p| p.is_file())
        .collect();
    runs.sort();
    let path = runs.first().ok_or_else(|| RlError::file(&dir, "no run with a config.toml"))?;
    let text = std::fs::read_to_string(path).map_err(|e| RlError::file(path, e.to_string()))?;
    let table: toml::Table = text.parse().map_err(|e: toml::de::Error| RlError::file(path, e.to_string()))?;
    Ok(if table.get("fixed_start").and_then(toml::Value::as_bool) == Some(true) {
        "fixed"
    } else if table.get("train_starts").and_then(toml::Value::as_str) == Some("per_slot") {
        "random (per slot)"
    } else {
        "random"
    })
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

/// The table for the report of `root` against `paper` (module docs), as Markdown.
pub fn paper_table(root: &Path, paper: &PaperFigures) -> Result<String> {
    let groups = read_groups(&root.join("report.csv"))?;
    let mut starts: BTreeMap<String, &'static str> = BTreeMap::new();
    let mut out = String::from(
        "| env | model | start | evaluated | here: % (mean ± s.e.) | seeds | env steps | paper: % (mean ± its spread) | \
         paper's env steps | paper's table |\n|---|---|---|---|---:|---:|---:|---:|---:|---|\n",
    );
    for g in &groups {
        let start = match starts.get(&g.variant) {
            Some(s) => *s,
            None => {
                let s = group_start(root, &g.variant)?;
                starts.insert(g.variant.clone(), s);
                s
            }
        };
        let what = if g.metric.starts_with("eval_win_rate") { "win" } else { "success" };
        let model =
            if g.opponent.is_empty() { format!("`{}`", g.model) } else { format!("`{}` vs `{}`", g.model, g.opponent) };
        let evaluated =
            if g.rotation_deg == 0 { what.to_string() } else { format!("{what}, rotated {}°", g.rotation_deg) };
        let key = if start == "fixed" { "fixed" } else { "random" };
        let figure = if g.opponent.is_empty() { paper.find(&g.env, &g.model, key, g.rotation_deg) } else { None };
        let (p, p_steps, p_table) = match figure {
            Some(f) => (
                format!("{} ± {}", paper_number(f.mean), paper_number(f.spread)),
                millions(f.steps as f64),
                f.table.clone(),
            ),
            None => ("–".into(), "–".into(), "not in the paper's tables".into()),
        };
        out.push_str(&format!(
            "| `{}` | {model} | {start} | {evaluated} | {:.2} ± {:.2} | {} | {} | {p} | {p_steps} | {p_table} |\n",
            g.env,
            g.mean,
            g.se,
            g.seeds,
            millions(g.steps)
        ));
    }
    Ok(out)
}

/// Writes [`paper_table`] to `root/paper.md` (atomically) and returns its path.
pub fn write_paper_table(root: &Path, paper_file: &Path) -> Result<PathBuf> {
    let paper = PaperFigures::load(paper_file)?;
    let table = paper_table(root, &paper)?;
    let path = root.join("paper.md");
    nn::write_atomic(&path, table.as_bytes()).map_err(|e| RlError::file(&path, e.to_string()))?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<PaperFigures> {
        let dir = std::env::temp_dir().join(format!("meben-paper-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(format!("paper-{}.toml", text.len()));
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
}
