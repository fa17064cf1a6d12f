//! `run.gif`: the sets over the run, a frame every [`FRAME_PERIOD_S`] of simulated time
//! played [`SPEEDUP`] times faster than the world, like the paper's video.
//!
//! Each frame is the region from above: the buildings, the explored ground, `S^o`, `H̄`
//! (darkened), `X̄`, each `X_j` in its target's colour, the true cars (black), and each UAV
//! with its camera's footprint in its colour, under a line with the time and the counts.
//! It is the sets picture's composition (the same colours; a pixel shows a set when any cell
//! it touches belongs to it), with `H̄` a flat shade instead of a hatch, on a fixed palette
//! of a few dozen colours, so a frame needs no colour quantisation; each frame stores only
//! the rectangle that changed, with the pixels unchanged inside it transparent, which keeps
//! the file small (about 5 kB a frame, 3 MB for the default 300 s run).

use std::borrow::Cow;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use protocol::camera::{Camera, CameraModel, CameraPose};
use protocol::scenario::Scenario;
use protocol::wire::TruthState;
use sets::math::{Point2, Point3};
use sets::raster::CellSet;
use world_server::scene::Building;

use super::chart::{OPEN, OUTSIDE};
use super::raster::{blend, cells_spanned, rgb};
use super::sets::{EXPLORED, OBSTACLE_NEIGHBOURHOOD, TARGET_ALPHA, UNDETECTED, target_colour};
use crate::observe::metrics::FusedSets;
use crate::observe::sink::{Sink, SinkError, SinkFile, SinkMaker, StepView};
use crate::pictures::{FONT, palette};

/// Simulated seconds between two frames.
pub const FRAME_PERIOD_S: f64 = 0.5;
/// How many times faster than the world the animation plays.
pub const SPEEDUP: f64 = 10.0;
/// Side of the map, pixels.
const SIDE: u32 = 320;
/// Height of the text line above the map, pixels.
const HEADER: u32 = 22;
/// How much `H̄` darkens what it covers.
const UNSEEN_SHADE: f64 = 0.22;

/// Palette entries: the 32 combinations of the ground layers, then these.
const BASE_COMBINATIONS: u8 = 32;
const TRANSPARENT: u8 = BASE_COMBINATIONS;
const WHITE_INK: u8 = TRANSPARENT + 1;
const BLACK_INK: u8 = WHITE_INK + 1;
const BORDER: u8 = BLACK_INK + 1;
/// First of the 8 target-set colours, then the 8 UAV colours.
const TARGETS: u8 = BORDER + 1;
const UAVS: u8 = TARGETS + 8;
const PALETTE_LEN: usize = UAVS as usize + 8;

/// Bits of a base combination.
const BUILDING_BIT: u8 = 1;
const EXPLORED_BIT: u8 = 2;
const FREE_BIT: u8 = 4;
const UNDETECTED_BIT: u8 = 8;
const UNSEEN_BIT: u8 = 16;

/// The animation being encoded, a frame at a time, in memory.
pub struct Animation {
    encoder: gif::Encoder<Vec<u8>>,
    camera: CameraModel,
    /// West and north edges of the view, metres, and metres per pixel.
    view: (f64, f64, f64),
    /// The grid columns each pixel column touches, and the grid rows each pixel row (from
    /// the top) touches.
    columns: Vec<Option<(u32, u32)>>,
    rows: Vec<Option<(u32, u32)>>,
    /// The buildings as a pixel mask of the map.
    buildings: Vec<bool>,
    /// The previous frame, to store only what changed.
    previous: Option<Vec<u8>>,
    delay_cs: u16,
    frames: u64,
}

