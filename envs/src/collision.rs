//! Collision detection: a bounding-sphere broad phase over the candidate pairs fixed at build
//! time (different trees only, `contype`/`conaffinity` compatible), then exact narrow phases
//! for sphere/capsule against a plane and against each other. A capsule is the set of points
//! within `radius` of a segment, so every test reduces to the closest points of two segments
//! (or a segment and a point) and a sphere-sphere test (Ericson, *Real-Time Collision
//! Detection*, §5.1.9). Contacts are generated only for penetrating pairs (distance < 0).

use crate::data::{Contact, Data};
use crate::math::{self, Vec3};
use crate::model::{CapsuleEnds, Model, Shape};

/// Segment of a sphere (both ends at the centre) or capsule geom in world coordinates.
#[inline]
fn segment(m: &Model, d: &Data, g: usize) -> (Vec3, Vec3, f64) {
    let c = d.geom_xpos[g];
    match m.geoms[g].shape {
        Shape::Sphere { radius } => (c, c, radius),
        Shape::Capsule { radius, half_length } => {
            let x = &d.geom_xmat[g];
            let u = [x[0][2] * half_length, x[1][2] * half_length, x[2][2] * half_length];
            (math::sub(c, u), math::add(c, u), radius)
        }
        Shape::Plane => unreachable!("planes have no segment"),
    }
}

/// Closest points of segments `[p1, q1]` and `[p2, q2]` (Ericson §5.1.9).
pub fn closest_segment_points(p1: Vec3, q1: Vec3, p2: Vec3, q2: Vec3) -> (Vec3, Vec3) {
    let d1 = math::sub(q1, p1);
    let d2 = math::sub(q2, p2);
    let r = math::sub(p1, p2);
    let a = math::dot(d1, d1);
    let e = math::dot(d2, d2);
    let f = math::dot(d2, r);
    const EPS: f64 = 1e-14;
    let (s, t);
    if a <= EPS && e <= EPS {
        return (p1, p2);
    }
    if a <= EPS {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = math::dot(d1, r);
        if e <= EPS {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = math::dot(d1, d2);
            let denom = a * e - b * b;
            let s0 = if denom > EPS * a * e { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
            let t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            } else {
                t = t0;
                s = s0;
            }
        }
    }
    (math::add_scaled(p1, d1, s), math::add_scaled(p2, d2, t))
}

/// Contact between spheres at `c1` (radius `r1`, geom 1) and `c2` (`r2`, geom 2), if they
/// penetrate.
#[inline]
fn sphere_sphere(c1: Vec3, r1: f64, c2: Vec3, r2: f64) -> Option<(Vec3, Vec3, f64)> {
    let v = math::sub(c2, c1);
    let l = math::norm(v);
    let dist = l - r1 - r2;
    if dist >= 0.0 {
        return None;
    }
    // Concentric spheres: any direction will do; pick +z for determinism.
    let n = if l > 1e-12 { math::scale(v, 1.0 / l) } else { [0.0, 0.0, 1.0] };
    let pos = math::add_scaled(c1, n, r1 + 0.5 * dist);
    Some((pos, n, dist))
}

