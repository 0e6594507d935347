//! Index kernels on the device (the CPU's `kernels/index.rs`): select, add at indices
//! (duplicates accumulate), gather and its adjoint, segment sums and means and their adjoint.
//!
//! An axis is described as `(outer, n, inner)`, as [`split_at_axis`] splits a shape. Callers
//! have validated shapes and indices with the CPU's checks (`check_indices`, `check_index_add`,
//! `gather_shape`, `check_segments`): the wrappers assume every index is in range, buffer
//! lengths match the sizes given and segment ids are sorted; a bad input is a caller bug
//! (debug builds assert the lengths and the order of segment ids; an out-of-range index gives
//! wrong values, kept inside the buffers by WebGPU's bounds checks, or a panic on the host).
//!
//! Every output element is computed by one thread in a fixed order, without atomics, so a
//! launch gives the same bits every run. The scatter-style ops (several sources adding into
//! one destination) get from the host a CSR list of each destination's sources in increasing
//! source order, and the destination's thread adds them in that order starting from its
//! current value: the order the CPU adds them in. Select, gather, index_add, gather's adjoint
//! and the segment ops are therefore bit-identical to the CPU (on a device that keeps f32
//! subnormals; a driver that flushes them may differ where they occur).
//!
//! [`split_at_axis`]: crate::shape::split_at_axis

use std::sync::{Arc, Mutex};

use super::{kernel, u};
use crate::gpu::context::Kernel;
use crate::gpu::list_cache::{ListCache, ListKind, derived};
use crate::gpu::{DeviceBuffer, device};

/// Words of index lists (host keys and device buffers) kept between calls: 128 MiB each side
/// at most, far above a paper-size model's lists (a few MB).
const KEPT_WORDS: usize = 1 << 25;

/// The device lists derived from index lists, kept while they recur (`gpu/list_cache.rs`).
static LISTS: Mutex<ListCache<Vec<DeviceBuffer>>> = Mutex::new(ListCache::new(KEPT_WORDS));

/// The device buffers derived from `idx` as `kind`: kept ones when the same list came before,
/// else `build(idx as u32)`'s, kept for the next call.
fn lists(kind: ListKind, idx: &[usize], build: impl FnOnce(&[u32]) -> Vec<DeviceBuffer>) -> Arc<Vec<DeviceBuffer>> {
    derived(&LISTS, kind, idx, |key| {
        let bufs = build(key);
        let words = bufs.iter().map(DeviceBuffer::len).sum();
        (bufs, words)
    })
}

/// `idx` on the device as u32.
fn indices(idx: &[usize]) -> Arc<Vec<DeviceBuffer>> {
    lists(ListKind::Indices, idx, |key| vec![DeviceBuffer::upload_u32(key)])
}

const SELECT: Kernel = kernel!("index_select", "index_select.wgsl");
const GATHER: Kernel = kernel!("index_gather", "index_gather.wgsl");
const ADD: Kernel = kernel!("index_add", "index_add.wgsl");
const SCATTER_ADD: Kernel = kernel!("index_scatter_add", "index_scatter_add.wgsl");
const SEGMENT_REDUCE: Kernel = kernel!("index_segment_reduce", "index_segment_reduce.wgsl");
const SEGMENT_BACKWARD: Kernel = kernel!("index_segment_backward", "index_segment_backward.wgsl");

/// The sources of each destination that has any, as compressed rows: destination `dests[q]`
/// receives the sources `srcs[offsets[q]..offsets[q + 1]]`, in increasing order. `dests` is
/// increasing; destinations without sources are left out.
#[derive(Debug, PartialEq, Eq)]
struct Csr {
    dests: Vec<u32>,
    offsets: Vec<u32>,
    srcs: Vec<u32>,
}

