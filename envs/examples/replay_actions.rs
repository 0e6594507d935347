//! Replays a fixed action sequence in a `VecEnv` and writes every array it returns, as raw
//! little-endian `f32`, so that another front end (the Python package's tests) can compare
//! its own trajectory with the Rust one bit for bit.
//!
//! `cargo run --release -p envs --example replay_actions -- NAME NUM_ENVS SEED ACTIONS OUT`
//!
//! `ACTIONS` holds `steps x NUM_ENVS x n_actions` `f32` (little-endian, the number of steps
//! follows from the file's length). The environments are built then reset (as `meben.make(...)` then `env.reset()` in
//! Python). `OUT` gets the observations after the reset (`vectors`,
//! `scalars`, `heading`), then per step: `obs` (the same three), `reward`, `final_obs`,
//! `terminated` and `truncated` (as 0.0 or 1.0).

use envs::layout::Observation;
use envs::tasks::{StartMode, VecEnv};

fn push_obs(out: &mut Vec<f32>, o: &Observation) {
    out.extend_from_slice(&o.vectors);
    out.extend_from_slice(&o.scalars);
    out.extend_from_slice(&o.heading);
}

fn run(args: &[String]) -> Result<(), String> {
    let [name, batch, seed, actions, out] = args else {
        return Err("expected 5 arguments: NAME NUM_ENVS SEED ACTIONS OUT".into());
    };
    let batch: usize = batch.parse().map_err(|_| format!("NUM_ENVS must be a whole number, got `{batch}`"))?;
    let seed: u64 = seed.parse().map_err(|_| format!("SEED must be a non-negative integer, got `{seed}`"))?;
    let bytes = std::fs::read(actions).map_err(|e| format!("{actions}: {e}"))?;
    let actions: Vec<f32> = bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    let mut env = VecEnv::from_name(name, batch, seed, StartMode::Random).map_err(|e| e.to_string())?;
    let row = batch * env.n_actions();
    if !bytes.len().is_multiple_of(4) || !actions.len().is_multiple_of(row) {
        return Err(format!("{} bytes of actions is not a whole number of steps of {row} f32", bytes.len()));
    }
    let mut trace = Vec::new();
    push_obs(&mut trace, env.reset());
    for step in actions.chunks_exact(row) {
        let o = env.step(step).map_err(|e| e.to_string())?;
        push_obs(&mut trace, &o.obs);
        trace.extend_from_slice(&o.reward);
        push_obs(&mut trace, &o.final_obs);
        trace.extend(o.terminated.iter().map(|&t| if t { 1.0f32 } else { 0.0 }));
        trace.extend(o.truncated.iter().map(|&t| if t { 1.0f32 } else { 0.0 }));
    }
    let bytes: Vec<u8> = trace.iter().flat_map(|x| x.to_le_bytes()).collect();
    std::fs::write(out, bytes).map_err(|e| format!("{out}: {e}"))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let Err(e) = run(&args) {
        eprintln!("error: {e}");
        std::process::exit(2);
    }
}
