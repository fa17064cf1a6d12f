//! The sets one CVS frame proves (docs/design.md §3, "How each CVS-derived set is computed").
//!
//! Every function here reads a [`FrameView`]: the frame with its posed camera and each pixel's
//! *effective* label, where a pixel whose depth is not a finite positive number counts as
//! [`Label::Unknown`] whatever the vision system said, so bad depth can only make sets larger
//! (outer) or smaller (inner), never wrong.
//!
//! Rules and the reason each one keeps the guarantee:
//! - [`free_ground`] (`P^g`, inner): a cell is free when the pixel bounding box of its four
//!   projected corners (closed pixel rectangles, widened by [`PIXEL_EPSILON`]) lies inside the
//!   image and holds only ground pixels. The projected cell is a convex quadrilateral inside
//!   that box, so every pixel it touches is ground.
//! - [`target_measurement`] (`X^m_j`, outer): the convex hull of the ground shadows of every
//!   target pixel's depth frustum in the box ([`Camera::pixel_frustum_ground_hull`]), grown by
//!   a polygon circumscribing the disc of radius `r_t`. The hull contains the union, the
//!   circumscribed polygon contains the disc, so the result contains the union dilated by `r_t`.
//! - [`obstacle_neighbourhood`] (`S^o`, inner): an obstacle pixel proves an obstacle point in
//!   its depth frustum, and the ground within `r_s` of that point is free of cars. The rule
//!   depends on what is assumed of the ray the depth was measured along
//!   (`estimator.depth_ray`, [`RayAssumption`]):
//!   - `any` (the default, the paper's eq. 5: the range along *some* ray of the pixel): the
//!     point lies in the pixel's frustum between the range bounds, which
//!     [`Camera::pixel_frustum`] bounds by a convex polytope of 8 corners (its far face covers
//!     the sphere cap that bulges past the far corners). With `m` the mean of the corners'
//!     ground projections and `e` the largest horizontal distance from `m` to a corner (the
//!     farthest point of a convex hull from a fixed point is a vertex), every point of the
//!     frustum is within `e` of `m` horizontally, so the disc of radius `r_s - e` around `m`
//!     is within `r_s` of the obstacle point, wherever in the pixel it was. This is the
//!     design's rule on the frustum's corners.
//!   - `centre` (valid **only** for a source that measures along the centre ray, as this
//!     project's renderer does with `camera.depth_ray = "centre"`): the point is on the
//!     centre ray within `[lo, hi]`, so its horizontal position is within
//!     `e = (hi - lo) / 2 * |ray_xy|` of the interval's midpoint, and the disc of radius
//!     `r_s - e` around the midpoint is within `r_s` of it. Tighter than the frustum rule by
//!     up to half a pixel's footprint, and **not** implied by it: fed depth measured along
//!     another ray of the pixel, it can claim ground up to that much too far and take a car's
//!     cell out of its set.
//!
//!   Discs are drawn for a lattice of obstacle pixels every `stride` pixels plus every
//!   obstacle pixel on the border of an obstacle region; a subset of valid inner discs is
//!   still inner.
//! - [`hidden_ground`] (`H^CVS`, approximate): cells of the view whose centre projects into an
//!   obstacle, target or unknown pixel.
//! - [`observe_map`] (OEM, approximate): an obstacle pixel marks the map cell under its
//!   obstacle point's estimate (the barycentre of its frustum's corners with `any`, the
//!   midpoint of its centre-ray interval with `centre`) as obstacle, at least as tall as that
//!   point; a map cell whose centre projects into a ground pixel becomes ground.
//!
//! The other rules read no depth direction: `P^g` reads labels only, and `X^m_j` takes each
//! target pixel's whole frustum, so both hold under eq. (5) whatever the ray.

use protocol::camera::{Camera, range_interval};
use protocol::frame::{CvsFrame, Label, TargetBox};
use protocol::scenario::RayAssumption;
use sets::grid::GroundGrid;
use sets::math::{Point2, Point3, Real, Vector3, convex_hull, floor_fast};
use sets::raster::{CellSet, Coverage};

use crate::occupancy::OccupancyMap;

/// Slack in pixels added on each side of a projected cell's bounding box, far above the
/// rounding of the projection, so `P^g` never keeps a cell that grazes a non-ground pixel.
pub const PIXEL_EPSILON: Real = 1e-6;

/// Sides of the polygon that circumscribes the target disc when growing `X^m_j` by `r_t`.
const DISC_POLYGON_SIDES: usize = 16;

/// A frame ready to be measured: header checked, camera posed, effective labels computed.
pub struct FrameView<'a> {
    frame: &'a CvsFrame,
    camera: Camera,
    projector: GroundProjector,
    rays: PixelRays,
    corners: PixelRays,
    ray_assumption: RayAssumption,
    noise: [Real; 2],
    rows: u32,
    cols: u32,
    labels: Vec<Label>,
    invalid_depth: u32,
}

