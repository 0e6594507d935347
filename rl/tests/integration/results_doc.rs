//! `docs/RESULTS.md` quotes the committed evidence: every figure in the reproduction's
//! tables (issue 15) is the one its run files give, to the places it is written with.
//!
//! The final rates beside the paper's are generated (`results/<experiment>/paper.md`) and
//! quoted verbatim; the tables still written by hand are read back:
//! - a table of final rates (first column `model`): every "here" cell of the form
//!   `mean ± s.e. (seed, seed, ...)` must be a row of one of the section's
//!   `results/<experiment>/report.csv` files (same model, the environment the column names,
//!   the rotation it names), and the per-seed figures the last evaluation of each seed's
//!   `metrics.csv`;
//! - a table of runs (first column `run`, cells like `` `mlp` seed 1 ``): success and return
//!   at 0 and 180 degrees, from the run's last evaluation;
//! - a table of evaluations (first column `env steps`): each row the evaluation at those env
//!   steps of the section's one run (win, loss and draw rates, mean returns, mean length).
//!
//! - the prose (and every table line not generated): every figure written with two
//!   decimals (not env steps, `20.15M`) is a value of the section's evidence
//!   ([`the_reproduction_prose_quotes_the_committed_evidence`]): a run's evaluated success,
//!   win, loss or draw rate at any of its evaluations and rotations, a statistic of a
//!   report (`report.csv`, also at a matched budget: mean, s.e., s.d., IQM, intervals), a
//!   figure of `results/paper.toml`, a value of a `metrics.csv` column the paragraph
//!   names in backticks (`entropy_t0`), or a number in a table of the experiment's
//!   generated `diagnostics.md`, `substitution.md` or `values.md`
//!   (`rl/sweeps/assignment_diagnostics.py`, `assignment_substitution.py`,
//!   `assignment_values.py`; a `%` cell counts as its number). A retyped per-seed
//!   figure that no longer matches any of them fails; one edited into another value of the
//!   same evidence does not.
//!
//! A section's experiments are the `results/<experiment>/report.md`, `diagnostics.md`,
//! `substitution.md` and `values.md` files it links (a section that links none: those its `## ` part
//! links). A figure matches when it equals the evidence rounded to the decimals it is
//! written with (either way at an exact tie, since `{:.2}` and Python's rounding differ
//! there).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The workspace root.
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// One markdown table of the document, with the `###` heading it stands under.
struct Table {
    section: String,
    line: usize,
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

/// The cells of a markdown table line `| a | b |`.
fn cells(line: &str) -> Vec<String> {
    let inner = line.trim().trim_start_matches('|').trim_end_matches('|');
    inner.split('|').map(|c| c.trim().to_string()).collect()
}

/// The sections (`###` heading → its text) and tables of the reproduction part of the
/// document: from `## The reproduction` to the next `## ` heading.
fn reproduction(doc: &str) -> (HashMap<String, String>, Vec<Table>) {
    let mut sections: HashMap<String, String> = HashMap::new();
    let mut tables = Vec::new();
    let mut inside = false;
    let mut section = String::new();
    let mut current: Option<Table> = None;
    for (i, line) in doc.lines().enumerate() {
        if line.starts_with("## ") {
            inside = line.starts_with("## The reproduction");
        }
        if !inside {
            continue;
        }
        if let Some(h) = line.strip_prefix("### ") {
            section = h.to_string();
        }
        let text = sections.entry(section.clone()).or_default();
        text.push_str(line);
        text.push('\n');
        if line.starts_with('|') {
            let c = cells(line);
            match current.as_mut() {
                None => current = Some(Table { section: section.clone(), line: i + 1, header: c, rows: Vec::new() }),
                Some(t) if c.iter().all(|x| x.chars().all(|ch| ch == '-' || ch == ':')) => {
                    assert!(t.rows.is_empty(), "RESULTS.md line {}: a second separator line", i + 1)
                }
                Some(t) => t.rows.push(c),
            }
        } else if let Some(t) = current.take() {
            tables.push(t);
        }
    }
    tables.extend(current);
    (sections, tables)
}

/// The generated tables an experiment may hold beside its report, whose numbers the prose
/// may quote: `rl/sweeps/assignment_diagnostics.py`'s, `assignment_substitution.py`'s and
/// `assignment_values.py`'s.
const GENERATED_TABLES: [&str; 3] = ["diagnostics.md", "substitution.md", "values.md"];

/// The experiments a section's text links: `results/<experiment>/report.md` (or one of its
/// [`GENERATED_TABLES`]).
fn linked_experiments(text: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for piece in text.split("results/").skip(1) {
        let named = ["/report.md", "/diagnostics.md", "/substitution.md", "/values.md"]
            .iter()
            .filter_map(|file| piece.split_once(file).map(|(name, _)| name))
            .find(|name| !name.is_empty() && !name.contains(['/', ' ', '(', ')', '`']));
        if let Some(name) = named
            && !out.iter().any(|o| o == name)
        {
            out.push(name.to_string());
        }
    }
    out
}

/// A `report.csv`'s rows as column → cell (it holds names as well as numbers, and no quoted
/// fields).
fn read_report(path: &Path) -> Vec<HashMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    lines.map(|l| header.iter().map(|h| h.to_string()).zip(l.split(',').map(str::to_string)).collect()).collect()
}

