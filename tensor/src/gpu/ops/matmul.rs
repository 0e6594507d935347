//! Matrix products on the device: batched `op(a) @ op(b)` with broadcast batch dims and
//! transposed operands read through strides (as `kernels/matmul.rs` on the CPU), with an
//! optional fused epilogue (bias and activation), and the fused layer [`linear_sum`] (as
//! `kernels/nnops.rs`).
//!
//! One tiled kernel (`wgsl/matmul.wgsl`): 64 x 64 output tiles per workgroup of 16 x 16
//! threads, 4 x 4 outputs per thread, the inner dim in steps of 16 through workgroup memory;
//! or, with the tile [`MatMulTile::Rows128`] configured ([`crate::device::GpuConfig`]), 128 x 64 tiles of 8 x 4 outputs
//! per thread for the products with enough of them ([`Route::tiled`]; the same bits: each
//! output's sum is the same sequence of fused multiply-adds).
//! Batched products of small matrices (each entry's output at most a quarter of a tile, k at
//! most 64: the subequivariant layers' Gram matrices and vector mixings) go to
//! `wgsl/matmul_small.wgsl`, one thread per output, which gives the tiled kernel's bits.
//! Batch entries at regular offsets (every product of the models) pass them as two strides
//! in the parameters instead of an uploaded list.
//! Each output element is summed by one thread over k in increasing order, so a product has
//! the same bits on every run (on the same GPU and driver). A product of few output tiles
//! over a long inner dim (the weight gradients `x^T g`: a 256 x 256 output over 5120 rows is
//! 16 tiles for a GPU of 132 multiprocessors) splits k into slices ([`split_k`], a function
//! of the shapes alone), each a workgroup per tile writing partial sums, then
//! `matmul_reduce.wgsl` adds the slices in order and applies the epilogue.

use super::{kernel, u};
use crate::device::MatMulTile;
use crate::gpu::context::Kernel;
use crate::gpu::{DeviceBuffer, device};
use crate::kernels::matmul::MatMulPlan;
use crate::op::Activation;

const MATMUL: Kernel = kernel!("matmul", "matmul_activation.wgsl", "matmul_tile_64.wgsl", "matmul.wgsl");
const MATMUL_TALL: Kernel = kernel!("matmul_tall", "matmul_activation.wgsl", "matmul_tile_128.wgsl", "matmul.wgsl");
const MATMUL_REDUCE: Kernel = kernel!("matmul_reduce", "matmul_activation.wgsl", "matmul_reduce.wgsl");
const MATMUL_SMALL: Kernel = kernel!("matmul_small", "matmul_activation.wgsl", "matmul_small.wgsl");

/// Output rows of the 64 x 64 tile (`TILE_M` in `matmul.wgsl` with `matmul_tile_64.wgsl`),
/// which also decides a product's split of k ([`split_k`]) and the small-matrix kernel's
/// limit, whichever tile computes it.
const TILE_M: usize = 64;
/// Output columns of the tile one workgroup computes (`TILE_N` in `matmul.wgsl`).
const TILE_N: usize = 64;

/// Workgroups a product should launch to fill a large GPU (about two per multiprocessor of
/// the biggest ones): a product of fewer output tiles over a long inner dim splits k.
const TARGET_GROUPS: usize = 256;
/// The shortest run of k one slice of a split product sums (16 steps of `TILE_K`).
const MIN_K_PER_SLICE: usize = 256;
/// `TILE_K` in `matmul.wgsl`: slices start at multiples of it.
const TILE_K: usize = 16;

/// The split of the inner dim of a product of `groups` output tiles: `(slices,
/// k_per_slice)`, one slice (no split) unless the tiles are too few to fill the GPU and k is
/// long enough to give each slice at least [`MIN_K_PER_SLICE`]. A function of the shapes
/// alone, so a product's order of summation, and its bits, are the same on every run.
fn split_k(groups: usize, k: usize) -> (usize, usize) {
    let want = TARGET_GROUPS.div_ceil(groups.max(1)).min(k / MIN_K_PER_SLICE);
    if want <= 1 {
        return (1, k.max(1));
    }
    let per = k.div_ceil(want).next_multiple_of(TILE_K);
    (k.div_ceil(per), per)
}

/// The kernel computing tiles of `tile`'s size.
fn tile_kernel(tile: MatMulTile) -> &'static Kernel {
    match tile {
        MatMulTile::Rows64 => &MATMUL,
        MatMulTile::Rows128 => &MATMUL_TALL,
    }
}

/// The tile asked for ([`Route::tiled`] decides per product): the process's
/// [`crate::device::GpuConfig::matmul_tile`].
fn tile() -> MatMulTile {
    crate::device::gpu_config().matmul_tile
}

/// The largest output of one batch entry (`m * n`) the small-matrix kernel takes: a quarter
/// of a tile (fewer would leave most of a tile's threads idle).
const SMALL_OUTPUT: usize = TILE_M * TILE_N / 4;
/// The longest inner dim the small-matrix kernel takes (one thread sums all of k).
const SMALL_K: usize = 64;

/// Whether a product of `m x k` by `k x n` matrices goes to `matmul_small.wgsl` (one thread
/// per output) rather than the tiled kernel.
fn is_small(m: usize, k: usize, n: usize) -> bool {
    m * n <= SMALL_OUTPUT && k <= SMALL_K
}

