//! Running a sweep ([`run_sweep`]): the runs a shard and `--only` patterns select
//! ([`RunSelection`], [`Shard`]), each skipped when done, resumed when partial (after
//! checking its configuration) or trained, and what was done ([`SweepOutcome`]).

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use crate::app::record::RunSummary;
use crate::app::run_dir::{RunDir, RunStatus};
use crate::app::sweep::{Sweep, SweepRun};
use crate::error::{Result, RlError};
use crate::mappo::config::TrainConfig;
use crate::mappo::config_match;

/// Shard `index` of `count` (1-based): the runs whose 0-based position `i` has
/// `i % count == index - 1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// Which shard, from 1 to `count`.
    pub index: usize,
    /// How many shards.
    pub count: usize,
}

/// Which runs of a sweep to run: a shard and name patterns (module docs).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RunSelection {
    /// Only this shard (all runs if `None`).
    pub shard: Option<Shard>,
    /// Only runs whose name contains one of these (all runs if empty).
    pub only: Vec<String>,
}

impl RunSelection {
    /// Every run.
    pub fn all() -> RunSelection {
        RunSelection::default()
    }

    /// The runs of one shard.
    pub fn shard(shard: Shard) -> RunSelection {
        RunSelection { shard: Some(shard), only: Vec::new() }
    }

    /// Whether the run named `name` at 0-based position `i` of the sweep is selected.
    pub fn contains(&self, i: usize, name: &str) -> bool {
        self.shard.is_none_or(|s| s.contains(i))
            && (self.only.is_empty() || self.only.iter().any(|p| name.contains(p.as_str())))
    }

    /// ` (shard k/n, only a, b)`, or empty when every run is selected: for progress lines.
    fn describe(&self) -> String {
        let mut parts = Vec::new();
        if let Some(s) = self.shard {
            parts.push(format!("shard {s}"));
        }
        if !self.only.is_empty() {
            parts.push(format!("only {}", self.only.join(", ")));
        }
        if parts.is_empty() { String::new() } else { format!(" ({})", parts.join(", ")) }
    }
}

/// What [`run_sweep`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SweepOutcome {
    /// Runs of the shard.
    pub runs: usize,
    /// Runs trained from scratch.
    pub trained: usize,
    /// Runs resumed from their checkpoint.
    pub resumed: usize,
    /// Runs already done.
    pub skipped: usize,
    /// Runs another process was training ([`RlError::RunInUse`]): left to it, not failed.
    pub taken: usize,
}

impl fmt::Display for SweepOutcome {
    /// `4 runs: 1 trained, 1 resumed, 1 already done, 1 taken by another process`, for
    /// the sweep's last line.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: {} trained, {} resumed, {} already done",
            crate::app::report::count(self.runs, "run"),
            self.trained,
            self.resumed,
            self.skipped
        )?;
        if self.taken > 0 {
            write!(
                f,
                ", {} taken by another process (training there; `meben status` shows {})",
                self.taken,
                if self.taken == 1 { "it" } else { "them" }
            )?;
        }
        Ok(())
    }
}

impl Shard {
    /// Parses `k/n` (1 <= k <= n); errors name the value and what is expected.
    pub fn parse(s: &str) -> Result<Shard> {
        let err = |msg: String| RlError::config("command line", "--shard", s, msg);
        let usage = "expected k/n, shard k of n counted from 1 (e.g. 3/8)";
        let (k, n) = s.split_once('/').ok_or_else(|| err(usage.into()))?;
        let (Ok(index), Ok(count)) = (k.trim().parse::<usize>(), n.trim().parse::<usize>()) else {
            return Err(err(usage.into()));
        };
        if count == 0 {
            return Err(err("the number of shards n must be at least 1".into()));
        }
        if index == 0 || index > count {
            return Err(err(format!("shard {index} of {count} does not exist: k must lie in 1..={count}")));
        }
        Ok(Shard { index, count })
    }

    /// Whether the run at 0-based position `i` of the sweep belongs to this shard.
    pub fn contains(&self, i: usize) -> bool {
        i % self.count == self.index - 1
    }