/// A run's `metrics.csv` rows (the project's reader: empty cells `None`).
fn read_metrics(run: &Path) -> Vec<MetricsRow> {
    rl::app::record::MetricsTable::read(&run.join("metrics.csv")).unwrap().rows
}

/// One row of `metrics.csv`.
type MetricsRow = rl::app::record::IterationRow;

/// The last value of `column` in a run's rows.
fn last(rows: &[MetricsRow], column: &str) -> f64 {
    rows.iter().rev().find_map(|r| r.get(column)).unwrap_or_else(|| panic!("{column} is never written"))
}

/// The run directories of the experiments under `results/`.
fn runs_of(experiments: &[String]) -> Vec<PathBuf> {
    experiments
        .iter()
        .flat_map(|exp| rl::app::record::find_run_dirs(&root().join("results").join(exp)).unwrap())
        .collect()
}

/// Whether the figure `shown`, as written, is `value` rounded to its decimals.
fn quotes(shown: &str, value: f64) -> bool {
    let Ok(x) = shown.parse::<f64>() else { return false };
    let decimals = shown.split_once('.').map_or(0, |(_, d)| d.len()) as i32;
    (x - value).abs() <= 0.5 * 10f64.powi(-decimals) * (1.0 + 1e-9) + 1e-12
}

/// `a ± b (s, s, s)` → (a, b, [s...]); None for a cell without `±`.
fn mean_se_seeds(cell: &str) -> Option<(String, String, Vec<String>)> {
    let (mean, rest) = cell.split_once(" ± ")?;
    let se: String = rest.chars().take_while(|c| c.is_ascii_digit() || *c == '.').collect();
    let seeds = match rest.split_once('(') {
        Some((_, list)) => list.trim_end_matches(')').split(',').map(|s| s.trim().to_string()).collect(),
        None => Vec::new(),
    };
    Some((mean.trim().to_string(), se, seeds))
}

/// What a test of one table found: figures checked and mismatches.
#[derive(Default)]
struct Tally {
    checked: usize,
    wrong: Vec<String>,
}

impl Tally {
    fn check(&mut self, place: String, shown: &str, value: f64) {
        self.checked += 1;
        if !quotes(shown, value) {
            self.wrong.push(format!("{place}: the document says {shown}, the evidence {value}"));
        }
    }
}

