//! Training in a run directory ([`crate::app::run_dir`]): [`train`] drives a
//! [`Trainer`] (module [`crate::mappo::trainer`]) and writes the resolved configuration, a
//! metrics row per iteration, the evaluations, checkpoints, the learning curve, the
//! summary and the build of each session (`builds.csv`, [`crate::app::build_info`]), and
//! resumes a run exactly from its checkpoint.

use std::io::Write;
use std::time::Instant;

use crate::app::build_info::record_build;
use crate::app::lock::{RunLock, remove_stale_temporaries};
use crate::app::metrics::{MetricsLayout, MetricsRow, eval_column, loss_column};
use crate::app::record::RunSummary;
use crate::app::run_dir::RunDir;
use crate::error::{Result, RlError};
use crate::mappo::checkpoint::Checkpoint;
use crate::mappo::config::TrainConfig;
use crate::mappo::evaluate::EvalSummary;
use crate::mappo::ppo::LossStats;
use crate::mappo::trainer::{IterationStats, Trainer};
use crate::stop::StopFlag;

/// How [`train`] runs, beyond the configuration.
#[derive(Clone, Debug, Default)]
pub struct TrainOptions {
    /// Show a progress bar on the terminal (and a line per evaluation otherwise).
    pub progress: bool,
    /// Stop (with a checkpoint) after this many iterations in total, as if interrupted.
    pub stop_after: Option<u64>,
    /// Once set, stop after the current iteration with a checkpoint and return
    /// [`RlError::Interrupted`] ([`crate::stop`]).
    pub stop: StopFlag,
}

/// How many of `num_evals` evaluations, evenly spaced over `n` iterations with the last at
/// the end, fall at or before iteration `i` (0 for `n = 0`).
pub(crate) fn evals_through(i: u64, n: u64, num_evals: u64) -> u64 {
    (i * num_evals).checked_div(n).unwrap_or(0)
}

/// Whether an evaluation falls after iteration `i` (1-based) of `n` ([`evals_through`]).
fn eval_due(i: u64, n: u64, num_evals: u64) -> bool {
    evals_through(i, n, num_evals) > evals_through(i - 1, n, num_evals)
}

/// Fills a metrics row from an iteration's figures and evaluations (one per rotation of
/// `eval_rotations`, or none).
fn metrics_row(t: &Trainer, s: &IterationStats, wall: f64, sps: f64, evals: &[EvalSummary]) -> MetricsRow {
    let sumo = t.spec.n_teams > 1;
    let mut r = MetricsRow::default();
    r.set("iteration", t.iteration as f64);
    r.set("env_steps", t.env_steps as f64);
    r.set("wall_s", wall);
    r.set("steps_per_s", sps);
    r.set("curriculum_alpha", s.alpha);
    let ep = &s.episodes;
    r.set("train_episodes", ep.episodes as f64);
    if ep.episodes > 0 {
        let n = ep.episodes as f64;
        r.set("train_return_t0", ep.return_sum[0] / n);
        r.set("train_length", ep.length_sum as f64 / n);
        if sumo {
            r.set("train_return_t1", ep.return_sum[1] / n);
            r.set("train_win_rate_t0", ep.wins[0] as f64 / n);
            r.set("train_win_rate_t1", ep.wins[1] as f64 / n);
            r.set("train_draw_rate", ep.draws as f64 / n);
        } else {
            r.set("train_success_rate", ep.successes as f64 / n);
        }
    }
    if let Some(e) = evals.first() {
        r.set("eval_sampled", if e.sampled { 1.0 } else { 0.0 });
    }
    for (e, &deg) in evals.iter().zip(&t.config.eval_rotations) {
        let col = |base: &str| eval_column(base, deg);
        r.set(col("eval_episodes"), e.episodes as f64);
        r.set(col("eval_return_t0"), e.mean_return[0]);
        r.set(col("eval_length"), e.mean_length);
        if sumo {
            r.set(col("eval_return_t1"), e.mean_return[1]);
            r.set(col("eval_win_rate_t0"), e.win_rate[0]);
            r.set(col("eval_win_rate_t1"), e.win_rate[1]);
            r.set(col("eval_draw_rate"), e.draw_rate);
        } else {
            r.set(col("eval_success_rate"), e.success_rate);
        }
    }
    for (k, l) in s.losses.iter().enumerate().take(2) {
        for (name, x) in LossStats::RECORDED.iter().zip(l.recorded()) {
            r.set(loss_column(name, k), x);
        }
    }
    r
}

