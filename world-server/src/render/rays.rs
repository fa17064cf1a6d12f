//! The camera's rays, many at a time.
//!
//! [`Camera::ray`] recomputes the focal length (a tangent) and divides both image offsets by
//! it for every ray; [`RayGrid`] computes those quotients once per column and per row and
//! otherwise performs the very same operations in the same order, so its rays are bit for bit
//! those of [`Camera::ray`] (a test pins this), and the estimator, which uses [`Camera`],
//! back-projects exactly what was cast.
//!
//! Most rays meet only the ground. Of a corner ray the renderer then needs only whether it
//! points down ([`RayGrid::corner_descends`], mostly without normalising), and of a centre
//! ray only the vertical component of its unit direction: [`RayGrid::centre_row`] computes
//! those of a whole row, and the norms that finish the other rays' normalisation, in one loop
//! the compiler can vectorise, with nalgebra's arithmetic (`Matrix3 * Vector3`, `normalize`)
//! operation for operation.

use protocol::camera::Camera;
use protocol::math::{Real, Vector3};

/// The rays of one posed camera.
#[derive(Clone, Debug)]
pub struct RayGrid {
    world_from_camera: nalgebra::Matrix3<Real>,
    focal: Real,
    half_cols: Real,
    half_rows: Real,
    /// `(c - cols / 2) / f` for corner columns `c` in `0..=cols`.
    corner_x: Vec<Real>,
    /// `(r - rows / 2) / f` for corner rows `r` in `0..=rows`.
    corner_y: Vec<Real>,
    /// `(c + 0.5 - cols / 2) / f` for pixel columns.
    centre_x: Vec<Real>,
    /// `(r + 0.5 - rows / 2) / f` for pixel rows.
    centre_y: Vec<Real>,
    /// Whether every offset is finite and at most [`OFFSET_BOUND`], so that a direction's
    /// norm is at most a few times that.
    bounded: bool,
}

/// Bound on the image offsets under which [`DESCENT_BOUND`] decides a ray's descent.
const OFFSET_BOUND: Real = 1e50;
/// A ray whose unnormalised vertical component is below `-DESCENT_BOUND` points down: with
/// offsets within [`OFFSET_BOUND`] its norm is below `1e51`, and the quotient stays a normal
/// negative float (above `-1e-251` at worst), never rounding to zero.
const DESCENT_BOUND: Real = 1e-200;

/// One row of centre rays, as [`RayGrid::centre_row`] fills it.
#[derive(Clone, Debug, Default)]
pub struct RowRays {
    /// Norm of each column's unnormalised direction.
    pub norm: Vec<Real>,
    /// Vertical component of each column's unit direction.
    pub z: Vec<Real>,
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
        let focal = camera.model.focal_px();
        let half_cols = camera.model.cols as Real / 2.0;
        let half_rows = camera.model.rows as Real / 2.0;
        // The same quotients as `CameraModel::ray_camera`, of the same image coordinates as
        // `Camera::corner_ray` and `Camera::centre_ray`.
        let (cols, rows) = (camera.model.cols, camera.model.rows);
        let offsets = |n: u32, half: Real, shift: Real| -> Vec<Real> {
            (0..n).map(|i| (i as Real + shift - half) / focal).collect()
        };
        let corner_x = offsets(cols + 1, half_cols, 0.0);
        let corner_y = offsets(rows + 1, half_rows, 0.0);
        let centre_x = offsets(cols, half_cols, 0.5);
        let centre_y = offsets(rows, half_rows, 0.5);
        let bounded = [&corner_x, &corner_y, &centre_x, &centre_y]
            .iter()
            .all(|t| t.iter().all(|o| o.abs() <= OFFSET_BOUND));
        RayGrid {
            world_from_camera: nalgebra::Matrix3::from_columns(&[right, down, forward]),
            focal,
            half_cols,
            half_rows,
            corner_x,
            corner_y,
            centre_x,
            centre_y,
            bounded,
        }
    }

    /// Unit world direction through image point `(u, v)`: [`Camera::ray`].
    #[inline]
    pub fn ray(&self, u: Real, v: Real) -> Vector3 {
        let f = self.focal;
        self.direction((u - self.half_cols) / f, (v - self.half_rows) / f)
            .normalize()
    }

    /// World direction, not normalised, of camera-frame direction `(x, y, 1)`.
    #[inline]
    fn direction(&self, x: Real, y: Real) -> Vector3 {
        self.world_from_camera * Vector3::new(x, y, 1.0)
    }

    /// [`Camera::corner_ray`], for `r <= rows`, `c <= cols`.
    #[inline]
    pub fn corner_ray(&self, r: u32, c: u32) -> Vector3 {
        self.corner_unnormalised(r, c).normalize()
    }

    /// [`Camera::centre_ray`], for `r < rows`, `c < cols`.
    #[inline]
    pub fn centre_ray(&self, r: u32, c: u32) -> Vector3 {
        self.centre_unnormalised(r, c).normalize()
    }

    /// The corner ray `(r, c)` before normalisation: [`RayGrid::corner_ray`] is its
    /// `normalize()`.
    #[inline]
    pub fn corner_unnormalised(&self, r: u32, c: u32) -> Vector3 {
        self.direction(self.corner_x[c as usize], self.corner_y[r as usize])
    }

    /// The centre ray `(r, c)` before normalisation: [`RayGrid::centre_ray`] is its
    /// `normalize()`.
    #[inline]
    pub fn centre_unnormalised(&self, r: u32, c: u32) -> Vector3 {
        self.direction(self.centre_x[c as usize], self.centre_y[r as usize])
    }

    /// Whether the corner ray `(r, c)` points down: `corner_ray(r, c).z < 0`.
    #[inline]
    pub fn corner_descends(&self, r: u32, c: u32) -> bool {
        let v = self.corner_unnormalised(r, c);
        (self.bounded && v.z < -DESCENT_BOUND) || (v.z < 0.0 && unit_z(&v) < 0.0)
    }

    /// The centre rays of row `r`: for column `c`, `out.norm[c]` is the norm of
    /// `centre_unnormalised(r, c)` and `out.z[c]` is `centre_ray(r, c).z`. The unit ray is
    /// then `(v.x / norm, v.y / norm, z)` with `v` the unnormalised direction.
    pub fn centre_row(&self, r: u32, out: &mut RowRays) {
        let n = self.centre_x.len();
        out.norm.resize(n, 0.0);
        out.z.resize(n, 0.0);
        let m = &self.world_from_camera;
        let y = self.centre_y[r as usize];
        // `Matrix3 * Vector3` accumulates the columns times the components in order (gemv);
        // `norm` sums the squares left to right; `normalize` divides by the norm.
        let (ax, ay, az) = (m[(0, 1)] * y, m[(1, 1)] * y, m[(2, 1)] * y);
        let (bx, by, bz) = (m[(0, 2)], m[(1, 2)], m[(2, 2)]);
        let (cx, cy, cz) = (m[(0, 0)], m[(1, 0)], m[(2, 0)]);
        for ((&x, norm), z) in self.centre_x.iter().zip(&mut out.norm).zip(&mut out.z) {
            let vx = cx * x + ax + bx;
            let vy = cy * x + ay + by;
            let vz = cz * x + az + bz;
            let s = (vx * vx + vy * vy + vz * vz).sqrt();
            *norm = s;
            *z = vz / s;
        }
    }
}

