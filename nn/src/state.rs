//! Saved parameters: a state dictionary of named, shaped tensors, written as JSON with serde
//! (atomically: to a temporary file, then renamed) and checked name by name on load.

use std::path::Path;

use serde::{Deserialize, Serialize};
use tensor::{Float, Tensor};

use crate::atomic::write_atomic;
use crate::error::{NnError, Result};
use crate::params::ParamStore;

/// One saved tensor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SavedTensor {
    /// Dotted parameter name.
    pub name: String,
    /// Shape.
    pub shape: Vec<usize>,
    /// Elements in row-major order (stored as f64: exact for f32 and f64 parameters).
    pub data: Vec<f64>,
}

/// Every parameter of a store, in order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StateDict {
    /// Format version, for future changes.
    pub version: u32,
    /// The tensors.
    pub tensors: Vec<SavedTensor>,
}

impl StateDict {
    /// Current format version.
    pub const VERSION: u32 = 1;

    /// Snapshot of a store, on the host: values on another device come back in one
    /// transfer (`tensor::to_host_all`); an error if that transfer fails.
    pub fn from_store<T: Float>(store: &ParamStore<T>) -> Result<Self> {
        let host = tensor::to_host_all(store.values())?;
        let tensors = store
            .iter()
            .zip(&host)
            .map(|((name, _), v)| SavedTensor {
                name: name.to_string(),
                shape: v.shape().to_vec(),
                data: v.data().iter().map(|x| x.to_f64()).collect(),
            })
            .collect();
        Ok(Self { version: Self::VERSION, tensors })
    }

    /// Copies the saved values into `store`. Every parameter of the store must be present
    /// with the same shape, and the file must hold no other parameter; errors name the
    /// parameter. Nothing is changed unless every check passes.
    pub fn load_into<T: Float>(&self, store: &mut ParamStore<T>) -> Result<()> {
        let mut updates = Vec::with_capacity(store.len());
        for t in &self.tensors {
            if store.find(&t.name).is_none() {
                return Err(NnError::Param {
                    name: t.name.clone(),
                    detail: "is in the saved state but not in the model".into(),
                });
            }
        }
        for (name, value) in store.iter() {
            let saved = self.tensors.iter().find(|t| t.name == name).ok_or_else(|| NnError::Param {
                name: name.to_string(),
                detail: "is missing from the saved state".into(),
            })?;
            if saved.shape != value.shape() {
                return Err(NnError::Param {
                    name: name.to_string(),
                    detail: format!("saved shape {:?} differs from the model's {:?}", saved.shape, value.shape()),
                });
            }
            let n: usize = saved.shape.iter().product();
            if saved.data.len() != n {
                return Err(NnError::Param {
                    name: name.to_string(),
                    detail: format!("{} saved values for shape {:?}", saved.data.len(), saved.shape),
                });
            }
            updates.push(Tensor::new(saved.data.iter().map(|&x| T::from_f64(x)).collect(), &saved.shape)?);
        }
        for (dst, src) in store.values_mut().iter_mut().zip(updates) {
            *dst = src;
        }
        Ok(())
    }

    /// Writes JSON to `path` atomically (temporary file in the same folder, then rename).
    pub fn save(&self, path: &Path) -> Result<()> {
        let text =
            serde_json::to_string(self).map_err(|e| NnError::Format { path: path.into(), detail: e.to_string() })?;
        write_atomic(path, text.as_bytes())
    }

    /// Reads a state written by [`StateDict::save`].
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| NnError::Io { path: path.into(), source: e })?;
        let sd: StateDict = serde_json::from_str(&text)
            .map_err(|e| NnError::Format { path: path.into(), detail: format!("not a saved state ({e})") })?;
        if sd.version != Self::VERSION {
            return Err(NnError::Format {
                path: path.into(),
                detail: format!("format version {} is not supported (expected {})", sd.version, Self::VERSION),
            });
        }
        Ok(sd)
    }
}
