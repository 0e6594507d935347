//! A run's `metrics.csv` read back as typed rows ([`MetricsTable`]): one [`IterationRow`]
//! per iteration, its columns (those of [`crate::app::metrics::MetricsLayout`]) in typed
//! fields, an empty cell as `None`, and any other column kept by name
//! ([`IterationRow::other`]), so files written before or after a column was added still
//! read. [`IterationRow::get`] reads any column by its name.
//!
//! Every row must have an `iteration` and its `env_steps` (the writer always sets both);
//! counts (`iteration`, `env_steps`, `*_episodes`) must be non-negative integers and
//! `eval_sampled` 0 or 1. Errors name the line and the column (and [`MetricsTable::read`]
//! the file).

use std::collections::BTreeMap;
use std::path::Path;

use crate::app::metrics::{eval_column, loss_column};
use crate::error::{Result, RlError};
use crate::mappo::ppo::LossStats;

/// The figures of a set of episodes: the training episodes that ended during an iteration
/// (`train_*` columns) or an evaluation (`eval_*`, one per rotation). Team Reach has a
/// success rate, Team Sumo win and draw rates; a cell that does not apply is `None`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Episodes {
    /// `*_episodes`: how many.
    pub episodes: Option<u64>,
    /// `*_success_rate` (Team Reach).
    pub success_rate: Option<f64>,
    /// `*_win_rate_t0`, `*_win_rate_t1` (Team Sumo).
    pub win_rate: [Option<f64>; 2],
    /// `*_draw_rate` (Team Sumo).
    pub draw_rate: Option<f64>,
    /// `*_return_t0`, `*_return_t1`: mean episode return per team.
    pub returns: [Option<f64>; 2],
    /// `*_length`: mean episode length in control steps.
    pub length: Option<f64>,
}

/// One rate of a set of episodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rate {
    /// The success rate (Team Reach).
    Success,
    /// The win rate of a team (Team Sumo).
    Win(usize),
    /// The draw rate (Team Sumo).
    Draw,
}

impl Rate {
    /// Its column without the `train_`/`eval_` prefix and rotation suffix: `success_rate`,
    /// `win_rate_t0`, `draw_rate`.
    pub fn name(self) -> String {
        match self {
            Rate::Success => "success_rate".into(),
            Rate::Win(team) => format!("win_rate_t{team}"),
            Rate::Draw => "draw_rate".into(),
        }
    }

    /// The training episodes' column of this rate: `train_success_rate`.
    pub fn train_column(self) -> String {
        format!("train_{}", self.name())
    }

    /// The evaluation column of this rate at rotation `degrees`: `eval_success_rate`,
    /// `eval_win_rate_t0_rot180`.
    pub fn eval_column(self, degrees: f64) -> String {
        eval_column(&format!("eval_{}", self.name()), degrees)
    }
}

impl Episodes {
    /// The value of `rate`.
    pub fn rate(&self, rate: Rate) -> Option<f64> {
        match rate {
            Rate::Success => self.success_rate,
            Rate::Win(team) => self.win_rate.get(team).copied().flatten(),
            Rate::Draw => self.draw_rate,
        }
    }

    fn slot(&mut self, field: Field) -> Slot<'_> {
        match field {
            Field::Episodes => Slot::Count(&mut self.episodes),
            Field::Success => Slot::Real(&mut self.success_rate),
            Field::Win(t) => Slot::Real(&mut self.win_rate[t]),
            Field::Draw => Slot::Real(&mut self.draw_rate),
            Field::Return(t) => Slot::Real(&mut self.returns[t]),
            Field::Length => Slot::Real(&mut self.length),
        }
    }

    fn value(&self, field: Field) -> Option<f64> {
        match field {
            Field::Episodes => self.episodes.map(|n| n as f64),
            Field::Success => self.success_rate,
            Field::Win(t) => self.win_rate[t],
            Field::Draw => self.draw_rate,
            Field::Return(t) => self.returns[t],
            Field::Length => self.length,
        }
    }
}

