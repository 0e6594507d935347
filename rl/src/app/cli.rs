//! The `meben` program's command line: train, evaluate, sweep, report and render MeBen
//! agents, and drive the simulator.
//! `meben <command> --help` explains each command; with no command, `meben` trains `shnn` on
//! `team_reach/1_ant` with the built-in `quick` budget (as `meben train`).

// The doc comments of the argument structs are the `--help` text, written for a terminal
// (`runs/<env>-<model>-seed<seed>`), not HTML.
#![allow(rustdoc::invalid_html_tags)]

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::OnceLock;

use crate::app::eval_assignment::{AssignmentOverride, check_rule};
use crate::app::outputs;
use crate::app::presets::Preset;
use crate::app::run::TrainOptions;
use crate::app::run_dir::RunDir;
use crate::app::signals::{INTERRUPTED_EXIT_CODE, install_signal_handler};
use crate::error::RlError;
use crate::mappo::config::TrainConfig;
use crate::mappo::evaluate::{EvalOptions, EvalRequest};
use crate::stop::StopFlag;
use clap::{ArgGroup, Args, Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "meben",
    version = crate::app::build_info::LONG_VERSION,
    about = "Subequivariant multi-entity RL on MeBen: train, eval, ablate, report, status, export, export-policy, render, \
             sim, info"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Train a model (MAPPO). With no options: shnn on team_reach/1_ant, about ten minutes.
    ///
    /// Ctrl-C or SIGTERM stops after the current iteration with a checkpoint (exit status
    /// 130); the same command resumes the run. A second Ctrl-C quits at once.
    Train(Box<TrainArgs>),
    /// Evaluate a trained run, or a policy file, on N episodes.
    Eval(EvalArgs),
    /// Run a sweep of models x envs x seeds x variants (skips finished runs, resumes others).
    ///
    /// Ctrl-C or SIGTERM stops the running run after its current iteration with a checkpoint
    /// and ends the sweep (exit status 130); the same command goes on from there.
    Ablate(AblateArgs),
    /// Tables (Markdown, CSV) and learning curves of a sweep or of runs under a directory
    /// (also redraws each run's curve.svg).
    Report(ReportArgs),
    /// How far every run under a directory got: state (training now, stopped, finished),
    /// env steps of the budget, last evaluation, training speed and hours left.
    Status(StatusArgs),
    /// Copy the evidence of the runs under a directory (config.toml, metrics.csv, done.json,
    /// curve.svg, builds.csv, the sweep file) to another, without checkpoints: for
    /// committing results.
    Export(ExportArgs),
    /// Record an episode of a trained run or policy file: .html (animation), .gif, or .csv
    /// (body poses).
    Render(RenderArgs),
    /// Write what acting needs (the policy weights, model, observation normaliser,
    /// environment, configuration and last evaluation) to one safetensors file, for
    /// eval/render --policy, Python's meben.Policy.load and any safetensors reader.
    ExportPolicy(ExportPolicyArgs),
    /// The simulator's rollout tool (random actions, timing, trajectories).
    Sim(envs::rollout_tool::RolloutArgs),
    /// Parameter counts by part, one line per model and team:
    /// `<model> policy_params=N critic_params=M`.
    Info(InfoArgs),
}

#[derive(Args)]
struct InfoArgs {
    /// Environment (e.g. team_reach/3_ant_claw_centipede, or a composition whose
    /// morphologies may be Brax-config .txt or MJCF .xml files, as for train).
    #[arg(long, default_value = "team_reach/1_ant")]
    env: String,
    /// Model specification, with options ("shnn:critic=shared"); repeatable.
    #[arg(long, required = true)]
    model: Vec<String>,
    /// Team Sumo: model of team 1 (default: the same as --model).
    #[arg(long)]
    opponent: Option<String>,
}

