//! Records one episode of a MeBen task with uniform random actions and writes it as a
//! self-contained HTML player, an animated GIF and a CSV of body poses.
//!
//! `cargo run --release -p envs --example tasks_render -- team_sumo/2_ants 0 300 episode`
//! writes `episode.html`, `episode.gif` and `episode.csv` (arguments: environment name or
//! composition, seed, control steps, output path without extension).

use envs::tasks::render::{GifOptions, record_episode};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Parses argument `i` (or returns `default` when absent); a malformed value is an error
/// naming the argument.
fn arg<T: std::str::FromStr>(args: &[String], i: usize, what: &str, default: T) -> T {
    match args.get(i) {
        None => default,
        Some(s) => s.parse().unwrap_or_else(|_| {
            eprintln!("error: {what} must be a non-negative integer, got `{s}`");
            std::process::exit(2);
        }),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args.first().map(String::as_str).unwrap_or("team_reach/3_ant_claw_centipede");
    let seed: u64 = arg(&args, 1, "seed (2nd argument)", 0);
    let steps: usize = arg(&args, 2, "control steps (3rd argument)", 200);
    let out = args.get(3).map(String::as_str).unwrap_or("episode");
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let traj = match record_episode(name, seed, steps, |_obs, a| {
        a.iter_mut().for_each(|x| *x = rng.random_range(-1.0..1.0))
    }) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    let gif = match traj.to_gif(&GifOptions::default()) {
        Ok(g) => g,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    for (ext, text) in [("html", traj.to_html().into_bytes()), ("gif", gif), ("csv", traj.to_csv().into_bytes())] {
        let path = format!("{out}.{ext}");
        if let Err(e) = std::fs::write(&path, text) {
            eprintln!("error: cannot write {path}: {e}");
            std::process::exit(1);
        }
        println!("wrote {path}");
    }
    println!("{} frames of {name}", traj.len());
}
