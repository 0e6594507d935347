//! The tape: a flat, append-only list of nodes, one per operation, in the order they ran.
//!
//! A [`Var`] is a cheap handle (tape reference + position). Because a node can only read
//! nodes recorded before it, walking the list backwards visits every node after all of its
//! consumers: reverse-mode differentiation needs no graph sort and no reference counting.
//! Gradient rules live in `backprop.rs`.

use std::cell::{Cell, Ref, RefCell};
use std::collections::HashMap;
use std::time::{Duration, Instant};

use crate::backprop::{GradStore, propagate};
use crate::element::Float;
use crate::error::{Result, TensorError, invalid};
use crate::flops::{self, FlopCount, OpFlops};
use crate::op::{NodeId, Op};
use crate::tensor::Tensor;

/// One recorded value with the operation that produced it.
pub(crate) struct Node<T: Float> {
    pub(crate) value: Tensor<T>,
    pub(crate) op: Op,
    pub(crate) requires_grad: bool,
}

/// A recording of operations for reverse-mode differentiation.
///
/// Create one per forward pass; it owns every intermediate value until dropped.
pub struct Tape<T: Float> {
    nodes: RefCell<Vec<Node<T>>>,
    device: crate::device::Device,
    grad_enabled: Cell<bool>,
    profile: RefCell<Option<Profile>>,
    /// Why the first leaf that could not be placed on the tape's device stayed on the host.
    misplaced: RefCell<Option<String>>,
}

/// Time and flops per op, forward and backward (see [`Tape::enable_profiling`]).
#[derive(Default)]
struct Profile {
    forward: HashMap<String, OpStats>,
    backward: HashMap<String, OpStats>,
    last: Option<Instant>,
    /// Whether products are told apart by their operand shapes.
    by_shape: bool,
}

/// What the profile records about one op name in one direction.
#[derive(Clone, Copy, Default)]
struct OpStats {
    calls: u64,
    time: Duration,
    flops: OpFlops,
}

impl OpStats {
    fn add(&mut self, time: Duration, flops: OpFlops) {
        self.calls += 1;
        self.time += time;
        self.flops += flops;
    }
}

/// The profile's row for `op` (output shape `out`): its name, and with `by_shape` the operand
/// shapes of a product (a transposed operand marked `^T`) or the output shape of other ops.
fn profile_key<T: Float>(nodes: &[Node<T>], op: &Op, out: &[usize], by_shape: bool) -> String {
    let shape = |id: NodeId, t: bool| format!("{:?}{}", nodes[id].value.shape(), if t { "^T" } else { "" });
    match op {
        _ if !by_shape => op.name().to_string(),
        Op::Linear { parts, col, .. } => {
            let n = out.last().copied().unwrap_or(0);
            let terms: Vec<String> = parts
                .iter()
                .map(|t| {
                    let (k, w) = (nodes[t.x].value.shape().last().copied().unwrap_or(0), &nodes[t.w].value);
                    let whole = t.row == 0 && w.shape()[0] == k && *col == 0 && w.shape()[1] == n;
                    let block =
                        if whole { String::new() } else { format!("[{}..{}, {col}..{}]", t.row, t.row + k, col + n) };
                    format!("{}x{}{block}", shape(t.x, false), shape(t.w, false))
                })
                .collect();
            format!("linear {}", terms.join(" + "))
        }
        Op::MatMul { a, b, ta, tb } => format!("matmul {}x{}", shape(*a, *ta), shape(*b, *tb)),
        _ => format!("{} {out:?}", op.name()),
    }
}

impl Profile {
    /// Flops summed over op names.
    fn flops(&self) -> FlopCount {
        let sum = |t: &HashMap<String, OpStats>| {
            t.values().fold(OpFlops::default(), |mut acc, s| {
                acc += s.flops;
                acc
            })
        };
        let (f, b) = (sum(&self.forward), sum(&self.backward));
        FlopCount {
            matmul_forward: f.matmul,
            matmul_backward: b.matmul,
            other_forward: f.other,
            other_backward: b.other,
        }
    }
}

impl<T: Float> Default for Tape<T> {
    fn default() -> Self {
        Self::new()
    }
}

/// Restores gradient recording when dropped; see [`Tape::no_grad`].
pub struct NoGradGuard<'t, T: Float> {
    tape: &'t Tape<T>,
    previous: bool,
}

impl<T: Float> Drop for NoGradGuard<'_, T> {
    fn drop(&mut self) {
        self.tape.grad_enabled.set(self.previous);
    }
}

