//! Rendering a CVS frame (docs/design.md §3): depth, labels and target boxes of one camera, with
//! the paper's assumptions holding by construction.
//!
//! 1. Every object's box is projected exactly into the image ([`footprint`]): per row, the
//!    span of pixels its silhouette touches. Those are the only pixels it can appear in.
//! 2. A ray is cast through every pixel corner (shared between neighbours) and every pixel
//!    centre; each ray is tested against the analytic ground `z = 0` and against only the
//!    objects whose footprint touches the pixels around it, with parry3d's arithmetic
//!    ([`objects::SeenFrom`]). A ray no footprint touches (most of them) meets only the
//!    ground: a centre ray needs only the vertical component of its unit direction and its
//!    range, a corner ray only whether it points down ([`rays`]).
//! 3. A pixel is G when its 5 rays hit the ground and no footprint touches it; T (O) when its 5
//!    rays hit the same target (building) and every other object whose footprint touches it is
//!    entirely farther than that object's farthest corner (nothing can then stand in front of
//!    it inside the pixel, and its convex silhouette, containing the 4 corners, covers the
//!    pixel); U otherwise, and for other UAVs. An imported building is several convex prisms
//!    ([`prism`]) of one [`ObjectKind::Obstacle`]: a part of the same building in front of the
//!    one hit is still that building, and a pixel whose rays hit different parts is O when its
//!    section by the roof's plane lies inside the building's outline (`roof_covers`).
//! 4. Classifier doubt turns a random share of pixels U; depth is the range of the pixel's
//!    depth ray times `1 + w`, `w` uniform in the noise bounds, NaN (and the pixel U) when
//!    that ray hits nothing or starts inside a box. The depth ray is the centre ray, or with
//!    `camera.depth_ray = "random"` the ray through a seeded random point of the pixel
//!    ([`noise::RowRayPoints`]): the paper's eq. (5) leaves the ray unknown, and the estimator
//!    must not rely on it. A G, T or O pixel is seen whole (rule 3), so any of its rays hits
//!    what its label says.
//! 5. A target is identified when enough pixels are labelled T with it; its box bounds every
//!    pixel any of whose rays hit it.
//!
//! Rows are rendered in parallel on the current rayon pool; each row draws its noise from its
//! own seeded generator, so the frame is the same bits on any number of threads.

pub mod boxes;
pub mod footprint;
pub mod noise;
pub mod objects;
pub mod prism;
pub mod rays;
#[cfg(test)]
mod reference;

use protocol::camera::{Camera, CameraModel};
use protocol::frame::{CvsFrame, FRAME_MAX_BOXES, FRAME_MAX_PIXELS, Label, TargetBox};
use protocol::scenario::DepthRay;
use rayon::prelude::*;
use sets::math::{Point2, Point3, Real, Vector3};

use boxes::RowTargets;
use footprint::Footprint;
use noise::{RowNoise, RowRayPoints};
pub use objects::{ObjectKind, SceneObject, SeenFrom};
use rays::{RayGrid, RowOf, RowRays, UnitRays};

/// Code of a ray that hit the ground first.
const HIT_GROUND: u32 = u32::MAX - 1;
/// Code of a ray that hit nothing (above the horizon).
const HIT_NOTHING: u32 = u32::MAX;
/// Relative slack when comparing an occluder's nearest distance with an object's farthest.
const DISTANCE_SLACK: Real = 1e-9;

/// Everything about a frame that is not geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameSpec {
    /// Run tag for the header.
    pub run_tag: u64,
    /// Scenario seed (noise).
    pub seed: u64,
    /// Step index.
    pub step: u64,
    /// Simulated time, seconds.
    pub time_s: Real,
    /// UAV index.
    pub uav: u32,
    /// Multiplicative depth noise bounds `[w_lo, w_hi]`.
    pub depth_noise: [Real; 2],
    /// Share of pixels turned U at random.
    pub unknown_fraction: Real,
    /// T pixels needed to identify a target.
    pub min_pixels: u32,
    /// The ray of each pixel its depth is measured along.
    pub depth_ray: DepthRay,
}

/// An object the camera may see, with its footprint and distances from the camera.
struct Visible {
    object: SceneObject,
    seen: SeenFrom,
    footprint: Footprint,
    nearest: Real,
    farthest: Real,
}

/// An object touching a row (or, for corner rows, the corners around it): inclusive span.
#[derive(Clone, Copy)]
struct Entry {
    visible: u32,
    c0: u32,
    c1: u32,
}

