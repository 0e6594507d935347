//! Small fixed-size linear algebra used by the simulator: 3-vectors, 3x3 matrices,
//! unit quaternions (w, x, y, z; Hamilton product, as MuJoCo) and 6-D spatial vectors.
//!
//! Everything is a plain array so that it lives on the stack and never allocates.
//! Spatial vectors follow Featherstone, *Rigid Body Dynamics Algorithms* (RBDA), ch. 2:
//! a motion vector is `[angular; linear]`, a force vector `[torque; force]`, both expressed in
//! world axes about a reference point (here: the root of the kinematic tree, see `kinematics`).

/// A 3-vector.
pub type Vec3 = [f64; 3];
/// A unit quaternion `(w, x, y, z)`.
pub type Quat = [f64; 4];
/// A 3x3 matrix, row-major.
pub type Mat3 = [[f64; 3]; 3];
/// A spatial (motion or force) vector `[angular(3); linear(3)]`.
pub type Vec6 = [f64; 6];

/// The identity quaternion.
pub const QUAT_IDENTITY: Quat = [1.0, 0.0, 0.0, 0.0];
/// The 3x3 identity matrix.
pub const MAT3_IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// `a + b`.
#[inline(always)]
pub fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `a - b`.
#[inline(always)]
pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `s * a`.
#[inline(always)]
pub fn scale(a: Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `a + s * b`.
#[inline(always)]
pub fn add_scaled(a: Vec3, b: Vec3, s: f64) -> Vec3 {
    [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
}

/// Dot product.
#[inline(always)]
pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Cross product `a x b`.
#[inline(always)]
pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Euclidean norm.
#[inline(always)]
pub fn norm(a: Vec3) -> f64 {
    dot(a, a).sqrt()
}

/// `a / |a|`, or `None` when `|a|` is (numerically) zero.
#[inline]
pub fn normalize(a: Vec3) -> Option<Vec3> {
    let n = norm(a);
    if n > 1e-15 { Some(scale(a, 1.0 / n)) } else { None }
}

/// `m * v`.
#[inline(always)]
pub fn mat_vec(m: &Mat3, v: Vec3) -> Vec3 {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}

/// `m^T * v`.
#[inline(always)]
pub fn mat_t_vec(m: &Mat3, v: Vec3) -> Vec3 {
    [
        m[0][0] * v[0] + m[1][0] * v[1] + m[2][0] * v[2],
        m[0][1] * v[0] + m[1][1] * v[1] + m[2][1] * v[2],
        m[0][2] * v[0] + m[1][2] * v[1] + m[2][2] * v[2],
    ]
}

/// `a * b`.
#[inline]
pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    r
}

/// `a^T`.
#[inline]
pub fn transpose(a: &Mat3) -> Mat3 {
    [[a[0][0], a[1][0], a[2][0]], [a[0][1], a[1][1], a[2][1]], [a[0][2], a[1][2], a[2][2]]]
}

/// `r * a * r^T`: a tensor given in a rotated frame expressed in the outer frame.
#[inline]
pub fn rotate_tensor(r: &Mat3, a: &Mat3) -> Mat3 {
    mat_mul(&mat_mul(r, a), &transpose(r))
}

/// `a + b` for matrices.
#[inline]
pub fn mat_add(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut r = *a;
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] += b[i][j];
        }
    }
    r
}

/// Parallel-axis term `m (|c|^2 I - c c^T)`: the inertia of a point mass `m` at offset `c`.
#[inline]
pub fn point_inertia(m: f64, c: Vec3) -> Mat3 {
    let cc = dot(c, c);
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = -m * c[i] * c[j];
        }
        r[i][i] += m * cc;
    }
    r
}

/// Hamilton product `a * b` (apply `b` first, then `a`, when rotating vectors).
#[inline(always)]
pub fn quat_mul(a: Quat, b: Quat) -> Quat {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// The conjugate (inverse for a unit quaternion).
#[inline(always)]
pub fn quat_conj(q: Quat) -> Quat {
    [q[0], -q[1], -q[2], -q[3]]
}

/// `q / |q|`; the identity when `|q|` is zero or not finite.
#[inline]
pub fn quat_normalize(q: Quat) -> Quat {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if n > 1e-15 && n.is_finite() { [q[0] / n, q[1] / n, q[2] / n, q[3] / n] } else { QUAT_IDENTITY }
}

/// Rotation of `angle` radians about the unit `axis`.
#[inline]
pub fn quat_axis_angle(axis: Vec3, angle: f64) -> Quat {
    let (s, c) = (0.5 * angle).sin_cos();
    [c, axis[0] * s, axis[1] * s, axis[2] * s]
}

/// The rotation matrix of a unit quaternion.
#[inline]
pub fn quat_to_mat(q: Quat) -> Mat3 {
    let [w, x, y, z] = q;
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, xz, yz) = (x * y, x * z, y * z);
    let (wx, wy, wz) = (w * x, w * y, w * z);
    [
        [1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)],
        [2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)],
        [2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)],
    ]
}

/// Rotates `v` by the unit quaternion `q`.
#[inline]
pub fn quat_rotate(q: Quat, v: Vec3) -> Vec3 {
    // v' = v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z).
    let u = [q[1], q[2], q[3]];
    let t = scale(cross(u, v), 2.0);
    add(add_scaled(v, t, q[0]), cross(u, t))
}

/// The shortest rotation taking the z axis onto the unit vector `d`.
pub fn quat_z_to(d: Vec3) -> Quat {
    let z = [0.0, 0.0, 1.0];
    let c = dot(z, d);
    if c < -1.0 + 1e-12 {
        // Opposite: half a turn about x.
        return [0.0, 1.0, 0.0, 0.0];
    }
    let a = cross(z, d);
    quat_normalize([1.0 + c, a[0], a[1], a[2]])
}