    /// The items of this shard, in order.
    pub fn select<T>(&self, items: Vec<T>) -> Vec<T> {
        items.into_iter().enumerate().filter(|(i, _)| self.contains(*i)).map(|(_, x)| x).collect()
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = RlError;
    fn from_str(s: &str) -> Result<Shard> {
        Shard::parse(s)
    }
}

/// A shard beyond the sweep's runs (`--shard 9/10` of a sweep of 8 runs) is empty: it
/// says so on standard error and returns an outcome of no runs, writing nothing.
///
/// Runs the runs of `sweep` chosen by `selection` under `out`, skipping finished runs,
/// resuming partial ones (module docs) and calling `train_fn` for the others; writes a copy
/// of the sweep file to `<out>/sweep.toml` if there is none.
///
/// A run that fails (its `train_fn` returns an error, or its checkpoint was made with a
/// different configuration) does not stop the others; the error then lists every failed
/// run. A run another process holds ([`RlError::RunInUse`]: a second `meben ablate` on the
/// same directory) is no failure: it is counted as taken and left to that process. A run interrupted on request ([`RlError::Interrupted`], [`crate::stop`]) stops
/// the sweep: that error is returned at once, and the same command goes on from there. Progress is printed to standard error, one line per run.
pub fn run_sweep(
    sweep: &Sweep,
    out: &Path,
    selection: &RunSelection,
    mut train_fn: impl FnMut(&TrainConfig, &RunDir) -> Result<RunSummary>,
) -> Result<SweepOutcome> {
    let all = sweep.runs()?;
    let total = all.len();
    if let Some(shard) = selection.shard
        && !(0..total).any(|i| shard.contains(i))
    {
        // More shards than runs (a Slurm array larger than the sweep): this one is empty,
        // which is no error (rl/sweeps/slurm_array.sh).
        eprintln!(
            "meben: shard {shard} of {} is empty: the sweep has {} for {} shards; nothing to do",
            sweep.source,
            crate::app::report::count(total, "run"),
            shard.count
        );
        return Ok(SweepOutcome::default());
    }
    let runs: Vec<(usize, SweepRun)> =
        all.into_iter().enumerate().filter(|(i, r)| selection.contains(*i, &r.name)).collect();
    if runs.is_empty() {
        return Err(RlError::config(
            "command line",
            "--only",
            selection.only.join(", "),
            format!("no run of the {total} in {} is selected{}", sweep.source, selection.describe()),
        ));
    }
    std::fs::create_dir_all(out).map_err(|e| RlError::file(out, format!("cannot create the directory: {e}")))?;
    let copy = out.join("sweep.toml");
    if !copy.exists()
        && let Err(e) = nn::write_atomic(&copy, sweep.text.as_bytes())
        && !copy.exists()
    {
        // Another shard may have written it at the same moment; only a missing copy fails.
        return Err(e.into());
    }
    let mut outcome = SweepOutcome { runs: runs.len(), ..SweepOutcome::default() };
    let mut failed: Vec<String> = Vec::new();
    let shard_text = selection.describe();
    for (pos, (i, run)) in runs.iter().enumerate() {
        let dir = RunDir::new(out.join(&run.name));
        let status = dir.status();
        let head = format!("[{}/{}{shard_text}, run {} of {total}] {}", pos + 1, runs.len(), i + 1, run.name);
        let result = match status {
            RunStatus::Done => {
                if let Ok(saved) = TrainConfig::load(&dir.config()) {
                    let diff = config_differences(&saved, &run.config, &config_match::NEVER_IDENTITY_FIELDS);
                    if !diff.is_empty() {
                        eprintln!(
                            "{head}: warning: finished with a configuration that differs from the sweep's: {}",
                            diff.join("; ")
                        );
                    }
                }
                eprintln!("{head}: done, skipped");
                outcome.skipped += 1;
                continue;
            }
            RunStatus::Partial => check_resumable(&dir, &run.config).and_then(|()| {
                eprintln!("{head}: resuming");
                train_fn(&run.config, &dir)
            }),
            // `train` makes the directory once it begins (a stop before then leaves none).
            RunStatus::New => {
                eprintln!("{head}: training");
                train_fn(&run.config, &dir)
            }
        };
        match result {
            // A stop was asked for: the sweep stops too (the same command goes on from here).
            Err(e @ RlError::Interrupted { .. }) => return Err(e),
            Ok(_) if status == RunStatus::Partial => outcome.resumed += 1,
            Ok(_) => outcome.trained += 1,
            // Another `meben ablate` on this directory holds the run: it is being trained.
            Err(RlError::RunInUse { holder, .. }) => {
                eprintln!("{head}: taken by {holder}, left to it");
                outcome.taken += 1;
            }
            Err(e) => {
                eprintln!("{head}: failed: {e}");
                failed.push(format!("{}: {e}", run.name));
            }
        }
    }
    if !failed.is_empty() {
        return Err(RlError::file(
            out,
            format!(
                "{} of {} runs{shard_text} failed ({} trained, {} resumed, {} skipped, {} taken by another \
                 process):\n  {}",
                failed.len(),
                runs.len(),
                outcome.trained,
                outcome.resumed,
                outcome.skipped,
                outcome.taken,
                failed.join("\n  ")
            ),
        ));
    }
    Ok(outcome)
}

/// The fields a sweep lets differ between a partial run's saved configuration and the
/// sweep's when it resumes the run: those no result depends on, and the budget `steps`
/// (raised to train longer); not `num_evals`, since the sweep file fixes each run's
/// evaluation schedule ([`crate::mappo::config_match`]).
const RESUME_MAY_DIFFER: [&str; 7] =
    ["steps", "checkpoint_every", "threads", "device", "act_device", "gpu_matmul_tile", "gpu_reduce_lanes"];

/// Checks that a partial run's saved configuration is the sweep's ([`RESUME_MAY_DIFFER`]).
fn check_resumable(dir: &RunDir, wanted: &TrainConfig) -> Result<()> {
    let saved = TrainConfig::load(&dir.config())?;
    let diff = config_differences(&saved, wanted, &RESUME_MAY_DIFFER);
    if diff.is_empty() {
        return Ok(());
    }
    Err(RlError::file(
        dir.root(),
        format!(
            "the checkpoint was made with a different configuration than the sweep asks for ({}); use another \
             --out directory, restore the sweep file, or delete this run directory to start it again",
            diff.join("; ")
        ),
    ))
}

/// `field: saved X, sweep Y` for every field that differs but those of `may_differ`
/// ([`config_match::differences`], the comparison resuming makes too).
fn config_differences(saved: &TrainConfig, wanted: &TrainConfig, may_differ: &[&str]) -> Vec<String> {
    config_match::differences(saved, wanted, may_differ)
        .into_iter()
        .map(|d| format!("{}: saved {}, sweep {}", d.field, d.first, d.second))
        .collect()
}

#[cfg(test)]
mod tests {
    use std::cell::RefCell;

