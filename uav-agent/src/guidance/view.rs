//! Predicted fields of view: the ground a camera at a predicted pose will see, minus what the
//! known buildings of the occupancy map will hide from it.

use std::collections::BTreeMap;

use protocol::camera::{Camera, CameraModel, CameraPose};
use sets::grid::{GroundGrid, Rect};
use sets::math::{Point2, Point3, convex_hull_into};
use sets::raster::{CellSet, Coverage};

use estimator::occupancy::{OccupancyMap, OemStatus};

/// A known obstacle for planning: an OEM cell marked occupied, with its estimated height.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObstacleCell {
    /// The cell's footprint.
    pub rect: Rect,
    /// Estimated height, metres.
    pub height_m: f64,
}

impl ObstacleCell {
    /// The buildings `oem` knows: every cell marked occupied, with its height.
    pub fn known(oem: &OccupancyMap) -> Vec<ObstacleCell> {
        let grid = oem.grid();
        oem.known_cells()
            .filter(|(_, c)| c.status == OemStatus::Obstacle)
            .map(|(idx, c)| ObstacleCell {
                rect: grid.cell_rect(idx),
                height_m: f64::from(c.height_m),
            })
            .collect()
    }
}

/// Ground shadow of an obstacle seen from `eye`: the convex hull of its footprint and of its
/// top face projected from the eye onto the ground. `None` if the eye is not above the top.
pub fn shadow(eye: &Point3, obstacle: &ObstacleCell) -> Option<Vec<Point2>> {
    let mut hull = Vec::new();
    shadow_into(eye, obstacle, &mut hull).then_some(hull)
}

/// [`shadow`] written into `hull` (cleared first), without allocating once it has room;
/// false (and `hull` empty) if the eye is not above the top.
fn shadow_into(eye: &Point3, obstacle: &ObstacleCell, hull: &mut Vec<Point2>) -> bool {
    let Some(scale) = shadow_scale(eye, obstacle) else {
        hull.clear();
        return false;
    };
    let corners = obstacle.rect.corners();
    let mut pts = [Point2::origin(); 8];
    for (i, c) in corners.iter().enumerate() {
        pts[2 * i] = *c;
        pts[2 * i + 1] = project(eye, c, scale);
    }
    convex_hull_into(&mut pts, hull);
    true
}

/// The factor that projects the obstacle's top from `eye` onto the ground, if the eye is above
/// the top.
fn shadow_scale(eye: &Point3, obstacle: &ObstacleCell) -> Option<f64> {
    (eye.z > obstacle.height_m + 1e-6).then(|| eye.z / (eye.z - obstacle.height_m))
}

fn project(eye: &Point3, p: &Point2, scale: f64) -> Point2 {
    Point2::new(eye.x + (p.x - eye.x) * scale, eye.y + (p.y - eye.y) * scale)
}

/// The bounding box of [`shadow`] without building the hull: the footprint and the projected
/// top are both axis-aligned rectangles (the projection scales about the eye by a positive
/// factor), so the hull's box is the union of the two.
fn shadow_bounds(eye: &Point3, obstacle: &ObstacleCell) -> Option<Rect> {
    let scale = shadow_scale(eye, obstacle)?;
    let (lo, hi) = (
        project(eye, &obstacle.rect.min, scale),
        project(eye, &obstacle.rect.max, scale),
    );
    Some(Rect {
        min: Point2::new(obstacle.rect.min.x.min(lo.x), obstacle.rect.min.y.min(lo.y)),
        max: Point2::new(obstacle.rect.max.x.max(hi.x), obstacle.rect.max.y.max(hi.y)),
    })
}

fn bbox(points: &[Point2]) -> Rect {
    let mut r = Rect {
        min: Point2::new(f64::INFINITY, f64::INFINITY),
        max: Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
    };
    for p in points {
        r.min.x = r.min.x.min(p.x);
        r.min.y = r.min.y.min(p.y);
        r.max.x = r.max.x.max(p.x);
        r.max.y = r.max.y.max(p.y);
    }
    r
}

