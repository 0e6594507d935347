//! Throughput of the MeBen tasks: env steps per second (control steps of 0.05 s, 5 physics
//! steps each, rewards, observations and auto-resets included) with uniform random actions
//! for 256 environments of `team_reach/1_ant`, `team_reach/3_ant_claw_centipede` and
//! `team_sumo/2_ants`, on every core. One line per environment:
//!
//! `<env> env_steps_per_s=...  envs=256 steps=... threads=N`
//!
//! Environment variables `NENV` and `STEPS` override the sizes; `ENVS` (comma separated)
//! the environment names.

use envs::tasks::{StartMode, VecEnv};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn bench(name: &str, nenv: usize, steps: usize) -> Result<(), String> {
    let mut env = VecEnv::from_name(name, nenv, 0, StartMode::Random).map_err(|e| e.to_string())?;
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    // A pool of random action batches, cycled (drawing them is not what is measured).
    let pool: Vec<Vec<f32>> =
        (0..16).map(|_| (0..nenv * env.n_actions()).map(|_| rng.random_range(-1.0f32..1.0)).collect()).collect();
    for a in pool.iter().take(10) {
        env.step(a).map_err(|e| e.to_string())?;
    }
    let t = Instant::now();
    let mut done = 0usize;
    for s in 0..steps {
        let out = env.step(&pool[s % pool.len()]).map_err(|e| e.to_string())?;
        done += out.terminated.iter().zip(&out.truncated).filter(|(a, b)| **a || **b).count();
    }
    let dt = t.elapsed().as_secs_f64();
    println!(
        "{name} env_steps_per_s={:.0}  envs={nenv} steps={steps} threads={} episodes_ended={done}",
        (nenv * steps) as f64 / dt,
        rayon::current_num_threads()
    );
    Ok(())
}

fn main() {
    let nenv = env_usize("NENV", 256);
    let steps = env_usize("STEPS", 200);
    let names = std::env::var("ENVS")
        .unwrap_or_else(|_| "team_reach/1_ant,team_reach/3_ant_claw_centipede,team_sumo/2_ants".to_string());
    for name in names.split(',') {
        if let Err(e) = bench(name, nenv, steps) {
            eprintln!("error: {name}: {e}");
            std::process::exit(1);
        }
    }
}