/// A table of final rates: first column the model, "here" columns `mean ± s.e. (seeds)`.
fn check_final_rates(t: &Table, experiments: &[String], tally: &mut Tally) {
    let results = root().join("results");
    let reports: Vec<(&String, HashMap<String, String>)> = experiments
        .iter()
        .filter(|exp| results.join(exp).join("report.csv").is_file())
        .flat_map(|exp| read_report(&results.join(exp).join("report.csv")).into_iter().map(move |r| (exp, r)))
        .collect();
    for row in &t.rows {
        let model = row[0].trim_matches('`');
        for (j, head) in t.header.iter().enumerate().filter(|(_, h)| h.contains("here")) {
            let Some((mean, se, seeds)) = mean_se_seeds(&row[j]) else { continue };
            let env = head.split('`').nth(1);
            let rotation = if head.contains("180°") { "180" } else { "0" };
            let place = format!("RESULTS.md, table at line {} ({}), {model}, column \"{head}\"", t.line, t.section);
            let found = reports.iter().find(|(_, r)| {
                r["model"] == model
                    && r["rotation_deg"] == rotation
                    && env.is_none_or(|e| r["env"].ends_with(&format!("/{e}")))
                    && quotes(&mean, r["mean_pct"].parse().unwrap())
                    && quotes(&se, r["se_pct"].parse().unwrap())
            });
            tally.checked += 2;
            let Some((exp, r)) = found else {
                tally.wrong.push(format!("{place}: {mean} ± {se} is no row of the reports of {experiments:?}"));
                continue;
            };
            if seeds.is_empty() {
                continue;
            }
            let seed_list: Vec<&str> = r["seed_list"].split(' ').collect();
            if seeds.len() != seed_list.len() {
                tally.wrong.push(format!("{place}: {} per-seed figures for seeds {seed_list:?}", seeds.len()));
                continue;
            }
            let metric = r["metric"].clone();
            for (shown, seed) in seeds.iter().zip(seed_list) {
                let rows = read_metrics(&results.join(exp).join(&r["variant"]).join(format!("seed{seed}")));
                tally.check(format!("{place}, seed {seed}"), shown, 100.0 * last(&rows, &metric));
            }
        }
    }
}

/// The run directory of `` `model` seed k `` among the section's experiments: exactly one.
fn run_dir(cell: &str, experiments: &[String]) -> PathBuf {
    let (model, seed) = cell.split_once(" seed ").unwrap_or_else(|| panic!("run cell {cell:?}: not `model` seed k"));
    let tail = Path::new(model.trim_matches('`')).join(format!("seed{}", seed.trim()));
    let mut found: Vec<PathBuf> = runs_of(experiments).into_iter().filter(|d| d.ends_with(&tail)).collect();
    assert_eq!(found.len(), 1, "run {cell:?}: run directories {found:?} among {experiments:?}");
    found.pop().unwrap()
}

/// A table of runs at their last evaluation: success and return at 0 and 180 degrees.
fn check_runs(t: &Table, experiments: &[String], tally: &mut Tally) {
    for row in &t.rows {
        let rows = read_metrics(&run_dir(&row[0], experiments));
        for (j, head) in t.header.iter().enumerate().skip(1) {
            let suffix = if head.contains("180°") { "_rot180" } else { "" };
            let (column, scale) = if head.starts_with("success") {
                (format!("eval_success_rate{suffix}"), 100.0)
            } else if head.starts_with("return") {
                (format!("eval_return_t0{suffix}"), 1.0)
            } else {
                panic!("RESULTS.md line {}: column {head:?} of a table of runs is not known to this test", t.line)
            };
            let place = format!("RESULTS.md, table at line {} ({}), {}, column \"{head}\"", t.line, t.section, row[0]);
            tally.check(place, &row[j], scale * last(&rows, &column));
        }
    }
}

