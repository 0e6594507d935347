//! Forward + backward of policy and value on a 5120-transition minibatch: for
//! `team_reach/2_ants` and `team_reach/3_ant_claw_centipede`, team 0, the
//! models `shnn`, `mlp_hn`, `shtransformer` and `shgnn`, in f32. The minibatch is 512
//! observations of the vectorised environment (after a few random steps) replicated 10
//! times. The loss sums the means of every agent's `loc`, `std` and the value, so the
//! backward pass reaches every parameter. Prints `<env> <model> median_ms=...` per pair, with
//! the buffer pool's counters since the process started (misses, evictions, peak and cap:
//! `tensor::pool`).
//!
//! Run: `cargo bench -p models --bench forward_backward [-- <filter>]` (the filter is a
//! substring of `<env> <model>`). `TENSOR_PROFILE=1` prints the per-op forward/backward
//! time of the last step of each pair.

use std::time::Instant;

#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

use envs::layout::ObsRows;
use envs::tasks::{StartMode, VecEnv};
use models::{Model, ModelDescription};
use nn::ParamStore;
use tensor::Tape;

const MINIBATCH: usize = 5120;
const DISTINCT: usize = 512;
const WARMUP: usize = 1;
const STEPS: usize = 5;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let profile = std::env::var_os("TENSOR_PROFILE").is_some();
    for env_name in ["team_reach/2_ants", "team_reach/3_ant_claw_centipede"] {
        let mut env = VecEnv::from_name(env_name, DISTINCT, 7, StartMode::Random)?;
        let na = env.n_actions();
        for k in 0..3 {
            let actions: Vec<f32> = (0..DISTINCT * na).map(|i| (((i * 7 + k * 13) % 17) as f32 / 8.0) - 1.0).collect();
            env.step(&actions)?;
        }
        let spec = env.scene().obs_spec.clone();
        let o = env.obs();
        let rep = MINIBATCH / DISTINCT;
        let vectors = o.vectors.repeat(rep);
        let scalars = o.scalars.repeat(rep);
        let heading = o.heading.repeat(rep);
        let obs = ObsRows::new(spec.n_nodes, spec.n_agents, &vectors[..], &scalars[..], &heading[..])?;
        for name in ["shnn", "mlp_hn", "shtransformer", "shgnn"] {
            let label = format!("{env_name} {name}");
            if filter.as_ref().is_some_and(|f| !label.contains(f.as_str())) {
                continue;
            }
            let mut store = ParamStore::<f32>::new();
            let mut init = nn::init_rng(0);
            let mut model =
                Model::new(&mut store.scope("team0", &mut init), &ModelDescription::parse(name)?, &spec, 0)?;
            let mut times = Vec::with_capacity(STEPS);
            for k in 0..WARMUP + STEPS {
                let t = Instant::now();
                let tape = Tape::new();
                if profile && k + 1 == WARMUP + STEPS {
                    tape.enable_profiling();
                }
                let p = store.bind(&tape);
                let out = model.forward_batch(&p, &obs)?;
                let mut loss = out.team_value()?.mean_all()?;
                for a in &out.agents {
                    loss = loss.add(a.loc.mean_all()?)?.add(a.std().mean_all()?)?;
                }
                let g = tape.backward(loss)?;
                std::hint::black_box(p.grads(&g));
                if let Some(report) = tape.profile_report() {
                    eprintln!("{label}\n{report}");
                }
                if k >= WARMUP {
                    times.push(t.elapsed().as_secs_f64() * 1e3);
                }
            }
            times.sort_by(f64::total_cmp);
            let median = times[STEPS / 2];
            let pool = tensor::pool::stats::<f32>();
            println!(
                "{label} median_ms={median:.1} (B={MINIBATCH}, params={}) pool_misses={} pool_evicted={} pool_peak_mb={} pool_cap_mb={}",
                model.num_params(&store),
                pool.misses,
                pool.evicted,
                pool.peak_pooled_bytes >> 20,
                tensor::pool::max_pooled_bytes() >> 20
            );
        }
    }
    Ok(())
}
