//! The closed set of recorded operations. Each tape node stores one [`Op`]: which inputs it
//! read and the few constants its gradient rule needs. Forward kernels live in `kernels/`,
//! gradient rules in `backprop.rs`.

use std::sync::Arc;

use crate::element::Float;

/// Element-wise functions of one tensor. `apply` is the forward value, `derivative` is
/// dy/dx given the input `x` and the output `y` (whichever is cheaper is used).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum UnaryOp {
    /// -x
    Neg,
    /// e^x
    Exp,
    /// ln x
    Log,
    /// sqrt x
    Sqrt,
    /// x^2
    Square,
    /// tanh x
    Tanh,
    /// 1 / (1 + e^-x)
    Sigmoid,
    /// max(x, 0)
    Relu,
    /// ln(1 + e^x), computed as max(x, 0) + ln(1 + e^-|x|)
    Softplus,
    /// |x|
    Abs,
    /// x^p
    Powf(f64),
    /// min(max(x, lo), hi)
    Clamp(f64, f64),
    /// c * x
    Scale(f64),
    /// x + c
    AddScalar(f64),
}

impl UnaryOp {
    /// The forward value of one element.
    #[inline(always)]
    pub fn apply<T: Float>(self, x: T) -> T {
        match self {
            UnaryOp::Neg => -x,
            UnaryOp::Exp => x.exp(),
            UnaryOp::Log => x.ln(),
            UnaryOp::Sqrt => x.sqrt(),
            UnaryOp::Square => x * x,
            UnaryOp::Tanh => x.tanh(),
            UnaryOp::Sigmoid => sigmoid(x),
            UnaryOp::Relu => x.max(T::ZERO),
            UnaryOp::Softplus => softplus(x),
            UnaryOp::Abs => x.abs(),
            UnaryOp::Powf(p) => x.powf(T::from_f64(p)),
            UnaryOp::Clamp(lo, hi) => x.max(T::from_f64(lo)).min(T::from_f64(hi)),
            UnaryOp::Scale(c) => x * T::from_f64(c),
            UnaryOp::AddScalar(c) => x + T::from_f64(c),
        }
    }

    /// dy/dx at input `x` with output `y`.
    #[inline(always)]
    pub fn derivative<T: Float>(self, x: T, y: T) -> T {
        let two = T::from_f64(2.0);
        match self {
            UnaryOp::Neg => -T::ONE,
            UnaryOp::Exp => y,
            UnaryOp::Log => T::ONE / x,
            UnaryOp::Sqrt => T::ONE / (two * y),
            UnaryOp::Square => two * x,
            UnaryOp::Tanh => T::ONE - y * y,
            UnaryOp::Sigmoid => y * (T::ONE - y),
            UnaryOp::Relu => {
                if x > T::ZERO {
                    T::ONE
                } else {
                    T::ZERO
                }
            }
            UnaryOp::Softplus => sigmoid(x),
            UnaryOp::Abs => {
                if x > T::ZERO {
                    T::ONE
                } else if x < T::ZERO {
                    -T::ONE
                } else {
                    T::ZERO
                }
            }
            UnaryOp::Powf(p) => T::from_f64(p) * x.powf(T::from_f64(p - 1.0)),
            // Gradient flows where the input is inside [lo, hi], boundaries included
            // (PyTorch's convention).
            UnaryOp::Clamp(lo, hi) => {
                if x >= T::from_f64(lo) && x <= T::from_f64(hi) {
                    T::ONE
                } else {
                    T::ZERO
                }
            }
            UnaryOp::Scale(c) => T::from_f64(c),
            UnaryOp::AddScalar(_) => T::ONE,
        }
    }
}

/// Numerically stable logistic function.
#[inline(always)]
pub fn sigmoid<T: Float>(x: T) -> T {
    if x >= T::ZERO {
        T::ONE / (T::ONE + (-x).exp())
    } else {
        let e = x.exp();
        e / (T::ONE + e)
    }
}

/// Numerically stable softplus, ln(1 + e^x).
#[inline(always)]
pub fn softplus<T: Float>(x: T) -> T {
    x.max(T::ZERO) + (-x.abs()).exp().ln_1p()
}