/// A table of one run's evaluations, a row each: `env steps | wins t0 | wins t1 | draw |
/// return t0 / return t1 | length`.
fn check_evaluations(t: &Table, experiments: &[String], tally: &mut Tally) {
    let mut runs = runs_of(experiments);
    assert_eq!(
        runs.len(),
        1,
        "RESULTS.md, table at line {}: a table of evaluations needs one run in {experiments:?}",
        t.line
    );
    let evaluations: Vec<MetricsRow> =
        read_metrics(&runs.pop().unwrap()).into_iter().filter(|r| r.get("eval_win_rate_t0").is_some()).collect();
    let expected_header = ["env steps", "wins", "wins", "draw", "mean return", "mean episode"];
    for (head, want) in t.header.iter().zip(expected_header) {
        assert!(
            head.contains(want),
            "RESULTS.md, table at line {}: column {head:?} where this test reads {want:?}",
            t.line
        );
    }
    for row in &t.rows {
        let place = format!("RESULTS.md, table at line {} ({}), evaluation at {}", t.line, t.section, row[0]);
        let shown_steps = row[0].trim_end_matches('M');
        let Some(row_of) = evaluations.iter().find(|e| quotes(shown_steps, e.env_steps as f64 / 1e6)) else {
            tally.wrong.push(format!("{place}: no evaluation at those env steps"));
            continue;
        };
        let e = |column: &str| row_of.get(column).unwrap_or_else(|| panic!("{place}: no {column}"));
        tally.check(format!("{place}, wins t0"), &row[1], 100.0 * e("eval_win_rate_t0"));
        tally.check(format!("{place}, wins t1"), &row[2], 100.0 * e("eval_win_rate_t1"));
        tally.check(format!("{place}, draw"), &row[3], 100.0 * e("eval_draw_rate"));
        let (r0, r1) = row[4].split_once(" / ").unwrap_or_else(|| panic!("{place}: returns {:?}", row[4]));
        tally.check(format!("{place}, return t0"), r0, e("eval_return_t0"));
        tally.check(format!("{place}, return t1"), r1, e("eval_return_t1"));
        tally.check(format!("{place}, length"), &row[5], e("eval_length"));
    }
}

#[test]
fn the_reproduction_tables_quote_the_committed_evidence() {
    let path = root().join("docs/RESULTS.md");
    let doc = std::fs::read_to_string(&path).unwrap();
    let (sections, tables) = reproduction(&doc);
    let mut tally = Tally::default();
    let mut checked_by_section: HashMap<String, usize> = HashMap::new();
    for t in &tables {
        let experiments = linked_experiments(&sections[&t.section]);
        let before = tally.checked;
        match t.header[0].as_str() {
            "model" if t.header.iter().any(|h| h.contains("here")) => check_final_rates(t, &experiments, &mut tally),
            "run" if t.rows.iter().all(|r| r[0].contains(" seed ")) => check_runs(t, &experiments, &mut tally),
            "env steps" => check_evaluations(t, &experiments, &mut tally),
            _ => continue,
        }
        *checked_by_section.entry(t.section.clone()).or_default() += tally.checked - before;
    }
    // Each experiment's section has a checked table with figures in it, or quotes a
    // generated one (checked by `every_generated_paper_table_is_quoted_verbatim`): a table
    // whose header this test no longer recognises fails here instead of going unchecked.
    for n in 1..=3 {
        let name = format!("Experiment {n}:");
        let checked = checked_by_section.iter().any(|(s, &c)| s.starts_with(&name) && c > 0);
        let generated = sections
            .iter()
            .any(|(s, text)| s.starts_with(&name) && text.contains("| env | model | start | evaluated |"));
        assert!(checked || generated, "RESULTS.md: no figure of Experiment {n}'s tables was checked");
    }
    println!("{} figures checked: {checked_by_section:?}", tally.checked);
    assert!(tally.wrong.is_empty(), "RESULTS.md disagrees with results/:\n{}", tally.wrong.join("\n"));
}

#[test]
fn a_figure_matches_only_to_its_decimals() {
    assert!(quotes("67.19", 67.1875));
    assert!(!quotes("67.18", 67.1875));
    assert!(quotes("3.12", 3.125) && quotes("3.13", 3.125), "an exact tie rounds either way");
    assert!(!quotes("3.11", 3.125));
    assert!(quotes("5297", 5297.096));
    assert!(!quotes("5298", 5297.096));
    assert!(!quotes("–", 1.0));
    assert_eq!(
        mean_se_seeds("82.36 ± 2.61 (85.16, 84.77, 77.15)"),
        Some(("82.36".into(), "2.61".into(), vec!["85.16".into(), "84.77".into(), "77.15".into()]))
    );
    assert_eq!(mean_se_seeds("training (seed 0: 83.50 at 12.1M)"), None);
    assert_eq!(
        linked_experiments("[a](../results/sumo/report.md) and `results/reach_1_ant/report.md`"),
        ["sumo", "reach_1_ant"]
    );
    // A linked diagnostics file names its experiment too, once.
    assert_eq!(
        linked_experiments(
            "[d](../results/swap/diagnostics.md), [r](../results/sumo/report.md), results/swap/report.md"
        ),
        ["swap", "sumo"]
    );
    assert_eq!(linked_experiments("[s](../results/critic/substitution.md)"), ["critic"]);
}

