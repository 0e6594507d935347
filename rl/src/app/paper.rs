//! The paper-versus-here tables of an experiment (`meben report DIR --paper FILE`), from a
//! committed data file of the paper's figures and claims (`results/paper.toml`), written to
//! `DIR/paper.md`. Nothing is typed by hand: the file is generated from the runs' records
//! and the data file alone, and `docs/RESULTS.md` quotes it.
//!
//! - The figures: each of the report's groups ([`crate::app::report::aggregate`]) beside the
//!   paper's figure for the same environment, model, start and evaluation rotation. Both
//!   sides are a mean ± a standard deviation over seeds, with the seed counts of both: the
//!   paper runs 10 seeds and its `±` is a standard deviation (`results/paper.toml` says how
//!   that is known). Ours also gives the 95% percentile-bootstrap interval of its mean
//!   ([`crate::app::report::stats::bootstrap_ci`]).
//! - The claims: each claim of the data file that the report's groups can test, "`A` above
//!   `B`" in the paper's order (in Team Sumo: team 0 wins more often than team 1), with
//!   the verdict of the rule below ([`verdict`]).
//!
//! The verdict rule, the one every verdict of `docs/RESULTS.md` and the README follows:
//! - **reproduced**: our means order as the paper's, our two 95% intervals of the mean do
//!   not overlap (A's lies wholly above B's), and each of the paper's two means lies inside
//!   our interval for the same model;
//! - **consistent in the mean**: our means order as the paper's, and not all of the above
//!   holds;
//! - **differs**: otherwise (our means in the other order, or equal);
//! - **single run**: either side has a single run (Team Sumo here), whatever its values.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::app::report::{GroupReport, StartKind, md_cell};
use crate::error::{Result, RlError};

/// The paper's figures and claims (the file's module docs, `results/paper.toml`).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PaperFigures {
    /// The seeds behind each of the paper's figures (10).
    pub seeds: u32,
    /// Every figure.
    pub figure: Vec<PaperFigure>,
    /// The paper's claims of order (none by default).
    #[serde(default)]
    pub claim: Vec<PaperClaim>,
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
    /// The paper's `±` over seeds: a standard deviation, percent.
    pub sd: f64,
    /// The paper's budget in env steps (default 50M, Team Reach's).
    #[serde(default = "paper_budget")]
    pub steps: u64,
}

/// One claim of the paper: in an environment and start, `above` ends above `below`. In
/// Team Sumo: `above`, trained as team 0 against `below` as team 1, wins more often than
/// it loses.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PaperClaim {
    /// The environment (`team_reach/2_ants`, `team_sumo/2_ants`).
    pub env: String,
    /// `random` (the default) or `fixed`, as [`PaperFigure::start`].
    #[serde(default = "random_start")]
    pub start: String,
    /// The side the paper puts higher.
    pub above: ClaimSide,
    /// The side the paper puts lower.
    pub below: ClaimSide,
}

/// One side of a [`PaperClaim`]: a model evaluated at a rotation.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ClaimSide {
    /// The model's name as this library names it.
    pub model: String,
    /// The evaluation's rotation, degrees (default 0; ignored in Team Sumo).
    #[serde(default)]
    pub rotation_deg: i64,
}

fn random_start() -> String {
    "random".into()
}

fn paper_budget() -> u64 {
    50_000_000
}

fn is_sumo(env: &str) -> bool {
    env.starts_with("team_sumo")
}

fn check_start(path: &Path, start: &str) -> Result<()> {
    if start == "random" || start == "fixed" {
        return Ok(());
    }
    Err(RlError::config(path.display().to_string(), "start", start, "expected `random` or `fixed`"))
}

