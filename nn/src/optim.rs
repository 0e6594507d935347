//! Optimisers and gradient clipping: Adam with PyTorch's semantics, element-wise and
//! global-norm clipping, constant and linear learning-rate schedules.
//!
//! Each works on the device its tensors live on. On the host the arithmetic is the
//! reference (in place; f64 moments, the same code whatever the build). On another device
//! clipping runs there ([`Tensor::map_unary`], [`Tensor::sum_of_squares`]) and Adam's step
//! is the device's ([`tensor::adam_update`], f32 moments as tensors beside the parameters),
//! so an update moves no tensor to the host.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tensor::{AdamStep, Device, Float, Tensor, UnaryOp};

use crate::error::{NnError, Result};
use crate::params::ParamStore;

/// Clips every gradient element to `[-limit, limit]` (optax's `clip(limit)`; the reference
/// release uses 0.1). Gradients on the GPU are clipped there.
pub fn clip_elementwise<T: Float>(grads: &mut [Tensor<T>], limit: f64) {
    let (lo, hi) = (T::from_f64(-limit), T::from_f64(limit));
    for g in grads {
        match g.host_data_mut() {
            Some(values) => values.iter_mut().for_each(|v| *v = v.max(lo).min(hi)),
            None => *g = g.map_unary(UnaryOp::Clamp(-limit, limit)),
        }
    }
}

/// Scales all gradients by `min(1, max_norm / ||g||)` where `||g||` is the norm of all of
/// them together; returns that norm (computed in f64 on the host; for gradients on the GPU
/// each one's sum of squares is taken there in f32 and only that value comes back, and the
/// scaling runs there). A failure of the device makes the norm NaN (and nothing is scaled).
pub fn clip_global_norm<T: Float>(grads: &mut [Tensor<T>], max_norm: f64) -> f64 {
    let sq: f64 = grads.iter().map(|g| g.sum_of_squares().unwrap_or(f64::NAN)).sum();
    let norm = sq.sqrt();
    if norm > max_norm {
        let s = T::from_f64(max_norm / norm);
        for g in grads {
            match g.host_data_mut() {
                Some(values) => values.iter_mut().for_each(|v| *v *= s),
                None => *g = g.map_unary(UnaryOp::Scale(s.to_f64())),
            }
        }
    }
    norm
}

/// A learning rate as a function of the update count.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum LrSchedule {
    /// The same rate throughout.
    Constant(f64),
    /// Linear from `start` to `end` over `steps` updates, then `end`.
    Linear {
        /// Rate at update 0.
        start: f64,
        /// Rate from update `steps` on.
        end: f64,
        /// Length of the ramp.
        steps: u64,
    },
}

impl LrSchedule {
    /// The rate for update number `t` (0-based).
    pub fn at(&self, t: u64) -> f64 {
        match *self {
            LrSchedule::Constant(lr) => lr,
            LrSchedule::Linear { start, end, steps } => {
                if steps == 0 || t >= steps {
                    end
                } else {
                    start + (end - start) * t as f64 / steps as f64
                }
            }
        }
    }
}

/// Adam's hyper-parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdamConfig {
    /// Learning rate schedule.
    pub lr: LrSchedule,
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// Added to the root of the second moment.
    pub eps: f64,
}

impl Default for AdamConfig {
    /// lr 3e-4, betas (0.9, 0.999), eps 1e-8: the reference release's values.
    fn default() -> Self {
        Self { lr: LrSchedule::Constant(3e-4), beta1: 0.9, beta2: 0.999, eps: 1e-8 }
    }
}