/// One iteration's row of `metrics.csv` (module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct IterationRow {
    /// `iteration`: 1-based.
    pub iteration: u64,
    /// `env_steps`: environment steps collected up to the end of the iteration.
    pub env_steps: u64,
    /// `wall_s`: seconds of training and evaluation so far, across resumes.
    pub wall_s: Option<f64>,
    /// `steps_per_s`: the iteration's env steps per second.
    pub steps_per_s: Option<f64>,
    /// `curriculum_alpha`: Team Sumo's curriculum factor.
    pub curriculum_alpha: Option<f64>,
    /// `train_*`: the episodes that ended during collection.
    pub train: Episodes,
    /// `eval_sampled`: whether the iteration's evaluation sampled actions (else it took the
    /// mean action).
    pub eval_sampled: Option<bool>,
    /// `eval_*`: the iteration's evaluations as `(rotation in degrees, figures)`, in the
    /// order of the file's columns (the writer's: the unrotated one, plain `eval_*` columns,
    /// first); only rotations with a cell in this row (none between evaluations).
    pub evals: Vec<(f64, Episodes)>,
    /// The loss statistics of teams 0 and 1, in the order of [`LossStats::RECORDED`]
    /// (`<name>_t0`, `<name>_t1`).
    pub losses: [Vec<Option<f64>>; 2],
    /// Every other column with a value, by name.
    pub other: BTreeMap<String, f64>,
}

impl IterationRow {
    /// The evaluation at rotation `degrees` (0: unrotated), if this row has one.
    pub fn eval(&self, degrees: f64) -> Option<&Episodes> {
        self.evals.iter().find(|(d, _)| *d == degrees).map(|(_, e)| e)
    }

    /// Whether the iteration ended with an evaluation (its unrotated `eval_episodes` cell
    /// is set).
    pub fn evaluated(&self) -> bool {
        self.eval(0.0).is_some_and(|e| e.episodes.is_some())
    }

    /// The loss statistic `name` (one of [`LossStats::RECORDED`]) of team `team`.
    pub fn loss(&self, name: &str, team: usize) -> Option<f64> {
        let k = LossStats::RECORDED.iter().position(|n| *n == name)?;
        self.losses.get(team)?.get(k).copied().flatten()
    }

    /// The value of the column named `column`, whatever it is (`None`: empty or absent).
    pub fn get(&self, column: &str) -> Option<f64> {
        self.value(&Column::of(column))
    }

    /// Every cell with a value as `(column, value)`, in column-name order.
    pub fn cells(&self) -> Vec<(String, f64)> {
        let mut columns = vec![
            Column::Iteration,
            Column::EnvSteps,
            Column::WallS,
            Column::StepsPerS,
            Column::CurriculumAlpha,
            Column::EvalSampled,
        ];
        columns.extend(FIELDS.iter().map(|&(_, f)| Column::Train(f)));
        for (deg, _) in &self.evals {
            columns.extend(FIELDS.iter().map(|&(_, f)| Column::Eval(*deg, f)));
        }
        for team in 0..2 {
            columns.extend((0..LossStats::RECORDED.len()).map(|k| Column::Loss(k, team)));
        }
        columns.extend(self.other.keys().map(|k| Column::Other(k.clone())));
        let mut out: Vec<(String, f64)> = columns.iter().filter_map(|c| Some((c.name(), self.value(c)?))).collect();
        out.sort_by(|a, b| a.0.cmp(&b.0));
        out
    }

