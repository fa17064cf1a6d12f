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
//! ray only the vertical component of its unit direction and its range to the ground:
//! [`RayGrid::centre_row`] computes those of a whole row in one loop the compiler can
//! vectorise. The rays that may meet a box are normalised a run of columns at a time too,
//! with the reciprocals of their components that the slab tests divide by
//! ([`RayGrid::unit_rays`]).
//! All of it is nalgebra's arithmetic (`Matrix3 * Vector3`, `norm`, `normalize`) operation
//! for operation.

use std::ops::Range;

use protocol::camera::Camera;
use sets::math::{Real, Vector3};

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
    /// Vertical component of each column's unit direction.
    pub z: Vec<Real>,
    /// Range to the ground `z = 0` from the given height, `-height / z` (meaningful where the
    /// ray points down from above the ground).
    pub ground: Vec<Real>,
}

/// Unit rays of some columns of a row, indexed by column, as [`RayGrid::unit_rays`] fills
/// them: the unit direction and the reciprocals of its components.
#[derive(Clone, Debug, Default)]
pub struct UnitRays {
    dir: [Vec<Real>; 3],
    inv: [Vec<Real>; 3],
}

impl UnitRays {
    /// The unit direction of column `c` and `[1 / dir.x, 1 / dir.y, 1 / dir.z]`, as last
    /// filled by [`RayGrid::unit_rays`] (a column never filled gives zeros or stale values).
    #[inline]
    pub fn get(&self, c: u32) -> (Vector3, [Real; 3]) {
        let c = c as usize;
        let [dx, dy, dz] = &self.dir;
        let [ix, iy, iz] = &self.inv;
        (Vector3::new(dx[c], dy[c], dz[c]), [ix[c], iy[c], iz[c]])
    }
}

/// Which rays of a row: the corner rays of corner row `r`, or the centre rays of pixel row `r`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowOf {
    /// Corner row `r` (`0..=rows`), columns `0..=cols`.
    Corners(u32),
    /// Pixel row `r` (`0..rows`), columns `0..cols`.
    Centres(u32),
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

    /// The centre rays of pixel row `r` seen from `height` above the ground: for column `c`,
    /// `out.z[c]` is `centre_ray(r, c).z` and `out.ground[c]` is `-height / out.z[c]`.
    pub fn centre_row(&self, r: u32, height: Real, out: &mut RowRays) {
        let n = self.centre_x.len();
        out.z.resize(n, 0.0);
        out.ground.resize(n, 0.0);
        let row = self.row_terms(self.centre_y[r as usize]);
        for ((&x, z), ground) in self.centre_x.iter().zip(&mut out.z).zip(&mut out.ground) {
            let v = row.unnormalised(x);
            let unit_z = v.z / (v.x * v.x + v.y * v.y + v.z * v.z).sqrt();
            *z = unit_z;
            *ground = -height / unit_z;
        }
    }

    /// The unit rays of a run of columns of a row, and their reciprocals: for `c` in
    /// `columns`, `out.get(c).0` is `corner_ray(r, c)` or `centre_ray(r, c)`.
    pub fn unit_rays(&self, which: RowOf, columns: Range<u32>, out: &mut UnitRays) {
        let (xs, y) = match which {
            RowOf::Corners(r) => (&self.corner_x, self.corner_y[r as usize]),
            RowOf::Centres(r) => (&self.centre_x, self.centre_y[r as usize]),
        };
        for v in out.dir.iter_mut().chain(&mut out.inv) {
            if v.len() < xs.len() {
                v.resize(xs.len(), 0.0);
            }
        }
        let row = self.row_terms(y);
        let span = columns.start as usize..columns.end as usize;
        let xs = &xs[span.clone()];
        let [dx, dy, dz] = out.dir.each_mut().map(|v| &mut v[span.clone()]);
        let [ix, iy, iz] = out.inv.each_mut().map(|v| &mut v[span.clone()]);
        for (i, &x) in xs.iter().enumerate() {
            let v = row.unnormalised(x);
            let s = (v.x * v.x + v.y * v.y + v.z * v.z).sqrt();
            let d = [v.x / s, v.y / s, v.z / s];
            (dx[i], dy[i], dz[i]) = (d[0], d[1], d[2]);
            (ix[i], iy[i], iz[i]) = (1.0 / d[0], 1.0 / d[1], 1.0 / d[2]);
        }
    }

    /// The terms of `Matrix3 * Vector3::new(x, y, 1.0)` that do not depend on `x`.
    #[inline]
    fn row_terms(&self, y: Real) -> RowTerms {
        let m = &self.world_from_camera;
        RowTerms {
            x: [m[(0, 0)], m[(1, 0)], m[(2, 0)]],
            y: [m[(0, 1)] * y, m[(1, 1)] * y, m[(2, 1)] * y],
            one: [m[(0, 2)], m[(1, 2)], m[(2, 2)]],
        }
    }
}

/// `Matrix3 * Vector3::new(x, y, 1.0)` for one `y`: nalgebra's product accumulates the columns
/// times the components in order (`gemv`), `(m0 * x + m1 * y) + m2`; its `norm` then sums the
/// squares left to right and `normalize` divides every component by the norm.
struct RowTerms {
    x: [Real; 3],
    y: [Real; 3],
    one: [Real; 3],
}

impl RowTerms {
    #[inline]
    fn unnormalised(&self, x: Real) -> Vector3 {
        Vector3::new(
            self.x[0] * x + self.y[0] + self.one[0],
            self.x[1] * x + self.y[1] + self.one[1],
            self.x[2] * x + self.y[2] + self.one[2],
        )
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
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use sets::math::Point3;

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
            let (mut corners, mut centres) = (UnitRays::default(), UnitRays::default());
            let height = 37.5;
            for r in 0..=rows {
                grid.unit_rays(RowOf::Corners(r), 0..cols + 1, &mut corners);
                if r < rows {
                    grid.centre_row(r, height, &mut row);
                    grid.unit_rays(RowOf::Centres(r), 0..cols, &mut centres);
                }
                for c in 0..=cols {
                    let corner = camera.corner_ray(r, c);
                    assert_eq!(bits(grid.corner_ray(r, c)), bits(corner));
                    let z = unit_z(&grid.corner_unnormalised(r, c));
                    assert_eq!(z.to_bits(), corner.z.to_bits());
                    assert_eq!(bits(grid.ray(c as Real, r as Real)), bits(corner));
                    assert_eq!(grid.corner_descends(r, c), corner.z < 0.0);
                    let (dir, inv) = corners.get(c);
                    assert_eq!(bits(dir), bits(corner));
                    let want = [0, 1, 2].map(|i| (1.0 / corner[i]).to_bits());
                    assert_eq!(inv.map(Real::to_bits), want);
                    if r < rows && c < cols {
                        let centre = camera.centre_ray(r, c);
                        assert_eq!(row.z[c as usize].to_bits(), centre.z.to_bits());
                        let ground = -height / centre.z;
                        assert_eq!(row.ground[c as usize].to_bits(), ground.to_bits());
                        let (dir, inv) = centres.get(c);
                        assert_eq!(bits(dir), bits(centre));
                        let want = [0, 1, 2].map(|i| (1.0 / centre[i]).to_bits());
                        assert_eq!(inv.map(Real::to_bits), want);
                        assert_eq!(bits(grid.centre_ray(r, c)), bits(centre));
                        let z = unit_z(&grid.centre_unnormalised(r, c));
                        assert_eq!(z.to_bits(), centre.z.to_bits());
                    }
                }
            }
        }
    }
}