    use super::*;
    use crate::app::sweep::EXAMPLE;
    use crate::app::test_util::TempDir;

    #[test]
    fn shards_parse_and_partition() {
        assert_eq!(Shard::parse("3/8").unwrap(), Shard { index: 3, count: 8 });
        assert_eq!("1/1".parse::<Shard>().unwrap().to_string(), "1/1");
        for bad in ["0/8", "9/8", "x/y", "3", "1/0", "-1/3", ""] {
            let msg = Shard::parse(bad).unwrap_err().to_string();
            assert!(msg.contains("--shard") && msg.contains(&format!("{bad:?}")), "{bad}: {msg}");
        }
        assert!(Shard::parse("9/8").unwrap_err().to_string().contains("1..=8"));
        let runs = Sweep::parse(EXAMPLE, "x").unwrap().runs().unwrap();
        let names: Vec<String> = runs.iter().map(|r| r.name.clone()).collect();
        for n in 1..=7 {
            let mut seen: Vec<String> = Vec::new();
            for k in 1..=n {
                let part = Shard { index: k, count: n }.select(names.clone());
                assert!(part.len() >= names.len() / n && part.len() <= names.len().div_ceil(n));
                seen.extend(part);
            }
            seen.sort();
            let mut all = names.clone();
            all.sort();
            assert_eq!(seen, all, "{n} shards");
        }
        assert_eq!(Shard { index: 2, count: 3 }.select((0..7).collect()), vec![1, 4]);
    }