/// Keeps the metrics rows of iterations up to `iteration` (a resumed run drops rows written
/// after its checkpoint), each iteration once and in increasing order (the first row of an
/// iteration wins), and returns the file's text, with the header of `layout`. Damaged rows
/// (incomplete, not numbered, or with bytes that are not UTF-8) are dropped one by one: the
/// file is read as bytes, so one bad byte does not cost the other rows. A missing file has
/// no rows; any other error reading it is an error naming the file (before, an unreadable
/// file was taken as empty and rewritten without its rows: issue 77 item 3).
fn metrics_upto(path: &std::path::Path, iteration: u64, layout: &MetricsLayout) -> Result<String> {
    kept_metrics(path, std::fs::read(path), iteration, layout)
}

/// [`metrics_upto`] of the file at `path` whose reading gave `read`.
fn kept_metrics(
    path: &std::path::Path,
    read: std::io::Result<Vec<u8>>,
    iteration: u64,
    layout: &MetricsLayout,
) -> Result<String> {
    let mut out = layout.header();
    out.push('\n');
    let mut last: Option<u64> = None;
    let bytes = match read {
        Ok(bytes) => Some(bytes),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => {
            return Err(RlError::file(
                path,
                format!(
                    "cannot read the run's metrics ({e}); the resume would lose its rows up to the checkpoint: make \
                     it readable, or move it aside to start the metrics afresh"
                ),
            ));
        }
    };
    if let Some(bytes) = bytes {
        let text = String::from_utf8_lossy(&bytes);
        for line in text.lines().skip(1) {
            let complete = line.split(',').count() == layout.columns().len();
            let clean = !line.contains(char::REPLACEMENT_CHARACTER);
            match line.split(',').next().and_then(|c| c.parse::<u64>().ok()) {
                Some(i) if complete && clean && i <= iteration && last.is_none_or(|l| i > l) => {
                    last = Some(i);
                    out.push_str(line);
                    out.push('\n');
                }
                _ => {}
            }
        }
    }
    Ok(out)
}

/// The most worker threads a training may ask for on a machine of `cores` cores:
/// [`THREADS_PER_CORE`] per core, and at least [`MIN_THREADS_CAP`] (so that a sweep file
/// written for a larger machine still runs on a laptop). Beyond it the threads only contend:
/// on 2 cores, a run of 1.3 s took 22 to 31 s on 512 threads (issue 44 item 10).
pub fn max_threads(cores: usize) -> usize {
    cores.saturating_mul(THREADS_PER_CORE).max(MIN_THREADS_CAP)
}

/// Worker threads allowed per core ([`max_threads`]).
pub const THREADS_PER_CORE: usize = 4;

/// Worker threads allowed whatever the number of cores ([`max_threads`]).
pub const MIN_THREADS_CAP: usize = 64;

/// The cores this process may use (`std::thread::available_parallelism`, 1 if unknown).
fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Refuses `threads` above [`max_threads`] of `cores`, naming the value and the cores.
fn check_threads(threads: usize, cores: usize) -> Result<()> {
    let max = max_threads(cores);
    if threads > max {
        return Err(RlError::config(
            "config",
            "threads",
            threads,
            format!(
                "at most {max} worker threads on this machine's {cores} cores (the larger of {THREADS_PER_CORE} per \
                 core and {MIN_THREADS_CAP}; 0 uses every core, and results do not depend on it)"
            ),
        ));
    }
    Ok(())
}

/// Refuses to resume the checkpoint `c` (at `path`) under a budget of `config.steps` env
/// steps that it has already passed, or that it has reached but was not trained to: the run
/// would end at once without its final evaluation (`done.json` with `"final_eval": null`),
/// and its `config.toml` would say a budget smaller than the steps done. A finished run
/// resumed with its own budget, or a larger one, passes.
fn check_budget(c: &Checkpoint, config: &TrainConfig, path: &std::path::Path) -> Result<()> {
    let total = config.iterations();
    let own_total = c.config.iterations();
    let done = format!(
        "the {} env steps ({} iterations) this run has already done of its budget of {}",
        c.env_steps, c.iteration, c.config.steps
    );
    let message = if c.iteration > total {
        format!(
            "a budget of {} env steps ({total} iterations) is below {done}: {}",
            config.steps,
            if own_total > c.iteration {
                format!("give more than {} steps", c.env_steps)
            } else {
                format!("the run is finished; give at least {} steps", c.config.steps)
            }
        )
    } else if c.iteration == total && own_total > c.iteration {
        format!(
            "a budget of {} env steps ({total} iterations) is not more than {done}: the run would end without its \
             final evaluation; give more than {} steps",
            config.steps, c.env_steps
        )
    } else {
        return Ok(());
    };
    Err(RlError::config(path.display().to_string(), "steps", config.steps, message))
}