fn overlaps(a: &Rect, b: &Rect) -> bool {
    a.min.x <= b.max.x && b.min.x <= a.max.x && a.min.y <= b.max.y && b.min.y <= a.max.y
}

/// Adds to `seen` the cells of the field of view of a camera at `pose` (cells whose centre
/// lies wholly in the footprint: approximate by design, guidance needs no guarantee), less
/// the shadows of `obstacles`.
pub fn add_visible_ground(
    seen: &mut CellSet,
    grid: &GroundGrid,
    model: &CameraModel,
    pose: &CameraPose,
    obstacles: &[ObstacleCell],
) {
    let camera = Camera::new(*model, *pose);
    let Some(footprint) = camera.image_ground_footprint() else {
        return;
    };
    let mut visible = CellSet::empty(grid);
    visible.fill_convex_polygon(grid, &footprint, Coverage::Inner);
    if !obstacles.is_empty() {
        let fov_box = bbox(&footprint);
        let whole = CellWindow::whole(grid);
        let mut shadows = CellSet::empty(grid);
        let mut any = false;
        for o in obstacles {
            // The boxes first: most shadows lie far from the field of view, and a shadow's rows
            // without cells visible and not yet shadowed change nothing (tall buildings cast
            // shadows far longer than the field of view).
            if let Some(b) = shadow_bounds(&pose.position, o)
                && overlaps(&b, &fov_box)
                && let Some(rows) = rows_to_cover(grid, &b, &visible, &shadows, &whole)
                && let Some(hull) = shadow(&pose.position, o)
            {
                shadows.fill_convex_polygon_rows(grid, &hull, Coverage::Outer, rows);
                any = true;
            }
        }
        if any {
            visible.and_not_assign(&shadows);
        }
    }
    seen.or_assign(&visible);
}

/// Predicts the ground cameras at planned poses will see, but only on the ground a caller
/// cares about (the cells of the predicted sets: a view only changes the sets where they
/// are), with buffers reused from one pose to the next.
///
/// [`GroundPredictor::add_visible_ground_within`] adds exactly the cells of `relevant` that
/// [`add_visible_ground`] adds: the shadows are rasterised only on the rows where the field of
/// view holds relevant cells not yet shadowed, so a pose whose footprint misses the sets costs
/// its footprint's raster and nothing more.
#[derive(Clone, Debug)]
pub struct GroundPredictor {
    /// The relevant visible cells of the pose being predicted; empty between calls.
    visible: CellSet,
    /// The shadows of the pose being predicted; empty between calls.
    shadows: CellSet,
    /// The hull of the shadow being rasterised.
    hull: Vec<Point2>,
    /// The footprints rasterised so far, by pose, on the grid named (when asked to remember
    /// them).
    footprints: Option<(GroundGrid, BTreeMap<[u64; 4], FootprintRaster>)>,
}

/// The inner raster of a pose's footprint: its rows' words.
#[derive(Clone, Debug)]
struct FootprintRaster {
    rows: (u32, u32),
    fov_box: Rect,
    words: Vec<u64>,
}

impl GroundPredictor {
    /// A predictor for sets on `grid`.
    pub fn new(grid: &GroundGrid) -> Self {
        Self {
            visible: CellSet::empty(grid),
            shadows: CellSet::empty(grid),
            hull: Vec::with_capacity(9),
            footprints: None,
        }
    }

    /// A predictor for sets on `grid` that remembers the raster of every pose's footprint,
    /// for a caller that predicts the same poses several times (the paper's search bounds
    /// each sequence, then costs it): the same cells for less time, and memory that grows
    /// with the poses (a few kilobytes each).
    pub fn remembering_footprints(grid: &GroundGrid) -> Self {
        Self {
            footprints: Some((*grid, BTreeMap::new())),
            ..Self::new(grid)
        }
    }

