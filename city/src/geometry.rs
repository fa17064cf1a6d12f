//! Plane geometry on `[x, y]` points in metres: areas, distances and convex polygons.
//!
//! Polygons are rings of points without the closing repeat. A convex part is counter-clockwise.

/// A point of the local metric frame: `[east, north]`, metres.
pub type Xy = [f64; 2];

/// Twice the signed area of the triangle `a b c`: positive when it turns left.
pub fn cross(a: Xy, b: Xy, c: Xy) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// The signed area of a ring: positive when counter-clockwise.
pub fn signed_area(ring: &[Xy]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|i| {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

/// Euclidean distance.
pub fn dist(a: Xy, b: Xy) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Length of a polyline.
pub fn length(line: &[Xy]) -> f64 {
    line.windows(2).map(|w| dist(w[0], w[1])).sum()
}

/// The point `a + t (b - a)`.
pub fn lerp(a: Xy, b: Xy, t: f64) -> Xy {
    [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
}

/// Distance from `p` to the segment `a b`.
pub fn point_segment_distance(p: Xy, a: Xy, b: Xy) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    dist(p, lerp(a, b, t))
}

/// Whether the closed segments `a b` and `c d` meet.
pub fn segments_intersect(a: Xy, b: Xy, c: Xy, d: Xy) -> bool {
    let (d1, d2) = (cross(a, b, c), cross(a, b, d));
    let (d3, d4) = (cross(c, d, a), cross(c, d, b));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    // Touching or collinear: an end lies on the other segment.
    let on = |p: Xy, q: Xy, r: Xy, turn: f64| {
        turn == 0.0
            && r[0] >= p[0].min(q[0])
            && r[0] <= p[0].max(q[0])
            && r[1] >= p[1].min(q[1])
            && r[1] <= p[1].max(q[1])
    };
    on(a, b, c, d1) || on(a, b, d, d2) || on(c, d, a, d3) || on(c, d, b, d4)
}

/// Distance between the segments `a b` and `c d` (0 when they meet).
pub fn segment_segment_distance(a: Xy, b: Xy, c: Xy, d: Xy) -> f64 {
    if segments_intersect(a, b, c, d) {
        return 0.0;
    }
    point_segment_distance(a, c, d)
        .min(point_segment_distance(b, c, d))
        .min(point_segment_distance(c, a, b))
        .min(point_segment_distance(d, a, b))
}

/// Distance from the segment `a b` to the convex counter-clockwise polygon `poly` (0 when they
/// meet): exact, the least of the distances to its edges unless an end lies inside.
pub fn segment_convex_distance(a: Xy, b: Xy, poly: &[Xy]) -> f64 {
    if convex_contains(poly, a) || convex_contains(poly, b) {
        return 0.0;
    }
    let n = poly.len();
    (0..n)
        .map(|i| segment_segment_distance(a, b, poly[i], poly[(i + 1) % n]))
        .fold(f64::INFINITY, f64::min)
}

/// Whether `p` lies inside the ring `ring` of any shape (the even-odd rule; a point on an edge
/// may fall either way).
pub fn ring_contains(ring: &[Xy], p: Xy) -> bool {
    let n = ring.len();
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + n - 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1])
            && p[0] < a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
        {
            inside = !inside;
        }
    }
    inside
}

/// Whether `p` lies inside or on the convex counter-clockwise polygon `poly`.
pub fn convex_contains(poly: &[Xy], p: Xy) -> bool {
    let n = poly.len();
    n >= 3 && (0..n).all(|i| cross(poly[i], poly[(i + 1) % n], p) >= 0.0)
}

/// Distance from `p` to the convex counter-clockwise polygon `poly` (0 inside).
pub fn point_convex_distance(p: Xy, poly: &[Xy]) -> f64 {
    if convex_contains(poly, p) {
        return 0.0;
    }
    let n = poly.len();
    (0..n)
        .map(|i| point_segment_distance(p, poly[i], poly[(i + 1) % n]))
        .fold(f64::INFINITY, f64::min)
}

/// Whether a ring is strictly convex and counter-clockwise (no three consecutive points on a
/// line, no reflex corner).
pub fn is_convex_ccw(ring: &[Xy]) -> bool {
    let n = ring.len();
    n >= 3 && (0..n).all(|i| cross(ring[i], ring[(i + 1) % n], ring[(i + 2) % n]) > 0.0)
}

/// The part of the convex polygon `poly` inside the axis-aligned square `[-h, h]^2`
/// (Sutherland-Hodgman against the square's four sides): convex, possibly empty.
pub fn clip_convex_to_square(poly: &[Xy], h: f64) -> Vec<Xy> {
    // Each side as (axis, sign): keep points with sign * p[axis] <= h.
    let mut out = poly.to_vec();
    for (axis, sign) in [(0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0)] {
        let input = std::mem::take(&mut out);
        let n = input.len();
        let inside = |p: Xy| sign * p[axis] <= h;
        for i in 0..n {
            let (a, b) = (input[i], input[(i + 1) % n]);
            if inside(a) {
                out.push(a);
            }
            if inside(a) != inside(b) {
                let t = (sign * h - a[axis]) / (b[axis] - a[axis]);
                out.push(lerp(a, b, t));
            }
        }
    }
    out
}

/// Drops repeated points and points on a straight line between their neighbours, so that a
/// convex ring becomes strictly convex (see [`is_convex_ccw`]). `eps` is twice an area, m².
pub fn simplify_ring(ring: &[Xy], eps: f64) -> Vec<Xy> {
    let mut out: Vec<Xy> = Vec::with_capacity(ring.len());
    for &p in ring {
        if out.last().is_none_or(|&q| dist(p, q) > 1e-9) {
            out.push(p);
        }
    }
    while out.len() > 1 && dist(out[0], out[out.len() - 1]) <= 1e-9 {
        out.pop();
    }
    loop {
        let n = out.len();
        if n < 3 {
            return out;
        }
        let drop =
            (0..n).find(|&i| cross(out[(i + n - 1) % n], out[i], out[(i + 1) % n]).abs() <= eps);
        match drop {
            Some(i) => {
                out.remove(i);
            }
            None => return out,
        }
    }
}

