//! The device layer: what a device must provide ([`Backend`]), where a tensor's storage is
//! matched to its device (the one `match`, [`on_backend!`]), and the implementations: the CPU
//! ([`cpu::Cpu`], kernels in `kernels/`) and the GPU (`crate::gpu::backend::Gpu`, feature
//! `gpu`, kernels in `gpu/ops/` and `gpu/wgsl/`).
//!
//! The layers above never name a device: `dispatch.rs` checks an op's shapes once and hands the
//! operands to the backend their storage belongs to; the gradient rules (`backprop.rs`) are
//! written over `dispatch.rs`; the gradient store (`grad_store.rs`) accumulates through the
//! backend's in-place primitives. A third device is a third implementation of [`Backend`],
//! a variant of `Storage` and an arm of [`on_backend!`], and nothing else.
//!
//! Every method receives operands that already live on its device (`dispatch.rs` checks it) and
//! shapes that are already checked; it returns its output on the same device.

pub(crate) mod cpu;

use std::sync::Arc;

use crate::element::Float;
use crate::error::Result;
use crate::kernels::matmul::MatMulPlan;
use crate::kernels::nnops::WeightRows;
use crate::op::{Activation, BinaryOp, ReduceOp, UnaryOp};
use crate::tensor::Tensor;

/// The gradients of a binary op's two operands, each present when wanted.
pub(crate) type GradPair<T> = (Option<Tensor<T>>, Option<Tensor<T>>);

/// A matrix inside a row-major buffer: it starts at element `start` and its stored rows are
/// `ld` elements apart (a block of rows and columns of a weight `[in, ld]`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Block {
    /// The first element.
    pub start: usize,
    /// The elements between stored rows.
    pub ld: usize,
}

/// A node's gradient buffer while a backward pass accumulates into it: a flat tensor on the
/// device of the contributions (`None` before the first one). The store owns it; a backend
/// writes it in place where it is not shared, and copies it first where it is.
pub(crate) type Slot<T> = Option<Tensor<T>>;

/// The primitive operations of one device. The CPU's are the reference; another device's
/// kernels compute the same values (the same bits where the tests say so; `docs/TENSOR.md`).
pub(crate) trait Backend {
    // --- Element-wise ---------------------------------------------------------------------

    /// `op(x)` element by element.
    fn unary<T: Float>(x: &Tensor<T>, op: UnaryOp) -> Tensor<T>;

    /// `g * op'(x)` (through the output `y` where cheaper): one fused kernel, where the
    /// derivative as tensor arithmetic would be two to five launches and passes over memory.
    /// Against the arithmetic on the CPU: tanh 3.0-3.9x, sigmoid 1.9-2.3x, sqrt 1.09-1.14x
    /// faster; softplus 0.91-0.98x (its exponential is the cost either way: kept for the
    /// GPU's one launch where the arithmetic takes two) (`cargo bench -p tensor --bench fused_backward`: CPU, one thread, paper-size operands, two runs).
    fn unary_backward<T: Float>(g: &Tensor<T>, x: &Tensor<T>, y: &Tensor<T>, op: UnaryOp) -> Tensor<T>;

    /// `g * act'` of a layer's activation through its output `y` (`relu' = [y > 0]`,
    /// `tanh' = 1 - y^2`): the layers' most frequent gradient, a kernel of its own on the
    /// CPU (through the generic derivative it took 2.71% of an `mlp_hn` training's samples
    /// against 0.75%, `perf record`, `team_reach/2_ants`, one thread).
    fn activation_backward<T: Float>(y: &Tensor<T>, g: &Tensor<T>, act: Activation) -> Tensor<T>;

    /// `op(a, b)` broadcast to `shape` (checked).
    fn binary<T: Float>(a: &Tensor<T>, b: &Tensor<T>, shape: &[usize], op: BinaryOp) -> Result<Tensor<T>>;

