//! The differentiable operations on [`Var`]: each computes its value with a kernel and
//! records one [`Op`] node. Calls that a user can get wrong return `Result`; errors name the
//! op and the shapes.

use std::sync::Arc;

use crate::dispatch as k;
use crate::element::Float;
use crate::error::{Result, check_axis, invalid, mismatch};
use crate::kernels::nnops;
use crate::op::{Activation, BinaryOp, LinearTerm, NodeId, Op, ReduceOp, UnaryOp};
use crate::shape::{broadcast_shapes, numel};
use crate::tape::{Tape, Var};
use crate::tensor::Tensor;

// The arithmetic methods share the names of std's operator traits but return `Result`
// (broadcasting can fail), so they cannot implement those traits.
#[allow(clippy::should_implement_trait)]
impl<'t, T: Float> Var<'t, T> {
    fn unary(self, op: UnaryOp) -> Var<'t, T> {
        let y = k::unary(&self.value(), op);
        self.tape.record(y, Op::Unary(self.id, op), &[self.id])
    }

    /// -x
    pub fn neg(self) -> Self {
        self.unary(UnaryOp::Neg)
    }
    /// e^x
    pub fn exp(self) -> Self {
        self.unary(UnaryOp::Exp)
    }
    /// ln x
    pub fn log(self) -> Self {
        self.unary(UnaryOp::Log)
    }
    /// sqrt x
    pub fn sqrt(self) -> Self {
        self.unary(UnaryOp::Sqrt)
    }
    /// x^2
    pub fn square(self) -> Self {
        self.unary(UnaryOp::Square)
    }
    /// tanh x
    pub fn tanh(self) -> Self {
        self.unary(UnaryOp::Tanh)
    }
    /// 1 / (1 + e^-x)
    pub fn sigmoid(self) -> Self {
        self.unary(UnaryOp::Sigmoid)
    }
    /// max(x, 0)
    pub fn relu(self) -> Self {
        self.unary(UnaryOp::Relu)
    }
    /// ln(1 + e^x), numerically stable.
    pub fn softplus(self) -> Self {
        self.unary(UnaryOp::Softplus)
    }
    /// |x|
    pub fn abs(self) -> Self {
        self.unary(UnaryOp::Abs)
    }
    /// x^p
    pub fn powf(self, p: f64) -> Self {
        self.unary(UnaryOp::Powf(p))
    }
    /// min(max(x, lo), hi)
    pub fn clamp(self, lo: f64, hi: f64) -> Self {
        self.unary(UnaryOp::Clamp(lo, hi))
    }
    /// c * x
    pub fn scale(self, c: f64) -> Self {
        self.unary(UnaryOp::Scale(c))
    }
    /// x + c
    pub fn add_scalar(self, c: f64) -> Self {
        self.unary(UnaryOp::AddScalar(c))
    }

    fn binary(self, other: Var<'t, T>, op: BinaryOp) -> Result<Var<'t, T>> {
        self.tape.check_same(other);
        let y = k::binary(&self.value(), &other.value(), op)?;
        Ok(self.tape.record(y, Op::Binary(self.id, other.id, op), &[self.id, other.id]))
    }

    /// a + b (broadcasting)
    pub fn add(self, other: Var<'t, T>) -> Result<Self> {
        self.binary(other, BinaryOp::Add)
    }
    /// a - b (broadcasting)
    pub fn sub(self, other: Var<'t, T>) -> Result<Self> {
        self.binary(other, BinaryOp::Sub)
    }
    /// a * b (broadcasting)
    pub fn mul(self, other: Var<'t, T>) -> Result<Self> {
        self.binary(other, BinaryOp::Mul)
    }
    /// a / b (broadcasting)
    pub fn div(self, other: Var<'t, T>) -> Result<Self> {
        self.binary(other, BinaryOp::Div)
    }
    /// Element-wise minimum (broadcasting); ties send the gradient to `self`.
    pub fn minimum(self, other: Var<'t, T>) -> Result<Self> {
        self.binary(other, BinaryOp::Minimum)
    }
    /// Element-wise maximum (broadcasting); ties send the gradient to `self`.
    pub fn maximum(self, other: Var<'t, T>) -> Result<Self> {
        self.binary(other, BinaryOp::Maximum)
    }

    fn reduce(self, op: ReduceOp, axis: Option<usize>, keepdim: bool) -> Result<Var<'t, T>> {
        let y = k::reduce(&self.value(), op, axis, keepdim)?;
        Ok(self.tape.record(y, Op::Reduce { x: self.id, op, axis, keepdim }, &[self.id]))
    }

    /// Sum over `axis`.
    pub fn sum(self, axis: usize, keepdim: bool) -> Result<Self> {
        self.reduce(ReduceOp::Sum, Some(axis), keepdim)
    }
    /// Mean over `axis`.
    pub fn mean(self, axis: usize, keepdim: bool) -> Result<Self> {
        self.reduce(ReduceOp::Mean, Some(axis), keepdim)
    }
    /// Maximum over `axis` (gradient to the first maximal entry).
    pub fn max(self, axis: usize, keepdim: bool) -> Result<Self> {
        self.reduce(ReduceOp::Max, Some(axis), keepdim)
    }
    /// Sum of all elements (a scalar).
    pub fn sum_all(self) -> Self {
        self.reduce(ReduceOp::Sum, None, false).expect("a full sum cannot fail")
    }
    /// Mean of all elements (a scalar); fails on an empty tensor.
    pub fn mean_all(self) -> Result<Self> {
        self.reduce(ReduceOp::Mean, None, false)
    }
    /// Maximum of all elements (a scalar); fails on an empty tensor.
    pub fn max_all(self) -> Result<Self> {
        self.reduce(ReduceOp::Max, None, false)
    }

    /// Matrix product over the last two dims, batch dims broadcast (both operands rank >= 2).
    pub fn matmul(self, other: Var<'t, T>) -> Result<Self> {
        self.matmul_t(other, false, false)
    }

    /// `op(self) @ op(other)` where `op` transposes the last two dims when asked; the
    /// transposes are read as strides, nothing is copied.
    pub fn matmul_t(self, other: Var<'t, T>, ta: bool, tb: bool) -> Result<Self> {
        self.tape.check_same(other);
        let y = k::matmul(&self.value(), &other.value(), ta, tb)?;
        Ok(self.tape.record(y, Op::MatMul { a: self.id, b: other.id, ta, tb }, &[self.id, other.id]))
    }

    /// Fused `act(self @ w + b)` over the last dim: `self [.., in]`, `w [in, out]`, `b [out]`.
    pub fn linear(self, w: Var<'t, T>, b: Option<Var<'t, T>>, act: Activation) -> Result<Self> {
        self.linear_block(w, b, None, act)
    }

    /// Some of a layer's outputs: `act(self @ w[:, start..start + len] + b[start..start +
    /// len])` for `self [.., in]`, `w [in, out]`, `b [out]`. The same values as [`Var::linear`]
    /// of `w.narrow(1, start, len)` and `b.narrow(0, start, len)` (the same bits on the CPU and
    /// on the GPU), without the narrows: on the GPU the product reads the columns where they
    /// lie, and their gradient is written into them.
    pub fn linear_columns(
        self,
        w: Var<'t, T>,
        b: Option<Var<'t, T>>,
        start: usize,
        len: usize,
        act: Activation,
    ) -> Result<Self> {
        self.linear_block(w, b, Some((start, len)), act)
    }

    /// [`Var::linear`] of the output columns `cols` (`(start, len)`; `None`: all of them).
    fn linear_block(
        self,
        w: Var<'t, T>,
        b: Option<Var<'t, T>>,
        cols: Option<(usize, usize)>,
        act: Activation,
    ) -> Result<Self> {
        self.tape.check_same(w);
        let bv = b.map(|b| {
            self.tape.check_same(b);
            b.value()
        });
        let (xv, wv) = (self.value(), w.value());
        nnops::linear_shapes(xv.shape(), wv.shape(), bv.as_ref().map(|b| b.shape()))?;
        if let Some((start, len)) = cols
            && start + len > wv.shape()[1]
        {
            return Err(invalid(
                "linear_columns",
                format!("columns {start}..{} of a weight of shape {:?}", start + len, wv.shape()),
            ));
        }
        let y = k::linear_sum(&[(&xv, &wv, 0)], bv.as_ref(), act, cols)?;
        let mut inputs = vec![self.id, w.id];
        inputs.extend(b.map(|b| b.id));
        let parts = vec![LinearTerm { x: self.id, w: w.id, row: 0 }];
        let col = cols.map_or(0, |c| c.0);
        Ok(self.tape.record(y, Op::Linear { parts, b: b.map(|b| b.id), col, act }, &inputs))
    }

    /// Softmax over the last axis.
    pub fn softmax(self) -> Self {
        let y = k::softmax(&self.value());
        self.tape.record(y, Op::Softmax(self.id), &[self.id])
    }

    /// Euclidean norm over the last axis, `sqrt(sum x^2 + eps)`, with that axis kept as
    /// size 1 (`eps >= 0` keeps the gradient finite at 0).
    pub fn norm_last(self, eps: f64) -> Self {
        let y = k::norm_last(&self.value(), eps);
        self.tape.record(y, Op::NormLast { x: self.id, eps }, &[self.id])
    }

    /// `(x - mean) / sqrt(var + eps)` over the last axis (biased variance): layer
    /// normalisation without its affine part, in one op.
    pub fn standardize(self, eps: f64) -> Self {
        let y = k::standardize(&self.value(), eps);
        self.tape.record(y, Op::Standardize { x: self.id, eps }, &[self.id])
    }

    /// Same elements, new shape (no copy).
    pub fn reshape(self, shape: &[usize]) -> Result<Self> {
        let y = self.value().reshape(shape)?;
        Ok(self.tape.record(y, Op::Reshape(self.id), &[self.id]))
    }

    /// Inserts a dim of size 1 at `axis`.
    pub fn unsqueeze(self, axis: usize) -> Result<Self> {
        let mut s = self.shape();
        if axis > s.len() {
            return Err(check_axis("unsqueeze", axis, &s).unwrap_err());
        }
        s.insert(axis, 1);
        self.reshape(&s)
    }

    /// Reorders axes: output axis `i` is input axis `perm[i]`.
    pub fn permute(self, perm: &[usize]) -> Result<Self> {
        let y = k::permute(&self.value(), perm)?;
        Ok(self.tape.record(y, Op::Permute(self.id, perm.to_vec()), &[self.id]))
    }

    /// Swaps two axes.
    pub fn transpose(self, a: usize, b: usize) -> Result<Self> {
        let r = self.rank();
        check_axis("transpose", a, &self.shape())?;
        check_axis("transpose", b, &self.shape())?;
        let mut perm: Vec<usize> = (0..r).collect();
        perm.swap(a, b);
        self.permute(&perm)
    }

    /// Broadcasts to a larger shape (copies).
    pub fn expand(self, shape: &[usize]) -> Result<Self> {
        let y = k::expand(&self.value(), shape)?;
        Ok(self.tape.record(y, Op::Expand(self.id), &[self.id]))
    }

    /// Entries `start..start+len` of `axis`.
    pub fn narrow(self, axis: usize, start: usize, len: usize) -> Result<Self> {
        let y = k::narrow(&self.value(), axis, start, len)?;
        Ok(self.tape.record(y, Op::Narrow { x: self.id, axis, start }, &[self.id]))
    }

    /// Entries of `axis` picked by `idx` (repeats allowed).
    pub fn index_select(self, axis: usize, idx: &[usize]) -> Result<Self> {
        let y = k::index_select(&self.value(), axis, idx)?;
        Ok(self.tape.record(y, Op::IndexSelect { x: self.id, axis, idx: Arc::new(idx.to_vec()) }, &[self.id]))
    }

    /// `self` with `src[.., j, ..]` added at entry `idx[j]` of `axis`; duplicate indices
    /// accumulate.
    pub fn index_add(self, axis: usize, idx: &[usize], src: Var<'t, T>) -> Result<Self> {
        self.tape.check_same(src);
        let y = k::index_add(&self.value(), axis, idx, &src.value())?;
        Ok(self.tape.record(
            y,
            Op::IndexAdd { x: self.id, src: src.id, axis, idx: Arc::new(idx.to_vec()) },
            &[self.id, src.id],
        ))
    }

    /// Scatter-add into zeros: an output with `size` entries on `axis` where entry `idx[j]`
    /// receives the sum of `self[.., j, ..]`.
    pub fn scatter_add(self, axis: usize, idx: &[usize], size: usize) -> Result<Self> {
        check_axis("scatter_add", axis, &self.shape())?;
        let mut shape = self.shape();
        shape[axis] = size;
        let zeros = self.tape.constant(crate::dispatch::zeros(self.value().device(), &shape));
        zeros.index_add(axis, idx, self)
    }

    /// `out[o, j, i] = self[o, idx[o, j, i], i]` along `axis`; `idx` has shape `idx_shape`
    /// (equal to the input's except along `axis`).
    pub fn gather(self, axis: usize, idx_shape: &[usize], idx: &[usize]) -> Result<Self> {
        let y = k::gather(&self.value(), axis, idx_shape, idx)?;
        Ok(self.tape.record(y, Op::Gather { x: self.id, axis, idx: Arc::new(idx.to_vec()) }, &[self.id]))
    }

    /// Sums of rows (axis 0) grouped by sorted segment ids into `num_segments` rows.
    pub fn segment_sum(self, seg: &[usize], num_segments: usize) -> Result<Self> {
        self.segment(seg, num_segments, false)
    }

    /// Means of rows (axis 0) grouped by sorted segment ids; empty segments give 0.
    pub fn segment_mean(self, seg: &[usize], num_segments: usize) -> Result<Self> {
        self.segment(seg, num_segments, true)
    }

    fn segment(self, seg: &[usize], n: usize, mean: bool) -> Result<Self> {
        let y = k::segment_reduce(&self.value(), seg, n, mean)?;
        Ok(self.tape.record(y, Op::Segment { x: self.id, seg: Arc::new(seg.to_vec()), mean }, &[self.id]))
    }
}