    /// Writes what a trainer leaves behind: `config.toml`, then a checkpoint, then `done.json`.
    fn fake_run(dir: &RunDir, config: &TrainConfig, done: bool) {
        std::fs::create_dir_all(dir.root()).unwrap();
        config.save(&dir.config()).unwrap();
        std::fs::write(dir.checkpoint(), "{}").unwrap();
        if done {
            std::fs::write(dir.done(), "{}").unwrap();
        }
    }

    #[test]
    fn skips_done_resumes_partial_trains_new() {
        let tmp = TempDir::new("sweep-resume");
        let text = "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\", \"shnn\"]\nseeds = [0, 1]\npreset = \"quick\"";
        let sweep = Sweep::parse(text, "s.toml").unwrap();
        let runs = sweep.runs().unwrap();
        // run 0: done; run 1: partial (started with fewer steps); runs 2, 3: new.
        fake_run(&RunDir::new(tmp.0.join(&runs[0].name)), &runs[0].config, true);
        let shorter = TrainConfig { steps: 1000, ..runs[1].config.clone() };
        fake_run(&RunDir::new(tmp.0.join(&runs[1].name)), &shorter, false);
        let calls = RefCell::new(Vec::new());
        let fake_train = |c: &TrainConfig, r: &RunDir| {
            calls.borrow_mut().push((c.model.clone(), c.seed, r.root().to_path_buf()));
            fake_run(r, c, true);
            Ok(RunSummary::default())
        };
        let outcome = run_sweep(&sweep, &tmp.0, &RunSelection::all(), fake_train).unwrap();
        assert_eq!(outcome, SweepOutcome { runs: 4, trained: 2, resumed: 1, skipped: 1, taken: 0 });
        let called: Vec<(String, u64)> = calls.borrow().iter().map(|(m, s, _)| (m.clone(), *s)).collect();
        assert_eq!(called, [("mlp_hn".to_string(), 1), ("shnn".into(), 0), ("shnn".into(), 1)]);
        assert_eq!(calls.borrow()[0].2, tmp.0.join("team_reach_1_ant/mlp_hn/seed1"));
        assert_eq!(std::fs::read_to_string(tmp.0.join("sweep.toml")).unwrap(), text);

        // Everything is done now.
        calls.borrow_mut().clear();
        let outcome = run_sweep(&sweep, &tmp.0, &RunSelection::all(), fake_train).unwrap();
        assert_eq!(outcome, SweepOutcome { runs: 4, trained: 0, resumed: 0, skipped: 4, taken: 0 });
        assert!(calls.borrow().is_empty());
    }

