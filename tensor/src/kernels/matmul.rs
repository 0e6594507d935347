//! Batched matrix products over the last two dims, with broadcasting of the batch dims and
//! transposed operands read through strides (no copies).
//!
//! Large matrices go through `faer::linalg::matmul::matmul` (single-threaded per call; rayon
//! splits batches or fixed blocks of rows). Tiny matrices — the 3x32 by 32x32 products of
//! the subequivariant layers — go through a direct loop, because a general matmul call per
//! 3x32 block costs more than the arithmetic.

use std::sync::OnceLock;

use faer::{Accum, MatMut, MatRef, Par};
use rayon::prelude::*;

use crate::element::Float;
use crate::error::{Result, mismatch};
use crate::shape::{broadcast_shapes, broadcast_strides, numel};
use crate::tensor::Tensor;

/// Products with fewer multiply-adds than this use the direct loop.
const SMALL_WORK: usize = 16 * 1024;
/// Smallest chunk of the inner dimension when a weight-gradient product is split along it.
const K_CHUNK: usize = 1024;

/// Smallest block (rows or columns) when one large product is split.
const MIN_BLOCK: usize = 64;

/// Block length for splitting an output side of length `len`: about an eighth of it (so up
/// to eight threads get work), a multiple of 16, at least [`MIN_BLOCK`], at most 512.
fn block_size(len: usize) -> usize {
    (len.div_ceil(8).div_ceil(16) * 16).clamp(MIN_BLOCK, 512)
}

/// One product `op(A) @ op(B)` over row-major storage: `op(A)` is `m x k` (`a` holds `A`,
/// or `A^T` when `ta`), `op(B)` is `k x n` (likewise with `tb`).
#[derive(Clone, Copy)]
struct Product<'a, T> {
    a: &'a [T],
    ta: bool,
    b: &'a [T],
    tb: bool,
    m: usize,
    k: usize,
    n: usize,
}

impl<'a, T: Float> Product<'a, T> {
    /// faer views of `op(A)` and `op(B)`; a transpose is a swap of strides, not a copy.
    fn views(&self) -> (MatRef<'a, T>, MatRef<'a, T>) {
        let (a, b, m, k, n) = (self.a, self.b, self.m, self.k, self.n);
        let lhs = if self.ta {
            MatRef::from_row_major_slice(a, k, m).transpose()
        } else {
            MatRef::from_row_major_slice(a, m, k)
        };
        let rhs = if self.tb {
            MatRef::from_row_major_slice(b, n, k).transpose()
        } else {
            MatRef::from_row_major_slice(b, k, n)
        };
        (lhs, rhs)
    }
}

/// The logical problem: `op(A)` is `m x k`, `op(B)` is `k x n`, per batch entry.
#[derive(Clone, Debug)]
pub struct MatMulPlan {
    /// Rows of the output.
    pub m: usize,
    /// Shared inner dimension.
    pub k: usize,
    /// Columns of the output.
    pub n: usize,
    /// Broadcast batch shape.
    pub batch: Vec<usize>,
    /// Per batch dim, the elements between consecutive matrices of A and of B along it (0
    /// where that operand is broadcast).
    strides: Vec<(usize, usize)>,
    /// Each batch entry's A and B offsets, listed on first use ([`MatMulPlan::offsets`]):
    /// a GPU product of regular offsets never needs the list.
    offsets: OnceLock<Vec<(usize, usize)>>,
}

