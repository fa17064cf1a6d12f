//! The cell layers as one bitmap: which ground each pixel of the plotting area covers, which
//! pixels show a set, and the pixels themselves, blitted under the vector overlays.

use anyhow::Context as _;
use plotters::prelude::*;
use sets::grid::GroundGrid;
use sets::math::Point2;
use sets::raster::CellSet;
use world_server::scene::Building;

use super::chart::{Area, Chart};

/// Where the chart's plotting area lies in the picture and what ground each pixel covers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct PlotRaster {
    /// Picture column of the area's first pixel.
    pub(super) left: i32,
    /// Picture row of the area's first pixel.
    pub(super) top: i32,
    pub(super) width: u32,
    pub(super) height: u32,
    /// West edge of the view, metres.
    pub(super) x_lo: f64,
    /// North edge of the view, metres.
    pub(super) y_hi: f64,
    /// Metres per pixel along x.
    pub(super) mx: f64,
    /// Metres per pixel along y.
    pub(super) my: f64,
}

impl PlotRaster {
    pub(super) fn of(chart: &Chart<'_, '_>, half: f64) -> anyhow::Result<PlotRaster> {
        let (left, bottom) = chart.backend_coord(&(-half, -half));
        let (right, top) = chart.backend_coord(&(half, half));
        let width = u32::try_from(right - left).ok().filter(|&w| w > 0);
        let height = u32::try_from(bottom - top).ok().filter(|&h| h > 0);
        let (Some(width), Some(height)) = (width, height) else {
            anyhow::bail!("the chart's plotting area is empty");
        };
        Ok(PlotRaster {
            left,
            top,
            width,
            height,
            x_lo: -half,
            y_hi: half,
            mx: 2.0 * half / f64::from(width),
            my: 2.0 * half / f64::from(height),
        })
    }

    pub(super) fn x_centre(&self, px: u32) -> f64 {
        self.x_lo + (f64::from(px) + 0.5) * self.mx
    }

    pub(super) fn y_centre(&self, py: u32) -> f64 {
        self.y_hi - (f64::from(py) + 0.5) * self.my
    }

    /// The pixel (from the area's top-left corner) showing ground point `(x, y)`.
    #[cfg(test)]
    pub(super) fn pixel_of(&self, x: f64, y: f64) -> Option<(u32, u32)> {
        let px = ((x - self.x_lo) / self.mx).floor();
        let py = ((self.y_hi - y) / self.my).floor();
        (px >= 0.0 && py >= 0.0 && px < f64::from(self.width) && py < f64::from(self.height))
            .then_some((px as u32, py as u32))
    }

    /// The range of pixel columns whose centres lie in `[lo, hi]` metres, if any.
    pub(super) fn columns_in(&self, lo: f64, hi: f64) -> Option<(u32, u32)> {
        let a = ((lo - self.x_lo) / self.mx - 0.5).ceil().max(0.0);
        let b = ((hi - self.x_lo) / self.mx - 0.5)
            .floor()
            .min(f64::from(self.width) - 1.0);
        (a <= b).then_some((a as u32, b as u32))
    }

    /// The range of pixel rows whose centres lie in `[lo, hi]` metres, if any.
    pub(super) fn rows_in(&self, lo: f64, hi: f64) -> Option<(u32, u32)> {
        let a = ((self.y_hi - hi) / self.my - 0.5).ceil().max(0.0);
        let b = ((self.y_hi - lo) / self.my - 0.5)
            .floor()
            .min(f64::from(self.height) - 1.0);
        (a <= b).then_some((a as u32, b as u32))
    }

    /// For each pixel column, the grid columns it touches.
    pub(super) fn cell_columns(&self, grid: &GroundGrid) -> Vec<Option<(u32, u32)>> {
        (0..self.width)
            .map(|px| {
                let lo = self.x_lo + f64::from(px) * self.mx;
                cells_spanned(grid.origin.x, grid.cell_m, grid.nx, lo, lo + self.mx)
            })
            .collect()
    }

    /// For each pixel row (from the top), the grid rows it touches.
    pub(super) fn cell_rows(&self, grid: &GroundGrid) -> Vec<Option<(u32, u32)>> {
        (0..self.height)
            .map(|py| {
                let hi = self.y_hi - f64::from(py) * self.my;
                cells_spanned(grid.origin.y, grid.cell_m, grid.ny, hi - self.my, hi)
            })
            .collect()
    }

    /// Copies `pixels` onto the plotting area of `root`.
    pub(super) fn blit(&self, root: &Area<'_>, pixels: Pixels) -> anyhow::Result<()> {
        let image = BitMapElement::<(i32, i32)>::with_owned_buffer(
            (self.left, self.top),
            (self.width, self.height),
            pixels.rgb,
        )
        .context("the cell bitmap does not fit the plotting area")?;
        root.draw(&image)?;
        Ok(())
    }
}

/// The cells along one axis (origin `origin`, side `d`, `n` cells) whose extent meets the
/// span `[lo, hi]` with more than a point, clamped to the grid; `None` when the span misses it.
pub(super) fn cells_spanned(origin: f64, d: f64, n: u32, lo: f64, hi: f64) -> Option<(u32, u32)> {
    let k0 = ((lo - origin) / d).floor();
    let k1 = (((hi - origin) / d).ceil() - 1.0).max(k0);
    if !(k0.is_finite() && k1.is_finite()) || k1 < 0.0 || k0 >= f64::from(n) {
        return None;
    }
    Some((k0.max(0.0) as u32, k1.min(f64::from(n) - 1.0) as u32))
}

