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
//!    pixel); U otherwise, and for other UAVs.
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
use sets::math::{Point3, Real, Vector3};

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
                object: *o,
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
            classify(&codes, touching(), visible)
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

/// Rule 3: the label of a pixel from its 5 ray codes and the objects touching it.
fn classify<'a>(
    codes: &[u32; 5],
    mut touching: impl Iterator<Item = &'a Entry>,
    visible: &[Visible],
) -> Label {
    let first = codes[0];
    if codes.iter().any(|&c| c != first) {
        return Label::Unknown;
    }
    if first == HIT_GROUND {
        return if touching.next().is_none() {
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
    let clear = touching.all(|e| e.visible == first || visible[e.visible as usize].nearest > limit);
    if clear { label } else { Label::Unknown }
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
}