impl Csr {
    /// The lists for sources `0..keys.len()`, source `s` going to destination `keys[s]`
    /// (`< num_keys`). A counting sort (`O(num_keys + sources)`) when the destinations are
    /// few enough, else a sort of the (destination, source) pairs (`O(sources log sources)`),
    /// so that a few sources into a large tensor cost nothing per destination.
    fn new(keys: &[u32], num_keys: usize) -> Self {
        let ns = keys.len();
        let mut dests = Vec::new();
        let mut offsets = Vec::new();
        let mut srcs = vec![0u32; ns];
        if num_keys <= 2 * ns + 4096 {
            // start[k] = the first position of destination k's sources.
            let mut start = vec![0u32; num_keys + 1];
            for &k in keys {
                start[k as usize + 1] += 1;
            }
            for k in 0..num_keys {
                if start[k + 1] > 0 {
                    dests.push(u(k));
                    offsets.push(start[k]);
                }
                start[k + 1] += start[k];
            }
            let mut next = start;
            for (s, &k) in keys.iter().enumerate() {
                srcs[next[k as usize] as usize] = u(s);
                next[k as usize] += 1;
            }
        } else {
            let mut pairs: Vec<u64> = keys.iter().enumerate().map(|(s, &k)| (u64::from(k) << 32) | s as u64).collect();
            pairs.sort_unstable();
            for (pos, &pair) in pairs.iter().enumerate() {
                let k = (pair >> 32) as u32;
                if dests.last() != Some(&k) {
                    dests.push(k);
                    offsets.push(u(pos));
                }
                srcs[pos] = pair as u32;
            }
        }
        offsets.push(u(ns));
        Csr { dests, offsets, srcs }
    }

    /// Uploads `[dests, offsets, srcs]`.
    fn upload(&self) -> Vec<DeviceBuffer> {
        vec![
            DeviceBuffer::upload_u32(&self.dests),
            DeviceBuffer::upload_u32(&self.offsets),
            DeviceBuffer::upload_u32(&self.srcs),
        ]
    }
}

/// `1 / count` of each segment as the CPU computes a mean's scale (`T::ONE / T::from_f64`),
/// 1 for an empty segment; and the row offsets of the segments (`offsets[s]..offsets[s + 1]`
/// are the rows of segment `s`; `seg` is sorted).
fn segment_offsets_and_scales(seg: &[usize], num_segments: usize) -> (Vec<u32>, Vec<f32>) {
    let mut offsets = vec![0u32; num_segments + 1];
    for &s in seg {
        offsets[s + 1] += 1;
    }
    let scales = offsets[1..].iter().map(|&c| if c > 0 { 1.0 / (f64::from(c) as f32) } else { 1.0 }).collect();
    for s in 0..num_segments {
        offsets[s + 1] += offsets[s];
    }
    (offsets, scales)
}

/// `out[o, j, i] = x[o, idx[j], i]`: `x` is `[outer, n, inner]`, the output
/// `[outer, idx.len(), inner]` (the CPU's `index_select`, bit for bit: values are copied as
/// words). Indices must be below `n`.
pub(crate) fn index_select(x: &DeviceBuffer, outer: usize, n: usize, inner: usize, idx: &[usize]) -> DeviceBuffer {
    debug_assert_eq!(x.len(), outer * n * inner);
    let m = idx.len();
    let total = outer * m * inner;
    let out = DeviceBuffer::uninit(total);
    if total > 0 {
        let idx_d = indices(idx);
        device().launch_1d(
            &SELECT,
            &[u(total), u(n), u(m), u(inner)],
            &[x.buffer(), idx_d[0].buffer(), out.buffer()],
            total,
        );
    }
    out
}