/// Adam (Kingma & Ba) exactly as `torch.optim.Adam` without weight decay:
/// `m <- b1 m + (1-b1) g`, `v <- b2 v + (1-b2) g^2`,
/// `p <- p - lr (m / (1 - b1^t)) / (sqrt(v / (1 - b2^t)) + eps)`.
///
/// **Devices.** On the host the moments are f64 vectors (what a checkpoint holds, and what
/// an exact resume needs). When the parameters or gradients of a [`Adam::step`] are on
/// another device, the step runs there ([`tensor::adam_update`]) with the moments as f32
/// tensors beside the parameters (placed there from the host ones at the first such step,
/// or by [`Adam::to_device`]): **device Adam keeps its moments in f32**, whatever the
/// parameter precision, so its steps differ from the host's by f32 rounding. While the
/// moments are placed there the host vectors are stale: [`Adam::sync_to_host`] copies them
/// back (one transfer) before the state is saved, and the host vectors are what serialises,
/// so a checkpoint has the same format whichever device wrote it. A host step after device
/// steps brings the moments back first.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Adam {
    /// Hyper-parameters.
    pub config: AdamConfig,
    /// Number of updates done.
    pub t: u64,
    /// First moments, one per parameter (store order). Moments are kept in f64 whatever the
    /// parameter precision: the same formula as PyTorch, with less rounding.
    m: Vec<Vec<f64>>,
    /// Second moments.
    v: Vec<Vec<f64>>,
    /// The first moments on the parameters' device (f32, one `[n]` tensor per parameter)
    /// while steps there use them; empty otherwise. Never saved: [`Adam::sync_to_host`]
    /// copies them into `m`.
    #[serde(skip)]
    device_m: Vec<Tensor<f32>>,
    /// The second moments on the parameters' device, like `device_m`.
    #[serde(skip)]
    device_v: Vec<Tensor<f32>>,
}

impl Adam {
    /// Zero moments for every parameter of `store`.
    pub fn new<T: Float>(config: AdamConfig, store: &ParamStore<T>) -> Self {
        let zeros: Vec<Vec<f64>> = store.values().iter().map(|v| vec![0.0; v.numel()]).collect();
        Self { config, t: 0, m: zeros.clone(), v: zeros, device_m: Vec::new(), device_v: Vec::new() }
    }

    /// Where the moments live: the parameters' device while steps there use them, else the
    /// host.
    pub fn device(&self) -> Device {
        tensor::device_of_all(&self.device_m)
    }

    /// Moves the moments to `device`. To another device than the host: the host moments are
    /// placed there as f32 (on resuming a run there; [`Adam::step`] does it by itself at the
    /// first step there). To the host: the placed moments are copied back
    /// ([`Adam::sync_to_host`]) and dropped.
    pub fn to_device(&mut self, device: Device) -> Result<()> {
        if device == self.device() {
            return Ok(());
        }
        self.sync_to_host()?;
        self.device_m.clear();
        self.device_v.clear();
        if !device.is_host() {
            let place = |bufs: &[Vec<f64>]| -> Result<Vec<Tensor<f32>>> {
                bufs.iter()
                    .map(|b| Ok(Tensor::new(b.iter().map(|&x| x as f32).collect(), &[b.len()])?.to_device(device)?))
                    .collect()
            };
            let (m, v) = (place(&self.m)?, place(&self.v)?);
            self.device_m = m;
            self.device_v = v;
        }
        Ok(())
    }

    /// Copies the moments on the GPU, if any, into the host's f64 vectors (all of them in
    /// one transfer; exact: f32 values are f64 values), keeping the GPU copy: call it before
    /// saving the state. Nothing to do when the moments are on the host.
    pub fn sync_to_host(&mut self) -> Result<()> {
        if self.device_m.is_empty() {
            return Ok(());
        }
        let all: Vec<Tensor<f32>> = self.device_m.iter().chain(&self.device_v).cloned().collect();
        let host = tensor::to_host_all(&all)?;
        let (m, v) = host.split_at(self.device_m.len());
        for (dst, src) in self.m.iter_mut().zip(m).chain(self.v.iter_mut().zip(v)) {
            *dst = src.data().iter().map(|&x| x as f64).collect();
        }
        Ok(())
    }

