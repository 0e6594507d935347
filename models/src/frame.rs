//! The local reference frame (paper eqs. (ortho), (ort_matrix), (lrf)) and heading frames:
//! [`local_frame`] builds `O = OP(u)`, [`lrf`] is eq. (lrf), an agent's observation `o'_i`
//! in its frame.
//!
//! From a learned direction `u` (eq. (ortho)): `e3 = z`, `e1 = (u - <u, e3> e3) / |..|`,
//! and the third axis completes the frame. The paper writes `e2 = e1 x e3`, which makes
//! `[e1, e2, e3]` a reflection (determinant -1); this crate uses `e2 = e3 x e1`, so that
//! `O = [e1, e2, e3]` is a rotation (the right-handed frame MEBEN.md asks for). Either choice
//! is `SO_g(3)`-equivariant (`O(R u) = R O(u)` for rotations `R` about `z`), which is all
//! the invariance argument (Theorem "eqo") needs.

use tensor::{Float, Tape, Tensor, Var};

use crate::error::{ModelError, Result};
use crate::input::{AgentBody, NeighbourRows};
use envs::layout::{N_SCALARS, NODE_VECTORS};

/// `O = OP(u)` for `u: [N, 3]`: returns `[N, 3, 3]` whose columns are `e1, e2, e3`.
/// `eps` keeps the normalisation finite when `u` is (nearly) vertical.
pub fn local_frame<'t, T: Float>(u: Var<'t, T>, eps: f64) -> tensor::Result<Var<'t, T>> {
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

/// Expresses vectors in frames: `O^T Z` `[N, c, m]` for `o: [N, 3, c]` (the `c` axes of each
/// frame as columns), `z: [N, 3, m]` (`m` vectors as columns).
pub fn to_frame<'t, T: Float>(o: Var<'t, T>, z: Var<'t, T>) -> tensor::Result<Var<'t, T>> {
    o.matmul_t(z, true, false)
}

/// The frame `O_i` of eq. (lrf), per scene.
#[derive(Clone, Debug)]
pub enum AgentFrame<'t, T: Float> {
    /// A learned frame on the tape, `[B, 3, c]`: SHNN's `O_i = OP(Z'_i W_u)` (`c = 3`, eqs.
    /// (ortho), (ort_matrix)) or SHNN:Og3's `O_i = Z'_i` (`c = m`).
    Learned(Var<'t, T>),
    /// A rotation about the vertical, `(sin, cos)` of its angle (its first axis is
    /// `(cos, sin, 0)`): the HNN family's world, heading or goal-direction frame, applied to
    /// the constant rows in `f64`.
    Horizontal(Vec<(f64, f64)>),
}

/// Agent `i`'s invariant observation `o'_i` of eq. (lrf), one row per node:
/// `z` `[B, R, c, 3]` (`O_i^T Z`, frame axes by channels position, velocity, angular
/// velocity) and `h` `[B, R, N_SCALARS]`, `R = K_i + |N(i)|` rows.
#[derive(Clone, Copy, Debug)]
pub struct LocalObservation<'t, T: Float> {
    /// `O_i^T Z_{i,k}`, then `O_i^T Z_{j,1}` for `j ∈ N(i)`.
    pub z: Var<'t, T>,
    /// `h_{i,k}`, then `h_{j,1}` for `j ∈ N(i)`.
    pub h: Var<'t, T>,
}