#[derive(Args, Default)]
struct TrainArgs {
    /// Environment: a built-in name (e.g. team_reach/1_ant, team_sumo/2_ants) or a custom
    /// composition ("team_reach:agents=ant+claw;R=5;balls=2",
    /// "team_sumo:team1=ant;team2=claw;R=3"); a morphology is a built-in name (ant, claw,
    /// centipede, unimal_1, ...), a Brax-config file (.txt) or an MJCF file (.xml: bodies with
    /// sphere/capsule geoms, ranged hinges, motors, a free root; see envs::mjcf_agent).
    #[arg(long)]
    env: Option<String>,
    /// Model of team 0 (shnn, shnn_og3, shnn_so3, mlp, mlp_hn, transformer_hn, shtransformer,
    /// shgnn, hnn, hnn_hn, hnn_dn), optionally with options: "shnn:assignment=hungarian".
    #[arg(long)]
    model: Option<String>,
    /// Team Sumo: model of team 1 (default: the same as --model).
    #[arg(long)]
    opponent: Option<String>,
    /// Task assignment (ablation): greedy, hungarian, stochastic, none or learned (the SHNN family; appended to the
    /// model options).
    #[arg(long)]
    assignment: Option<String>,
    /// Translation of positions (ablation; see models::Translation).
    #[arg(long)]
    translation: Option<String>,
    /// Entity abstraction (ablation; see models::EntityAbstraction).
    #[arg(long)]
    abstraction: Option<String>,
    /// Seed of everything random.
    #[arg(long)]
    seed: Option<u64>,
    /// Environment steps to train for.
    #[arg(long)]
    steps: Option<u64>,
    /// Environments stepped together.
    #[arg(long)]
    num_envs: Option<usize>,
    /// Worker threads (0: all cores; results do not depend on it). At most 4 per core, or
    /// 64 if that is more.
    #[arg(long)]
    threads: Option<usize>,
    /// Where the updates run: cpu (default) or gpu (a build with --features gpu). Not part
    /// of the run's identity: a run resumes on either device.
    #[arg(long)]
    device: Option<String>,
    /// Starting point: quick (default, ~10 minutes on 2 cores) or paper (the reference schedule).
    #[arg(long)]
    preset: Option<String>,
    /// A TOML file of TrainConfig fields (see rl/configs/).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Any other field: --set entropy_coef=0.005 (repeatable).
    #[arg(long = "set", value_name = "FIELD=VALUE")]
    set: Vec<String>,
    /// Run directory (default runs/<env>-<model>-seed<seed>). An existing run resumes.
    #[arg(long)]
    out: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Stop after this many iterations in total (with a checkpoint), as if interrupted.
    #[arg(long, hide = true)]
    stop_after: Option<u64>,
}

#[derive(Args)]
#[command(group(ArgGroup::new("source").required(true).args(["run", "policy"])))]
struct EvalArgs {
    /// Run directory (with config.toml and checkpoint.json).
    #[arg(long)]
    run: Option<PathBuf>,
    /// A policy file (meben export-policy), or pretrained:<env>/<model> for a shipped one
    /// (e.g. pretrained:team_reach/2_ants/shnn), instead of --run.
    #[arg(long)]
    policy: Option<String>,
    /// Also write the summary (JSON) to this file. With --run it goes to the run directory
    /// anyway (eval.json, eval_rotate<deg>.json, ...). A run directory's other files
    /// (checkpoint.json, metrics.csv, ...) and the --policy file are refused.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Episodes.
    #[arg(long, default_value_t = 1024)]
    episodes: usize,
    /// Sample actions (default: as the run's eval_deterministic says; the paper preset
    /// samples, the quick preset takes the mean action).
    #[arg(long, conflicts_with = "mean")]
    stochastic: bool,
    /// Take the mean action tanh(loc) instead of sampling.
    #[arg(long)]
    mean: bool,
    /// Start every episode from the fixed start of the run's seed.
    #[arg(long)]
    fixed: bool,
    /// Start every episode from the fixed start rotated by this many degrees about the
    /// vertical through the origin (implies --fixed): the paper's equivariance test.
    #[arg(long, allow_negative_numbers = true)]
    rotate: Option<f64>,
    /// Translate the whole scene (agents, goal balls, Sumo's centre ball) horizontally by
    /// X,Y metres after the rotation (implies --fixed), e.g. --translate 2.5,-1.
    #[arg(long, value_name = "X,Y", value_parser = parse_translation, allow_hyphen_values = true)]
    translate: Option<[f64; 2]>,
    /// Seed of the evaluation's starts and noise.
    #[arg(long, default_value_t = crate::mappo::evaluate::DEFAULT_EVAL_SEED)]
    seed: u64,
    /// Where the policy's forward pass runs: cpu (default) or gpu (a build with --features
    /// gpu; the parameters are placed there, sampling stays on the host). The simulator runs
    /// on the CPU either way; GPU results differ from the CPU's by f32 rounding.
    #[arg(long, default_value = "cpu")]
    device: String,
    /// Also measure how much each team's actions depend on its task assignment: at every
    /// step, the KL divergence (nats) from its action distribution under the assignment it
    /// acted on to that under each other one-to-one assignment (the episodes play as
    /// without; the summary gains `assignment_sensitivity`). Models with an assignment only.
    #[arg(long)]
    assignment_sensitivity: bool,
    /// Also read, at every episode's first step, the value V(s0, σ) and probability π(σ|s0)
    /// of each assignment a learned scorer draws from, beside the episode's discounted
    /// return in the value's units (the episodes play as without; the summary gains
    /// `assignment_values`, per episode). Models with assignment=learned;assign_critic=held,
    /// with --run (a policy file holds no value network).
    #[arg(long)]
    assignment_values: bool,
    /// Evaluate with this task-assignment rule in place of the one the policy was trained
    /// with, on the same parameters: greedy (Algorithm 1), hungarian (least total distance)
    /// or stochastic (a random one-to-one assignment at every step). Models with a greedy,
    /// hungarian or stochastic assignment; a policy that learned its assignment takes greedy
    /// only (Algorithm 1 in place of its scorer's draws); with --run the summary goes to
    /// eval[...]_assignment-<rule>.json, beside the run's own.
    #[arg(long, value_name = "RULE")]
    assignment: Option<String>,
    /// Hold each random task assignment (stochastic, or learned) for K steps instead of the
    /// run's own hold: drawn at the evaluation's steps 0, K, 2K, ... (K = 1000, Team
    /// Reach's episode, draws one assignment an episode). With --run the summary goes to
    /// eval[...]_hold<K>.json.
    #[arg(long, value_name = "K")]
    assignment_hold: Option<usize>,
}

