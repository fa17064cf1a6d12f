//! Buildings: the generated city's axis-aligned boxes, standing on the ground inside the blocks
//! of the road grid, and an imported city's footprints cut into convex parts.

use std::sync::Arc;

use rand::Rng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use sets::math::{Point2, Point3, Real};

use super::roads::RoadGrid;
use crate::error::WorldBuildError;
use crate::render::prism::Prism;

/// Gap between neighbouring lots of a block.
const LOT_GAP_M: Real = 3.0;
/// Smallest side of a lot worth building on.
const MIN_LOT_SIDE_M: Real = 2.0;
/// Smallest share of a lot's side a building takes in the first pass.
const MIN_SIDE_SHARE: Real = 0.45;

/// A building standing on the ground, up to `height`: the box over `[min, max]` (a generated
/// building), or the union of convex upright prisms `parts` (an imported one, whose bounding
/// box is `[min, max]`).
#[derive(Clone, Debug, PartialEq)]
pub struct Building {
    /// South-west corner of the footprint (of its bounding box, for parts).
    pub min: Point2,
    /// North-east corner of the footprint (of its bounding box, for parts).
    pub max: Point2,
    /// Height of the roof, metres.
    pub height: Real,
    /// The convex parts that tile an imported footprint, each up to `height`; empty for a box.
    pub parts: Vec<Arc<Prism>>,
}

impl Building {
    /// The box over `[min, max]` up to `height`.
    pub fn boxed(min: Point2, max: Point2, height: Real) -> Building {
        Building {
            min,
            max,
            height,
            parts: Vec::new(),
        }
    }

    /// The building whose footprint the convex counter-clockwise `parts` tile, up to `height`
    /// (none if `parts` is empty).
    pub fn from_parts(parts: Vec<Vec<Point2>>, height: Real) -> Option<Building> {
        let corners = parts.iter().flatten();
        let min = corners
            .clone()
            .copied()
            .reduce(|a, b| Point2::new(a.x.min(b.x), a.y.min(b.y)))?;
        let max = corners
            .copied()
            .reduce(|a, b| Point2::new(a.x.max(b.x), a.y.max(b.y)))?;
        Some(Building {
            min,
            max,
            height,
            parts: Prism::building(parts, height)
                .into_iter()
                .map(Arc::new)
                .collect(),
        })
    }

    /// The footprint as convex counter-clockwise polygons: the box's rectangle, or the parts.
    pub fn footprint(&self) -> Vec<Vec<Point2>> {
        if self.parts.is_empty() {
            let (a, b) = (self.min, self.max);
            vec![vec![a, Point2::new(b.x, a.y), b, Point2::new(a.x, b.y)]]
        } else {
            self.parts.iter().map(|p| p.footprint.clone()).collect()
        }
    }

    /// The footprint's outline as segments: the box's four sides, or the parts' edges that no
    /// other part shares.
    pub fn outline(&self) -> Vec<(Point2, Point2)> {
        if self.parts.is_empty() {
            let f = &self.footprint()[0];
            return (0..4).map(|i| (f[i], f[(i + 1) % 4])).collect();
        }
        (self.parts.iter())
            .flat_map(|part| part.outline_edges())
            .collect()
    }

    /// Footprint area, m².
    pub fn area(&self) -> Real {
        if self.parts.is_empty() {
            return (self.max.x - self.min.x) * (self.max.y - self.min.y);
        }
        self.parts
            .iter()
            .map(|p| {
                let f = &p.footprint;
                let n = f.len();
                (0..n)
                    .map(|i| f[i].coords.perp(&f[(i + 1) % n].coords))
                    .sum::<Real>()
                    / 2.0
            })
            .sum()
    }

    /// Horizontal distance from a ground point to the footprint (0 inside).
    pub fn footprint_distance(&self, p: &Point2) -> Real {
        if self.parts.is_empty() {
            let dx = (self.min.x - p.x).max(p.x - self.max.x).max(0.0);
            let dy = (self.min.y - p.y).max(p.y - self.max.y).max(0.0);
            return dx.hypot(dy);
        }
        let ground = Point3::new(p.x, p.y, 0.0);
        self.parts
            .iter()
            .map(|part| part.nearest_distance(&ground))
            .fold(Real::INFINITY, Real::min)
    }

    /// Whether a ground point lies on the footprint (its border included).
    pub fn covers(&self, p: &Point2) -> bool {
        let in_box =
            p.x >= self.min.x && p.x <= self.max.x && p.y >= self.min.y && p.y <= self.max.y;
        in_box && (self.parts.is_empty() || self.parts.iter().any(|part| part.contains(p)))
    }

    /// Centre of the box (of the bounding box, for parts).
    pub fn centre(&self) -> Point3 {
        Point3::new(
            (self.min.x + self.max.x) / 2.0,
            (self.min.y + self.max.y) / 2.0,
            self.height / 2.0,
        )
    }

    /// Half extents of the box (of the bounding box, for parts).
    pub fn half_extents(&self) -> [Real; 3] {
        [
            (self.max.x - self.min.x) / 2.0,
            (self.max.y - self.min.y) / 2.0,
            self.height / 2.0,
        ]
    }
}