    /// Adds to `seen` the cells of `relevant` in the field of view of a camera at `pose`
    /// before any building hides them: a superset of what
    /// [`GroundPredictor::add_visible_ground_within`] adds, for a fraction of its time.
    pub fn add_footprint_within(
        &mut self,
        seen: &mut CellSet,
        grid: &GroundGrid,
        model: &CameraModel,
        pose: &CameraPose,
        relevant: &CellSet,
    ) {
        if !seen.same_shape(relevant) {
            return;
        }
        if let Some(footprint) = self.relevant_footprint(grid, model, pose, relevant) {
            let (r0, r1) = footprint.rows;
            for y in r0..=r1 {
                for (out, v) in seen.row_mut(y).iter_mut().zip(self.visible.row_mut(y)) {
                    *out |= *v;
                    *v = 0;
                }
            }
        }
    }

    /// Rasterises into `visible` the cells of `relevant` in the field of view (inner cells)
    /// and says where they are; `None` when there is none (`visible` is then left empty).
    fn relevant_footprint(
        &mut self,
        grid: &GroundGrid,
        model: &CameraModel,
        pose: &CameraPose,
        relevant: &CellSet,
    ) -> Option<Footprint> {
        if (relevant.nx(), relevant.ny()) != (grid.nx, grid.ny) {
            return None;
        }
        if !self.visible.same_shape(relevant) {
            // Not the grid the buffers were made for: start afresh rather than mix shapes.
            let remember = self.footprints.is_some();
            *self = Self::new(grid);
            if remember {
                self.footprints = Some((*grid, BTreeMap::new()));
            }
        }
        if let Some((on, known)) = &mut self.footprints
            && on != grid
        {
            *on = *grid;
            known.clear();
        }
        let key = [pose.position.x, pose.position.y, pose.position.z, pose.yaw].map(f64::to_bits);
        let known = self.footprints.as_ref().and_then(|(_, k)| k.get(&key));
        let ((r0, r1), fov_box) = if let Some(raster) = known {
            let wpr = self.visible.words_per_row();
            for (y, words) in (raster.rows.0..=raster.rows.1).zip(raster.words.chunks(wpr)) {
                self.visible.row_mut(y).copy_from_slice(words);
            }
            (raster.rows, raster.fov_box)
        } else {
            let camera = Camera::new(*model, *pose);
            let footprint = camera.image_ground_footprint()?;
            let fov_box = bbox(&footprint);
            // The inner raster of the footprint lies in these rows (widened by a cell: the
            // buffer is cleared over them afterwards).
            let rows =
                grid.rows_touching(fov_box.min.y - grid.cell_m, fov_box.max.y + grid.cell_m)?;
            self.visible
                .fill_convex_polygon_rows(grid, &footprint, Coverage::Inner, rows);
            if let Some((_, known)) = &mut self.footprints {
                let words = (rows.0..=rows.1)
                    .flat_map(|y| self.visible.row(y).iter().copied())
                    .collect();
                known.insert(
                    key,
                    FootprintRaster {
                        rows,
                        fov_box,
                        words,
                    },
                );
            }
            (rows, fov_box)
        };
        let mut cells = CellWindow::EMPTY;
        for y in r0..=r1 {
            for (w, (v, r)) in self
                .visible
                .row_mut(y)
                .iter_mut()
                .zip(relevant.row(y))
                .enumerate()
            {
                *v &= r;
                cells.add_word(y, w, *v);
            }
        }
        (cells.count > 0).then_some(Footprint {
            rows: (r0, r1),
            fov_box,
            cells,
        })
    }

