//! Floating-point operation counts of recorded ops, for profiled tapes
//! ([`Tape::enable_profiling`](crate::Tape::enable_profiling),
//! [`Tape::profile_flops`](crate::Tape::profile_flops)).
//!
//! The counts describe the arithmetic an op needs, not the instructions the kernels
//! happen to issue; they are what an "arithmetic floor" (FLOPs divided by the machine's
//! matmul rate) is computed from. Nothing is counted unless profiling is on.
//!
//! # Convention
//!
//! **Matrix products** (`matmul`, `matmul_t`, batched products, the product inside
//! `linear`) count `2 * m * n * k` per product (one multiply and one add per
//! multiply-add), times the number of products of the broadcast batch. The backward pass
//! counts the products it actually computes: one `2 * m * n * k` product for each input
//! that requires a gradient (`x @ W` with both requiring one: 2 products; a constant `x`:
//! 1 product; an operand used twice, `A^T A`: 2 products).
//!
//! **Everything else** counts one flop per element an arithmetic step produces. Every
//! scalar function counts 1, whether it is an add, a compare, an `exp`, a `tanh` or a
//! derivative. Pure data movement (reshape, permute, narrow, cat, index_select and gather
//! forward, where, leaves) counts 0. Per op, with `N` the output's element count and `X`
//! the input's:
//!
//! | op | forward | backward (per input that requires a gradient) |
//! |---|---|---|
//! | unary (exp, relu, scale, ...) | `N` | `2 N` (derivative, times the output gradient) |
//! | add, sub | `N` | 0 (the output gradient, or its negation) |
//! | mul, minimum, maximum | `N` | `N` |
//! | div | `N` | `N` for the dividend, `2 N` for the divisor |
//! | sum, mean, max (reductions) | `X` (one add or compare per input element) | `X` |
//! | `linear` bias, activation | `N` each | `2 N` activation; `N` bias (row sum) |
//! | softmax | `5 N` (max, subtract, exp, sum, scale) | `4 N` |
//! | `norm_last` | `2 X + N` (square, add; square root) | `X + N` |
//! | `standardize` | `6 N` (two row passes for mean and variance, subtract, scale) | `11 N` (the statistics are recomputed) |
//! | index_add / scatter_add | `S` (the source's element count) | 0 |
//! | segment_sum, segment_mean | `X` (`+ N` divisions for the mean) | 0 (sum), `X` (mean) |
//! | expand | 0 | `N` (sum over the broadcast dims) |
//! | index_select, gather | 0 | `N` (scatter-add of the gradient) |
//! | reshape, permute, narrow, cat, where | 0 | 0 |
//!
//! When a binary op, `where` or a batched product broadcast an input, its gradient is
//! summed over the broadcast dims: one more flop per element of the full-size gradient.
//! Adding one contribution to a gradient that already holds another (a value used twice)
//! is bookkeeping of the tape and is not counted. Per-row scalars (a row's mean, one
//! division per row) are ignored where the table does not list them.

use std::ops::{Add, AddAssign};

use crate::element::Float;
use crate::op::{Activation, BinaryOp, LinearTerm, NodeId, Op};
use crate::shape::{broadcast_shapes, numel};
use crate::tape::Node;

/// Floating-point operations counted on a profiled tape
/// ([`Tape::profile_flops`](crate::Tape::profile_flops)), matrix products apart from the
/// rest, forward apart from backward. The conventions are in the module documentation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FlopCount {
    /// Matrix products of the forward pass (`2 * m * n * k` each).
    pub matmul_forward: u64,
    /// Matrix products of the backward pass (one product per input wanting a gradient).
    pub matmul_backward: u64,
    /// Every other op of the forward pass.
    pub other_forward: u64,
    /// Every other gradient rule of the backward pass.
    pub other_backward: u64,
}

impl FlopCount {
    /// All four counts together.
    pub fn total(&self) -> u64 {
        self.forward() + self.backward()
    }

    /// The forward pass (products and the rest).
    pub fn forward(&self) -> u64 {
        self.matmul_forward + self.other_forward
    }

    /// The backward pass (products and the rest).
    pub fn backward(&self) -> u64 {
        self.matmul_backward + self.other_backward
    }

    /// Matrix products, forward and backward.
    pub fn matmul(&self) -> u64 {
        self.matmul_forward + self.matmul_backward
    }