/// The parameter interval `[t0, t1]` of the segment `a + t (b - a)`, `t` in `[0, 1]`, whose
/// points are closer than `d` to the convex polygon `poly`, if any.
///
/// The distance from a point moving along a line to a convex set is a convex function of `t`,
/// so the points closer than `d` form one interval. Its minimum is found by ternary search and
/// its ends by bisection to within `tol` metres, widened outward by `tol`: the interval returned
/// holds every point closer than `d`.
pub fn segment_near_convex(a: Xy, b: Xy, poly: &[Xy], d: f64, tol: f64) -> Option<(f64, f64)> {
    let len = dist(a, b);
    let f = |t: f64| point_convex_distance(lerp(a, b, t), poly);
    if len <= tol {
        return (f(0.0).min(f(1.0)) < d + tol).then_some((0.0, 1.0));
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    let step = tol / len;
    while hi - lo > step {
        let m1 = lo + (hi - lo) / 3.0;
        let m2 = hi - (hi - lo) / 3.0;
        if f(m1) <= f(m2) {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    let t_min = (lo + hi) / 2.0;
    // The sampled minimum can miss the true one by the ternary search's resolution; a point
    // within `tol` of the line's closest approach counts as near.
    if f(t_min) >= d + tol {
        return None;
    }
    let edge = |mut inside: f64, mut outside: f64| {
        while (outside - inside).abs() > step {
            let m = (inside + outside) / 2.0;
            if f(m) < d {
                inside = m;
            } else {
                outside = m;
            }
        }
        outside
    };
    let t0 = if f(0.0) < d { 0.0 } else { edge(t_min, 0.0) };
    let t1 = if f(1.0) < d { 1.0 } else { edge(t_min, 1.0) };
    Some(((t0 - step).max(0.0), (t1 + step).min(1.0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    const SQUARE: [Xy; 4] = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];

    #[test]
    fn areas_and_orientation() {
        assert_eq!(signed_area(&SQUARE), 100.0);
        let mut cw = SQUARE;
        cw.reverse();
        assert_eq!(signed_area(&cw), -100.0);
        assert!(is_convex_ccw(&SQUARE));
        assert!(!is_convex_ccw(&cw));
    }

    #[test]
    fn distances_to_a_square() {
        assert_eq!(point_convex_distance([5.0, 5.0], &SQUARE), 0.0);
        assert_eq!(point_convex_distance([13.0, 5.0], &SQUARE), 3.0);
        assert_eq!(point_convex_distance([13.0, 14.0], &SQUARE), 5.0);
    }

    #[test]
    fn segment_distances() {
        // Crossing the square, beside it, and touching a corner.
        assert_eq!(
            segment_convex_distance([-5.0, 5.0], [15.0, 5.0], &SQUARE),
            0.0
        );
        assert_eq!(
            segment_convex_distance([-5.0, 12.0], [15.0, 12.0], &SQUARE),
            2.0
        );
        assert_eq!(
            segment_convex_distance([10.0, 10.0], [20.0, 20.0], &SQUARE),
            0.0
        );
        let d = segment_convex_distance([13.0, 0.0], [20.0, 14.0], &SQUARE);
        assert!((d - 3.0).abs() < 1e-12, "{d}");
        assert!(segments_intersect(
            [0.0, 0.0],
            [4.0, 0.0],
            [2.0, 0.0],
            [6.0, 0.0]
        ));
        assert!(!segments_intersect(
            [0.0, 0.0],
            [1.0, 0.0],
            [2.0, 0.0],
            [6.0, 0.0]
        ));
    }

    #[test]
    fn clipping_keeps_the_inside() {
        let poly = [[-20.0, -5.0], [5.0, -5.0], [5.0, 5.0], [-20.0, 5.0]];
        let clipped = clip_convex_to_square(&poly, 10.0);
        assert!((signed_area(&clipped) - 150.0).abs() < 1e-9);
        assert!(
            clip_convex_to_square(&[[20.0, 20.0], [30.0, 20.0], [30.0, 30.0]], 10.0).is_empty()
        );
    }

    #[test]
    fn collinear_points_are_dropped() {
        let ring = [
            [0.0, 0.0],
            [5.0, 0.0],
            [10.0, 0.0],
            [10.0, 10.0],
            [10.0, 10.0],
            [0.0, 10.0],
        ];
        assert_eq!(simplify_ring(&ring, 1e-9), SQUARE.to_vec());
    }

    #[test]
    fn the_near_part_of_a_segment_is_one_interval() {
        // A road along y = 12 passes 2 m above the square's top edge: within 3 m from x = -2.24
        // to x = 12.24 (the corners' discs of radius 3 meet the line at sqrt(9 - 4) = 2.236).
        let (t0, t1) =
            segment_near_convex([-20.0, 12.0], [30.0, 12.0], &SQUARE, 3.0, 1e-3).unwrap();
        let (x0, x1) = (-20.0 + 50.0 * t0, -20.0 + 50.0 * t1);
        assert!((x0 + 2.236).abs() < 0.01 && x0 <= -2.236, "{x0}");
        assert!((x1 - 12.236).abs() < 0.01 && x1 >= 12.236, "{x1}");
        assert!(segment_near_convex([-20.0, 14.0], [30.0, 14.0], &SQUARE, 3.0, 1e-3).is_none());
    }
}