/// `dst[o, idx[j], i] += src[o, j, i]` in place: `dst` is `[outer, n, inner]`, `src`
/// `[outer, idx.len(), inner]`; repeated indices accumulate. Each destination adds its sources
/// in increasing `j` starting from its current value, as the CPU's `index_add_into` does, so
/// the result is bit-identical to it. Indices must be below `n`.
pub(crate) fn index_add_into(
    dst: &DeviceBuffer,
    n: usize,
    src: &DeviceBuffer,
    outer: usize,
    inner: usize,
    idx: &[usize],
) {
    let m = idx.len();
    debug_assert_eq!(dst.len(), outer * n * inner);
    debug_assert_eq!(src.len(), outer * m * inner);
    if outer * m * inner == 0 {
        return;
    }
    let csr = lists(ListKind::Scatter { n }, idx, |keys| Csr::new(keys, n).upload());
    let (dests, offsets, srcs) = (&csr[0], &csr[1], &csr[2]);
    let nd = dests.len();
    let total = outer * nd * inner;
    device().launch_1d(
        &ADD,
        &[u(total), u(n), u(m), u(inner), u(nd)],
        &[src.buffer(), dests.buffer(), offsets.buffer(), srcs.buffer(), dst.buffer()],
        total,
    );
}

/// `out[o, j, i] = x[o, idx[(o * m + j) * inner + i], i]`: `x` is `[outer, n, inner]`, `idx`
/// and the output `[outer, m, inner]` (the CPU's `gather`, bit for bit: values are copied as
/// words). Indices must be below `n`.
pub(crate) fn gather(x: &DeviceBuffer, outer: usize, n: usize, inner: usize, m: usize, idx: &[usize]) -> DeviceBuffer {
    debug_assert_eq!(x.len(), outer * n * inner);
    debug_assert_eq!(idx.len(), outer * m * inner);
    let total = idx.len();
    let out = DeviceBuffer::uninit(total);
    if total > 0 {
        let idx_d = indices(idx);
        device().launch_1d(
            &GATHER,
            &[u(total), u(n), u(m), u(inner)],
            &[x.buffer(), idx_d[0].buffer(), out.buffer()],
            total,
        );
    }
    out
}

/// The adjoint of [`gather`], in place: `dst[o, idx[p], i] += g[p]` for every
/// `p = (o * m + j) * inner + i`; `dst` is `[outer, n, inner]`, `g` and `idx`
/// `[outer, m, inner]`. Each destination element adds its sources in increasing `p` starting
/// from its current value, as the CPU's `gather_backward_into` does, so the result is
/// bit-identical to it. Indices must be below `n`.
pub(crate) fn gather_backward_into(
    dst: &DeviceBuffer,
    outer: usize,
    n: usize,
    inner: usize,
    m: usize,
    g: &DeviceBuffer,
    idx: &[usize],
) {
    debug_assert_eq!(dst.len(), outer * n * inner);
    debug_assert_eq!(g.len(), outer * m * inner);
    debug_assert_eq!(idx.len(), outer * m * inner);
    if idx.is_empty() {
        return;
    }
    let kind = ListKind::GatherScatter { outer, n, inner, m };
    let csr = lists(kind, idx, |idx| {
        let keys: Vec<u32> = idx
            .iter()
            .enumerate()
            .map(|(p, &k)| {
                let (o, i) = (p / (m * inner), p % inner);
                u((o * n + k as usize) * inner + i)
            })
            .collect();
        Csr::new(&keys, dst.len()).upload()
    });
    let (dests, offsets, srcs) = (&csr[0], &csr[1], &csr[2]);
    let nd = dests.len();
    device().launch_1d(
        &SCATTER_ADD,
        &[u(nd)],
        &[g.buffer(), dests.buffer(), offsets.buffer(), srcs.buffer(), dst.buffer()],
        nd,
    );
}