impl MatMulPlan {
    /// Plans `op(a) @ op(b)` for stored shapes `a` and `b`.
    pub fn new(a: &[usize], b: &[usize], ta: bool, tb: bool) -> Result<Self> {
        if a.len() < 2 || b.len() < 2 {
            return Err(mismatch("matmul", &[a, b], "both operands need at least 2 dims"));
        }
        let (ar, ac) = (a[a.len() - 2], a[a.len() - 1]);
        let (br, bc) = (b[b.len() - 2], b[b.len() - 1]);
        let (m, k) = if ta { (ac, ar) } else { (ar, ac) };
        let (k2, n) = if tb { (bc, br) } else { (br, bc) };
        if k != k2 {
            return Err(mismatch(
                "matmul",
                &[a, b],
                format!("inner dims differ ({k} vs {k2}; transposes: {ta}, {tb})"),
            ));
        }
        let (ba, bb) = (&a[..a.len() - 2], &b[..b.len() - 2]);
        let batch = broadcast_shapes("matmul", ba, bb)
            .map_err(|_| mismatch("matmul", &[a, b], "batch dims do not broadcast"))?;
        let sa = broadcast_strides(ba, &batch);
        let sb = broadcast_strides(bb, &batch);
        let strides = sa.iter().zip(&sb).map(|(&x, &y)| (x * ar * ac, y * br * bc)).collect();
        Ok(Self { m, k, n, batch, strides, offsets: OnceLock::new() })
    }

    /// One product of matrices that start at offset 0 of both operands.
    pub fn single(m: usize, k: usize, n: usize) -> Self {
        Self { m, k, n, batch: vec![], strides: vec![], offsets: OnceLock::new() }
    }

    /// The number of batch entries (products).
    pub fn batches(&self) -> usize {
        numel(&self.batch)
    }

    /// Each batch entry's offsets (in elements) of its A and B matrices, in batch order.
    pub fn offsets(&self) -> &[(usize, usize)] {
        self.offsets.get_or_init(|| {
            let nb = self.batches();
            let mut offsets = Vec::with_capacity(nb);
            let mut idx = vec![0usize; self.batch.len()];
            for _ in 0..nb {
                let oa: usize = idx.iter().zip(&self.strides).map(|(i, s)| i * s.0).sum();
                let ob: usize = idx.iter().zip(&self.strides).map(|(i, s)| i * s.1).sum();
                offsets.push((oa, ob));
                for d in (0..self.batch.len()).rev() {
                    idx[d] += 1;
                    if idx[d] < self.batch[d] {
                        break;
                    }
                    idx[d] = 0;
                }
            }
            offsets
        })
    }

    /// `(sa, sb)` when batch entry `i`'s matrices start at `(i sa, i sb)` (every product of
    /// the models: batch dims that are contiguous or broadcast as a whole), without listing
    /// them; `None` when they do not.
    pub fn regular(&self) -> Option<(usize, usize)> {
        let linear = |stride: fn(&(usize, usize)) -> usize| {
            // The innermost batch dim of more than one entry fixes the step; every outer one
            // must then step by it times the entries inside.
            let mut step: Option<usize> = None;
            let mut inside = 1usize;
            for (d, &size) in self.batch.iter().enumerate().rev() {
                if size > 1 {
                    let s = stride(&self.strides[d]);
                    let unit = *step.get_or_insert(s);
                    if unit.checked_mul(inside) != Some(s) {
                        return None;
                    }
                }
                inside = inside.checked_mul(size)?;
            }
            Some(step.unwrap_or(0))
        };
        Some((linear(|s| s.0)?, linear(|s| s.1)?))
    }

    /// Output shape `[batch.., m, n]`.
    pub fn out_shape(&self) -> Vec<usize> {
        let mut s = self.batch.clone();
        s.extend([self.m, self.n]);
        s
    }
}

/// `op(a) @ op(b)` as a new tensor.
pub fn matmul<T: Float>(a: &Tensor<T>, b: &Tensor<T>, ta: bool, tb: bool) -> Result<Tensor<T>> {
    let plan = MatMulPlan::new(a.shape(), b.shape(), ta, tb)?;
    // Every element is written (not accumulated), so the buffer need not be cleared first.
    let mut out = crate::pool::for_overwrite(numel(&plan.out_shape()));
    matmul_into(&mut out, false, a.data(), ta, b.data(), tb, &plan);
    Ok(Tensor::from_parts(out, plan.out_shape()))
}