impl PaperFigures {
    /// Reads and checks `path` (errors name the file and the field): rates in percent,
    /// non-negative standard deviations, at least one seed, and each claim in the order of
    /// the paper's figures where it has both.
    pub fn load(path: &Path) -> Result<PaperFigures> {
        let text = crate::bounded_read::read_text(
            path,
            crate::mappo::config::MAX_CONFIG_BYTES,
            "the paper's figures (a TOML file)",
        )?;
        let figures: PaperFigures = toml::from_str(&text).map_err(|e| RlError::file(path, e.to_string()))?;
        let source = || path.display().to_string();
        if figures.seeds == 0 {
            return Err(RlError::config(source(), "seeds", 0, "at least one seed"));
        }
        figures.check_one_line(path)?;
        for f in &figures.figure {
            check_start(path, &f.start)?;
            if !(0.0..=100.0).contains(&f.mean) || !f.sd.is_finite() || f.sd < 0.0 {
                return Err(RlError::config(
                    source(),
                    "mean",
                    format!("{} ± {}", f.mean, f.sd),
                    format!("{} {}: a rate in percent with a non-negative standard deviation", f.env, f.model),
                ));
            }
        }
        for c in &figures.claim {
            check_start(path, &c.start)?;
            if let (Some(a), Some(b)) = (figures.claim_figure(c, &c.above), figures.claim_figure(c, &c.below))
                && a.mean <= b.mean
            {
                return Err(RlError::config(
                    source(),
                    "claim",
                    format!("{} above {}", c.above.model, c.below.model),
                    format!("{}: the paper's figures are {} and {}, not in that order", c.env, a.mean, b.mean),
                ));
            }
        }
        Ok(figures)
    }

    /// Refuses a line break in any text of the file (it would end a row of `paper.md`'s
    /// tables), naming the file, the field and the value; a `|` is escaped where written.
    fn check_one_line(&self, path: &Path) -> Result<()> {
        let mut texts: Vec<(String, &str)> = Vec::new();
        for (i, f) in self.figure.iter().enumerate() {
            for (key, v) in [("table", &f.table), ("env", &f.env), ("model", &f.model), ("start", &f.start)] {
                texts.push((format!("figure[{i}].{key}"), v));
            }
        }
        for (i, c) in self.claim.iter().enumerate() {
            for (key, v) in [("env", &c.env), ("start", &c.start), ("above.model", &c.above.model)] {
                texts.push((format!("claim[{i}].{key}"), v));
            }
            texts.push((format!("claim[{i}].below.model"), &c.below.model));
        }
        match texts.into_iter().find(|(_, v)| v.contains(['\n', '\r'])) {
            Some((field, value)) => Err(RlError::config(
                path.display().to_string(),
                &field,
                value,
                "a line break would end a row of paper.md's tables: write it on one line",
            )),
            None => Ok(()),
        }
    }

    /// The figure for `env`, `model`, `start` and `rotation_deg`, if the paper has one.
    pub fn find(&self, env: &str, model: &str, start: &str, rotation_deg: i64) -> Option<&PaperFigure> {
        self.figure
            .iter()
            .find(|f| f.env == env && f.model == model && f.start == start && f.rotation_deg == rotation_deg)
    }

    /// The paper's figure for one side of `claim`, if it has one.
    fn claim_figure(&self, claim: &PaperClaim, side: &ClaimSide) -> Option<&PaperFigure> {
        self.find(&claim.env, &side.model, &claim.start, side.rotation_deg)
    }
}

/// What the rule ([`verdict`], module docs) says of one claim.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Our means order as the paper's, with 95% intervals apart, each holding the paper's mean.
    Reproduced,
    /// Our means order as the paper's; not all the rest holds.
    ConsistentInTheMean,
    /// Our means do not order as the paper's.
    Differs,
    /// A side has a single run.
    SingleRun,
}

impl Verdict {
    /// As the tables write it: `reproduced`, `consistent in the mean`, `differs`, `single run`.
    pub fn label(self) -> &'static str {
        match self {
            Verdict::Reproduced => "reproduced",
            Verdict::ConsistentInTheMean => "consistent in the mean",
            Verdict::Differs => "differs",
            Verdict::SingleRun => "single run",
        }
    }
}