    /// A stop asked for between runs (the first signal, during a sweep's last iteration of
    /// a run) ends the sweep before the next run: its error says nothing was changed, and
    /// nothing is (no directory is made for it); a partial run keeps its own.
    #[test]
    fn a_stop_before_a_new_run_leaves_no_directory() {
        let tmp = TempDir::new("sweep-stop");
        let text = "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\"]\nseeds = [0, 1]\npreset = \"quick\"";
        let sweep = Sweep::parse(text, "s.toml").unwrap();
        let runs = sweep.runs().unwrap();
        let mut calls = 0;
        let e = run_sweep(&sweep, &tmp.0, &RunSelection::all(), |c, r| {
            calls += 1;
            if c.seed == 0 {
                fake_run(r, c, true);
                return Ok(RunSummary::default());
            }
            Err(RlError::Interrupted { run: r.root().to_path_buf(), iteration: None })
        })
        .unwrap_err();
        assert!(matches!(e, RlError::Interrupted { iteration: None, .. }), "{e}");
        assert_eq!(calls, 2);
        assert!(tmp.0.join(&runs[0].name).join("done.json").is_file());
        assert!(!tmp.0.join(&runs[1].name).exists(), "the stopped new run left its directory");

        // A partial run stopped before its next iteration keeps its directory and checkpoint.
        let partial = RunDir::new(tmp.0.join(&runs[1].name));
        fake_run(&partial, &runs[1].config, false);
        let e = run_sweep(&sweep, &tmp.0, &RunSelection::all(), |_, r| {
            Err(RlError::Interrupted { run: r.root().to_path_buf(), iteration: None })
        })
        .unwrap_err();
        assert!(matches!(e, RlError::Interrupted { .. }), "{e}");
        assert!(partial.checkpoint().is_file());
    }

    /// Issue 44 item 11: two `meben ablate` on one directory shared the work but both
    /// exited 1 with "2 of 4 runs failed": a run whose lock another process holds is taken,
    /// not failed, and the sweep succeeds; its last line is written for a person.
    #[test]
    fn a_run_another_process_holds_is_taken_not_failed() {
        let tmp = TempDir::new("sweep-taken");
        let text = "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\"]\nseeds = [0, 1, 2]\npreset = \"quick\"";
        let sweep = Sweep::parse(text, "s.toml").unwrap();
        let runs = sweep.runs().unwrap();
        let held = RunDir::new(tmp.0.join(&runs[1].name));
        std::fs::create_dir_all(held.root()).unwrap();
        // As another `meben ablate` holds it (an flock on its own open file).
        let other = crate::app::lock::RunLock::acquire(held.root()).unwrap();
        let mut trained = Vec::new();
        let outcome = run_sweep(&sweep, &tmp.0, &RunSelection::all(), |c, r| {
            std::fs::create_dir_all(r.root()).unwrap(); // as `train` does
            let _lock = crate::app::lock::RunLock::acquire(r.root())?;
            trained.push(c.seed);
            fake_run(r, c, true);
            Ok(RunSummary::default())
        })
        .unwrap();
        assert_eq!(trained, [0, 2]);
        assert_eq!(outcome, SweepOutcome { runs: 3, trained: 2, resumed: 0, skipped: 0, taken: 1 });
        assert_eq!(
            outcome.to_string(),
            "3 runs: 2 trained, 0 resumed, 0 already done, 1 taken by another process (training there; `meben \
             status` shows it)"
        );
        drop(other);
        let outcome = run_sweep(&sweep, &tmp.0, &RunSelection::all(), |c, r| {
            fake_run(r, c, true);
            Ok(RunSummary::default())
        })
        .unwrap();
        assert_eq!(outcome.to_string(), "3 runs: 1 trained, 0 resumed, 2 already done");
    }

    #[test]
    fn shards_run_only_their_runs_and_mismatched_checkpoints_fail() {
        let tmp = TempDir::new("sweep-shard");
        let text = "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\"]\nseeds = [0, 1, 2, 3, 4]\npreset = \"quick\"";
        let sweep = Sweep::parse(text, "s.toml").unwrap();
        let runs = sweep.runs().unwrap();
        let mut seeds = Vec::new();
        let outcome = run_sweep(&sweep, &tmp.0, &RunSelection::shard(Shard::parse("2/2").unwrap()), |c, _| {
            seeds.push(c.seed);
            Ok(RunSummary::default())
        })
        .unwrap();
        assert_eq!(seeds, [1, 3]);
        assert_eq!(outcome.trained, 2);

        // A partial run made with another learning rate is not resumed; the others still run.
        let other = TrainConfig { learning_rate: 1e-3, num_evals: 3, ..runs[0].config.clone() };
        fake_run(&RunDir::new(tmp.0.join(&runs[0].name)), &other, false);
        let mut seeds = Vec::new();
        let msg = run_sweep(&sweep, &tmp.0, &RunSelection::shard(Shard::parse("1/2").unwrap()), |c, _| {
            seeds.push(c.seed);
            Ok(RunSummary::default())
        })
        .unwrap_err()
        .to_string();
        assert_eq!(seeds, [2, 4]);
        for w in ["team_reach_1_ant/mlp_hn/seed0", "learning_rate", "num_evals", "1 of 3 runs"] {
            assert!(msg.contains(w), "{msg} (missing {w})");
        }
        assert!(!msg.contains("steps:"), "{msg}");
    }