/// Eq. (lrf), agent `i`'s observation in its local reference frame:
///
/// `o'_i = O_i^T o_i = [{O_i^T Z_{i,k}, h_{i,k}}_{k=1}^{K_i}, O_i^T Z_{j,1}, h_{j,1}]`, `j ∈ N(i)`,
///
/// with positions relative by Algorithm 1's labels, `p_{i,k} - p_{C(i),1}` and
/// `p_{j,1} - p_{C(j),1}`. `body` holds the agent's own rows `Z_{i,k}`, `h_{i,k}` and
/// `neighbours` the rows `Z_{j,1}`, `h_{j,1}` of `N(i)` (`None`: no neighbour rows,
/// `neighbour=none`), positions already re-based as the translation mode says
/// ([`crate::input::InputProcessor::bodies`], [`crate::input::InputProcessor::neighbours`]);
/// `frame` is `O_i`. The rows are constants of the tape; a learned frame carries the gradient.
pub fn lrf<'t, T: Float>(
    tape: &'t Tape<T>,
    body: &AgentBody<T>,
    neighbours: Option<&NeighbourRows<T>>,
    frame: &AgentFrame<'t, T>,
) -> Result<LocalObservation<'t, T>> {
    // The agent's rows, then its neighbours', joined before they are placed on the tape.
    let join = |own: &Tensor<T>, theirs: Option<&Tensor<T>>| -> Result<Tensor<T>> {
        Ok(match theirs {
            Some(theirs) => Tensor::cat(&[own, theirs], 1)?,
            None => own.clone(),
        })
    };
    let z = join(&body.z, neighbours.map(|nr| &nr.z))?;
    let h = tape.constant(join(&body.h, neighbours.map(|nr| &nr.h))?);
    let (nb, rows) = (z.shape()[0], z.shape()[1]);
    let z = match frame {
        AgentFrame::Learned(o) => {
            if o.shape().len() != 3 || o.shape()[..2] != [nb, 3] {
                return Err(ModelError::Input(format!("frames {:?} for {nb} scenes", o.shape())));
            }
            // O_i of each scene for every row of that scene.
            let per_row: Vec<usize> = (0..nb).flat_map(|b| std::iter::repeat_n(b, rows)).collect();
            let z = tape.constant(z.reshape(&[nb * rows, 3, NODE_VECTORS])?);
            let local = to_frame(o.index_select(0, &per_row)?, z)?;
            local.reshape(&[nb, rows, o.shape()[2], NODE_VECTORS])?
        }
        AgentFrame::Horizontal(frames) => {
            if frames.len() != nb {
                return Err(ModelError::Input(format!("{} frames for {nb} scenes", frames.len())));
            }
            // The rows rotated in f64, then placed once (the tape's device).
            tape.constant(to_horizontal_frame(&z, rows, frames)?)
        }
    };
    debug_assert_eq!(h.shape(), [nb, rows, N_SCALARS]);
    Ok(LocalObservation { z, h })
}

/// The shape of eq. (lrf)'s `o'_i` for an agent of `dof` actuated DoF, `neighbours`
/// neighbour rows and a frame of `axes` axes: `(R, width)`, `R = K_i + |N(i)| = 1 + dof +
/// neighbours` rows of `3 axes + N_SCALARS` numbers each.
pub fn lrf_shape(dof: usize, neighbours: usize, axes: usize) -> (usize, usize) {
    (1 + dof + neighbours, axes * NODE_VECTORS + N_SCALARS)
}

/// `v` in the horizontal frame `(sin, cos)`: `O^T v` for `O` the rotation about `z` whose first
/// axis is `(cos, sin, 0)`.
pub fn rotate_horizontal(v: [f64; 3], (s, c): (f64, f64)) -> [f64; 3] {
    [c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]]
}

/// `O^T Z` for every `[3, NODE_VECTORS]` block of `z` (spatial rows), `O` the horizontal frame
/// of the block's scene, `frames[block / per_scene]` (computed in `f64`).
pub fn to_horizontal_frame<T: Float>(z: &Tensor<T>, per_scene: usize, frames: &[(f64, f64)]) -> Result<Tensor<T>> {
    let shape = z.shape().to_vec();
    let mut out = z.to_vec();
    for (i, blk) in out.chunks_mut(3 * NODE_VECTORS).enumerate() {
        let f = frames[i / per_scene];
        for k in 0..NODE_VECTORS {
            let v = rotate_horizontal([0, 1, 2].map(|r| blk[r * NODE_VECTORS + k].to_f64()), f);
            (0..3).for_each(|r| blk[r * NODE_VECTORS + k] = T::from_f64(v[r]));
        }
    }
    Ok(Tensor::new(out, &shape)?)
}
