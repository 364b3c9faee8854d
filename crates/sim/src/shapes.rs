//! Exact ray intersections and footprint shapes. Every function returns the distance along a
//! ray with a unit direction, or `None`; none of them produce NaN for grazing, parallel or
//! degenerate input (tested below).

use glam::{DVec2, DVec3};

/// Tolerance on a segment's parameter, so that a beam through the shared corner of two
/// touching obstacles hits one of them (zero-width gaps stay closed).
const SEGMENT_PARAM_SLACK: f64 = 1e-9;

/// Distance along the ray `o + t d` (`d` unit) to segment `a`-`b`, if it is hit at `t >= 0`.
/// A ray running along the segment's own line does not hit it (a wall seen edge-on has no
/// width); the obstacle's neighbouring edges are hit instead.
pub fn ray_segment(o: DVec2, d: DVec2, a: DVec2, b: DVec2) -> Option<f64> {
    SegmentFromOrigin::new(o, a, b).hit(d)
}

/// One segment seen from one origin, with what does not depend on the ray's direction
/// computed once: a scan tests hundreds of directions against each segment.
#[derive(Debug, Clone, Copy)]
pub struct SegmentFromOrigin {
    e: DVec2,
    ao: DVec2,
    ao_perp_e: f64,
    parallel_tolerance: f64,
}

impl SegmentFromOrigin {
    pub fn new(o: DVec2, a: DVec2, b: DVec2) -> Self {
        let e = b - a;
        let ao = a - o;
        Self {
            e,
            ao,
            ao_perp_e: ao.perp_dot(e),
            parallel_tolerance: 1e-12 * e.length(),
        }
    }

    /// As [`ray_segment`], for the direction `d` (unit).
    #[inline]
    pub fn hit(&self, d: DVec2) -> Option<f64> {
        let denom = d.perp_dot(self.e);
        if denom.abs() <= self.parallel_tolerance {
            return None;
        }
        let inv = 1.0 / denom;
        let t = self.ao_perp_e * inv;
        if t < 0.0 {
            return None;
        }
        let s = self.ao.perp_dot(d) * inv;
        (-SEGMENT_PARAM_SLACK..=1.0 + SEGMENT_PARAM_SLACK)
            .contains(&s)
            .then_some(t)
    }
}

/// Distance along the ray to the circle (filled disc) at `c` of radius `r`. An origin on or
/// inside the disc gives 0.
pub fn ray_circle(o: DVec2, d: DVec2, c: DVec2, r: f64) -> Option<f64> {
    let m = o - c;
    let b = m.dot(d);
    let cc = m.length_squared() - r * r;
    if cc <= 0.0 {
        return Some(0.0);
    }
    if b >= 0.0 {
        return None; // outside and moving away
    }
    // r^2 minus the squared distance from the centre to the beam's line, from the
    // perpendicular offset itself: no cancellation of large squares for far circles.
    let perp = m - d * b;
    let disc = r * r - perp.length_squared();
    if disc < 0.0 {
        return None;
    }
    Some((-b - disc.sqrt()).max(0.0))
}

/// Distance along the 3D ray `o + t d` (`d` unit) to the ball of radius `r` at `c`.
fn ray_ball(o: DVec3, d: DVec3, c: DVec3, r: f64) -> Option<f64> {
    let m = o - c;
    let b = m.dot(d);
    let cc = m.length_squared() - r * r;
    if cc <= 0.0 {
        return Some(0.0);
    }
    if b >= 0.0 {
        return None;
    }
    let disc = r * r - (m - d * b).length_squared();
    (disc >= 0.0).then(|| (-b - disc.sqrt()).max(0.0))
}

/// Squared distance from `p` to segment `a`-`b` in 3D (a zero-length segment is a point).
pub fn point_segment_dist_sq(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let len_sq = ab.length_squared();
    let s = if len_sq > 0.0 {
        ((p - a).dot(ab) / len_sq).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * s - p).length_squared()
}

