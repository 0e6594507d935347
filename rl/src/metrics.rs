//! The metrics CSV of a run: one row per iteration, a fixed set of columns (empty cells where
//! a value does not apply, e.g. team 1 of Team Reach, or was not measured, e.g. evaluation
//! columns between evaluations).

use std::collections::BTreeMap;

/// Column names, in file order. `_t0`/`_t1` are teams 0 and 1; `train_*` are episodes that
/// ended during collection in this iteration, `eval_*` an evaluation run at the end of this
/// iteration, the losses the means over the iteration's minibatches.
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
    "eval_success_rate",
    "eval_win_rate_t0",
    "eval_win_rate_t1",
    "eval_draw_rate",
    "eval_return_t0",
    "eval_return_t1",
    "eval_length",
    "policy_loss_t0",
    "value_loss_t0",
    "entropy_t0",
    "approx_kl_t0",
    "clip_fraction_t0",
    "explained_variance_t0",
    "policy_loss_t1",
    "value_loss_t1",
    "entropy_t1",
    "approx_kl_t1",
    "clip_fraction_t1",
    "explained_variance_t1",
];

/// One row: values by column name (absent: empty cell).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MetricsRow {
    values: BTreeMap<&'static str, f64>,
}

impl MetricsRow {
    /// Sets a column (names not in [`COLUMNS`] are an internal error).
    pub fn set(&mut self, column: &'static str, value: f64) {
        assert!(COLUMNS.contains(&column), "unknown metrics column {column}");
        self.values.insert(column, value);
    }

    /// A column's value.
    pub fn get(&self, column: &str) -> Option<f64> {
        self.values.get(column).copied()
    }

    /// The header line (no newline).
    pub fn header() -> String {
        COLUMNS.join(",")
    }

    /// The row as a CSV line (no newline); integers without a fraction, others with full
    /// precision (the shortest representation that reads back to the same `f64`).
    pub fn to_csv(&self) -> String {
        COLUMNS
            .iter()
            .map(|c| match self.values.get(c) {
                Some(v) if v.fract() == 0.0 && v.abs() < 1e15 => format!("{}", *v as i64),
                Some(v) => format!("{v}"),
                None => String::new(),
            })
            .collect::<Vec<_>>()
            .join(",")
    }
}

/// Parses a metrics CSV written by a run into rows of `column -> value` (empty cells absent);
/// unknown columns are kept, so older and newer files both read.
pub fn parse_csv(text: &str) -> Result<Vec<BTreeMap<String, f64>>, String> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().ok_or("empty file (no header line)")?.split(',').collect();
    let mut rows = Vec::new();
    for (i, line) in lines.enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let cells: Vec<&str> = line.split(',').collect();
        if cells.len() != header.len() {
            return Err(format!("line {}: {} cells, the header has {}", i + 2, cells.len(), header.len()));
        }
        let mut row = BTreeMap::new();
        for (name, cell) in header.iter().zip(cells) {
            if cell.is_empty() {
                continue;
            }
            let v: f64 =
                cell.parse().map_err(|_| format!("line {}: column {name}: {cell:?} is not a number", i + 2))?;
            row.insert(name.to_string(), v);
        }
        rows.push(row);
    }
    Ok(rows)
}
