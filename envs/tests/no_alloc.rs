//! Stepping does not allocate: `Data` holds every buffer, and the constraint buffers only grow
//! when a scene meets more simultaneous contacts than ever before. A counting global
//! allocator checks that replaying a rollout on a `Data` that has already seen it allocates
//! nothing.

use envs::{Data, Model};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call forwards to the system allocator with the caller's arguments; the
// counter has no effect on memory.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded unchanged; the caller upholds `GlobalAlloc`'s contract.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged; the caller upholds `GlobalAlloc`'s contract.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded unchanged; the caller upholds `GlobalAlloc`'s contract.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

const ANT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/morphologies/mujoco_ant.xml");

fn rollout(m: &Model, d: &mut Data, ctrl: &[f64]) {
    let nu = m.nu();
    for row in ctrl.chunks(nu) {
        d.ctrl.copy_from_slice(row);
        for _ in 0..5 {
            envs::step(m, d);
        }
    }
}

#[test]
fn replaying_a_rollout_allocates_nothing() {
    for integrator in [envs::Integrator::Euler, envs::Integrator::EulerGyro, envs::Integrator::Implicit] {
        let mut m = envs::mjcf::load_file(ANT).unwrap();
        m.opt.timestep = 0.01;
        m.opt.integrator = integrator;
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let ctrl: Vec<f64> = (0..300 * m.nu()).map(|_| rng.random_range(-1.0..1.0)).collect();
        let q0 = [0.0, 0.0, 0.55, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0, -1.0, 0.0, 1.0];
        let mut d = Data::new(&m);
        d.reset_to(&m, &q0).unwrap();
        rollout(&m, &mut d, &ctrl);
        let first = d.qpos.clone();
        d.reset_to(&m, &q0).unwrap();
        let before = ALLOCATIONS.load(Ordering::Relaxed);
        rollout(&m, &mut d, &ctrl);
        let after = ALLOCATIONS.load(Ordering::Relaxed);
        // The replay is the same computation (deterministic), so it needs no new capacity.
        assert_eq!(d.qpos, first, "{integrator:?}: the replay differs");
        assert_eq!(after - before, 0, "{integrator:?}: {} allocations in 1500 steps", after - before);
    }
}