/// Quaternion of intrinsic Euler angles (radians) in the given axis sequence, e.g. `b"xyz"`;
/// lower-case letters are intrinsic (rotating) axes, upper-case extrinsic (fixed) ones, as in
/// MuJoCo's `compiler/eulerseq`.
pub fn quat_euler(angles: Vec3, seq: [u8; 3]) -> Quat {
    let mut q = QUAT_IDENTITY;
    for (k, &c) in seq.iter().enumerate() {
        let axis = match c.to_ascii_lowercase() {
            b'x' => [1.0, 0.0, 0.0],
            b'y' => [0.0, 1.0, 0.0],
            _ => [0.0, 0.0, 1.0],
        };
        let r = quat_axis_angle(axis, angles[k]);
        q = if c.is_ascii_lowercase() { quat_mul(q, r) } else { quat_mul(r, q) };
    }
    q
}

/// Motion cross product `v x m` (RBDA eq. 2.31): how the motion vector `m`, fixed in a frame
/// moving with velocity `v`, changes in time.
#[inline(always)]
pub fn cross_motion(v: &Vec6, m: &Vec6) -> Vec6 {
    let w = [v[0], v[1], v[2]];
    let vl = [v[3], v[4], v[5]];
    let a = [m[0], m[1], m[2]];
    let b = [m[3], m[4], m[5]];
    let r0 = cross(w, a);
    let r1 = add(cross(w, b), cross(vl, a));
    [r0[0], r0[1], r0[2], r1[0], r1[1], r1[2]]
}

/// Force cross product `v x* f` (RBDA eq. 2.32).
#[inline(always)]
pub fn cross_force(v: &Vec6, f: &Vec6) -> Vec6 {
    let w = [v[0], v[1], v[2]];
    let vl = [v[3], v[4], v[5]];
    let n = [f[0], f[1], f[2]];
    let fl = [f[3], f[4], f[5]];
    let r0 = add(cross(w, n), cross(vl, fl));
    let r1 = cross(w, fl);
    [r0[0], r0[1], r0[2], r1[0], r1[1], r1[2]]
}

/// Dot product of 6-vectors.
#[inline(always)]
pub fn dot6(a: &Vec6, b: &Vec6) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4] + a[5] * b[5]
}

/// A rigid-body spatial inertia about a reference point `p`, in world axes (RBDA eq. 2.63):
/// mass `m`, first moment `h = m c` (c: centre of mass minus `p`) and rotational inertia `i`
/// about `p`. Sums of such inertias about the same point are again spatial inertias, which is
/// what the composite rigid body algorithm needs.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpatialInertia {
    /// Rotational inertia about the reference point, world axes.
    pub i: Mat3,
    /// First mass moment `m c`.
    pub h: Vec3,
    /// Mass.
    pub m: f64,
}

impl SpatialInertia {
    /// The spatial inertia of a body of mass `m`, centre of mass at `c` relative to the
    /// reference point and rotational inertia `ic` about its centre of mass.
    #[inline]
    pub fn from_com(m: f64, c: Vec3, ic: &Mat3) -> Self {
        SpatialInertia { i: mat_add(ic, &point_inertia(m, c)), h: scale(c, m), m }
    }

    /// Componentwise sum (both about the same point).
    #[inline]
    pub fn add_assign(&mut self, o: &SpatialInertia) {
        for r in 0..3 {
            for c in 0..3 {
                self.i[r][c] += o.i[r][c];
            }
        }
        self.h = add(self.h, o.h);
        self.m += o.m;
    }

    /// `I * v`: the momentum of the body moving with spatial velocity `v`.
    #[inline(always)]
    pub fn mul(&self, v: &Vec6) -> Vec6 {
        let w = [v[0], v[1], v[2]];
        let vl = [v[3], v[4], v[5]];
        let n = add(mat_vec(&self.i, w), cross(self.h, vl));
        let f = sub(scale(vl, self.m), cross(self.h, w));
        [n[0], n[1], n[2], f[0], f[1], f[2]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_rotation_matches_matrix() {
        let q = quat_normalize([0.3, -0.2, 0.9, 0.1]);
        let v = [0.4, -1.3, 2.0];
        let a = quat_rotate(q, v);
        let b = mat_vec(&quat_to_mat(q), v);
        for k in 0..3 {
            // Both are a handful of flops on O(1) values: round-off is ~1e-15.
            assert!((a[k] - b[k]).abs() < 1e-12);
        }
        let d = normalize([1.0, -2.0, 0.5]).unwrap();
        let z = quat_rotate(quat_z_to(d), [0.0, 0.0, 1.0]);
        for k in 0..3 {
            assert!((z[k] - d[k]).abs() < 1e-12);
        }
    }

    #[test]
    fn spatial_inertia_momentum_is_physical() {
        // A point mass at c from the reference point, moving with the body: linear momentum
        // m (v + w x c), angular momentum about the point c x m(v + w x c).
        let c = [0.5, -0.2, 0.1];
        let si = SpatialInertia::from_com(2.0, c, &[[0.0; 3]; 3]);
        let v = [0.1, 0.2, -0.3, 1.0, 0.5, -0.7];
        let h = si.mul(&v);
        let vc = add([v[3], v[4], v[5]], cross([v[0], v[1], v[2]], c));
        let p = scale(vc, 2.0);
        let l = cross(c, p);
        for k in 0..3 {
            assert!((h[k] - l[k]).abs() < 1e-12);
            assert!((h[3 + k] - p[k]).abs() < 1e-12);
        }
    }
}