/// Distance along the 3D ray to the capsule (all points within `r` of segment `a`-`b`).
/// For a horizontal ray at the Lidar's height this is exactly the beam against the capsule's
/// cross-section with the scan plane, whatever its shape (ellipse-like for an oblique limb,
/// a long stadium for a limb lying parallel to the plane). An origin inside gives 0.
///
/// The first point of the capsule on the ray lies on the surface of one of its parts (the
/// side of the cylinder between the end planes, or one of the end balls), and every point on
/// those surfaces belongs to the capsule; so the nearest hit over the parts is exact.
pub fn ray_capsule(o: DVec3, d: DVec3, a: DVec3, b: DVec3, r: f64) -> Option<f64> {
    if point_segment_dist_sq(o, a, b) <= r * r {
        return Some(0.0);
    }
    let mut best = f64::INFINITY;
    let ab = b - a;
    let len_sq = ab.length_squared();
    if len_sq > 1e-18 {
        let axis = ab / len_sq.sqrt();
        // The ray and the origin offset with their components along the axis removed.
        let ao = o - a;
        let dp = d - axis * d.dot(axis);
        let mp = ao - axis * ao.dot(axis);
        let qa = dp.length_squared();
        // qa ~ 0: the ray runs along the axis; then the end balls are hit first (or nothing).
        if qa > 1e-14 {
            let qb = mp.dot(dp);
            let qc = mp.length_squared() - r * r;
            let disc = qb * qb - qa * qc;
            if disc >= 0.0 {
                let sq = disc.sqrt();
                // Both roots, computed without cancellation.
                let q = -(qb + qb.signum() * sq);
                let roots = if q != 0.0 {
                    [q / qa, qc / q]
                } else {
                    [-qb / qa, -qb / qa]
                };
                for t in roots {
                    if t >= 0.0 && t < best {
                        let along = (ao + d * t).dot(ab);
                        if (0.0..=len_sq).contains(&along) {
                            best = t;
                        }
                    }
                }
            }
        }
    }
    for end in [a, b] {
        if let Some(t) = ray_ball(o, d, end, r) {
            best = best.min(t);
        }
    }
    best.is_finite().then_some(best)
}

/// Is `p` inside the simple polygon (even-odd rule)? Points on an edge may go either way.
pub fn point_in_polygon(p: DVec2, poly: &[DVec2]) -> bool {
    let mut inside = false;
    let n = poly.len();
    for i in 0..n {
        let a = poly[i];
        let b = poly[(i + n - 1) % n];
        if (a.y > p.y) != (b.y > p.y) {
            let x = a.x + (p.y - a.y) * (b.x - a.x) / (b.y - a.y);
            if p.x < x {
                inside = !inside;
            }
        }
    }
    inside
}

/// Distance from `p` to segment `a`-`b` in the plane.
pub fn point_segment_dist(p: DVec2, a: DVec2, b: DVec2) -> f64 {
    let ab = b - a;
    let len_sq = ab.length_squared();
    let s = if len_sq > 0.0 {
        ((p - a).dot(ab) / len_sq).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * s - p).length()
}

/// Do segments `a`-`b` and `c`-`d` share a point (touching counts)?
pub fn segments_intersect(a: DVec2, b: DVec2, c: DVec2, d: DVec2) -> bool {
    let d1 = (b - a).perp_dot(c - a);
    let d2 = (b - a).perp_dot(d - a);
    let d3 = (d - c).perp_dot(a - c);
    let d4 = (d - c).perp_dot(b - c);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    let on = |p: DVec2, q: DVec2, r: DVec2, cross: f64| {
        cross == 0.0
            && r.x >= p.x.min(q.x)
            && r.x <= p.x.max(q.x)
            && r.y >= p.y.min(q.y)
            && r.y <= p.y.max(q.y)
    };
    on(a, b, c, d1) || on(a, b, d, d2) || on(c, d, a, d3) || on(c, d, b, d4)
}

/// Twice the signed area (positive counter-clockwise).
///
/// Summed from the first corner: on absolute coordinates a 5 x 4 m room at (1e9, 1e9) has
/// shoelace terms near 1e18 that cancel to exactly 0.
pub fn polygon_area2(poly: &[DVec2]) -> f64 {
    let Some(&origin) = poly.first() else {
        return 0.0;
    };
    let n = poly.len();
    (0..n)
        .map(|i| (poly[i] - origin).perp_dot(poly[(i + 1) % n] - origin))
        .sum()
}

/// The first pair of non-adjacent edges that cross, if the polygon is not simple.
pub fn polygon_self_intersection(poly: &[DVec2]) -> Option<(usize, usize)> {
    let n = poly.len();
    for i in 0..n {
        for j in i + 1..n {
            let adjacent = j == i + 1 || (i == 0 && j == n - 1);
            if adjacent {
                continue;
            }
            if segments_intersect(poly[i], poly[(i + 1) % n], poly[j], poly[(j + 1) % n]) {
                return Some((i, j));
            }
        }
    }
    None
}