/// Trains `config` in `run`: from scratch, or from the run's checkpoint (module docs). The
/// resolved configuration goes to `config.toml`, a row per iteration to `metrics.csv`, the
/// state to `checkpoint.json` and the summary to `done.json` at the end. A run whose
/// `done.json` exists and whose steps are reached returns its summary at once; a budget not
/// above the steps a checkpoint has done is refused before anything is written. The run
/// directory is locked while training ([`RunLock`]: a second training of it fails at once,
/// naming the holder); temporary files of interrupted writes are removed first.
pub fn train(config: &TrainConfig, run: &RunDir, options: &TrainOptions) -> Result<RunSummary> {
    let threads = config.threads;
    check_threads(threads, cores())?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| RlError::config("config", "threads", threads, e.to_string()))?;
    pool.install(|| train_in_pool(config, run, options))
}

fn train_in_pool(config: &TrainConfig, run: &RunDir, options: &TrainOptions) -> Result<RunSummary> {
    if options.stop.is_requested() {
        // Asked to stop before it began (a sweep between runs): nothing is created or changed.
        return Err(RlError::Interrupted { run: run.root().to_path_buf(), iteration: None });
    }
    let ckpt_path = run.checkpoint();
    // A new run is built before its directory is created: building checks what validation
    // cannot (model options that do not apply to the model, the rollout's memory). First,
    // everything the training holds at once (environments, rollout, an evaluation's
    // environments) against the machine's memory, before any of it is built; a resumed run
    // is checked once its morphology files are (a missing one is then named with its copy).
    let fresh = if ckpt_path.is_file() {
        None
    } else {
        crate::mappo::memory::check_run_fits(config)?;
        Some(Trainer::new(config)?)
    };
    std::fs::create_dir_all(run.root()).map_err(|e| RlError::file(run.root(), format!("cannot create: {e}")))?;
    // Held until training returns: a second training of this directory is refused.
    let lock = RunLock::acquire(run.root())?;
    // The morphology files the environment names: recorded with a copy by a new run,
    // checked unchanged by a resumed one ([`crate::app::morphology`]).
    crate::app::morphology::record_or_verify(run, &config.env, ckpt_path.is_file())?;
    let (mut trainer, wall_before, mut last_evals) = if ckpt_path.is_file() {
        let c = Checkpoint::load(&ckpt_path)?;
        check_budget(&c, config, &ckpt_path)?;
        crate::mappo::memory::check_run_fits(config)?;
        let t = Trainer::from_checkpoint(&c, config, &ckpt_path)?;
        let evals: Vec<EvalSummary> = c.last_eval.iter().chain(&c.last_eval_rotated).cloned().collect();
        (t, c.wall_s, evals)
    } else {
        let t = match fresh {
            Some(t) => t,
            None => Trainer::new(config)?,
        };
        (t, 0.0, Vec::new())
    };
    // The rows kept up to the checkpoint, read before anything is written: an unreadable
    // metrics.csv stops the resume with nothing changed.
    let metrics_path = run.metrics();
    let layout = MetricsLayout::new(&config.eval_rotations);
    let kept_metrics = metrics_upto(&metrics_path, trainer.iteration, &layout)?;
    // Only now that the checkpoint has loaded: a failed resume changes nothing, and the
    // tensors file of a newer checkpoint outlives an older checkpoint.json put back in its
    // place (issue 77 item 2).
    remove_stale_temporaries(run.root(), &lock)?;
    let total = config.iterations();
    // Written before a finished run returns too: running the command again repairs a
    // damaged config.toml, which evaluation and rendering read.
    config.save(&run.config())?;
    if trainer.iteration >= total
        && let Some(s) = crate::app::record::read_summary(run)
    {
        return Ok(s);
    }
    let _ = std::fs::remove_file(run.done());
    record_build(&run.builds(), trainer.iteration)?;
    nn::write_atomic(&metrics_path, kept_metrics.as_bytes())?;
    let mut metrics = std::fs::OpenOptions::new()
        .append(true)
        .open(&metrics_path)
        .map_err(|e| RlError::file(&metrics_path, format!("cannot open: {e}")))?;
    let bar = crate::app::progress::Progress::new(options.progress, config, trainer.env_steps);
    let start = Instant::now();
    let mut since_ckpt = 0u64;
    // The stop flag is read once an iteration, so the iteration it stops after is the one
    // whose checkpoint is written.
    let mut requested = false;
    while trainer.iteration < total && !requested {
        if options.stop_after.is_some_and(|s| trainer.iteration >= s) {
            break;
        }
        let t0 = Instant::now();
        let gpu_clock = gpu_timeline_wanted(config.device);
        if gpu_clock {
            start_gpu_timeline()?;
        }
        let moved_before = tensor::transfers();
        let stats = trainer.iterate()?;
        let dt = t0.elapsed().as_secs_f64();
        let sps = config.steps_per_iteration() as f64 / dt;
        if timings_wanted() {
            eprintln!("meben: iteration {} took {dt:.3} s: {}", trainer.iteration, stats.timings.describe());
            let moved = tensor::transfers().since(&moved_before);
            eprintln!("meben: iteration {} moved {moved}", trainer.iteration);
        }
        if gpu_clock {
            eprintln!("meben: iteration {} on the GPU's clock: {}", trainer.iteration, stop_gpu_timeline()?);
        }
        let mut evals = Vec::new();
        if eval_due(trainer.iteration, total, config.num_evals as u64) {
            for options in trainer.scheduled_evals(trainer.evals_done) {
                evals.push(trainer.evaluate(&options)?);
            }
            trainer.evals_done += 1;
            last_evals.clone_from(&evals);
        }
        let evaluated = !evals.is_empty();
        let wall = wall_before + start.elapsed().as_secs_f64();
        let row = metrics_row(&trainer, &stats, wall, sps, &evals);
        writeln!(metrics, "{}", layout.to_csv(&row))
            .map_err(|e| RlError::file(&metrics_path, format!("cannot write: {e}")))?;
        bar.update(&row, trainer.env_steps);
        since_ckpt += 1;
        requested = options.stop.is_requested();
        let last =
            trainer.iteration >= total || requested || options.stop_after.is_some_and(|s| trainer.iteration >= s);
        if evaluated || last || (config.checkpoint_every > 0 && since_ckpt >= config.checkpoint_every as u64) {
            trainer.checkpoint(wall, &last_evals)?.save(&ckpt_path)?;
            since_ckpt = 0;
        }
        if evaluated {
            crate::app::curve::write_run_curve(run)?;
        }
    }
    bar.finish();
    if requested && trainer.iteration < total {
        // The caller asked; the metrics and the checkpoint are complete up to this iteration.
        return Err(RlError::Interrupted { run: run.root().to_path_buf(), iteration: Some(trainer.iteration) });
    }
    let summary = RunSummary {
        iterations: trainer.iteration,
        env_steps: trainer.env_steps,
        wall_s: wall_before + start.elapsed().as_secs_f64(),
        final_eval: last_evals.first().cloned(),
        final_eval_rotated: last_evals.iter().skip(1).cloned().collect(),
    };
    if trainer.iteration >= total {
        let text = serde_json::to_string_pretty(&summary).unwrap_or_default();
        nn::write_atomic(&run.done(), text.as_bytes())?;
    }
    Ok(summary)
}