/// Which pixels show `set`: those touching at least one of its cells.
pub(super) fn mask(
    set: &CellSet,
    cols: &[Option<(u32, u32)>],
    rows: &[Option<(u32, u32)>],
) -> Vec<bool> {
    let w = cols.len();
    let mut out = vec![false; w * rows.len()];
    let Some(bbox) = set.bounding_box() else {
        return out;
    };
    for (line, row) in out.chunks_exact_mut(w).zip(rows) {
        let Some((r0, r1)) = *row else {
            continue;
        };
        if r1 < bbox.y0 || r0 > bbox.y1 {
            continue;
        }
        for (pixel, col) in line.iter_mut().zip(cols) {
            let Some((c0, c1)) = *col else {
                continue;
            };
            if c1 < bbox.x0 || c0 > bbox.x1 {
                continue;
            }
            *pixel = (r0..=r1).any(|iy| (c0..=c1).any(|ix| set.contains((ix, iy))));
        }
    }
    out
}

/// The RGB bitmap of the plotting area, row-major from the top-left pixel.
pub(super) struct Pixels {
    pub(super) width: u32,
    pub(super) rgb: Vec<u8>,
}

impl Pixels {
    pub(super) fn new(raster: &PlotRaster) -> Pixels {
        Pixels {
            width: raster.width,
            rgb: vec![255; raster.width as usize * raster.height as usize * 3],
        }
    }

    pub(super) fn index(&self, px: u32, py: u32) -> usize {
        (py as usize * self.width as usize + px as usize) * 3
    }

    pub(super) fn get(&self, px: u32, py: u32) -> [u8; 3] {
        let i = self.index(px, py);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    pub(super) fn put(&mut self, px: u32, py: u32, c: [u8; 3]) {
        let i = self.index(px, py);
        self.rgb[i..i + 3].copy_from_slice(&c);
    }

    /// Paints the pixels whose centres lie on building `b`'s footprint.
    pub(super) fn fill_footprint(&mut self, raster: &PlotRaster, b: &Building, c: [u8; 3]) {
        let (Some((x0, x1)), Some((y0, y1))) = (
            raster.columns_in(b.min.x, b.max.x),
            raster.rows_in(b.min.y, b.max.y),
        ) else {
            return;
        };
        for py in y0..=y1 {
            for px in x0..=x1 {
                let centre = Point2::new(raster.x_centre(px), raster.y_centre(py));
                if b.parts.is_empty() || b.covers(&centre) {
                    self.put(px, py, c);
                }
            }
        }
    }
}

/// The colour as the bitmap stores it.
pub(super) fn rgb(c: RGBColor) -> [u8; 3] {
    [c.0, c.1, c.2]
}

/// `over` at opacity `alpha` on `under`.
pub(super) fn blend(under: [u8; 3], over: RGBColor, alpha: f64) -> [u8; 3] {
    let mix = |u: u8, o: u8| (f64::from(u) + (f64::from(o) - f64::from(u)) * alpha).round() as u8;
    [
        mix(under[0], over.0),
        mix(under[1], over.1),
        mix(under[2], over.2),
    ]
}

pub(super) fn blend_rgb(under: RGBColor, over: RGBColor, alpha: f64) -> RGBColor {
    let [r, g, b] = blend(rgb(under), over, alpha);
    RGBColor(r, g, b)
}

/// Whether pixel `(px, py)` of `mask` has a 4-neighbour outside it (or lies on the border).
pub(super) fn is_edge(mask: &[bool], w: usize, h: usize, px: usize, py: usize) -> bool {
    px == 0
        || py == 0
        || px + 1 == w
        || py + 1 == h
        || !mask[py * w + px - 1]
        || !mask[py * w + px + 1]
        || !mask[(py - 1) * w + px]
        || !mask[(py + 1) * w + px]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_spans_cover_a_pixel_and_clamp_to_the_grid() {
        // Cells of 0.5 m from -10: a pixel over [0.1, 0.9] touches cells 20 and 21.
        assert_eq!(cells_spanned(-10.0, 0.5, 40, 0.1, 0.9), Some((20, 21)));
        // A pixel inside one cell touches only it.
        assert_eq!(cells_spanned(-10.0, 0.5, 40, 0.1, 0.2), Some((20, 20)));
        // Exactly on a cell's edges: only that cell.
        assert_eq!(cells_spanned(-10.0, 0.5, 40, 0.0, 0.5), Some((20, 20)));
        assert_eq!(cells_spanned(-10.0, 0.5, 40, -11.0, -9.8), Some((0, 0)));
        assert_eq!(cells_spanned(-10.0, 0.5, 40, 9.9, 12.0), Some((39, 39)));
        assert_eq!(cells_spanned(-10.0, 0.5, 40, 10.0, 12.0), None);
        assert_eq!(cells_spanned(-10.0, 0.5, 40, -12.0, -10.0), None);
    }
}