/// Every experiment's generated paper-versus-here table (`results/<experiment>/paper.md`,
/// and `results/<experiment>/at_<N>/paper.md` at a matched budget, which
/// `committed_results` regenerates byte for byte) is quoted in `docs/RESULTS.md`
/// exactly as generated: the document's final rates are never typed by hand.
#[test]
fn every_generated_paper_table_is_quoted_verbatim() {
    let doc = std::fs::read_to_string(root().join("docs/RESULTS.md")).unwrap();
    let mut quoted = 0;
    let mut tables = Vec::new();
    for entry in std::fs::read_dir(root().join("results")).unwrap() {
        let exp = entry.unwrap().path();
        tables.push(exp.join("paper.md"));
        // Its reports at a matched budget (`meben report --at-steps N`), if any.
        if exp.is_dir() {
            for sub in std::fs::read_dir(&exp).unwrap() {
                let sub = sub.unwrap().path();
                if sub.file_name().and_then(|n| n.to_str()).and_then(rl::app::report::at_steps_of).is_some() {
                    tables.push(sub.join("paper.md"));
                }
            }
        }
    }
    for table in tables {
        if table.is_file() {
            let text = std::fs::read_to_string(&table).unwrap();
            assert!(doc.contains(&text), "docs/RESULTS.md does not quote {} as generated", table.display());
            quoted += 1;
        }
    }
    assert!(quoted >= 7, "only {quoted} generated tables under results/");
}

/// The figures written with two decimals in `line` (`93.95`), leaving out env steps
/// (`20.15M`, `81.92k`) and figures with more decimals (`1.759M`, `5.538`); a minus sign
/// written before one (`−3.19`, `-3.19`, after a space or an opening bracket) is its sign.
fn two_decimal_figures(line: &str) -> Vec<String> {
    let bytes = line.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        if !bytes[i].is_ascii_digit() || (i > 0 && (bytes[i - 1].is_ascii_digit() || bytes[i - 1] == b'.')) {
            i += 1;
            continue;
        }
        let start = i;
        while i < bytes.len() && bytes[i].is_ascii_digit() {
            i += 1;
        }
        let point = i;
        if point < bytes.len() && bytes[point] == b'.' {
            i += 1;
            while i < bytes.len() && bytes[i].is_ascii_digit() {
                i += 1;
            }
            let unit = bytes.get(i).copied();
            if i - point == 3 && !matches!(unit, Some(b'M' | b'k' | b'G')) {
                let before = &line[..start];
                let sign = ["−", "-"]
                    .iter()
                    .find_map(|m| before.strip_suffix(m))
                    .is_some_and(|rest| rest.is_empty() || rest.ends_with([' ', '(', '[']));
                out.push(format!("{}{}", if sign { "-" } else { "" }, &line[start..i]));
            }
        }
    }
    out
}

