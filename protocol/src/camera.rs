//! The pinhole camera shared by the renderer and the estimator.
//!
//! Image coordinates: `u` runs along columns (right), `v` along rows (down); pixel `(r, c)`
//! covers the closed rectangle `[c, c+1] x [r, r+1]`, and the principal point is the image
//! centre. The camera frame is x right, y down, z forward. The camera looks along the UAV's yaw,
//! tilted `tilt_rad` below the horizon on a stabilised gimbal (no roll, no pitch from the body).
//!
//! Every function here is the one both sides use: the world-server casts the rays it returns,
//! the estimator back-projects with the same numbers, so the two can never disagree about
//! which ray lights which pixel.

use serde::{Deserialize, Serialize};

use sets::math::{Point2, Point3, Real, Rotation3, Vector3, convex_hull};

/// Relative inflation applied to depth intervals, covering the `f32` rounding of the depth on
/// the wire (2^-24) with a wide margin.
pub const DEPTH_ROUNDING_MARGIN: Real = 1e-6;

/// Intrinsics and mounting of the camera: what does not change while flying.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraModel {
    /// Image rows `Nr`.
    pub rows: u32,
    /// Image columns `Nc`.
    pub cols: u32,
    /// Horizontal aperture `a` in radians.
    pub aperture_rad: Real,
    /// Tilt of the optical axis below the horizon, radians.
    pub tilt_rad: Real,
}

impl CameraModel {
    /// Focal length in pixels: `f = (Nc / 2) / tan(a / 2)`.
    pub fn focal_px(&self) -> Real {
        (self.cols as Real / 2.0) / (self.aperture_rad / 2.0).tan()
    }

    /// Number of pixels `Nr * Nc`.
    pub fn pixel_count(&self) -> usize {
        self.rows as usize * self.cols as usize
    }

    /// Direction (not normalised, z = 1) in the camera frame of image point `(u, v)`.
    pub fn ray_camera(&self, u: Real, v: Real) -> Vector3 {
        let f = self.focal_px();
        Vector3::new(
            (u - self.cols as Real / 2.0) / f,
            (v - self.rows as Real / 2.0) / f,
            1.0,
        )
    }

    /// Half of the vertical aperture, radians.
    pub fn vertical_half_aperture(&self) -> Real {
        ((self.rows as Real / 2.0) / self.focal_px()).atan()
    }
}

/// Where the camera is and where it looks: position of the optical centre and the UAV's yaw.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraPose {
    /// Optical centre in the world frame.
    pub position: Point3,
    /// Heading of the optical axis, radians counter-clockwise from east.
    pub yaw: Real,
}

/// A posed camera: model plus pose, with the rotation cached.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    /// Intrinsics and tilt.
    pub model: CameraModel,
    /// Position and yaw.
    pub pose: CameraPose,
    world_from_camera: Rotation3,
}

impl Camera {
    /// Builds a posed camera.
    pub fn new(model: CameraModel, pose: CameraPose) -> Self {
        let (st, ct) = model.tilt_rad.sin_cos();
        let (sy, cy) = pose.yaw.sin_cos();
        let forward = Vector3::new(ct * cy, ct * sy, -st);
        let right = Vector3::new(sy, -cy, 0.0);
        let down = forward.cross(&right);
        let m = nalgebra::Matrix3::from_columns(&[right, down, forward]);
        Self {
            model,
            pose,
            world_from_camera: Rotation3::from_matrix_unchecked(m),
        }
    }

    /// Optical centre.
    pub fn origin(&self) -> Point3 {
        self.pose.position
    }

    /// Unit world direction of the ray through image point `(u, v)`.
    pub fn ray(&self, u: Real, v: Real) -> Vector3 {
        (self.world_from_camera * self.model.ray_camera(u, v)).normalize()
    }

