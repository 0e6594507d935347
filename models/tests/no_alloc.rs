//! The input processing and the graph builder allocate only their output buffers: the number
//! of allocations of one call does not depend on the batch size (no per-scene allocation).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use envs::tasks::{StartMode, VecEnv};
use models::{AssignmentMethod, GraphBuilder, InputProcessor, Translation};

struct Counting;

static ALLOCS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call forwards to the system allocator with the caller's arguments; the
// counter has no effect on memory.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded unchanged; the caller upholds `GlobalAlloc`'s contract.
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        // SAFETY: forwarded unchanged; the caller upholds `GlobalAlloc`'s contract.
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded unchanged; the caller upholds `GlobalAlloc`'s contract.
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn count<R>(f: impl FnOnce() -> R) -> (usize, R) {
    let before = ALLOCS.load(Ordering::Relaxed);
    let r = f();
    (ALLOCS.load(Ordering::Relaxed) - before, r)
}

#[test]
fn allocations_do_not_grow_with_the_batch() {
    for name in ["team_reach/2_ants", "team_sumo/2_ants"] {
        let env = VecEnv::from_name(name, 40, 3, StartMode::Random).unwrap();
        let spec = env.scene().obs_spec.clone();
        let o = env.obs();
        let proc = InputProcessor::new(&spec, Translation::Assigned).unwrap();
        // Warm-up: one-time lazy initialisations (the thread pool's workers, thread-locals)
        // allocate on first use, possibly on other threads while a later call is counted
        // (the counter sees every thread); they must not be attributed to a batch size.
        {
            let obs = o.rows().slice(0..40).node_batch();
            let mut builder = GraphBuilder::new(&spec, AssignmentMethod::Greedy, 0, 0).unwrap();
            let e = proc.entities::<f32, f32>(&obs).unwrap();
            let g = builder.build(&e).unwrap();
            proc.bodies(&obs, &e, &g.agent_entity, &[0, 1]).unwrap();
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        let mut counts = Vec::new();
        for batch in [2, 40] {
            let obs = o.rows().slice(0..batch).node_batch();
            for method in [AssignmentMethod::Greedy, AssignmentMethod::Hungarian, AssignmentMethod::None] {
                let mut builder = GraphBuilder::new(&spec, method, 0, 0).unwrap();
                let (ce, e) = count(|| proc.entities::<f32, f32>(&obs).unwrap());
                let (cg, g) = count(|| builder.build(&e).unwrap());
                let (cb, bodies) = count(|| proc.bodies(&obs, &e, &g.agent_entity, &[0, 1]).unwrap());
                assert_eq!(bodies.len(), 2);
                counts.push((batch, method, ce, cg, cb));
            }
        }
        let (small, large) = counts.split_at(3);
        for (s, l) in small.iter().zip(large) {
            assert_eq!((s.2, s.3, s.4), (l.2, l.3, l.4), "{name}: {s:?} vs {l:?}");
        }
    }
}