    /// The gradients of `y = op(a, b)` for mul, div, minimum and maximum, summed back to the
    /// operands' shapes: both in one fused kernel (each written as arithmetic would be a
    /// product, a division and a comparison per operand). Against the arithmetic on the CPU:
    /// div 1.71-1.74x and a block divided by one value a row 1.71-1.87x faster; mul 0.79-0.88x
    /// (two passes either way on the CPU: its win is the GPU's one launch for both gradients
    /// where the arithmetic takes two) (`cargo bench -p tensor --bench fused_backward`: CPU, one thread, paper-size operands, two runs).
    fn binary_backward<T: Float>(
        g: &Tensor<T>,
        a: &Tensor<T>,
        b: &Tensor<T>,
        y: &Tensor<T>,
        op: BinaryOp,
        wants: (bool, bool),
    ) -> Result<GradPair<T>>;

    /// `mask ? a : b` over the broadcast `shape`.
    fn where_select<T: Float>(
        mask: &Arc<Vec<bool>>,
        shape: &[usize],
        a: &Tensor<T>,
        b: &Tensor<T>,
    ) -> Result<Tensor<T>>;

    // --- Reductions -----------------------------------------------------------------------

    /// A reduction over `axis` (or everything), checked.
    fn reduce<T: Float>(x: &Tensor<T>, op: ReduceOp, axis: Option<usize>, keepdim: bool) -> Result<Tensor<T>>;

    /// `g` summed back to `target`, the shape of an operand it was broadcast from.
    fn sum_to_shape<T: Float>(g: &Tensor<T>, target: &[usize]) -> Result<Tensor<T>>;

    /// `g` of a reduction's output spread back over the reduced axis: `g` (times `scale`)
    /// at every position for a sum or a mean, at the first maximal one for a max (against
    /// the arithmetic, expanding, comparing and selecting, 4.9-6.5x faster on the CPU
    /// (`cargo bench -p tensor --bench fused_backward`: CPU, one thread, paper-size operands, two runs)).
    fn reduce_backward<T: Float>(
        x: &Tensor<T>,
        y: &Tensor<T>,
        g: &Tensor<T>,
        op: ReduceOp,
        split: (usize, usize, usize),
    ) -> Result<Tensor<T>>;

    // --- Products -------------------------------------------------------------------------

    /// `op(a) @ op(b)` following `plan` (checked).
    fn matmul<T: Float>(a: &Tensor<T>, b: &Tensor<T>, ta: bool, tb: bool, plan: &MatMulPlan) -> Result<Tensor<T>>;