/// Element-wise functions of two broadcast tensors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BinaryOp {
    /// a + b
    Add,
    /// a - b
    Sub,
    /// a * b
    Mul,
    /// a / b
    Div,
    /// min(a, b); on ties the gradient goes to `a`.
    Minimum,
    /// max(a, b); on ties the gradient goes to `a`.
    Maximum,
}

impl BinaryOp {
    /// The forward value of one pair.
    #[inline(always)]
    pub fn apply<T: Float>(self, a: T, b: T) -> T {
        match self {
            BinaryOp::Add => a + b,
            BinaryOp::Sub => a - b,
            BinaryOp::Mul => a * b,
            BinaryOp::Div => a / b,
            BinaryOp::Minimum => {
                if a <= b {
                    a
                } else {
                    b
                }
            }
            BinaryOp::Maximum => {
                if a >= b {
                    a
                } else {
                    b
                }
            }
        }
    }

    /// Name for error messages.
    pub fn name(self) -> &'static str {
        match self {
            BinaryOp::Add => "add",
            BinaryOp::Sub => "sub",
            BinaryOp::Mul => "mul",
            BinaryOp::Div => "div",
            BinaryOp::Minimum => "minimum",
            BinaryOp::Maximum => "maximum",
        }
    }
}

/// The activation fused into [`Op::Linear`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Activation {
    /// No activation.
    Identity,
    /// max(x, 0)
    Relu,
    /// tanh x
    Tanh,
}

/// Reductions over one axis or over everything.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReduceOp {
    /// Sum.
    Sum,
    /// Arithmetic mean.
    Mean,
    /// Maximum; the gradient goes to the first maximal element.
    Max,
}

/// Node identifier on a tape (its position).
pub type NodeId = usize;

/// One product of a fused [`Op::Linear`]: `x @ w[row..row + k]`, with `k` the last dim of
/// `x` (`row` 0 and `k` all of `w`'s rows for a whole weight).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinearTerm {
    /// The input `x [.., k]`.
    pub x: NodeId,
    /// The weight `w [in, out]`, of which rows `row..row + k` multiply `x`.
    pub w: NodeId,
    /// The first row of `w` that `x` multiplies.
    pub row: usize,
}

