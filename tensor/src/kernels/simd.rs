//! Hand-vectorised f32 kernels for x86-64 with AVX2 and FMA (detected at run time; other
//! machines and other element types keep the portable loops).
//!
//! Only one kernel lives here: the rows-against-rows dot products `out = A B^T` of the tiny
//! batched products (the backward of the subequivariant layers' `M C` and `Z^T Z`, eq.
//! (subeq2), and the forward of the normaliser's `Z Z^T`). Written portably, each of those dots ends in a horizontal sum of one vector,
//! which costs more than its four multiply-adds; here eight dots are reduced together (one
//! transpose-and-add of eight vectors), so the reduction is shared.
//!
//! The order of the additions depends only on the shapes, never on the thread count.

use std::any::TypeId;

use crate::element::Float;

/// [`rows_dot_f32`] for any element type: `false` unless `T` is `f32`.
pub(crate) fn rows_dot<T: Float>(
    out: &mut [T],
    accumulate: bool,
    a: &[T],
    b: &[T],
    m: usize,
    k: usize,
    n: usize,
) -> bool {
    if TypeId::of::<T>() != TypeId::of::<f32>() {
        return false;
    }
    // SAFETY: T is f32 (same type id), so the slices are reinterpreted as themselves.
    let (out, a, b) = unsafe {
        (
            std::slice::from_raw_parts_mut(out.as_mut_ptr().cast::<f32>(), out.len()),
            std::slice::from_raw_parts(a.as_ptr().cast::<f32>(), a.len()),
            std::slice::from_raw_parts(b.as_ptr().cast::<f32>(), b.len()),
        )
    };
    rows_dot_f32(out, accumulate, a, b, m, k, n)
}

/// `out[i, j] (+)= sum_p a[i, p] * b[j, p]` for `a` of `m x k` and `b` of `n x k`, row-major,
/// added to `out` when `accumulate` is set and written over it otherwise. Returns `false`
/// (and touches nothing) when the machine or the shape does not suit the kernel: `k` must be
/// a positive multiple of 8.
pub fn rows_dot_f32(out: &mut [f32], accumulate: bool, a: &[f32], b: &[f32], m: usize, k: usize, n: usize) -> bool {
    assert!(a.len() >= m * k && b.len() >= n * k && out.len() >= m * n, "rows_dot_f32: operand lengths");
    #[cfg(target_arch = "x86_64")]
    {
        if k > 0 && k.is_multiple_of(8) && has_avx2_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above), and the lengths
            // were checked against m, k and n.
            unsafe { x86::rows_dot(out, accumulate, a, b, m, k, n) };
            return true;
        }
    }
    let _ = (out, accumulate, a, b, m, k, n);
    false
}