    /// Adds to `seen` the cells of `relevant` that [`add_visible_ground`] would add to it.
    /// `seen` and `relevant` must lie on `grid` (nothing is added when their shapes differ).
    ///
    /// A shadow is rasterised only when it may cover a visible cell not yet shadowed, and only
    /// on the rows where it may: the shadows and rows skipped would change no cell.
    pub fn add_visible_ground_within(
        &mut self,
        seen: &mut CellSet,
        grid: &GroundGrid,
        model: &CameraModel,
        pose: &CameraPose,
        obstacles: &[ObstacleCell],
        relevant: &CellSet,
    ) {
        if !seen.same_shape(relevant) {
            return;
        }
        let Some(footprint) = self.relevant_footprint(grid, model, pose, relevant) else {
            return;
        };
        let cells = footprint.cells;
        let window = cells.rect(grid);
        let mut shadowed: Option<(u32, u32)> = None;
        for o in obstacles {
            if let Some(b) = shadow_bounds(&pose.position, o)
                && overlaps(&b, &footprint.fov_box)
                && overlaps(&b, &window)
                && let Some(rows) = rows_to_cover(grid, &b, &self.visible, &self.shadows, &cells)
                && shadow_into(&pose.position, o, &mut self.hull)
            {
                self.shadows
                    .fill_convex_polygon_rows(grid, &self.hull, Coverage::Outer, rows);
                shadowed = Some(shadowed.map_or(rows, |(a, b)| (a.min(rows.0), b.max(rows.1))));
            }
        }
        let (r0, r1) = footprint.rows;
        for y in r0..=r1 {
            let (v, s) = (self.visible.row_mut(y), self.shadows.row(y));
            for ((out, v), s) in seen.row_mut(y).iter_mut().zip(v.iter_mut()).zip(s) {
                *out |= *v & !s;
                *v = 0;
            }
        }
        if let Some((a, b)) = shadowed {
            for y in a..=b.min(grid.ny.saturating_sub(1)) {
                self.shadows.row_mut(y).fill(0);
            }
        }
    }
}

/// What [`GroundPredictor::relevant_footprint`] rasterised.
struct Footprint {
    /// The rows written (to clear afterwards).
    rows: (u32, u32),
    /// The footprint's bounding box.
    fov_box: Rect,
    /// Where the relevant visible cells are.
    cells: CellWindow,
}

/// The rows and columns the cells of a set lie in, and how many there are.
#[derive(Clone, Copy, Debug)]
struct CellWindow {
    rows: (u32, u32),
    columns: (u32, u32),
    count: u64,
}

impl CellWindow {
    const EMPTY: Self = Self {
        rows: (u32::MAX, 0),
        columns: (u32::MAX, 0),
        count: 0,
    };

    /// Every cell of `grid` (its count left at 0).
    fn whole(grid: &GroundGrid) -> Self {
        Self {
            rows: (0, grid.ny.saturating_sub(1)),
            columns: (0, grid.nx.saturating_sub(1)),
            count: 0,
        }
    }

    /// Takes in word `w` of row `y`.
    fn add_word(&mut self, y: u32, w: usize, word: u64) {
        if word == 0 {
            return;
        }
        let base = w as u32 * 64;
        self.rows = (self.rows.0.min(y), self.rows.1.max(y));
        self.columns = (
            self.columns.0.min(base + word.trailing_zeros()),
            self.columns.1.max(base + 63 - word.leading_zeros()),
        );
        self.count += u64::from(word.count_ones());
    }

    /// The window's cells on `grid`, widened by a cell on every side (so that rounding cannot
    /// make a box that misses it touch one of its cells).
    fn rect(&self, grid: &GroundGrid) -> Rect {
        let d = grid.cell_m;
        let at = |o: f64, k: u32| o + f64::from(k) * d;
        Rect {
            min: Point2::new(
                at(grid.origin.x, self.columns.0) - d,
                at(grid.origin.y, self.rows.0) - d,
            ),
            max: Point2::new(
                at(grid.origin.x, self.columns.1) + 2.0 * d,
                at(grid.origin.y, self.rows.1) + 2.0 * d,
            ),
        }
    }
}

