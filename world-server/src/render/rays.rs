//! The camera's rays, many at a time.
//!
//! [`Camera::ray`] recomputes the focal length (a tangent) for every ray, which was a quarter
//! of a frame's time; [`RayGrid`] hoists it out and otherwise performs the very same
//! operations in the same order, so its rays are bit for bit those of [`Camera::ray`] (a test
//! pins this), and the estimator, which uses [`Camera`], back-projects exactly what was cast.

use protocol::camera::Camera;
use protocol::math::{Real, Vector3};

/// The rays of one posed camera.
#[derive(Clone, Copy, Debug)]
pub struct RayGrid {
    world_from_camera: nalgebra::Matrix3<Real>,
    focal: Real,
    half_cols: Real,
    half_rows: Real,
}

impl RayGrid {
    /// The ray grid of `camera`.
    pub fn new(camera: &Camera) -> Self {
        // The same construction as `Camera::new`.
        let (st, ct) = camera.model.tilt_rad.sin_cos();
        let (sy, cy) = camera.pose.yaw.sin_cos();
        let forward = Vector3::new(ct * cy, ct * sy, -st);
        let right = Vector3::new(sy, -cy, 0.0);
        let down = forward.cross(&right);
        RayGrid {
            world_from_camera: nalgebra::Matrix3::from_columns(&[right, down, forward]),
            focal: camera.model.focal_px(),
            half_cols: camera.model.cols as Real / 2.0,
            half_rows: camera.model.rows as Real / 2.0,
        }
    }

    /// Unit world direction through image point `(u, v)`: [`Camera::ray`].
    #[inline]
    pub fn ray(&self, u: Real, v: Real) -> Vector3 {
        let f = self.focal;
        let local = Vector3::new((u - self.half_cols) / f, (v - self.half_rows) / f, 1.0);
        (self.world_from_camera * local).normalize()
    }

    /// [`Camera::corner_ray`].
    #[inline]
    pub fn corner_ray(&self, r: u32, c: u32) -> Vector3 {
        self.ray(c as Real, r as Real)
    }

    /// [`Camera::centre_ray`].
    #[inline]
    pub fn centre_ray(&self, r: u32, c: u32) -> Vector3 {
        self.ray(c as Real + 0.5, r as Real + 0.5)
    }
}

#[cfg(test)]
mod tests {
    use protocol::camera::{CameraModel, CameraPose};
    use protocol::math::Point3;

    use super::*;

    #[test]
    fn rays_are_bit_for_bit_those_of_the_camera() {
        for (yaw, tilt, rows, cols) in [(0.3, 0.78, 36, 48), (-2.9, 0.2, 9, 16), (1.7, 1.3, 5, 7)] {
            let camera = Camera::new(
                CameraModel {
                    rows,
                    cols,
                    aperture_rad: 0.9,
                    tilt_rad: tilt,
                },
                CameraPose {
                    position: Point3::new(3.0, -7.0, 90.0),
                    yaw,
                },
            );
            let grid = RayGrid::new(&camera);
            for r in 0..=rows {
                for c in 0..=cols {
                    assert_eq!(grid.corner_ray(r, c), camera.corner_ray(r, c));
                    assert_eq!(grid.centre_ray(r, c), camera.centre_ray(r, c));
                }
            }
        }
    }
}
