//! The legend panel: rows of swatches, set symbols as the paper writes them, and text; and the
//! markers the chart and the legend both draw.

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::chart::{Area, OPEN, OUTLINE};
use super::raster::blend_rgb;
use crate::pictures::FONT;

/// What a legend row shows left of its text.
pub(super) enum Swatch {
    /// A filled box.
    Fill(RGBColor),
    /// A filled box with a building outline.
    Building(RGBColor),
    /// A filled box with an edge of another colour.
    Edged(RGBColor, RGBColor),
    /// An empty box.
    Outline(RGBColor),
    /// A hatch on open ground.
    Hatch(Hatch),
    /// A true target's marker.
    Target,
    /// A track ending in a UAV marker.
    Track(RGBColor),
}

/// Hatch lines drawn over a layer: every pixel whose `x + y` is a multiple of `period`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Hatch {
    /// Colour of the lines.
    pub(super) ink: RGBColor,
    /// Their opacity.
    pub(super) alpha: f64,
    /// Their period, pixels.
    pub(super) period: u32,
}

/// A set's symbol as the paper writes it, drawn before a legend row's text.
#[derive(Clone, Copy, Debug)]
pub(super) enum Symbol<'s> {
    /// A letter with a bar over it (`X̄`, `H̄`).
    Bar(&'s str),
    /// A letter with a superscript (`S^o`).
    Sup(&'s str, &'s str),
    /// A letter with a subscript (`X_j`).
    Sub(&'s str, &'s str),
}

/// Rows of swatches and text down a legend panel.
pub(super) struct Legend<'a, 'b> {
    area: &'a Area<'b>,
    y: i32,
}

impl<'a, 'b> Legend<'a, 'b> {
    const ROW_PX: i32 = 22;
    const LEFT: i32 = 14;
    const SWATCH: (i32, i32) = (26, 14);

    pub(super) fn new(area: &'a Area<'b>) -> Legend<'a, 'b> {
        Legend { area, y: 16 }
    }