/// Does segment `a`-`b` cross or touch any edge of the closed polygon `outline`?
pub fn segments_cross_outline(a: DVec2, b: DVec2, outline: &[DVec2]) -> bool {
    let n = outline.len();
    (0..n).any(|i| segments_intersect(a, b, outline[i], outline[(i + 1) % n]))
}

/// A footprint on the floor.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    Polygon(Vec<DVec2>),
    Circle { center: DVec2, radius: f64 },
}

impl Shape {
    /// Signed distance from `p` to the shape's boundary: negative inside.
    pub fn signed_distance(&self, p: DVec2) -> f64 {
        match self {
            Shape::Circle { center, radius } => (p - *center).length() - radius,
            Shape::Polygon(poly) => {
                let n = poly.len();
                let d = (0..n)
                    .map(|i| point_segment_dist(p, poly[i], poly[(i + 1) % n]))
                    .fold(f64::INFINITY, f64::min);
                if point_in_polygon(p, poly) { -d } else { d }
            }
        }
    }

    /// Axis-aligned bounds (min, max).
    pub fn bounds(&self) -> (DVec2, DVec2) {
        match self {
            Shape::Circle { center, radius } => (
                *center - DVec2::splat(*radius),
                *center + DVec2::splat(*radius),
            ),
            Shape::Polygon(poly) => poly.iter().fold(
                (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
                |(lo, hi), p| (lo.min(*p), hi.max(*p)),
            ),
        }
    }

    /// Does the segment `a`-`b` pass through (or touch) the shape?
    pub fn crosses_segment(&self, a: DVec2, b: DVec2) -> bool {
        match self {
            Shape::Circle { center, radius } => point_segment_dist(*center, a, b) <= *radius,
            Shape::Polygon(poly) => {
                let n = poly.len();
                point_in_polygon(a, poly)
                    || point_in_polygon(b, poly)
                    || (0..n).any(|i| segments_intersect(a, b, poly[i], poly[(i + 1) % n]))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const X: DVec2 = DVec2::X;

    #[test]
    fn segment_hit_miss_and_parallel() {
        let o = DVec2::ZERO;
        assert_eq!(
            ray_segment(o, X, DVec2::new(2.0, -1.0), DVec2::new(2.0, 1.0)),
            Some(2.0)
        );
        assert_eq!(
            ray_segment(o, -X, DVec2::new(2.0, -1.0), DVec2::new(2.0, 1.0)),
            None
        );
        // Along the segment's own line: no hit, no NaN.
        assert_eq!(
            ray_segment(o, X, DVec2::new(1.0, 0.0), DVec2::new(3.0, 0.0)),
            None
        );
        // Degenerate (zero-length) segment.
        assert_eq!(
            ray_segment(o, X, DVec2::new(1.0, 0.0), DVec2::new(1.0, 0.0)),
            None
        );
    }

    #[test]
    fn beam_through_a_shared_corner_is_not_lost() {
        // Two squares touching at (2, 0); a beam exactly through the shared corner.
        let o = DVec2::new(0.0, -2.0);
        let d = (DVec2::new(2.0, 0.0) - o).normalize();
        let left = ray_segment(o, d, DVec2::new(1.0, 0.0), DVec2::new(2.0, 0.0));
        let right = ray_segment(o, d, DVec2::new(2.0, 0.0), DVec2::new(3.0, 0.0));
        assert!(left.is_some() || right.is_some());
    }

    #[test]
    fn grazing_circle_is_stable() {
        let c = DVec2::new(5.0, 1.0);
        // Tangent ray along y = 0 touching the unit circle at (5, 0).
        let t = ray_circle(DVec2::ZERO, X, c, 1.0).expect("tangent ray touches");
        assert!((t - 5.0).abs() < 1e-6, "{t}");
        // Just outside: miss; just inside: hit near 5.
        assert_eq!(ray_circle(DVec2::new(0.0, -1e-9), X, c, 1.0), None);
        let t = ray_circle(DVec2::new(0.0, 1e-6), X, c, 1.0).unwrap();
        assert!(t.is_finite() && (t - 5.0).abs() < 2e-3);
        // Origin on the surface and inside.
        assert_eq!(ray_circle(DVec2::new(5.0, 0.0), X, c, 1.0), Some(0.0));
        assert_eq!(ray_circle(c, X, c, 1.0), Some(0.0));
    }

    #[test]
    fn far_circle_keeps_precision() {
        let t = ray_circle(DVec2::ZERO, X, DVec2::new(1e5, 0.0), 0.05).unwrap();
        assert!((t - (1e5 - 0.05)).abs() < 1e-6);
    }

    #[test]
    fn capsule_upright_matches_circle() {
        // An upright shin cut at its middle: a circle of the capsule's radius.
        let a = DVec3::new(3.0, 0.0, 0.0);
        let b = DVec3::new(3.0, 0.0, 0.5);
        let t = ray_capsule(DVec3::new(0.0, 0.0, 0.25), DVec3::X, a, b, 0.05).unwrap();
        assert!((t - 2.95).abs() < 1e-12);
    }

    #[test]
    fn capsule_oblique_gives_ellipse_width() {
        // A segment at 45 degrees through the plane: the section is an ellipse stretched to
        // r / cos(45) along the segment's direction.
        let r = 0.05;
        let a = DVec3::new(-1.0, 0.0, -1.0);
        let b = DVec3::new(1.0, 0.0, 1.0);
        let t = ray_capsule(DVec3::new(-3.0, 0.0, 0.0), DVec3::X, a, b, r).unwrap();
        let expect = 3.0 - r * std::f64::consts::SQRT_2;
        assert!((t - expect).abs() < 1e-12, "{t} vs {expect}");
    }

    #[test]
    fn capsule_parallel_to_plane_and_beam() {
        // A lying limb in the plane, seen end-on along its axis: the nearer end ball.
        let a = DVec3::new(2.0, 0.0, 0.0);
        let b = DVec3::new(4.0, 0.0, 0.0);
        let t = ray_capsule(DVec3::ZERO, DVec3::X, a, b, 0.1).unwrap();
        assert!((t - 1.9).abs() < 1e-12);
        // Seen side-on: a long stadium; a beam across its middle hits the side.
        let t = ray_capsule(DVec3::new(3.0, -2.0, 0.05), DVec3::Y, a, b, 0.1).unwrap();
        let expect = 2.0 - (0.01f64 - 0.0025).sqrt();
        assert!((t - expect).abs() < 1e-12);
        // Cut above its top: nothing.
        assert_eq!(
            ray_capsule(DVec3::new(3.0, -2.0, 0.11), DVec3::Y, a, b, 0.1),
            None
        );
    }

    #[test]
    fn capsule_nearly_parallel_has_no_nan() {
        for k in 0..50 {
            let tilt = 1e-15 * 10f64.powi(k / 4);
            let a = DVec3::new(2.0, 0.0, 0.0);
            let b = DVec3::new(4.0, tilt, tilt);
            for y in [-0.1, -0.05, 0.0, 0.05, 0.0999] {
                let hit = ray_capsule(DVec3::new(0.0, y, 0.0), DVec3::X, a, b, 0.1);
                let t = hit.expect("beam inside the stadium's width must hit");
                assert!(
                    t.is_finite() && (1.89..=2.0).contains(&t),
                    "tilt {tilt} y {y}: {t}"
                );
            }
        }
    }

    #[test]
    fn capsule_origin_inside_is_zero() {
        let a = DVec3::new(0.0, 0.0, -1.0);
        let b = DVec3::new(0.0, 0.0, 1.0);
        assert_eq!(ray_capsule(DVec3::ZERO, DVec3::X, a, b, 0.2), Some(0.0));
    }

    #[test]
    fn polygon_tests() {
        let sq = vec![
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(0.0, 1.0),
        ];
        assert!(point_in_polygon(DVec2::new(0.5, 0.5), &sq));
        assert!(!point_in_polygon(DVec2::new(1.5, 0.5), &sq));
        assert!(polygon_area2(&sq) > 0.0);
        assert_eq!(polygon_self_intersection(&sq), None);
        let bow = vec![
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(0.0, 1.0),
        ];
        assert!(polygon_self_intersection(&bow).is_some());
        let s = Shape::Polygon(sq);
        assert!((s.signed_distance(DVec2::new(0.5, 0.5)) + 0.5).abs() < 1e-12);
        assert!((s.signed_distance(DVec2::new(2.0, 0.5)) - 1.0).abs() < 1e-12);
    }
}