impl<'a> FrameView<'a> {
    /// Views a frame the caller checked with [`CvsFrame::is_well_formed`]. `noise` are the depth
    /// noise bounds the estimator was configured with; the bounds used are the hull of these
    /// and the frame's, so a frame that under-reports its noise cannot shrink an outer set.
    /// `ray_assumption` is what the rules may assume of the ray a depth was measured along.
    pub fn new(frame: &'a CvsFrame, noise: [Real; 2], ray_assumption: RayAssumption) -> Self {
        let camera = frame.camera();
        let (rows, cols) = (frame.header.rows, frame.header.cols);
        let n = frame.pixel_count();
        let mut invalid_depth = 0;
        let labels = frame.labels[..n]
            .iter()
            .zip(&frame.depth[..n])
            .map(|(&l, &d)| {
                if d.is_finite() && d > 0.0 {
                    Label::from_u8(l)
                } else {
                    invalid_depth += 1;
                    Label::Unknown
                }
            })
            .collect();
        let h = frame.header.depth_noise;
        let projector = GroundProjector::new(&camera);
        Self {
            frame,
            camera,
            rays: PixelRays::new(&projector, rows, cols, 0.5),
            corners: PixelRays::new(&projector, rows + 1, cols + 1, 0.0),
            ray_assumption,
            projector,
            noise: [noise[0].min(h[0]), noise[1].max(h[1])],
            rows,
            cols,
            labels,
            invalid_depth,
        }
    }

    /// The posed camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Pixels whose depth was not a finite positive number (counted as unknown).
    pub fn invalid_depth_pixels(&self) -> u32 {
        self.invalid_depth
    }

    /// Effective label of pixel `(r, c)`.
    pub fn label(&self, r: u32, c: u32) -> Label {
        self.labels[(r * self.cols + c) as usize]
    }

    /// The range interval of pixel `(r, c)` under the noise bounds in use.
    fn range(&self, r: u32, c: u32) -> Option<(Real, Real)> {
        range_interval(self.frame.depth_at(r, c), self.noise)
    }

    /// Where obstacle pixel `(r, c)`'s obstacle point may be, given its range interval
    /// `[lo, hi]`: a point `m` and a horizontal distance `e` such that the obstacle point is
    /// within `e` of `m` horizontally (see the module docs for each [`RayAssumption`]).
    fn obstacle_point(&self, r: u32, c: u32, lo: Real, hi: Real) -> (Point3, Real) {
        let o = self.camera.pose.position;
        // Each spread adds slack for the rounding of the ray directions and of the products.
        match self.ray_assumption {
            RayAssumption::Centre => {
                let dir = self.rays.get(r, c);
                let spread = (hi - lo) / 2.0 * dir.x.hypot(dir.y) + 1e-9 * hi + 1e-9;
                (o + dir * ((lo + hi) / 2.0), spread)
            }
            RayAssumption::Any => {
                let corners = self.frustum(r, c, lo, hi);
                let m = corners
                    .iter()
                    .fold(Vector3::zeros(), |acc, p| acc + p.coords)
                    / 8.0;
                let spread = corners
                    .iter()
                    .map(|p| (p.x - m.x).hypot(p.y - m.y))
                    .fold(0.0, Real::max);
                (Point3::from(m), spread + 1e-9 * hi + 1e-9)
            }
        }
    }

    /// [`Camera::pixel_frustum`] of pixel `(r, c)` from the frame's precomputed rays: the 4
    /// near corners then the 4 far corners of a convex polytope holding every point lit by the
    /// pixel at a range in `[lo, hi]`.
    fn frustum(&self, r: u32, c: u32, lo: Real, hi: Real) -> [Point3; 8] {
        let axis = self.rays.get(r, c);
        let rays = [
            self.corners.get(r, c),
            self.corners.get(r, c + 1),
            self.corners.get(r + 1, c + 1),
            self.corners.get(r + 1, c),
        ];
        let cos = rays.map(|d| axis.dot(&d));
        let near = lo.max(0.0) * cos.iter().copied().fold(Real::INFINITY, Real::min);
        let o = self.camera.pose.position;
        let mut out = [o; 8];
        for i in 0..4 {
            out[i] = o + rays[i] * (near / cos[i]);
            out[i + 4] = o + rays[i] * (hi / cos[i]);
        }
        out
    }

    /// The cells of `grid` worth examining: those touching the ground footprint of the image
    /// (a convex quadrilateral), row by row, or the whole grid when the image reaches the
    /// horizon.
    fn cell_window(&self, grid: &GroundGrid) -> Option<CellWindow> {
        let Some(quad) = self.camera.image_ground_footprint() else {
            let full = (0, grid.nx.checked_sub(1)?);
            return Some(CellWindow {
                iy0: 0,
                spans: vec![Some(full); grid.ny as usize],
            });
        };
        let (y0, y1) = quad
            .iter()
            .fold((Real::INFINITY, Real::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.y), hi.max(p.y))
            });
        let (iy0, iy1) = grid.rows_touching(y0, y1)?;
        let (columns, rows) = (grid.columns(), grid.rows());
        let spans = (iy0..=iy1)
            .map(|iy| {
                let band_lo = rows.edge(iy);
                let (x0, x1) = x_extent_in_band(&quad, band_lo, band_lo + grid.cell_m)?;
                // The margin of a cell covers every rounding of the projections.
                columns.touching(x0 - grid.cell_m, x1 + grid.cell_m)
            })
            .collect();
        Some(CellWindow { iy0, spans })
    }
}

/// The cells a frame can say something about: per row from `iy0`, the columns touching the
/// image's ground footprint (a cell outside projects partly outside the image).
struct CellWindow {
    iy0: u32,
    /// `(ix0, ix1)` per row, `None` for a row the footprint misses.
    spans: Vec<Option<(u32, u32)>>,
}

impl CellWindow {
    /// `(iy, ix0, ix1)` of every row the footprint touches.
    fn rows(&self) -> impl Iterator<Item = (u32, u32, u32)> + '_ {
        (self.iy0..)
            .zip(&self.spans)
            .filter_map(|(iy, span)| span.map(|(a, b)| (iy, a, b)))
    }

    /// The columns of row `iy`, if the footprint touches it.
    fn span(&self, iy: u32) -> Option<(u32, u32)> {
        let k = iy.checked_sub(self.iy0)? as usize;
        self.spans.get(k).copied().flatten()
    }
}