/// Why the animation could not be made.
#[derive(Debug, thiserror::Error)]
pub enum AnimationError {
    /// The GIF encoder failed.
    #[error("cannot encode run.gif: {0}")]
    Encode(#[from] gif::EncodingError),
    /// The text line could not be drawn.
    #[error("cannot draw the text of run.gif: {0}")]
    Text(String),
}

impl Animation {
    /// An animation of `scenario`'s region with its `buildings`.
    pub fn new(scenario: &Scenario, buildings: &[Building]) -> Result<Animation, AnimationError> {
        let grid = scenario.grid();
        let half = scenario.region.half_extent_m;
        let mpp = 2.0 * half / f64::from(SIDE);
        let mut encoder = gif::Encoder::new(
            Vec::new(),
            SIDE as u16,
            (SIDE + HEADER) as u16,
            &palette_bytes(),
        )?;
        encoder.set_repeat(gif::Repeat::Infinite)?;
        let columns = (0..SIDE)
            .map(|px| {
                let lo = -half + f64::from(px) * mpp;
                cells_spanned(grid.origin.x, grid.cell_m, grid.nx, lo, lo + mpp)
            })
            .collect();
        let rows = (0..SIDE)
            .map(|py| {
                let hi = half - f64::from(py) * mpp;
                cells_spanned(grid.origin.y, grid.cell_m, grid.ny, hi - mpp, hi)
            })
            .collect();
        let mut mask = vec![false; (SIDE * SIDE) as usize];
        for b in buildings {
            let xs = cells_spanned(0.0, mpp, SIDE, b.min.x + half, b.max.x + half);
            let ys = cells_spanned(0.0, mpp, SIDE, half - b.max.y, half - b.min.y);
            if let (Some((x0, x1)), Some((y0, y1))) = (xs, ys) {
                for py in y0..=y1 {
                    for px in x0..=x1 {
                        // A box marks every pixel it touches; parts, the pixels whose centre
                        // they cover.
                        let centre = Point2::new(
                            (f64::from(px) + 0.5) * mpp - half,
                            half - (f64::from(py) + 0.5) * mpp,
                        );
                        if b.parts.is_empty() || b.covers(&centre) {
                            mask[(py * SIDE + px) as usize] = true;
                        }
                    }
                }
            }
        }
        let delay_cs = (FRAME_PERIOD_S / SPEEDUP * 100.0).round().max(2.0) as u16;
        Ok(Animation {
            encoder,
            camera: scenario.camera_model(),
            view: (-half, half, mpp),
            columns,
            rows,
            buildings: mask,
            previous: None,
            delay_cs,
            frames: 0,
        })
    }

    /// Frames added so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Adds a frame: `sets` (those of agent `uav`, or none when no estimate arrived) over the
    /// truth of the step.
    pub fn add(
        &mut self,
        truth: &TruthState,
        sets: Option<(u32, &FusedSets)>,
    ) -> Result<(), AnimationError> {
        let mut image = vec![WHITE_INK; (SIDE * (SIDE + HEADER)) as usize];
        let map = &mut image[(SIDE * HEADER) as usize..];
        self.paint_ground(map, sets.map(|(_, s)| s));
        self.paint_truth(map, truth);
        let targets = truth.targets().len();
        let text = match sets {
            Some((uav, s)) => format!(
                "t = {:.1} s   UAV {uav}'s sets: {} of {targets} cars identified",
                truth.time_s,
                truth
                    .targets()
                    .iter()
                    .filter(|t| s.targets.contains_key(&t.id))
                    .count()
            ),
            None => format!("t = {:.1} s   no estimate", truth.time_s),
        };
        paint_text(&mut image[..(SIDE * HEADER) as usize], &text)?;
        self.push(image)
    }

    /// Ends the animation; its bytes.
    pub fn finish(self) -> Result<Vec<u8>, AnimationError> {
        Ok(self.encoder.into_inner()?)
    }

    fn paint_ground(&self, map: &mut [u8], sets: Option<&FusedSets>) {
        for (pixel, &building) in map.iter_mut().zip(&self.buildings) {
            *pixel = if building { BUILDING_BIT } else { 0 };
        }
        let Some(sets) = sets else {
            return;
        };
        for (set, bit) in [
            (&*sets.explored, EXPLORED_BIT),
            (&*sets.obstacle_neighbourhood, FREE_BIT),
            (&*sets.undetected, UNDETECTED_BIT),
            (&sets.unseen, UNSEEN_BIT),
        ] {
            self.mark(map, set, |pixel| *pixel |= bit);
        }
        for (&id, set) in &sets.targets {
            let ink = TARGETS + (id % 8) as u8;
            self.mark(map, set, |pixel| *pixel = ink);
        }
    }

    /// Paints every pixel that touches a cell of `set` with `paint`: per pixel row, the grid
    /// rows it touches are ORed into one row, and each pixel column looks for a set bit among
    /// the grid columns it touches.
    fn mark(&self, pixels: &mut [u8], set: &CellSet, paint: impl Fn(&mut u8)) {
        let Some((y0, y1)) = set.row_range() else {
            return;
        };
        let mut merged = vec![0u64; set.words_per_row()];
        for (py, rows) in self.rows.iter().enumerate() {
            let Some((r0, r1)) = *rows else {
                continue;
            };
            let (r0, r1) = (r0.max(y0), r1.min(y1));
            if r0 > r1 {
                continue;
            }
            merged.fill(0);
            for iy in r0..=r1 {
                for (m, w) in merged.iter_mut().zip(set.row(iy)) {
                    *m |= w;
                }
            }
            let line = &mut pixels[py * SIDE as usize..(py + 1) * SIDE as usize];
            for (pixel, columns) in line.iter_mut().zip(&self.columns) {
                if let Some((c0, c1)) = *columns
                    && any_bit(&merged, c0, c1)
                {
                    paint(pixel);
                }
            }
        }
    }