/// A rectangle of a block where one building may stand.
#[derive(Clone, Copy, Debug)]
struct Lot {
    min: Point2,
    max: Point2,
}

impl Lot {
    fn area(&self) -> Real {
        (self.max.x - self.min.x) * (self.max.y - self.min.y)
    }
}

/// Places buildings covering `fraction` of the ground area `ground_area` (to rounding), with
/// heights uniform in `heights`, one at most per lot of about `lot_size` metres a side
/// (`region.lot_size_m`), every footprint at least the grid's building setback from every road
/// centreline.
pub fn generate(
    grid: &RoadGrid,
    ground_area: Real,
    fraction: Real,
    heights: [Real; 2],
    lot_size: Real,
    rng: &mut ChaCha8Rng,
) -> Result<Vec<Building>, WorldBuildError> {
    let wanted = fraction * ground_area;
    if wanted <= 0.0 {
        return Ok(Vec::new());
    }
    let mut lots = lots(grid, lot_size);
    let capacity: Real = lots.iter().map(Lot::area).sum();
    if wanted > capacity {
        return Err(WorldBuildError::Placement(format!(
            "region.building_fraction = {fraction} needs {wanted:.0} m² of buildings but the \
             blocks hold at most {capacity:.0} m² ({:.3} of the ground)",
            capacity / ground_area
        )));
    }
    lots.shuffle(rng);

    // First pass: a random building per lot until the area is reached, the last one shrunk
    // to land on it.
    let mut placed: Vec<(Building, Lot)> = Vec::new();
    let mut total = 0.0;
    for lot in &lots {
        if total >= wanted {
            break;
        }
        let (lw, lh) = (lot.max.x - lot.min.x, lot.max.y - lot.min.y);
        let mut w = lw * rng.random_range(MIN_SIDE_SHARE..=1.0);
        let mut h = lh * rng.random_range(MIN_SIDE_SHARE..=1.0);
        let rest = wanted - total;
        if w * h > rest {
            let k = (rest / (w * h)).sqrt();
            w *= k;
            h *= k;
        }
        let x0 = lot.min.x + rng.random_range(0.0..=1.0) * (lw - w);
        let y0 = lot.min.y + rng.random_range(0.0..=1.0) * (lh - h);
        let height = rng.random_range(heights[0]..=heights[1]);
        let b = Building::boxed(Point2::new(x0, y0), Point2::new(x0 + w, y0 + h), height);
        total += b.area();
        placed.push((b, *lot));
    }

    // Second pass, for large fractions: grow buildings toward their whole lot.
    let mut i = 0;
    while wanted - total > 1e-6 * wanted && i < placed.len() {
        let (b, lot) = (placed[i].0.clone(), placed[i].1);
        let grown = |t: Real| {
            Building::boxed(
                b.min + (lot.min - b.min) * t,
                b.max + (lot.max - b.max) * t,
                b.height,
            )
        };
        let full_gain = lot.area() - b.area();
        let need = wanted - total;
        let t = if full_gain <= need {
            1.0
        } else {
            // Area grows monotonically with t: bisect for the exact remainder.
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..60 {
                let mid = (lo + hi) / 2.0;
                if grown(mid).area() - b.area() < need {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            hi
        };
        let g = grown(t);
        total += g.area() - b.area();
        placed[i].0 = g;
        i += 1;
    }
    Ok(placed.into_iter().map(|(b, _)| b).collect())
}

/// Every lot of every block, in a fixed order.
fn lots(grid: &RoadGrid, lot_size: Real) -> Vec<Lot> {
    let setback = grid.profile.building_setback();
    let mut out = Vec::new();
    for wx in grid.xs.windows(2) {
        for wy in grid.ys.windows(2) {
            let (x0, x1) = (wx[0] + setback, wx[1] - setback);
            let (y0, y1) = (wy[0] + setback, wy[1] - setback);
            for (ax0, ax1) in split(x0, x1, lot_size) {
                for (ay0, ay1) in split(y0, y1, lot_size) {
                    out.push(Lot {
                        min: Point2::new(ax0, ay0),
                        max: Point2::new(ax1, ay1),
                    });
                }
            }
        }
    }
    out
}

/// Cuts `[a, b]` into lots of about `lot_size` separated by [`LOT_GAP_M`].
fn split(a: Real, b: Real, lot_size: Real) -> Vec<(Real, Real)> {
    let len = b - a;
    if len < MIN_LOT_SIDE_M {
        return Vec::new();
    }
    let n = ((len + LOT_GAP_M) / (lot_size + LOT_GAP_M))
        .round()
        .max(1.0) as usize;
    let side = (len - (n - 1) as Real * LOT_GAP_M) / n as Real;
    if side < MIN_LOT_SIDE_M {
        return vec![(a, b)];
    }
    (0..n)
        .map(|i| {
            let s = a + i as Real * (side + LOT_GAP_M);
            (s, (s + side).min(b))
        })
        .collect()
}