/// The x-extent of the convex hull of `points` within the band `ya <= y <= yb`: reached at a
/// point inside the band or where a segment between two points crosses a side of the band.
fn x_extent_in_band(points: &[Point2; 4], ya: Real, yb: Real) -> Option<(Real, Real)> {
    let (mut lo, mut hi) = (Real::INFINITY, Real::NEG_INFINITY);
    for (i, p) in points.iter().enumerate() {
        if (ya..=yb).contains(&p.y) {
            lo = lo.min(p.x);
            hi = hi.max(p.x);
        }
        for q in &points[i + 1..] {
            for y in [ya, yb] {
                if (p.y - y) * (q.y - y) < 0.0 {
                    let x = p.x + (y - p.y) / (q.y - p.y) * (q.x - p.x);
                    lo = lo.min(x);
                    hi = hi.max(x);
                }
            }
        }
    }
    (lo <= hi).then_some((lo, hi))
}

/// Projects ground points into the image with one affine map per frame: the camera-frame
/// coordinates of a ground point are affine in its `(x, y)`. Mirrors [`Camera::project`].
#[derive(Clone, Copy)]
struct GroundProjector {
    base: Vector3,
    ex: Vector3,
    ey: Vector3,
    f: Real,
    cx: Real,
    cy: Real,
    right: Vector3,
    down: Vector3,
    forward: Vector3,
}

impl GroundProjector {
    fn new(camera: &Camera) -> Self {
        let (st, ct) = camera.model.tilt_rad.sin_cos();
        let (sy, cy) = camera.pose.yaw.sin_cos();
        let forward = Vector3::new(ct * cy, ct * sy, -st);
        let right = Vector3::new(sy, -cy, 0.0);
        let down = forward.cross(&right);
        let o = camera.pose.position.coords;
        // Camera coordinates of world point p: (right, down, forward) . (p - o).
        let base = -Vector3::new(right.dot(&o), down.dot(&o), forward.dot(&o));
        Self {
            base,
            ex: Vector3::new(right.x, down.x, forward.x),
            ey: Vector3::new(right.y, down.y, forward.y),
            f: camera.model.focal_px(),
            cx: camera.model.cols as Real / 2.0,
            cy: camera.model.rows as Real / 2.0,
            right,
            down,
            forward,
        }
    }

    /// Camera-frame coordinates of the ground point `(x, y, 0)`.
    fn camera_coords(&self, x: Real, y: Real) -> Vector3 {
        self.base + self.ex * x + self.ey * y
    }

    /// Image point of camera-frame coordinates, `None` when not in front.
    fn image_point(&self, pc: &Vector3) -> Option<(Real, Real)> {
        (pc.z > 1e-9).then(|| {
            (
                self.cx + self.f * pc.x / pc.z,
                self.cy + self.f * pc.y / pc.z,
            )
        })
    }
}

/// Rays through a lattice of image points, `(c + offset, r + offset)`: the pixels' centre rays
/// (as [`Camera::centre_ray`], offset 0.5) or their corner rays (as [`Camera::corner_ray`],
/// offset 0, one more row and column), with the term of each column and of each row computed
/// once per frame.
struct PixelRays {
    /// `right * x` per column.
    across: Vec<Vector3>,
    /// `down * y` per row.
    down: Vec<Vector3>,
    forward: Vector3,
}

impl PixelRays {
    fn new(p: &GroundProjector, rows: u32, cols: u32, offset: Real) -> Self {
        Self {
            across: (0..cols)
                .map(|c| p.right * ((c as Real + offset - p.cx) / p.f))
                .collect(),
            down: (0..rows)
                .map(|r| p.down * ((r as Real + offset - p.cy) / p.f))
                .collect(),
            forward: p.forward,
        }
    }

    /// Unit world direction of the ray of lattice point `(r, c)`.
    fn get(&self, r: u32, c: u32) -> Vector3 {
        (self.across[c as usize] + self.down[r as usize] + self.forward).normalize()
    }
}

/// 2D prefix sums of "not ground" over the image, for O(1) box queries.
struct NotGroundSums {
    cols: usize,
    sums: Vec<u32>,
}

impl NotGroundSums {
    fn new(view: &FrameView<'_>) -> Self {
        let (rows, cols) = (view.rows as usize, view.cols as usize);
        let stride = cols + 1;
        let mut sums = vec![0u32; (rows + 1) * stride];
        for r in 0..rows {
            let mut run = 0u32;
            for c in 0..cols {
                run += (view.labels[r * cols + c] != Label::Ground) as u32;
                sums[(r + 1) * stride + c + 1] = sums[r * stride + c + 1] + run;
            }
        }
        Self { cols, sums }
    }

    /// Non-ground pixels in rows `r0..=r1`, columns `c0..=c1`.
    fn count(&self, r0: usize, r1: usize, c0: usize, c1: usize) -> u32 {
        let s = self.cols + 1;
        self.sums[(r1 + 1) * s + c1 + 1] + self.sums[r0 * s + c0]
            - self.sums[r0 * s + c1 + 1]
            - self.sums[(r1 + 1) * s + c0]
    }
}