    /// The host moments: first and second, one buffer per parameter in store order (stale
    /// while the moments are on the GPU: [`Adam::sync_to_host`] first). What a checkpoint
    /// saves besides the configuration and the update count.
    pub fn moments(&self) -> (&[Vec<f64>], &[Vec<f64>]) {
        (&self.m, &self.v)
    }

    /// An optimiser restored from saved parts: its configuration, update count and host
    /// moments ([`Adam::moments`]). Nothing is checked here: [`Adam::check_fits`] checks the
    /// moments against a store.
    pub fn from_moments(config: AdamConfig, t: u64, m: Vec<Vec<f64>>, v: Vec<Vec<f64>>) -> Self {
        Self { config, t, m, v, device_m: Vec::new(), device_v: Vec::new() }
    }

    /// Checks a loaded state against `store`: one first and one second moment buffer per
    /// parameter, each with the parameter's number of elements, all finite. Errors name the
    /// parameter.
    pub fn check_fits<T: Float>(&self, store: &ParamStore<T>) -> Result<()> {
        if self.m.len() != store.len() || self.v.len() != store.len() {
            return Err(NnError::Config(format!(
                "Adam: {} first and {} second moment buffers for {} parameters",
                self.m.len(),
                self.v.len(),
                store.len()
            )));
        }
        for (i, value) in store.values().iter().enumerate() {
            for (moment, buf) in [("first", &self.m[i]), ("second", &self.v[i])] {
                if buf.len() != value.numel() {
                    return Err(NnError::Param {
                        name: store.names()[i].clone(),
                        detail: format!(
                            "the saved Adam {moment} moment has {} elements for a parameter of {}",
                            buf.len(),
                            value.numel()
                        ),
                    });
                }
            }
        }
        match self.non_finite() {
            Some((i, moment)) => Err(NnError::Param {
                name: store.names()[i].clone(),
                detail: format!("the saved Adam {moment} moment is not finite"),
            }),
            None => Ok(()),
        }
    }

    /// The first moment buffer holding a NaN or an infinity: its parameter's index (store
    /// order) and which moment (`first` or `second`).
    pub fn non_finite(&self) -> Option<(usize, &'static str)> {
        let bad = |b: &Vec<f64>| !b.iter().all(|x| x.is_finite());
        (0..self.m.len().max(self.v.len())).find_map(|i| {
            if self.m.get(i).is_some_and(bad) {
                Some((i, "first"))
            } else if self.v.get(i).is_some_and(bad) {
                Some((i, "second"))
            } else {
                None
            }
        })
    }

    /// The learning rate the next update will use.
    pub fn current_lr(&self) -> f64 {
        self.config.lr.at(self.t)
    }

    /// One update of every parameter with `grads` (store order, same shapes). When a
    /// parameter or a gradient is on the GPU, the whole step runs there with f32 moments
    /// (type docs) and the parameters end up on the GPU.
    pub fn step<T: Float>(&mut self, store: &mut ParamStore<T>, grads: &[Tensor<T>]) -> Result<()> {
        self.step_with(store, grads, None)
    }

    /// [`Adam::step`] with every gradient element first clipped to `[-limit, limit]`: the
    /// same values as [`clip_elementwise`] then [`Adam::step`], bit for bit, without writing
    /// the clipped gradients anywhere (on the GPU the clip runs inside the Adam kernel: one
    /// launch per parameter instead of two).
    pub fn step_clipped<T: Float>(&mut self, store: &mut ParamStore<T>, grads: &[Tensor<T>], limit: f64) -> Result<()> {
        self.step_with(store, grads, Some(limit))
    }