    fn value(&self, column: &Column) -> Option<f64> {
        match column {
            Column::Iteration => Some(self.iteration as f64),
            Column::EnvSteps => Some(self.env_steps as f64),
            Column::WallS => self.wall_s,
            Column::StepsPerS => self.steps_per_s,
            Column::CurriculumAlpha => self.curriculum_alpha,
            Column::EvalSampled => self.eval_sampled.map(|s| if s { 1.0 } else { 0.0 }),
            Column::Train(f) => self.train.value(*f),
            Column::Eval(deg, f) => self.eval(*deg)?.value(*f),
            Column::Loss(k, team) => self.losses[*team].get(*k).copied().flatten(),
            Column::Other(name) => self.other.get(name).copied(),
        }
    }

    fn slot(&mut self, column: &Column) -> Slot<'_> {
        match column {
            Column::Iteration | Column::EnvSteps => unreachable!("counted by MetricsTable::parse"),
            Column::WallS => Slot::Real(&mut self.wall_s),
            Column::StepsPerS => Slot::Real(&mut self.steps_per_s),
            Column::CurriculumAlpha => Slot::Real(&mut self.curriculum_alpha),
            Column::EvalSampled => Slot::Flag(&mut self.eval_sampled),
            Column::Train(f) => self.train.slot(*f),
            Column::Eval(deg, f) => {
                let i = match self.evals.iter().position(|(d, _)| d == deg) {
                    Some(i) => i,
                    None => {
                        self.evals.push((*deg, Episodes::default()));
                        self.evals.len() - 1
                    }
                };
                self.evals[i].1.slot(*f)
            }
            Column::Loss(k, team) => Slot::Real(&mut self.losses[*team][*k]),
            Column::Other(name) => Slot::Named(self.other.entry(name.clone()).or_insert(0.0)),
        }
    }
}

/// The rows of a metrics file with its header (module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MetricsTable {
    /// The column names, in file order.
    pub columns: Vec<String>,
    /// One row per line with cells, in file order.
    pub rows: Vec<IterationRow>,
}

impl MetricsTable {
    /// Reads the metrics file at `path` ([`MetricsTable::parse`]); errors name the file.
    pub fn read(path: &Path) -> Result<MetricsTable> {
        let text = std::fs::read_to_string(path).map_err(|e| RlError::file(path, format!("cannot read: {e}")))?;
        MetricsTable::parse(&text).map_err(|e| RlError::file(path, e))
    }

    /// Parses a metrics file's text (module docs); blank lines are skipped, and errors name
    /// the line (1-based, the header being line 1) and the column. Every cell is checked to
    /// be a number before any row is checked to have its `iteration` and `env_steps`.
    pub fn parse(text: &str) -> std::result::Result<MetricsTable, String> {
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().ok_or("empty file (no header line)")?.split(',').collect();
        let kinds: Vec<Column> = header.iter().map(|name| Column::of(name)).collect();
        let mut rows = Vec::new();
        let mut unnumbered: Option<String> = None;
        for (i, line) in lines.enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let at = |name: &str| format!("line {}: column {name}", i + 2);
            let cells: Vec<&str> = line.split(',').collect();
            if cells.len() != header.len() {
                return Err(format!("line {}: {} cells, the header has {}", i + 2, cells.len(), header.len()));
            }
            let mut row =
                IterationRow { losses: [0, 1].map(|_| vec![None; LossStats::RECORDED.len()]), ..Default::default() };
            let (mut has_iteration, mut has_steps) = (false, false);
            for ((name, cell), kind) in header.iter().zip(&cells).zip(&kinds) {
                if cell.is_empty() {
                    continue;
                }
                let v: f64 = cell.parse().map_err(|_| format!("{}: {cell:?} is not a number", at(name)))?;
                let as_count =
                    || count(v).ok_or_else(|| format!("{}: {cell:?} is not a non-negative integer", at(name)));
                match kind {
                    Column::Iteration => (row.iteration, has_iteration) = (as_count()?, true),
                    Column::EnvSteps => (row.env_steps, has_steps) = (as_count()?, true),
                    _ => {}
                }
                if matches!(kind, Column::Iteration | Column::EnvSteps) {
                    continue;
                }
                match row.slot(kind) {
                    Slot::Real(slot) => *slot = Some(v),
                    Slot::Named(slot) => *slot = v,
                    Slot::Count(slot) => *slot = Some(as_count()?),
                    Slot::Flag(slot) => {
                        *slot = Some(match v {
                            0.0 => false,
                            1.0 => true,
                            _ => return Err(format!("{}: {cell:?} is neither 0 nor 1", at(name))),
                        })
                    }
                }
            }
            if let Some((missing, _)) =
                [("iteration", has_iteration), ("env_steps", has_steps)].iter().find(|(_, has)| !has)
            {
                unnumbered.get_or_insert_with(|| {
                    format!("line {}: no {missing} (every row of a run's metrics has one)", i + 2)
                });
            }
            rows.push(row);
        }
        match unnumbered {
            Some(e) => Err(e),
            None => Ok(MetricsTable { columns: header.iter().map(|c| c.to_string()).collect(), rows }),
        }
    }

    /// The values of column `name`, one per row, an empty cell (or a column the file does
    /// not have) as NaN.
    pub fn column(&self, name: &str) -> Vec<f64> {
        let column = Column::of(name);
        self.rows.iter().map(|r| r.value(&column).unwrap_or(f64::NAN)).collect()
    }
}