/// `P^g(Y^g)`, inner: cells whose projection touches only ground pixels (see the module docs).
///
/// The cells are examined in bands of 8 rows. A block of 8 x 8 cells whose
/// projection lies inside the image and touches only ground pixels is free as a whole: the
/// projection of a ground rectangle in front of the camera is the convex quadrilateral of its
/// corners' images, so every cell's pixels are among the block's (the block's pixel range is
/// widened by `1e-6` pixels against the rounding of the separate projections). Every other
/// cell is examined alone; the result is the same cell by cell.
pub fn free_ground(view: &FrameView<'_>, grid: &GroundGrid) -> CellSet {
    let mut out = CellSet::empty(grid);
    let Some(window) = view.cell_window(grid) else {
        return out;
    };
    let test = PixelTest::new(view);
    let p = &view.projector;
    // Vertex row `iy` is projected over the columns of the cell rows below and above it,
    // `ix0..=ix1 + 1`; no other entry of it is read.
    let vertex_row = |iy: u32, buf: &mut [Option<(Real, Real)>]| {
        let y = grid.origin.y + iy as Real * grid.cell_m;
        let spans = [
            iy.checked_sub(1).and_then(|b| window.span(b)),
            window.span(iy),
        ];
        let Some((a, b)) = spans
            .into_iter()
            .flatten()
            .reduce(|(a0, b0), (a1, b1)| (a0.min(a1), b0.max(b1)))
        else {
            return;
        };
        for (k, slot) in buf
            .iter_mut()
            .enumerate()
            .take(b as usize + 2)
            .skip(a as usize)
        {
            let x = grid.origin.x + k as Real * grid.cell_m;
            *slot = p.image_point(&p.camera_coords(x, y));
        }
    };
    let width = grid.nx as usize + 1;
    let mut vertices = vec![None; width * (BLOCK as usize + 1)];
    let last_row = window.iy0 + window.spans.len() as u32;
    for band in (window.iy0..last_row).step_by(BLOCK as usize) {
        let band_end = (band + BLOCK).min(last_row);
        // The previous band's top vertex row is this band's bottom one.
        let (fresh, first) = if band == window.iy0 {
            (0, band)
        } else {
            vertices.copy_within(BLOCK as usize * width.., 0);
            (1, band + 1)
        };
        for (j, iy) in (fresh..).zip(first..=band_end) {
            vertex_row(iy, &mut vertices[j * width..(j + 1) * width]);
        }
        let vertex = |iy: u32, ix: u32| vertices[(iy - band) as usize * width + ix as usize];
        // Blocks inside every row's span of the band, free as a whole.
        let common = (band..band_end)
            .map(|iy| window.span(iy))
            .reduce(|a, b| Some((a?.0.max(b?.0), a?.1.min(b?.1))))
            .flatten();
        let mut free_blocks = Vec::new();
        if let Some((a, b)) = common.filter(|_| band_end - band == BLOCK) {
            let mut bx = a.div_ceil(BLOCK) * BLOCK;
            while bx + BLOCK - 1 <= b {
                let corners = [
                    vertex(band, bx),
                    vertex(band, bx + BLOCK),
                    vertex(band_end, bx),
                    vertex(band_end, bx + BLOCK),
                ];
                if test.all_ground(corners, BLOCK_MARGIN) {
                    free_blocks.push(bx);
                }
                bx += BLOCK;
            }
        }
        for iy in band..band_end {
            let Some((ix0, ix1)) = window.span(iy) else {
                continue;
            };
            for &bx in &free_blocks {
                out.fill_row_span(iy, bx, bx + BLOCK - 1);
            }
            let mut blocks = free_blocks.iter().peekable();
            let mut ix = ix0;
            while ix <= ix1 {
                if blocks.peek() == Some(&&ix) {
                    blocks.next();
                    ix += BLOCK;
                    continue;
                }
                let corners = [
                    vertex(iy, ix),
                    vertex(iy, ix + 1),
                    vertex(iy + 1, ix),
                    vertex(iy + 1, ix + 1),
                ];
                if test.all_ground(corners, 0.0) {
                    out.set((ix, iy), true);
                }
                ix += 1;
            }
        }
    }
    out
}

/// Cells per side of the blocks [`free_ground`] tries whole.
const BLOCK: u32 = 8;
/// Extra widening, pixels, of a block's pixel range: far above the rounding of projecting its
/// corners and its cells' corners separately, far below a pixel.
const BLOCK_MARGIN: Real = 1e-6;

/// Whether a ground quadrilateral, given by the images of its corners, projects inside the
/// image onto ground pixels only.
struct PixelTest {
    sums: NotGroundSums,
    rows: Real,
    cols: Real,
}

impl PixelTest {
    fn new(view: &FrameView<'_>) -> Self {
        Self {
            sums: NotGroundSums::new(view),
            rows: view.rows as Real,
            cols: view.cols as Real,
        }
    }

    /// True when every corner is in front of the camera and the closed pixels touching the
    /// corners' bounding box, widened by [`PIXEL_EPSILON`] and `margin`, lie in the image and
    /// are all ground.
    fn all_ground(&self, corners: [Option<(Real, Real)>; 4], margin: Real) -> bool {
        let mut bb = [
            Real::INFINITY,
            Real::NEG_INFINITY,
            Real::INFINITY,
            Real::NEG_INFINITY,
        ];
        for c in corners {
            let Some((u, v)) = c else {
                return false;
            };
            bb[0] = bb[0].min(u);
            bb[1] = bb[1].max(u);
            bb[2] = bb[2].min(v);
            bb[3] = bb[3].max(v);
        }
        // Closed pixel c covers [c, c+1]: the columns touching [u0, u1] run from floor(u0)
        // (minus one when u0 sits on a pixel edge) to floor(u1).
        let widen = PIXEL_EPSILON + margin;
        let c0 = floor_fast(bb[0] - widen);
        let c1 = floor_fast(bb[1] + widen);
        let r0 = floor_fast(bb[2] - widen);
        let r1 = floor_fast(bb[3] + widen);
        c0 >= 0.0
            && r0 >= 0.0
            && c1 < self.cols
            && r1 < self.rows
            && self
                .sums
                .count(r0 as usize, r1 as usize, c0 as usize, c1 as usize)
                == 0
    }
}