/// Rays a frame of `rows x cols` casts: every corner and every centre.
pub fn rays_per_frame(rows: u32, cols: u32) -> u64 {
    (rows as u64 + 1) * (cols as u64 + 1) + rows as u64 * cols as u64
}

/// Renders `camera`'s view of the ground and `objects` into `frame`, in place.
///
/// The caller guarantees `rows * cols <= FRAME_MAX_PIXELS` (the world checks its scenario);
/// a larger camera renders an empty frame with `rows = cols = 0`.
pub fn render(camera: &Camera, objects: &[SceneObject], spec: &FrameSpec, frame: &mut CvsFrame) {
    let (rows, cols) = frame_size(camera);
    let origin = camera.origin();
    let grid = RayGrid::new(&Camera::new(
        CameraModel {
            rows,
            cols,
            ..camera.model
        },
        camera.pose,
    ));
    let visible = visible_objects(camera, objects, &origin);
    let row_entries = row_entries(&visible, rows);
    let view = View {
        origin,
        grid: &grid,
        visible: &visible,
        row_entries: &row_entries,
        rows,
        cols,
    };
    let corners = corner_codes(&view);
    let row_targets = centre_rows(&view, &corners, spec, frame);
    let found: Vec<TargetBox> = boxes::identified(&row_targets, spec.min_pixels);
    write_header(frame, camera, spec, (rows, cols), &found);
}

/// The image size `render` draws: the camera's, or `0 x 0` for a camera larger than a frame.
fn frame_size(camera: &Camera) -> (u32, u32) {
    let (rows, cols) = (camera.model.rows, camera.model.cols);
    let fits = rows as usize * cols as usize <= FRAME_MAX_PIXELS;
    if fits { (rows, cols) } else { (0, 0) }
}

/// Rule 1: the objects whose box projects into the image, with their footprints and
/// distances from the camera at `origin`.
fn visible_objects(camera: &Camera, objects: &[SceneObject], origin: &Point3) -> Vec<Visible> {
    objects
        .iter()
        .filter_map(|o| {
            let fp = footprint::footprint(camera, o)?;
            Some(Visible {
                object: o.clone(),
                seen: o.seen_from(origin),
                footprint: fp,
                nearest: o.nearest_distance(origin),
                farthest: o.farthest_distance(origin),
            })
        })
        .collect()
}

/// Per pixel row of `rows`, the objects of `visible` whose footprint touches it, with their
/// spans.
fn row_entries(visible: &[Visible], rows: u32) -> Vec<Vec<Entry>> {
    (0..rows)
        .map(|r| {
            visible
                .iter()
                .enumerate()
                .filter_map(|(i, v)| {
                    let (c0, c1) = v.footprint.span(r)?;
                    Some(Entry {
                        visible: i as u32,
                        c0,
                        c1,
                    })
                })
                .collect()
        })
        .collect()
}

/// What the two passes of [`render`] cast their rays at: the camera's rays, the objects in
/// view and, per pixel row, those touching it.
struct View<'a> {
    origin: Point3,
    grid: &'a RayGrid,
    visible: &'a [Visible],
    row_entries: &'a [Vec<Entry>],
    rows: u32,
    cols: u32,
}

/// Pass 1: the code of every corner ray, `rows + 1` rows of `cols + 1`. Corner (R, C) borders
/// pixels R-1..=R x C-1..=C; an object touching pixel columns c0..=c1 of those rows can be hit
/// by corners c0..=c1 + 1.
fn corner_codes(view: &View<'_>) -> Vec<u32> {
    let View {
        origin,
        grid,
        visible,
        row_entries,
        rows,
        cols,
    } = *view;
    let corner_cols = cols as usize + 1;
    let mut corners = vec![HIT_NOTHING; (rows as usize + 1) * corner_cols];
    if rows > 0 {
        corners
            .par_chunks_mut(corner_cols)
            .enumerate()
            .for_each_init(Scratch::default, |scratch, (r, out)| {
                let r = r as u32;
                let entries = corner_row_entries(row_entries, r, rows);
                let touching = |c: u32| entries.iter().filter(move |e| e.c0 <= c && c <= e.c1);
                scratch.touched.clear();
                for (c, code) in out.iter_mut().enumerate() {
                    let c = c as u32;
                    if touching(c).next().is_some() {
                        scratch.touched.push(c);
                    } else {
                        // `cast` without candidates, from the sign of the unit ray's z.
                        *code = if origin.z > 0.0 && grid.corner_descends(r, c) {
                            HIT_GROUND
                        } else {
                            HIT_NOTHING
                        };
                    }
                }
                for run in runs(&scratch.touched) {
                    grid.unit_rays(RowOf::Corners(r), run, &mut scratch.rays);
                }
                for &c in &scratch.touched {
                    let (dir, inv) = scratch.rays.get(c);
                    out[c as usize] = cast(&origin, (&dir, &inv), touching(c), visible).0;
                }
            });
    }
    corners
}

