//! Simulator throughput benchmark (`../shared/bench/SIM.md`): MuJoCo's ant loaded from
//! `shared/reference/mjcf/ant.xml` through the MJCF loader, semi-implicit Euler at dt 0.01,
//! 64 independent ants x 1000 control steps of 5 physics steps, controls uniform in [-1, 1]
//! (seeded ChaCha8, a fresh draw per ant per control step), on every core. Prints
//!
//! `ant_rollout env_steps_per_s=... envs=64 steps=1000 threads=N torso_z_max=... nan=0`
//!
//! Environment variables `NENV` and `STEPS` override the sizes (as the MuJoCo peer's do).

use envs::{Data, Integrator, Model};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::time::Instant;

const FRAMES: usize = 5;
const INIT_QPOS: [f64; 15] = [0.0, 0.0, 0.55, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0, -1.0, 0.0, 1.0];

fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// Runs every ant through its controls; returns (highest torso z, any non-finite state).
fn rollout(m: &Model, datas: &mut [Data], ctrl: &[f64], steps: usize) -> (f64, bool) {
    let nu = m.nu();
    datas
        .par_iter_mut()
        .enumerate()
        .map(|(e, d)| {
            let mut zmax = f64::NEG_INFINITY;
            let mut nan = false;
            for s in 0..steps {
                let off = (e * steps + s) * nu;
                d.ctrl.copy_from_slice(&ctrl[off..off + nu]);
                for _ in 0..FRAMES {
                    envs::step(m, d);
                }
                zmax = zmax.max(d.qpos[2]);
                nan |= !d.is_finite();
            }
            (zmax, nan)
        })
        .reduce(|| (f64::NEG_INFINITY, false), |a, b| (a.0.max(b.0), a.1 | b.1))
}

fn main() {
    let nenv = env_usize("NENV", 64);
    let steps = env_usize("STEPS", 1000);
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/reference/mjcf/ant.xml");
    let mut model = match envs::mjcf::load_file(path) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    model.opt.integrator = Integrator::Euler;
    model.opt.timestep = 0.01;
    let nu = model.nu();
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let ctrl: Vec<f64> = (0..nenv * steps * nu).map(|_| rng.random_range(-1.0..1.0)).collect();
    let fresh = |n: usize| -> Vec<Data> {
        (0..n)
            .map(|_| {
                let mut d = Data::new(&model);
                d.reset_to(&model, &INIT_QPOS).expect("the ant has nq = 15");
                d
            })
            .collect()
    };
    // Warm-up: two ants, 50 control steps.
    let mut warm = fresh(2);
    rollout(&model, &mut warm, &ctrl[..2 * 50 * nu], 50);
    let mut datas = fresh(nenv);
    let t = Instant::now();
    let (zmax, nan) = rollout(&model, &mut datas, &ctrl, steps);
    let dt = t.elapsed().as_secs_f64();
    println!(
        "ant_rollout env_steps_per_s={:.0}  envs={nenv}  steps={steps}  threads={}  torso_z_max={zmax:.2}  nan={}",
        (nenv * steps) as f64 / dt,
        rayon::current_num_threads(),
        nan as u8
    );
}
