//! Parameters with stable dotted names (`actor.0.weight`).
//!
//! A [`ParamStore`] owns every parameter tensor of a model in creation order. Layers keep
//! [`ParamId`]s. For a forward pass, [`ParamStore::bind`] puts every parameter on a tape as
//! a leaf and returns a [`Bound`] that layers read their [`Var`]s from; after
//! `tape.backward`, [`Bound::grads`] returns the gradients in store order for the optimiser.
//!
//! A store lives on one device ([`ParamStore::to_device`]): bound to a tape, parameters on
//! the GPU stay there, so the forward and backward passes, the gradients and the optimiser
//! step all run on the GPU; the values come back to the host (in one transfer) only when
//! asked for.

use std::collections::HashMap;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tensor::{Device, Float, Gradients, Tape, Tensor, Var};

use crate::error::{NnError, Result};

/// Index of a parameter in its [`ParamStore`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ParamId(pub usize);

/// Named parameter tensors, in creation order.
#[derive(Clone, Debug, Default)]
pub struct ParamStore<T: Float> {
    names: Vec<String>,
    values: Vec<Tensor<T>>,
    index: HashMap<String, usize>,
}

impl<T: Float> ParamStore<T> {
    /// An empty store.
    pub fn new() -> Self {
        Self { names: Vec::new(), values: Vec::new(), index: HashMap::new() }
    }

    /// Adds a parameter; names must be unique.
    pub fn add(&mut self, name: &str, value: Tensor<T>) -> Result<ParamId> {
        if self.index.contains_key(name) {
            return Err(NnError::Param { name: name.into(), detail: "defined twice".into() });
        }
        self.index.insert(name.to_string(), self.values.len());
        self.names.push(name.to_string());
        self.values.push(value);
        Ok(ParamId(self.values.len() - 1))
    }

    /// A naming and initialisation scope rooted at `prefix` ("" for the top level), drawing
    /// initial values from `rng`.
    pub fn scope<'a>(&'a mut self, prefix: &str, rng: &'a mut ChaCha8Rng) -> Scope<'a, T> {
        Scope { store: self, prefix: prefix.to_string(), rng }
    }

    /// Number of parameter tensors.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Whether the store holds no parameter.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Total number of scalar parameters.
    pub fn num_elements(&self) -> usize {
        self.values.iter().map(|v| v.numel()).sum()
    }

    /// Number of scalar parameters whose name starts with `prefix`.
    pub fn num_elements_under(&self, prefix: &str) -> usize {
        self.iter().filter(|(n, _)| n.starts_with(prefix)).map(|(_, v)| v.numel()).sum()
    }

    /// Names in creation order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// `(name, value)` pairs in creation order.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &Tensor<T>)> {
        self.names.iter().map(|s| s.as_str()).zip(self.values.iter())
    }

    /// The value of a parameter.
    pub fn get(&self, id: ParamId) -> &Tensor<T> {
        &self.values[id.0]
    }

    /// The parameter called `name`, if any.
    pub fn find(&self, name: &str) -> Option<ParamId> {
        self.index.get(name).map(|&i| ParamId(i))
    }

    /// The name of a parameter.
    pub fn name(&self, id: ParamId) -> &str {
        &self.names[id.0]
    }

    /// All values, in creation order (for optimisers).
    pub fn values(&self) -> &[Tensor<T>] {
        &self.values
    }

    /// Mutable values, in creation order (for optimisers).
    pub fn values_mut(&mut self) -> &mut [Tensor<T>] {
        &mut self.values
    }

    /// Replaces a parameter's value; the shape must not change.
    pub fn set(&mut self, id: ParamId, value: Tensor<T>) -> Result<()> {
        let old = &self.values[id.0];
        if old.shape() != value.shape() {
            return Err(NnError::Param {
                name: self.names[id.0].clone(),
                detail: format!("new value has shape {:?}, expected {:?}", value.shape(), old.shape()),
            });
        }
        self.values[id.0] = value;
        Ok(())
    }

    /// The device the parameters live on: the GPU if any of them is there (after
    /// [`ParamStore::to_device`] all are), else the CPU (also for an empty store).
    pub fn device(&self) -> Device {
        tensor::device_of_all(&self.values)
    }

    /// Moves every parameter to `device` (names, order and shapes unchanged; nothing to do
    /// for parameters already there): [`tensor::to_device_all`]. To the GPU: each parameter
    /// is uploaded once (f32 stores only; fails without the `gpu` feature or a GPU adapter).
    /// To the CPU: every value comes back in one transfer. Nothing is changed if the move
    /// fails.
    pub fn to_device(&mut self, device: Device) -> Result<()> {
        self.values = tensor::to_device_all(&self.values, device)?;
        Ok(())
    }

    /// Puts every parameter on `tape` as a gradient-wanting leaf.
    pub fn bind<'t>(&self, tape: &'t Tape<T>) -> Bound<'t, T> {
        Bound { vars: self.values.iter().map(|v| tape.var(v.clone())).collect() }
    }
}

/// The parameters of a store placed on one tape.
pub struct Bound<'t, T: Float> {
    vars: Vec<Var<'t, T>>,
}

impl<'t, T: Float> Bound<'t, T> {
    /// Parameters given directly as tape variables, one per store entry in store order
    /// (used by gradient checks, whose inputs are the parameters).
    pub fn from_vars(vars: Vec<Var<'t, T>>) -> Self {
        Self { vars }
    }

    /// The tape variable of a parameter.
    pub fn get(&self, id: ParamId) -> Var<'t, T> {
        self.vars[id.0]
    }

    /// The tape the parameters were bound to.
    pub fn tape(&self) -> &'t Tape<T> {
        self.vars.first().map(|v| v.tape()).expect("bind() of an empty store")
    }

    /// Gradients in store order (zeros for parameters the loss does not use).
    pub fn grads(&self, g: &Gradients<T>) -> Vec<Tensor<T>> {
        self.vars.iter().map(|&v| g.get_or_zeros(v)).collect()
    }
}

/// Where layers create their parameters: a store, a dotted name prefix and a random stream.
pub struct Scope<'a, T: Float> {
    store: &'a mut ParamStore<T>,
    prefix: String,
    rng: &'a mut ChaCha8Rng,
}

impl<T: Float> Scope<'_, T> {
    /// A child scope: names get `name.` prepended after the current prefix.
    pub fn sub(&mut self, name: impl std::fmt::Display) -> Scope<'_, T> {
        let prefix = if self.prefix.is_empty() { name.to_string() } else { format!("{}.{name}", self.prefix) };
        Scope { store: self.store, prefix, rng: self.rng }
    }

    /// The full name a parameter called `name` gets here.
    pub fn full_name(&self, name: &str) -> String {
        if self.prefix.is_empty() { name.to_string() } else { format!("{}.{name}", self.prefix) }
    }

    /// Adds a parameter under this scope.
    pub fn param(&mut self, name: &str, value: Tensor<T>) -> Result<ParamId> {
        let full = self.full_name(name);
        self.store.add(&full, value)
    }

    /// The random stream for initial values.
    pub fn rng(&mut self) -> &mut ChaCha8Rng {
        self.rng
    }
}

/// A seeded random stream for initialisation.
pub fn init_rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}
