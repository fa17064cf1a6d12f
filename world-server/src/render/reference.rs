//! The renderer as it was before [`super::render`] cast its rays with [`SeenFrom`]: every
//! ray normalised and cast with parry3d against every object whose footprint touches it.
//! Kept as the reference the fast renderer must match bit for bit.
//!
//! [`SeenFrom`]: super::objects::SeenFrom

use protocol::camera::Camera;
use protocol::frame::{CvsFrame, FRAME_MAX_BOXES, FRAME_MAX_PIXELS, Label, TargetBox};
use protocol::math::{Point3, Real, Vector3};
use rayon::prelude::*;

use super::boxes::{self, RowTargets};
use super::footprint;
use super::noise::RowNoise;
use super::{
    Entry, FrameSpec, HIT_GROUND, HIT_NOTHING, ObjectKind, SceneObject, Visible, classify,
    corner_row_entries,
};

/// Renders `camera`'s view of the ground and `objects` into `frame`, in place.
///
/// The caller guarantees `rows * cols <= FRAME_MAX_PIXELS` (the world checks its scenario);
/// a larger camera renders an empty frame with `rows = cols = 0`.
pub(super) fn render(
    camera: &Camera,
    objects: &[SceneObject],
    spec: &FrameSpec,
    frame: &mut CvsFrame,
) {
    let (rows, cols) = (camera.model.rows, camera.model.cols);
    let fits = rows as usize * cols as usize <= FRAME_MAX_PIXELS;
    let (rows, cols) = if fits { (rows, cols) } else { (0, 0) };
    let n = rows as usize * cols as usize;
    let origin = camera.origin();

    let visible: Vec<Visible> = objects
        .iter()
        .filter_map(|o| {
            let fp = footprint::footprint(camera, o)?;
            Some(Visible {
                object: *o,
                seen: o.seen_from(&origin),
                footprint: fp,
                nearest: o.nearest_distance(&origin),
                farthest: o.farthest_distance(&origin),
            })
        })
        .collect();

    let row_entries: Vec<Vec<Entry>> = (0..rows)
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
        .collect();

    // Pass 1: corner rays. Corner (R, C) borders pixels R-1..=R x C-1..=C; an object touching
    // pixel columns c0..=c1 of those rows can be hit by corners c0..=c1 + 1.
    let corner_cols = cols as usize + 1;
    let mut corners = vec![HIT_NOTHING; (rows as usize + 1) * corner_cols];
    if rows > 0 {
        corners
            .par_chunks_mut(corner_cols)
            .enumerate()
            .for_each(|(r, out)| {
                let r = r as u32;
                let entries = corner_row_entries(&row_entries, r, rows);
                for (c, code) in out.iter_mut().enumerate() {
                    let c = c as u32;
                    let dir = camera.corner_ray(r, c);
                    let cands = entries.iter().filter(|e| e.c0 <= c && c <= e.c1);
                    *code = cast(&origin, &dir, cands, &visible).0;
                }
            });
    }

    // Pass 2: centre rays, labels, depth, target hits, row by row.
    let row_targets: Vec<RowTargets> = frame.depth[..n]
        .par_chunks_mut(cols.max(1) as usize)
        .zip(frame.labels[..n].par_chunks_mut(cols.max(1) as usize))
        .enumerate()
        .map(|(r, (depth, labels))| {
            let r = r as u32;
            let mut noise = RowNoise::new(
                spec.seed,
                spec.step,
                spec.uav,
                r,
                spec.unknown_fraction,
                spec.depth_noise,
            );
            let entries = &row_entries[r as usize];
            let top = &corners[r as usize * corner_cols..(r as usize + 1) * corner_cols];
            let bottom = &corners[(r as usize + 1) * corner_cols..(r as usize + 2) * corner_cols];
            let mut targets = RowTargets::default();
            for c in 0..cols {
                let ci = c as usize;
                let touching = || entries.iter().filter(move |e| e.c0 <= c && c <= e.c1);
                let dir = camera.centre_ray(r, c);
                let (centre, range) = cast(&origin, &dir, touching(), &visible);
                let codes = [top[ci], top[ci + 1], bottom[ci + 1], bottom[ci], centre];
                let mut label = classify(&codes, touching(), &visible);

                let px = noise.next_pixel();
                // A zero range means the camera is inside a box (a UAV flown into a building
                // by an explicit altitude): nothing can be measured there.
                let measured = centre != HIT_NOTHING && range > 0.0;
                let doubted = (px.doubt || !measured) && label != Label::Unknown;
                for (k, &code) in codes.iter().enumerate() {
                    if code >= HIT_GROUND || codes[..k].contains(&code) {
                        continue;
                    }
                    if let ObjectKind::Target(id) = visible[code as usize].object.kind {
                        targets.hit(id, c, label == Label::Target && !doubted);
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
        })
        .collect();

    let found: Vec<TargetBox> = boxes::identified(&row_targets, spec.min_pixels);
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
    for (slot, b) in frame.boxes.iter_mut().zip(&found) {
        *slot = *b;
    }
    frame.header.checksum = frame.checksum();
}

/// First hit of the unit ray `dir` from `origin` among the ground and the candidates:
/// (code, range). Ties go to the object, the side that labels the pixel U rather than G.
fn cast<'a>(
    origin: &Point3,
    dir: &Vector3,
    candidates: impl Iterator<Item = &'a Entry>,
    visible: &[Visible],
) -> (u32, Real) {
    let (mut code, mut best) = if dir.z < 0.0 && origin.z > 0.0 {
        (HIT_GROUND, -origin.z / dir.z)
    } else {
        (HIT_NOTHING, Real::INFINITY)
    };
    for e in candidates {
        if let Some(t) = visible[e.visible as usize].object.cast(origin, dir, best)
            && t <= best
        {
            best = t;
            code = e.visible;
        }
    }
    (code, best)
}