    /// [`Adam::step`], clipping the gradients' elements to `[-limit, limit]` when given.
    fn step_with<T: Float>(&mut self, store: &mut ParamStore<T>, grads: &[Tensor<T>], clip: Option<f64>) -> Result<()> {
        if grads.len() != store.len() || self.m.len() != store.len() {
            return Err(NnError::Config(format!(
                "Adam: {} gradients and {} moment buffers for {} parameters",
                grads.len(),
                self.m.len(),
                store.len()
            )));
        }
        for (i, (g, m)) in grads.iter().zip(&self.m).enumerate() {
            if g.numel() != m.len() {
                return Err(NnError::Param {
                    name: store.names()[i].clone(),
                    detail: format!("gradient has {} elements, the parameter {}", g.numel(), m.len()),
                });
            }
        }
        let lr = self.current_lr();
        self.t += 1;
        let t = self.t as i32;
        let (b1, b2, eps) = (self.config.beta1, self.config.beta2, self.config.eps);
        let c1 = 1.0 / (1.0 - b1.powi(t));
        let c2 = 1.0 / (1.0 - b2.powi(t));
        let device = tensor::device_of_all(store.values().iter().chain(grads));
        if !device.is_host() {
            let step = AdamStep { lr, beta1: b1, beta2: b2, c1, c2, eps, clip };
            return self.step_on_device(store, grads, device, step);
        }
        // The moments may have been last updated on another device.
        self.to_device(device)?;
        let bounds = clip.map(|limit| (T::from_f64(-limit), T::from_f64(limit)));
        let values = store.values_mut();
        values.par_iter_mut().zip(grads.par_iter()).zip(self.m.par_iter_mut().zip(self.v.par_iter_mut())).for_each(
            |((p, g), (m, v))| {
                for (((pv, &gv), mv), vv) in p.data_mut().iter_mut().zip(g.data()).zip(m.iter_mut()).zip(v.iter_mut()) {
                    // clip_elementwise's rule, in the gradient's precision.
                    let gv = match bounds {
                        Some((lo, hi)) => gv.max(lo).min(hi),
                        None => gv,
                    };
                    let gv = gv.to_f64();
                    *mv = b1 * *mv + (1.0 - b1) * gv;
                    *vv = b2 * *vv + (1.0 - b2) * gv * gv;
                    let upd = lr * (*mv * c1) / ((*vv * c2).sqrt() + eps);
                    *pv = T::from_f64(pv.to_f64() - upd);
                }
            },
        );
        Ok(())
    }

    /// [`Adam::step`] on `device`, other than the host (counts and shapes already checked,
    /// `t` advanced): the device's step with the placed f32 moments.
    fn step_on_device<T: Float>(
        &mut self,
        store: &mut ParamStore<T>,
        grads: &[Tensor<T>],
        device: Device,
        step: AdamStep,
    ) -> Result<()> {
        self.to_device(device)?;
        let values = store.values_mut();
        for (i, (p, g)) in values.iter_mut().zip(grads).enumerate() {
            let p_there = p.to_device(device)?;
            let (p1, m1, v1) = tensor::adam_update(&p_there, g, &self.device_m[i], &self.device_v[i], step)?;
            *p = p1;
            self.device_m[i] = m1;
            self.device_v[i] = v1;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn store() -> ParamStore<f32> {
        let mut s = ParamStore::new();
        s.add("a.weight", Tensor::zeros(&[2, 3])).unwrap();
        s.add("b.bias", Tensor::zeros(&[4])).unwrap();
        s
    }

    #[test]
    fn loaded_moments_must_fit_the_store_and_be_finite() {
        let store = store();
        let adam = Adam::new(AdamConfig::default(), &store);
        adam.check_fits(&store).unwrap();
        assert_eq!(adam.non_finite(), None);

        let mut short = adam.clone();
        short.v[1].pop();
        let e = short.check_fits(&store).unwrap_err().to_string();
        assert!(e.contains("b.bias") && e.contains("second moment has 3 elements"), "{e}");

        let mut fewer = adam.clone();
        fewer.m.pop();
        let e = fewer.check_fits(&store).unwrap_err().to_string();
        assert!(e.contains("1 first and 2 second"), "{e}");

        let mut nan = adam;
        nan.m[0][4] = f64::NAN;
        assert_eq!(nan.non_finite(), Some((0, "first")));
        let e = nan.check_fits(&store).unwrap_err().to_string();
        assert!(e.contains("a.weight") && e.contains("not finite"), "{e}");
    }
}