    /// Unit world direction of the ray through pixel corner `(r, c)`, `r` in `0..=rows`,
    /// `c` in `0..=cols`. Neighbouring pixels share corners.
    pub fn corner_ray(&self, r: u32, c: u32) -> Vector3 {
        self.ray(c as Real, r as Real)
    }

    /// Unit world direction of the ray through the centre of pixel `(r, c)`.
    pub fn centre_ray(&self, r: u32, c: u32) -> Vector3 {
        self.ray(c as Real + 0.5, r as Real + 0.5)
    }

    /// The four corner rays of pixel `(r, c)`, in order top-left, top-right, bottom-right,
    /// bottom-left (a closed loop in the image).
    pub fn pixel_corner_rays(&self, r: u32, c: u32) -> [Vector3; 4] {
        [
            self.corner_ray(r, c),
            self.corner_ray(r, c + 1),
            self.corner_ray(r + 1, c + 1),
            self.corner_ray(r + 1, c),
        ]
    }

    /// Projects a world point into the image: `(u, v)`, or `None` if it is not in front of the
    /// camera. The result may lie outside the image.
    pub fn project(&self, p: &Point3) -> Option<(Real, Real)> {
        let pc = self
            .world_from_camera
            .inverse_transform_vector(&(p - self.pose.position));
        if pc.z <= 1e-9 {
            return None;
        }
        let f = self.model.focal_px();
        Some((
            self.model.cols as Real / 2.0 + f * pc.x / pc.z,
            self.model.rows as Real / 2.0 + f * pc.y / pc.z,
        ))
    }

    /// Depth of a world point along the optical axis (camera z); negative behind the camera.
    pub fn axial_depth(&self, p: &Point3) -> Real {
        self.world_from_camera
            .inverse_transform_vector(&(p - self.pose.position))
            .z
    }

    /// Where a ray from the optical centre meets the ground `z = 0`, if it goes down.
    pub fn ground_hit(&self, dir: &Vector3) -> Option<Point2> {
        if dir.z >= -1e-12 || self.pose.position.z <= 0.0 {
            return None;
        }
        let t = -self.pose.position.z / dir.z;
        let p = self.pose.position + dir * t;
        Some(Point2::new(p.x, p.y))
    }

    /// Ground footprint of pixel `(r, c)`: the quadrilateral where its corner rays meet the
    /// ground (convex, in image-loop order), or `None` if a corner ray does not reach the ground.
    pub fn pixel_ground_footprint(&self, r: u32, c: u32) -> Option<[Point2; 4]> {
        let rays = self.pixel_corner_rays(r, c);
        Some([
            self.ground_hit(&rays[0])?,
            self.ground_hit(&rays[1])?,
            self.ground_hit(&rays[2])?,
            self.ground_hit(&rays[3])?,
        ])
    }

    /// Ground footprint of the whole image (the field of view on flat ground), or `None` if a
    /// corner of the image looks at or above the horizon.
    pub fn image_ground_footprint(&self) -> Option<[Point2; 4]> {
        let (rows, cols) = (self.model.rows, self.model.cols);
        Some([
            self.ground_hit(&self.corner_ray(0, 0))?,
            self.ground_hit(&self.corner_ray(0, cols))?,
            self.ground_hit(&self.corner_ray(rows, cols))?,
            self.ground_hit(&self.corner_ray(rows, 0))?,
        ])
    }

    /// Area of [`Camera::image_ground_footprint`], m² (0 if it misses the ground).
    pub fn ground_footprint_area(&self) -> Real {
        self.image_ground_footprint().map_or(0.0, |p| {
            let mut twice = 0.0;
            for i in 0..p.len() {
                let (a, b) = (p[i], p[(i + 1) % p.len()]);
                twice += a.x * b.y - b.x * a.y;
            }
            twice.abs() / 2.0
        })
    }