/// Pass 2: the centre rays, labels, depth and target hits of every pixel row into `frame`,
/// rows in parallel; the target hits of each row.
fn centre_rows(
    view: &View<'_>,
    corners: &[u32],
    spec: &FrameSpec,
    frame: &mut CvsFrame,
) -> Vec<RowTargets> {
    let n = view.rows as usize * view.cols as usize;
    let width = view.cols.max(1) as usize;
    frame.depth[..n]
        .par_chunks_mut(width)
        .zip(frame.labels[..n].par_chunks_mut(width))
        .enumerate()
        .map_init(Scratch::default, |scratch, (r, (depth, labels))| {
            centre_row(view, corners, spec, scratch, r as u32, depth, labels)
        })
        .collect()
}

/// Pass 2 on pixel row `r`: its centre rays cast, each pixel labelled (rules 3 and 4) from its
/// 5 ray codes with the corner rows around it, its depth drawn with the row's noise, into
/// `depth` and `labels`; returns the row's target hits.
#[inline]
fn centre_row(
    view: &View<'_>,
    corners: &[u32],
    spec: &FrameSpec,
    scratch: &mut Scratch,
    r: u32,
    depth: &mut [f32],
    labels: &mut [u8],
) -> RowTargets {
    let View {
        origin,
        grid,
        visible,
        row_entries,
        cols,
        ..
    } = *view;
    let corner_cols = cols as usize + 1;
    grid.centre_row(r, origin.z, &mut scratch.row);
    let mut noise = RowNoise::new(
        spec.seed,
        spec.step,
        spec.uav,
        r,
        spec.unknown_fraction,
        spec.depth_noise,
    );
    let mut ray_points = random_rays(spec, r);
    let entries = &row_entries[r as usize];
    let top = &corners[r as usize * corner_cols..(r as usize + 1) * corner_cols];
    let bottom = &corners[(r as usize + 1) * corner_cols..(r as usize + 2) * corner_cols];
    scratch.touched.clear();
    scratch
        .touched
        .extend((0..cols).filter(|&c| entries.iter().any(|e| e.c0 <= c && c <= e.c1)));
    for run in runs(&scratch.touched) {
        grid.unit_rays(RowOf::Centres(r), run, &mut scratch.rays);
    }
    let (row, rays) = (&scratch.row, &scratch.rays);
    let mut touched = scratch.touched.iter().peekable();
    let mut targets = RowTargets::default();
    for c in 0..cols {
        let ci = c as usize;
        let touching = || entries.iter().filter(move |e| e.c0 <= c && c <= e.c1);
        let untouched = touched.next_if_eq(&&c).is_none();
        let (centre, range) = if untouched {
            ground_only(&origin, row.z[ci], row.ground[ci])
        } else {
            let (dir, inv) = rays.get(c);
            cast(&origin, (&dir, &inv), touching(), visible)
        };
        let codes = [top[ci], top[ci + 1], bottom[ci + 1], bottom[ci], centre];
        let mut label = if untouched {
            // `classify` when no object touches the pixel.
            if codes.iter().all(|&code| code == HIT_GROUND) {
                Label::Ground
            } else {
                Label::Unknown
            }
        } else {
            let corners = || {
                [
                    grid.corner_ray(r, c),
                    grid.corner_ray(r, c + 1),
                    grid.corner_ray(r + 1, c + 1),
                    grid.corner_ray(r + 1, c),
                ]
            };
            let pixel = PixelRays {
                origin,
                corners: &corners,
            };
            classify(&codes, touching(), visible, &pixel)
        };

        let px = noise.next_pixel();
        let (depth_code, range) = match ray_points.as_mut() {
            None => (centre, range),
            Some(points) => {
                let dir = pixel_point_ray(grid, points, r, c);
                if untouched {
                    ground_only(&origin, dir.z, -origin.z / dir.z)
                } else {
                    cast(&origin, (&dir, &reciprocals(&dir)), touching(), visible)
                }
            }
        };
        // A zero range means the camera is inside a box (a UAV flown into a building
        // by an explicit altitude): nothing can be measured there.
        let measured = depth_code != HIT_NOTHING && range > 0.0;
        let doubted = (px.doubt || !measured) && label != Label::Unknown;
        // Most pixels see only the ground or the sky: no target to note.
        if codes.iter().any(|&code| code < HIT_GROUND) {
            for (k, &code) in codes.iter().enumerate() {
                if code >= HIT_GROUND || codes[..k].contains(&code) {
                    continue;
                }
                if let ObjectKind::Target(id) = visible[code as usize].object.kind {
                    targets.hit(id, c, label == Label::Target && !doubted);
                }
            }
        }
        if doubted {
            label = Label::Unknown;
        }
        labels[ci] = label as u8;
        depth[ci] = if measured {
            (range * (1.0 + px.w)) as f32
        } else {
            f32::NAN
        };
    }
    targets
}