/// Writes (or, with `accumulate`, adds) `op(a) @ op(b)` into `out` following `plan`.
pub fn matmul_into<T: Float>(out: &mut [T], accumulate: bool, a: &[T], ta: bool, b: &[T], tb: bool, plan: &MatMulPlan) {
    matmul_into_then(out, accumulate, a, ta, b, tb, plan, None);
}

/// A pass over runs of whole output rows that [`matmul_into_then`] applies after the product.
pub type RowsPost<'a, T> = &'a (dyn Fn(&mut [T]) + Sync);

/// [`matmul_into`], then `post` applied to the finished output in runs of whole rows (each
/// row exactly once): for a large product split by rows, to each block right after it is
/// computed, while it is still in cache (a layer's bias and activation without another pass
/// over memory).
#[allow(clippy::too_many_arguments)]
pub fn matmul_into_then<T: Float>(
    out: &mut [T],
    accumulate: bool,
    a: &[T],
    ta: bool,
    b: &[T],
    tb: bool,
    plan: &MatMulPlan,
    post: Option<RowsPost<'_, T>>,
) {
    let (m, k, n) = (plan.m, plan.k, plan.n);
    let mn = m * n;
    if mn == 0 {
        return;
    }
    let work = m * n * k;
    let one = |o: &mut [T], &(oa, ob): &(usize, usize)| {
        let am = &a[oa..oa + m * k];
        let bm = &b[ob..ob + k * n];
        if work < SMALL_WORK {
            small_matmul(o, accumulate, Product { a: am, ta, b: bm, tb, m, k, n });
        } else {
            faer_matmul(o, accumulate, Product { a: am, ta, b: bm, tb, m, k, n }, 0, m);
        }
    };
    let nb = plan.batches();
    if nb > 1 && work * nb >= 1 << 16 {
        out.par_chunks_mut(mn).zip(plan.offsets().par_iter()).for_each(|(o, off)| one(o, off));
    } else if nb == 1 && work >= 1 << 22 && ta && !tb && inner_split_suits(m, k, n) {
        // A^T B with a small result and a long inner dim (weight gradients x^T g): split the
        // inner dim into fixed chunks, one partial product each, summed in chunk order. The
        // chunking depends only on the shape, so the bits do not depend on the thread count.
        let (oa, ob) = plan.offsets()[0];
        let chunks = (k / K_CHUNK).clamp(1, 8);
        let chunks = 1 << chunks.ilog2(); // a power of two: even work for 2, 4 or 8 threads
        let chunk = k.div_ceil(chunks);
        let parts: Vec<Vec<T>> = (0..k.div_ceil(chunk))
            .into_par_iter()
            .map(|c| {
                let (k0, kc) = (c * chunk, chunk.min(k - c * chunk));
                let mut part = crate::pool::zeros(m * n);
                let (a_rows, b_rows) = (&a[oa + k0 * m..oa + (k0 + kc) * m], &b[ob + k0 * n..ob + (k0 + kc) * n]);
                faer_matmul(&mut part, false, Product { a: a_rows, ta: true, b: b_rows, tb: false, m, k: kc, n }, 0, m);
                part
            })
            .collect();
        for (i, part) in parts.into_iter().enumerate() {
            if i == 0 && !accumulate {
                out.copy_from_slice(&part);
            } else {
                out.iter_mut().zip(&part).for_each(|(o, &p)| *o += p);
            }
            crate::pool::recycle(part);
        }
    } else if nb == 1 && work >= 1 << 22 && ta && !tb && m >= 4 * n && k >= 4 * m {
        // A^T B with a tall, thin result and a long inner dim (weight gradients x^T g of wide
        // inputs): faer is several times faster on the transposed problem B^T A, so compute
        // that ([n, m]) and transpose it into place.
        let (oa, ob) = plan.offsets()[0];
        let t_plan = MatMulPlan::single(n, k, m);
        let mut tmp = crate::pool::for_overwrite(m * n);
        matmul_into(&mut tmp, false, &b[ob..ob + k * n], true, &a[oa..oa + k * m], false, &t_plan);
        for i in 0..m {
            for j in 0..n {
                let v = tmp[j * m + i];
                if accumulate {
                    out[i * n + j] += v;
                } else {
                    out[i * n + j] = v;
                }
            }
        }
        crate::pool::recycle(tmp);
    } else if nb == 1 && work >= 1 << 22 && m.max(n) >= 2 * MIN_BLOCK {
        // One large product: split the longer output side into fixed blocks (a function of
        // the shape only) computed in parallel, each by one single-threaded faer call.
        let (oa, ob) = plan.offsets()[0];
        let (am, bm) = (&a[oa..oa + m * k], &b[ob..ob + k * n]);
        if m >= n {
            let rb = block_size(m);
            out.par_chunks_mut(rb * n).enumerate().for_each(|(blk, o)| {
                faer_matmul(o, accumulate, Product { a: am, ta, b: bm, tb, m, k, n }, blk * rb, o.len() / n);
                if let Some(post) = post {
                    post(o);
                }
            });
            return;
        }
        matmul_col_blocks(out, accumulate, Product { a: am, ta, b: bm, tb, m, k, n }, block_size(n));
    } else {
        out.chunks_mut(mn).zip(plan.offsets().iter()).for_each(|(o, off)| one(o, off));
    }
    if let Some(post) = post {
        // Runs of whole rows (of length n), in parallel when large.
        let run = n * (super::PAR_CHUNK / n).max(1);
        if out.len() >= super::PAR_MIN {
            out.par_chunks_mut(run).for_each(post);
        } else {
            post(out);
        }
    }
}