/// `H^CVS`, approximate: cells whose centre projects into an obstacle, target or unknown pixel.
///
/// The cells of `free`, this frame's [`free_ground`], are not examined: every pixel their
/// projection touches is ground, so their centre's is.
pub fn hidden_ground(view: &FrameView<'_>, grid: &GroundGrid, free: &CellSet) -> CellSet {
    let mut out = CellSet::empty(grid);
    let Some(window) = view.cell_window(grid) else {
        return out;
    };
    let p = &view.projector;
    for (iy, ix0, ix1) in window.rows() {
        let y = grid.origin.y + (iy as Real + 0.5) * grid.cell_m;
        for ix in (ix0..=ix1).filter(|&ix| !free.contains((ix, iy))) {
            let x = grid.origin.x + (ix as Real + 0.5) * grid.cell_m;
            if let Some((u, v)) = p.image_point(&p.camera_coords(x, y))
                && u >= 0.0
                && v >= 0.0
                && u < view.cols as Real
                && v < view.rows as Real
                && view.label(v as u32, u as u32) != Label::Ground
            {
                out.set((ix, iy), true);
            }
        }
    }
    out
}

/// `X^m_j`, outer, for one box (checked valid by the caller): `None` when the box holds no
/// target pixel with a usable depth, in which case the frame says nothing about the target.
pub fn target_measurement(
    view: &FrameView<'_>,
    grid: &GroundGrid,
    target_box: &TargetBox,
    target_radius_m: Real,
) -> Option<CellSet> {
    let mut shadow = Vec::new();
    for r in target_box.r0..target_box.r1 {
        for c in target_box.c0..target_box.c1 {
            if view.label(r, c) != Label::Target {
                continue;
            }
            if let Some((lo, hi)) = view.range(r, c) {
                shadow.extend(view.camera.pixel_frustum_ground_hull(r, c, lo, hi));
            }
        }
    }
    let hull = convex_hull(&shadow);
    if hull.is_empty() {
        return None;
    }
    // The regular polygon with apothem r_t contains the disc of radius r_t; a relative margin
    // covers the rounding of the trigonometry.
    let circumradius = target_radius_m / (std::f64::consts::PI / DISC_POLYGON_SIDES as Real).cos()
        * (1.0 + 1e-9)
        + 1e-9;
    let grown: Vec<Point2> = hull
        .iter()
        .flat_map(|v| {
            (0..DISC_POLYGON_SIDES).map(move |k| {
                let a = std::f64::consts::TAU * k as Real / DISC_POLYGON_SIDES as Real;
                Point2::new(v.x + circumradius * a.cos(), v.y + circumradius * a.sin())
            })
        })
        .collect();
    let mut out = CellSet::empty(grid);
    out.fill_convex_polygon(grid, &convex_hull(&grown), Coverage::Outer);
    Some(out)
}

/// `S^o` of this frame, inner (see the module docs for the rule and the pixel subset).
pub fn obstacle_neighbourhood(
    view: &FrameView<'_>,
    grid: &GroundGrid,
    safety_distance_m: Real,
    stride: u32,
) -> CellSet {
    let mut out = CellSet::empty(grid);
    add_obstacle_neighbourhood(view, grid, safety_distance_m, stride, &mut out);
    out
}

/// `out ∪=` [`obstacle_neighbourhood`] of this frame. Folding a frame into the `S^o` accumulated so
/// far costs less than building the frame's own and joining it: a disc whose cells the set
/// already holds is skipped before it is rasterised, and most obstacles were seen before.
pub fn add_obstacle_neighbourhood(
    view: &FrameView<'_>,
    grid: &GroundGrid,
    safety_distance_m: Real,
    stride: u32,
    out: &mut CellSet,
) {
    let stride = stride.max(1);
    let is_obstacle = |r: u32, c: u32| view.label(r, c) == Label::Obstacle;
    for r in 0..view.rows {
        for c in 0..view.cols {
            if !is_obstacle(r, c) {
                continue;
            }
            let on_lattice = r % stride == 0 && c % stride == 0;
            let on_border = r == 0
                || c == 0
                || r + 1 == view.rows
                || c + 1 == view.cols
                || !is_obstacle(r - 1, c)
                || !is_obstacle(r + 1, c)
                || !is_obstacle(r, c - 1)
                || !is_obstacle(r, c + 1);
            if !(on_lattice || on_border) {
                continue;
            }
            let Some((lo, hi)) = view.range(r, c) else {
                continue;
            };
            let (point, spread) = view.obstacle_point(r, c, lo, hi);
            let radius = safety_distance_m - spread;
            if radius <= 0.0 {
                continue;
            }
            out.fill_disc(grid, Point2::new(point.x, point.y), radius, Coverage::Inner);
        }
    }
}