    /// `act(sum_i x_i @ w_i[row_i.., cols] + b[cols])`: the product with its epilogue (bias
    /// and activation in the kernel that writes the output).
    fn linear_sum<T: Float>(
        parts: &[WeightRows<'_, T>],
        b: Option<&Tensor<T>>,
        act: Activation,
        cols: Option<(usize, usize)>,
    ) -> Result<Tensor<T>>;

    // --- Layout ---------------------------------------------------------------------------

    /// Axis permutation (checked).
    fn permute<T: Float>(x: &Tensor<T>, perm: &[usize]) -> Result<Tensor<T>>;

    /// Broadcast to `shape` (checked; copies).
    fn expand<T: Float>(x: &Tensor<T>, shape: &[usize]) -> Result<Tensor<T>>;

    /// Entries `start..start + len` of `axis` (checked).
    fn narrow<T: Float>(x: &Tensor<T>, axis: usize, start: usize, len: usize) -> Result<Tensor<T>>;

    /// Concatenation along `axis` into `shape` (checked).
    fn cat<T: Float>(xs: &[&Tensor<T>], axis: usize, shape: &[usize]) -> Result<Tensor<T>>;

    // --- Gathers, scatters and segments ---------------------------------------------------

    /// Entries of `axis` picked by `idx` (checked).
    fn index_select<T: Float>(x: &Tensor<T>, axis: usize, idx: &[usize]) -> Result<Tensor<T>>;

    /// `x` with `src` added at `idx` along `axis` (checked; `split` is `x`'s around `axis`).
    fn index_add<T: Float>(
        x: &Tensor<T>,
        split: (usize, usize, usize),
        idx: &[usize],
        src: &Tensor<T>,
    ) -> Result<Tensor<T>>;

    /// `out[o, j, i] = x[o, idx[o, j, i], i]` along `axis` (checked).
    fn gather<T: Float>(x: &Tensor<T>, axis: usize, idx_shape: &[usize], idx: &[usize]) -> Result<Tensor<T>>;

    /// Row sums (or means) by sorted segment id (checked).
    fn segment_reduce<T: Float>(x: &Tensor<T>, seg: &[usize], n: usize, mean: bool) -> Result<Tensor<T>>;

    /// Row `r` of the result is `g[seg[r]]` (over the segment's count for a mean): a gather
    /// by segment, with the mean's division fused (the mean 5.9x faster than a gather then a
    /// product on the CPU (`cargo bench -p tensor --bench fused_backward`: CPU, one thread, paper-size operands, two runs)).
    fn segment_backward<T: Float>(x_shape: &[usize], g: &Tensor<T>, seg: &[usize], mean: bool) -> Result<Tensor<T>>;

    // --- Network kernels that earn their place (one pass per row instead of three to five)

    /// Softmax over the last axis.
    fn softmax<T: Float>(x: &Tensor<T>) -> Tensor<T>;

    /// `y * (g - sum(g * y))` row by row (2.1-2.3x faster than its 4 kernels as arithmetic
    /// on the CPU, rows of 16 (`cargo bench -p tensor --bench fused_backward`: CPU, one thread, paper-size operands, two runs)).
    fn softmax_backward<T: Float>(y: &Tensor<T>, g: &Tensor<T>) -> Tensor<T>;

    /// `sqrt(sum x^2 + eps)` over the last axis, kept as size 1.
    fn norm_last<T: Float>(x: &Tensor<T>, eps: f64) -> Tensor<T>;

    /// `g x / y` row by row (1.27-1.29x faster than its 2 kernels as arithmetic on the CPU,
    /// rows of 3 (`cargo bench -p tensor --bench fused_backward`: CPU, one thread, paper-size operands, two runs)).
    fn norm_last_backward<T: Float>(x: &Tensor<T>, y: &Tensor<T>, g: &Tensor<T>) -> Tensor<T>;

    /// `(x - mean) / sqrt(var + eps)` over the last axis.
    fn standardize<T: Float>(x: &Tensor<T>, eps: f64) -> Tensor<T>;

    /// The gradient of [`Backend::standardize`] (2.4-3.0x faster than its 13 kernels as
    /// arithmetic on the CPU, rows of 128 (`cargo bench -p tensor --bench fused_backward`: CPU, one thread, paper-size operands, two runs)).
    fn standardize_backward<T: Float>(x: &Tensor<T>, y: &Tensor<T>, g: &Tensor<T>, eps: f64) -> Tensor<T>;

    // --- Values made on the device ------------------------------------------------------

    /// Zeros of `shape`, written on the device (nothing travels).
    fn zeros<T: Float>(shape: &[usize]) -> Tensor<T>;

    /// The Gaussian radial basis `exp(coeff (x_e - c_k)^2)` of host values `x` (`[E, K]` for
    /// `E` values and `K` centres), a constant input of a network (the critic's edge
    /// features, `models::critic`). The CPU evaluates it in f64, `(coeff * y) * y` with `y =
    /// x_e - c_k`, and rounds once to `T`; a device evaluates it in its own precision from `x`
    /// and the centres rounded to `T`, so only `E` values travel where the basis has `E K`.
    fn gaussian_basis<T: Float>(x: &[f64], centres: &[f64], coeff: f64) -> Result<Tensor<T>>;

    // --- Accumulation into a gradient slot (in place) ---------------------------------------

    /// `slot += t` (takes `t` as the slot on first use).
    fn accumulate<T: Float>(slot: &mut Slot<T>, t: Tensor<T>);

    /// `slot (+)= op(l) @ op(R)` following `plan`, `len` values, `R` the [`Block`] of `r`.
    fn product_into<T: Float>(
        slot: &mut Slot<T>,
        len: usize,
        l: (&Tensor<T>, bool),
        r: (&Tensor<T>, Block, bool),
        plan: &MatMulPlan,
    ) -> Result<()>;

    /// `slot[block] += op(l) @ op(r)` following `plan` (`len` values in the slot).
    fn product_into_block<T: Float>(
        slot: &mut Slot<T>,
        len: usize,
        at: Block,
        l: (&Tensor<T>, bool),
        r: (&Tensor<T>, bool),
        plan: &MatMulPlan,
    ) -> Result<()>;

    /// Adds `g` into the entries `start..` of `axis` of the slot (shaped `x_shape`): the
    /// adjoint of a narrow.
    fn narrow_backward_into<T: Float>(
        slot: &mut Slot<T>,
        x_shape: &[usize],
        g: &Tensor<T>,
        axis: usize,
        start: usize,
    ) -> Result<()>;

    /// Adds entries `start..start + len` of `axis` of `g` into the slot (`len_x` values):
    /// the adjoint of a concatenation for one part.
    fn cat_part_into<T: Float>(
        slot: &mut Slot<T>,
        len_x: usize,
        g: &Tensor<T>,
        axis: usize,
        start: usize,
        len: usize,
    ) -> Result<()>;

    /// Adds `g` at the entries `idx` of an axis (`split` of the slot's shape) into the slot.
    fn index_add_into<T: Float>(
        slot: &mut Slot<T>,
        split: (usize, usize, usize),
        g: &Tensor<T>,
        idx: &[usize],
    ) -> Result<()>;

    /// Adds `g` at the gathered positions into the slot (shaped `x_shape`).
    fn gather_backward_into<T: Float>(
        slot: &mut Slot<T>,
        x_shape: &[usize],
        axis: usize,
        g: &Tensor<T>,
        idx: &[usize],
    ) -> Result<()>;

    /// Both gradients of a batch of tiny products in one pass, written into the two slots
    /// (`a`'s alone when `same`); `false` when this backend has no such path and the general
    /// rule must run.
    fn small_batched_backward<T: Float>(
        g: &Tensor<T>,
        a: (&mut Slot<T>, &Tensor<T>, bool, bool),
        b: (&mut Slot<T>, &Tensor<T>, bool, bool),
        same: bool,
    ) -> bool;

    // --- Transfers -------------------------------------------------------------------------

    /// Every tensor's values on the host, in one transfer (a host backend's are already
    /// there).
    fn to_host_all<T: Float>(ts: &[Tensor<T>]) -> Result<Vec<Tensor<T>>>;

    // --- Checks and the optimiser ---------------------------------------------------------

    /// The index of the first tensor holding a NaN or an infinity, if any.
    fn first_non_finite<T: Float>(ts: &[Tensor<T>]) -> Result<Option<usize>>;

    /// The sum of the squared elements.
    fn sum_of_squares<T: Float>(x: &Tensor<T>) -> Result<f64>;

    /// One Adam step with f32 moments: the new parameter and moments.
    fn adam_step<T: Float>(
        p: &Tensor<T>,
        g: &Tensor<T>,
        m: &Tensor<f32>,
        v: &Tensor<f32>,
        step: AdamStep,
    ) -> Result<(Tensor<T>, Tensor<f32>, Tensor<f32>)>;
}

/// Adam's constants for one step: the learning rate, the decays and the bias corrections
/// `c1 = 1/(1-b1^t)`, `c2 = 1/(1-b2^t)`.
#[derive(Clone, Copy, Debug)]
pub struct AdamStep {
    /// Learning rate of this step.
    pub lr: f64,
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// `1 / (1 - beta1^t)`.
    pub c1: f64,
    /// `1 / (1 - beta2^t)`.
    pub c2: f64,
    /// Added to the root of the second moment.
    pub eps: f64,
    /// When set, each gradient element is first clipped to `[-clip, clip]` (as
    /// `nn::clip_elementwise` and the `clamp` op do: `min(max(g, -clip), clip)` in f32).
    pub clip: Option<f64>,
}

/// Runs `$body` with `$B` naming the backend of `$device`: the one place a device is matched
/// to its implementation. (Without the feature `gpu`, `crate::gpu::backend::Gpu` names the CPU
/// backend so that the arm compiles; no tensor is on the GPU then, so it is never taken.)
macro_rules! on_backend {
    ($device:expr, $B:ident => $body:expr) => {
        match $device {
            $crate::device::Device::Cpu => {
                use $crate::backend::cpu::Cpu as $B;
                $body
            }
            $crate::device::Device::Gpu => {
                use $crate::gpu::backend::Gpu as $B;
                $body
            }
        }
    };
}
pub(crate) use on_backend;
