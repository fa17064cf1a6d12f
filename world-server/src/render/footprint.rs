//! The exact image footprint of an object (a box or a convex prism): which pixels it can
//! appear in.
//!
//! The object is clipped against the camera's near plane, its remaining vertices are projected,
//! and the 2D convex hull of the projections is the box's silhouette (the projection of a
//! convex polytope is the hull of its projected vertices). For each image row, the footprint
//! keeps the span of columns whose closed pixel rectangle the silhouette touches, widened by
//! [`TOUCH_EPS_PX`] so that rounding can only add pixels, never lose one.

use protocol::camera::Camera;
use sets::math::{Point2, Point3, Real, convex_hull};

use super::objects::SceneObject;

/// Camera depth of the near plane. A ray from the optical centre meets points of camera depth
/// in `(0, NEAR_PLANE_M)` only within a micrometre of the centre, where no object ever is.
pub const NEAR_PLANE_M: Real = 1e-6;
/// Widening of silhouettes, in pixels, covering projection rounding.
pub const TOUCH_EPS_PX: Real = 1e-6;

/// The pixels an object can appear in: for rows `row0..row0 + spans.len()`, the inclusive
/// column span `(c0, c1)` (empty when `c0 > c1`).
#[derive(Clone, Debug, PartialEq)]
pub struct Footprint {
    /// First row touched.
    pub row0: u32,
    /// Column span per row.
    pub spans: Vec<(u32, u32)>,
}

impl Footprint {
    /// Span of row `r`, if the object touches it.
    pub fn span(&self, r: u32) -> Option<(u32, u32)> {
        let i = r.checked_sub(self.row0)? as usize;
        self.spans.get(i).copied().filter(|(a, b)| a <= b)
    }
}

/// The footprint of `object` in `camera`'s image, or `None` if it touches no pixel.
pub fn footprint(camera: &Camera, object: &SceneObject) -> Option<Footprint> {
    let verts = object.vertices();
    let depth: Vec<Real> = verts.iter().map(|v| camera.axial_depth(v)).collect();
    if depth.iter().all(|&z| z < NEAR_PLANE_M) {
        return None;
    }
    let mut pts: Vec<Point2> = Vec::with_capacity(2 * verts.len());
    let mut push = |p: &Point3| {
        if let Some((u, v)) = camera.project(p) {
            pts.push(Point2::new(u, v));
        }
    };
    for (v, &z) in verts.iter().zip(&depth) {
        if z >= NEAR_PLANE_M {
            push(v);
        }
    }
    for (a, b) in object.edges() {
        let (za, zb) = (depth[a], depth[b]);
        if (za < NEAR_PLANE_M) != (zb < NEAR_PLANE_M) {
            // Nudge the cut slightly to the far side, so that its depth is surely above
            // the projection's own cut-off.
            let t = (za - 2.0 * NEAR_PLANE_M) / (za - zb);
            let t = t.clamp(0.0, 1.0);
            push(&(verts[a] + (verts[b] - verts[a]) * t));
        }
    }
    let hull = convex_hull(&pts);
    spans(&hull, camera.model.rows, camera.model.cols)
}

/// Per-row column spans of the closed pixels a convex polygon touches.
fn spans(hull: &[Point2], rows: u32, cols: u32) -> Option<Footprint> {
    if hull.is_empty() || rows == 0 || cols == 0 {
        return None;
    }
    let e = TOUCH_EPS_PX;
    let vmin = hull.iter().map(|p| p.y).fold(Real::INFINITY, Real::min) - e;
    let vmax = hull.iter().map(|p| p.y).fold(Real::NEG_INFINITY, Real::max) + e;
    // Row r covers [r, r + 1]: touched when r <= vmax and r + 1 >= vmin.
    let r_lo = (vmin.ceil() - 1.0).max(0.0);
    let r_hi = vmax.floor().min(rows as Real - 1.0);
    // NaN bounds (never expected) fail this test too and give no footprint.
    if r_lo
        .partial_cmp(&r_hi)
        .is_none_or(|o| o == std::cmp::Ordering::Greater)
    {
        return None;
    }
    let (r_lo, r_hi) = (r_lo as u32, r_hi as u32);
    let mut out = Vec::with_capacity((r_hi - r_lo + 1) as usize);
    let mut any = false;
    for r in r_lo..=r_hi {
        let span = u_range(hull, r as Real - e, r as Real + 1.0 + e).and_then(|(a, b)| {
            let c_lo = ((a - e).ceil() - 1.0).max(0.0);
            let c_hi = (b + e).floor().min(cols as Real - 1.0);
            (c_lo <= c_hi).then_some((c_lo as u32, c_hi as u32))
        });
        any |= span.is_some();
        out.push(span.unwrap_or((1, 0)));
    }
    any.then_some(Footprint {
        row0: r_lo,
        spans: out,
    })
}

/// Range of `u` over the convex polygon (or segment, or point) `poly` within the strip
/// `v_lo <= v <= v_hi`: its vertices inside the strip and its edges' crossings of the strip's
/// borders.
fn u_range(poly: &[Point2], v_lo: Real, v_hi: Real) -> Option<(Real, Real)> {
    let mut lo = Real::INFINITY;
    let mut hi = Real::NEG_INFINITY;
    let mut take = |u: Real| {
        lo = lo.min(u);
        hi = hi.max(u);
    };
    let n = poly.len();
    for i in 0..n {
        let a = poly[i];
        if a.y >= v_lo && a.y <= v_hi {
            take(a.x);
        }
        if n < 2 {
            continue;
        }
        let b = poly[(i + 1) % n];
        for line in [v_lo, v_hi] {
            if (a.y - line) * (b.y - line) < 0.0 {
                let t = (line - a.y) / (b.y - a.y);
                take(a.x + (b.x - a.x) * t);
            }
        }
    }
    (lo <= hi).then_some((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_touches_its_closed_neighbours() {
        let sq = [
            Point2::new(2.0, 3.0),
            Point2::new(4.0, 3.0),
            Point2::new(4.0, 5.0),
            Point2::new(2.0, 5.0),
        ];
        let f = spans(&sq, 10, 10).unwrap();
        // Rows 2..=5 (row 2 touches v = 3 from above, row 5 touches v = 5 from below).
        assert_eq!(f.row0, 2);
        assert_eq!(f.spans, vec![(1, 4); 4]);
    }

    #[test]
    fn sloped_edge_spans_follow_the_edge() {
        let tri = [
            Point2::new(0.5, 0.5),
            Point2::new(8.5, 0.5),
            Point2::new(0.5, 8.5),
        ];
        let f = spans(&tri, 10, 10).unwrap();
        assert_eq!(f.span(0), Some((0, 8)));
        assert_eq!(f.span(4), Some((0, 5)));
        assert_eq!(f.span(8), Some((0, 1)));
        assert_eq!(f.span(9), None);
    }

    #[test]
    fn outside_the_image_is_nothing() {
        let sq = [
            Point2::new(-4.0, 3.0),
            Point2::new(-2.0, 3.0),
            Point2::new(-2.0, 5.0),
        ];
        assert!(spans(&sq, 10, 10).is_none());
    }
}