/// Folds the frame into the occupancy map (see the module docs). Returns the cells changed.
pub fn observe_map(view: &FrameView<'_>, map: &mut OccupancyMap) -> usize {
    let mut changed = 0;
    for r in 0..view.rows {
        for c in 0..view.cols {
            if view.label(r, c) != Label::Obstacle {
                continue;
            }
            let Some((lo, hi)) = view.range(r, c) else {
                continue;
            };
            let (p, _) = view.obstacle_point(r, c, lo, hi);
            changed += map.observe_obstacle(&Point2::new(p.x, p.y), p.z) as usize;
        }
    }
    let grid = *map.grid();
    let Some(window) = view.cell_window(&grid) else {
        return changed;
    };
    let pr = &view.projector;
    for (iy, ix0, ix1) in window.rows() {
        for ix in ix0..=ix1 {
            let centre = grid.cell_centre((ix, iy));
            if let Some((u, v)) = pr.image_point(&pr.camera_coords(centre.x, centre.y))
                && u >= 0.0
                && v >= 0.0
                && u < view.cols as Real
                && v < view.rows as Real
                && view.label(v as u32, u as u32) == Label::Ground
            {
                changed += map.observe_ground((ix, iy)) as usize;
            }
        }
    }
    changed
}

#[cfg(test)]
mod tests {
    use protocol::camera::{CameraModel, CameraPose};
    use sets::math::Point3;

    use super::*;

    fn small_frame(yaw: Real) -> Box<CvsFrame> {
        let mut f = CvsFrame::new_boxed();
        let model = CameraModel {
            rows: 24,
            cols: 32,
            aperture_rad: std::f64::consts::FRAC_PI_4,
            tilt_rad: 0.9,
        };
        let pose = CameraPose {
            position: Point3::new(3.0, -4.0, 40.0),
            yaw,
        };
        let h = &mut f.header;
        h.rows = model.rows;
        h.cols = model.cols;
        h.camera_aperture = model.aperture_rad;
        h.camera_tilt = model.tilt_rad;
        h.camera_position = [pose.position.x, pose.position.y, pose.position.z];
        h.camera_yaw = pose.yaw;
        h.depth_noise = [-0.01, 0.01];
        f
    }

    /// Labels from a deterministic pattern: mostly ground with blobs of other classes.
    fn paint(f: &mut CvsFrame, seed: u32) {
        let cam = f.camera();
        let (rows, cols) = (f.header.rows, f.header.cols);
        for r in 0..rows {
            for c in 0..cols {
                let i = (r * cols + c) as usize;
                let h =
                    (r.wrapping_mul(73) ^ c.wrapping_mul(151) ^ seed).wrapping_mul(2_654_435_761);
                f.labels[i] = match (h >> 28) % 8 {
                    0 => Label::Obstacle as u8,
                    1 => Label::Unknown as u8,
                    _ => Label::Ground as u8,
                };
                let ray = cam.centre_ray(r, c);
                f.depth[i] = (cam.origin().z / -ray.z) as f32;
            }
        }
    }

    #[test]
    fn projector_matches_camera_project() {
        let f = small_frame(0.7);
        let cam = f.camera();
        let p = GroundProjector::new(&cam);
        for &(x, y) in &[(10.0, 20.0), (-3.0, 55.0), (30.0, 5.0)] {
            let a = cam.project(&Point3::new(x, y, 0.0));
            let b = p.image_point(&p.camera_coords(x, y));
            match (a, b) {
                (Some(a), Some(b)) => assert!((a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9),
                (None, None) => {}
                _ => panic!("front tests disagree at ({x}, {y})"),
            }
        }
        let rays = PixelRays::new(&p, 24, 32, 0.5);
        let corners = PixelRays::new(&p, 25, 33, 0.0);
        for &(r, c) in &[(0, 0), (5, 17), (23, 31)] {
            assert!((rays.get(r, c) - cam.centre_ray(r, c)).norm() < 1e-12);
            assert!((corners.get(r + 1, c + 1) - cam.corner_ray(r + 1, c + 1)).norm() < 1e-12);
        }
        let view = FrameView::new(&f, [-0.01, 0.01], RayAssumption::Any);
        for (a, b) in view
            .frustum(5, 17, 40.0, 41.0)
            .iter()
            .zip(cam.pixel_frustum(5, 17, 40.0, 41.0))
        {
            assert!((a - b).norm() < 1e-9);
        }
    }

    /// The naive rule: project the corners with the camera, take the closed pixel box, and
    /// look at every pixel in it.
    fn naive_free_ground(view: &FrameView<'_>, grid: &GroundGrid) -> CellSet {
        let mut out = CellSet::empty(grid);
        let cam = view.camera();
        for iy in 0..grid.ny {
            'cells: for ix in 0..grid.nx {
                let rect = grid.cell_rect((ix, iy));
                let mut uv = Vec::new();
                for p in rect.corners() {
                    match cam.project(&Point3::new(p.x, p.y, 0.0)) {
                        Some(q) => uv.push(q),
                        None => continue 'cells,
                    }
                }
                let u0 = uv.iter().map(|q| q.0).fold(Real::INFINITY, Real::min);
                let u1 = uv.iter().map(|q| q.0).fold(Real::NEG_INFINITY, Real::max);
                let v0 = uv.iter().map(|q| q.1).fold(Real::INFINITY, Real::min);
                let v1 = uv.iter().map(|q| q.1).fold(Real::NEG_INFINITY, Real::max);
                let (c0, c1) = ((u0 - PIXEL_EPSILON).floor(), (u1 + PIXEL_EPSILON).floor());
                let (r0, r1) = ((v0 - PIXEL_EPSILON).floor(), (v1 + PIXEL_EPSILON).floor());
                if c0 < 0.0 || r0 < 0.0 || c1 >= view.cols as Real || r1 >= view.rows as Real {
                    continue;
                }
                for r in r0 as u32..=r1 as u32 {
                    for c in c0 as u32..=c1 as u32 {
                        if view.label(r, c) != Label::Ground {
                            continue 'cells;
                        }
                    }
                }
                out.set((ix, iy), true);
            }
        }
        out
    }

