//! Open-loop rollout of an MJCF model, to hold the simulator against another engine: the
//! program behind `cargo run -p envs --example rollout` and `meben sim` (both parse
//! [`RolloutArgs`] and call [`run`]).
//!
//! ```text
//! cargo run --release -p envs --example rollout -- --mjcf FILE --controls CTRL.csv \
//!     --out OUT.csv --frames 5 [--qpos q0,q1,...]
//! ```
//!
//! Loads the model, sets the initial qpos (MuJoCo layout: free joint `x y z qw qx qy qz`, then
//! hinge angles in file order; default: the model's own initial pose) at rest, applies each
//! row of CTRL.csv (no header, one column per actuator in file order; blank lines skipped) for
//! `--frames` physics steps and writes OUT.csv: a header line `q0,q1,...`, then one row of
//! qpos per control step (`{:e}`, exact), the initial state first. It prints nothing on
//! success; every bad input is a [`RolloutError`] naming the flag or file, line and column
//! (the programs print it on stderr and exit with a non-zero code): `--qpos` and the controls
//! must lie within [`crate::limits`], `--frames` in `1..=`[`MAX_FRAMES`].

use crate::data::Data;
use crate::limits;
use crate::mjcf::{self, MjcfError};
use std::fmt;
use std::path::{Path, PathBuf};

/// Open-loop rollout of an MJCF model; writes qpos per control step.
#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct RolloutArgs {
    /// MJCF (MuJoCo XML) model file.
    #[arg(long)]
    pub mjcf: PathBuf,
    /// Controls: one row per control step, one column per actuator, no header.
    #[arg(long)]
    pub controls: PathBuf,
    /// Output CSV of qpos, one row per control step (initial state first).
    #[arg(long)]
    pub out: PathBuf,
    /// Physics steps per control step (1 to 10000).
    #[arg(long, default_value_t = 5)]
    pub frames: usize,
    /// Initial qpos, comma-separated (default: the model's initial pose): positions within
    /// +-1000 m, hinge angles within +-20 pi rad, quaternion components within +-1000, not all
    /// zero (envs/src/limits.rs).
    #[arg(long)]
    pub qpos: Option<String>,
}

/// Why a rollout failed.
#[derive(Debug)]
pub enum RolloutError {
    /// A command-line value that is malformed or out of range (`--frames`, `--qpos`).
    Argument {
        /// The flag.
        flag: String,
        /// What is wrong.
        message: String,
    },
    /// The model file could not be loaded (boxed: the error is large and rare).
    Model(Box<MjcfError>),
    /// A file could not be read or written, or a controls row is malformed.
    File {
        /// The file, with `:line` for a controls row.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// The state stopped being finite (the output file holds the whole rollout).
    NonFinite {
        /// The first control step (1-based) after which the state was not finite.
        control_step: usize,
    },
}

impl fmt::Display for RolloutError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RolloutError::Argument { flag, message } => write!(f, "{flag}: {message}"),
            RolloutError::Model(e) => write!(f, "{e}"),
            RolloutError::File { path, message } => write!(f, "{path}: {message}"),
            RolloutError::NonFinite { control_step } => {
                write!(f, "the state became non-finite (first after control step {control_step})")
            }
        }
    }
}

impl std::error::Error for RolloutError {}

impl From<MjcfError> for RolloutError {
    fn from(e: MjcfError) -> Self {
        RolloutError::Model(Box::new(e))
    }
}

/// Parses a comma-separated row of finite numbers; errors name the column (1-based).
fn parse_row(text: &str) -> Result<Vec<f64>, String> {
    text.split(',')
        .enumerate()
        .map(|(i, t)| {
            let t = t.trim();
            t.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("column {}: \"{t}\" is not a finite number", i + 1))
        })
        .collect()
}

/// Parses a controls file (`text`, named `source` in errors): one row per control step,
/// `actuators` comma-separated numbers each, blank lines skipped. Every value must be finite
/// and within [`limits::CONTROL`] (a motor without a control range multiplies it by its
/// gear); errors name `source:line` and the column.
pub fn parse_controls(text: &str, source: &str, actuators: usize) -> Result<Vec<Vec<f64>>, RolloutError> {
    let mut controls = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let at = || format!("{source}:{}", i + 1);
        let row = parse_row(line).map_err(|message| RolloutError::File { path: at(), message })?;
        if row.len() != actuators {
            let message = format!("{} columns, but the model has {actuators} actuators", row.len());
            return Err(RolloutError::File { path: at(), message });
        }
        for (k, x) in row.iter().enumerate() {
            limits::CONTROL
                .check(*x)
                .map_err(|m| RolloutError::File { path: at(), message: format!("column {}: {m}", k + 1) })?;
        }
        controls.push(row);
    }
    Ok(controls)
}

/// The most physics steps per control step (`--frames`): 100 s of simulated time at a
/// time step of 0.01 s, where MuJoCo's frame skips are 1 to 50. Beyond it a rollout could
/// run for days (`--frames 18446744073709551615` never ended).
pub const MAX_FRAMES: usize = 10_000;