/// Where each batch entry's matrices start, for the kernels: `(a_base, b_base, a_stride,
/// b_stride)` when the offsets are regular (`b * stride`: every batched product of the
/// models, broadcast or not; `regular` is [`MatMulPlan::regular`], no list made), with no
/// buffer; otherwise the listed offsets, uploaded. `b`'s matrices start `b_base` elements
/// into its buffer (a block of rows of a weight).
fn batch_offsets(
    plan: &MatMulPlan,
    regular: Option<(usize, usize)>,
    b_base: usize,
) -> ([u32; 4], Option<DeviceBuffer>) {
    if let Some((sa, sb)) = regular
        && plan.batches().checked_mul(sa.max(sb)).is_some_and(|end| end.saturating_add(b_base) < u32::MAX as usize)
    {
        return ([0, u(b_base), u(sa), u(sb)], None);
    }
    let list: Vec<u32> = plan.offsets().iter().flat_map(|&(oa, ob)| [u(oa), u(b_base + ob)]).collect();
    ([0; 4], Some(DeviceBuffer::upload_u32(&list)))
}

/// A product kernel's buffers: its four inputs, then `dst`, the one it writes.
fn with_output<'a>(inputs: [&'a wgpu::Buffer; 4], dst: &'a DeviceBuffer) -> [&'a wgpu::Buffer; 5] {
    let [a, b, offsets, bias] = inputs;
    [a, b, offsets, bias, dst.buffer()]
}

/// The kernel's code of an activation (`activation` in `matmul.wgsl`).
fn activation_code(act: Activation) -> u32 {
    match act {
        Activation::Identity => 0,
        Activation::Relu => 1,
        Activation::Tanh => 2,
    }
}

/// Writes (or, with `accumulate`, adds to `out`'s current values) `op(a) @ op(b)` following
/// `plan` (`op(a)` is `a` or, with `ta`, its transpose read through strides; likewise `b`),
/// then, when given, the epilogue: `+ bias` (an `[n]` buffer added to every row) and `act`,
/// applied to the final sum. `out` holds `plan.out_shape()` values.
#[allow(clippy::too_many_arguments)]
pub(crate) fn matmul_into(
    out: &DeviceBuffer,
    accumulate: bool,
    a: &DeviceBuffer,
    ta: bool,
    b: &DeviceBuffer,
    tb: bool,
    plan: &MatMulPlan,
    bias: Option<&DeviceBuffer>,
    act: Activation,
) {
    let (out, b, bias) = (Placed::whole(out), Placed::whole(b), bias.map(Placed::whole));
    matmul_into_with(Route::of(plan), out, accumulate, a, ta, b, tb, plan, bias, act);
}

/// A matrix inside a buffer: it starts at element `base` and its stored rows are `ld`
/// elements apart (`None`: its own width, i.e. packed). A block of rows of a row-major
/// weight is `base` = first row times the width; a block of columns also has `ld` = the
/// weight's width. Read or written in place, without copying the block out or back.
#[derive(Clone, Copy)]
pub(crate) struct Placed<'a> {
    /// The buffer.
    pub buf: &'a DeviceBuffer,
    /// The first element.
    pub base: usize,
    /// The elements between stored rows, when not the matrix's own width.
    pub ld: Option<usize>,
}

impl<'a> Placed<'a> {
    /// The whole buffer, packed from element 0.
    pub(crate) fn whole(buf: &'a DeviceBuffer) -> Self {
        Self { buf, base: 0, ld: None }
    }

    /// Packed from element `base`.
    pub(crate) fn at(buf: &'a DeviceBuffer, base: usize) -> Self {
        Self { buf, base, ld: None }
    }

    /// From element `base`, stored rows `ld` elements apart.
    pub(crate) fn block(buf: &'a DeviceBuffer, base: usize, ld: usize) -> Self {
        Self { buf, base, ld: Some(ld) }
    }
}

/// [`matmul_into`] with `b` (and the bias) read from, and the output written to, the blocks
/// [`Placed`] says (one product: a plan of one batch entry when a row stride is given): the
/// products of a layer that multiply blocks of its weight, and the gradients of those
/// blocks, without copying the blocks out or back.
#[allow(clippy::too_many_arguments)]
pub(crate) fn matmul_into_at(
    out: Placed<'_>,
    accumulate: bool,
    a: &DeviceBuffer,
    ta: bool,
    b: Placed<'_>,
    tb: bool,
    plan: &MatMulPlan,
    bias: Option<Placed<'_>>,
    act: Activation,
) {
    matmul_into_with(Route::of(plan), out, accumulate, a, ta, b, tb, plan, bias, act);
}

/// Which kernel computes a product.
#[derive(Clone, Copy, Debug)]
enum Route {
    /// `matmul_small.wgsl`, one thread per output.
    Small,
    /// `matmul.wgsl` with this tile.
    Tiled(MatMulTile),
}

impl Route {
    /// The small-matrix kernel for small products ([`is_small`]), else the tiled one with
    /// the tile of [`tile`] (see [`Route::tiled`]).
    fn of(plan: &MatMulPlan) -> Self {
        if is_small(plan.m, plan.k, plan.n) {
            Route::Small
        } else {
            Route::tiled(tile(), plan.m, plan.k, plan.n, plan.batches())
        }
    }