/// Whether two poses are the same, bit for bit (so that everything predicted from one holds
/// for the other).
pub(super) fn same_pose(a: &CameraPose, b: &CameraPose) -> bool {
    let bits = |p: &CameraPose| [p.position.x, p.position.y, p.position.z, p.yaw].map(f64::to_bits);
    bits(a) == bits(b)
}

/// The obstacles, tallest first: the predicted views are the same in any order (a union of
/// shadows is taken away), but tall buildings cast the long shadows that cover those of the
/// low ones, so that more of the low ones are skipped as changing nothing.
pub fn tallest_first(obstacles: &[ObstacleCell]) -> Vec<ObstacleCell> {
    let mut sorted = obstacles.to_vec();
    sorted.sort_by(|a, b| b.height_m.total_cmp(&a.height_m));
    sorted
}

/// The first and last rows where the outer raster of a polygon whose vertices lie in
/// `bounds` may hold a cell of `visible` not yet in `shadows`: `None` when it holds none, every
/// row when it cannot tell (non-finite bounds).
///
/// The raster's cells lie in the cells touching `bounds` widened by the rasteriser's margin
/// (about `1e-9 * (1 + |coordinates|)`) and by the rounding of its edge clipping (a few ulps);
/// widening by `1e-6 * (1 + |coordinates|)` bounds both, so the rows left out are exact.
fn rows_to_cover(
    grid: &GroundGrid,
    bounds: &Rect,
    visible: &CellSet,
    shadows: &CellSet,
    cells: &CellWindow,
) -> Option<(u32, u32)> {
    let scale = [bounds.min, bounds.max, grid.origin, grid.bounds().max]
        .iter()
        .fold(0.0_f64, |m, p| m.max(p.x.abs()).max(p.y.abs()));
    if !scale.is_finite() {
        return Some((0, u32::MAX));
    }
    let slack = 1e-6 * (1.0 + scale);
    let (Some((x0, x1)), Some((y0, y1))) = (
        grid.columns_touching(bounds.min.x - slack, bounds.max.x + slack),
        grid.rows_touching(bounds.min.y - slack, bounds.max.y + slack),
    ) else {
        return None;
    };
    // Outside the window of the visible cells there is nothing to cover.
    let (x0, x1) = (x0.max(cells.columns.0), x1.min(cells.columns.1));
    let (y0, y1) = (y0.max(cells.rows.0), y1.min(cells.rows.1));
    if x0 > x1 || y0 > y1 {
        return None;
    }
    let (w0, w1) = (x0 as usize / 64, x1 as usize / 64);
    let uncovered = |&y: &u32| {
        let (v, s) = (visible.row(y), shadows.row(y));
        (w0..=w1).any(|w| {
            let lo = if w == w0 {
                u64::MAX << (x0 % 64)
            } else {
                u64::MAX
            };
            let hi = if w == w1 {
                u64::MAX >> (63 - x1 % 64)
            } else {
                u64::MAX
            };
            v[w] & !s[w] & lo & hi != 0
        })
    };
    let first = (y0..=y1).find(uncovered)?;
    let last = (first..=y1).rev().find(uncovered)?;
    Some((first, last))
}

/// Whether a known obstacle blocks the segment from `eye` to the ground point `target`
/// (slab test of the segment against each obstacle's box `rect x [0, height]`).
pub fn hidden_by(eye: &Point3, target: &Point2, obstacles: &[ObstacleCell]) -> bool {
    let d = [target.x - eye.x, target.y - eye.y, -eye.z];
    let o = [eye.x, eye.y, eye.z];
    obstacles.iter().any(|ob| {
        let lo = [ob.rect.min.x, ob.rect.min.y, 0.0];
        let hi = [ob.rect.max.x, ob.rect.max.y, ob.height_m];
        let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
        for a in 0..3 {
            if d[a].abs() < 1e-12 {
                if o[a] < lo[a] || o[a] > hi[a] {
                    return false;
                }
            } else {
                let (mut ta, mut tb) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
                if ta > tb {
                    std::mem::swap(&mut ta, &mut tb);
                }
                t0 = t0.max(ta);
                t1 = t1.min(tb);
                if t0 > t1 {
                    return false;
                }
            }
        }
        true
    })
}