    #[test]
    fn free_ground_equals_brute_force() {
        for (k, &yaw) in [0.0, 0.6, 2.2, -1.3].iter().enumerate() {
            let mut f = small_frame(yaw);
            paint(&mut f, k as u32);
            // A pixel with a bad depth counts as unknown, even when labelled ground.
            f.depth[40] = f32::NAN;
            f.labels[40] = Label::Ground as u8;
            let view = FrameView::new(&f, [-0.01, 0.01], RayAssumption::Any);
            assert_eq!(view.invalid_depth_pixels(), 1);
            let grid = GroundGrid::new(100.0, 1.0);
            let fast = free_ground(&view, &grid);
            let naive = naive_free_ground(&view, &grid);
            assert!(fast.count() > 0, "yaw {yaw}: nothing free");
            assert_eq!(fast, naive, "yaw {yaw}");
        }
    }

    #[test]
    fn free_ground_cells_project_only_onto_ground_pixels() {
        let mut f = small_frame(0.3);
        paint(&mut f, 9);
        let view = FrameView::new(&f, [-0.01, 0.01], RayAssumption::Any);
        let grid = GroundGrid::new(100.0, 1.0);
        let free = free_ground(&view, &grid);
        let cam = view.camera();
        // Sample points in every free cell: each must land on a ground pixel.
        for (ix, iy) in free.iter() {
            let rect = grid.cell_rect((ix, iy));
            for a in 0..=4 {
                for b in 0..=4 {
                    let x = rect.min.x + (rect.max.x - rect.min.x) * a as Real / 4.0;
                    let y = rect.min.y + (rect.max.y - rect.min.y) * b as Real / 4.0;
                    let (u, v) = cam.project(&Point3::new(x, y, 0.0)).unwrap();
                    let (c, r) = (u.floor().min(31.0) as u32, v.floor().min(23.0) as u32);
                    assert_eq!(view.label(r, c), Label::Ground);
                }
            }
        }
    }

    #[test]
    fn target_measurement_contains_the_lit_points_grown_by_the_radius() {
        let mut f = small_frame(1.1);
        paint(&mut f, 3);
        let cam = f.camera();
        let b = TargetBox {
            id: 4,
            r0: 10,
            c0: 12,
            r1: 14,
            c1: 17,
        };
        for r in b.r0..b.r1 {
            for c in b.c0..b.c1 {
                f.labels[(r * 32 + c) as usize] = Label::Target as u8;
            }
        }
        let view = FrameView::new(&f, [-0.01, 0.01], RayAssumption::Any);
        let grid = GroundGrid::new(100.0, 0.5);
        let radius = 2.5;
        let xm = target_measurement(&view, &grid, &b, radius).unwrap();
        // Any point lit by a target pixel at its measured range, moved by up to r_t, is in.
        for r in b.r0..b.r1 {
            for c in b.c0..b.c1 {
                let (lo, hi) = view.range(r, c).unwrap();
                for &(du, dv) in &[(0.0, 0.0), (1.0, 1.0), (0.5, 0.5), (1.0, 0.0)] {
                    for &t in &[lo, hi] {
                        let p = cam.origin() + cam.ray(c as Real + du, r as Real + dv) * t;
                        for k in 0..12 {
                            let a = k as Real * std::f64::consts::FRAC_PI_6;
                            let q = Point2::new(p.x + radius * a.cos(), p.y + radius * a.sin());
                            assert!(xm.contains(grid.cell_of(&q).unwrap()));
                        }
                    }
                }
            }
        }
        // A box with no target pixel says nothing.
        let empty = TargetBox {
            id: 5,
            r0: 0,
            c0: 0,
            r1: 1,
            c1: 1,
        };
        f.labels[0] = Label::Ground as u8;
        let view = FrameView::new(&f, [-0.01, 0.01], RayAssumption::Any);
        assert!(target_measurement(&view, &grid, &empty, radius).is_none());
    }

    /// Every `S^o` cell of `so` is within `r_s` of the obstacle point of one obstacle pixel,
    /// wherever that point is among `points(r, c, lo, hi)` (points of the pixel's depth ray(s)
    /// at the ends of its range interval).
    fn assert_within_safety_distance(
        view: &FrameView<'_>,
        grid: &GroundGrid,
        so: &CellSet,
        rs: Real,
        points: impl Fn(u32, u32, Real, Real) -> Vec<Point3>,
    ) {
        let mut pixels = Vec::new();
        for r in 0..view.rows {
            for c in 0..view.cols {
                if view.label(r, c) == Label::Obstacle {
                    let (lo, hi) = view.range(r, c).unwrap();
                    pixels.push(points(r, c, lo, hi));
                }
            }
        }
        for cell in so.iter() {
            let rect = grid.cell_rect(cell);
            let ok = pixels.iter().any(|pts| {
                pts.iter().all(|p| {
                    rect.corners()
                        .iter()
                        .all(|q| (q.x - p.x).hypot(q.y - p.y) <= rs + 1e-9)
                })
            });
            assert!(ok, "cell {cell:?} is not within r_s of one obstacle pixel");
        }
    }