/// Every value a two-decimal figure of a section may quote (the module docs): its
/// experiments' rates and report statistics, the paper's figures, and the values of the
/// `metrics.csv` columns in `named`.
fn evidence(experiments: &[String], named: &[String]) -> Vec<f64> {
    let results = root().join("results");
    let mut values = Vec::new();
    for exp in experiments {
        let dir = results.join(exp);
        // An experiment of evaluations only (`results/assignment_swap`) has no report.
        let mut reports: Vec<PathBuf> = [dir.join("report.csv")].into_iter().filter(|r| r.is_file()).collect();
        for sub in std::fs::read_dir(&dir).unwrap() {
            let sub = sub.unwrap().path();
            if sub.file_name().and_then(|n| n.to_str()).and_then(rl::app::report::at_steps_of).is_some() {
                reports.push(sub.join("report.csv"));
            }
        }
        for report in reports {
            for r in read_report(&report) {
                let stats = [
                    "mean_pct",
                    "se_pct",
                    "draw_mean_pct",
                    "lose_mean_pct",
                    "iqm_pct",
                    "iqm_ci_low_pct",
                    "iqm_ci_high_pct",
                    "mean_ci_low_pct",
                    "mean_ci_high_pct",
                ];
                values.extend(stats.iter().filter_map(|k| r[*k].parse::<f64>().ok()));
                let seeds: f64 = r["seeds"].parse().unwrap();
                values.push(r["se_pct"].parse::<f64>().unwrap() * seeds.sqrt());
            }
        }
        for generated in GENERATED_TABLES {
            if let Ok(text) = std::fs::read_to_string(dir.join(generated)) {
                values.extend(table_numbers(&text));
            }
        }
        for run in runs_of(std::slice::from_ref(exp)) {
            for row in read_metrics(&run) {
                for (column, v) in row.cells() {
                    if ["eval_success_rate", "eval_win_rate", "eval_draw_rate"].iter().any(|p| column.starts_with(p)) {
                        values.push(100.0 * v);
                    }
                    if named.contains(&column) {
                        values.push(v);
                    }
                }
            }
        }
    }
    let paper = std::fs::read_to_string(results.join("paper.toml")).unwrap();
    for line in paper.lines() {
        if let Some(v) = line.strip_prefix("mean = ").or_else(|| line.strip_prefix("sd = ")) {
            values.push(v.parse().unwrap());
        }
    }
    values
}

/// Every number in a cell of a Markdown table of `text` (`| 8.57 |`, `| 96.9% |`, a
/// half-width `| ±1.50 |`), and both ends of an interval cell (`| [44.03, 50.13] |`).
fn table_numbers(text: &str) -> Vec<f64> {
    let number = |c: &str| c.trim().trim_start_matches('±').trim_end_matches('%').parse::<f64>().ok();
    text.lines()
        .filter(|l| l.starts_with('|'))
        .flat_map(|l| l.split('|'))
        .flat_map(|c| match c.trim().strip_prefix('[').and_then(|c| c.strip_suffix(']')) {
            Some(interval) => interval.split(',').map(number).collect::<Option<Vec<f64>>>().unwrap_or_default(),
            None => number(c).into_iter().collect(),
        })
        .collect()
}

#[test]
fn a_diagnostics_table_gives_its_cells_numbers() {
    let text = "Scores at 2 m: 1.25.\n\n| run | P | steps | share |\n|---|---:|---:|---:|\n| `a/seed0` | 0.93 | 8008 | 97.8% |\n";
    assert_eq!(table_numbers(text), vec![0.93, 8008.0, 97.8]);
    let intervals = "| run | own | 95% |\n|---|---:|---:|\n| `a` | 47.07 | [44.03, 50.13] |\n| `b` | 1 | [x, 2] |\n";
    // (A header that is a number, `95%`, counts too; an interval that is not two numbers does not.)
    assert_eq!(table_numbers(intervals), vec![95.0, 47.07, 44.03, 50.13, 1.0]);
    assert_eq!(table_numbers("| `a` | -0.37 | ±116.00 | – |\n"), vec![-0.37, 116.0]);
}

/// The names in backticks in `text` (`entropy_t0`).
fn backticked(text: &str) -> Vec<String> {
    text.split('`').skip(1).step_by(2).map(str::to_string).collect()
}

/// The lines of every generated paper table under `results/` (quoted verbatim, checked by
/// [`every_generated_paper_table_is_quoted_verbatim`]).
fn generated_lines() -> std::collections::HashSet<String> {
    let mut lines = std::collections::HashSet::new();
    for entry in std::fs::read_dir(root().join("results")).unwrap() {
        let exp = entry.unwrap().path();
        if !exp.is_dir() {
            continue;
        }
        let mut tables = vec![exp.join("paper.md")];
        for sub in std::fs::read_dir(&exp).unwrap() {
            tables.push(sub.unwrap().path().join("paper.md"));
        }
        for t in tables.iter().filter(|t| t.is_file()) {
            lines.extend(std::fs::read_to_string(t).unwrap().lines().map(str::to_string));
        }
    }
    lines
}

