//! The memory a batch of environments takes, estimated before anything is allocated, so that
//! a batch the machine cannot hold is refused with the estimate ([`VecEnv::bytes_per_env`],
//! [`check_batch_fits`]; issue 44 item 2: `num_envs = 2^20` of `team_sumo/3_ants`, about
//! 130 GB, was accepted and the process aborted in the allocator).
//!
//! An environment's size depends on its scene: the simulator state ([`Data`]) is sized from
//! the model, but its constraint scratch grows with the most simultaneous contacts it has
//! seen (the `n x n` matrix of `n` constraint rows dominates). The estimate therefore steps
//! one probe environment of the scene for [`PROBE_STEPS`] control steps of full, alternating
//! torques from a random start and measures the capacities it holds then, plus the
//! environment's rows of the output arrays and the allocator's overhead. Tested against the
//! resident memory of built and stepped batches (`envs/tests/memory_estimate.rs`).

use super::{NextStart, Slot, VecEnv, begin_episode, env_rng};
use crate::data::Data;
use crate::tasks::error::TaskError;
use crate::tasks::outcome::{Outcome, RootState};
use crate::tasks::scene::Scene;

/// Control steps the probe environment is stepped for (module docs): enough for every
/// agent to land and flail against the ground.
pub const PROBE_STEPS: usize = 20;

/// Bytes the allocator adds per environment: about 16 per buffer (a `Data` holds some 50)
/// and the rounding of each to its size class.
const ALLOCATOR_OVERHEAD: u64 = 2048;

impl VecEnv {
    /// Estimated bytes one environment of `scene` takes in a [`VecEnv`] (module docs): its
    /// state and scratch after [`PROBE_STEPS`] probe steps, its rows of the observation,
    /// final observation, reward and flag arrays, and the allocator's overhead.
    pub fn bytes_per_env(scene: &Scene) -> u64 {
        let m = &scene.model;
        let na = scene.n_agents();
        let mut slot = Slot {
            data: Data::new(m),
            rng: env_rng(0, 0),
            balls: Vec::new(),
            step: 0,
            roots: RootState { pos: vec![[0.0; 2]; na], vel: vec![[0.0; 2]; na], action_norm: vec![0.0; na] },
        };
        begin_episode(scene, &mut slot, NextStart::Fresh);
        for t in 0..PROBE_STEPS {
            for (k, c) in slot.data.ctrl.iter_mut().enumerate() {
                *c = if (t + k) % 2 == 0 { 1.0 } else { -1.0 };
            }
            for _ in 0..scene.spec.physics_steps {
                crate::step(m, &mut slot.data);
            }
        }
        let slot_bytes = std::mem::size_of::<Slot>()
            + slot.data.heap_bytes()
            + scene.spec.balls * std::mem::size_of::<[f64; 2]>()
            + na * (2 * std::mem::size_of::<[f64; 2]>() + std::mem::size_of::<f64>());
        let w = scene.obs_spec.row_widths();
        let obs_row = 4 * (w.vectors + w.scalars + w.heading);
        let outputs = 2 * obs_row
            + 4 * scene.n_teams()
            + 2
            + std::mem::size_of::<Outcome>()
            + 4
            + std::mem::size_of::<super::Row<'static>>();
        (slot_bytes + outputs) as u64 + ALLOCATOR_OVERHEAD
    }
}

/// Refuses `batch` environments of `scene` when their estimated size
/// ([`VecEnv::bytes_per_env`]) is more than the machine's memory
/// ([`crate::memory::machine_memory`]); the error names the batch, the scene, the estimate
/// per environment and in all, and the machine's memory.
pub fn check_batch_fits(scene: &Scene, batch: usize) -> Result<(), TaskError> {
    let per_env = VecEnv::bytes_per_env(scene);
    let total = (batch as u128).checked_mul(per_env as u128);
    crate::memory::check_fits(total).map_err(|why| TaskError::BadArgument {
        what: "batch".into(),
        value: batch.to_string(),
        message: format!(
            "{batch} environments of {} at about {} each {why}",
            scene.spec.name,
            crate::memory::gigabytes(per_env as u128)
        ),
    })
}
