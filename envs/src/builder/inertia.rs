//! Inertia from geometry, as MuJoCo's `inertiafromgeom`: every sphere and capsule geom of a
//! body is a solid of uniform density (or of a given mass); the body's mass, centre of mass
//! and inertia tensor are the sums (parallel-axis theorem).

use crate::math::{self, Mat3, Vec3};
use crate::model::Shape;

/// Mass and inertia (about the centre, geom axes) of a solid sphere or capsule.
///
/// Capsule (radius r, cylinder height h = 2 * half_length, axis z): the cylinder has
/// `I_z = m r^2 / 2`, `I_x = m (3 r^2 + h^2) / 12`; each hemisphere of mass `m_s / 2` has
/// `I_z = m r^2 / 5 * ...` about the axis and, about a transverse axis through its own centre
/// of mass (at 3r/8 from the flat face), `83/320 m r^2`; moving both to the capsule centre
/// (distance h/2 + 3r/8) gives `m_s (2 r^2 / 5 + h (3 r + 2 h) / 8)` for the pair.
pub(super) fn solid_inertia(shape: &Shape, density: f64, mass: Option<f64>) -> Option<(f64, Mat3)> {
    use std::f64::consts::PI;
    let diag = |a: f64, b: f64, c: f64| [[a, 0.0, 0.0], [0.0, b, 0.0], [0.0, 0.0, c]];
    match *shape {
        Shape::Plane => None,
        Shape::Sphere { radius: r } => {
            let vol = 4.0 / 3.0 * PI * r * r * r;
            let m = mass.unwrap_or(density * vol);
            let i = 0.4 * m * r * r;
            Some((m, diag(i, i, i)))
        }
        Shape::Capsule { radius: r, half_length } => {
            let h = 2.0 * half_length;
            let v_sph = 4.0 / 3.0 * PI * r * r * r;
            let v_cyl = PI * r * r * h;
            let m = mass.unwrap_or(density * (v_sph + v_cyl));
            let ms = m * v_sph / (v_sph + v_cyl);
            let mc = m - ms;
            let ix = mc * (3.0 * r * r + h * h) / 12.0 + ms * (0.4 * r * r + h * (3.0 * r + 2.0 * h) / 8.0);
            let iz = mc * r * r / 2.0 + ms * 0.4 * r * r;
            Some((m, diag(ix, ix, iz)))
        }
    }
}

/// Total mass, centre of mass and inertia about it of parts `(mass, centre, inertia about
/// own centre)`.
pub(super) fn combine(parts: &[(f64, Vec3, Mat3)]) -> (f64, Vec3, Mat3) {
    let m: f64 = parts.iter().map(|p| p.0).sum();
    if m <= 0.0 {
        return (0.0, [0.0; 3], [[0.0; 3]; 3]);
    }
    let mut c = [0.0; 3];
    for p in parts {
        c = math::add_scaled(c, p.1, p.0 / m);
    }
    let mut i = [[0.0; 3]; 3];
    for p in parts {
        i = math::mat_add(&i, &math::mat_add(&p.2, &math::point_inertia(p.0, math::sub(p.1, c))));
    }
    (m, c, i)
}