    fn paint_truth(&self, map: &mut [u8], truth: &TruthState) {
        let (x_lo, y_hi, mpp) = self.view;
        let pixel = |x: f64, y: f64| {
            let (px, py) = ((x - x_lo) / mpp, (y_hi - y) / mpp);
            (px.is_finite() && py.is_finite()).then_some((px.floor() as i64, py.floor() as i64))
        };
        let dot = |map: &mut [u8], x: f64, y: f64, r: i64, ink: u8| {
            if let Some((cx, cy)) = pixel(x, y) {
                for py in cy - r..=cy + r {
                    for px in cx - r..=cx + r {
                        put(map, px, py, ink);
                    }
                }
            }
        };
        for t in truth.targets() {
            dot(map, t.ground[0], t.ground[1], 1, BLACK_INK);
        }
        for u in truth.uavs() {
            let ink = UAVS + (u.id % 8) as u8;
            let camera = Camera::new(
                self.camera,
                CameraPose {
                    position: Point3::new(u.position[0], u.position[1], u.position[2]),
                    yaw: u.yaw,
                },
            );
            if let Some(corners) = camera.image_ground_footprint() {
                for k in 0..4 {
                    let (a, b) = (corners[k], corners[(k + 1) % 4]);
                    if let (Some(p), Some(q)) = (pixel(a.x, a.y), pixel(b.x, b.y)) {
                        line(map, p, q, ink);
                    }
                }
            }
            dot(map, u.position[0], u.position[1], 3, ink);
            dot(map, u.position[0], u.position[1], 1, BORDER);
        }
    }