impl<T: Float> Tape<T> {
    /// Concatenation along `axis`.
    pub fn cat<'t>(&'t self, xs: &[Var<'t, T>], axis: usize) -> Result<Var<'t, T>> {
        xs.iter().for_each(|&x| self.check_same(x));
        let vals: Vec<Tensor<T>> = xs.iter().map(|x| x.value()).collect();
        let refs: Vec<&Tensor<T>> = vals.iter().collect();
        let y = k::cat(&refs, axis)?;
        let ids: Vec<usize> = xs.iter().map(|x| x.id).collect();
        Ok(self.record(y, Op::Cat { xs: ids.clone(), axis }, &ids))
    }

    /// One layer over several inputs, `act(sum_i x_i @ w_i + b)` for `parts = [(x_i, w_i)]`:
    /// the layer of weight `cat(w_i, axis 0)` applied to `cat(x_i, last axis)`, without
    /// building either concatenation and in one op (no intermediate sums on the tape). The
    /// `x_i` share their leading dims, the `w_i` their width.
    pub fn linear_sum<'t>(
        &'t self,
        parts: &[(Var<'t, T>, Var<'t, T>)],
        b: Option<Var<'t, T>>,
        act: Activation,
    ) -> Result<Var<'t, T>> {
        let vals: Vec<(Tensor<T>, Tensor<T>)> = parts
            .iter()
            .map(|&(x, w)| {
                self.check_same(x);
                self.check_same(w);
                (x.value(), w.value())
            })
            .collect();
        let (first_x, first_w) =
            vals.first().ok_or_else(|| mismatch("linear", &[], "needs at least one (x, w) part"))?;
        let bv = b.map(|b| {
            self.check_same(b);
            b.value()
        });
        nnops::linear_shapes(first_x.shape(), first_w.shape(), bv.as_ref().map(|b| b.shape()))?;
        for (x, w) in &vals {
            nnops::linear_shapes(x.shape(), w.shape(), None)?;
        }
        let terms: Vec<LinearTerm> = parts.iter().map(|&(x, w)| LinearTerm { x: x.id, w: w.id, row: 0 }).collect();
        let refs: Vec<nnops::WeightRows<'_, T>> = vals.iter().map(|(x, w)| (x, w, 0)).collect();
        self.record_linear(terms, &refs, b, bv.as_ref(), act)
    }

    /// One layer over several inputs that reads its weight in place: `act(cat(xs, last axis)
    /// @ w + b)` for `w [in, out]`, where `x_i [.., k_i]` multiplies rows `r_i..r_i + k_i` of
    /// `w` (`r_i` the sum of the earlier `k_j`; the `k_i` sum to `in`). The same values as
    /// [`Tape::linear_sum`] of `x_i` and `w.narrow(0, r_i, k_i)` (the same bits on the CPU and
    /// on the GPU), without the narrows: the products read the blocks of `w` where they lie,
    /// and the weight's gradient is written into them.
    pub fn linear_rows<'t>(
        &'t self,
        xs: &[Var<'t, T>],
        w: Var<'t, T>,
        b: Option<Var<'t, T>>,
        act: Activation,
    ) -> Result<Var<'t, T>> {
        self.check_same(w);
        let wv = w.value();
        let vals: Vec<Tensor<T>> = xs
            .iter()
            .map(|&x| {
                self.check_same(x);
                x.value()
            })
            .collect();
        let bv = b.map(|b| {
            self.check_same(b);
            b.value()
        });
        let (mut row, mut terms, mut refs) = (0, Vec::with_capacity(xs.len()), Vec::with_capacity(xs.len()));
        for (x, xv) in xs.iter().zip(&vals) {
            terms.push(LinearTerm { x: x.id, w: w.id, row });
            refs.push((xv, &wv, row));
            row += xv.shape().last().copied().unwrap_or(0);
        }
        if wv.rank() != 2 || row != wv.shape()[0] {
            let mut shapes: Vec<&[usize]> = vals.iter().map(|x| x.shape()).collect();
            shapes.push(wv.shape());
            return Err(mismatch(
                "linear",
                &shapes,
                format!("the inputs' widths sum to {row}, the weight must be [{row}, out]"),
            ));
        }
        self.record_linear(terms, &refs, b, bv.as_ref(), act)
    }

    /// Computes and records a fused layer of checked terms.
    fn record_linear<'t>(
        &'t self,
        terms: Vec<LinearTerm>,
        refs: &[nnops::WeightRows<'_, T>],
        b: Option<Var<'t, T>>,
        bv: Option<&Tensor<T>>,
        act: Activation,
    ) -> Result<Var<'t, T>> {
        let y = k::linear_sum(refs, bv, act, None)?;
        let mut inputs: Vec<NodeId> = terms.iter().flat_map(|t| [t.x, t.w]).collect();
        inputs.extend(b.map(|b| b.id));
        Ok(self.record(y, Op::Linear { parts: terms, b: b.map(|b| b.id), col: 0, act }, &inputs))
    }

    /// Stacks equally shaped tensors along a new `axis`.
    pub fn stack<'t>(&'t self, xs: &[Var<'t, T>], axis: usize) -> Result<Var<'t, T>> {
        let first = xs.first().ok_or_else(|| invalid("stack", "needs at least one tensor"))?;
        let s0 = first.shape();
        if axis > s0.len() {
            return Err(check_axis("stack", axis, &s0).unwrap_err());
        }
        let mut ys = Vec::with_capacity(xs.len());
        for x in xs {
            if x.shape() != s0 {
                return Err(mismatch("stack", &[&s0, &x.shape()], "all tensors must have the same shape"));
            }
            ys.push(x.unsqueeze(axis)?);
        }
        self.cat(&ys, axis)
    }

    /// `mask ? a : b` element-wise; `a` and `b` broadcast, `mask` has the broadcast shape's
    /// element count (row-major).
    pub fn where_select<'t>(&'t self, mask: &[bool], a: Var<'t, T>, b: Var<'t, T>) -> Result<Var<'t, T>> {
        self.check_same(a);
        self.check_same(b);
        let (av, bv) = (a.value(), b.value());
        let shape = broadcast_shapes("where", av.shape(), bv.shape())?;
        if mask.len() != numel(&shape) {
            return Err(mismatch(
                "where",
                &[av.shape(), bv.shape()],
                format!("mask has {} entries, the broadcast shape {shape:?} needs {}", mask.len(), numel(&shape)),
            ));
        }
        let mask = Arc::new(mask.to_vec());
        let y = k::where_select(&mask, &shape, &av, &bv)?;
        Ok(self.record(y, Op::Where { a: a.id, b: b.id, mask }, &[a.id, b.id]))
    }
}