impl<T: Float> Tape<T> {
    /// An empty tape with gradient recording on.
    pub fn new() -> Self {
        Self::on(crate::device::Device::Cpu)
    }

    /// An empty tape whose leaves ([`Tape::var`], [`Tape::constant`]) are placed on `device`
    /// when they are recorded: a host tensor given to a GPU tape is uploaded once there, so
    /// every op of the forward and backward pass runs on the GPU. (On any tape an op runs on
    /// the GPU when one of its inputs is there.) An upload that fails (no GPU adapter, an
    /// `f64` tape, a tensor too large for a device buffer) leaves the leaf on the host, where
    /// its ops would run unnoticed: [`Tape::backward`] then refuses with the upload's error,
    /// and [`Tape::misplaced`] says it at any time.
    pub fn on(device: crate::device::Device) -> Self {
        Self {
            nodes: RefCell::new(Vec::new()),
            device,
            grad_enabled: Cell::new(true),
            profile: RefCell::new(None),
            misplaced: RefCell::new(None),
        }
    }

    /// Why a leaf of this tape stayed on the host instead of its device (the first such
    /// upload's error), if one did.
    pub fn misplaced(&self) -> Option<String> {
        self.misplaced.borrow().clone()
    }

    /// The device this tape places its leaves on.
    pub fn device(&self) -> crate::device::Device {
        self.device
    }

    /// `value` on the tape's device if that is the GPU (a CPU tape leaves tensors where they
    /// are: a GPU tensor on it is computed on the GPU).
    fn place(&self, value: Tensor<T>) -> Tensor<T> {
        if value.device() == self.device || self.device == crate::device::Device::Cpu {
            return value;
        }
        match value.to_device(self.device) {
            Ok(v) => v,
            Err(e) => {
                self.misplaced.borrow_mut().get_or_insert_with(|| e.to_string());
                value
            }
        }
    }

    /// Starts recording the wall time and the floating-point operations of every op:
    /// forward time is the time since the previous node was recorded (so it includes any
    /// caller code in between), backward time is that of the op's gradient rule. Flops are
    /// counted by the conventions of [`crate::flops`]: `2 m n k` per matrix product, one per
    /// element of other arithmetic. Read them with
    /// [`Tape::profile_report`] and [`Tape::profile_flops`]. Without this call nothing is
    /// timed or counted.
    pub fn enable_profiling(&self) {
        *self.profile.borrow_mut() = Some(Profile { last: Some(Instant::now()), ..Profile::default() });
    }

    /// [`Tape::enable_profiling`], with ops reported per shape: products (`linear`, `matmul`)
    /// by operand shapes (`linear [5120, 1153]x[1153, 64]`), other ops by output shape (`add
    /// [10240, 64]`). It tells which calls are slow, not only which kind of op.
    pub fn enable_profiling_by_shape(&self) {
        *self.profile.borrow_mut() = Some(Profile { last: Some(Instant::now()), by_shape: true, ..Profile::default() });
    }

    /// Floating-point operations recorded since [`Tape::enable_profiling`] (forward ops
    /// recorded and gradient rules run), or `None` if profiling is off.
    pub fn profile_flops(&self) -> Option<FlopCount> {
        self.profile.borrow().as_ref().map(Profile::flops)
    }

    /// A table per direction (forward, then backward; slowest op first) of calls, time,
    /// millions of flops and the achieved GFLOP/s of each op, if profiling is on. Forward
    /// times include caller code between ops, so forward rates are lower bounds.
    pub fn profile_report(&self) -> Option<String> {
        let prof = self.profile.borrow();
        let prof = prof.as_ref()?;
        let mut out = String::new();
        for (title, table) in [("forward", &prof.forward), ("backward", &prof.backward)] {
            let mut rows: Vec<_> = table.iter().collect();
            rows.sort_by(|a, b| b.1.time.cmp(&a.1.time).then(a.0.cmp(b.0)));
            let total: Duration = rows.iter().map(|r| r.1.time).sum();
            let flops: u64 = rows.iter().map(|r| r.1.flops.matmul + r.1.flops.other).sum();
            let mm: u64 = rows.iter().map(|r| r.1.flops.matmul).sum();
            out.push_str(&format!(
                "{title}: {:.2} ms, {:.3} GFLOP ({:.3} in matmuls), {}\n",
                total.as_secs_f64() * 1e3,
                flops as f64 * 1e-9,
                mm as f64 * 1e-9,
                rate(flops, total),
            ));
            for (name, s) in rows {
                let f = s.flops.matmul + s.flops.other;
                out.push_str(&format!(
                    "  {name:<14} {:>6} calls {:>10.3} ms {:>12.3} MFLOP {:>14}\n",
                    s.calls,
                    s.time.as_secs_f64() * 1e3,
                    f as f64 * 1e-6,
                    rate(f, s.time),
                ));
            }
        }
        Some(out)
    }

