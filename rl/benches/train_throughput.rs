//! End-to-end training throughput (`../shared/bench/TRAIN.md`): env steps per second of wall
//! time while training with the reference release's defaults (2048 environments, unroll 5,
//! batch 1024 unrolls x 32 minibatches = 163,840 env steps an iteration, 4 epochs, Adam,
//! observation normalisation), collection and updates together, on every core.
//!
//! For each pair it prints
//! `<env> <model> env_steps_per_s=<median over the measured iterations> ...`, and for the
//! arithmetic floor: the floating-point operations of the update per env step (forward and
//! backward of one minibatch counted on a profiled tape, times minibatches and epochs, divided
//! by the iteration's env steps), the f32 matmul rate measured here, and the floor
//! `floor_steps_per_s = rate / flops_per_step` with the ratio `floor / measured`.
//!
//! Run: `cargo bench -p rl --bench train_throughput [-- <filter>]` (a substring of
//! `<env> <model>`). `ITERATIONS=k` measures k iterations (default 2) after one warm-up
//! iteration (`WARMUP=0` for none). `TENSOR_PROFILE=1` prints the per-op profile of the
//! counted minibatch update.

use std::time::Instant;

#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

use rl::ppo::{PpoParams, ppo_loss};
use rl::rollout::MinibatchBuf;
use rl::{Preset, TrainConfig, Trainer};
use tensor::{Tape, Tensor};

fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// Median GFLOP/s of f32 products of the update's typical shape through the library.
fn matmul_rate() -> Result<f64, Box<dyn std::error::Error>> {
    let mut rates = Vec::new();
    for (m, k, n) in [(6144, 256, 256), (6144, 1153, 64), (2048, 2048, 2048)] {
        let a = Tensor::<f32>::new((0..m * k).map(|i| ((i % 97) as f32) * 0.01).collect(), &[m, k])?;
        let b = Tensor::<f32>::new((0..k * n).map(|i| ((i % 89) as f32) * 0.01).collect(), &[k, n])?;
        let mut t = Vec::new();
        for rep in 0..8 {
            let tape = Tape::<f32>::new();
            let (x, y) = (tape.constant(a.clone()), tape.constant(b.clone()));
            let s = Instant::now();
            let z = x.matmul(y)?;
            std::hint::black_box(z.value());
            if rep >= 2 {
                t.push(s.elapsed().as_secs_f64());
            }
        }
        t.sort_by(f64::total_cmp);
        rates.push(2.0 * (m * k * n) as f64 / t[t.len() / 2] / 1e9);
    }
    rates.sort_by(f64::total_cmp);
    Ok(rates[rates.len() / 2])
}

/// FLOPs of one minibatch update of team 0 (forward and backward), counted on a profiled tape.
fn minibatch_flops(t: &mut Trainer, c: &TrainConfig) -> Result<u64, Box<dyn std::error::Error>> {
    let ids: Vec<usize> = (0..c.batch_size).collect();
    let mut mb = MinibatchBuf::default();
    t.rollout().gather(&ids, 0, &mut mb);
    let spec = t.spec.clone();
    let team = &mut t.teams[0];
    let (mut v, mut s) = (Vec::new(), Vec::new());
    team.norm.apply(&mb.vectors, &mb.scalars, &mut v, &mut s);
    let hp = PpoParams::from_config(c);
    let tape = Tape::<f32>::new();
    tape.enable_profiling();
    let p = team.store.bind(&tape);
    let mut model = team.model.clone();
    let (loss, _) = ppo_loss(&mut model, &spec, &p, &mb.view(&v, &s), &hp)?;
    tape.backward(loss)?;
    if std::env::var_os("TENSOR_PROFILE").is_some()
        && let Some(r) = tape.profile_report()
    {
        eprintln!("{r}");
    }
    Ok(tape.profile_flops().map(|f| f.total()).unwrap_or(0))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let iterations = env_usize("ITERATIONS", 2).max(1);
    let warmup = env_usize("WARMUP", 1);
    let rate = matmul_rate()?;
    println!("matmul_rate_gflops={rate:.1}");
    for env in ["team_reach/1_ant", "team_reach/3_ant_claw_centipede"] {
        for model in ["shnn", "mlp_hn"] {
            let label = format!("{env} {model}");
            if filter.as_ref().is_some_and(|f| !label.contains(f.as_str())) {
                continue;
            }
            let ov = vec![("env".to_string(), format!("{env:?}")), ("model".to_string(), format!("{model:?}"))];
            let config = TrainConfig::resolve(Some(Preset::Paper), None, &ov)?;
            let mut t = Trainer::new(&config)?;
            for _ in 0..warmup {
                t.iterate()?;
            }
            let mut sps = Vec::new();
            let (mut collect, mut update) = (0.0, 0.0);
            for _ in 0..iterations {
                let s = Instant::now();
                let st = t.iterate()?;
                sps.push(config.steps_per_iteration() as f64 / s.elapsed().as_secs_f64());
                collect += st.collect_s / iterations as f64;
                update += st.update_s / iterations as f64;
            }
            let flops = minibatch_flops(&mut t, &config)? as f64;
            let per_step =
                flops * (config.num_minibatches * config.epochs) as f64 / config.steps_per_iteration() as f64;
            let floor = rate * 1e9 / per_step;
            let mut sorted = sps.clone();
            sorted.sort_by(f64::total_cmp);
            let k = sorted.len();
            let median = if k % 2 == 1 { sorted[k / 2] } else { 0.5 * (sorted[k / 2 - 1] + sorted[k / 2]) };
            let all: Vec<String> = sps.iter().map(|x| format!("{x:.0}")).collect();
            println!(
                "{label} env_steps_per_s={median:.0} iterations=[{}] update_flops_per_step={:.3e} \
                 floor_steps_per_s={floor:.0} floor_ratio={:.2} collect_s={collect:.1} update_s={update:.1}",
                all.join(","),
                per_step,
                floor / median
            );
        }
    }
    Ok(())
}