    /// Depth of [`Camera::image_ground_footprint`] along the camera's heading (its yaw), m (0
    /// if it misses the ground).
    pub fn ground_footprint_depth(&self) -> Real {
        let heading = Point2::new(self.pose.yaw.cos(), self.pose.yaw.sin());
        self.image_ground_footprint().map_or(0.0, |p| {
            let along = p.iter().map(|q| q.coords.dot(&heading.coords));
            let (lo, hi) = along.fold((Real::INFINITY, Real::NEG_INFINITY), |(lo, hi), a| {
                (lo.min(a), hi.max(a))
            });
            (hi - lo).max(0.0)
        })
    }

    /// Mean width of [`Camera::image_ground_footprint`] across the camera's heading: its area
    /// over its depth, m (0 if it misses the ground).
    pub fn ground_footprint_width(&self) -> Real {
        let depth = self.ground_footprint_depth();
        if depth > 0.0 {
            self.ground_footprint_area() / depth
        } else {
            0.0
        }
    }

    /// Corners of a convex polytope that contains every point lit by pixel `(r, c)` whose range
    /// (distance from the optical centre) lies in `[range_lo, range_hi]`.
    ///
    /// The set of such points is a pyramid sliced by two spheres; its far face is a sphere cap
    /// that bulges past the far corners. The polytope returned is the pyramid cut by two planes
    /// orthogonal to the pixel's centre ray: the far plane at distance `range_hi` (every point
    /// of range `<= range_hi` is on its near side) and the near plane at `range_lo * cos(theta)`,
    /// `theta` the largest angle between the centre ray and a corner ray (every point of range
    /// `>= range_lo` in the pyramid is beyond it). Returns 4 near corners then 4 far corners.
    pub fn pixel_frustum(&self, r: u32, c: u32, range_lo: Real, range_hi: Real) -> [Point3; 8] {
        let axis = self.centre_ray(r, c);
        let corners = self.pixel_corner_rays(r, c);
        let cos_i = corners.map(|d| axis.dot(&d));
        let cos_min = cos_i.iter().copied().fold(Real::INFINITY, Real::min);
        let near_plane = range_lo.max(0.0) * cos_min;
        let o = self.pose.position;
        let mut out = [o; 8];
        for i in 0..4 {
            out[i] = o + corners[i] * (near_plane / cos_i[i]);
            out[i + 4] = o + corners[i] * (range_hi / cos_i[i]);
        }
        out
    }

    /// Outer ground shadow of [`Camera::pixel_frustum`]: the convex hull of its corners
    /// projected vertically on the ground (counter-clockwise).
    pub fn pixel_frustum_ground_hull(
        &self,
        r: u32,
        c: u32,
        range_lo: Real,
        range_hi: Real,
    ) -> Vec<Point2> {
        let pts = self
            .pixel_frustum(r, c, range_lo, range_hi)
            .map(|p| Point2::new(p.x, p.y));
        convex_hull(&pts)
    }
}