    /// Number of recorded nodes.
    pub fn len(&self) -> usize {
        self.nodes.borrow().len()
    }

    /// Whether nothing has been recorded.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// A leaf whose gradient [`Tape::backward`] will report (a parameter or an input of a
    /// gradient check). Inside a no-grad scope it is a constant.
    pub fn var(&self, value: Tensor<T>) -> Var<'_, T> {
        self.push(self.place(value), Op::Leaf, self.grad_enabled.get())
    }

    /// A leaf that never receives a gradient.
    pub fn constant(&self, value: Tensor<T>) -> Var<'_, T> {
        self.push(self.place(value), Op::Leaf, false)
    }

    /// The Gaussian radial basis `exp(coeff (x_e - c_k)^2)` of the host values `x` and
    /// `centres`, `[E, K]`, as a constant of this tape, computed on the tape's device: the CPU
    /// in f64 (then rounded once to `T`), the GPU in f32 from the `E` values uploaded, so a
    /// basis of `E K` entries costs an upload of `E` (the critic's edge features,
    /// `models::critic`). An error where the device cannot hold `T` (f64 on the GPU).
    pub fn gaussian_basis(&self, x: &[f64], centres: &[f64], coeff: f64) -> Result<Var<'_, T>> {
        let basis = crate::dispatch::gaussian_basis(self.device, x, centres, coeff)?;
        Ok(self.constant(basis))
    }

    /// Turns gradient recording off until the returned guard is dropped: values computed in
    /// the scope are constants.
    pub fn no_grad(&self) -> NoGradGuard<'_, T> {
        let previous = self.grad_enabled.replace(false);
        NoGradGuard { tape: self, previous }
    }

    /// Whether operations are currently recorded for differentiation.
    pub fn grad_enabled(&self) -> bool {
        self.grad_enabled.get()
    }

    /// Appends a node; its gradient is wanted if `requires_grad` and recording is on.
    pub(crate) fn push(&self, value: Tensor<T>, op: Op, requires_grad: bool) -> Var<'_, T> {
        let requires_grad = requires_grad && self.grad_enabled.get();
        if let Some(prof) = self.profile.borrow_mut().as_mut() {
            // On the GPU an op only queues its kernels: wait for them, so the time is theirs
            // (the output's device: a CPU tape runs an op on the GPU when an input is there).
            value.device().synchronize();
            let now = Instant::now();
            let f = flops::forward(&self.nodes.borrow(), &op, value.shape());
            let key = profile_key(&self.nodes.borrow(), &op, value.shape(), prof.by_shape);
            prof.forward.entry(key).or_default().add(now - prof.last.unwrap_or(now), f);
            prof.last = Some(now);
        }
        // A leaf launches nothing: launches still unlabelled when one is recorded were made
        // outside the tape (the last step's clipping and Adam) and keep no op's name.
        label_gpu_launches(if matches!(op, Op::Leaf) { None } else { Some((op.name(), false)) });
        let op = if requires_grad { op } else { Op::Leaf };
        let mut nodes = self.nodes.borrow_mut();
        nodes.push(Node { value, op, requires_grad });
        Var { tape: self, id: nodes.len() - 1 }
    }

    /// Records the result of an op whose inputs are `inputs`.
    pub(crate) fn record(&self, value: Tensor<T>, op: Op, inputs: &[NodeId]) -> Var<'_, T> {
        let rg = {
            let nodes = self.nodes.borrow();
            inputs.iter().any(|&i| nodes[i].requires_grad)
        };
        self.push(value, op, rg)
    }

    /// The value of node `id` (shares storage).
    pub(crate) fn value(&self, id: NodeId) -> Tensor<T> {
        self.nodes.borrow()[id].value.clone()
    }

    /// Reverse-mode differentiation of the scalar `loss` with respect to every leaf created
    /// with [`Tape::var`] that it depends on.
    pub fn backward(&self, loss: Var<'_, T>) -> Result<Gradients<T>> {
        self.check_same(loss);
        if let Some(why) = self.misplaced() {
            return Err(TensorError::Device {
                op: "backward",
                detail: format!("a leaf of this {} tape stayed on the host, so its ops ran there: {why}", self.device),
            });
        }
        let nodes: Ref<'_, Vec<Node<T>>> = self.nodes.borrow();
        let root = &nodes[loss.id];
        if root.value.numel() != 1 {
            return Err(invalid(
                "backward",
                format!("the loss must be a single value, got shape {:?}", root.value.shape()),
            ));
        }
        let mut store = GradStore::new(&nodes[..=loss.id]);
        if root.requires_grad {
            let seed = Tensor::ones(root.value.shape()).to_device(root.value.device())?;
            store.add(loss.id, seed)?;
        }
        for id in (0..=loss.id).rev() {
            if matches!(nodes[id].op, Op::Leaf) {
                continue;
            }
            if let Some(g) = store.take(id) {
                let start = Instant::now();
                propagate(&nodes, id, g, &mut store)?;
                label_gpu_launches(Some((nodes[id].op.name(), true)));
                if let Some(prof) = self.profile.borrow_mut().as_mut() {
                    nodes[id].value.device().synchronize();
                    let elapsed = start.elapsed();
                    let f = flops::backward(&nodes, id);
                    let key = profile_key(&nodes, &nodes[id].op, nodes[id].value.shape(), prof.by_shape);
                    prof.backward.entry(key).or_default().add(elapsed, f);
                }
            }
        }
        Ok(Gradients { grads: store.into_leaf_grads(&nodes[..=loss.id]) })
    }

    /// Asserts that `v` belongs to this tape (mixing tapes is a programming error).
    pub(crate) fn check_same(&self, v: Var<'_, T>) {
        assert!(std::ptr::eq(self, v.tape), "a Var from another tape was used");
    }
}