/// The generator of row `r`'s depth-ray points, when depth is measured along random rays.
fn random_rays(spec: &FrameSpec, r: u32) -> Option<RowRayPoints> {
    (spec.depth_ray == DepthRay::Random)
        .then(|| RowRayPoints::new(spec.seed, spec.step, spec.uav, r))
}

/// The unit ray through the next random point of pixel `(r, c)`.
fn pixel_point_ray(grid: &RayGrid, points: &mut RowRayPoints, r: u32, c: u32) -> Vector3 {
    let (du, dv) = points.next_point();
    grid.ray(c as Real + du, r as Real + dv)
}

/// `[1 / dir.x, 1 / dir.y, 1 / dir.z]`, as [`RayGrid::unit_rays`] gives them.
fn reciprocals(dir: &Vector3) -> [Real; 3] {
    [1.0 / dir.x, 1.0 / dir.y, 1.0 / dir.z]
}

/// The header of a frame of `rows x cols` pixels drawn by `camera`, its boxes `found` (as many
/// as a frame holds) and its checksum.
fn write_header(
    frame: &mut CvsFrame,
    camera: &Camera,
    spec: &FrameSpec,
    (rows, cols): (u32, u32),
    found: &[TargetBox],
) {
    let origin = camera.origin();
    let h = &mut frame.header;
    h.run_tag = spec.run_tag;
    h.step = spec.step;
    h.time_s = spec.time_s;
    h.uav = spec.uav;
    h.rows = rows;
    h.cols = cols;
    h.box_count = found.len().min(FRAME_MAX_BOXES) as u32;
    h.camera_position = [origin.x, origin.y, origin.z];
    h.camera_yaw = camera.pose.yaw;
    h.camera_tilt = camera.model.tilt_rad;
    h.camera_aperture = camera.model.aperture_rad;
    h.depth_noise = spec.depth_noise;
    frame.boxes = [TargetBox::default(); FRAME_MAX_BOXES];
    for (slot, b) in frame.boxes.iter_mut().zip(found) {
        *slot = *b;
    }
    frame.header.checksum = frame.checksum();
}

/// The objects to test for corner row `r`: those touching pixel rows `r - 1` or `r`, their
/// spans merged and widened by one column.
fn corner_row_entries(row_entries: &[Vec<Entry>], r: u32, rows: u32) -> Vec<Entry> {
    let above: &[Entry] = if r > 0 {
        &row_entries[r as usize - 1]
    } else {
        &[]
    };
    let below: &[Entry] = if r < rows {
        &row_entries[r as usize]
    } else {
        &[]
    };
    let mut out: Vec<Entry> = Vec::with_capacity(above.len() + below.len());
    for e in above.iter().chain(below) {
        match out.iter_mut().find(|o| o.visible == e.visible) {
            Some(o) => {
                o.c0 = o.c0.min(e.c0);
                o.c1 = o.c1.max(e.c1 + 1);
            }
            None => out.push(Entry { c1: e.c1 + 1, ..*e }),
        }
    }
    out
}

/// The runs of consecutive values of an increasing list, as ranges.
fn runs(sorted: &[u32]) -> impl Iterator<Item = std::ops::Range<u32>> + '_ {
    let mut i = 0;
    std::iter::from_fn(move || {
        let start = *sorted.get(i)?;
        let mut end = start + 1;
        i += 1;
        while sorted.get(i) == Some(&end) {
            end += 1;
            i += 1;
        }
        Some(start..end)
    })
}

/// Buffers of one row, reused from row to row.
#[derive(Default)]
struct Scratch {
    /// Columns whose ray some footprint touches.
    touched: Vec<u32>,
    /// Their unit rays.
    rays: UnitRays,
    /// The row's centre rays.
    row: RowRays,
}