/// The vertical component of `v.normalize()`, computed as nalgebra's `normalize` computes it
/// (the component divided by the norm), without the other two divisions.
#[inline]
pub fn unit_z(v: &Vector3) -> Real {
    v.z / v.norm()
}

#[cfg(test)]
mod tests {
    use protocol::camera::{CameraModel, CameraPose};
    use protocol::math::Point3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    #[test]
    fn rays_are_bit_for_bit_those_of_the_camera() {
        let mut cases = vec![(0.3, 0.78, 36, 48), (-2.9, 0.2, 9, 16), (1.7, 1.3, 5, 7)];
        // Level and steep cameras too, the horizon across the image or above it.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..40 {
            let tilt = [0.0, rng.random_range(-0.3..1.6)][rng.random_range(0..2)];
            cases.push((rng.random_range(-4.0..4.0), tilt, 30, 40));
        }
        for (yaw, tilt, rows, cols) in cases {
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
            let bits = |v: Vector3| v.map(Real::to_bits);
            let mut row = RowRays::default();
            for r in 0..=rows {
                if r < rows {
                    grid.centre_row(r, &mut row);
                }
                for c in 0..=cols {
                    let corner = camera.corner_ray(r, c);
                    assert_eq!(bits(grid.corner_ray(r, c)), bits(corner));
                    let z = unit_z(&grid.corner_unnormalised(r, c));
                    assert_eq!(z.to_bits(), corner.z.to_bits());
                    assert_eq!(bits(grid.ray(c as Real, r as Real)), bits(corner));
                    assert_eq!(grid.corner_descends(r, c), corner.z < 0.0);
                    if r < rows && c < cols {
                        let centre = camera.centre_ray(r, c);
                        let v = grid.centre_unnormalised(r, c);
                        assert_eq!(row.norm[c as usize].to_bits(), v.norm().to_bits());
                        assert_eq!(row.z[c as usize].to_bits(), centre.z.to_bits());
                        let n = row.norm[c as usize];
                        let unit = Vector3::new(v.x / n, v.y / n, row.z[c as usize]);
                        assert_eq!(bits(unit), bits(centre));
                        assert_eq!(bits(grid.centre_ray(r, c)), bits(centre));
                        let z = unit_z(&grid.centre_unnormalised(r, c));
                        assert_eq!(z.to_bits(), centre.z.to_bits());
                    }
                }
            }
        }
    }
}