/// While the GPU times its launches ([`crate::gpu::Gpu::start_timing`]), gives the launches
/// of the op just run its name and direction (`None`: no op's, shown as `-`); nothing
/// otherwise (or without the `gpu` feature).
fn label_gpu_launches(op: Option<(&'static str, bool)>) {
    crate::gpu::label_launches(op);
}

/// `flops / time` as "12.34 GFLOP/s", or "-" when either is zero.
fn rate(flops: u64, time: Duration) -> String {
    let secs = time.as_secs_f64();
    if flops == 0 || secs == 0.0 { "-".to_owned() } else { format!("{:.2} GFLOP/s", flops as f64 * 1e-9 / secs) }
}

/// Gradients of the leaves of one backward pass, indexed by [`Var`].
#[derive(Debug)]
pub struct Gradients<T: Float> {
    grads: Vec<Option<Tensor<T>>>,
}

impl<T: Float> Gradients<T> {
    /// The gradient of a leaf, or `None` if the loss does not depend on it (or it is a
    /// constant).
    pub fn get(&self, v: Var<'_, T>) -> Option<&Tensor<T>> {
        self.grads.get(v.id).and_then(|g| g.as_ref())
    }

    /// The gradient of a leaf, or zeros shaped like it, on its device, when the loss does not
    /// depend on it.
    pub fn get_or_zeros(&self, v: Var<'_, T>) -> Tensor<T> {
        self.get(v).cloned().unwrap_or_else(|| crate::dispatch::zeros(v.value().device(), v.shape().as_slice()))
    }
}

/// A value on a tape: a handle that is `Copy` and cheap to pass around.
#[derive(Clone, Copy)]
pub struct Var<'t, T: Float> {
    pub(crate) tape: &'t Tape<T>,
    pub(crate) id: NodeId,
}

impl<'t, T: Float> Var<'t, T> {
    /// The tape this value lives on.
    pub fn tape(&self) -> &'t Tape<T> {
        self.tape
    }

    /// Position on the tape.
    pub fn id(&self) -> NodeId {
        self.id
    }

    /// The value (shares storage, no copy).
    pub fn value(&self) -> Tensor<T> {
        self.tape.value(self.id)
    }

    /// The shape.
    pub fn shape(&self) -> Vec<usize> {
        self.tape.nodes.borrow()[self.id].value.shape().to_vec()
    }

    /// The number of dimensions.
    pub fn rank(&self) -> usize {
        self.tape.nodes.borrow()[self.id].value.rank()
    }

    /// Whether a gradient flows back through this value.
    pub fn requires_grad(&self) -> bool {
        self.tape.nodes.borrow()[self.id].requires_grad
    }

    /// The same value as a constant: no gradient flows back through the result.
    pub fn detach(&self) -> Var<'t, T> {
        self.tape.constant(self.value())
    }
}

impl<T: Float> std::fmt::Debug for Var<'_, T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Var#{} {:?}", self.id, self.value())
    }
}