/// The ground point the camera's optical axis meets, or the camera's ground projection when
/// the axis does not reach the ground.
pub fn view_centre(model: &CameraModel, pose: &CameraPose) -> Point2 {
    let camera = Camera::new(*model, *pose);
    let axis = camera.ray(model.cols as f64 / 2.0, model.rows as f64 / 2.0);
    camera
        .ground_hit(&axis)
        .unwrap_or(Point2::new(pose.position.x, pose.position.y))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use protocol::scenario::Scenario;

    /// [`add_visible_ground`] rasterising in full every shadow whose box meets the field of
    /// view's.
    fn add_visible_ground_every_shadow(
        seen: &mut CellSet,
        grid: &GroundGrid,
        model: &CameraModel,
        pose: &CameraPose,
        obstacles: &[ObstacleCell],
    ) {
        let camera = Camera::new(*model, *pose);
        let Some(footprint) = camera.image_ground_footprint() else {
            return;
        };
        let mut visible = CellSet::empty(grid);
        visible.fill_convex_polygon(grid, &footprint, Coverage::Inner);
        let fov_box = bbox(&footprint);
        let mut shadows = CellSet::empty(grid);
        for o in obstacles {
            if shadow_bounds(&pose.position, o).is_some_and(|b| overlaps(&b, &fov_box))
                && let Some(hull) = shadow(&pose.position, o)
            {
                shadows.fill_convex_polygon(grid, &hull, Coverage::Outer);
            }
        }
        visible.and_not_assign(&shadows);
        seen.or_assign(&visible);
    }

    fn obstacle_strategy() -> impl Strategy<Value = ObstacleCell> {
        // 5 m cells of a 300 m region or packed in its middle (where shadows overlap), some
        // of them taller than the UAVs fly.
        let cell = prop_oneof![-30i32..30, -6i32..6];
        (cell.clone(), cell, 5.0f64..90.0).prop_map(|(x, y, height_m)| {
            let min = Point2::new(x as f64 * 5.0, y as f64 * 5.0);
            ObstacleCell {
                rect: Rect {
                    min,
                    max: Point2::new(min.x + 5.0, min.y + 5.0),
                },
                height_m,
            }
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// Skipping the shadows, and the rows of shadows, that can only cover cells already
        /// shadowed or not visible changes no cell.
        #[test]
        fn skipped_shadows_change_nothing(
            x in -100.0f64..100.0,
            y in -100.0f64..100.0,
            z in 20.0f64..80.0,
            yaw in -4.0f64..4.0,
            obstacles in proptest::collection::vec(obstacle_strategy(), 0..120),
        ) {
            let mut s = Scenario::default();
            s.region.half_extent_m = 150.0;
            let model = s.camera_model();
            let grid = super::super::CoarseGrid::new(s.grid()).coarse;
            let pose = CameraPose {
                position: Point3::new(x, y, z),
                yaw,
            };
            let mut fast = CellSet::empty(&grid);
            add_visible_ground(&mut fast, &grid, &model, &pose, &obstacles);
            let mut reference = CellSet::empty(&grid);
            add_visible_ground_every_shadow(&mut reference, &grid, &model, &pose, &obstacles);
            prop_assert_eq!(fast, reference);
        }

        /// The predictor adds exactly the relevant cells of the full prediction, pose after
        /// pose with the same buffers (so nothing is left over from a previous pose), and so
        /// does one that remembers the footprints, looking at the same poses again.
        #[test]
        fn the_predictor_adds_the_relevant_part_of_the_view(
            poses in proptest::collection::vec(
                (-100.0f64..100.0, -100.0f64..100.0, 20.0f64..80.0, -4.0f64..4.0),
                1..5,
            ),
            discs in proptest::collection::vec((-150.0f64..150.0, -150.0f64..150.0, 0.0f64..80.0), 0..4),
            obstacles in proptest::collection::vec(obstacle_strategy(), 0..120),
        ) {
            let mut s = Scenario::default();
            s.region.half_extent_m = 150.0;
            let model = s.camera_model();
            let grid = super::super::CoarseGrid::new(s.grid()).coarse;
            let mut relevant = CellSet::empty(&grid);
            for (x, y, r) in discs {
                relevant.fill_disc(&grid, Point2::new(x, y), r, Coverage::Outer);
            }
            let mut predictor = GroundPredictor::new(&grid);
            let mut remembering = GroundPredictor::remembering_footprints(&grid);
            // Every pose twice: the remembering predictor's second look is from memory.
            for (x, y, z, yaw) in poses.iter().chain(&poses).copied() {
                let pose = CameraPose {
                    position: Point3::new(x, y, z),
                    yaw,
                };
                let mut within = CellSet::empty(&grid);
                predictor.add_visible_ground_within(
                    &mut within, &grid, &model, &pose, &obstacles, &relevant,
                );
                let mut reference = CellSet::empty(&grid);
                add_visible_ground(&mut reference, &grid, &model, &pose, &obstacles);
                reference.and_assign(&relevant);
                prop_assert_eq!(&within, &reference);
                let mut remembered = CellSet::empty(&grid);
                remembering.add_visible_ground_within(
                    &mut remembered, &grid, &model, &pose, &obstacles, &relevant,
                );
                prop_assert_eq!(&remembered, &reference);
                let (mut footprint, mut footprint_remembered) =
                    (CellSet::empty(&grid), CellSet::empty(&grid));
                predictor.add_footprint_within(&mut footprint, &grid, &model, &pose, &relevant);
                remembering.add_footprint_within(
                    &mut footprint_remembered, &grid, &model, &pose, &relevant,
                );
                prop_assert_eq!(&footprint_remembered, &footprint);
                prop_assert!(reference.is_subset_of(&footprint));
            }
        }
    }

    #[test]
    fn shadow_points_away_from_the_eye() {
        let o = ObstacleCell {
            rect: Rect {
                min: Point2::new(10.0, 0.0),
                max: Point2::new(15.0, 5.0),
            },
            height_m: 20.0,
        };
        let eye = Point3::new(0.0, 2.5, 100.0);
        let s = shadow(&eye, &o).unwrap();
        let far = s.iter().map(|p| p.x).fold(f64::MIN, f64::max);
        // The top's far edge at x = 15 projects to 15 * 100 / 80 = 18.75.
        assert!((far - 18.75).abs() < 1e-9);
        assert!(shadow(&Point3::new(0.0, 0.0, 10.0), &o).is_none());
        // The cheap box is the hull's box, to rounding.
        let b = shadow_bounds(&eye, &o).unwrap();
        let h = bbox(&s);
        for (x, y) in [
            (b.min.x, h.min.x),
            (b.min.y, h.min.y),
            (b.max.x, h.max.x),
            (b.max.y, h.max.y),
        ] {
            assert!((x - y).abs() < 1e-9, "{b:?} {h:?}");
        }
        // Behind the building, seen from the eye: hidden; in front of it: not.
        assert!(hidden_by(&eye, &Point2::new(17.0, 2.5), &[o]));
        assert!(!hidden_by(&eye, &Point2::new(5.0, 2.5), &[o]));
        assert!(!hidden_by(&eye, &Point2::new(17.0, 30.0), &[o]));
    }
}