/// Finds all contacts of the current pose into `d.contacts`. Needs
/// [`crate::kinematics::kinematics`].
pub fn collide(m: &Model, d: &mut Data) {
    d.contacts.clear();
    if m.opt.disable_contact {
        return;
    }
    for pair in &m.plane_pairs {
        let (p, g) = (pair.g1, pair.g2);
        let x = &d.geom_xmat[p];
        let n = [x[0][2], x[1][2], x[2][2]];
        let p0 = d.geom_xpos[p];
        let c = d.geom_xpos[g];
        // Broad phase: bounding sphere against the plane.
        if math::dot(n, math::sub(c, p0)) >= m.geoms[g].rbound {
            continue;
        }
        let mu = m.geoms[p].friction.max(m.geoms[g].friction);
        let (a, b, r) = segment(m, d, g);
        let is_capsule = matches!(m.geoms[g].shape, Shape::Capsule { .. });
        let ends = m.geoms[g].ends;
        // Slot 0: the segment's +z end (or the sphere centre), slot 1: its -z end.
        let points = [(b, !is_capsule || ends != CapsuleEnds::Minus), (a, is_capsule && ends != CapsuleEnds::Plus)];
        for (k, (e, on)) in points.into_iter().enumerate() {
            if !on {
                continue;
            }
            let dist = math::dot(n, math::sub(e, p0)) - r;
            if dist < 0.0 {
                d.contacts.push(Contact {
                    pos: math::add_scaled(e, n, -(r + 0.5 * dist)),
                    normal: n,
                    dist,
                    geom1: p,
                    geom2: g,
                    friction: mu,
                    slot: pair.slot + k,
                });
            }
        }
    }
    if m.geom_pairs.is_empty() {
        return;
    }
    // Tree bounding spheres about each tree's reference point.
    for (t, tree) in m.trees.iter().enumerate() {
        let c = d.tree_ref[t];
        d.tree_rbound[t] = tree
            .geoms
            .iter()
            .map(|&g| math::norm(math::sub(d.geom_xpos[g], c)) + m.geoms[g].rbound)
            .fold(0.0, f64::max);
    }
    for group in &m.pair_groups {
        if group.tree2 != crate::model::NONE {
            let (t1, t2) = (group.tree1, group.tree2);
            let v = math::sub(d.tree_ref[t1], d.tree_ref[t2]);
            let r = d.tree_rbound[t1] + d.tree_rbound[t2];
            if math::dot(v, v) >= r * r {
                continue;
            }
        }
        collide_pairs(m, d, &m.geom_pairs[group.start..group.end]);
    }
}

/// Narrow phase of sphere/capsule pairs (after a bounding-sphere test per pair).
fn collide_pairs(m: &Model, d: &mut Data, pairs: &[crate::model::CollisionPair]) {
    for pair in pairs {
        let (g1, g2) = (pair.g1, pair.g2);
        let (c1, c2) = (d.geom_xpos[g1], d.geom_xpos[g2]);
        let rb = m.geoms[g1].rbound + m.geoms[g2].rbound;
        let v = math::sub(c2, c1);
        if math::dot(v, v) >= rb * rb {
            continue;
        }
        let (a1, b1, r1) = segment(m, d, g1);
        let (a2, b2, r2) = segment(m, d, g2);
        let (p1, p2) = closest_segment_points(a1, b1, a2, b2);
        if let Some((pos, normal, dist)) = sphere_sphere(p1, r1, p2, r2) {
            d.contacts.push(Contact {
                pos,
                normal,
                dist,
                geom1: g1,
                geom2: g2,
                friction: m.geoms[g1].friction.max(m.geoms[g2].friction),
                slot: pair.slot,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_closest_points() {
        // Crossing perpendicular segments 1 apart in z: closest points at the crossing.
        let (p, q) = closest_segment_points([-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, -1.0, 1.0], [0.0, 1.0, 1.0]);
        assert!(math::norm(math::sub(p, [0.0; 3])) < 1e-12);
        assert!(math::norm(math::sub(q, [0.0, 0.0, 1.0])) < 1e-12);
        // Parallel overlapping segments: distance 2 and both points inside the overlap.
        let (p, q) = closest_segment_points([0.0; 3], [2.0, 0.0, 0.0], [1.0, 2.0, 0.0], [3.0, 2.0, 0.0]);
        assert!((math::norm(math::sub(p, q)) - 2.0).abs() < 1e-12);
        // Point against a segment beyond its end: the end is closest.
        let (p, q) = closest_segment_points([5.0, 1.0, 0.0], [5.0, 1.0, 0.0], [0.0; 3], [2.0, 0.0, 0.0]);
        assert_eq!(p, [5.0, 1.0, 0.0]);
        assert!(math::norm(math::sub(q, [2.0, 0.0, 0.0])) < 1e-12);
    }
}