/// Whether an `A^T B` product with an `m x n` result and inner dim `k` is split along `k`
/// (fixed chunks, partial products summed) rather than along its output: a small result
/// with an inner dim at least 8 times its longer side, or a short, wide result (up to 128
/// rows, at least 4 times as many columns, at most 2^17 elements) with an inner dim at least
/// 4 times its width. Measured on the weight gradient `X^T G` of a `[10240, 64] x [64, 1024]`
/// layer (`matmul_rate`'s `dw`): 329 GFLOP/s split along k, 296 split into column blocks.
fn inner_split_suits(m: usize, k: usize, n: usize) -> bool {
    let small = m.max(n) <= 512 && k >= 8 * m.max(n);
    let short_wide = m <= 128 && n >= 4 * m && m * n <= 1 << 17 && k >= 4 * n;
    small || short_wide
}

/// A pointer that may cross threads; each thread writes a disjoint block through it.
#[derive(Clone, Copy)]
struct SendPtr<T>(*mut T);
// SAFETY: a `SendPtr` is only made from a live `&mut [T]` whose owner waits for the
// parallel scope to end, and each thread writes a block disjoint from every other's.
unsafe impl<T> Send for SendPtr<T> {}
// SAFETY: as for `Send`: shared only to hand each thread its own disjoint block.
unsafe impl<T> Sync for SendPtr<T> {}

impl<T> SendPtr<T> {
    /// The pointer (a method, so closures capture the whole `SendPtr`, which is `Send`).
    fn get(self) -> *mut T {
        self.0
    }
}

/// `op(A) @ op(B)` split into fixed blocks of columns computed in parallel (for outputs
/// with few rows and many columns, such as weight gradients `x^T g`). Each output element
/// is computed by one thread, so the result does not depend on the thread count.
fn matmul_col_blocks<T: Float>(out: &mut [T], accumulate: bool, p: Product<'_, T>, cb: usize) {
    let (m, n) = (p.m, p.n);
    assert_eq!(out.len(), m * n);
    let (lhs, rhs) = p.views();
    let ptr = SendPtr(out.as_mut_ptr());
    let accum = if accumulate { Accum::Add } else { Accum::Replace };
    (0..n.div_ceil(cb)).into_par_iter().for_each(|blk| {
        let c0 = blk * cb;
        let nc = cb.min(n - c0);
        // SAFETY: `out` holds m x n elements in row-major order and outlives this scope; block
        // `blk` covers columns c0..c0+nc of every row, disjoint from every other block, so no
        // two threads write the same element and nothing else reads `out` meanwhile.
        let dst: MatMut<'_, T> = unsafe { MatMut::from_raw_parts_mut(ptr.get().add(c0), m, nc, n as isize, 1) };
        faer::linalg::matmul::matmul(dst, accum, lhs, rhs.subcols(c0, nc), T::ONE, Par::Seq);
    });
}