/// Sums (or means when `mean`) of the rows of `x` (`[rows, inner]`) grouped by the sorted
/// segment ids `seg` (one per row, each below `num_segments`): `[num_segments, inner]`. An
/// empty segment gives 0, sum or mean. Rows add in increasing order from 0 and a mean then
/// multiplies by `1 / count`, as the CPU's `segment_reduce` does: bit-identical to it.
pub(crate) fn segment_reduce(
    x: &DeviceBuffer,
    rows: usize,
    inner: usize,
    seg: &[usize],
    num_segments: usize,
    mean: bool,
) -> DeviceBuffer {
    debug_assert_eq!(x.len(), rows * inner);
    debug_assert_eq!(seg.len(), rows);
    debug_assert!(seg.windows(2).all(|w| w[0] <= w[1]), "segment ids are sorted");
    let total = num_segments * inner;
    let out = DeviceBuffer::uninit(total);
    if total > 0 {
        let rows_of = lists(ListKind::SegmentRows { num_segments }, seg, |_| {
            let (offsets, scales) = segment_offsets_and_scales(seg, num_segments);
            vec![DeviceBuffer::upload_u32(&offsets), DeviceBuffer::upload(&scales)]
        });
        device().launch_1d(
            &SEGMENT_REDUCE,
            &[u(total), u(inner), u32::from(mean)],
            &[x.buffer(), rows_of[0].buffer(), rows_of[1].buffer(), out.buffer()],
            total,
        );
    }
    out
}

/// The adjoint of [`segment_reduce`]: `dx[r, i] = g[seg[r], i]`, divided by the segment's
/// row count when `mean` (multiplied by `1 / count`, as `backprop.rs` does on the CPU:
/// bit-identical to it). `g` is `[num_segments, inner]`, the output `[rows, inner]`; `seg`
/// is sorted, each id below `num_segments`.
pub(crate) fn segment_backward(
    g: &DeviceBuffer,
    rows: usize,
    inner: usize,
    seg: &[usize],
    num_segments: usize,
    mean: bool,
) -> DeviceBuffer {
    debug_assert_eq!(g.len(), num_segments * inner);
    debug_assert_eq!(seg.len(), rows);
    let total = rows * inner;
    let dx = DeviceBuffer::uninit(total);
    if total > 0 {
        let ids = lists(ListKind::SegmentIds { num_segments }, seg, |key| {
            let (_, scales) = segment_offsets_and_scales(seg, num_segments);
            vec![DeviceBuffer::upload_u32(key), DeviceBuffer::upload(&scales)]
        });
        device().launch_1d(
            &SEGMENT_BACKWARD,
            &[u(total), u(inner), u32::from(mean)],
            &[g.buffer(), ids[0].buffer(), ids[1].buffer(), dx.buffer()],
            total,
        );
    }
    dx
}

#[cfg(test)]
mod tests {
    //! Every op against the CPU kernel, compared bit for bit (`to_bits`): the device
    //! reproduces the CPU's order of additions exactly. Each GPU op also runs twice and must
    //! give the same bits both times.

    use super::*;
    use crate::kernels::index as cpu;
    use crate::tensor::Tensor;