/// [`cast`] without candidates, from the vertical component `z` of the unit ray and its range
/// `ground = -origin.z / z` to the ground.
#[inline]
fn ground_only(origin: &Point3, z: Real, ground: Real) -> (u32, Real) {
    if z < 0.0 && origin.z > 0.0 {
        (HIT_GROUND, ground)
    } else {
        (HIT_NOTHING, Real::INFINITY)
    }
}

/// First hit of the unit ray `dir` from `origin` among the ground and the candidates:
/// (code, range). Ties go to the object, the side that labels the pixel U rather than G.
///
/// `ray` is the unit direction and the reciprocals of its components.
fn cast<'a>(
    origin: &Point3,
    (dir, inv): (&Vector3, &[Real; 3]),
    candidates: impl Iterator<Item = &'a Entry>,
    visible: &[Visible],
) -> (u32, Real) {
    let (mut code, mut best) = if dir.z < 0.0 && origin.z > 0.0 {
        (HIT_GROUND, -origin.z / dir.z)
    } else {
        (HIT_NOTHING, Real::INFINITY)
    };
    for e in candidates {
        let seen = &visible[e.visible as usize].seen;
        let t = if seen.is_square() {
            seen.cast_square(dir, inv, best)
        } else {
            seen.cast(dir, best)
        };
        if let Some(t) = t
            && t <= best
        {
            best = t;
            code = e.visible;
        }
    }
    (code, best)
}

/// The rays of one pixel that a label may need beyond its 5 codes: the camera's centre and,
/// computed only when asked, the unit rays through the pixel's 4 corners in the codes' order.
pub(crate) struct PixelRays<'a> {
    origin: Point3,
    corners: &'a dyn Fn() -> [Vector3; 4],
}

/// Rule 3: the label of a pixel from its 5 ray codes and the objects touching it.
///
/// The parts of one imported building (prisms of the same [`ObjectKind::Obstacle`]) count as
/// one building:
/// - when the 5 rays hit the same part, a sibling part in front of it inside the pixel is the
///   same building, so it does not stop the pixel being O;
/// - when they hit different parts, no one convex silhouette covers the pixel, and the pixel
///   is O only through its roof ([`roof_covers`]).
fn classify<'a>(
    codes: &[u32; 5],
    touching: impl Iterator<Item = &'a Entry> + Clone,
    visible: &[Visible],
    pixel: &PixelRays<'_>,
) -> Label {
    let first = codes[0];
    if codes.iter().any(|&c| c != first) {
        return if roof_covers(codes, touching, visible, pixel) {
            Label::Obstacle
        } else {
            Label::Unknown
        };
    }
    if first == HIT_GROUND {
        return if touching.clone().next().is_none() {
            Label::Ground
        } else {
            Label::Unknown
        };
    }
    if first == HIT_NOTHING {
        return Label::Unknown;
    }
    let hit = &visible[first as usize];
    let label = match hit.object.kind {
        ObjectKind::Target(_) => Label::Target,
        ObjectKind::Obstacle(_) => Label::Obstacle,
        ObjectKind::Uav(_) => return Label::Unknown,
    };
    let limit = hit.farthest * (1.0 + DISTANCE_SLACK) + DISTANCE_SLACK;
    let clear = touching.into_iter().all(|e| {
        let other = &visible[e.visible as usize];
        e.visible == first || sibling(other, hit) || other.nearest > limit
    });
    if clear { label } else { Label::Unknown }
}

/// Whether `a` and `b` are parts of the same imported building.
fn sibling(a: &Visible, b: &Visible) -> bool {
    matches!((a.object.kind, b.object.kind), (ObjectKind::Obstacle(x), ObjectKind::Obstacle(y)) if x == y)
        && a.object.as_prism().is_some()
        && b.object.as_prism().is_some()
}

