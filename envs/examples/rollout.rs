//! Open-loop rollout of an MJCF model, to hold the simulator against another engine.
//!
//! ```text
//! cargo run --release -p envs --example rollout -- --mjcf FILE --controls CTRL.csv \
//!     --out OUT.csv --frames 5 [--qpos q0,q1,...]
//! ```
//!
//! Loads the model, sets the initial qpos (MuJoCo layout: free joint `x y z qw qx qy qz`, then
//! hinge angles in file order; default: the model's own initial pose) at rest, applies each
//! row of CTRL.csv (no header, one column per actuator in file order) for `--frames` physics
//! steps and writes OUT.csv: a header line `q0,q1,...`, then one row of qpos per control step,
//! the initial state first. Any bad input is reported on stderr with a non-zero exit code.

use clap::Parser;
use std::io::Write;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(about = "Open-loop rollout of an MJCF model; writes qpos per control step")]
struct Args {
    /// MJCF (MuJoCo XML) model file.
    #[arg(long)]
    mjcf: String,
    /// Controls: one row per control step, one column per actuator, no header.
    #[arg(long)]
    controls: String,
    /// Output CSV of qpos, one row per control step (initial state first).
    #[arg(long)]
    out: String,
    /// Physics steps per control step.
    #[arg(long, default_value_t = 5)]
    frames: usize,
    /// Initial qpos, comma-separated (default: the model's initial pose).
    #[arg(long)]
    qpos: Option<String>,
}

fn parse_row(text: &str, what: &str) -> Result<Vec<f64>, String> {
    text.split(',')
        .enumerate()
        .map(|(i, t)| {
            let t = t.trim();
            t.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("{what}, column {}: \"{t}\" is not a finite number", i + 1))
        })
        .collect()
}

fn run(args: Args) -> Result<(), String> {
    if args.frames == 0 {
        return Err("--frames must be at least 1".into());
    }
    let model = envs::mjcf::load_file(&args.mjcf).map_err(|e| e.to_string())?;
    let mut data = envs::Data::new(&model);
    if let Some(q) = &args.qpos {
        let q = parse_row(q, "--qpos")?;
        data.reset_to(&model, &q).map_err(|e| format!("--qpos: {e}"))?;
    }
    let text = std::fs::read_to_string(&args.controls).map_err(|e| format!("{}: cannot read: {e}", args.controls))?;
    let mut controls = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let row = parse_row(line, &format!("{}:{}", args.controls, i + 1))?;
        if row.len() != model.nu() {
            return Err(format!(
                "{}:{}: {} columns, but the model has {} actuators",
                args.controls,
                i + 1,
                row.len(),
                model.nu()
            ));
        }
        controls.push(row);
    }
    let file = std::fs::File::create(&args.out).map_err(|e| format!("{}: cannot create: {e}", args.out))?;
    let mut out = std::io::BufWriter::new(file);
    let io = |e: std::io::Error| format!("{}: write failed: {e}", args.out);
    let header: Vec<String> = (0..model.nq).map(|i| format!("q{i}")).collect();
    writeln!(out, "{}", header.join(",")).map_err(io)?;
    let write_row = |out: &mut std::io::BufWriter<std::fs::File>, q: &[f64]| {
        let row: Vec<String> = q.iter().map(|x| format!("{x:e}")).collect();
        writeln!(out, "{}", row.join(",")).map_err(io)
    };
    write_row(&mut out, &data.qpos)?;
    for row in &controls {
        data.ctrl.copy_from_slice(row);
        for _ in 0..args.frames {
            envs::step(&model, &mut data);
        }
        write_row(&mut out, &data.qpos)?;
    }
    out.flush().map_err(io)?;
    if !data.is_finite() {
        return Err("the state became non-finite".into());
    }
    Ok(())
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