/// One recorded operation: the inputs (node ids) and the constants its gradient rule needs.
#[derive(Clone, Debug)]
pub enum Op {
    /// A leaf: a constant or a parameter.
    Leaf,
    /// Element-wise unary function.
    Unary(NodeId, UnaryOp),
    /// Broadcasting binary function.
    Binary(NodeId, NodeId, BinaryOp),
    /// Reduction over `axis` (None: all elements).
    Reduce {
        /// The reduced input.
        x: NodeId,
        /// Sum, mean or max.
        op: ReduceOp,
        /// The reduced axis; `None` reduces every element.
        axis: Option<usize>,
        /// Whether the reduced axis stays as size 1.
        keepdim: bool,
    },
    /// Batched matrix product of the last two dims, with optional transposes read as strides.
    MatMul {
        /// Left operand.
        a: NodeId,
        /// Right operand.
        b: NodeId,
        /// Whether `a`'s last two dims are read transposed.
        ta: bool,
        /// Whether `b`'s last two dims are read transposed.
        tb: bool,
    },
    /// Fused `act(sum_i x_i @ W_i + b)` over the last dims of the `x_i`, where `W_i` is the
    /// block of rows `row_i..row_i + k_i` and columns `col..col + n` of `w_i` (`k_i` the last
    /// dim of `x_i`, `n` the output's; one part of a whole weight is an ordinary layer,
    /// several are one layer applied to the concatenation of the `x_i` without building it
    /// or slicing its weight; `col` and `n` short of the weight's width are some of a layer's
    /// outputs).
    Linear {
        /// The input/weight terms.
        parts: Vec<LinearTerm>,
        /// The bias (of the weights' full width: entries `col..col + n` are added), if any.
        b: Option<NodeId>,
        /// The first column of the weights (and entry of the bias) the layer computes.
        col: usize,
        /// The activation applied after the bias.
        act: Activation,
    },
    /// Same data, new shape.
    Reshape(NodeId),
    /// Axis permutation.
    Permute(NodeId, Vec<usize>),
    /// Broadcast to a larger shape.
    Expand(NodeId),
    /// `len` entries of `axis` starting at `start`.
    Narrow {
        /// The input.
        x: NodeId,
        /// The narrowed axis.
        axis: usize,
        /// The first kept entry.
        start: usize,
    },
    /// Concatenation along `axis`.
    Cat {
        /// The inputs, in order.
        xs: Vec<NodeId>,
        /// The concatenation axis.
        axis: usize,
    },
    /// Selection of entries of `axis` by index (repeats allowed).
    IndexSelect {
        /// The input.
        x: NodeId,
        /// The indexed axis.
        axis: usize,
        /// The selected entries, in output order.
        idx: Arc<Vec<usize>>,
    },
    /// `x` with `src` entries added at `idx` along `axis` (duplicates accumulate).
    IndexAdd {
        /// The tensor added into.
        x: NodeId,
        /// The entries added.
        src: NodeId,
        /// The indexed axis.
        axis: usize,
        /// Where each entry of `src` goes along `axis`.
        idx: Arc<Vec<usize>>,
    },
    /// Element-wise gather along `axis` with an index array shaped like the output.
    Gather {
        /// The input.
        x: NodeId,
        /// The gathered axis.
        axis: usize,
        /// One index along `axis` per output element.
        idx: Arc<Vec<usize>>,
    },
    /// Sums (or means) of rows grouped by a sorted segment id (axis 0).
    Segment {
        /// The rows.
        x: NodeId,
        /// The sorted segment id of every row.
        seg: Arc<Vec<usize>>,
        /// Mean instead of sum.
        mean: bool,
    },
    /// `mask ? a : b` with broadcasting.
    Where {
        /// Taken where the mask is true.
        a: NodeId,
        /// Taken where the mask is false.
        b: NodeId,
        /// The mask, in the output's shape.
        mask: Arc<Vec<bool>>,
    },
    /// Softmax along the last axis.
    Softmax(NodeId),
    /// Euclidean norm over the last axis, `sqrt(sum x^2 + eps)`, keeping the axis as size 1.
    NormLast {
        /// The input.
        x: NodeId,
        /// Added to the sum of squares inside the root.
        eps: f64,
    },
    /// `(x - mean) / sqrt(var + eps)` over the last axis (biased variance).
    Standardize {
        /// The input.
        x: NodeId,
        /// Added to the variance inside the root.
        eps: f64,
    },
}

impl Op {
    /// Short name of the operation (for profiles and messages).
    pub fn name(&self) -> &'static str {
        match self {
            Op::Leaf => "leaf",
            Op::Unary(_, u) => match u {
                UnaryOp::Neg => "neg",
                UnaryOp::Exp => "exp",
                UnaryOp::Log => "log",
                UnaryOp::Sqrt => "sqrt",
                UnaryOp::Square => "square",
                UnaryOp::Tanh => "tanh",
                UnaryOp::Sigmoid => "sigmoid",
                UnaryOp::Relu => "relu",
                UnaryOp::Softplus => "softplus",
                UnaryOp::Abs => "abs",
                UnaryOp::Powf(_) => "powf",
                UnaryOp::Clamp(..) => "clamp",
                UnaryOp::Scale(_) => "scale",
                UnaryOp::AddScalar(_) => "add_scalar",
            },
            Op::Binary(_, _, b) => b.name(),
            Op::Reduce { op: ReduceOp::Sum, .. } => "sum",
            Op::Reduce { op: ReduceOp::Mean, .. } => "mean",
            Op::Reduce { op: ReduceOp::Max, .. } => "max",
            Op::MatMul { .. } => "matmul",
            Op::Linear { .. } => "linear",
            Op::Reshape(_) => "reshape",
            Op::Permute(..) => "permute",
            Op::Expand(_) => "expand",
            Op::Narrow { .. } => "narrow",
            Op::Cat { .. } => "cat",
            Op::IndexSelect { .. } => "index_select",
            Op::IndexAdd { .. } => "index_add",
            Op::Gather { .. } => "gather",
            Op::Segment { mean: false, .. } => "segment_sum",
            Op::Segment { mean: true, .. } => "segment_mean",
            Op::Where { .. } => "where",
            Op::Softmax(_) => "softmax",
            Op::NormLast { .. } => "norm",
            Op::Standardize { .. } => "standardize",
        }
    }
}