    /// Seconds that [`FlopCount::total`] takes at `gflops` billion flops per second: the
    /// arithmetic floor of the recorded work at that rate.
    pub fn seconds_at(&self, gflops: f64) -> f64 {
        self.total() as f64 / (gflops * 1e9)
    }
}

impl Add for FlopCount {
    type Output = FlopCount;

    /// Field-wise sum (e.g. of several tapes that make one update).
    fn add(mut self, rhs: FlopCount) -> FlopCount {
        self += rhs;
        self
    }
}

impl AddAssign for FlopCount {
    /// Field-wise sum.
    fn add_assign(&mut self, rhs: FlopCount) {
        self.matmul_forward += rhs.matmul_forward;
        self.matmul_backward += rhs.matmul_backward;
        self.other_forward += rhs.other_forward;
        self.other_backward += rhs.other_backward;
    }
}

/// Flops of one op run (forward or backward), products apart from the rest.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct OpFlops {
    /// Matrix products.
    pub(crate) matmul: u64,
    /// Everything else.
    pub(crate) other: u64,
}

impl OpFlops {
    fn other(other: usize) -> Self {
        Self { matmul: 0, other: other as u64 }
    }
}

impl AddAssign for OpFlops {
    fn add_assign(&mut self, rhs: OpFlops) {
        self.matmul += rhs.matmul;
        self.other += rhs.other;
    }
}

/// `(batch count, m, k, n)` of `op(a) @ op(b)` for stored shapes `a`, `b` (rank >= 2,
/// checked when the op was recorded).
fn product_dims(a: &[usize], b: &[usize], ta: bool, tb: bool) -> (usize, usize, usize, usize) {
    let (ar, ac) = (a[a.len() - 2], a[a.len() - 1]);
    let (br, bc) = (b[b.len() - 2], b[b.len() - 1]);
    let (m, k) = if ta { (ac, ar) } else { (ar, ac) };
    let n = if tb { br } else { bc };
    let batch = broadcast_shapes("matmul", &a[..a.len() - 2], &b[..b.len() - 2]).map_or(1, |s| numel(&s));
    (batch, m, k, n)
}

/// `2 * m * n * k` per product, `batch` products.
fn product_flops(batch: usize, m: usize, k: usize, n: usize) -> u64 {
    2 * (batch as u64) * (m as u64) * (k as u64) * (n as u64)
}

/// Flops of the forward computation of `op` whose output is `out` (its inputs are in
/// `nodes`).
pub(crate) fn forward<T: Float>(nodes: &[Node<T>], op: &Op, out: &[usize]) -> OpFlops {
    let x_len = |i: NodeId| nodes[i].value.numel();
    let n = numel(out);
    match op {
        Op::Leaf
        | Op::Reshape(_)
        | Op::Permute(..)
        | Op::Expand(_)
        | Op::Narrow { .. }
        | Op::Cat { .. }
        | Op::IndexSelect { .. }
        | Op::Gather { .. }
        | Op::Where { .. } => OpFlops::default(),
        Op::Unary(..) | Op::Binary(..) => OpFlops::other(n),
        Op::Reduce { x, .. } => OpFlops::other(x_len(*x)),
        Op::MatMul { a, b, ta, tb } => {
            let (batch, m, k, n) = product_dims(nodes[*a].value.shape(), nodes[*b].value.shape(), *ta, *tb);
            OpFlops { matmul: product_flops(batch, m, k, n), other: 0 }
        }
        Op::Linear { parts, b, act, .. } => {
            let mut matmul = 0;
            for t in parts {
                let (k, cols) = term_dims(nodes, t, out);
                matmul += product_flops(1, n.checked_div(cols).unwrap_or(0), k, cols);
            }
            // One add per element for every part after the first, the bias and the activation.
            let passes =
                parts.len().saturating_sub(1) + usize::from(b.is_some()) + usize::from(*act != Activation::Identity);
            OpFlops { matmul, other: (passes * n) as u64 }
        }
        Op::IndexAdd { src, .. } => OpFlops::other(x_len(*src)),
        Op::Segment { x, mean, .. } => OpFlops::other(x_len(*x) + if *mean { n } else { 0 }),
        Op::Softmax(_) => OpFlops::other(5 * n),
        Op::NormLast { x, .. } => OpFlops::other(2 * x_len(*x) + n),
        Op::Standardize { .. } => OpFlops::other(6 * n),
    }
}