/// Whether this CPU has AVX2 and FMA (the detection caches its answer).
#[cfg(target_arch = "x86_64")]
fn has_avx2_fma() -> bool {
    std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    /// Eight horizontal sums at once: lane `l` of the result is the sum of the lanes of
    /// `v[l]`, each summed as `((x0 + x1) + (x2 + x3)) + ((x4 + x5) + (x6 + x7))`.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn sum_lanes_8(v: &[__m256; 8]) -> __m256 {
        // hadd(x, y) = [x0+x1, x2+x3, y0+y1, y2+y3 | x4+x5, x6+x7, y4+y5, y6+y7].
        let t01 = _mm256_hadd_ps(v[0], v[1]);
        let t23 = _mm256_hadd_ps(v[2], v[3]);
        let t45 = _mm256_hadd_ps(v[4], v[5]);
        let t67 = _mm256_hadd_ps(v[6], v[7]);
        // [s0 lo, s1 lo, s2 lo, s3 lo | s0 hi, s1 hi, s2 hi, s3 hi], lo/hi = lanes 0-3 / 4-7.
        let u03 = _mm256_hadd_ps(t01, t23);
        let u47 = _mm256_hadd_ps(t45, t67);
        let lo = _mm256_permute2f128_ps::<0x20>(u03, u47);
        let hi = _mm256_permute2f128_ps::<0x31>(u03, u47);
        _mm256_add_ps(lo, hi)
    }

    /// See [`super::rows_dot_f32`]; the caller guarantees AVX2 and FMA, `k % 8 == 0` and
    /// the operand lengths.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn rows_dot(
        out: &mut [f32],
        accumulate: bool,
        a: &[f32],
        b: &[f32],
        m: usize,
        k: usize,
        n: usize,
    ) {
        let (ap, bp, op) = (a.as_ptr(), b.as_ptr(), out.as_mut_ptr());
        // SAFETY: every pointer below stays in bounds: row i of a spans [i k, (i + 1) k) with
        // i < m, rows j of b span [j k, (j + 1) k) with j < n, and out[i n + j] with
        // j < n; the caller checked a.len() >= m k, b.len() >= n k, out.len() >= m n,
        // and k is a multiple of 8, so every 8-lane load stays inside its row.
        unsafe {
            for i in 0..m {
                let ar = ap.add(i * k);
                let mut j0 = 0;
                while j0 < n {
                    let nb = (n - j0).min(8);
                    let mut acc = [_mm256_setzero_ps(); 8];
                    for p in (0..k).step_by(8) {
                        let av = _mm256_loadu_ps(ar.add(p));
                        for (jj, s) in acc.iter_mut().enumerate().take(nb) {
                            let bv = _mm256_loadu_ps(bp.add((j0 + jj) * k + p));
                            *s = _mm256_fmadd_ps(av, bv, *s);
                        }
                    }
                    let mut r = sum_lanes_8(&acc);
                    let o = op.add(i * n + j0);
                    if nb == 8 {
                        if accumulate {
                            r = _mm256_add_ps(_mm256_loadu_ps(o), r);
                        }
                        _mm256_storeu_ps(o, r);
                    } else {
                        let mut lanes = [0.0f32; 8];
                        _mm256_storeu_ps(lanes.as_mut_ptr(), r);
                        for (jj, &v) in lanes.iter().enumerate().take(nb) {
                            let dst = &mut *o.add(jj);
                            *dst = if accumulate { *dst + v } else { v };
                        }
                    }
                    j0 += nb;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::rows_dot_f32;

    /// Deterministic values in [-1, 1).
    fn values(len: usize, seed: u32) -> Vec<f32> {
        (0..len)
            .map(|i| ((i as u32).wrapping_mul(2_654_435_761).wrapping_add(seed) >> 8) as f32 / 8_388_608.0 - 1.0)
            .collect()
    }

    #[test]
    fn rows_dot_matches_f64_loops_written_and_added() {
        for &(m, k, n) in &[(3, 32, 32), (1, 8, 1), (4, 16, 7), (3, 40, 9), (2, 8, 16), (5, 24, 23)] {
            let (a, b) = (values(m * k, 1), values(n * k, 2));
            let start = values(m * n, 3);
            let want: Vec<f64> = (0..m * n)
                .map(|ij| (0..k).map(|p| a[ij / n * k + p] as f64 * b[ij % n * k + p] as f64).sum())
                .collect();
            for accumulate in [false, true] {
                let mut out = start.clone();
                let used = rows_dot_f32(&mut out, accumulate, &a, &b, m, k, n);
                #[cfg(target_arch = "x86_64")]
                assert_eq!(used, super::has_avx2_fma(), "kernel used exactly when the CPU has AVX2 and FMA");
                if !used {
                    assert_eq!(out, start, "an unused kernel leaves the output alone");
                    continue;
                }
                for (ij, (&got, &w)) in out.iter().zip(&want).enumerate() {
                    let w = if accumulate { w + start[ij] as f64 } else { w };
                    assert!((got as f64 - w).abs() <= 1e-6 * (k + 1) as f64, "m{m} k{k} n{n} at {ij}: {got} vs {w}");
                }
            }
        }
        // Inner sizes that are not multiples of 8 are left to the portable loops.
        let mut out = vec![0.0; 9];
        assert!(!rows_dot_f32(&mut out, false, &[1.0; 21], &[1.0; 21], 3, 7, 3));
    }
}