/// Rows `r0..r0+rows` of `op(A) @ op(B)` through faer, single-threaded.
fn faer_matmul<T: Float>(out: &mut [T], accumulate: bool, p: Product<'_, T>, r0: usize, rows: usize) {
    let n = p.n;
    let (lhs, rhs) = p.views();
    let lhs = lhs.subrows(r0, rows);
    let dst: MatMut<'_, T> = MatMut::from_row_major_slice_mut(out, rows, n);
    let accum = if accumulate { Accum::Add } else { Accum::Replace };
    faer::linalg::matmul::matmul(dst, accum, lhs, rhs, T::ONE, Par::Seq);
}

/// Widest output row [`small_matmul`] accumulates on the stack.
const ROW_ACC: usize = 64;

/// Direct loops for tiny products; the inner loop runs over contiguous memory.
fn small_matmul<T: Float>(out: &mut [T], accumulate: bool, p: Product<'_, T>) {
    let Product { a, ta, b, tb, m, k, n } = p;
    if m == 0 || n == 0 {
        return;
    }
    let a_at = |i: usize, p: usize| if ta { a[p * m + i] } else { a[i * k + p] };
    if !tb {
        // out[i, :] (+)= sum_p a[i, p] * b[p, :]. Rows up to ROW_ACC wide are summed on the
        // stack and stored once (the same additions in the same order as in place).
        let add_row = |acc: &mut [T], i: usize| {
            for (p, br) in b.chunks_exact(n).enumerate().take(k) {
                let s = a_at(i, p);
                acc.iter_mut().zip(br).for_each(|(o, &bv)| *o += s * bv);
            }
        };
        match n {
            16 => return add_rows_fixed::<T, 16>(out, accumulate, a_at, b, m, k),
            32 => return add_rows_fixed::<T, 32>(out, accumulate, a_at, b, m, k),
            64 => return add_rows_fixed::<T, 64>(out, accumulate, a_at, b, m, k),
            _ => {}
        }
        let rows = out.chunks_exact_mut(n).enumerate().take(m);
        if n <= ROW_ACC {
            let mut stack = [T::ZERO; ROW_ACC];
            let acc = &mut stack[..n];
            for (i, row) in rows {
                if accumulate {
                    acc.copy_from_slice(row);
                } else {
                    acc.fill(T::ZERO);
                }
                add_row(acc, i);
                row.copy_from_slice(acc);
            }
        } else {
            for (i, row) in rows {
                if !accumulate {
                    row.fill(T::ZERO);
                }
                add_row(row, i);
            }
        }
        return;
    }
    if !ta && super::simd::rows_dot(out, accumulate, a, b, m, k, n) {
        return;
    }
    if !accumulate {
        out[..m * n].iter_mut().for_each(|v| *v = T::ZERO);
    }
    // op(B) = B^T from here on.
    if !ta {
        // out[i, j] += dot(a[i, :], b[j, :])
        for i in 0..m {
            let ar = &a[i * k..(i + 1) * k];
            for j in 0..n {
                out[i * n + j] += dot(ar, &b[j * k..(j + 1) * k]);
            }
        }
    } else {
        for i in 0..m {
            for j in 0..n {
                let mut acc = T::ZERO;
                for p in 0..k {
                    acc += a[p * m + i] * b[j * k + p];
                }
                out[i * n + j] += acc;
            }
        }
    }
}