/// Whether `MEBEN_TIMINGS` asks for each iteration's stage timings on standard error
/// ([`crate::mappo::trainer::Timings`]; docs/PERFORMANCE.md), and the uploads, downloads
/// (with their bytes) and launches of each iteration ([`tensor::transfers`]).
fn timings_wanted() -> bool {
    std::env::var_os("MEBEN_TIMINGS").is_some_and(|v| !v.is_empty() && v != "0")
}

/// Whether `MEBEN_TIMINGS=gpu` also asks for each iteration's kernels on the GPU's own clock
/// (`tensor::gpu::timing`: busy time against the span of the update's kernels, by kernel and
/// op), for a run whose updates are on the GPU.
fn gpu_timeline_wanted(device: tensor::Device) -> bool {
    device == tensor::Device::Gpu && std::env::var("MEBEN_TIMINGS").is_ok_and(|v| v == "gpu")
}

#[cfg(feature = "gpu")]
fn start_gpu_timeline() -> Result<()> {
    Ok(tensor::gpu::gpu()?.start_timing()?)
}

#[cfg(feature = "gpu")]
fn stop_gpu_timeline() -> Result<tensor::gpu::KernelTimeline> {
    Ok(tensor::gpu::gpu()?.stop_timing()?)
}

// Without the feature no run's updates are on the GPU, so these are never called.
#[cfg(not(feature = "gpu"))]
fn start_gpu_timeline() -> Result<()> {
    Ok(())
}