/// `v` as a count, if it is a non-negative integer a `u64` holds.
fn count(v: f64) -> Option<u64> {
    (v >= 0.0 && v.fract() == 0.0 && v < 18_446_744_073_709_551_616.0).then_some(v as u64)
}

/// Where a cell's value goes.
enum Slot<'a> {
    Real(&'a mut Option<f64>),
    Count(&'a mut Option<u64>),
    Flag(&'a mut Option<bool>),
    Named(&'a mut f64),
}

/// A column of a set of episodes, without its `train_`/`eval_` prefix.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Field {
    Episodes,
    Success,
    Win(usize),
    Draw,
    Return(usize),
    Length,
}

/// The columns of a set of episodes by name (`crate::app::metrics::EVAL_COLUMNS` without
/// their `eval_`).
const FIELDS: [(&str, Field); 8] = [
    ("episodes", Field::Episodes),
    ("success_rate", Field::Success),
    ("win_rate_t0", Field::Win(0)),
    ("win_rate_t1", Field::Win(1)),
    ("draw_rate", Field::Draw),
    ("return_t0", Field::Return(0)),
    ("return_t1", Field::Return(1)),
    ("length", Field::Length),
];

/// What a column of the file is.
#[derive(Clone, Debug, PartialEq)]
enum Column {
    Iteration,
    EnvSteps,
    WallS,
    StepsPerS,
    CurriculumAlpha,
    EvalSampled,
    Train(Field),
    /// An evaluation column at a rotation (degrees).
    Eval(f64, Field),
    /// Loss statistic `LossStats::RECORDED[k]` of a team.
    Loss(usize, usize),
    Other(String),
}

impl Column {
    /// The column named `name` (the writer's names; anything else is [`Column::Other`]).
    fn of(name: &str) -> Column {
        let field = |rest: &str| FIELDS.iter().find(|(n, _)| *n == rest).map(|&(_, f)| f);
        match name {
            "iteration" => return Column::Iteration,
            "env_steps" => return Column::EnvSteps,
            "wall_s" => return Column::WallS,
            "steps_per_s" => return Column::StepsPerS,
            "curriculum_alpha" => return Column::CurriculumAlpha,
            "eval_sampled" => return Column::EvalSampled,
            _ => {}
        }
        if let Some(f) = name.strip_prefix("train_").and_then(field) {
            return Column::Train(f);
        }
        if let Some(rest) = name.strip_prefix("eval_") {
            if let Some(f) = field(rest) {
                return Column::Eval(0.0, f);
            }
            for &(n, f) in &FIELDS {
                let degrees = rest.strip_prefix(n).and_then(|r| r.strip_prefix("_rot")).and_then(|d| d.parse().ok());
                // Written only for rotations other than 0 (`metrics::rotation_suffix`).
                if let Some(deg) = degrees.filter(|d: &f64| d.is_finite() && *d != 0.0) {
                    return Column::Eval(deg, f);
                }
            }
        }
        for (k, stat) in LossStats::RECORDED.iter().enumerate() {
            if let Some(team) = (0..2).find(|&t| name == loss_column(stat, t)) {
                return Column::Loss(k, team);
            }
        }
        Column::Other(name.to_string())
    }

    /// The column's name, as the writer names it.
    fn name(&self) -> String {
        let field = |f: Field| FIELDS.iter().find(|(_, g)| *g == f).map_or("", |(n, _)| n);
        match self {
            Column::Iteration => "iteration".into(),
            Column::EnvSteps => "env_steps".into(),
            Column::WallS => "wall_s".into(),
            Column::StepsPerS => "steps_per_s".into(),
            Column::CurriculumAlpha => "curriculum_alpha".into(),
            Column::EvalSampled => "eval_sampled".into(),
            Column::Train(f) => format!("train_{}", field(*f)),
            Column::Eval(deg, f) => eval_column(&format!("eval_{}", field(*f)), *deg),
            Column::Loss(k, team) => loss_column(LossStats::RECORDED[*k], *team),
            Column::Other(name) => name.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::metrics::{MetricsLayout, MetricsRow};

    #[test]
    fn every_column_of_the_layout_lands_in_its_field_and_reads_back_by_name() {
        let layout = MetricsLayout::new(&[0.0, 180.0]);
        let mut row = MetricsRow::default();
        // A distinct value per column, integers where the column counts.
        for (i, c) in layout.columns().iter().enumerate() {
            let counts = ["iteration", "env_steps"].contains(&c.as_str()) || c.contains("episodes");
            let value = match c.as_str() {
                "eval_sampled" => 1.0,
                _ if counts => (i * 10) as f64,
                _ => i as f64 + 0.25,
            };
            row.set(c.clone(), value);
        }
        let text = format!("{},extra_tail\n{},7.5\n", layout.header(), layout.to_csv(&row));
        let table = MetricsTable::parse(&text).unwrap();
        assert_eq!(table.columns.len(), layout.columns().len() + 1);
        let r = &table.rows[0];
        for c in layout.columns() {
            assert_eq!(r.get(c), row.get(c), "{c}");
            assert_eq!(table.column(c), [row.get(c).unwrap()], "{c}");
        }
        assert_eq!(r.other.get("extra_tail"), Some(&7.5));
        assert_eq!((r.iteration, r.env_steps, r.eval_sampled), (0, 10, Some(true)));
        assert_eq!(r.train.episodes, Some(50));
        let rotated = r.eval(180.0).unwrap();
        assert_eq!(rotated.rate(Rate::Success), row.get("eval_success_rate_rot180"));
        assert_eq!(rotated.rate(Rate::Win(1)), row.get("eval_win_rate_t1_rot180"));
        let name = LossStats::RECORDED[0];
        assert_eq!(r.loss(name, 1), row.get(&loss_column(name, 1)));
        assert!(r.evaluated());
        // Every cell by name, and nothing else.
        let cells = r.cells();
        assert_eq!(cells.len(), layout.columns().len() + 1);
        assert!(cells.windows(2).all(|w| w[0].0 < w[1].0));
        assert!(cells.iter().all(|(c, v)| r.get(c) == Some(*v)));
        assert_eq!(Rate::Win(0).eval_column(180.0), "eval_win_rate_t0_rot180");
        assert_eq!(Rate::Success.train_column(), "train_success_rate");
    }

    #[test]
    fn empty_cells_are_none_and_unknown_columns_read_by_name() {
        let t = MetricsTable::parse(
            "iteration,env_steps,eval_success_rate,eval_length_rot90,old_column\n1,10,,,3\n\n2,20,0.5,7,\n",
        )
        .unwrap();
        assert_eq!(t.rows.len(), 2);
        let (a, b) = (&t.rows[0], &t.rows[1]);
        assert!(a.evals.is_empty() && !a.evaluated() && a.wall_s.is_none());
        assert_eq!(a.other.get("old_column"), Some(&3.0));
        assert_eq!(b.eval(0.0).unwrap().success_rate, Some(0.5));
        assert_eq!(b.eval(90.0).unwrap().length, Some(7.0));
        // An evaluation row without `eval_episodes` has figures but no episode count.
        assert!(!b.evaluated());
        assert!(b.other.is_empty());
        assert_eq!(t.column("eval_success_rate")[1], 0.5);
        assert!(t.column("eval_success_rate")[0].is_nan() && t.column("no_such_column")[1].is_nan());
    }

    #[test]
    fn malformed_files_name_the_line_and_column() {
        let err = |text: &str| MetricsTable::parse(text).unwrap_err();
        assert!(err("").contains("no header"));
        let e = err("iteration,env_steps,loss\n1,10,0.5\n2,20,oops\n");
        assert!(e.contains("line 3") && e.contains("column loss") && e.contains("\"oops\""), "{e}");
        let e = err("iteration,env_steps\n1,10\n2\n");
        assert!(e.contains("line 3") && e.contains("1 cells, the header has 2"), "{e}");
        let e = err("iteration,env_steps\n1.5,10\n");
        assert!(e.contains("line 2: column iteration") && e.contains("non-negative integer"), "{e}");
        let e = err("iteration,env_steps,eval_episodes\n1,10,-3\n");
        assert!(e.contains("column eval_episodes") && e.contains("\"-3\""), "{e}");
        let e = err("iteration,env_steps,eval_sampled\n1,10,0.5\n");
        assert!(e.contains("column eval_sampled") && e.contains("neither 0 nor 1"), "{e}");
        // Numbers first: a bad cell further down is named before a row without env_steps.
        let e = err("iteration,loss\n1,0.5\n2,oops\n");
        assert!(e.contains("line 3: column loss"), "{e}");
        let e = err("iteration,loss\n1,0.5\n2,0.25\n");
        assert!(e.contains("line 2: no env_steps"), "{e}");
        let e = err("iteration,env_steps\n1,10\n,20\n");
        assert!(e.contains("line 3: no iteration"), "{e}");
    }

    /// Issue 43 item 5: the four readers of `metrics.csv` into string maps became this one;
    /// every cell of every committed run reads back the same through it.
    #[test]
    fn every_cell_of_the_committed_runs_reads_back_by_name() {
        let results = Path::new(env!("CARGO_MANIFEST_DIR")).join("../results");
        let runs = crate::app::record::find_run_dirs(&results).unwrap();
        assert!(runs.len() >= 10, "{runs:?}");
        for run in runs {
            let path = run.join("metrics.csv");
            let text = std::fs::read_to_string(&path).unwrap();
            let table = MetricsTable::read(&path).unwrap();
            let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
            assert_eq!(table.columns, header);
            let lines: Vec<&str> = text.lines().skip(1).filter(|l| !l.trim().is_empty()).collect();
            assert_eq!(lines.len(), table.rows.len());
            for (line, row) in lines.iter().zip(&table.rows) {
                for (name, cell) in header.iter().zip(line.split(',')) {
                    let want = (!cell.is_empty()).then(|| cell.parse::<f64>().unwrap());
                    assert_eq!(row.get(name).map(f64::to_bits), want.map(f64::to_bits), "{}: {name}", path.display());
                }
                assert!(row.other.is_empty(), "{}: {:?}", path.display(), row.other);
            }
        }
    }
}
