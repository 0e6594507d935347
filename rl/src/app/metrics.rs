//! The metrics CSV of a run: one row per iteration, the columns of a [`MetricsLayout`]
//! (empty cells where a value does not apply, e.g. team 1 of Team Reach, or was not
//! measured, e.g. evaluation columns between evaluations).
//!
//! The layout is [`COLUMNS`], then the loss statistics of each team ([`loss_columns`]: the
//! recorded ones of [`LossStats`] with the suffix `_t0`, then `_t1`), then, for every rotation of the configuration's
//! `eval_rotations` after the first (which is 0 and uses the plain `eval_*` columns), the
//! [`EVAL_COLUMNS`] with the suffix `_rot<degrees>` ([`eval_column`]): e.g.
//! `eval_success_rate_rot180`. The header line names the columns, so the reader
//! ([`crate::app::record::MetricsTable`]) takes whatever columns a file has.

use std::collections::BTreeMap;

use crate::mappo::ppo::LossStats;

/// The columns of every run before the losses, in file order. `_t0`/`_t1` are teams 0 and
/// 1; `train_*` are episodes that ended during collection in this iteration, `eval_*` an
/// evaluation run at the end of this iteration (the first of `eval_rotations`, i.e.
/// unrotated; `eval_sampled` is 1 when it sampled actions, 0 when it took the mean action).
pub const COLUMNS: &[&str] = &[
    "iteration",
    "env_steps",
    "wall_s",
    "steps_per_s",
    "curriculum_alpha",
    "train_episodes",
    "train_return_t0",
    "train_return_t1",
    "train_success_rate",
    "train_win_rate_t0",
    "train_win_rate_t1",
    "train_draw_rate",
    "train_length",
    "eval_episodes",
    "eval_sampled",
    "eval_success_rate",
    "eval_win_rate_t0",
    "eval_win_rate_t1",
    "eval_draw_rate",
    "eval_return_t0",
    "eval_return_t1",
    "eval_length",
];

/// The column of loss statistic `name` (one of [`LossStats::RECORDED`]) of team `team`:
/// `policy_loss_t0`.
pub fn loss_column(name: &str, team: usize) -> String {
    format!("{name}_t{team}")
}

/// The loss columns of both teams, in file order: the means over the iteration's minibatches
/// of [`LossStats::RECORDED`], team 0's then team 1's.
pub fn loss_columns() -> Vec<String> {
    (0..2).flat_map(|team| LossStats::RECORDED.iter().map(move |name| loss_column(name, team))).collect()
}

/// The evaluation columns repeated, with a suffix, for every further rotation.
pub const EVAL_COLUMNS: &[&str] = &[
    "eval_episodes",
    "eval_success_rate",
    "eval_win_rate_t0",
    "eval_win_rate_t1",
    "eval_draw_rate",
    "eval_return_t0",
    "eval_return_t1",
    "eval_length",
];

/// The column suffix of an evaluation rotated by `degrees`: empty for 0, else
/// `_rot<degrees>` (shortest decimal form: `_rot180`, `_rot90.5`, `_rot-45`).
pub fn rotation_suffix(degrees: f64) -> String {
    if degrees == 0.0 { String::new() } else { format!("_rot{degrees}") }
}

/// The name of evaluation column `base` (one of [`EVAL_COLUMNS`]) for the rotation `degrees`.
pub fn eval_column(base: &str, degrees: f64) -> String {
    format!("{base}{}", rotation_suffix(degrees))
}

/// The rotations (degrees, 0 first) whose `base` evaluation column a file has, from its
/// column names: `eval_success_rate` is 0, `eval_success_rate_rot180` is 180.
pub fn rotations_of<'a>(base: &str, columns: impl IntoIterator<Item = &'a str>) -> Vec<f64> {
    let mut out: Vec<f64> = Vec::new();
    for c in columns {
        let deg = if c == base {
            Some(0.0)
        } else {
            c.strip_prefix(base).and_then(|r| r.strip_prefix("_rot")).and_then(|d| d.parse::<f64>().ok())
        };
        if let Some(d) = deg.filter(|d| d.is_finite() && !out.contains(d)) {
            out.push(d);
        }
    }
    out.sort_by(|a, b| (*a != 0.0).cmp(&(*b != 0.0)).then(a.total_cmp(b)));
    out
}

/// The columns of a run's metrics file (module docs).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MetricsLayout {
    columns: Vec<String>,
}

impl Default for MetricsLayout {
    /// The layout of a run evaluated without rotations: [`COLUMNS`] and the [`loss_columns`].
    fn default() -> Self {
        MetricsLayout::new(&[0.0])
    }
}

impl MetricsLayout {
    /// [`COLUMNS`], the [`loss_columns`], then the [`EVAL_COLUMNS`] of every rotation after
    /// the first.
    pub fn new(eval_rotations: &[f64]) -> Self {
        let mut columns: Vec<String> = COLUMNS.iter().map(|c| c.to_string()).collect();
        columns.extend(loss_columns());
        for &deg in eval_rotations.iter().skip(1) {
            columns.extend(EVAL_COLUMNS.iter().map(|c| eval_column(c, deg)));
        }
        MetricsLayout { columns }
    }

    /// The column names, in file order.
    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// The header line (no newline).
    pub fn header(&self) -> String {
        self.columns.join(",")
    }

