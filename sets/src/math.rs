//! Geometry aliases shared by every crate, so that geometry reads the same everywhere.
//!
//! World frame: x east, y north, z up, ground at z = 0; lengths in metres, angles in radians.
//! All geometry is `f64`; frames carry `f32` depth only on the wire.

/// Scalar type of all geometry.
pub type Real = f64;
/// A point in the world frame.
pub type Point3 = nalgebra::Point3<Real>;
/// A vector in the world frame.
pub type Vector3 = nalgebra::Vector3<Real>;
/// A point on the ground plane (x east, y north).
pub type Point2 = nalgebra::Point2<Real>;
/// A vector on the ground plane.
pub type Vector2 = nalgebra::Vector2<Real>;
/// A rigid motion (rotation + translation).
pub type Isometry3 = nalgebra::Isometry3<Real>;
/// A rotation in 3D.
pub type Rotation3 = nalgebra::Rotation3<Real>;

/// Wraps an angle into `(-pi, pi]`.
pub fn wrap_angle(a: Real) -> Real {
    let two_pi = std::f64::consts::TAU;
    let mut w = a.rem_euclid(two_pi);
    if w > std::f64::consts::PI {
        w -= two_pi;
    }
    w
}

/// `x.floor()`, bit for bit, without the library call that the baseline x86-64 target makes
/// of it (hot loops round millions of values per frame). Below `2^52` in magnitude a value
/// truncates exactly through `i64`; anything larger, infinite or NaN takes `floor` itself.
#[inline]
pub fn floor_fast(x: Real) -> Real {
    if x.abs() < 4_503_599_627_370_496.0 {
        let t = x as i64 as Real;
        // `t` is `x` rounded towards zero: one below for negative non-integers; a negative
        // value that truncates to zero keeps its sign as `floor` does.
        if t > x { t - 1.0 } else { t.copysign(x) }
    } else {
        x.floor()
    }
}

/// Convex hull (counter-clockwise, no repeated points) of a set of ground points,
/// by Andrew's monotone chain. Collinear points on the hull are dropped; points with a
/// non-finite coordinate are left out.
pub fn convex_hull(points: &[Point2]) -> Vec<Point2> {
    let mut hull = Vec::with_capacity(points.len() + 1);
    convex_hull_into(&mut points.to_vec(), &mut hull);
    hull
}

/// [`convex_hull`] for callers that take many hulls: reorders `points` in place and writes
/// the hull into `hull` (cleared first), so nothing is allocated once `hull` has room.
pub fn convex_hull_into(points: &mut [Point2], hull: &mut Vec<Point2>) {
    hull.clear();
    // The finite points first, then sorted, then each repeated point once (repeats are next
    // to each other once sorted).
    let mut finite = 0;
    for i in 0..points.len() {
        if points[i].x.is_finite() && points[i].y.is_finite() {
            points.swap(finite, i);
            finite += 1;
        }
    }
    let points = &mut points[..finite];
    points.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    let mut distinct = 0;
    for i in 0..points.len() {
        if distinct == 0 || points[i] != points[distinct - 1] {
            points[distinct] = points[i];
            distinct += 1;
        }
    }
    let pts = &points[..distinct];
    if pts.len() < 3 {
        hull.extend_from_slice(pts);
        return;
    }
    // Lower hull left to right, then upper hull right to left.
    monotone_chain(hull, pts.iter());
    monotone_chain(hull, pts.iter().rev());
}

/// One pass of the monotone chain: appends the turn-left chain of `ordered` to `hull` and
/// drops its last point (the next pass starts there). The points already in `hull` (the
/// floor) are never popped, so the upper pass keeps the lower hull.
fn monotone_chain<'a>(hull: &mut Vec<Point2>, ordered: impl Iterator<Item = &'a Point2>) {
    let cross =
        |o: &Point2, a: &Point2, b: &Point2| (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
    let floor = hull.len();
    for p in ordered {
        while hull.len() >= floor + 2
            && cross(&hull[hull.len() - 2], &hull[hull.len() - 1], p) <= 0.0
        {
            hull.pop();
        }
        hull.push(*p);
    }
    hull.pop();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_fast_is_floor_bit_for_bit() {
        let special = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.5,
            -2.5,
            1e-300,
            -1e-300,
            4503599627370495.5,
            -4503599627370495.5,
            4503599627370496.0,
            1e300,
            -1e300,
            Real::INFINITY,
            Real::NEG_INFINITY,
            Real::MIN_POSITIVE,
            -Real::MIN_POSITIVE,
        ];
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let random = (0..100_000).map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let x = Real::from_bits(state);
            if x.is_nan() { 0.25 } else { x }
        });
        for x in special.into_iter().chain(random) {
            assert_eq!(floor_fast(x).to_bits(), x.floor().to_bits(), "{x:e}");
        }
        assert!(floor_fast(Real::NAN).is_nan());
    }

    #[test]
    fn wrap_angle_stays_in_half_open_interval() {
        for k in -10..10 {
            let a = 0.3 + k as f64 * std::f64::consts::TAU;
            assert!((wrap_angle(a) - 0.3).abs() < 1e-9);
        }
        assert!((wrap_angle(-std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
    }

    #[test]
    fn hull_of_square_with_inner_point() {
        let pts = [
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(0.0, 1.0),
            Point2::new(0.5, 0.5),
        ];
        let h = convex_hull(&pts);
        assert_eq!(h.len(), 4);
        assert!(!h.contains(&Point2::new(0.5, 0.5)));
    }

    #[test]
    fn hull_keeps_repeated_points_once() {
        let p = |x, y| Point2::new(x, y);
        let h = convex_hull(&[
            p(0.0, 0.0),
            p(2.0, 0.0),
            p(0.0, 0.0),
            p(1.0, 3.0),
            p(2.0, 0.0),
        ]);
        assert_eq!(h, vec![p(0.0, 0.0), p(2.0, 0.0), p(1.0, 3.0)]);
        // Two distinct points (one repeated) are the hull, as a segment.
        assert_eq!(
            convex_hull(&[p(1.0, 1.0), p(1.0, 1.0), p(0.0, 2.0)]),
            vec![p(0.0, 2.0), p(1.0, 1.0)]
        );
        let mut buffer = vec![p(9.0, 9.0)];
        convex_hull_into(
            &mut [p(1.0, 1.0), p(f64::NAN, 0.0), p(1.0, 1.0)],
            &mut buffer,
        );
        assert_eq!(buffer, vec![p(1.0, 1.0)]);
    }
}