#[cfg(not(feature = "gpu"))]
fn stop_gpu_timeline() -> Result<&'static str> {
    Ok("")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 44 item 10: `--threads 512` on 2 cores was taken, and the run took 20 times as
    /// long. Above 4 per core (and above 64) it is refused, naming the cores.
    #[test]
    fn threads_are_bounded_by_the_cores() {
        assert_eq!(max_threads(2), 64);
        assert_eq!(max_threads(32), 128);
        check_threads(0, 2).unwrap();
        check_threads(64, 2).unwrap();
        check_threads(128, 32).unwrap();
        let e = check_threads(512, 2).unwrap_err().to_string();
        assert!(e.contains("`threads` = \"512\"") && e.contains("at most 64") && e.contains("2 cores"), "{e}");
        assert!(check_threads(usize::MAX, usize::MAX).is_ok());
        assert!(check_threads(129, 32).is_err());
    }

    #[test]
    fn evaluations_are_evenly_spaced_and_end_at_the_end() {
        let due: Vec<u64> = (1..=10).filter(|&i| eval_due(i, 10, 4)).collect();
        assert_eq!(due, vec![3, 5, 8, 10]);
        assert_eq!((1..=7).filter(|&i| eval_due(i, 7, 50)).count(), 7);
        assert!(!(1..=7).any(|i| eval_due(i, 7, 0)));
    }

    /// A metrics row holding only its iteration number.
    fn iteration_row(layout: &MetricsLayout, i: u64) -> String {
        let mut r = MetricsRow::default();
        r.set("iteration", i as f64);
        layout.to_csv(&r)
    }

    #[test]
    fn resumed_metrics_keep_each_iteration_once_in_order() {
        let layout = MetricsLayout::new(&[0.0]);
        let row = |i: u64| iteration_row(&layout, i);
        let path = std::env::temp_dir().join(format!("meben-metrics-{}.csv", std::process::id()));
        let rows = [1, 2, 2, 3, 1, 4, 5].map(row).join("\n");
        std::fs::write(&path, format!("{}\n{rows}\n", layout.header())).unwrap();
        let text = metrics_upto(&path, 4, &layout).unwrap();
        let _ = std::fs::remove_file(&path);
        let kept: Vec<&str> = text.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
        assert_eq!(kept, ["1", "2", "3", "4"]);
    }

    /// Bytes that are not UTF-8 cost only the rows that hold them (before, the whole file
    /// was unreadable and every row was dropped on resume).
    #[test]
    fn a_damaged_metrics_row_costs_only_itself() {
        let layout = MetricsLayout::new(&[0.0]);
        let row = |i: u64| iteration_row(&layout, i);
        let path = std::env::temp_dir().join(format!("meben-metrics-damaged-{}.csv", std::process::id()));
        let mut bytes = format!("{}\n{}\n", layout.header(), row(1)).into_bytes();
        let mut damaged = row(2).into_bytes();
        damaged[3] = 0xff;
        bytes.extend_from_slice(&damaged);
        bytes.extend_from_slice(format!("\n{}\n", row(2)).as_bytes());
        bytes.extend_from_slice(b"\xfe garbage\n");
        bytes.extend_from_slice(format!("{}\n", row(3)).as_bytes());
        std::fs::write(&path, &bytes).unwrap();
        let text = metrics_upto(&path, 3, &layout).unwrap();
        let _ = std::fs::remove_file(&path);
        let kept: Vec<&str> = text.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
        assert_eq!(kept, ["1", "2", "3"]);
        assert!(!text.contains(char::REPLACEMENT_CHARACTER));
    }

    /// Issue 77 item 3: a `metrics.csv` that could not be read (permissions) was taken as
    /// empty, and the resume rewrote it without the rows before the checkpoint. Any error
    /// but a missing file is refused, naming the file; a missing file has no rows.
    #[test]
    fn an_unreadable_metrics_file_is_an_error_naming_it_and_a_missing_one_is_empty() {
        let layout = MetricsLayout::new(&[0.0]);
        let path = std::path::Path::new("/runs/r/metrics.csv");
        let denied = std::io::Error::from(std::io::ErrorKind::PermissionDenied);
        let e = kept_metrics(path, Err(denied), 3, &layout).unwrap_err().to_string();
        assert!(e.starts_with("/runs/r/metrics.csv") && e.contains("cannot read"), "{e}");
        let missing = std::io::Error::from(std::io::ErrorKind::NotFound);
        assert_eq!(kept_metrics(path, Err(missing), 3, &layout).unwrap(), format!("{}\n", layout.header()));
        // A directory in its place (as root, permissions do not stop reads).
        let dir = crate::app::test_util::TempDir::new("metrics-dir");
        let e = metrics_upto(&dir.0, 3, &layout).unwrap_err().to_string();
        assert!(e.starts_with(&dir.0.display().to_string()) && e.contains("cannot read"), "{e}");
    }
}