    /// Writes `image`, storing only the rectangle that differs from the previous frame.
    fn push(&mut self, image: Vec<u8>) -> Result<(), AnimationError> {
        let width = SIDE as usize;
        let (left, top, w, h, buffer) = match &self.previous {
            None => (0, 0, width, image.len() / width, image.clone()),
            Some(before) => {
                let changed = |i: usize| image[i] != before[i];
                let rows: Vec<usize> = (0..image.len() / width)
                    .filter(|r| (r * width..(r + 1) * width).any(changed))
                    .collect();
                match (rows.first(), rows.last()) {
                    (Some(&r0), Some(&r1)) => {
                        let cols: Vec<usize> = (0..width)
                            .filter(|&c| (r0..=r1).any(|r| changed(r * width + c)))
                            .collect();
                        let (c0, c1) = (cols[0], cols[cols.len() - 1]);
                        let mut part = Vec::with_capacity((c1 - c0 + 1) * (r1 - r0 + 1));
                        for r in r0..=r1 {
                            for c in c0..=c1 {
                                let i = r * width + c;
                                part.push(if changed(i) { image[i] } else { TRANSPARENT });
                            }
                        }
                        (c0, r0, c1 - c0 + 1, r1 - r0 + 1, part)
                    }
                    // Nothing changed: one transparent pixel holds the time.
                    _ => (0, 0, 1, 1, vec![TRANSPARENT]),
                }
            }
        };
        let frame = gif::Frame {
            delay: self.delay_cs,
            dispose: gif::DisposalMethod::Keep,
            transparent: Some(TRANSPARENT),
            left: left as u16,
            top: top as u16,
            width: w as u16,
            height: h as u16,
            buffer: Cow::Owned(buffer),
            ..gif::Frame::default()
        };
        self.encoder.write_frame(&frame)?;
        self.previous = Some(image);
        self.frames += 1;
        Ok(())
    }
}

/// The palette as RGB triples, in the order of the indices above.
fn palette_bytes() -> Vec<u8> {
    let building = RGBColor(150, 150, 150);
    let mut colours = Vec::with_capacity(PALETTE_LEN);
    for bits in 0..BASE_COMBINATIONS {
        let mut c = rgb(if bits & BUILDING_BIT != 0 {
            building
        } else {
            OPEN
        });
        for (bit, (colour, alpha)) in [
            (EXPLORED_BIT, EXPLORED),
            (FREE_BIT, OBSTACLE_NEIGHBOURHOOD),
            (UNDETECTED_BIT, UNDETECTED),
        ] {
            if bits & bit != 0 {
                c = blend(c, colour, alpha);
            }
        }
        if bits & UNSEEN_BIT != 0 {
            c = blend(c, RGBColor(0, 0, 0), UNSEEN_SHADE);
        }
        colours.push(c);
    }
    colours.push(rgb(OUTSIDE)); // TRANSPARENT: never shown
    colours.push([255, 255, 255]);
    colours.push([0, 0, 0]);
    colours.push([255, 255, 255]);
    for k in 0..8 {
        colours.push(blend(rgb(OPEN), target_colour(k), TARGET_ALPHA.max(0.6)));
    }
    for k in 0..8 {
        colours.push(rgb(palette(k)));
    }
    colours.concat()
}

/// Whether any bit `c0..=c1` of the row `words` is set.
fn any_bit(words: &[u64], c0: u32, c1: u32) -> bool {
    let (w0, w1) = ((c0 / 64) as usize, (c1 / 64) as usize);
    (w0..=w1).any(|w| {
        let lo = if w == w0 { c0 % 64 } else { 0 };
        let hi = if w == w1 { c1 % 64 } else { 63 };
        let mask = (u64::MAX >> (63 - hi)) & (u64::MAX << lo);
        words.get(w).is_some_and(|word| word & mask != 0)
    })
}

fn put(map: &mut [u8], px: i64, py: i64, ink: u8) {
    let side = i64::from(SIDE);
    if (0..side).contains(&px) && (0..side).contains(&py) {
        map[(py * side + px) as usize] = ink;
    }
}

/// A one-pixel line from `p` to `q` (clipped to the map).
fn line(map: &mut [u8], p: (i64, i64), q: (i64, i64), ink: u8) {
    let steps = (q.0 - p.0)
        .abs()
        .max((q.1 - p.1).abs())
        .clamp(1, 4 * i64::from(SIDE));
    for s in 0..=steps {
        let t = s as f64 / steps as f64;
        let x = p.0 as f64 + (q.0 - p.0) as f64 * t;
        let y = p.1 as f64 + (q.1 - p.1) as f64 * t;
        put(map, x.round() as i64, y.round() as i64, ink);
    }
}

/// Draws `text` in black on the white header; anti-aliased pixels darker than mid-grey
/// become black.
fn paint_text(header: &mut [u8], text: &str) -> Result<(), AnimationError> {
    let mut rgb = vec![255u8; header.len() * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (SIDE, HEADER)).into_drawing_area();
        let style = (FONT, 14)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Left, VPos::Center));
        root.draw(&Text::new(text, (6, HEADER as i32 / 2), style))
            .map_err(|e| AnimationError::Text(e.to_string()))?;
        root.present()
            .map_err(|e| AnimationError::Text(e.to_string()))?;
    }
    for (pixel, c) in header.iter_mut().zip(rgb.chunks_exact(3)) {
        let grey = (u32::from(c[0]) + u32::from(c[1]) + u32::from(c[2])) / 3;
        *pixel = if grey < 128 { BLACK_INK } else { WHITE_INK };
    }
    Ok(())
}

/// `run.gif` as one of the run's sinks: a frame every [`FRAME_PERIOD_S`] of simulated time.
/// It is not essential: a failure is logged and the run goes on without it.
pub struct AnimationSink {
    animation: Animation,
    /// Steps between two frames.
    every: u64,
}

impl AnimationSink {
    /// The animation of every run, as a sink (none, with a warning, if it cannot be made).
    pub fn maker() -> SinkMaker {
        Box::new(|scenario, buildings| {
            let every = (FRAME_PERIOD_S / scenario.timing.cvs_period_s)
                .round()
                .max(1.0) as u64;
            Ok(Animation::new(scenario, buildings)
                .map_err(|e| tracing::warn!(error = %e, "no run.gif"))
                .ok()
                .map(|animation| Box::new(AnimationSink { animation, every }) as Box<dyn Sink>))
        })
    }
}

impl Sink for AnimationSink {
    fn phase(&self) -> &'static str {
        crate::observe::phase::ANIMATION
    }

    fn essential(&self) -> bool {
        false
    }

    fn step(&mut self, view: &StepView<'_>) -> Result<(), SinkError> {
        if view.truth.step.is_multiple_of(self.every) {
            self.animation.add(view.truth, view.sets)?;
        }
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<Option<SinkFile>, SinkError> {
        Ok(Some(SinkFile {
            name: "run.gif",
            bytes: self.animation.finish()?,
        }))
    }
}

#[cfg(test)]
mod tests {
    use protocol::wire::UavTruth;