    fn text_style(size: u32) -> TextStyle<'static> {
        (FONT, size)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Left, VPos::Center))
    }

    pub(super) fn heading(&mut self, text: &str) -> anyhow::Result<()> {
        self.area.draw_text(
            text,
            &(FONT, 15)
                .into_font()
                .style(FontStyle::Bold)
                .color(&BLACK)
                .pos(Pos::new(HPos::Left, VPos::Center)),
            (Self::LEFT, self.y),
        )?;
        self.y += Self::ROW_PX;
        Ok(())
    }

    pub(super) fn gap(&mut self) {
        self.y += Self::ROW_PX / 2;
    }

    pub(super) fn text(&mut self, text: &str) -> anyhow::Result<()> {
        self.area.draw_text(
            text,
            &Self::text_style(13),
            (Self::LEFT + Self::SWATCH.0 + 10, self.y),
        )?;
        self.y += Self::ROW_PX;
        Ok(())
    }

    pub(super) fn entry(
        &mut self,
        swatch: &Swatch,
        symbol: Option<Symbol<'_>>,
        text: &str,
    ) -> anyhow::Result<()> {
        let (x0, y0) = (Self::LEFT, self.y - Self::SWATCH.1 / 2);
        let (x1, y1) = (x0 + Self::SWATCH.0, y0 + Self::SWATCH.1);
        let rect = [(x0, y0), (x1, y1)];
        let a = self.area;
        match swatch {
            Swatch::Fill(c) => {
                a.draw(&Rectangle::new(rect, c.filled()))?;
                a.draw(&Rectangle::new(
                    rect,
                    RGBColor(150, 150, 150).stroke_width(1),
                ))?;
            }
            Swatch::Building(c) => {
                a.draw(&Rectangle::new(rect, c.filled()))?;
                a.draw(&Rectangle::new(rect, OUTLINE.stroke_width(1)))?;
            }
            Swatch::Edged(fill, edge) => {
                a.draw(&Rectangle::new(rect, fill.filled()))?;
                a.draw(&Rectangle::new(rect, edge.stroke_width(2)))?;
            }
            Swatch::Outline(c) => {
                a.draw(&Rectangle::new(rect, c.stroke_width(1)))?;
            }
            Swatch::Hatch(hatch) => {
                a.draw(&Rectangle::new(rect, OPEN.filled()))?;
                let ink = blend_rgb(OPEN, hatch.ink, hatch.alpha);
                let period = hatch.period as i32;
                for y in y0..=y1 {
                    for x in x0..=x1 {
                        if (x + y).rem_euclid(period) == 0 {
                            a.draw_pixel((x, y), &ink)?;
                        }
                    }
                }
                a.draw(&Rectangle::new(
                    rect,
                    RGBColor(150, 150, 150).stroke_width(1),
                ))?;
            }
            Swatch::Target => {
                target_marker(a, ((x0 + x1) / 2, self.y), OPEN)?;
            }
            Swatch::Track(c) => {
                thick_path(a, &[(x0, y1), (x0 + 8, y0 + 3), (x1 - 6, self.y)], *c)?;
                uav_marker(a, (x1 - 6, self.y), *c)?;
            }
        }
        let mut x = x1 + 10;
        if let Some(symbol) = symbol {
            x = self.symbol(symbol, x)?;
        }
        a.draw_text(text, &Self::text_style(14), (x, self.y))?;
        self.y += Self::ROW_PX;
        Ok(())
    }

    /// Draws `symbol` with its left edge at `x` on the current row; returns where text may
    /// follow.
    fn symbol(&self, symbol: Symbol<'_>, x: i32) -> anyhow::Result<i32> {
        let base_style = Self::text_style(15);
        let small_style = Self::text_style(11);
        let (base, small, rise) = match symbol {
            Symbol::Bar(base) => (base, None, 0),
            Symbol::Sup(base, sup) => (base, Some(sup), -5),
            Symbol::Sub(base, sub) => (base, Some(sub), 5),
        };
        let (w, _) = self.area.estimate_text_size(base, &base_style)?;
        let w = w as i32;
        self.area.draw_text(base, &base_style, (x, self.y))?;
        if let Symbol::Bar(_) = symbol {
            self.area.draw(&PathElement::new(
                vec![(x + 1, self.y - 10), (x + w - 1, self.y - 10)],
                BLACK.stroke_width(1),
            ))?;
        }
        let mut end = x + w;
        if let Some(small) = small {
            self.area
                .draw_text(small, &small_style, (end + 1, self.y + rise))?;
            let (sw, _) = self.area.estimate_text_size(small, &small_style)?;
            end += 1 + sw as i32;
        }
        Ok(end + 6)
    }
}

/// A two-pixel polyline through pixel points (four one-pixel passes: plotters' thick strokes
/// leave holes in steep segments).
pub(super) fn thick_path(
    area: &Area<'_>,
    points: &[(i32, i32)],
    colour: RGBColor,
) -> anyhow::Result<()> {
    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
        let shifted: Vec<(i32, i32)> = points.iter().map(|&(x, y)| (x + dx, y + dy)).collect();
        area.draw(&PathElement::new(shifted, colour.stroke_width(1)))?;
    }
    Ok(())
}

/// A UAV's last position: a triangle in its colour.
pub(super) fn uav_marker(area: &Area<'_>, at: (i32, i32), colour: RGBColor) -> anyhow::Result<()> {
    area.draw(&TriangleMarker::new(at, 8, colour.filled()))?;
    area.draw(&TriangleMarker::new(at, 8, BLACK.stroke_width(1)))?;
    Ok(())
}

/// A true target: a disc in its colour, ringed black.
pub(super) fn target_marker(
    area: &Area<'_>,
    at: (i32, i32),
    colour: RGBColor,
) -> anyhow::Result<()> {
    area.draw(&Circle::new(at, 5, colour.filled()))?;
    area.draw(&Circle::new(at, 5, BLACK.stroke_width(2)))?;
    Ok(())
}