/// `X,Y` as two finite numbers.
fn parse_translation(s: &str) -> Result<[f64; 2], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let xy: Vec<f64> = match parts.as_slice() {
        [x, y] => [x, y]
            .iter()
            .map(|v| v.parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| format!("expected two numbers X,Y in metres, e.g. 2.5,-1 ({e})"))?,
        _ => return Err("expected two numbers X,Y in metres, e.g. 2.5,-1".into()),
    };
    if !xy.iter().all(|v| v.is_finite()) {
        return Err("the translation must be finite".into());
    }
    Ok([xy[0], xy[1]])
}

#[derive(Args)]
struct AblateArgs {
    /// The sweep file (see rl/sweeps/).
    #[arg(long)]
    sweep: PathBuf,
    /// Directory of the sweep's runs.
    #[arg(long)]
    out: PathBuf,
    /// Only this shard, k/n (1-based): runs with index % n == k - 1.
    #[arg(long)]
    shard: Option<String>,
    /// Only the runs whose name (`<env>/<model>/seed<N>`) contains this; repeatable.
    #[arg(long)]
    only: Vec<String>,
    /// Worker threads of every run (0: every core), whatever the sweep says; results do not
    /// depend on it. At most 4 per core, or 64 if that is more.
    #[arg(long)]
    threads: Option<usize>,
    /// Where every run's updates run (cpu or gpu, the latter in a build with --features
    /// gpu), whatever the sweep says; a run resumes on either device.
    #[arg(long)]
    device: Option<String>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

#[derive(Args)]
struct ExportArgs {
    /// Directory holding run directories (a sweep's --out).
    from: PathBuf,
    /// Where the evidence goes (e.g. results/<experiment>).
    to: PathBuf,
}

#[derive(Args)]
struct StatusArgs {
    /// Directory holding run directories (a sweep's --out), or one run directory.
    root: PathBuf,
}

#[derive(Args)]
struct ReportArgs {
    /// Directory holding run directories (a sweep's --out).
    root: PathBuf,
    /// The paper's figures (`results/paper.toml`): also write ROOT/paper.md, each group
    /// beside the paper's figure for the same env, model, start and rotation.
    #[arg(long)]
    paper: Option<PathBuf>,
    /// Compare at one budget: every run as it stood after this many env steps (its rows up
    /// to then), written under ROOT/at_<N>/ instead of ROOT.
    #[arg(long, value_name = "N")]
    at_steps: Option<u64>,
}

#[derive(Args)]
struct ExportPolicyArgs {
    /// Run directory (with config.toml and checkpoint.json).
    #[arg(long)]
    run: PathBuf,
    /// The policy file to write (.safetensors).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
#[command(group(ArgGroup::new("source").required(true).args(["run", "policy"])))]
struct RenderArgs {
    /// Run directory.
    #[arg(long)]
    run: Option<PathBuf>,
    /// A policy file (meben export-policy), or pretrained:<env>/<model> for a shipped one,
    /// instead of --run.
    #[arg(long)]
    policy: Option<String>,
    /// Output file: .html (interactive animation), .gif (animated image) or .csv (body poses per frame).
    /// A run directory's own files (metrics.csv, config.toml, ...) and the --policy file are
    /// refused.
    #[arg(long)]
    out: PathBuf,
    /// Seed of the episode's start.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Control steps at most (default: the episode length).
    #[arg(long)]
    steps: Option<usize>,
    /// Sample actions instead of the mean action.
    #[arg(long)]
    stochastic: bool,
}

/// A line of a command's report on standard output, as `println!` but never a panic: a reader
/// that stops reading (`meben status | head`) ends the report quietly while the command
/// finishes its work (files are written all the same), and another write error is said once
/// on standard error ([`out`]).
macro_rules! outln {
    ($($arg:tt)*) => {
        out(format_args!($($arg)*), true)
    };
}

/// Whether standard output has failed once: nothing more is written to it.
static STDOUT_GONE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Writes `text` (and a newline if `newline`) to standard output unless it has failed before
/// ([`outln!`]): a closed pipe silently, another error said once on standard error.
fn out(text: std::fmt::Arguments<'_>, newline: bool) {
    use std::io::Write;
    use std::sync::atomic::Ordering;
    if STDOUT_GONE.load(Ordering::Relaxed) {
        return;
    }
    let mut stdout = std::io::stdout().lock();
    let written = if newline { writeln!(stdout, "{text}") } else { write!(stdout, "{text}") };
    if let Err(e) = written.and_then(|()| stdout.flush()) {
        STDOUT_GONE.store(true, Ordering::Relaxed);
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            eprintln!("meben: standard output: {e}; the rest of this command's report is not written there");
        }
    }
}

/// Runs the `meben` program on the process's arguments (module docs); its exit code.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        None => cmd_train(TrainArgs::default()),
        Some(Command::Train(a)) => cmd_train(*a),
        Some(Command::Eval(a)) => cmd_eval(a),
        Some(Command::Ablate(a)) => cmd_ablate(a),
        Some(Command::Report(a)) => cmd_report(a),
        Some(Command::Export(a)) => cmd_export(a),
        Some(Command::Status(a)) => cmd_status(a),
        Some(Command::Render(a)) => cmd_render(a),
        Some(Command::ExportPolicy(a)) => cmd_export_policy(a),
        Some(Command::Sim(a)) => cmd_sim(a),
        Some(Command::Info(a)) => cmd_info(a),
    };
    let interrupted = STOP.get().is_some_and(StopFlag::is_requested);
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if interrupted => {
            eprintln!("meben: {e}");
            ExitCode::from(INTERRUPTED_EXIT_CODE)
        }
        Err(e) => {
            eprintln!("meben: error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The training commands' stop flag, set by Ctrl-C or SIGTERM once [`stop_on_signals`] has
/// installed the handler.
static STOP: OnceLock<StopFlag> = OnceLock::new();

/// The stop flag of `meben train` and `meben ablate`: the first Ctrl-C or SIGTERM stops the
/// training after its current iteration with a checkpoint, the second ends the program
/// ([`crate::app::signals`]). Other commands keep the default: a signal ends them at once.
fn stop_on_signals() -> Result<StopFlag, String> {
    if let Some(flag) = STOP.get() {
        return Ok(flag.clone());
    }
    let flag = StopFlag::new();
    install_signal_handler(&flag).map_err(|e| e.to_string())?;
    Ok(STOP.get_or_init(|| flag).clone())
}

fn resolve_train_config(a: &TrainArgs) -> Result<TrainConfig, RlError> {
    let preset = a.preset.as_deref().map(|p| Preset::parse(p, "command line")).transpose()?;
    let mut ov: Vec<(String, String)> = Vec::new();
    let quote = |s: &str| format!("{s:?}");
    if let Some(v) = &a.env {
        ov.push(("env".into(), quote(v)));
    }
    let mut model = a.model.clone();
    let extra: Vec<String> =
        [("assignment", &a.assignment), ("translation", &a.translation), ("abstraction", &a.abstraction)]
            .iter()
            .filter_map(|(k, v)| v.as_ref().map(|v| format!("{k}={v}")))
            .collect();
    if !extra.is_empty() {
        let base = model.clone().unwrap_or_else(|| "shnn".into());
        let sep = if base.contains(':') { ";" } else { ":" };
        model = Some(format!("{base}{sep}{}", extra.join(";")));
    }
    if let Some(v) = &model {
        ov.push(("model".into(), quote(v)));
    }
    if let Some(v) = &a.opponent {
        ov.push(("opponent".into(), quote(v)));
    }
    for (k, v) in [("seed", a.seed), ("steps", a.steps)] {
        if let Some(v) = v {
            ov.push((k.into(), v.to_string()));
        }
    }
    for (k, v) in [("num_envs", a.num_envs), ("threads", a.threads)] {
        if let Some(v) = v {
            ov.push((k.into(), v.to_string()));
        }
    }
    if let Some(v) = &a.device {
        ov.push(("device".into(), quote(v)));
    }
    for s in &a.set {
        let (k, v) = s.split_once('=').ok_or_else(|| {
            RlError::config("command line", "--set", s, "expected FIELD=VALUE, e.g. --set entropy_coef=0.005")
        })?;
        ov.push((k.trim().into(), v.trim().into()));
    }
    TrainConfig::resolve(preset, a.config.as_deref(), &ov)
}

fn cmd_train(a: TrainArgs) -> Result<(), String> {
    let config = resolve_train_config(&a).map_err(|e| e.to_string())?;
    let out = a.out.clone().unwrap_or_else(|| {
        PathBuf::from("runs").join(format!(
            "{}-{}-seed{}",
            crate::app::names::sanitize_component(&config.env),
            crate::app::names::sanitize_component(&config.model),
            config.seed
        ))
    });
    let run = RunDir::new(&out);
    eprintln!(
        "meben: training {} on {} for {} env steps ({} iterations of {}), seed {} -> {}",
        config.model,
        config.env,
        config.steps,
        config.iterations(),
        config.steps_per_iteration(),
        config.seed,
        out.display()
    );
    announce_device(config.device)?;
    let options = TrainOptions { progress: !a.quiet, stop_after: a.stop_after, stop: stop_on_signals()? };
    let s = crate::app::run::train(&config, &run, &options).map_err(|e| e.to_string())?;
    print_summary(&config, &s);
    eprintln!("meben: metrics in {}, learning curve in {}", run.metrics().display(), run.curve().display());
    Ok(())
}

/// Checks that training can run on `device` ([`crate::mappo::device::check_device`]) and,
/// for the GPU, says which adapter it runs on.
fn announce_device(device: tensor::Device) -> Result<(), String> {
    if let Some(adapter) = crate::mappo::device::check_device(device).map_err(|e| e.to_string())? {
        eprintln!("meben: training on GPU: {adapter}");
    }
    Ok(())
}

fn print_summary(config: &TrainConfig, s: &crate::app::record::RunSummary) {
    outln!("iterations {} env_steps {} wall_s {:.1}", s.iterations, s.env_steps, s.wall_s);
    if let Some(e) = &s.final_eval {
        print_eval(config.is_sumo(), e);
    }
    for e in &s.final_eval_rotated {
        out(format_args!("rotated {} degrees: ", e.rotation_deg), false);
        print_eval(config.is_sumo(), e);
    }
}

fn print_eval(sumo: bool, e: &crate::mappo::evaluate::EvalSummary) {
    if sumo {
        outln!(
            "episodes {} win_rate_t0 {:.4} win_rate_t1 {:.4} draw_rate {:.4} mean_length {:.1} actions {}",
            e.episodes,
            e.win_rate[0],
            e.win_rate[1],
            e.draw_rate,
            e.mean_length,
            if e.sampled { "sampled" } else { "mean" }
        );
    } else {
        outln!(
            "episodes {} success_rate {:.4} mean_return {:.1} mean_length {:.1} actions {}",
            e.episodes,
            e.success_rate,
            e.mean_return[0],
            e.mean_length,
            if e.sampled { "sampled" } else { "mean" }
        );
    }
}

/// The teams to act: those of `--run` or of `--policy` (a file or `pretrained:...`).
fn load_teams(run: Option<&PathBuf>, policy: Option<&str>) -> Result<(TrainConfig, Vec<crate::Team>), String> {
    match (run, policy) {
        (_, Some(p)) => {
            let path = crate::app::policy_file::resolve_policy(p).map_err(|e| e.to_string())?;
            let f = crate::app::policy_file::load_policy(&path).map_err(|e| e.to_string())?;
            Ok((f.config, f.teams))
        }
        (Some(r), None) => crate::app::run_dir::load_policies(&RunDir::new(r)).map_err(|e| e.to_string()),
        (None, None) => Err("give --run DIR or --policy FILE".into()),
    }
}

fn cmd_eval(a: EvalArgs) -> Result<(), String> {
    let device = a
        .device
        .parse::<tensor::Device>()
        .map_err(|e| RlError::config("command line", "--device", &a.device, e).to_string())?;
    if let Some(adapter) = crate::mappo::device::check_device(device).map_err(|e| e.to_string())? {
        eprintln!("meben: evaluating on GPU: {adapter}");
    }
    if let Some(rule) = &a.assignment {
        check_rule(rule)?;
    }
    if a.assignment_values && a.policy.is_some() {
        return Err("--assignment-values reads the value network, which a policy file does not hold \
                    (export-policy keeps what acting needs): evaluate the run with --run"
            .into());
    }
    let in_run = a
        .run
        .as_ref()
        .map(|r| r.join(eval_file_name(a.rotate, a.translate, a.fixed, a.assignment.as_deref(), a.assignment_hold)));
    // `--out` is checked before anything is computed: never a run directory's own file
    // (but the run's own evaluation file, written anyway) nor the policy evaluated.
    let out = match (&a.out, &in_run) {
        (Some(out), Some(own)) if outputs::resolved(out) == outputs::resolved(own) => None,
        (out, _) => out.clone(),
    };
    if let Some(out) = &out {
        let policy = a.policy.as_deref().map(crate::app::policy_file::resolve_policy).transpose();
        let policy = policy.map_err(|e| e.to_string())?;
        let inputs: Vec<(&str, &std::path::Path)> = policy.iter().map(|p| ("--policy", p.as_path())).collect();
        outputs::check_output("--out", out, &inputs).map_err(|e| e.to_string())?;
    }
    let (config, mut teams) = load_teams(a.run.as_ref(), a.policy.as_deref())?;
    let assignment = AssignmentOverride { rule: a.assignment.clone(), hold: a.assignment_hold };
    assignment.apply(&config, &mut teams)?;
    if a.episodes == 0 {
        return Err("--episodes must be at least 1".into());
    }
    if let Some(deg) = a.rotate
        && !deg.is_finite()
    {
        return Err(format!("--rotate {deg}: the angle must be finite"));
    }
    let deterministic = if a.stochastic {
        Some(false)
    } else if a.mean {
        Some(true)
    } else {
        None
    };
    let options = EvalRequest {
        episodes: a.episodes,
        seed: a.seed,
        deterministic,
        fixed: a.fixed,
        rotation_deg: a.rotate,
        translation: a.translate,
    }
    .options(&config);
    let options = EvalOptions {
        assignment_sensitivity: a.assignment_sensitivity,
        assignment_values: a.assignment_values.then(|| crate::mappo::assignment_values::ReturnUnits::of(&config)),
        ..options
    };
    let mut e = evaluate_on_device(&config.env, &mut teams, &options, device)?;
    assignment.record(&mut e);
    if let Some(rule) = &e.assignment {
        outln!("assignment: {rule}, in place of the policy's own");
    }
    if let Some(every) = e.assignment_hold {
        outln!("assignment held for {every} steps at a time");
    }
    print_eval(config.is_sumo(), &e);
    for s in &e.assignment_sensitivity {
        if s.steps == 0 {
            outln!("team {} assignment sensitivity: no other one-to-one assignment to compare with", s.team);
            continue;
        }
        outln!(
            "team {} assignment sensitivity: KL(π(·|s,σ) ‖ π(·|s,σ')) mean {:.4}, median {:.4}, 90th percentile {:.4} nats over {} scene-steps, {} other assignment(s) a step; mean over each episode's first {} steps {:.4}",
            s.team,
            s.mean_kl,
            s.median_kl,
            s.p90_kl,
            s.steps,
            s.alternatives,
            crate::mappo::assignment_sensitivity::EARLY_STEPS,
            s.early_mean_kl
        );
    }
    for v in &e.assignment_values {
        let (value, g, r) = v.acted_value_and_return();
        outln!(
            "team {} assignment values at the episodes' first step: V(s0, σ acted) mean {value:.4}, the discounted return's mean {g:.4}, their correlation {r:.3}; the value ranks the acted σ first in {:.1}% of {} episodes",
            v.team,
            100.0 * v.acted_ranked_first(),
            v.episodes.len()
        );
    }
    let text = serde_json::to_string_pretty(&e).map_err(|e| e.to_string())?;
    for path in in_run.iter().chain(&out) {
        nn::write_atomic(path, text.as_bytes()).map_err(|e| e.to_string())?;
        eprintln!("meben: wrote {}", path.display());
    }
    Ok(())
}

/// `teams`' evaluation with the policies' forward passes on `device` (checked already): each
/// team's parameters are placed there first.
fn evaluate_on_device(
    env: &str,
    teams: &mut [crate::Team],
    options: &crate::mappo::evaluate::EvalOptions,
    device: tensor::Device,
) -> Result<crate::mappo::evaluate::EvalSummary, String> {
    for t in teams.iter_mut() {
        t.store.to_device(device).map_err(|e| e.to_string())?;
    }
    crate::mappo::evaluate::evaluate(env, teams, options).map_err(|e| e.to_string())
}

/// The file an evaluation is written to: `eval.json`, `eval_fixed.json`,
/// `eval_rotate<deg>.json`, `eval[_rotate<deg>]_translate<x>_<y>.json` (each with
/// `_assignment-<rule>` under `--assignment`, then `_hold<K>` under `--assignment-hold`,
/// before `.json`), every number in at
/// most 24 characters (`1e308`, not 309 digits: a file name has a length limit).
fn eval_file_name(
    rotate: Option<f64>,
    translate: Option<[f64; 2]>,
    fixed: bool,
    assignment: Option<&str>,
    hold: Option<usize>,
) -> String {
    let num = |x: f64| {
        let plain = x.to_string();
        if plain.len() <= 24 { plain } else { format!("{x:e}") }
    };
    let mut name = match rotate {
        Some(d) => format!("eval_rotate{}", num(d)),
        None if fixed || translate.is_some() => "eval_fixed".into(),
        None => "eval".into(),
    };
    if let Some([x, y]) = translate {
        let base = if rotate.is_some() { name.as_str() } else { "eval" };
        name = format!("{base}_translate{}_{}", num(x), num(y));
    }
    if let Some(rule) = assignment {
        name = format!("{name}_assignment-{rule}");
    }
    if let Some(every) = hold {
        name = format!("{name}_hold{every}");
    }
    format!("{name}.json")
}

fn cmd_ablate(a: AblateArgs) -> Result<(), String> {
    let sweep = crate::app::sweep::Sweep::load(&a.sweep).map_err(|e| e.to_string())?;
    let shard = a.shard.as_deref().map(crate::app::sweep::Shard::parse).transpose().map_err(|e| e.to_string())?;
    let selection = crate::app::sweep::RunSelection { shard, only: a.only.clone() };
    let device = a
        .device
        .as_deref()
        .map(|d| d.parse::<tensor::Device>().map_err(|e| RlError::config("command line", "--device", d, e).to_string()))
        .transpose()?;
    check_sweep_devices(&sweep, device).map_err(|e| e.to_string())?;
    let options = TrainOptions { progress: !a.quiet, stop_after: None, stop: stop_on_signals()? };
    let outcome = crate::app::sweep::run_sweep(&sweep, &a.out, &selection, |c, r| {
        eprintln!("meben: run {} ({} on {}, seed {})", r.root().display(), c.model, c.env, c.seed);
        let c =
            TrainConfig { threads: a.threads.unwrap_or(c.threads), device: device.unwrap_or(c.device), ..c.clone() };
        if let Some(adapter) = crate::mappo::device::check_device(c.device)? {
            eprintln!("meben: training on GPU: {adapter}");
        }
        crate::app::run::train(&c, r, &options)
    })
    .map_err(|e| e.to_string())?;
    outln!("meben: sweep {}: {outcome}", a.out.display());
    Ok(())
}

/// Refuses, once and before any run, a sweep whose runs would train on a device this build
/// lacks (`--device gpu`, or `device = "gpu"` in the sweep file, without the feature `gpu`):
/// before, every run failed in turn with the same error.
fn check_sweep_devices(sweep: &crate::app::sweep::Sweep, device: Option<tensor::Device>) -> Result<(), RlError> {
    let devices: Vec<(String, &str, tensor::Device)> = match device {
        Some(d) => vec![("command line".into(), "--device", d)],
        None => sweep.runs()?.into_iter().map(|r| (sweep.source.clone(), "device", r.config.device)).collect(),
    };
    match devices.into_iter().find(|(_, _, d)| !d.is_built()) {
        Some((source, field, d)) => Err(RlError::config(
            source,
            field,
            d.name(),
            "this build has no GPU device, so no run of the sweep could train: rebuild with --features gpu \
             (cargo build --release -p rl --features gpu)",
        )),
        None => Ok(()),
    }
}

fn cmd_report(a: ReportArgs) -> Result<(), String> {
    // The paper's figures are read and checked before the report writes anything.
    let paper = a.paper.as_deref().map(crate::app::paper::PaperFigures::load).transpose().map_err(|e| e.to_string())?;
    let r = crate::app::report::report_at(&a.root, a.at_steps).map_err(|e| e.to_string())?;
    // Every run's own learning curve is redrawn too (runs written by older versions).
    for dir in crate::app::record::find_run_dirs(&a.root).map_err(|e| e.to_string())? {
        crate::app::curve::write_run_curve(&RunDir::new(dir)).map_err(|e| e.to_string())?;
    }
    let text = std::fs::read_to_string(&r.markdown).map_err(|e| format!("{}: {e}", r.markdown.display()))?;
    outln!("{text}");
    eprintln!("meben: wrote {}", r.markdown.display());
    if let Some(paper) = &paper {
        let path = crate::app::paper::write_paper_table(&r.dir, &r.groups, paper).map_err(|e| e.to_string())?;
        eprintln!("meben: wrote {}", path.display());
    }
    Ok(())
}

fn cmd_export(a: ExportArgs) -> Result<(), String> {
    let s = crate::app::export::export(&a.from, &a.to).map_err(|e| e.to_string())?;
    outln!(
        "meben: exported {} ({} unfinished, {} bytes) from {} to {}",
        crate::app::report::count(s.runs.len(), "run"),
        s.unfinished.len(),
        s.bytes,
        a.from.display(),
        a.to.display()
    );
    for u in &s.unfinished {
        outln!("  unfinished: {}", u.display());
    }
    for k in &s.kept {
        outln!(
            "  kept: {} (the exported metrics.csv has {} rows; this run's {} are equal to its first ones)",
            k.run.display(),
            k.kept_rows,
            k.rows
        );
    }
    Ok(())
}

fn cmd_status(a: StatusArgs) -> Result<(), String> {
    let runs = crate::app::status::status(&a.root).map_err(|e| e.to_string())?;
    for line in crate::app::status::status_lines(&runs) {
        outln!("{line}");
    }
    Ok(())
}

fn cmd_info(a: InfoArgs) -> Result<(), String> {
    for line in crate::app::info::info_lines(&a.env, &a.model, a.opponent.as_deref()).map_err(|e| e.to_string())? {
        outln!("{line}");
    }
    Ok(())
}

fn cmd_export_policy(a: ExportPolicyArgs) -> Result<(), String> {
    let run = RunDir::new(&a.run);
    let s = crate::app::policy_file::export_policy(&run, &a.out).map_err(|e| e.to_string())?;
    let eval = match &s.eval {
        Some(e) if s.sumo => format!("team 0 win rate {:.4} on {} episodes", e.win_rate[0], e.episodes),
        Some(e) => format!("success rate {:.4} on {} episodes", e.success_rate, e.episodes),
        None => "not evaluated yet".into(),
    };
    outln!(
        "meben: wrote {} ({} bytes): the policy after {} env steps; last evaluation: {eval}",
        a.out.display(),
        s.bytes,
        s.env_steps
    );
    Ok(())
}

fn cmd_render(a: RenderArgs) -> Result<(), String> {
    let policy = a.policy.as_deref().map(crate::app::policy_file::resolve_policy).transpose();
    let policy = policy.map_err(|e| e.to_string())?;
    let inputs: Vec<(&str, &std::path::Path)> = policy.iter().map(|p| ("--policy", p.as_path())).collect();
    outputs::check_output("--out", &a.out, &inputs).map_err(|e| e.to_string())?;
    let (config, mut teams) = load_teams(a.run.as_ref(), a.policy.as_deref())?;
    let ext = a.out.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if !["html", "gif", "csv"].contains(&ext.as_str()) {
        return Err(format!("{}: unsupported output format {ext:?}; use .html, .gif or .csv", a.out.display()));
    }
    let spec = envs::tasks::TaskSpec::from_name(&config.env).map_err(|e| e.to_string())?;
    let steps = a.steps.unwrap_or(spec.episode_steps);
    let mut failure = None;
    let traj = crate::app::render::record_episode(&config.env, &mut teams, a.seed, steps, !a.stochastic, &mut failure)
        .map_err(|e| e.to_string())?;
    if let Some(e) = failure {
        return Err(e.to_string());
    }
    let bytes = match ext.as_str() {
        "html" => traj.to_html().into_bytes(),
        "gif" => traj.to_gif(&envs::tasks::render::GifOptions::default()).map_err(|e| e.to_string())?,
        _ => traj.to_csv().into_bytes(),
    };
    nn::write_atomic(&a.out, &bytes).map_err(|e| e.to_string())?;
    eprintln!("meben: wrote {} ({} frames)", a.out.display(), traj.len());
    Ok(())
}

/// `meben sim`: the simulator's rollout tool, which refuses its own inputs as `--out`;
/// a run directory's own files are refused here too.
fn cmd_sim(a: envs::rollout_tool::RolloutArgs) -> Result<(), String> {
    outputs::check_output("--out", &a.out, &[]).map_err(|e| e.to_string())?;
    envs::rollout_tool::run(&a).map_err(|e| e.to_string())
}