    /// The tiled kernel with `chosen`, except that the 128-row tile is taken only where it
    /// still gives [`TARGET_GROUPS`] workgroups and k is not split: a split product (few
    /// tiles, long k: the weight gradients) or a short one would launch half the
    /// workgroups, too few to fill a large GPU. The same bits either way.
    fn tiled(chosen: MatMulTile, m: usize, k: usize, n: usize, batches: usize) -> Self {
        let tiles_n = n.div_ceil(TILE_N);
        let split = split_k(m.div_ceil(TILE_M) * tiles_n * batches, k).0 > 1;
        let tall_groups = m.div_ceil(MatMulTile::Rows128.rows()) * tiles_n * batches;
        let tile = if chosen == MatMulTile::Rows128 && !split && tall_groups >= TARGET_GROUPS {
            MatMulTile::Rows128
        } else {
            MatMulTile::Rows64
        };
        Route::Tiled(tile)
    }
}

/// [`matmul_into_at`] on the kernel `route` names.
#[allow(clippy::too_many_arguments)]
fn matmul_into_with(
    route: Route,
    out: Placed<'_>,
    accumulate: bool,
    a: &DeviceBuffer,
    ta: bool,
    b: Placed<'_>,
    tb: bool,
    plan: &MatMulPlan,
    bias: Option<Placed<'_>>,
    act: Activation,
) {
    let (m, k, n) = (plan.m, plan.k, plan.n);
    let batches = plan.batches();
    // The stored b is [k, n] (or [n, k] with tb): its rows' stride, and the output's.
    let (b_rows, b_cols) = if tb { (n, k) } else { (k, n) };
    let (ldb, ldo) = (b.ld.unwrap_or(b_cols), out.ld.unwrap_or(n));
    assert!(ldb >= b_cols && ldo >= n, "matmul: a row stride shorter than the rows");
    assert!(batches == 1 || (ldb == b_cols && ldo == n), "matmul: row strides are for one product");
    // The extent of a (possibly strided) matrix of `rows x cols`.
    let extent = |rows: usize, cols: usize, ld: usize| if rows == 0 || cols == 0 { 0 } else { (rows - 1) * ld + cols };
    let (out, out_base, b, b_base) = (out.buf, out.base, b.buf, b.base);
    let out_end = if batches == 1 { extent(m, n, ldo) } else { batches * m * n };
    assert!(out_base + out_end <= out.len(), "matmul: the output holds the plan's output shape");
    let fits = |(oa, ob): (usize, usize)| oa + m * k <= a.len() && b_base + ob + extent(b_rows, b_cols, ldb) <= b.len();
    let strides = plan.regular();
    match strides {
        // Regular offsets grow with the entry: the last one is the furthest.
        Some((sa, sb)) => assert!(
            batches == 0 || fits(((batches - 1) * sa, (batches - 1) * sb)),
            "matmul: operands smaller than the plan"
        ),
        None => assert!(plan.offsets().iter().all(|&o| fits(o)), "matmul: operands smaller than the plan"),
    }
    if let Some(bias) = bias {
        assert!(bias.base + n <= bias.buf.len(), "matmul: the bias holds one value per output column");
    }
    let has_bias = bias.is_some();
    let bias_base = bias.map_or(0, |b| b.base);
    let tiles_n = n.div_ceil(TILE_N);
    // The split of k counts 64 x 64 tiles whichever tile computes the product: the same
    // slices, so the same bits.
    let groups = m.div_ceil(TILE_M) * tiles_n * batches;
    if groups == 0 {
        return;
    }
    // Regular offsets (always, in the models) go in the parameters: no upload.
    let (regular, listed) = batch_offsets(plan, strides, b_base);
    // Without a bias (or listed offsets) the kernel reads none: any buffer that is not the
    // output fills the slot.
    let offsets = listed.as_ref().unwrap_or(a);
    let bias = bias.map_or(a, |b| b.buf);
    // The kernels' buffers: these inputs, then the one they write.
    let inputs = [a.buffer(), b.buffer(), offsets.buffer(), bias.buffer()];
    // The parameters both kernels share (matmul_small.wgsl's whole list, the head of
    // matmul.wgsl's).
    let shared = [
        u(m),
        u(k),
        u(n),
        u32::from(ta),
        u32::from(tb),
        u32::from(accumulate),
        u32::from(has_bias),
        activation_code(act),
        u(batches),
        regular[0],
        regular[1],
        regular[2],
        regular[3],
        u32::from(listed.is_some()),
        u(out_base),
        u(ldb),
        u(ldo),
        u(bias_base),
    ];
    let total = batches * m * n;
    let tile = match route {
        Route::Small => {
            device().launch_1d(&MATMUL_SMALL, &shared, &with_output(inputs, out), total);
            return;
        }
        Route::Tiled(tile) => tile,
    };
    let per_batch = m.div_ceil(tile.rows()) * tiles_n;
    let (slices, k_per_slice) = split_k(groups, k);
    if slices == 1 {
        let params = [&shared[..], &[u(tiles_n), u(per_batch), u(slices), u(k_per_slice)]].concat();
        device().launch(tile_kernel(tile), &params, &with_output(inputs, out), u(per_batch * batches));
        return;
    }
    // Split k: the slices' partial sums (packed from element 0 of their own buffer), then
    // their sum in order with the epilogue, written where `out` says.
    let mut params = [&shared[..], &[u(tiles_n), u(per_batch), u(slices), u(k_per_slice)]].concat();
    params[OUT_BASE] = 0;
    params[OUT_LD] = u(n);
    let parts = DeviceBuffer::uninit(slices * total);
    device().launch(tile_kernel(tile), &params, &with_output(inputs, &parts), u(per_batch * batches * slices));
    let params = [
        u(total),
        u(n),
        u(slices),
        u32::from(accumulate),
        u32::from(has_bias),
        activation_code(act),
        u(out_base),
        u(ldo),
        u(bias_base),
    ];
    device().launch_1d(&MATMUL_REDUCE, &params, &[parts.buffer(), bias.buffer(), out.buffer()], total);
}