    use super::super::fixtures::{flown, small_scenario, synthetic_state};
    use super::*;
    use crate::pictures::register_fonts;

    /// The frames of a GIF, each as (left, top, width, height, indices).
    fn frames(bytes: &[u8]) -> Vec<(u16, u16, u16, u16, Vec<u8>)> {
        let mut options = gif::DecodeOptions::new();
        options.set_color_output(gif::ColorOutput::Indexed);
        let mut decoder = options.read_info(bytes).expect("a GIF");
        let mut out = Vec::new();
        while let Some(f) = decoder.read_next_frame().expect("a frame") {
            out.push((f.left, f.top, f.width, f.height, f.buffer.to_vec()));
        }
        out
    }

    #[test]
    fn frames_show_the_sets_and_store_only_what_changed() {
        register_fonts().unwrap();
        let scenario = small_scenario();
        let (world, _) = flown(&scenario, 40);
        let state = synthetic_state(&scenario, &world);
        let mut truth = TruthState::default();
        world.truth(1, &mut truth);
        let mut animation = Animation::new(&scenario, &world.scene().buildings).unwrap();
        animation.add(&truth, Some((0, &state.sets))).unwrap();
        animation.add(&truth, Some((0, &state.sets))).unwrap();
        animation.add(&truth, None).unwrap();
        assert_eq!(animation.frames(), 3);
        let bytes = animation.finish().unwrap();
        let frames = frames(&bytes);
        assert_eq!(frames.len(), 3);
        let (_, _, w, h, first) = &frames[0];
        assert_eq!((*w, *h), (SIDE as u16, (SIDE + HEADER) as u16));
        // The centre of a target set shows its colour (the car's dot may cover the middle).
        let half = scenario.region.half_extent_m;
        let mpp = 2.0 * half / f64::from(SIDE);
        let (id, set) = state.sets.targets.iter().next().unwrap();
        let bbox = set.bounding_box().unwrap();
        let grid = scenario.grid();
        let corner = grid.cell_centre((bbox.x0 + 1, (bbox.y0 + bbox.y1) / 2));
        let (px, py) = (
            ((corner.x + half) / mpp) as usize,
            ((half - corner.y) / mpp) as usize + HEADER as usize,
        );
        assert_eq!(first[py * SIDE as usize + px], TARGETS + (id % 8) as u8);
        // The text line has ink; the map has every ground layer.
        assert!(first[..(SIDE * HEADER) as usize].contains(&BLACK_INK));
        for bits in [EXPLORED_BIT, FREE_BIT, UNDETECTED_BIT, UNSEEN_BIT] {
            assert!(
                first
                    .iter()
                    .any(|&i| i < BASE_COMBINATIONS && i & bits != 0),
                "no pixel with bit {bits}"
            );
        }
        // The same picture again: one transparent pixel.
        assert_eq!(frames[1].4, vec![TRANSPARENT]);
        // Without sets the target sets go: the frame repaints them as ground.
        let third = &frames[2].4;
        assert!(!third.contains(&(TARGETS + (id % 8) as u8)));
        assert!(third.iter().any(|&i| i < BASE_COMBINATIONS));
    }

    #[test]
    fn any_bit_looks_at_exactly_its_columns() {
        let words = [1u64 << 63, 1 << 2];
        assert!(any_bit(&words, 63, 63));
        assert!(any_bit(&words, 60, 64));
        assert!(!any_bit(&words, 0, 62));
        assert!(any_bit(&words, 64, 66));
        assert!(!any_bit(&words, 64, 65));
        assert!(!any_bit(&words, 67, 127));
        assert!(!any_bit(&words, 128, 130));
    }

    #[test]
    fn a_uav_is_drawn_in_its_colour_with_its_footprint() {
        register_fonts().unwrap();
        let scenario = small_scenario();
        let mut animation = Animation::new(&scenario, &[]).unwrap();
        let mut truth = TruthState {
            uav_count: 1,
            ..TruthState::default()
        };
        truth.uavs[0] = UavTruth {
            id: 1,
            agent_live: 1,
            position: [0.0, 0.0, 20.0],
            yaw: 0.0,
            yaw_ref: 0.0,
            commanded_yaw_ref: 0.0,
        };
        animation.add(&truth, None).unwrap();
        let frames = frames(&animation.finish().unwrap());
        let ink = UAVS + 1;
        let count = frames[0].4.iter().filter(|&&i| i == ink).count();
        // The dot (7 x 7 less its 3 x 3 centre) and the footprint's outline.
        assert!(count > 40 + 20, "{count} pixels of the UAV's colour");
    }
}