/// `out[i, :] (+)= sum_p a(i, p) * b[p, :]` for rows of a fixed width `W`: the row's
/// accumulator is a fixed-size array, which the compiler keeps in vector registers (a slice
/// accumulator goes through the stack, a store-to-load round trip per step). The additions
/// are the same, in the same order, as in the general loop.
#[inline(always)]
fn add_rows_fixed<T: Float, const W: usize>(
    out: &mut [T],
    accumulate: bool,
    a_at: impl Fn(usize, usize) -> T,
    b: &[T],
    m: usize,
    k: usize,
) {
    for (i, row) in out.chunks_exact_mut(W).enumerate().take(m) {
        let mut acc = [T::ZERO; W];
        if accumulate {
            acc.copy_from_slice(row);
        }
        for (p, br) in b.chunks_exact(W).enumerate().take(k) {
            let br: &[T; W] = br.try_into().expect("chunks of W");
            let s = a_at(i, p);
            for l in 0..W {
                acc[l] += s * br[l];
            }
        }
        row.copy_from_slice(&acc);
    }
}

/// Dot product with eight interleaved partial sums (a fixed order, so it vectorises and stays
/// deterministic).
#[inline(always)]
fn dot<T: Float>(a: &[T], b: &[T]) -> T {
    let mut acc = [T::ZERO; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    let mut s = ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for (&x, &y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// Whether [`small_batched_backward`] handles a product of these stored shapes: rank-3
/// operands with the same batch length (no broadcasting) and tiny matrices.
pub fn fused_small_backward_applies(a: &[usize], b: &[usize], ta: bool, tb: bool) -> bool {
    if a.len() != 3 || b.len() != 3 || a[0] != b[0] || a[0] < 2 {
        return false;
    }
    let (m, k) = if ta { (a[2], a[1]) } else { (a[1], a[2]) };
    let n = if tb { b[1] } else { b[2] };
    m * n * k < SMALL_WORK
}

/// Gradients of a batch of tiny products `C_i = op(A_i) op(B_i)` given `G_i = dL/dC_i`, in one
/// pass over the batch: `dA` into `da.0` and `dB` into `db.0` (either may be absent when its
/// operand wants no gradient), each added to the buffer when its flag is set and written over
/// it otherwise. When `A` and `B` are the same tensor (`same`), both contributions go to `da`
/// and `db` must be `None`.
#[allow(clippy::too_many_arguments)]
pub fn small_batched_backward<T: Float>(
    g: &[T],
    a: &[T],
    ta: bool,
    b: &[T],
    tb: bool,
    a_shape: &[usize],
    b_shape: &[usize],
    da: Option<(&mut [T], bool)>,
    db: Option<(&mut [T], bool)>,
    same: bool,
) {
    let (m, k) = if ta { (a_shape[2], a_shape[1]) } else { (a_shape[1], a_shape[2]) };
    let n = if tb { b_shape[1] } else { b_shape[2] };
    let (la, lb, lg) = (m * k, k * n, m * n);
    // dA (stored layout) and dB (stored layout) of one batch entry.
    let grad_a = |out: &mut [T], acc: bool, gi: &[T], bi: &[T]| {
        if !ta {
            small_matmul(out, acc, Product { a: gi, ta: false, b: bi, tb: !tb, m, k: n, n: k });
        } else {
            small_matmul(out, acc, Product { a: bi, ta: tb, b: gi, tb: true, m: k, k: n, n: m });
        }
    };
    let grad_b = |out: &mut [T], acc: bool, gi: &[T], ai: &[T]| {
        if !tb {
            small_matmul(out, acc, Product { a: ai, ta: !ta, b: gi, tb: false, m: k, k: m, n });
        } else {
            small_matmul(out, acc, Product { a: gi, ta: true, b: ai, tb: ta, m: n, k: m, n: k });
        }
    };
    match (da, db) {
        (Some((da, acc_a)), Some((db, acc_b))) => {
            da.par_chunks_mut(la).zip(db.par_chunks_mut(lb)).enumerate().for_each(|(i, (oa, ob))| {
                let gi = &g[i * lg..(i + 1) * lg];
                grad_a(oa, acc_a, gi, &b[i * lb..(i + 1) * lb]);
                grad_b(ob, acc_b, gi, &a[i * la..(i + 1) * la]);
            });
        }
        (Some((da, acc_a)), None) if same => {
            // A and B are the same tensor: both contributions to the same block.
            da.par_chunks_mut(la).enumerate().for_each(|(i, oa)| {
                let gi = &g[i * lg..(i + 1) * lg];
                let xi = &a[i * la..(i + 1) * la];
                grad_a(oa, acc_a, gi, xi);
                grad_b(oa, true, gi, xi);
            });
        }
        (Some((da, acc_a)), None) => {
            da.par_chunks_mut(la).enumerate().for_each(|(i, oa)| {
                grad_a(oa, acc_a, &g[i * lg..(i + 1) * lg], &b[i * lb..(i + 1) * lb]);
            });
        }
        (None, Some((db, acc_b))) => {
            db.par_chunks_mut(lb).enumerate().for_each(|(i, ob)| {
                grad_b(ob, acc_b, &g[i * lg..(i + 1) * lg], &a[i * la..(i + 1) * la]);
            });
        }
        (None, None) => {}
    }
}

#[cfg(test)]
mod tests {
    use super::MatMulPlan;

    /// A's shape, B's shape, and the strides `regular` should find (or none).
    type Case = (&'static [usize], &'static [usize], Option<(usize, usize)>);

    /// The offsets `new` plans, as `offsets` lists them (entry `idx`, row-major over the batch
    /// shape, starts at the sum of `idx` times each operand's broadcast stride).
    fn listed(a: &[usize], b: &[usize], ta: bool, tb: bool) -> Vec<(usize, usize)> {
        MatMulPlan::new(a, b, ta, tb).unwrap().offsets().to_vec()
    }

    #[test]
    fn regular_offsets_are_recognised_and_match_the_list() {
        let cases: [Case; 7] = [
            (&[7, 3, 32], &[7, 32, 32], Some((96, 1024))),
            (&[7, 3, 32], &[32, 32], Some((96, 0))),
            (&[32, 3], &[7, 3, 5], Some((0, 15))),
            (&[2, 3, 4, 5], &[2, 3, 5, 6], Some((20, 30))),
            (&[2, 1, 4, 5], &[2, 3, 5, 6], None),
            (&[2, 1, 4, 5], &[1, 3, 5, 6], None),
            (&[1, 3, 4, 5], &[2, 1, 5, 6], None),
        ];
        for (a, b, want) in cases {
            let plan = MatMulPlan::new(a, b, false, false).unwrap();
            assert_eq!(plan.regular(), want, "{a:?} x {b:?}");
            assert_eq!(plan.offsets().len(), plan.batches());
            if let Some((sa, sb)) = want {
                let by_stride: Vec<_> = (0..plan.batches()).map(|i| (i * sa, i * sb)).collect();
                assert_eq!(plan.offsets(), &by_stride[..], "{a:?} x {b:?}");
            }
        }
        // A batch dim of one entry between others does not break regularity.
        assert_eq!(
            MatMulPlan::new(&[2, 1, 3, 4, 5], &[2, 1, 3, 5, 6], false, false).unwrap().regular(),
            Some((20, 30))
        );
        // The broadcast cases' lists, by hand: A repeats along the second batch dim.
        assert_eq!(
            listed(&[2, 1, 4, 5], &[2, 3, 5, 6], false, false),
            [(0, 0), (0, 30), (0, 60), (20, 90), (20, 120), (20, 150)]
        );
        assert_eq!(MatMulPlan::single(4, 5, 6).offsets(), &[(0, 0)]);
        assert_eq!(MatMulPlan::single(4, 5, 6).regular(), Some((0, 0)));
    }
}