/// The index of `out_base` in the kernels' shared parameters.
const OUT_BASE: usize = 14;
/// The index of the output's row stride in the kernels' shared parameters.
const OUT_LD: usize = 16;

/// `op(a) @ op(b)` following `plan`, as a new buffer of `plan.out_shape()` values.
pub(crate) fn matmul(a: &DeviceBuffer, ta: bool, b: &DeviceBuffer, tb: bool, plan: &MatMulPlan) -> DeviceBuffer {
    let out = DeviceBuffer::uninit(plan.batches() * plan.m * plan.n);
    matmul_into(&out, false, a, ta, b, tb, plan, None, Activation::Identity);
    out
}

/// One product of [`linear_sum`]: `x`, a `[rows, k]` buffer, times the `[k, n]` block of a
/// weight that `w` places (rows and columns of a weight, read in place).
pub(crate) struct Term<'a> {
    /// The input.
    pub x: &'a DeviceBuffer,
    /// Its width.
    pub k: usize,
    /// The weight's block.
    pub w: Placed<'a>,
}

/// `act(sum_i x_i @ w_i + bias)` as a new `[rows, n]` buffer for the [`Term`]s `(x_i, w_i)`.
/// The first product writes the output, later ones add to it, and the bias (`n` values
/// from where it is placed) and activation are applied after the last (as
/// `kernels::nnops::linear_sum`). Panics without terms.
pub(crate) fn linear_sum(
    terms: &[Term<'_>],
    rows: usize,
    n: usize,
    bias: Option<Placed<'_>>,
    act: Activation,
) -> DeviceBuffer {
    assert!(!terms.is_empty(), "linear_sum: needs at least one (x, w) part");
    let out = DeviceBuffer::uninit(rows * n);
    let last = terms.len() - 1;
    for (i, t) in terms.iter().enumerate() {
        let plan = MatMulPlan::single(rows, t.k, n);
        let (bias, act) = if i == last { (bias, act) } else { (None, Activation::Identity) };
        matmul_into_at(Placed::whole(&out), i > 0, t.x, false, t.w, false, &plan, bias, act);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::matmul as cpu;
    use crate::kernels::nnops;
    use crate::tensor::Tensor;

    /// Deterministic values in [-1, 1) (xorshift64*).
    fn values(len: usize, seed: u64) -> Vec<f32> {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..len)
            .map(|_| {
                s ^= s >> 12;
                s ^= s << 25;
                s ^= s >> 27;
                let r = s.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40; // 24 bits
                r as f32 / (1u32 << 23) as f32 - 1.0
            })
            .collect()
    }

    /// A host tensor of `shape` with [`values`] from `seed`.
    fn tensor(shape: &[usize], seed: u64) -> Tensor<f32> {
        Tensor::new(values(shape.iter().product(), seed), shape).unwrap()
    }

    /// The tensor of the magnitudes of `t`'s elements.
    fn abs(t: &Tensor<f32>) -> Tensor<f32> {
        Tensor::new(t.data().iter().map(|v| v.abs()).collect(), t.shape()).unwrap()
    }

    /// Checks `got` against `want` elementwise. `mag` is, per element, the sum of the
    /// magnitudes of everything added into it (`sum_k |a_ik b_kj|`, plus `|old|` when
    /// accumulating and `|bias_j|`): f32 sums of the same terms in a different order (the CPU
    /// uses other blockings and vector widths) differ by a few ulps of that sum, hence
    /// `|gpu - cpu| <= 1e-5 * mag + 1e-6`. Relu and tanh are 1-Lipschitz, so the bound holds
    /// after them too (the 1e-6 also covers the two tanh formulas' own rounding).
    fn check(what: &str, got: &[f32], want: &[f32], mag: &[f32]) {
        assert_eq!(got.len(), want.len(), "{what}: lengths");
        for (i, ((g, w), s)) in got.iter().zip(want).zip(mag).enumerate() {
            let tol = 1e-5 * s + 1e-6;
            assert!((g - w).abs() <= tol, "{what}: element {i}: gpu {g} vs cpu {w} (tolerance {tol})");
        }
    }

    /// The bits of the values (for exact comparisons).
    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// The GPU product of two host tensors against the CPU's; with `twice`, also checks that a
    /// second run gives the same bits.
    fn compare(what: &str, a: &Tensor<f32>, ta: bool, b: &Tensor<f32>, tb: bool, twice: bool) {
        let plan = MatMulPlan::new(a.shape(), b.shape(), ta, tb).unwrap();
        let want = cpu::matmul(a, b, ta, tb).unwrap();
        let mag = cpu::matmul(&abs(a), &abs(b), ta, tb).unwrap();
        let (ad, bd) = (DeviceBuffer::upload(a.data()), DeviceBuffer::upload(b.data()));
        let got = matmul(&ad, ta, &bd, tb, &plan).download();
        let what =
            format!("{what} {:?}{} @ {:?}{}", a.shape(), ["", "^T"][ta as usize], b.shape(), ["", "^T"][tb as usize]);
        check(&what, &got, want.data(), mag.data());
        if twice {
            let again = matmul(&ad, ta, &bd, tb, &plan).download();
            assert_eq!(bits(&got), bits(&again), "{what}: a second run gives other bits");
        }
    }

    /// Stored shape of a matrix whose `op` is `r x c`.
    fn stored(r: usize, c: usize, t: bool) -> [usize; 2] {
        if t { [c, r] } else { [r, c] }
    }

    /// Random m, k, n in 1..70 for each of the four transpose combinations.
    #[test]
    fn small_random_shapes_match_the_cpu() {
        // Sizes 1..70: one and two tiles along m and n, inner dims not multiples of 16.
        let dims = values(3 * 4 * 12, 7);
        let mut dims = dims.iter().map(|v| 1 + ((v + 1.0) * 34.5) as usize % 69);
        let mut seed = 100;
        for ta in [false, true] {
            for tb in [false, true] {
                for case in 0..12 {
                    let (m, k, n) = (dims.next().unwrap(), dims.next().unwrap(), dims.next().unwrap());
                    seed += 2;
                    let a = tensor(&stored(m, k, ta), seed);
                    let b = tensor(&stored(k, n, tb), seed + 1);
                    compare(&format!("m={m} k={k} n={n}"), &a, ta, &b, tb, case == 0);
                }
            }
        }
        // Exact tile multiples and one more than a tile.
        for (m, k, n) in [(64, 16, 64), (128, 32, 64), (65, 17, 65), (1, 1, 1)] {
            compare("edges", &tensor(&[m, k], 1), false, &tensor(&[k, n], 2), false, false);
        }
    }

    /// Batch dims broadcast between the operands, and a batch of more workgroups than one
    /// grid dimension holds.
    #[test]
    fn batched_broadcast_shapes_match_the_cpu() {
        for ta in [false, true] {
            for tb in [false, true] {
                let a = tensor(&[[2, 3], stored(5, 7, ta)].concat(), 11);
                let b = tensor(&[[3].as_slice(), &stored(7, 4, tb)].concat(), 12);
                compare("batch", &a, ta, &b, tb, ta && tb);
                let a = tensor(&[[1].as_slice(), &stored(5, 7, ta)].concat(), 13);
                let b = tensor(&[[4].as_slice(), &stored(7, 6, tb)].concat(), 14);
                compare("batch", &a, ta, &b, tb, false);
                let a = tensor(&[[3].as_slice(), &stored(70, 33, ta)].concat(), 15);
                let b = tensor(&stored(33, 66, tb), 16);
                compare("batch", &a, ta, &b, tb, false);
            }
        }
        // More workgroups than one grid dimension holds (65535): the grid folds into y.
        let a = tensor(&[66_000, 1, 2], 17);
        let b = tensor(&[66_000, 2, 1], 18);
        compare("many batches", &a, false, &b, false, true);
    }

    /// `accumulate` adds the product to the output's values.
    #[test]
    fn accumulate_adds_to_the_output() {
        for (ta, tb) in [(false, false), (true, false), (false, true), (true, true)] {
            check_accumulate("accumulate", &tensor(&stored(37, 45, ta), 21), ta, &tensor(&stored(45, 70, tb), 22), tb);
        }
    }

    /// `op(a) @ op(b)` accumulated into old values on the GPU, against the CPU's.
    fn check_accumulate(what: &str, a: &Tensor<f32>, ta: bool, b: &Tensor<f32>, tb: bool) {
        let plan = MatMulPlan::new(a.shape(), b.shape(), ta, tb).unwrap();
        let old = values(plan.m * plan.n, 23);
        let mut want = old.clone();
        cpu::matmul_into(&mut want, true, a.data(), ta, b.data(), tb, &plan);
        let mag = cpu::matmul(&abs(a), &abs(b), ta, tb).unwrap();
        let mag: Vec<f32> = mag.data().iter().zip(&old).map(|(s, o)| s + o.abs()).collect();
        let out = DeviceBuffer::upload(&old);
        let (ad, bd) = (DeviceBuffer::upload(a.data()), DeviceBuffer::upload(b.data()));
        matmul_into(&out, true, &ad, ta, &bd, tb, &plan, None, Activation::Identity);
        check(&format!("{what} ta={ta} tb={tb}"), &out.download(), &want, &mag);
    }

    /// k = 0: the product is zeros, so the output is the old values or the epilogue of 0.
    #[test]
    fn empty_inner_dim_gives_zeros_then_the_epilogue() {
        let (a, b) = (Tensor::<f32>::zeros(&[5, 0]), Tensor::<f32>::zeros(&[0, 70]));
        let plan = MatMulPlan::new(a.shape(), b.shape(), false, false).unwrap();
        let (ad, bd) = (DeviceBuffer::upload(&[]), DeviceBuffer::upload(&[]));
        assert_eq!(matmul(&ad, false, &bd, false, &plan).download(), vec![0.0; 5 * 70]);
        let old = values(5 * 70, 31);
        let out = DeviceBuffer::upload(&old);
        matmul_into(&out, true, &ad, false, &bd, false, &plan, None, Activation::Identity);
        assert_eq!(out.download(), old);
        let bias = values(70, 32);
        let want = nnops::linear(&a, &b, Some(&Tensor::new(bias.clone(), &[70]).unwrap()), Activation::Relu).unwrap();
        matmul_into(&out, false, &ad, false, &bd, false, &plan, Some(&DeviceBuffer::upload(&bias)), Activation::Relu);
        assert_eq!(out.download(), want.data());
    }

    /// The fused bias and each activation, against the CPU's `linear`.
    #[test]
    fn bias_and_activation_epilogues_match_the_cpu() {
        let (rows, k, n) = (70, 40, 67);
        let (x, w, bias) = (tensor(&[rows, k], 41), tensor(&[k, n], 42), tensor(&[n], 43));
        let (xd, wd, bd) =
            (DeviceBuffer::upload(x.data()), DeviceBuffer::upload(w.data()), DeviceBuffer::upload(bias.data()));
        for (act, got) in check_bias_and_activations("bias", &x, &w, &bias) {
            let terms = [Term { x: &xd, k, w: Placed::whole(&wd) }];
            let again = linear_sum(&terms, rows, n, Some(Placed::whole(&bd)), act).download();
            assert_eq!(bits(&got), bits(&again), "{act:?}: linear_sum gives other bits than matmul_into");
        }
    }

    /// `act(x @ w + bias)` on the GPU for each activation, against the CPU's `linear`; the
    /// GPU's outputs, per activation.
    fn check_bias_and_activations(
        what: &str,
        x: &Tensor<f32>,
        w: &Tensor<f32>,
        bias: &Tensor<f32>,
    ) -> Vec<(Activation, Vec<f32>)> {
        let (rows, n) = (x.shape()[0], w.shape()[1]);
        let mag = cpu::matmul(&abs(x), &abs(w), false, false).unwrap();
        let mag: Vec<f32> =
            mag.data().chunks(n).flat_map(|r| r.iter().zip(bias.data()).map(|(s, c)| s + c.abs())).collect();
        let plan = MatMulPlan::new(x.shape(), w.shape(), false, false).unwrap();
        let (xd, wd, bd) =
            (DeviceBuffer::upload(x.data()), DeviceBuffer::upload(w.data()), DeviceBuffer::upload(bias.data()));
        [Activation::Identity, Activation::Relu, Activation::Tanh]
            .into_iter()
            .map(|act| {
                let want = nnops::linear(x, w, Some(bias), act).unwrap();
                let out = DeviceBuffer::uninit(rows * n);
                matmul_into(&out, false, &xd, false, &wd, false, &plan, Some(&bd), act);
                let got = out.download();
                check(&format!("{what} + {act:?}"), &got, want.data(), &mag);
                (act, got)
            })
            .collect()
    }

    /// Sums of 2 and 3 products, with and without bias, against the CPU's `linear_sum`; the
    /// same weights as row blocks of one stacked weight, read in place, give the same bits.
    #[test]
    fn linear_sum_matches_the_cpu() {
        let (rows, n) = (90, 35);
        for (ks, bias, act) in [
            (vec![20, 33], true, Activation::Tanh),
            (vec![7, 64, 1], false, Activation::Relu),
            (vec![16, 5, 48], true, Activation::Identity),
        ] {
            let xs: Vec<Tensor<f32>> = ks.iter().enumerate().map(|(i, &k)| tensor(&[rows, k], 50 + i as u64)).collect();
            let ws: Vec<Tensor<f32>> = ks.iter().enumerate().map(|(i, &k)| tensor(&[k, n], 60 + i as u64)).collect();
            let b = bias.then(|| tensor(&[n], 70));
            let parts: Vec<(&Tensor<f32>, &Tensor<f32>)> = xs.iter().zip(&ws).collect();
            let want = nnops::linear_sum(&parts, b.as_ref(), act).unwrap();
            let mut mag = vec![0.0f32; rows * n];
            for (x, w) in &parts {
                let m = cpu::matmul(&abs(x), &abs(w), false, false).unwrap();
                mag.iter_mut().zip(m.data()).for_each(|(s, v)| *s += v);
            }
            if let Some(b) = &b {
                mag.chunks_mut(n).for_each(|r| r.iter_mut().zip(b.data()).for_each(|(s, c)| *s += c.abs()));
            }
            let xd: Vec<DeviceBuffer> = xs.iter().map(|x| DeviceBuffer::upload(x.data())).collect();
            let wd: Vec<DeviceBuffer> = ws.iter().map(|w| DeviceBuffer::upload(w.data())).collect();
            let bd = b.as_ref().map(|b| DeviceBuffer::upload(b.data()));
            let terms: Vec<Term<'_>> =
                xd.iter().zip(&wd).zip(&ks).map(|((x, w), &k)| Term { x, k, w: Placed::whole(w) }).collect();
            let got = linear_sum(&terms, rows, n, bd.as_ref().map(Placed::whole), act).download();
            check(&format!("linear_sum {ks:?} bias={bias} {act:?}"), &got, want.data(), &mag);
            let again = linear_sum(&terms, rows, n, bd.as_ref().map(Placed::whole), act).download();
            assert_eq!(bits(&got), bits(&again), "linear_sum {ks:?}: a second run gives other bits");
            // One weight [sum k, n] whose row blocks are the w_i, after a row of padding.
            let stacked: Vec<f32> =
                values(n, 71).into_iter().chain(ws.iter().flat_map(|w| w.data().to_vec())).collect();
            let stacked = DeviceBuffer::upload(&stacked);
            let mut row = 1;
            let blocks: Vec<Term<'_>> = xd
                .iter()
                .zip(&ks)
                .map(|(x, &k)| {
                    row += k;
                    Term { x, k, w: Placed::at(&stacked, (row - k) * n) }
                })
                .collect();
            let in_place = linear_sum(&blocks, rows, n, bd.as_ref().map(Placed::whole), act).download();
            assert_eq!(bits(&got), bits(&in_place), "linear_sum {ks:?}: row blocks read in place");
        }
    }

    /// Few output tiles over a long inner dim split k ([`split_k`]); the slices' sum, with
    /// accumulation, bias and activation after it, matches the CPU and repeats its bits.
    #[test]
    fn split_k_products_match_the_cpu() {
        assert_eq!(split_k(320, 256), (1, 256), "enough tiles: no split");
        assert_eq!(split_k(16, 5120), (16, 320), "a 256 x 256 weight gradient over 5120 rows");
        assert_eq!(split_k(2, 3000), (11, 288));
        assert_eq!(split_k(1, 300), (1, 300), "too short to split");
        for (ta, tb) in [(false, false), (true, false), (false, true), (true, true)] {
            let (m, k, n) = (70usize, 3000, 33usize);
            assert!(split_k(m.div_ceil(TILE_M) * n.div_ceil(TILE_N), k).0 > 1);
            let (a, b) = (tensor(&stored(m, k, ta), 91), tensor(&stored(k, n, tb), 92));
            compare("split", &a, ta, &b, tb, true);
            check_accumulate("split accumulate", &a, ta, &b, tb);
        }
        // Bias and activation after the slices' sum (one tile, two slices).
        let (rows, k, n) = (20, 600, 30);
        assert_eq!(split_k(1, k).0, 2);
        check_bias_and_activations("split bias", &tensor(&[rows, k], 94), &tensor(&[k, n], 95), &tensor(&[n], 96));
    }

    /// A product reading `b` from inside a larger buffer and adding into a block inside a
    /// larger output (a layer's weight rows and their gradient, in place; with a row stride,
    /// its columns) gives the bits of the same product on buffers of its own, on each kernel
    /// (small, tiled, split k), with a bias read from inside a larger buffer, and leaves the
    /// rest of the output alone.
    #[test]
    fn products_read_and_write_blocks_in_place() {
        for (m, k, n) in [(20, 40, 30), (70, 100, 33), (70, 3000, 33)] {
            for (ta, tb) in [(false, false), (true, false), (false, true), (true, true)] {
                for pad in [0, 5] {
                    let (a, b) = (tensor(&stored(m, k, ta), 111), tensor(&stored(k, n, tb), 112));
                    let plan = MatMulPlan::single(m, k, n);
                    let b_cols = stored(k, n, tb)[1];
                    // Matrices of `cols` columns stored in rows of `cols + pad`, after `before`
                    // values, with `after` more at the end.
                    let (before, after) = (3 * n + 1, 2 * n);
                    let embed = |v: &[f32], cols: usize, seed: u64| -> Vec<f32> {
                        let mut fill = values(before + v.len() / cols * pad + after, seed).into_iter();
                        let mut out: Vec<f32> = fill.by_ref().take(before).collect();
                        for row in v.chunks(cols) {
                            out.extend_from_slice(row);
                            out.extend(fill.by_ref().take(pad));
                        }
                        out.extend(fill);
                        out
                    };
                    let old = values(m * n, 113);
                    let (bias, act) = (values(n, 115), Activation::Tanh);
                    let ad = DeviceBuffer::upload(a.data());
                    let own = DeviceBuffer::upload(&old);
                    let (bd, biasd) = (DeviceBuffer::upload(b.data()), DeviceBuffer::upload(&bias));
                    matmul_into(&own, true, &ad, ta, &bd, tb, &plan, Some(&biasd), act);
                    let want = embed(&own.download(), n, 116);
                    let out = DeviceBuffer::upload(&embed(&old, n, 116));
                    let bpad = DeviceBuffer::upload(&embed(b.data(), b_cols, 114));
                    let bias_in = DeviceBuffer::upload(&embed(&bias, n, 117));
                    let place = |buf, cols| Placed::block(buf, before, cols + pad);
                    let bias_at = Some(Placed::at(&bias_in, before));
                    matmul_into_at(place(&out, n), true, &ad, ta, place(&bpad, b_cols), tb, &plan, bias_at, act);
                    let what = format!("m={m} k={k} n={n} ta={ta} tb={tb} pad={pad}");
                    assert_eq!(bits(&out.download()), bits(&want), "{what}: the block and what surrounds it");
                }
            }
        }
    }

    /// The subequivariant layers' batched products of small matrices go to the one-thread-
    /// per-output kernel, which matches the CPU and gives the tiled kernel's bits (the same
    /// fused multiply-adds in the same order), with and without the epilogue.
    #[test]
    fn small_matrix_kernel_matches_the_cpu_and_the_tiled_kernel() {
        let batch = 300;
        for (m, k, n) in [(3, 32, 32), (32, 3, 32), (3, 32, 3), (3, 3, 3), (1, 64, 16)] {
            assert!(is_small(m, k, n));
            for (ta, tb) in [(false, false), (true, false), (false, true), (true, true)] {
                let a = tensor(&[[batch].as_slice(), &stored(m, k, ta)].concat(), 101);
                let b = tensor(&[[batch].as_slice(), &stored(k, n, tb)].concat(), 102);
                compare("small", &a, ta, &b, tb, false);
                let plan = MatMulPlan::new(a.shape(), b.shape(), ta, tb).unwrap();
                let (ad, bd) = (DeviceBuffer::upload(a.data()), DeviceBuffer::upload(b.data()));
                let bias = DeviceBuffer::upload(&values(n, 103));
                let old = values(batch * m * n, 104);
                let run = |route: Route, act: Activation| {
                    let out = DeviceBuffer::upload(&old);
                    let (o, b) = (Placed::whole(&out), Placed::whole(&bd));
                    matmul_into_with(route, o, true, &ad, ta, b, tb, &plan, Some(Placed::whole(&bias)), act);
                    bits(&out.download())
                };
                for act in [Activation::Identity, Activation::Tanh] {
                    let tiled = Route::Tiled(MatMulTile::Rows64);
                    assert_eq!(run(Route::Small, act), run(tiled, act), "m={m} k={k} n={n} ta={ta} tb={tb} {act:?}");
                }
            }
        }
        // A weight shared by every batch entry (stride 0) and a tall product stay tiled.
        assert!(!is_small(5120, 256, 256) && !is_small(3, 300, 3));
        let a = tensor(&[batch, 3, 32], 105);
        let w = tensor(&[32, 32], 106);
        compare("shared weight", &a, false, &w, false, true);
    }

    /// The 128 x 64 tile gives the 64 x 64 tile's bits: every output is the same sequence of
    /// fused multiply-adds, and the split of k does not depend on the tile. Shapes with
    /// partial tiles of either size, split k (few tiles over a long k), batches, both
    /// transposes, accumulation, the epilogue and a block of a weight read and written in
    /// place.
    #[test]
    fn both_tiles_give_the_same_bits() {
        let shapes = [(129, 40, 70, 1), (127, 17, 64, 3), (200, 70, 1, 1), (64, 5000, 70, 1), (300, 1153, 64, 1)];
        for (m, k, n, batch) in shapes {
            assert!(!is_small(m, k, n));
            for (ta, tb) in [(false, false), (true, false), (false, true), (true, true)] {
                let a = tensor(&[[batch].as_slice(), &stored(m, k, ta)].concat(), 111);
                let b = tensor(&[[batch].as_slice(), &stored(k, n, tb)].concat(), 112);
                let plan = MatMulPlan::new(a.shape(), b.shape(), ta, tb).unwrap();
                let (ad, bd) = (DeviceBuffer::upload(a.data()), DeviceBuffer::upload(b.data()));
                let bias = DeviceBuffer::upload(&values(n, 113));
                let old = values(batch * m * n, 114);
                for (accumulate, with_bias, act) in [
                    (false, false, Activation::Identity),
                    (true, true, Activation::Tanh),
                    (false, true, Activation::Relu),
                ] {
                    let run = |tile: MatMulTile| {
                        let out = DeviceBuffer::upload(&old);
                        let bias = with_bias.then(|| Placed::whole(&bias));
                        let (o, b) = (Placed::whole(&out), Placed::whole(&bd));
                        matmul_into_with(Route::Tiled(tile), o, accumulate, &ad, ta, b, tb, &plan, bias, act);
                        bits(&out.download())
                    };
                    let (narrow, tall) = (run(MatMulTile::Rows64), run(MatMulTile::Rows128));
                    let what =
                        format!("m={m} k={k} n={n} batch={batch} ta={ta} tb={tb} {accumulate} {with_bias} {act:?}");
                    assert_eq!(narrow, tall, "{what}");
                }
            }
        }
        // A block of columns of a wider weight, read and accumulated into in place.
        let (rows, k, width, col, n) = (150, 48, 100, 20, 64);
        let x = tensor(&[rows, k], 115);
        let w = tensor(&[k, width], 116);
        let (xd, wd) = (DeviceBuffer::upload(x.data()), DeviceBuffer::upload(w.data()));
        let old = values(rows * width, 117);
        let plan = MatMulPlan::single(rows, k, n);
        let run = |tile: MatMulTile| {
            let out = DeviceBuffer::upload(&old);
            let (o, b) = (Placed::block(&out, col, width), Placed::block(&wd, col, width));
            matmul_into_with(Route::Tiled(tile), o, true, &xd, false, b, false, &plan, None, Activation::Identity);
            bits(&out.download())
        };
        assert_eq!(run(MatMulTile::Rows64), run(MatMulTile::Rows128), "a block in place");
        // And the tiled kernel against the CPU.
        compare("tiled kernel", &tensor(&[257, 70], 118), false, &tensor(&[70, 65], 119), false, true);
    }

    /// The tall tile goes to tall products only: not to split ones, nor to those it would
    /// cover with fewer than [`TARGET_GROUPS`] workgroups.
    #[test]
    fn the_tall_tile_goes_to_products_with_many_tiles() {
        let tall = |m, k, n, batches| {
            matches!(Route::tiled(MatMulTile::Rows128, m, k, n, batches), Route::Tiled(MatMulTile::Rows128))
        };
        // A message layer of the paper preset, and its input gradient.
        assert!(tall(153_600, 1024, 64, 1) && tall(153_600, 64, 1024, 1));
        // Its weight gradient (k = 153,600 split), a 6,144-row layer (48 tall tiles).
        assert!(!tall(1024, 153_600, 64, 1) && !tall(6144, 64, 64, 1));
        // Nothing changes without the setting.
        assert!(matches!(Route::tiled(MatMulTile::Rows64, 153_600, 1024, 64, 1), Route::Tiled(MatMulTile::Rows64)));
    }

    /// The model's tall, skinny layer products and their backward products.
    #[test]
    fn tall_skinny_model_shapes_match_the_cpu() {
        // The model's layer products with the batch of rows scaled down (lavapipe runs on the
        // CPU): forward x @ w, and the backward products x^T g (weights) and g w^T (inputs).
        let rows = 3000;
        let x = tensor(&[rows, 1153], 81);
        let w = tensor(&[1153, 64], 82);
        let g = tensor(&[rows, 64], 83);
        compare("forward", &x, false, &w, false, true);
        compare("weight gradient", &x, true, &g, false, true);
        compare("input gradient", &g, false, &w, true, false);
        let w2 = tensor(&[64, 1088], 84);
        let g2 = tensor(&[rows, 1088], 85);
        compare("forward", &g, false, &w2, false, false);
        compare("weight gradient", &g, true, &g2, false, false);
    }
}