/// One side of a claim as measured here: our mean and its 95% interval over `runs` runs,
/// and the paper's mean for it if the paper gives one (percent).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measured {
    /// Our mean over the runs.
    pub mean: f64,
    /// Our 95% percentile-bootstrap interval of the mean, `(low, high)`.
    pub ci: (f64, f64),
    /// Our runs (seeds).
    pub runs: usize,
    /// The paper's mean, if it gives one.
    pub paper_mean: Option<f64>,
}

impl Measured {
    /// Whether the paper's mean lies inside our interval (`None` without a paper figure).
    pub fn holds_paper_mean(&self) -> Option<bool> {
        self.paper_mean.map(|p| self.ci.0 <= p && p <= self.ci.1)
    }
}

/// Whether our means order as the paper's: `above`'s strictly higher.
pub fn means_in_order(above: &Measured, below: &Measured) -> bool {
    above.mean > below.mean
}

/// Whether our 95% intervals do not overlap, `above`'s wholly above `below`'s.
pub fn intervals_apart(above: &Measured, below: &Measured) -> bool {
    above.ci.0 > below.ci.1
}

/// The verdict on the claim "`above` ends above `below`" (the rule of the module docs).
pub fn verdict(above: &Measured, below: &Measured) -> Verdict {
    if above.runs < 2 || below.runs < 2 {
        Verdict::SingleRun
    } else if !means_in_order(above, below) {
        Verdict::Differs
    } else if intervals_apart(above, below)
        && above.holds_paper_mean() == Some(true)
        && below.holds_paper_mean() == Some(true)
    {
        Verdict::Reproduced
    } else {
        Verdict::ConsistentInTheMean
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

/// The paper's key for a group's start: `random (per slot)`, the release's reset, matches
/// the paper's `random` figures, which that reset produced.
fn start_key(g: &GroupReport) -> &'static str {
    if g.start == StartKind::Fixed { "fixed" } else { "random" }
}

/// The name of a sweep's named variant in a group's run path (`<env>/<model>+<variant>`,
/// [`crate::app::sweep`]), which changes configuration fields that the model does not show.
fn sweep_variant(path: &str) -> Option<&str> {
    path.rsplit('/').next().and_then(|last| last.split_once('+')).map(|(_, variant)| variant)
}

/// The table of the report's `groups` against the paper's figures (module docs), as
/// Markdown. A Team Reach group is matched by environment, model, rotation and start (see
/// [`start_key`]); Team Sumo's figures are not in the data file.
fn figures_table(groups: &[GroupReport], paper: &PaperFigures) -> String {
    let mut out = String::from(
        "| env | model | start | evaluated | here: % (mean ± s.d.) | here: mean's 95% CI | seeds | env steps | \
         paper: % (mean ± s.d.) | paper's seeds | paper's env steps | paper's table |\n\
         |---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---|\n",
    );
    for g in groups {
        let what = if g.metric.starts_with("eval_win_rate") { "win" } else { "success" };
        let mut model = if g.opponent.is_empty() {
            format!("`{}`", md_cell(&g.model))
        } else {
            format!("`{}` vs `{}`", md_cell(&g.model), md_cell(&g.opponent))
        };
        if let Some(variant) = sweep_variant(&g.variant) {
            model.push_str(&format!(", variant `{}`", md_cell(variant)));
        }
        let rotation = g.rotation_deg as i64;
        let evaluated = if rotation == 0 { what.to_string() } else { format!("{what}, rotated {rotation}°") };
        let figure = if g.opponent.is_empty() { paper.find(&g.env, &g.model, start_key(g), rotation) } else { None };
        let (p, p_seeds, p_steps, p_table) = match figure {
            Some(f) => (
                format!("{} ± {}", paper_number(f.mean), paper_number(f.sd)),
                paper.seeds.to_string(),
                millions(f.steps as f64),
                md_cell(&f.table),
            ),
            None => ("–".into(), "–".into(), "–".into(), "not in the paper's tables".into()),
        };
        let (here, ci) = if g.runs.len() < 2 {
            (format!("{:.2} (one run)", g.mean), "–".to_string())
        } else {
            (format!("{:.2} ± {:.2}", g.mean, g.sd), format!("[{:.2}, {:.2}]", g.mean_ci.0, g.mean_ci.1))
        };
        out.push_str(&format!(
            "| `{}` | {model} | {} | {evaluated} | {here} | {ci} | {} | {} | {p} | {p_seeds} | {p_steps} | {p_table} |\n",
            md_cell(&g.env),
            g.start.label(),
            g.runs.len(),
            steps_reached(g)
        ));
    }
    out
}

/// A claim of `paper` tested by two measured sides, with the cells that name them.
struct ClaimRow {
    claim: String,
    above: Measured,
    below: Measured,
}

/// The claims of `paper` that `groups` can test: one row per pair of matching groups.
fn claim_rows(groups: &[GroupReport], paper: &PaperFigures) -> Vec<ClaimRow> {
    let mut rows = Vec::new();
    for c in &paper.claim {
        if is_sumo(&c.env) {
            // Team 0 `above` against team 1 `below`: its win rate against its loss rate.
            for g in groups.iter().filter(|g| g.env == c.env && g.model == c.above.model && g.opponent == c.below.model)
            {
                let (Some((lose, _)), Some(lose_ci)) = (g.lose, g.lose_ci) else { continue };
                let runs = g.runs.len();
                rows.push(ClaimRow {
                    claim: format!(
                        "`{}` (team 0) wins more often than `{}` (team 1), trained against each other \
                         (`{}`, {} start)",
                        c.above.model,
                        c.below.model,
                        c.env,
                        g.start.label()
                    ),
                    above: Measured { mean: g.mean, ci: g.mean_ci, runs, paper_mean: None },
                    below: Measured { mean: lose, ci: lose_ci, runs, paper_mean: None },
                });
            }
            continue;
        }
        let matches = |side: &ClaimSide| {
            groups
                .iter()
                .filter(|g| {
                    g.env == c.env
                        && g.model == side.model
                        && g.opponent.is_empty()
                        && start_key(g) == c.start
                        && g.rotation_deg as i64 == side.rotation_deg
                })
                .collect::<Vec<_>>()
        };
        let rotated = c.above.rotation_deg != 0 || c.below.rotation_deg != 0;
        let name = |side: &ClaimSide| {
            if !rotated {
                format!("`{}`", side.model)
            } else if side.rotation_deg == 0 {
                format!("`{}` at 0°", side.model)
            } else {
                format!("`{}` rotated {}°", side.model, side.rotation_deg)
            }
        };
        let measured = |g: &GroupReport, side: &ClaimSide| Measured {
            mean: g.mean,
            ci: g.mean_ci,
            runs: g.runs.len(),
            paper_mean: paper.claim_figure(c, side).map(|f| f.mean),
        };
        for a in matches(&c.above) {
            for b in matches(&c.below) {
                rows.push(ClaimRow {
                    claim: format!(
                        "{} above {} (`{}`, {} start)",
                        name(&c.above),
                        name(&c.below),
                        c.env,
                        a.start.label()
                    ),
                    above: measured(a, &c.above),
                    below: measured(b, &c.below),
                });
            }
        }
    }
    rows
}

/// A measured side as a cell: `97.33 [95.51, 98.44]`, or `78.52 (one run)`.
fn measured_cell(m: &Measured) -> String {
    if m.runs < 2 {
        format!("{:.2} (one run)", m.mean)
    } else {
        format!("{:.2} [{:.2}, {:.2}]", m.mean, m.ci.0, m.ci.1)
    }
}

fn yes_no(b: bool) -> &'static str {
    if b { "yes" } else { "no" }
}

