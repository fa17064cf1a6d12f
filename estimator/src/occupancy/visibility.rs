//! Line-of-sight tests through the map, for predicting what buildings will hide.

use sets::math::{Point2, Point3, Real};

use super::{OccupancyMap, OemStatus};

impl OccupancyMap {
    /// Whether the segment from `eye` (e.g. a camera) down to the ground point `target` passes
    /// through a known obstacle cell taller than the segment there.
    ///
    /// The segment's horizontal trace is walked cell by cell (every cell it touches, exactly,
    /// by a grid traversal); in each obstacle cell the segment is lowest where it leaves the
    /// cell, and the cell blocks when its height exceeds that. The cell holding `target` itself
    /// is not tested: the ground point is what is looked at, and a 5 m cell that is partly
    /// building must not hide its own open ground. Cells outside the map are unknown and never
    /// block. Non-finite input is reported as not blocked.
    pub fn segment_blocked(&self, eye: &Point3, target: &Point2) -> bool {
        let g = self.grid();
        let d = g.cell_m;
        let (ax, ay) = ((eye.x - g.origin.x) / d, (eye.y - g.origin.y) / d);
        let (bx, by) = ((target.x - g.origin.x) / d, (target.y - g.origin.y) / d);
        if ![ax, ay, bx, by, eye.z].iter().all(|v| v.is_finite()) {
            return false;
        }
        let (dx, dy) = (bx - ax, by - ay);
        let (mut ix, mut iy) = (ax.floor() as i64, ay.floor() as i64);
        let (tx_end, ty_end) = (bx.floor() as i64, by.floor() as i64);
        let step_x: i64 = if dx > 0.0 { 1 } else { -1 };
        let step_y: i64 = if dy > 0.0 { 1 } else { -1 };
        // Parameter (0 at the eye, 1 at the target) where the segment crosses the next column
        // or row boundary, and the parameter step between boundaries.
        let boundary = |a: Real, delta: Real, i: i64, step: i64| -> (Real, Real) {
            if delta == 0.0 {
                return (Real::INFINITY, Real::INFINITY);
            }
            let next = if step > 0 { i as Real + 1.0 } else { i as Real };
            ((next - a) / delta, 1.0 / delta.abs())
        };
        let (mut t_max_x, t_delta_x) = boundary(ax, dx, ix, step_x);
        let (mut t_max_y, t_delta_y) = boundary(ay, dy, iy, step_y);
        let max_steps = (tx_end - ix).unsigned_abs() + (ty_end - iy).unsigned_abs();
        for _ in 0..=max_steps {
            if ix == tx_end && iy == ty_end {
                return false;
            }
            let t_exit = t_max_x.min(t_max_y).min(1.0);
            if self.blocks(ix, iy, eye.z * (1.0 - t_exit)) {
                return true;
            }
            if t_max_x < t_max_y {
                t_max_x += t_delta_x;
                ix += step_x;
            } else {
                t_max_y += t_delta_y;
                iy += step_y;
            }
        }
        false
    }

    fn blocks(&self, ix: i64, iy: i64, z: Real) -> bool {
        if ix < 0 || iy < 0 || ix > u32::MAX as i64 || iy > u32::MAX as i64 {
            return false;
        }
        self.cell((ix as u32, iy as u32))
            .is_some_and(|c| c.status == OemStatus::Obstacle && c.height_m as Real > z)
    }
}

#[cfg(test)]
mod tests {
    use sets::grid::GroundGrid;

    use super::*;

    #[test]
    fn a_tall_building_between_eye_and_ground_blocks() {
        let mut m = OccupancyMap::new(GroundGrid::new(50.0, 5.0));
        // A 30 m building at x in [0, 5], y in [0, 5].
        m.observe_obstacle(&Point2::new(2.5, 2.5), 30.0);
        let eye = Point3::new(-40.0, 2.5, 40.0);
        // Ground just behind the building: the segment is ~ 33 m high over it, then lower.
        assert!(m.segment_blocked(&eye, &Point2::new(10.0, 2.5)));
        // Ground in front of the building is not hidden.
        assert!(!m.segment_blocked(&eye, &Point2::new(-5.0, 2.5)));
        // Ground far behind: the segment passes over the building high enough.
        let high_eye = Point3::new(-40.0, 2.5, 400.0);
        assert!(!m.segment_blocked(&high_eye, &Point2::new(45.0, 2.5)));
        // Beside the building's row, nothing blocks.
        assert!(!m.segment_blocked(&eye, &Point2::new(10.0, 20.0)));
        // The building's own cell does not hide itself.
        assert!(!m.segment_blocked(&eye, &Point2::new(3.0, 3.0)));
    }

    #[test]
    fn diagonal_walks_touch_every_cell() {
        let mut m = OccupancyMap::new(GroundGrid::new(50.0, 5.0));
        m.observe_obstacle(&Point2::new(7.5, 2.5), 100.0);
        // The segment from (0.1, 0.1) to (14.9, 9.9) passes through cell (1, 0) in map cells
        // offset from the origin at -50: cell x in [5, 10], y in [0, 5].
        assert!(m.segment_blocked(&Point3::new(0.1, 0.1, 50.0), &Point2::new(14.9, 9.9)));
        assert!(!m.segment_blocked(&Point3::new(f64::NAN, 0.1, 50.0), &Point2::new(14.9, 9.9)));
    }
}
