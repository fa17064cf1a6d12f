//! The renderer as it was before [`super::render`] cast its rays with [`SeenFrom`]: every
//! ray normalised and cast with parry3d against every object whose footprint touches it.
//! Kept as the reference the fast renderer must match bit for bit. What does not cast rays
//! (the objects in view, their rows, the labels' rule, the header) is the fast renderer's.
//!
//! [`SeenFrom`]: super::objects::SeenFrom

use protocol::camera::Camera;
use protocol::frame::{CvsFrame, Label, TargetBox};
use rayon::prelude::*;
use sets::math::{Point3, Real, Vector3};

use super::boxes::{self, RowTargets};
use super::noise::RowNoise;
use super::{
    Entry, FrameSpec, HIT_GROUND, HIT_NOTHING, ObjectKind, PixelRays, SceneObject, Visible,
    classify, corner_row_entries, frame_size, random_rays, row_entries, visible_objects,
    write_header,
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
    let (rows, cols) = frame_size(camera);
    let visible = visible_objects(camera, objects, &camera.origin());
    let row_entries = row_entries(&visible, rows);
    let corners = corner_codes(camera, &visible, &row_entries, (rows, cols));
    let row_targets = centre_rows(
        camera,
        &visible,
        &row_entries,
        &corners,
        spec,
        (rows, cols),
        frame,
    );
    let found: Vec<TargetBox> = boxes::identified(&row_targets, spec.min_pixels);
    write_header(frame, camera, spec, (rows, cols), &found);
}

/// Pass 1: corner rays. Corner (R, C) borders pixels R-1..=R x C-1..=C; an object touching
/// pixel columns c0..=c1 of those rows can be hit by corners c0..=c1 + 1.
fn corner_codes(
    camera: &Camera,
    visible: &[Visible],
    row_entries: &[Vec<Entry>],
    (rows, cols): (u32, u32),
) -> Vec<u32> {
    let origin = camera.origin();
    let corner_cols = cols as usize + 1;
    let mut corners = vec![HIT_NOTHING; (rows as usize + 1) * corner_cols];
    if rows > 0 {
        corners
            .par_chunks_mut(corner_cols)
            .enumerate()
            .for_each(|(r, out)| {
                let r = r as u32;
                let entries = corner_row_entries(row_entries, r, rows);
                for (c, code) in out.iter_mut().enumerate() {
                    let c = c as u32;
                    let dir = camera.corner_ray(r, c);
                    let cands = entries.iter().filter(|e| e.c0 <= c && c <= e.c1);
                    *code = cast(&origin, &dir, cands, visible).0;
                }
            });
    }
    corners
}

/// Pass 2: centre rays, labels, depth, target hits, row by row.
fn centre_rows(
    camera: &Camera,
    visible: &[Visible],
    row_entries: &[Vec<Entry>],
    corners: &[u32],
    spec: &FrameSpec,
    (rows, cols): (u32, u32),
    frame: &mut CvsFrame,
) -> Vec<RowTargets> {
    let origin = camera.origin();
    let n = rows as usize * cols as usize;
    let corner_cols = cols as usize + 1;
    frame.depth[..n]
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
            let mut ray_points = random_rays(spec, r);
            let entries = &row_entries[r as usize];
            let top = &corners[r as usize * corner_cols..(r as usize + 1) * corner_cols];
            let bottom = &corners[(r as usize + 1) * corner_cols..(r as usize + 2) * corner_cols];
            let mut targets = RowTargets::default();
            for c in 0..cols {
                let ci = c as usize;
                let touching = || entries.iter().filter(move |e| e.c0 <= c && c <= e.c1);
                let dir = camera.centre_ray(r, c);
                let (centre, range) = cast(&origin, &dir, touching(), visible);
                let codes = [top[ci], top[ci + 1], bottom[ci + 1], bottom[ci], centre];
                let corners = || {
                    [
                        camera.corner_ray(r, c),
                        camera.corner_ray(r, c + 1),
                        camera.corner_ray(r + 1, c + 1),
                        camera.corner_ray(r + 1, c),
                    ]
                };
                let pixel = PixelRays {
                    origin,
                    corners: &corners,
                };
                let mut label = classify(&codes, touching(), visible, &pixel);

                let px = noise.next_pixel();
                let (depth_code, range) = match ray_points.as_mut() {
                    None => (centre, range),
                    Some(points) => {
                        let (du, dv) = points.next_point();
                        let dir = camera.ray(c as Real + du, r as Real + dv);
                        cast(&origin, &dir, touching(), visible)
                    }
                };
                // A zero range means the camera is inside a box (a UAV flown into a building
                // by an explicit altitude): nothing can be measured there.
                let measured = depth_code != HIT_NOTHING && range > 0.0;
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
        .collect()
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