/// A section of the document: its `## ` heading and its `### ` heading (or the `## ` one
/// again before any).
type SectionKey = (String, String);

/// The `## ` parts of the document whose prose is checked against the evidence: the
/// reproduction's three waves and the learned task assignment's runs.
const EVIDENCE_PARTS: [&str; 4] = [
    "## The reproduction",
    "## Second wave of the reproduction",
    "## Third wave of the reproduction",
    "## A learned task assignment",
];

/// The reproduction's prose (its `## ` parts, [`EVIDENCE_PARTS`]) retypes per-seed
/// figures, and a few statistics, from the evidence: every two-decimal figure of it, outside
/// the generated tables, is a value of the section's evidence (module docs).
#[test]
fn the_reproduction_prose_quotes_the_committed_evidence() {
    let doc = std::fs::read_to_string(root().join("docs/RESULTS.md")).unwrap();
    let generated = generated_lines();
    // (part, section) -> its lines with their numbers, in order.
    let mut sections: Vec<(SectionKey, Vec<(usize, &str)>)> = Vec::new();
    let (mut inside, mut part, mut section) = (false, String::new(), String::new());
    for (i, line) in doc.lines().enumerate() {
        if line.starts_with("## ") {
            inside = EVIDENCE_PARTS.iter().any(|p| line.starts_with(p));
            (part, section) = (line.to_string(), line.to_string());
        }
        if !inside {
            continue;
        }
        if line.starts_with("### ") {
            section = line.to_string();
        }
        match sections.last_mut() {
            Some((key, lines)) if *key == (part.clone(), section.clone()) => lines.push((i + 1, line)),
            _ => sections.push(((part.clone(), section.clone()), vec![(i + 1, line)])),
        }
    }
    assert!(sections.len() >= 5, "RESULTS.md: the reproduction's sections are not found");
    let text_of = |lines: &[(usize, &str)]| lines.iter().map(|(_, l)| *l).collect::<Vec<_>>().join("\n");
    let (mut checked, mut wrong) = (0, Vec::new());
    for ((part, section), lines) in &sections {
        let mut experiments = linked_experiments(&text_of(lines));
        if experiments.is_empty() {
            let whole: Vec<(usize, &str)> =
                sections.iter().filter(|((p, _), _)| p == part).flat_map(|(_, l)| l.iter().copied()).collect();
            experiments = linked_experiments(&text_of(&whole));
        }
        // Paragraphs: runs of non-blank lines.
        for paragraph in lines.split(|(_, l)| l.trim().is_empty()).filter(|p| !p.is_empty()) {
            let values = evidence(&experiments, &backticked(&text_of(paragraph)));
            for (n, line) in paragraph {
                if line.starts_with("    ") || generated.contains(*line) {
                    continue;
                }
                for shown in two_decimal_figures(line) {
                    checked += 1;
                    if !values.iter().any(|&v| quotes(&shown, v)) {
                        wrong.push(format!(
                            "RESULTS.md line {n} ({section}): {shown} is no value of the evidence of {experiments:?}"
                        ));
                    }
                }
            }
        }
    }
    println!("{checked} figures of the prose checked");
    assert!(checked > 200, "only {checked} figures of the prose checked");
    assert!(wrong.is_empty(), "RESULTS.md's prose disagrees with results/:\n{}", wrong.join("\n"));
}

#[test]
fn two_decimal_figures_leave_out_env_steps_and_longer_figures() {
    assert_eq!(
        two_decimal_figures("93.95, 7.91% at 20.15M and 81.92k; 1.759M, 5.538 h, 12.5, (99.71)"),
        ["93.95", "7.91", "99.71"]
    );
    // A minus sign after a space or bracket is the figure's; a hyphen inside a word is not.
    assert_eq!(two_decimal_figures("(−3.19, -16.78 and x-2.53)"), ["-3.19", "-16.78", "2.53"]);
    assert_eq!(backticked("the `entropy_t0` and `approx_kl_t0` columns"), ["entropy_t0", "approx_kl_t0"]);
}
