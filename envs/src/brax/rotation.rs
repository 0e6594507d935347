//! The little rotation algebra the Brax loader needs: Brax's Euler convention and unit
//! quaternions in (w, x, y, z) order, in f64.

/// A unit quaternion (w, x, y, z).
pub type Quat = [f64; 4];
/// A 3-vector.
pub type Vec3 = [f64; 3];

/// The identity rotation.
pub const IDENTITY: Quat = [1.0, 0.0, 0.0, 0.0];

/// Brax v1's Euler angles (degrees, intrinsic x-y'-z'') to a quaternion (w, x, y, z).
///
/// With half angles a1 = x/2, a2 = y/2, a3 = z/2 (radians) and c_i = cos a_i, s_i = sin a_i
/// (MEBEN.md section 1): w = c1c2c3 - s1s2s3, x = s1c2c3 + c1s2s3, y = c1s2c3 - s1c2s3,
/// z = c1c2s3 + s1s2c3; that is q = q_x * q_y * q_z.
pub fn euler_degrees_to_quat(angles: Vec3) -> Quat {
    let [a1, a2, a3] = angles.map(|a| a.to_radians() / 2.0);
    let (s1, c1) = a1.sin_cos();
    let (s2, c2) = a2.sin_cos();
    let (s3, c3) = a3.sin_cos();
    [c1 * c2 * c3 - s1 * s2 * s3, s1 * c2 * c3 + c1 * s2 * s3, c1 * s2 * c3 - s1 * c2 * s3, c1 * c2 * s3 + s1 * s2 * c3]
}

/// The Hamilton product a * b (apply b first, then a).
pub fn quat_mul(a: Quat, b: Quat) -> Quat {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// The rotation by `angle` radians about the unit vector `axis`.
pub fn quat_from_axis_angle(axis: Vec3, angle: f64) -> Quat {
    let (s, c) = (angle / 2.0).sin_cos();
    [c, axis[0] * s, axis[1] * s, axis[2] * s]
}

/// Rotates `v` by the unit quaternion `q`.
pub fn quat_rotate(q: Quat, v: Vec3) -> Vec3 {
    let u = [q[1], q[2], q[3]];
    let w = q[0];
    // v' = v + 2w (u x v) + 2 u x (u x v)
    let t = scale(cross(u, v), 2.0);
    add(add(v, scale(t, w)), cross(u, t))
}

/// The quaternion scaled to unit length (identity if it is zero).
pub fn quat_normalize(q: Quat) -> Quat {
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    if n > 0.0 { q.map(|x| x / n) } else { IDENTITY }
}

/// The 3x3 rotation matrix (row-major) of a unit quaternion.
pub fn quat_to_matrix(q: Quat) -> [[f64; 3]; 3] {
    let c0 = quat_rotate(q, [1.0, 0.0, 0.0]);
    let c1 = quat_rotate(q, [0.0, 1.0, 0.0]);
    let c2 = quat_rotate(q, [0.0, 0.0, 1.0]);
    [[c0[0], c1[0], c2[0]], [c0[1], c1[1], c2[1]], [c0[2], c1[2], c2[2]]]
}

/// a + b.
pub fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// a - b.
pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// s * a.
pub fn scale(a: Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// The cross product a x b.
pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// The dot product.
pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &[f64], b: &[f64]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
    }

    #[test]
    fn single_axis_angles_are_half_angle_quaternions() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!(close(&euler_degrees_to_quat([90.0, 0.0, 0.0]), &[h, h, 0.0, 0.0]));
        assert!(close(&euler_degrees_to_quat([0.0, -90.0, 0.0]), &[h, 0.0, -h, 0.0]));
        assert!(close(&euler_degrees_to_quat([0.0, 0.0, 180.0]), &[0.0, 0.0, 0.0, 1.0]));
    }

    #[test]
    fn euler_is_intrinsic_x_then_y_then_z() {
        // Hand computation: x = 90, y = -90 (the ant's leg colliders). q = qx * qy with
        // qx = (h, h, 0, 0), qy = (h, 0, -h, 0), h = 1/sqrt(2): w = h*h = 1/2,
        // x = h*h = 1/2, y = h*(-h) = -1/2, z = h*(-h) = -1/2.
        let q = euler_degrees_to_quat([90.0, -90.0, 0.0]);
        assert!(close(&q, &[0.5, 0.5, -0.5, -0.5]), "{q:?}");
        // That rotation sends the capsule axis (local z) to -x: the leg capsules lie along
        // the limb's x axis.
        assert!(close(&quat_rotate(q, [0.0, 0.0, 1.0]), &[-1.0, 0.0, 0.0]));
        // Composition check against explicit intrinsic products for a generic triple.
        let (x, y, z) = (30.0_f64, 45.0_f64, -60.0_f64);
        let qx = quat_from_axis_angle([1.0, 0.0, 0.0], x.to_radians());
        let qy = quat_from_axis_angle([0.0, 1.0, 0.0], y.to_radians());
        let qz = quat_from_axis_angle([0.0, 0.0, 1.0], z.to_radians());
        let expected = quat_mul(quat_mul(qx, qy), qz);
        assert!(close(&euler_degrees_to_quat([x, y, z]), &expected));
    }

    #[test]
    fn rotate_and_matrix_agree() {
        let q = euler_degrees_to_quat([10.0, 20.0, 30.0]);
        let m = quat_to_matrix(q);
        let v = [0.3, -1.2, 2.0];
        let mv = [dot(m[0], v), dot(m[1], v), dot(m[2], v)];
        assert!(close(&quat_rotate(q, v), &mv));
        let n: f64 = q.iter().map(|x| x * x).sum();
        assert!((n - 1.0).abs() < 1e-12);
    }
}