    #[test]
    fn only_patterns_select_runs_and_threads_and_devices_do_not_block_a_resume() {
        let tmp = TempDir::new("sweep-only");
        let text = "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\", \"shnn\"]\nseeds = [0, 1]\npreset = \"quick\"";
        let sweep = Sweep::parse(text, "s.toml").unwrap();
        let runs = sweep.runs().unwrap();
        // A partial shnn run trained with one thread, other checkpoints and on the GPU; the
        // sweep says every core, its own checkpoint interval and the CPU.
        let one_thread =
            TrainConfig { threads: 1, checkpoint_every: 7, device: tensor::Device::Gpu, ..runs[3].config.clone() };
        fake_run(&RunDir::new(tmp.0.join(&runs[3].name)), &one_thread, false);
        let selection = RunSelection { shard: None, only: vec!["shnn/".into(), "mlp_hn/seed0".into()] };
        let mut called = Vec::new();
        let outcome = run_sweep(&sweep, &tmp.0, &selection, |c, _| {
            called.push((c.model.clone(), c.seed));
            Ok(RunSummary::default())
        })
        .unwrap();
        assert_eq!(called, [("mlp_hn".to_string(), 0), ("shnn".into(), 0), ("shnn".into(), 1)]);
        assert_eq!(outcome, SweepOutcome { runs: 3, trained: 2, resumed: 1, skipped: 0, taken: 0 });

        // A pattern that matches nothing is an error naming it, not a silent no-op.
        let none = RunSelection { shard: Some(Shard::parse("2/2").unwrap()), only: vec!["2_ants".into()] };
        let msg = run_sweep(&sweep, &tmp.0, &none, |_, _| Ok(RunSummary::default())).unwrap_err().to_string();
        for w in ["--only", "2_ants", "no run of the 4", "s.toml", "shard 2/2"] {
            assert!(msg.contains(w), "{msg} (missing {w})");
        }
    }

    /// Issue 77 item 11: `--shard k/n` with more shards than runs exited 1 with a message
    /// about `--only`, where rl/sweeps/slurm_array.sh says the extra shards are empty. An
    /// empty shard succeeds with no runs, writing nothing; an `--only` that selects nothing
    /// of a shard with runs is still an error.
    #[test]
    fn a_shard_beyond_the_runs_is_empty_not_an_error() {
        let tmp = TempDir::new("sweep-empty-shard");
        let text = "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\"]\nseeds = [0, 1]\npreset = \"quick\"";
        let sweep = Sweep::parse(text, "s.toml").unwrap();
        let out = tmp.0.join("out");
        for only in [vec![], vec!["seed0".to_string()]] {
            let selection = RunSelection { shard: Some(Shard::parse("3/8").unwrap()), only };
            let outcome = run_sweep(&sweep, &out, &selection, |_, _| panic!("no run is in shard 3/8")).unwrap();
            assert_eq!(outcome, SweepOutcome::default());
            assert_eq!(outcome.to_string(), "0 runs: 0 trained, 0 resumed, 0 already done");
        }
        assert!(!out.exists(), "an empty shard wrote {}", out.display());
        let none = RunSelection { shard: Some(Shard::parse("2/8").unwrap()), only: vec!["seed0".into()] };
        let msg = run_sweep(&sweep, &out, &none, |_, _| Ok(RunSummary::default())).unwrap_err().to_string();
        assert!(msg.contains("--only") && msg.contains("shard 2/8"), "{msg}");
    }
}