/// The table of the claims `groups` can test, with each condition of the rule and its
/// verdict (module docs); empty when there are none.
fn claims_table(groups: &[GroupReport], paper: &PaperFigures) -> String {
    let rows = claim_rows(groups, paper);
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from(
        "| the paper's claim | here: upper side, % mean [95% CI] | here: lower side, % mean [95% CI] | \
         paper: % means | our means in the paper's order | our 95% intervals apart | the paper's means inside \
         ours | verdict |\n|---|---:|---:|---:|---|---|---|---|\n",
    );
    for r in &rows {
        let single = r.above.runs < 2 || r.below.runs < 2;
        let paper_means = match (r.above.paper_mean, r.below.paper_mean) {
            (Some(a), Some(b)) => format!("{}, {}", paper_number(a), paper_number(b)),
            _ => "–".into(),
        };
        let apart = if single { "– (one run)" } else { yes_no(intervals_apart(&r.above, &r.below)) };
        let inside = match (single, r.above.holds_paper_mean(), r.below.holds_paper_mean()) {
            (true, _, _) => "– (one run)".to_string(),
            (false, Some(a), Some(b)) => format!(
                "{}: {}; {}: {}",
                paper_number(r.above.paper_mean.unwrap_or_default()),
                yes_no(a),
                paper_number(r.below.paper_mean.unwrap_or_default()),
                yes_no(b)
            ),
            _ => "– (no figure)".to_string(),
        };
        out.push_str(&format!(
            "| {} | {} | {} | {paper_means} | {} | {apart} | {inside} | {} |\n",
            md_cell(&r.claim),
            measured_cell(&r.above),
            measured_cell(&r.below),
            yes_no(means_in_order(&r.above, &r.below)),
            verdict(&r.above, &r.below).label()
        ));
    }
    out
}