    /// Draws the test frame's `S^o` under `rule` and checks it against `points` (see
    /// [`assert_within_safety_distance`]).
    fn check_rule(
        rule: RayAssumption,
        points: impl Fn(&Camera, u32, u32, Real, Real) -> Vec<Point3>,
    ) {
        let mut f = small_frame(-0.4);
        paint(&mut f, 5);
        let view = FrameView::new(&f, [-0.01, 0.01], rule);
        let grid = GroundGrid::new(100.0, 0.5);
        let rs = 3.0;
        let so = obstacle_neighbourhood(&view, &grid, rs, 1);
        assert!(so.count() > 0);
        let cam = view.camera();
        assert_within_safety_distance(&view, &grid, &so, rs, |r, c, lo, hi| {
            points(cam, r, c, lo, hi)
        });
    }

    /// The centre-ray rule: within `r_s` of the centre ray's points.
    #[test]
    fn centre_ray_discs_stay_within_the_safety_distance_of_the_centre_ray() {
        check_rule(RayAssumption::Centre, |cam, r, c, lo, hi| {
            let d = cam.centre_ray(r, c);
            vec![cam.origin() + d * lo, cam.origin() + d * hi]
        });
    }

    /// The default rule (eq. 5): within `r_s` of every point of the pixel's frustum, so of the
    /// obstacle point whichever ray of the pixel the depth was measured along.
    #[test]
    fn any_ray_discs_stay_within_the_safety_distance_of_every_ray_of_the_pixel() {
        check_rule(RayAssumption::Any, |cam, r, c, lo, hi| {
            let mut pts = Vec::new();
            for k in 0..=4 {
                for l in 0..=4 {
                    let d = cam.ray(c as Real + k as Real / 4.0, r as Real + l as Real / 4.0);
                    pts.extend([cam.origin() + d * lo, cam.origin() + d * hi]);
                }
            }
            pts
        });
    }

    /// The frustum rule on one pixel: obstacle pixel (12, 16) of the test camera (yaw 0, tilt
    /// 0.9 rad, 32 x 24 pixels over pi/4) at range 40 m +- 1 %: its disc is centred on the
    /// mean of the frustum's corners and shrunk by the farthest corner, which is the
    /// centre-ray rule's spread plus about half the pixel's footprint.
    #[test]
    fn the_frustum_rule_shrinks_the_disc_by_the_farthest_corner() {
        let f = small_frame(0.0);
        let view = FrameView::new(&f, [-0.01, 0.01], RayAssumption::Any);
        let (lo, hi) = (40.0 / 1.01, 40.0 / 0.99);
        let (m, e) = view.obstacle_point(12, 16, lo, hi);
        let corners = f.camera().pixel_frustum(12, 16, lo, hi);
        let mean = corners.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / 8.0;
        assert!((m.coords - mean).norm() < 1e-9);
        let far = corners
            .iter()
            .map(|p| (p.x - mean.x).hypot(p.y - mean.y))
            .fold(0.0, Real::max);
        assert!(e >= far && e < far + 1e-6);
        // The centre-ray rule's spread: half the interval along the centre ray, horizontally.
        let centre = FrameView::new(&f, [-0.01, 0.01], RayAssumption::Centre);
        let (_, e_centre) = centre.obstacle_point(12, 16, lo, hi);
        let dir = f.camera().centre_ray(12, 16);
        let expected = (hi - lo) / 2.0 * dir.x.hypot(dir.y);
        assert!((e_centre - expected).abs() < 1e-6);
        // The frustum adds about half the pixel's footprint at 40 m: 40 * (pi/4) / 32 / 2.
        let half_pixel = 40.0 * std::f64::consts::FRAC_PI_4 / 32.0 / 2.0;
        assert!(
            e > e_centre && e < e_centre + 1.5 * half_pixel,
            "{e} vs {e_centre}"
        );
    }

    /// Why the centre-ray rule needs a centre-ray source: depth measured along a corner ray of
    /// an obstacle pixel (a ray eq. 5 allows) puts the obstacle point about half a pixel's
    /// footprint from the centre ray's, and the centre-ray rule then claims ground more than
    /// `r_s` from it, where the paper lets a car be. The frustum rule does not.
    #[test]
    fn the_centre_ray_rule_claims_ground_beyond_r_s_of_a_corner_ray_point() {
        let (r, c) = (12, 16);
        let mut f = small_frame(0.0);
        f.header.depth_noise = [0.0, 0.0];
        let n = f.pixel_count();
        f.labels[..n].fill(Label::Unknown as u8);
        let i = (r * f.header.cols + c) as usize;
        f.labels[i] = Label::Obstacle as u8;
        let cam = f.camera();
        let range = 40.0;
        f.depth[i] = range as f32;
        let range = f.depth[i] as Real;
        // The obstacle point, on the pixel's top-left corner ray.
        let p = cam.origin() + cam.corner_ray(r, c) * range;
        let m = cam.origin() + cam.centre_ray(r, c) * range;
        let away = Vector3::new(m.x - p.x, m.y - p.y, 0.0);
        let offset = away.norm();
        assert!(
            offset > 0.4,
            "the corner's point is {offset} m from the centre's"
        );
        // A car's ground point beyond r_s from p, on the far side of the centre ray's point.
        let rs = 3.0;
        let q = p + away / offset * (rs + offset / 2.0);
        let q = Point2::new(q.x, q.y);
        let grid = GroundGrid::new(100.0, 0.1);
        let cell = grid.cell_of(&q).unwrap();
        let centre = FrameView::new(&f, [0.0, 0.0], RayAssumption::Centre);
        assert!(obstacle_neighbourhood(&centre, &grid, rs, 1).contains(cell));
        let any = FrameView::new(&f, [0.0, 0.0], RayAssumption::Any);
        let so = obstacle_neighbourhood(&any, &grid, rs, 1);
        assert!(so.count() > 0 && !so.contains(cell));
    }
}
