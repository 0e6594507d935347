//! Batched stepping of many independent scenes with rayon. Each [`Data`] is stepped by one
//! thread from start to end with the same sequential code, so the results are bit-identical
//! whatever the number of threads or the work split.

use crate::data::Data;
use crate::integrator::step;
use crate::model::Model;
use rayon::prelude::*;

/// Advances every scene by `nsteps` physics steps (each with its own `ctrl`), in parallel on
/// the current rayon thread pool.
pub fn step_batch(m: &Model, datas: &mut [Data], nsteps: usize) {
    datas.par_iter_mut().for_each(|d| {
        for _ in 0..nsteps {
            step(m, d);
        }
    });
}

/// Like [`step_batch`], but first sets each scene's controls from `ctrl` (row-major,
/// `datas.len() x Model::nu()`). Panics if `ctrl` has the wrong length (a programming error).
pub fn step_batch_ctrl(m: &Model, datas: &mut [Data], ctrl: &[f64], nsteps: usize) {
    let nu = m.nu();
    assert_eq!(ctrl.len(), datas.len() * nu, "ctrl must hold nu values per scene");
    datas.par_iter_mut().enumerate().for_each(|(e, d)| {
        d.ctrl.copy_from_slice(&ctrl[e * nu..(e + 1) * nu]);
        for _ in 0..nsteps {
            step(m, d);
        }
    });
}