/// Whether a pixel whose 5 rays hit different parts of one imported building sees only that
/// building's roof.
///
/// The rays through the pixel form a convex pyramid; the roof's plane `z = h` cuts it in the
/// convex quadrilateral `Q` whose corners are where the 4 corner rays meet that plane. With
/// the camera above the roof, every ray through the pixel meets the plane inside `Q`; if `Q`
/// lies inside the building's footprint, the first point of the building on that ray is on its
/// roof (nothing of it stands above `h`). `Q` lies inside the footprint when its corners do and
/// no edge of the footprint's outline meets it: a point of `Q` outside would be joined to a
/// corner by a segment crossing the outline. Every other object touching the pixel must then
/// be entirely farther than the building's parts that touch it, as in the single-object rule.
fn roof_covers<'a>(
    codes: &[u32; 5],
    touching: impl Iterator<Item = &'a Entry> + Clone,
    visible: &[Visible],
    pixel: &PixelRays<'_>,
) -> bool {
    if codes.iter().any(|&c| c >= HIT_GROUND) {
        return false;
    }
    let hit = &visible[codes[0] as usize];
    let (ObjectKind::Obstacle(_), Some(first)) = (hit.object.kind, hit.object.as_prism()) else {
        return false;
    };
    let h = first.height;
    if !codes
        .iter()
        .all(|&c| sibling(&visible[c as usize], hit) || c == codes[0])
    {
        return false;
    }
    let parts: Vec<&Visible> = touching
        .clone()
        .map(|e| &visible[e.visible as usize])
        .filter(|v| v.object.kind == hit.object.kind && v.object.as_prism().is_some())
        .collect();
    if pixel.origin.z <= h
        || parts
            .iter()
            .any(|v| v.object.as_prism().is_some_and(|p| p.height != h))
    {
        return false;
    }
    let o = pixel.origin;
    let mut quad = [Point2::origin(); 4];
    for (q, dir) in quad.iter_mut().zip((pixel.corners)()) {
        if dir.z >= 0.0 {
            return false;
        }
        let t = (h - o.z) / dir.z;
        *q = Point2::new(o.x + t * dir.x, o.y + t * dir.y);
    }
    let prisms = || parts.iter().filter_map(|v| v.object.as_prism());
    if !quad.iter().all(|q| prisms().any(|p| p.contains(q))) {
        return false;
    }
    if prisms().any(|p| {
        p.outline_edges()
            .any(|(a, b)| segment_meets_quad(&a, &b, &quad))
    }) {
        return false;
    }
    let farthest = parts.iter().map(|v| v.farthest).fold(0.0, Real::max);
    let limit = farthest * (1.0 + DISTANCE_SLACK) + DISTANCE_SLACK;
    touching.into_iter().all(|e| {
        let other = &visible[e.visible as usize];
        sibling(other, hit) || other.nearest > limit
    })
}

/// Whether the segment `a b` meets the convex quadrilateral `quad` (closed; either winding).
fn segment_meets_quad(a: &Point2, b: &Point2, quad: &[Point2; 4]) -> bool {
    let turn = |p: &Point2, q: &Point2, r: &Point2| (q - p).perp(&(r - p));
    let inside = |p: &Point2| {
        let sides: Vec<Real> = (0..4)
            .map(|i| turn(&quad[i], &quad[(i + 1) % 4], p))
            .collect();
        sides.iter().all(|&s| s >= 0.0) || sides.iter().all(|&s| s <= 0.0)
    };
    if inside(a) || inside(b) {
        return true;
    }
    (0..4).any(|i| {
        let (c, d) = (&quad[i], &quad[(i + 1) % 4]);
        let (d1, d2) = (turn(a, b, c), turn(a, b, d));
        let (d3, d4) = (turn(c, d, a), turn(c, d, b));
        d1 * d2 <= 0.0 && d3 * d4 <= 0.0
    })
}

#[cfg(test)]
mod tests {
    use protocol::camera::CameraPose;
    use protocol::scenario::Scenario;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::World;

    /// Asserts two frames equal bit for bit: header, boxes, depth (NaNs included), labels.
    fn assert_same(fast: &CvsFrame, reference: &CvsFrame, what: &str) {
        assert_eq!(fast.header, reference.header, "{what}: header");
        assert_eq!(fast.boxes, reference.boxes, "{what}: boxes");
        let n = reference.header.rows as usize * reference.header.cols as usize;
        let bits = |f: &CvsFrame| f.depth[..n].iter().map(|d| d.to_bits()).collect::<Vec<_>>();
        assert!(bits(fast) == bits(reference), "{what}: depth");
        assert!(fast.labels[..n] == reference.labels[..n], "{what}: labels");
    }

