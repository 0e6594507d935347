//! The local reference frame (paper eqs. (ortho), (ort_matrix), (lrf)) and heading frames.
//!
//! From a learned direction `u` (eq. (ortho)): `e3 = z`, `e1 = (u - <u, e3> e3) / |..|`,
//! and the third axis completes the frame. The paper writes `e2 = e1 x e3`, which makes
//! `[e1, e2, e3]` a reflection (determinant -1); this crate uses `e2 = e3 x e1`, so that
//! `O = [e1, e2, e3]` is a rotation (the right-handed frame MEBEN.md asks for). Either choice
//! is `SO_g(3)`-equivariant (`O(R u) = R O(u)` for rotations `R` about `z`), which is all
//! the invariance argument (Theorem "eqo") needs.

use tensor::{Float, Result, Tensor, Var};

/// `O = OP(u)` for `u: [N, 3]`: returns `[N, 3, 3]` whose columns are `e1, e2, e3`.
/// `eps` keeps the normalisation finite when `u` is (nearly) vertical.
pub fn local_frame<'t, T: Float>(u: Var<'t, T>, eps: f64) -> Result<Var<'t, T>> {
    let n = u.shape()[0];
    let tape = u.tape();
    // Horizontal part of u, normalised: e1 = (u_x, u_y, 0) / |.|.
    let ux = u.narrow(1, 0, 1)?;
    let uy = u.narrow(1, 1, 1)?;
    let horiz = tape.cat(&[ux, uy], 1)?; // [N, 2]
    let norm = horiz.norm_last(eps); // [N, 1]
    let c = ux.div(norm)?; // cos of the heading
    let s = uy.div(norm)?; // sin of the heading
    let zero = tape.constant(Tensor::zeros(&[n, 1]));
    let one = tape.constant(Tensor::ones(&[n, 1]));
    // Rows of O: [c, -s, 0], [s, c, 0], [0, 0, 1]  (columns e1 = (c, s, 0), e2 = (-s, c, 0), e3).
    let rows = [c, s.neg(), zero, s, c, zero, zero, zero, one];
    tape.cat(&rows, 1)?.reshape(&[n, 3, 3])
}

/// The heading frame of a yaw angle per entity (for the `+HN` baselines): `[N, 3, 3]`
/// rotations about `z` by `yaw`, built as constants.
pub fn heading_frame<T: Float>(yaw: &[f64]) -> Tensor<T> {
    let mut out = Vec::with_capacity(yaw.len() * 9);
    for &a in yaw {
        let (s, c) = a.sin_cos();
        out.extend([c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0].map(T::from_f64));
    }
    Tensor::new(out, &[yaw.len(), 3, 3]).expect("size by construction")
}

/// Expresses vectors in the frames (eq. (lrf)): `O^T Z` for `o: [N, 3, 3]`, `z: [N, 3, m]`.
pub fn to_frame<'t, T: Float>(o: Var<'t, T>, z: Var<'t, T>) -> Result<Var<'t, T>> {
    o.matmul_t(z, true, false)
}