/// The range interval a measured depth allows: with `D = range * (1 + w)`, `w` in
/// `[w_lo, w_hi]`, the true range is in `[D / (1 + w_hi), D / (1 + w_lo)]`, widened by
/// [`DEPTH_ROUNDING_MARGIN`]. `None` for a depth that is not finite and positive, or noise
/// bounds that do not satisfy `-1 < w_lo <= w_hi`.
pub fn range_interval(depth: f32, noise: [Real; 2]) -> Option<(Real, Real)> {
    let d = depth as Real;
    let [w_lo, w_hi] = noise;
    if !(d.is_finite() && d > 0.0 && w_lo > -1.0 && w_lo <= w_hi && w_hi.is_finite()) {
        return None;
    }
    Some((
        d / (1.0 + w_hi) * (1.0 - DEPTH_ROUNDING_MARGIN),
        d / (1.0 + w_lo) * (1.0 + DEPTH_ROUNDING_MARGIN),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(yaw: Real) -> Camera {
        Camera::new(
            CameraModel {
                rows: 36,
                cols: 48,
                aperture_rad: std::f64::consts::FRAC_PI_4,
                tilt_rad: std::f64::consts::FRAC_PI_4,
            },
            CameraPose {
                position: Point3::new(10.0, -5.0, 80.0),
                yaw,
            },
        )
    }

    /// The footprint's area, depth and width do not depend on the heading, and the width is
    /// the area over the depth; a camera that misses the ground has none.
    #[test]
    fn the_footprint_measures_follow_the_camera_not_its_heading() {
        let (a, b) = (cam(0.0), cam(2.1));
        let area = a.ground_footprint_area();
        let depth = a.ground_footprint_depth();
        assert!(area > 0.0 && depth > 0.0);
        assert!((b.ground_footprint_area() - area).abs() < 1e-6 * area);
        assert!((b.ground_footprint_depth() - depth).abs() < 1e-6 * depth);
        assert!((a.ground_footprint_width() * depth - area).abs() < 1e-6 * area);
        // Tilted up past the horizon: no footprint.
        let level = cam(0.0);
        let model = CameraModel {
            tilt_rad: -0.5,
            ..level.model
        };
        let up = Camera::new(model, level.pose);
        assert_eq!(up.ground_footprint_width(), 0.0);
        assert_eq!(up.ground_footprint_area(), 0.0);
    }

    #[test]
    fn projection_inverts_rays() {
        let c = cam(0.7);
        for &(u, v) in &[(0.0, 0.0), (12.3, 30.1), (48.0, 36.0), (24.0, 18.0)] {
            let p = c.origin() + c.ray(u, v) * 57.0;
            let (pu, pv) = c.project(&p).unwrap();
            assert!((pu - u).abs() < 1e-9 && (pv - v).abs() < 1e-9);
        }
    }

    #[test]
    fn optical_axis_points_down_along_yaw() {
        let c = cam(std::f64::consts::FRAC_PI_2);
        let axis = c.ray(24.0, 18.0);
        assert!(axis.x.abs() < 1e-12);
        assert!((axis.y - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
        assert!((axis.z + std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
        // Column 0 is on the left of the heading (west when looking north).
        assert!(c.ray(0.0, 18.0).x < 0.0);
        // Row 0 looks farther away than the last row.
        assert!(c.ray(24.0, 0.0).z > c.ray(24.0, 36.0).z);
    }

    #[test]
    fn frustum_contains_points_of_the_range_interval() {
        let c = cam(-2.0);
        let (r, px) = (5, 40);
        let (lo, hi) = (90.0, 95.0);
        let f = c.pixel_frustum(r, px, lo, hi);
        let hull = convex_hull(&f.map(|p| Point2::new(p.x, p.y)));
        for &(du, dv) in &[
            (0.0, 0.0),
            (1.0, 0.0),
            (0.5, 0.5),
            (1.0, 1.0),
            (0.0, 1.0),
            (0.9, 0.1),
        ] {
            for &t in &[lo, (lo + hi) / 2.0, hi] {
                let p = c.origin() + c.ray(px as Real + du, r as Real + dv) * t;
                assert!(
                    point_in_convex(&hull, &Point2::new(p.x, p.y)),
                    "{du} {dv} {t}"
                );
            }
        }
    }

    fn point_in_convex(poly: &[Point2], p: &Point2) -> bool {
        (0..poly.len()).all(|i| {
            let a = poly[i];
            let b = poly[(i + 1) % poly.len()];
            (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x) >= -1e-9
        })
    }

    #[test]
    fn range_interval_contains_truth_at_noise_bounds() {
        for &w in &[-0.01, 0.0, 0.01] {
            let range = 123.456_f64;
            let d = (range * (1.0 + w)) as f32;
            let (lo, hi) = range_interval(d, [-0.01, 0.01]).unwrap();
            assert!(lo <= range && range <= hi);
        }
        assert!(range_interval(f32::NAN, [-0.01, 0.01]).is_none());
        assert!(range_interval(f32::INFINITY, [-0.01, 0.01]).is_none());
        assert!(range_interval(-1.0, [-0.01, 0.01]).is_none());
    }
}