    /// Deterministic pseudo-random values in [-2, 2) (a 64-bit LCG).
    fn values(len: usize, seed: u64) -> Vec<f32> {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..len)
            .map(|_| {
                s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
                ((s >> 40) as f32 / (1u64 << 24) as f32) * 4.0 - 2.0
            })
            .collect()
    }

    /// Deterministic pseudo-random indices below `n` (many repeats when `len > n`).
    fn indices(len: usize, n: usize, seed: u64) -> Vec<usize> {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..len)
            .map(|_| {
                s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
                ((s >> 33) as usize) % n
            })
            .collect()
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    #[test]
    fn csr_lists_sources_in_increasing_order_on_both_paths() {
        let keys = [3u32, 0, 3, 1, 3, 0];
        let want = Csr { dests: vec![0, 1, 3], offsets: vec![0, 2, 3, 6], srcs: vec![1, 5, 3, 0, 2, 4] };
        assert_eq!(Csr::new(&keys, 5), want, "counting sort");
        let mut big = Csr::new(&keys, 100_000);
        assert_eq!(big, want, "pair sort");
        big = Csr::new(&[], 10);
        assert_eq!(big, Csr { dests: vec![], offsets: vec![0], srcs: vec![] });
    }

    #[test]
    fn index_select_matches_the_cpu_bit_for_bit() {
        // (outer, n, inner, idx): repeats, n = 1, outer > 1, inner > 1, no indices.
        let cases: Vec<(usize, usize, usize, Vec<usize>)> = vec![
            (1, 7, 1, vec![3, 3, 0, 6, 3]),
            (3, 5, 4, vec![4, 0, 4, 2, 2, 1]),
            (2, 1, 3, vec![0, 0, 0]),
            (4, 6, 1, indices(300, 6, 1)),
            (1, 50, 33, indices(70, 50, 2)),
            (2, 3, 2, vec![]),
        ];
        for (k, (outer, n, inner, idx)) in cases.into_iter().enumerate() {
            let xv = values(outer * n * inner, k as u64);
            let want = cpu::index_select(&Tensor::new(xv.clone(), &[outer, n, inner]).unwrap(), 1, &idx).unwrap();
            let x = DeviceBuffer::upload(&xv);
            let got = index_select(&x, outer, n, inner, &idx).download();
            assert_eq!(bits(&got), bits(want.data()), "case {k}");
            assert_eq!(bits(&index_select(&x, outer, n, inner, &idx).download()), bits(&got), "case {k} rerun");
        }
    }

    #[test]
    fn index_add_into_matches_the_cpu_bit_for_bit() {
        // (outer, n, inner, idx) added into a non-zero destination: repeats (many adds into
        // one row), outer > 1, inner > 1, n = 1, a few rows of a large tensor (the CSR's pair
        // sort), no indices.
        let cases: Vec<(usize, usize, usize, Vec<usize>)> = vec![
            (1, 5, 1, vec![2, 2, 2, 0, 2, 4]),
            (3, 4, 5, indices(40, 4, 3)),
            (2, 1, 3, vec![0; 9]),
            (1, 9000, 1, vec![8999, 5, 8999]),
            (2, 30, 17, indices(500, 30, 4)),
            (2, 3, 2, vec![]),
        ];
        for (k, (outer, n, inner, idx)) in cases.into_iter().enumerate() {
            let m = idx.len();
            let (dv, sv) = (values(outer * n * inner, 10 + k as u64), values(outer * m * inner, 20 + k as u64));
            let mut want = dv.clone();
            cpu::index_add_into(&mut want, n, &sv, m, outer, inner, &idx);
            let src = DeviceBuffer::upload(&sv);
            let mut runs = Vec::new();
            for _ in 0..2 {
                let dst = DeviceBuffer::upload(&dv);
                index_add_into(&dst, n, &src, outer, inner, &idx);
                runs.push(bits(&dst.download()));
            }
            assert_eq!(runs[0], bits(&want), "case {k}");
            assert_eq!(runs[1], runs[0], "case {k} rerun");
        }
    }

    #[test]
    fn gather_matches_the_cpu_bit_for_bit() {
        // (outer, n, inner, m): outer > 1, inner > 1, m > n (repeats), n = 1, m = 0.
        for (k, (outer, n, inner, m)) in
            [(1, 6, 1, 4), (3, 4, 5, 7), (2, 1, 3, 2), (2, 10, 8, 3), (3, 5, 2, 0)].into_iter().enumerate()
        {
            let xv = values(outer * n * inner, 30 + k as u64);
            let idx = indices(outer * m * inner, n, 40 + k as u64);
            let want = cpu::gather(&Tensor::new(xv.clone(), &[outer, n, inner]).unwrap(), 1, &[outer, m, inner], &idx)
                .unwrap();
            let x = DeviceBuffer::upload(&xv);
            let got = gather(&x, outer, n, inner, m, &idx).download();
            assert_eq!(bits(&got), bits(want.data()), "case {k}");
            assert_eq!(bits(&gather(&x, outer, n, inner, m, &idx).download()), bits(&got), "case {k} rerun");
        }
    }

    #[test]
    fn gather_backward_into_matches_the_cpu_bit_for_bit() {
        // (outer, n, inner, m) into a non-zero destination: m > n (repeats), n = 1, a few
        // elements of a large tensor (the CSR's pair sort), m = 0.
        for (k, (outer, n, inner, m)) in
            [(1, 3, 1, 20), (3, 4, 5, 9), (2, 1, 3, 4), (1, 9000, 1, 3), (2, 7, 6, 11), (2, 3, 2, 0)]
                .into_iter()
                .enumerate()
        {
            let dv = values(outer * n * inner, 50 + k as u64);
            let gv = values(outer * m * inner, 60 + k as u64);
            let idx = indices(outer * m * inner, n, 70 + k as u64);
            let mut want = dv.clone();
            cpu::gather_backward_into(&mut want, &[outer, n, inner], 1, &gv, &idx);
            let g = DeviceBuffer::upload(&gv);
            let mut runs = Vec::new();
            for _ in 0..2 {
                let dst = DeviceBuffer::upload(&dv);
                gather_backward_into(&dst, outer, n, inner, m, &g, &idx);
                runs.push(bits(&dst.download()));
            }
            assert_eq!(runs[0], bits(&want), "case {k}");
            assert_eq!(runs[1], runs[0], "case {k} rerun");
        }
    }

    /// Segment cases `(inner, seg, num_segments)`: empty segments first, between and last,
    /// inner = 1 and > 1, one long segment, no rows.
    fn segment_cases() -> Vec<(usize, Vec<usize>, usize)> {
        let mut long = indices(200, 6, 80);
        long.sort_unstable();
        vec![
            (1, vec![1, 1, 1, 3, 3, 6], 8),
            (4, vec![0, 0, 2, 2, 2, 2, 2, 5], 6),
            (3, vec![0; 40], 1),
            (7, long, 9),
            (5, vec![], 3),
        ]
    }

    #[test]
    fn segment_reduce_matches_the_cpu_bit_for_bit() {
        for (k, (inner, seg, ns)) in segment_cases().into_iter().enumerate() {
            let rows = seg.len();
            let xv = values(rows * inner, 90 + k as u64);
            let xt = Tensor::new(xv.clone(), &[rows, inner]).unwrap();
            let x = DeviceBuffer::upload(&xv);
            for mean in [false, true] {
                // With no rows the CPU's kernel loses `inner` (it divides the element count
                // by the row count) and returns no values for a `[ns, inner]` shape: the
                // device gives the ns * inner zeros the shape says.
                let want = if rows == 0 {
                    vec![0.0; ns * inner]
                } else {
                    cpu::segment_reduce(&xt, &seg, ns, mean).unwrap().into_vec()
                };
                let got = segment_reduce(&x, rows, inner, &seg, ns, mean).download();
                assert_eq!(bits(&got), bits(&want), "case {k} mean {mean}");
                let again = segment_reduce(&x, rows, inner, &seg, ns, mean).download();
                assert_eq!(bits(&again), bits(&got), "case {k} mean {mean} rerun");
            }
        }
    }

    #[test]
    fn segment_backward_matches_the_cpu_bit_for_bit() {
        for (k, (inner, seg, ns)) in segment_cases().into_iter().enumerate() {
            let rows = seg.len();
            let gv = values(ns * inner, 100 + k as u64);
            let g = DeviceBuffer::upload(&gv);
            for mean in [false, true] {
                // The CPU's backward of Op::Segment (backprop.rs), written out.
                let counts = cpu::segment_counts(&seg, ns);
                let mut want = vec![0f32; rows * inner];
                for (r, &s) in seg.iter().enumerate() {
                    let scale = if mean { 1.0 / (counts[s] as f64) as f32 } else { 1.0 };
                    for i in 0..inner {
                        want[r * inner + i] = gv[s * inner + i] * scale;
                    }
                }
                let got = segment_backward(&g, rows, inner, &seg, ns, mean).download();
                assert_eq!(bits(&got), bits(&want), "case {k} mean {mean}");
                let again = segment_backward(&g, rows, inner, &seg, ns, mean).download();
                assert_eq!(bits(&again), bits(&got), "case {k} mean {mean} rerun");
            }
        }
    }
}
