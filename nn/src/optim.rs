//! Optimisers and gradient clipping: Adam with PyTorch's semantics, element-wise and
//! global-norm clipping, constant and linear learning-rate schedules.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tensor::{Float, Tensor};

use crate::error::{NnError, Result};
use crate::params::ParamStore;

/// Clips every gradient element to `[-limit, limit]` (optax's `clip(limit)`; the reference
/// release uses 0.1).
pub fn clip_elementwise<T: Float>(grads: &mut [Tensor<T>], limit: f64) {
    let (lo, hi) = (T::from_f64(-limit), T::from_f64(limit));
    for g in grads {
        g.data_mut().iter_mut().for_each(|v| *v = v.max(lo).min(hi));
    }
}

/// Scales all gradients by `min(1, max_norm / ||g||)` where `||g||` is the norm of all of
/// them together; returns that norm (computed in f64).
pub fn clip_global_norm<T: Float>(grads: &mut [Tensor<T>], max_norm: f64) -> f64 {
    let sq: f64 = grads.iter().map(|g| g.data().iter().map(|v| v.to_f64() * v.to_f64()).sum::<f64>()).sum();
    let norm = sq.sqrt();
    if norm > max_norm {
        let s = T::from_f64(max_norm / norm);
        for g in grads {
            g.data_mut().iter_mut().for_each(|v| *v *= s);
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
}

impl Adam {
    /// Zero moments for every parameter of `store`.
    pub fn new<T: Float>(config: AdamConfig, store: &ParamStore<T>) -> Self {
        let zeros: Vec<Vec<f64>> = store.values().iter().map(|v| vec![0.0; v.numel()]).collect();
        Self { config, t: 0, m: zeros.clone(), v: zeros }
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

    /// One update of every parameter with `grads` (store order, same shapes).
    pub fn step<T: Float>(&mut self, store: &mut ParamStore<T>, grads: &[Tensor<T>]) -> Result<()> {
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
        let values = store.values_mut();
        values.par_iter_mut().zip(grads.par_iter()).zip(self.m.par_iter_mut().zip(self.v.par_iter_mut())).for_each(
            |((p, g), (m, v))| {
                for (((pv, &gv), mv), vv) in p.data_mut().iter_mut().zip(g.data()).zip(m.iter_mut()).zip(v.iter_mut()) {
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
