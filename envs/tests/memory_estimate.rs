//! The memory estimate of a batch of environments ([`VecEnv::bytes_per_env`], issue 44 item
//! 2) against the resident memory (`VmRSS`) a built and stepped batch really takes, each
//! scene measured in a child process of its own (so that no other test's or scene's memory
//! is counted, nor freed memory reused); and a batch the machine cannot hold refused before
//! it is allocated, naming the estimate and the machine's memory.

use envs::tasks::{Scene, StartMode, VecEnv};

/// Environments of the measured batches.
const BATCH: usize = 1024;

/// The estimate must lie within this factor of the measured memory, either way.
const FACTOR: f64 = 1.5;

/// `VmRSS` of this process in bytes.
fn rss() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("VmRSS:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse::<u64>().unwrap() * 1024
}

/// In the child (`MEBEN_MEASURE_SCENE` set): builds [`BATCH`] environments of the scene,
/// steps them 50 control steps with alternating full torques, and prints
/// `measured <bytes per environment>`.
#[test]
fn measure_child() {
    let Ok(name) = std::env::var("MEBEN_MEASURE_SCENE") else { return };
    // The thread pool and the scene's first allocations before the baseline.
    let mut warm = VecEnv::from_name(&name, 2, 1, StartMode::Random).unwrap();
    warm.step(&vec![0.0; 2 * warm.n_actions()]).unwrap();
    let before = rss();
    let mut env = VecEnv::from_name(&name, BATCH, 1, StartMode::Random).unwrap();
    let na = env.n_actions();
    for t in 0..50 {
        let a: Vec<f32> = (0..BATCH * na).map(|i| if (i + t) % 2 == 0 { 1.0 } else { -1.0 }).collect();
        env.step(&a).unwrap();
    }
    let after = rss();
    println!("measured {}", (after - before) / BATCH as u64);
}

#[test]
fn the_estimate_is_within_its_factor_of_the_resident_memory() {
    let exe = std::env::current_exe().unwrap();
    let mut lines = Vec::new();
    for name in ["team_reach/1_ant", "team_reach/3_ant_claw_centipede", "team_sumo/3_ants"] {
        let out = std::process::Command::new(&exe)
            .args(["--exact", "measure_child", "--nocapture", "--test-threads", "1"])
            .env("MEBEN_MEASURE_SCENE", name)
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
        let measured: f64 = stdout
            .lines()
            .find_map(|l| l.split("measured ").nth(1))
            .unwrap_or_else(|| panic!("no measurement: {stdout}"))
            .trim()
            .parse()
            .unwrap();
        let estimate = VecEnv::bytes_per_env(&Scene::from_name(name).unwrap()) as f64;
        let ratio = estimate / measured;
        lines.push(format!(
            "{name}: estimate {estimate:.0} B, measured {measured:.0} B per environment, ratio {ratio:.2}"
        ));
        eprintln!("{}", lines.last().unwrap());
        assert!((1.0 / FACTOR..=FACTOR).contains(&ratio), "{}", lines.join("\n"));
    }
}

/// Issue 44 item 2: `meben.make("team_sumo/3_ants", num_envs=2**20)` was accepted (about
/// 130 GB) and the process aborted in the allocator. Refused now, before allocating, with
/// the estimate and the machine's memory; a batch of 4 is fine.
#[test]
fn a_batch_beyond_the_machine_is_refused_before_it_is_allocated() {
    let Some(memory) = envs::memory::machine_memory() else { return };
    let scene = Scene::from_name("team_sumo/3_ants").unwrap();
    let per_env = VecEnv::bytes_per_env(&scene);
    let batch = envs::tasks::MAX_ENVS;
    if (batch as u128) * (per_env as u128) <= memory.bytes {
        eprintln!("this machine holds {batch} environments of team_sumo/3_ants: nothing to refuse");
        return;
    }
    let e = VecEnv::from_name("team_sumo/3_ants", batch, 0, StartMode::Random).unwrap_err().to_string();
    assert!(e.contains("1048576 environments of team_sumo/3_ants at about") && e.contains("KB each"), "{e}");
    // The machine's memory, or the process's own limit where smaller (a cgroup, `ulimit -v`).
    assert!(
        (e.contains("GB, more than this machine's") && e.contains("/proc/meminfo"))
            || e.contains("GB, more than this process's limit"),
        "{e}"
    );
    VecEnv::from_name("team_sumo/3_ants", 4, 0, StartMode::Random).unwrap();
}
