//! Batched stepping of many independent scenes with rayon. Each [`Data`] is stepped by one
//! thread from start to end with the same sequential code, so the results are bit-identical
//! whatever the number of threads or the work split.

use crate::data::Data;
use crate::integrator::step;
use crate::model::Model;
use rayon::prelude::*;

/// Advances every scene by `nsteps` physics steps (each with its own `ctrl`), in parallel on
/// the current rayon thread pool. Errors, stepping nothing, if a `Data` was not made for this
/// model.
pub fn step_batch(m: &Model, datas: &mut [Data], nsteps: usize) -> Result<(), String> {
    check(m, datas)?;
    datas.par_iter_mut().for_each(|d| {
        for _ in 0..nsteps {
            step(m, d);
        }
    });
    Ok(())
}

fn check(m: &Model, datas: &[Data]) -> Result<(), String> {
    match datas.iter().position(|d| d.ctrl.len() != m.nu() || d.qpos.len() != m.nq || d.qvel.len() != m.nv) {
        Some(i) => {
            Err(format!("scene {i}: its Data does not match the model (nq {}, nv {}, nu {})", m.nq, m.nv, m.nu()))
        }
        None => Ok(()),
    }
}

/// Like [`step_batch`], but first sets each scene's controls from `ctrl` (row-major,
/// `datas.len() x Model::nu()`). Errors, stepping nothing, if `ctrl` has the wrong length or a
/// `Data` was not made for this model.
pub fn step_batch_ctrl(m: &Model, datas: &mut [Data], ctrl: &[f64], nsteps: usize) -> Result<(), String> {
    let nu = m.nu();
    if ctrl.len() != datas.len() * nu {
        return Err(format!(
            "ctrl has {} values, expected {} scenes x {nu} actuators = {}",
            ctrl.len(),
            datas.len(),
            datas.len() * nu
        ));
    }
    check(m, datas)?;
    datas.par_iter_mut().enumerate().for_each(|(e, d)| {
        d.ctrl.copy_from_slice(&ctrl[e * nu..(e + 1) * nu]);
        for _ in 0..nsteps {
            step(m, d);
        }
    });
    Ok(())
}