    /// A random viewpoint over (or in) the default city: mostly the fleet's heights and tilt,
    /// also low among the cars, inside a building, on or under the ground, and at tilts that
    /// show the horizon.
    fn camera(rng: &mut ChaCha8Rng, scenario: &Scenario, objects: &[SceneObject]) -> Camera {
        let h = scenario.region.half_extent_m;
        let mut position = Point3::new(
            rng.random_range(-h..h),
            rng.random_range(-h..h),
            [1.0, 3.0, 12.0, 30.0, 79.3, 95.0, 109.3, 140.0][rng.random_range(0..8)],
        );
        match rng.random_range(0..12) {
            0 => position.z = [0.0, -0.5][rng.random_range(0..2)],
            1 => {
                let inside = &objects[rng.random_range(0..objects.len())];
                position = Point3::from(inside.pose.translation.vector);
            }
            _ => {}
        }
        let mut model = scenario.camera_model();
        model.tilt_rad = match rng.random_range(0..4) {
            0 => rng.random_range(0.0..0.4),
            1 => rng.random_range(0.4..1.5),
            _ => model.tilt_rad,
        };
        let yaw = rng.random_range(-4.0..4.0);
        Camera::new(model, CameraPose { position, yaw })
    }

    #[test]
    fn frames_are_those_of_the_parry_reference_bit_for_bit() {
        let scenario = Scenario::default();
        let mut world = World::new(&scenario).unwrap_or_else(|e| panic!("{e}"));
        let mut rng = ChaCha8Rng::seed_from_u64(2024);
        let mut fast = CvsFrame::new_boxed();
        let mut reference = CvsFrame::new_boxed();
        let [mut target_px, mut obstacle_px, mut boxes, mut horizon_px] = [0usize; 4];
        for step in 0..=240 {
            if step % 60 == 0 {
                let objects = world.scene_objects(None);
                for k in 0..24 {
                    let camera = camera(&mut rng, &scenario, &objects);
                    let spec = FrameSpec {
                        run_tag: 5,
                        seed: scenario.seed,
                        step,
                        time_s: world.time_s(),
                        uav: k,
                        depth_noise: scenario.camera.depth_noise,
                        unknown_fraction: [0.0, 0.05][k as usize % 2],
                        min_pixels: scenario.camera.min_pixels,
                        depth_ray: [DepthRay::Centre, DepthRay::Random][k as usize / 2 % 2],
                    };
                    render(&camera, &objects, &spec, &mut fast);
                    reference::render(&camera, &objects, &spec, &mut reference);
                    assert_same(&fast, &reference, &format!("step {step}, {camera:?}"));
                    let n = camera.model.pixel_count();
                    let count =
                        |l: Label| fast.labels[..n].iter().filter(|&&x| x == l as u8).count();
                    target_px += count(Label::Target);
                    obstacle_px += count(Label::Obstacle);
                    boxes += fast.header.box_count as usize;
                    horizon_px += fast.depth[..n].iter().filter(|d| d.is_nan()).count();
                }
            }
            world.advance();
        }
        // The frames saw cars, buildings, identified boxes and the sky.
        assert!(target_px > 1_000, "{target_px} T pixels");
        assert!(obstacle_px > 100_000, "{obstacle_px} O pixels");
        assert!(boxes > 5, "{boxes} boxes");
        assert!(horizon_px > 100_000, "{horizon_px} pixels without depth");
    }

    /// Buildings in parts, as an import makes them: an L of two parts, a courtyard of four,
    /// a lone rectangle; two cars between them.
    fn parts_scene() -> Vec<SceneObject> {
        use std::sync::Arc;

        use super::prism::Prism;
        let p = |x: Real, y: Real| Point2::new(x, y);
        let rect = |x0: Real, y0: Real, x1: Real, y1: Real| {
            vec![p(x0, y0), p(x1, y0), p(x1, y1), p(x0, y1)]
        };
        let buildings: Vec<(Vec<Vec<Point2>>, Real)> = vec![
            // An L: a wing along x and a wing along y sharing the edge x = -30 ... -20 at y = -10.
            (
                vec![
                    rect(-40.0, -40.0, -10.0, -30.0),
                    vec![
                        p(-40.0, -30.0),
                        p(-30.0, -30.0),
                        p(-30.0, 0.0),
                        p(-40.0, 0.0),
                    ],
                ],
                25.0,
            ),
            // A courtyard: four wings around a 20 m square, cut along their corners' diagonals.
            (
                vec![
                    vec![p(10.0, 10.0), p(50.0, 10.0), p(40.0, 20.0), p(20.0, 20.0)],
                    vec![p(50.0, 10.0), p(50.0, 50.0), p(40.0, 40.0), p(40.0, 20.0)],
                    vec![p(50.0, 50.0), p(10.0, 50.0), p(20.0, 40.0), p(40.0, 40.0)],
                    vec![p(10.0, 50.0), p(10.0, 10.0), p(20.0, 20.0), p(20.0, 40.0)],
                ],
                18.0,
            ),
            (vec![rect(-40.0, 20.0, -20.0, 35.0)], 40.0),
        ];
        let mut objects = Vec::new();
        for (i, (parts, h)) in buildings.into_iter().enumerate() {
            for prism in Prism::building(parts, h) {
                objects.push(SceneObject::prism(
                    ObjectKind::Obstacle(i as u32),
                    Arc::new(prism),
                ));
            }
        }
        objects.push(SceneObject::new(
            ObjectKind::Target(0),
            Point3::new(0.0, -10.0, 0.75),
            [2.3, 0.9, 0.75],
            0.3,
        ));
        objects.push(SceneObject::new(
            ObjectKind::Target(1),
            Point3::new(30.0, 30.0, 0.75),
            [2.3, 0.9, 0.75],
            1.2,
        ));
        objects
    }

