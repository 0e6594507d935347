//! Shape arithmetic: element counts, row-major strides, NumPy broadcasting and the
//! `(outer, axis, inner)` view that every axis-wise kernel uses.

use crate::error::{Result, mismatch};

/// Number of elements of a shape (1 for a scalar `[]`).
pub fn numel(shape: &[usize]) -> usize {
    shape.iter().product()
}

/// Row-major (C-order) strides of a contiguous tensor of this shape.
pub fn strides(shape: &[usize]) -> Vec<usize> {
    let mut s = vec![1; shape.len()];
    for i in (0..shape.len().saturating_sub(1)).rev() {
        s[i] = s[i + 1] * shape[i + 1];
    }
    s
}

/// Splits a shape around `axis` into `(outer, len, inner)`: the product of the dims before
/// it, its length, and the product of the dims after it.
pub fn split_at_axis(shape: &[usize], axis: usize) -> (usize, usize, usize) {
    (numel(&shape[..axis]), shape[axis], numel(&shape[axis + 1..]))
}

/// The NumPy broadcast of two shapes: align on the right, each pair of dims equal or one of
/// them 1.
pub fn broadcast_shapes(op: &'static str, a: &[usize], b: &[usize]) -> Result<Vec<usize>> {
    let n = a.len().max(b.len());
    let mut out = vec![0; n];
    for i in 0..n {
        let da = if i + a.len() >= n { a[i + a.len() - n] } else { 1 };
        let db = if i + b.len() >= n { b[i + b.len() - n] } else { 1 };
        out[i] = if da == db || db == 1 {
            da
        } else if da == 1 {
            db
        } else {
            return Err(mismatch(op, &[a, b], "cannot broadcast (dims must be equal or 1)"));
        };
    }
    Ok(out)
}

/// Strides that read a tensor of shape `src` as if it had the broadcast shape `out`
/// (0 along broadcast dims). `src` must broadcast to `out`.
pub fn broadcast_strides(src: &[usize], out: &[usize]) -> Vec<usize> {
    let st = strides(src);
    let off = out.len() - src.len();
    (0..out.len()).map(|i| if i < off || src[i - off] == 1 { 0 } else { st[i - off] }).collect()
}

/// Visits every index of `shape` in row-major order and reports, for each, the linear
/// offsets into two strided operands. The innermost dimension is handed over as a run so
/// callers can write tight loops: `f(out_offset, a_offset, b_offset, run_len, a_step, b_step)`.
pub(crate) fn for_each_run2(
    shape: &[usize],
    sa: &[usize],
    sb: &[usize],
    mut f: impl FnMut(usize, usize, usize, usize, usize, usize),
) {
    let nd = shape.len();
    if nd == 0 {
        f(0, 0, 0, 1, 0, 0);
        return;
    }
    let inner = shape[nd - 1];
    if inner == 0 || numel(shape) == 0 {
        return;
    }
    let (ia, ib) = (sa[nd - 1], sb[nd - 1]);
    let mut idx = vec![0usize; nd - 1];
    let (mut oa, mut ob, mut oo) = (0usize, 0usize, 0usize);
    loop {
        f(oo, oa, ob, inner, ia, ib);
        oo += inner;
        // Odometer increment over the outer dims.
        let mut d = nd - 1;
        loop {
            if d == 0 {
                return;
            }
            d -= 1;
            idx[d] += 1;
            oa += sa[d];
            ob += sb[d];
            if idx[d] < shape[d] {
                break;
            }
            oa -= sa[d] * shape[d];
            ob -= sb[d] * shape[d];
            idx[d] = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn broadcast_rules() {
        assert_eq!(broadcast_shapes("t", &[2, 1, 3], &[4, 1]).unwrap(), vec![2, 4, 3]);
        assert_eq!(broadcast_shapes("t", &[], &[5]).unwrap(), vec![5]);
        let e = broadcast_shapes("add", &[2, 3], &[4]).unwrap_err().to_string();
        assert!(e.contains("add") && e.contains("[2, 3]") && e.contains("[4]"), "{e}");
    }

    #[test]
    fn strides_and_split() {
        assert_eq!(strides(&[2, 3, 4]), vec![12, 4, 1]);
        assert_eq!(split_at_axis(&[2, 3, 4], 1), (2, 3, 4));
        assert_eq!(broadcast_strides(&[3, 1], &[2, 3, 4]), vec![0, 1, 0]);
    }

    #[test]
    fn runs_visit_every_element_once() {
        let shape = [2, 3, 4];
        let sa = strides(&shape);
        let sb = broadcast_strides(&[3, 1], &shape);
        let mut seen = vec![];
        for_each_run2(&shape, &sa, &sb, |o, a, b, n, da, db| {
            for k in 0..n {
                seen.push((o + k, a + k * da, b + k * db));
            }
        });
        assert_eq!(seen.len(), 24);
        for (o, a, b) in seen {
            assert_eq!(o, a);
            assert_eq!(b, (o / 4) % 3);
        }
    }
}