/// Checks an initial `qpos` for `model` against [`limits`]: a free joint's position
/// ([`limits::LENGTH`]) and quaternion ([`limits::QUATERNION`], not all zero), a hinge's
/// angle ([`limits::HINGE_ANGLE`]). The message names the entry, the joint and the range.
pub fn check_qpos(model: &crate::model::Model, q: &[f64]) -> Result<(), String> {
    if q.len() != model.nq {
        return Err(format!("qpos has {} entries, the model has nq = {}", q.len(), model.nq));
    }
    for j in &model.joints {
        let a = j.qpos_adr;
        let name = if j.name.is_empty() { "(unnamed)" } else { j.name.as_str() };
        let at = |i: usize, m: String| format!("qpos[{i}] (joint {name}): {m}");
        match j.kind {
            crate::model::JointKind::Free => {
                for (i, x) in q.iter().enumerate().skip(a).take(7) {
                    let limit = if i < a + 3 { &limits::LENGTH } else { &limits::QUATERNION };
                    limit.check(*x).map_err(|m| at(i, m))?;
                }
                if q[a + 3..a + 7].iter().all(|x| *x == 0.0) {
                    return Err(format!(
                        "qpos[{}..{}] (joint {name}): a zero quaternion is no orientation (the identity is 1,0,0,0)",
                        a + 3,
                        a + 7
                    ));
                }
            }
            crate::model::JointKind::Hinge => {
                limits::HINGE_ANGLE.check(q[a]).map_err(|m| at(a, m))?;
            }
        }
    }
    Ok(())
}

/// Runs the rollout `args` describes (module docs), writing `args.out`.
pub fn run(args: &RolloutArgs) -> Result<(), RolloutError> {
    let arg = |flag: &str, message: String| RolloutError::Argument { flag: flag.into(), message };
    if !(1..=MAX_FRAMES).contains(&args.frames) {
        return Err(arg(
            "--frames",
            format!(
                "{} physics steps per control step: must be at least 1 and at most {MAX_FRAMES} (100 s at a time \
                 step of 0.01 s)",
                args.frames
            ),
        ));
    }
    check_not_an_input(&args.out, &[("--mjcf", &args.mjcf), ("--controls", &args.controls)])?;
    let model = mjcf::load_file(&args.mjcf)?;
    let mut data = Data::new(&model);
    if let Some(q) = &args.qpos {
        let q = parse_row(q).map_err(|e| arg("--qpos", e))?;
        check_qpos(&model, &q).map_err(|e| arg("--qpos", e))?;
        data.reset_to(&model, &q).map_err(|e| arg("--qpos", e))?;
    }
    let controls_path = args.controls.display().to_string();
    let text = std::fs::read_to_string(&args.controls)
        .map_err(|e| RolloutError::File { path: controls_path.clone(), message: format!("cannot read: {e}") })?;
    let controls = parse_controls(&text, &controls_path, model.nu())?;
    let out_path = args.out.display().to_string();
    let mut out = String::new();
    let header: Vec<String> = (0..model.nq).map(|i| format!("q{i}")).collect();
    out.push_str(&header.join(","));
    out.push('\n');
    let write_row = |out: &mut String, q: &[f64]| {
        let row: Vec<String> = q.iter().map(|x| format!("{x:e}")).collect();
        out.push_str(&row.join(","));
        out.push('\n');
    };
    write_row(&mut out, &data.qpos);
    let mut first_non_finite = None;
    for (k, row) in controls.iter().enumerate() {
        data.ctrl.copy_from_slice(row);
        for _ in 0..args.frames {
            crate::step(&model, &mut data);
        }
        write_row(&mut out, &data.qpos);
        if first_non_finite.is_none() && !data.is_finite() {
            first_non_finite = Some(k + 1);
        }
    }
    write_replacing(&args.out, out.as_bytes())
        .map_err(|e| RolloutError::File { path: out_path.clone(), message: format!("cannot write: {e}") })?;
    match first_non_finite {
        Some(control_step) => Err(RolloutError::NonFinite { control_step }),
        None => Ok(()),
    }
}

/// Writes `bytes` to `path` through a temporary sibling file, synced, then renamed over
/// `path`: a crash leaves the old file or the new one, never half of one (the scheme of
/// `nn::write_atomic`, written here so that the simulator depends on no other crate).
fn write_replacing(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.{}.tmp", std::process::id()));
    let written = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// Refuses an output path that names one of the inputs (compared canonicalised, so
/// `dir/./x.csv` and a symbolic link are found too): the rollout would overwrite its input.
fn check_not_an_input(out: &Path, inputs: &[(&str, &Path)]) -> Result<(), RolloutError> {
    let canonical = |p: &Path| -> Option<PathBuf> {
        p.canonicalize().ok().or_else(|| {
            let parent = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
            Some(parent.canonicalize().ok()?.join(p.file_name()?))
        })
    };
    let Some(out_c) = canonical(out) else { return Ok(()) };
    for (flag, input) in inputs {
        if canonical(input).is_some_and(|i| i == out_c) {
            return Err(RolloutError::Argument {
                flag: "--out".into(),
                message: format!("{} is the {flag} input; the rollout would overwrite it", out.display()),
            });
        }
    }
    Ok(())
}