    /// The first thing the unit ray `dir` from `origin` meets: an object's kind, or `None` for
    /// the ground or the sky.
    fn first_hit(
        objects: &[SceneObject],
        origin: &Point3,
        dir: &Vector3,
    ) -> (Option<ObjectKind>, Option<usize>) {
        let mut best = if dir.z < 0.0 {
            -origin.z / dir.z
        } else {
            Real::INFINITY
        };
        let mut hit = (None, None);
        for (i, o) in objects.iter().enumerate() {
            if let Some(t) = o.cast(origin, dir, best)
                && t <= best
            {
                best = t;
                hit = (Some(o.kind), Some(i));
            }
        }
        hit
    }

    #[test]
    fn buildings_in_parts_render_as_the_reference_does_and_o_pixels_see_only_their_building() {
        let scenario = Scenario::default();
        let objects = parts_scene();
        let mut rng = ChaCha8Rng::seed_from_u64(43);
        let mut fast = CvsFrame::new_boxed();
        let mut reference = CvsFrame::new_boxed();
        let (mut obstacle_px, mut seam_px) = (0usize, 0usize);
        for k in 0..24u32 {
            let mut model = scenario.camera_model();
            model.rows = 120;
            model.cols = 160;
            model.tilt_rad = rng.random_range(0.5..1.5);
            let position = Point3::new(
                rng.random_range(-60.0..60.0),
                rng.random_range(-60.0..60.0),
                rng.random_range(45.0..120.0),
            );
            // Look toward the buildings.
            let yaw = (-position.y).atan2(-position.x) + rng.random_range(-0.5..0.5);
            let camera = Camera::new(model, CameraPose { position, yaw });
            let spec = FrameSpec {
                run_tag: 1,
                seed: 7,
                step: k as u64,
                time_s: 0.0,
                uav: k,
                depth_noise: [0.0, 0.0],
                unknown_fraction: 0.0,
                min_pixels: 5,
                depth_ray: [DepthRay::Centre, DepthRay::Random][k as usize % 2],
            };
            render(&camera, &objects, &spec, &mut fast);
            reference::render(&camera, &objects, &spec, &mut reference);
            assert_same(&fast, &reference, &format!("camera {k}"));
            // Every O pixel sees its building and nothing else: sample rays across it.
            let origin = camera.origin();
            for r in 0..model.rows {
                for c in 0..model.cols {
                    if fast.labels[(r * model.cols + c) as usize] != Label::Obstacle as u8 {
                        continue;
                    }
                    obstacle_px += 1;
                    let mut kinds = Vec::new();
                    let mut parts = Vec::new();
                    for i in 0..5 {
                        for j in 0..5 {
                            let dir = camera
                                .ray(c as Real + i as Real / 4.0, r as Real + j as Real / 4.0);
                            let (kind, part) = first_hit(&objects, &origin, &dir);
                            kinds.push(kind);
                            parts.push(part);
                        }
                    }
                    assert!(
                        matches!(kinds[0], Some(ObjectKind::Obstacle(_)))
                            && kinds.iter().all(|k| *k == kinds[0]),
                        "camera {k}, pixel ({r}, {c}): {kinds:?}"
                    );
                    parts.sort();
                    parts.dedup();
                    seam_px += usize::from(parts.len() > 1);
                }
            }
        }
        assert!(obstacle_px > 10_000, "{obstacle_px} O pixels");
        // Pixels across the seams between parts are O too.
        assert!(seam_px > 100, "{seam_px} O pixels across seams");
    }
}