/// The tables of the report's `groups` against `paper` (module docs), as Markdown: the
/// figures, then the claims the groups test, if any, after a blank line.
pub fn paper_table(groups: &[GroupReport], paper: &PaperFigures) -> String {
    let mut out = figures_table(groups, paper);
    let claims = claims_table(groups, paper);
    if !claims.is_empty() {
        out.push('\n');
        out.push_str(&claims);
    }
    out
}

/// Writes [`paper_table`] of the report's `groups` against `paper` (read by
/// [`PaperFigures::load`] before the report is written: `meben report --paper`) to
/// `root/paper.md` (atomically) and returns its path.
pub fn write_paper_table(root: &Path, groups: &[GroupReport], paper: &PaperFigures) -> Result<PathBuf> {
    let path = root.join("paper.md");
    nn::write_atomic(&path, paper_table(groups, paper).as_bytes()).map_err(|e| RlError::file(&path, e.to_string()))?;
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

    const FIGURE: &str = "[[figure]]\ntable = \"t\"\nenv = \"e\"\nmodel = \"m\"\n";

    #[test]
    fn figures_default_to_random_starts_unrotated_at_50m_and_are_found_by_all_four_keys() {
        let p = parse(&format!("seeds = 10\n{FIGURE}mean = 5.0\nsd = 1.399\n")).unwrap();
        assert_eq!(p.seeds, 10);
        assert!(p.claim.is_empty());
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
    fn unknown_fields_starts_rates_seeds_and_claims_against_the_figures_are_errors_naming_them() {
        // The old name of the standard deviation, `spread`, is refused.
        let e = parse(&format!("seeds = 10\n{FIGURE}mean = 5.0\nspread = 1.0\n"));
        assert!(e.unwrap_err().to_string().contains("spread"));
        let e = parse(&format!("{FIGURE}mean = 5.0\nsd = 1.0\n"));
        assert!(e.unwrap_err().to_string().contains("seeds"), "the seed count is required");
        let e = parse(&format!("seeds = 0\n{FIGURE}mean = 5.0\nsd = 1.0\n"));
        assert!(e.unwrap_err().to_string().contains("seeds"));
        let e = parse(&format!("seeds = 10\n{FIGURE}start = \"rotated\"\nmean = 5.0\nsd = 1.0\n"));
        assert!(e.unwrap_err().to_string().contains("rotated"));
        let e = parse(&format!("seeds = 10\n{FIGURE}mean = 500.0\nsd = 1.0\n"));
        assert!(e.unwrap_err().to_string().contains("500"));
        // A claim the paper's own figures contradict.
        let two = "seeds = 10\n[[figure]]\ntable = \"t\"\nenv = \"e\"\nmodel = \"a\"\nmean = 5.0\nsd = 1.0\n\
                   [[figure]]\ntable = \"t\"\nenv = \"e\"\nmodel = \"b\"\nmean = 50.0\nsd = 1.0\n";
        let e =
            parse(&format!("{two}[[claim]]\nenv = \"e\"\nabove = {{ model = \"a\" }}\nbelow = {{ model = \"b\" }}\n"));
        assert!(e.unwrap_err().to_string().contains("not in that order"));
        let ok =
            parse(&format!("{two}[[claim]]\nenv = \"e\"\nabove = {{ model = \"b\" }}\nbelow = {{ model = \"a\" }}\n"));
        let claim = &ok.unwrap().claim[0];
        assert_eq!((claim.start.as_str(), claim.above.rotation_deg), ("random", 0));
    }

    fn side(mean: f64, ci: (f64, f64), runs: usize, paper_mean: Option<f64>) -> Measured {
        Measured { mean, ci, runs, paper_mean }
    }

    #[test]
    fn the_verdict_rule_has_four_answers() {
        // Reproduced: in order, intervals apart, each paper mean inside ours.
        let hi = side(97.0, (95.0, 99.0), 3, Some(97.26));
        let lo = side(82.0, (77.0, 85.0), 3, Some(80.0));
        assert_eq!(verdict(&hi, &lo), Verdict::Reproduced);
        // Consistent in the mean: one paper mean outside ours (the 1_ant pair: 93.39).
        let lo_off = side(82.0, (77.0, 85.0), 3, Some(93.39));
        assert_eq!(verdict(&hi, &lo_off), Verdict::ConsistentInTheMean);
        // ... intervals overlapping (the 2_ants pair), or no paper figure to hold.
        let lo_wide = side(67.0, (7.9, 99.7), 3, Some(5.25));
        assert_eq!(verdict(&hi, &lo_wide), Verdict::ConsistentInTheMean);
        let lo_bare = side(82.0, (77.0, 85.0), 3, None);
        assert_eq!(verdict(&hi, &lo_bare), Verdict::ConsistentInTheMean);
        // Intervals that touch overlap.
        let touching = side(82.0, (77.0, 95.0), 3, Some(80.0));
        assert_eq!(verdict(&hi, &touching), Verdict::ConsistentInTheMean);
        // Differs: our means in the other order, or equal.
        assert_eq!(verdict(&lo, &hi), Verdict::Differs);
        assert_eq!(verdict(&hi, &hi), Verdict::Differs);
        // Single run: a side with one run, whatever its values.
        let one = side(78.52, (78.52, 78.52), 1, None);
        assert_eq!(verdict(&one, &side(5.27, (5.27, 5.27), 1, None)), Verdict::SingleRun);
        assert_eq!(verdict(&hi, &side(99.0, (99.0, 99.0), 1, None)), Verdict::SingleRun);
        assert_eq!(
            [Verdict::Reproduced, Verdict::ConsistentInTheMean, Verdict::Differs, Verdict::SingleRun]
                .map(Verdict::label),
            ["reproduced", "consistent in the mean", "differs", "single run"]
        );
        assert_eq!(
            (hi.holds_paper_mean(), lo_off.holds_paper_mean(), lo_bare.holds_paper_mean()),
            (Some(true), Some(false), None)
        );
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
            sd: 7.07,
            iqm: 15.0,
            mean_ci: (10.0, 20.0),
            iqm_ci: (10.0, 20.0),
            draw: None,
            lose: None,
            lose_ci: None,
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
            "seeds = 10\n[[figure]]\ntable = \"r\"\nenv = \"team_reach/1_ant\"\nmodel = \"shnn\"\nmean = 60.0\nsd = 3.0\n\
             [[figure]]\ntable = \"f\"\nenv = \"team_reach/1_ant\"\nmodel = \"shnn\"\nstart = \"fixed\"\nmean = 70.0\nsd = 4.0\n",
        )
        .unwrap();
        let mut single = group("mlp", StartKind::Random, (10_158_080, 10_158_080));
        single.runs.truncate(1);
        // A sweep's named variant (run paths `<env>/<model>+<variant>/seed<N>`) is named.
        let mut variant = group("shnn:assignment=learned", StartKind::Random, (10_158_080, 10_158_080));
        variant.variant = "team_reach_1_ant/shnn_assignment-learned+no_assignment_bonus".into();
        let groups = [
            group("shnn", StartKind::Fixed, (10_158_080, 10_158_080)),
            group("shnn", StartKind::RandomPerSlot, (1_146_880, 10_158_080)),
            single,
            variant,
        ];
        let table = paper_table(&groups, &p);
        assert!(table.starts_with(
            "| env | model | start | evaluated | here: % (mean ± s.d.) | here: mean's 95% CI | seeds | env steps | \
             paper: % (mean ± s.d.) | paper's seeds |"
        ));
        let rows: Vec<&str> = table.lines().skip(2).collect();
        assert_eq!(rows.len(), 4, "no claims, no second table: {table}");
        assert_eq!(
            rows[0],
            "| `team_reach/1_ant` | `shnn` | fixed | success | 15.00 ± 7.07 | [10.00, 20.00] | 2 | 10.16M | \
             70.00 ± 4.00 | 10 | 50M | f |"
        );
        assert_eq!(
            rows[1],
            "| `team_reach/1_ant` | `shnn` | random (per slot) | success | 15.00 ± 7.07 | [10.00, 20.00] | 2 | \
             1.15M of 10M | 60.00 ± 3.00 | 10 | 50M | r |"
        );
        assert!(rows[2].contains("| 15.00 (one run) | – | 1 |"), "{}", rows[2]);
        assert!(rows[2].ends_with("| – | – | – | not in the paper's tables |"), "{}", rows[2]);
        assert!(
            rows[3].starts_with(
                "| `team_reach/1_ant` | `shnn:assignment=learned`, variant `no_assignment_bonus` | random |"
            ),
            "{}",
            rows[3]
        );
    }

    #[test]
    fn claims_the_groups_test_get_a_row_with_each_condition_and_the_verdict() {
        let p = parse(
            "seeds = 10\n\
             [[figure]]\ntable = \"t\"\nenv = \"team_reach/1_ant\"\nmodel = \"shnn\"\nmean = 97.26\nsd = 1.51\n\
             [[figure]]\ntable = \"t\"\nenv = \"team_reach/1_ant\"\nmodel = \"mlp_hn\"\nmean = 93.39\nsd = 5.25\n\
             [[figure]]\ntable = \"e\"\nenv = \"team_reach/1_ant\"\nmodel = \"mlp\"\nstart = \"fixed\"\nmean = 41.0\nsd = 9.0\n\
             [[figure]]\ntable = \"e\"\nenv = \"team_reach/1_ant\"\nmodel = \"mlp\"\nstart = \"fixed\"\nrotation_deg = 180\nmean = 0.18\nsd = 0.2\n\
             [[claim]]\nenv = \"team_reach/1_ant\"\nabove = { model = \"shnn\" }\nbelow = { model = \"mlp_hn\" }\n\
             [[claim]]\nenv = \"team_reach/1_ant\"\nstart = \"fixed\"\nabove = { model = \"mlp\" }\nbelow = { model = \"mlp\", rotation_deg = 180 }\n\
             [[claim]]\nenv = \"team_sumo/2_ants\"\nabove = { model = \"shnn\" }\nbelow = { model = \"mlp_hn\" }\n\
             [[claim]]\nenv = \"team_reach/2_ants\"\nabove = { model = \"shnn\" }\nbelow = { model = \"mlp_hn\" }\n",
        )
        .unwrap();
        let mut shnn = group("shnn", StartKind::Random, (10_158_080, 10_158_080));
        (shnn.mean, shnn.mean_ci) = (97.33, (95.51, 98.44));
        let mut mlp_hn = group("mlp_hn", StartKind::Random, (10_158_080, 10_158_080));
        (mlp_hn.mean, mlp_hn.mean_ci) = (82.36, (77.15, 85.16));
        let mut mlp = group("mlp", StartKind::Fixed, (10_158_080, 10_158_080));
        (mlp.mean, mlp.mean_ci) = (1.0, (0.5, 3.0));
        let mut mlp_rot = mlp.clone();
        (mlp_rot.rotation_deg, mlp_rot.mean, mlp_rot.mean_ci) = (180.0, 2.0, (0.0, 3.8));
        let mut sumo = group("shnn", StartKind::Random, (10_010_000, 10_010_000));
        (sumo.env, sumo.opponent, sumo.metric, sumo.mean, sumo.mean_ci) =
            ("team_sumo/2_ants".into(), "mlp_hn".into(), "eval_win_rate_t0".into(), 78.52, (78.52, 78.52));
        sumo.runs.truncate(1);
        (sumo.lose, sumo.lose_ci) = (Some((5.27, 0.0)), Some((5.27, 5.27)));
        let table = paper_table(&[mlp_hn, shnn, mlp, mlp_rot, sumo], &p);
        let (figures, claims) = table.split_once("\n\n").expect("two tables");
        assert_eq!(figures.lines().count(), 7);
        let rows: Vec<&str> = claims.lines().skip(2).collect();
        assert_eq!(rows.len(), 3, "the claim on 2_ants has no groups here: {claims}");
        assert_eq!(
            rows[0],
            "| `shnn` above `mlp_hn` (`team_reach/1_ant`, random start) | 97.33 [95.51, 98.44] | \
             82.36 [77.15, 85.16] | 97.26, 93.39 | yes | yes | 97.26: yes; 93.39: no | consistent in the mean |"
        );
        assert_eq!(
            rows[1],
            "| `mlp` at 0° above `mlp` rotated 180° (`team_reach/1_ant`, fixed start) | 1.00 [0.50, 3.00] | \
             2.00 [0.00, 3.80] | 41.00, 0.18 | no | no | 41.00: no; 0.18: yes | differs |"
        );
        assert_eq!(
            rows[2],
            "| `shnn` (team 0) wins more often than `mlp_hn` (team 1), trained against each other \
             (`team_sumo/2_ants`, random start) | 78.52 (one run) | 5.27 (one run) | – | yes | – (one run) | \
             – (one run) | single run |"
        );
    }

    /// Issue 77: a `|` in a value of `results/paper.toml` split its row of `paper.md`, and a
    /// line break ended it. A `|` is escaped; a line break is refused, naming the field.
    #[test]
    fn a_pipe_is_escaped_and_a_line_break_refused() {
        let figure = |table: &str| {
            format!(
                "seeds = 10\n[[figure]]\ntable = {table:?}\nenv = \"team_reach/1_ant\"\nmodel = \"shnn\"\nmean = 60.0\n\
                 sd = 3.0\n"
            )
        };
        let p = parse(&figure("Table 1 | left")).unwrap();
        let table = paper_table(&[group("shnn", StartKind::Random, (10_158_080, 10_158_080))], &p);
        let row = table.lines().nth(2).unwrap();
        assert!(row.ends_with("| Table 1 \\| left |"), "{row}");
        assert_eq!(row.matches(" | ").count(), 11, "{row}");
        let e = parse(&figure("Table 1\nleft")).unwrap_err().to_string();
        assert!(e.contains("figure[0].table") && e.contains("line break"), "{e}");
    }
}