/// Flops of the gradient rule of node `id`: only the contributions to inputs that require
/// a gradient are counted, as `backprop::propagate` only computes those.
pub(crate) fn backward<T: Float>(nodes: &[Node<T>], id: NodeId) -> OpFlops {
    let node = &nodes[id];
    let n = node.value.numel();
    let wants = |i: NodeId| nodes[i].requires_grad;
    let x_len = |i: NodeId| nodes[i].value.numel();
    // `per_element * N` if input `i` wants a gradient, plus the sum over broadcast dims.
    let elementwise = |i: NodeId, per_element: usize| {
        if !wants(i) {
            return 0;
        }
        per_element * n + if x_len(i) < n { n } else { 0 }
    };
    match &node.op {
        Op::Leaf | Op::Reshape(_) | Op::Permute(..) | Op::Narrow { .. } | Op::Cat { .. } | Op::IndexAdd { .. } => {
            OpFlops::default()
        }
        Op::Unary(x, _) => OpFlops::other(if wants(*x) { 2 * n } else { 0 }),
        Op::Binary(a, b, op) => {
            let (pa, pb) = match op {
                BinaryOp::Add | BinaryOp::Sub => (0, 0),
                BinaryOp::Mul | BinaryOp::Minimum | BinaryOp::Maximum => (1, 1),
                BinaryOp::Div => (1, 2),
            };
            OpFlops::other(elementwise(*a, pa) + elementwise(*b, pb))
        }
        Op::Where { a, b, .. } => OpFlops::other(elementwise(*a, 0) + elementwise(*b, 0)),
        Op::Reduce { x, .. } => OpFlops::other(if wants(*x) { x_len(*x) } else { 0 }),
        Op::MatMul { a, b, ta, tb } => {
            let (av, bv) = (&nodes[*a].value, &nodes[*b].value);
            let (batch, m, k, cols) = product_dims(av.shape(), bv.shape(), *ta, *tb);
            let mut f = OpFlops::default();
            // d op(A) is m x k, d op(B) is k x n, per batch entry; both are products over the
            // third dim. A gradient computed over the full batch and summed down to a
            // broadcast input costs one add per element of the full-batch product.
            for (input, full) in [(*a, batch * m * k), (*b, batch * k * cols)] {
                if wants(input) {
                    f.matmul += product_flops(batch, m, k, cols);
                    if x_len(input) < full {
                        f.other += full as u64;
                    }
                }
            }
            f
        }
        Op::Linear { parts, b, act, .. } => {
            let needed = parts.iter().any(|t| wants(t.x) || wants(t.w)) || b.is_some_and(wants);
            let mut f = OpFlops::default();
            if needed && *act != Activation::Identity {
                f.other += 2 * n as u64;
            }
            for t in parts {
                let (k, cols) = term_dims(nodes, t, node.value.shape());
                let rows = n.checked_div(cols).unwrap_or(0);
                for input in [t.x, t.w] {
                    if wants(input) {
                        f.matmul += product_flops(1, rows, k, cols);
                    }
                }
            }
            if b.is_some_and(wants) {
                f.other += n as u64;
            }
            f
        }
        Op::Softmax(x) => OpFlops::other(if wants(*x) { 4 * n } else { 0 }),
        Op::NormLast { x, .. } => OpFlops::other(if wants(*x) { x_len(*x) + n } else { 0 }),
        Op::Standardize { x, .. } => OpFlops::other(if wants(*x) { 11 * n } else { 0 }),
        Op::Expand(x) | Op::IndexSelect { x, .. } | Op::Gather { x, .. } => {
            OpFlops::other(if wants(*x) { n } else { 0 })
        }
        Op::Segment { x, mean, .. } => OpFlops::other(if wants(*x) && *mean { x_len(*x) } else { 0 }),
    }
}

/// `(k, n)` of one term of a fused layer of output `y`: the rows of its weight that it
/// multiplies (the last dim of its input) and the columns (the last dim of the output).
fn term_dims<T: Float>(nodes: &[Node<T>], t: &LinearTerm, y: &[usize]) -> (usize, usize) {
    let k = nodes[t.x].value.shape().last().copied().unwrap_or(0);
    (k, y.last().copied().unwrap_or(0))
}