    /// A row as a CSV line (no newline); integers without a fraction, others with full
    /// precision (the shortest representation that reads back to the same `f64`). Every
    /// column the row sets must be in the layout (an internal error otherwise).
    pub fn to_csv(&self, row: &MetricsRow) -> String {
        if let Some(c) = row.values.keys().find(|c| !self.columns.contains(c)) {
            panic!("metrics column {c} is not in the layout");
        }
        self.columns
            .iter()
            .map(|c| match row.values.get(c) {
                Some(v) if v.fract() == 0.0 && v.abs() < 1e15 => format!("{}", *v as i64),
                Some(v) => format!("{v}"),
                None => String::new(),
            })
            .collect::<Vec<_>>()
            .join(",")
    }
}

/// One row: values by column name (absent: empty cell).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MetricsRow {
    values: BTreeMap<String, f64>,
}

impl MetricsRow {
    /// Sets a column.
    pub fn set(&mut self, column: impl Into<String>, value: f64) {
        self.values.insert(column.into(), value);
    }

    /// A column's value.
    pub fn get(&self, column: &str) -> Option<f64> {
        self.values.get(column).copied()
    }
}

/// The columns of a metrics file that measure time rather than training: two runs of one
/// configuration, on any machine and thread count, agree bit for bit on every other column.
pub const WALL_TIME_COLUMNS: [&str; 2] = ["wall_s", "steps_per_s"];

/// The lines of a metrics CSV (header first, blank lines dropped) with the
/// [`WALL_TIME_COLUMNS`] cut out: the text two runs of one configuration must share. The
/// cells stay as written (each float's shortest round-trip text), so equal text is equal
/// bits.
pub fn training_lines(text: &str) -> Result<Vec<String>, String> {
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header: Vec<&str> = lines.next().ok_or("empty file (no header line)")?.split(',').collect();
    let keep: Vec<bool> = header.iter().map(|c| !WALL_TIME_COLUMNS.contains(c)).collect();
    let cut =
        |cells: Vec<&str>| cells.iter().zip(&keep).filter(|(_, k)| **k).map(|(c, _)| *c).collect::<Vec<_>>().join(",");
    let mut out = vec![cut(header.clone())];
    for (i, line) in lines.enumerate() {
        let cells: Vec<&str> = line.split(',').collect();
        if cells.len() != header.len() {
            return Err(format!("line {}: {} cells, the header has {}", i + 2, cells.len(), header.len()));
        }
        out.push(cut(cells));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotated_evaluations_get_their_own_columns_and_read_back() {
        let layout = MetricsLayout::new(&[0.0, 180.0, -45.5]);
        assert_eq!(layout.columns().len(), COLUMNS.len() + loss_columns().len() + 2 * EVAL_COLUMNS.len());
        assert!(layout.columns().iter().any(|c| c == "eval_success_rate_rot180"));
        assert!(layout.columns().iter().any(|c| c == "eval_win_rate_t0_rot-45.5"));
        assert_eq!(MetricsLayout::default().header(), [COLUMNS.join(","), loss_columns().join(",")].join(","));
        let mut row = MetricsRow::default();
        row.set("iteration", 3.0);
        row.set("eval_success_rate", 0.25);
        row.set(eval_column("eval_success_rate", 180.0), 0.5);
        row.set("env_steps", 30.0);
        let text = format!("{}\n{}\n", layout.header(), layout.to_csv(&row));
        let rows = crate::app::record::MetricsTable::parse(&text).unwrap().rows;
        assert_eq!(rows[0].get("eval_success_rate_rot180"), Some(0.5));
        assert_eq!(rows[0].iteration, 3);
        let rot = rotations_of("eval_success_rate", layout.columns().iter().map(|c| c.as_str()));
        assert_eq!(rot, [0.0, -45.5, 180.0]);
        // Columns of other bases are not rotations of this one.
        assert_eq!(rotations_of("eval_win_rate_t0", ["eval_win_rate_t0_rot90", "eval_win_rate_t1_rot90"]), [90.0]);
    }

    /// The header derived from the loss statistics' list is the one of the committed runs
    /// (a changed header would make their rows incomparable with a re-run's).
    #[test]
    fn the_header_is_that_of_the_committed_runs() {
        let committed =
            concat!(env!("CARGO_MANIFEST_DIR"), "/../results/reach_1_ant/team_reach_1_ant/shnn/seed0/metrics.csv");
        let text = std::fs::read_to_string(committed).unwrap();
        assert_eq!(text.lines().next().unwrap(), MetricsLayout::default().header());
    }

    #[test]
    fn training_lines_cut_the_wall_time_columns_and_keep_the_text() {
        let a =
            "iteration,env_steps,wall_s,steps_per_s,loss\n1,10,3.5,2.857,0.1\n\n2,20,7.25,2.75,0.30000000000000004\n";
        let b = "iteration,env_steps,wall_s,steps_per_s,loss\n1,10,9,1.1,0.1\n2,20,18,1.1,0.30000000000000004\n";
        let lines = training_lines(a).unwrap();
        assert_eq!(lines, ["iteration,env_steps,loss", "1,10,0.1", "2,20,0.30000000000000004"]);
        assert_eq!(lines, training_lines(b).unwrap());
        // One bit of difference in a training column is a difference.
        assert_ne!(lines, training_lines(&b.replace("0.30000000000000004", "0.3")).unwrap());
        let msg = training_lines("iteration,wall_s\n1\n").unwrap_err();
        assert!(msg.contains("line 2") && msg.contains("1 cells"), "{msg}");
        assert!(training_lines("").is_err());
    }

    #[test]
    #[should_panic(expected = "not in the layout")]
    fn a_column_outside_the_layout_is_an_internal_error() {
        let mut row = MetricsRow::default();
        row.set("eval_success_rate_rot90", 1.0);
        MetricsLayout::default().to_csv(&row);
    }
}
