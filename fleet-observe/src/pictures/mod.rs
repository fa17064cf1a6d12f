//! Pictures drawn with plotters (bitmap backend, no system fonts): the font is the DejaVu Sans
//! shipped in `assets/`, registered once at start-up by [`register_fonts`].

pub mod city;
pub mod frame;
pub mod topview;

use plotters::style::{FontStyle, RGBColor};

/// The font family every picture uses.
pub const FONT: &str = "sans-serif";

static DEJAVU_SANS: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");

/// Why the pictures' font could not be registered.
#[derive(Debug, thiserror::Error)]
#[error("the bundled font assets/DejaVuSans.ttf is not a valid font")]
pub struct FontRegisterError;

/// Registers the bundled font under [`FONT`] for every style the pictures use. Call once
/// before drawing (further calls are harmless).
pub fn register_fonts() -> Result<(), FontRegisterError> {
    for style in [FontStyle::Normal, FontStyle::Bold] {
        plotters::style::register_font(FONT, style, DEJAVU_SANS).map_err(|_| FontRegisterError)?;
    }
    Ok(())
}

/// A perceptually ordered colour map (viridis, by linear interpolation of 5 anchors):
/// `t` in `[0, 1]`, clamped.
pub fn viridis(t: f64) -> RGBColor {
    const ANCHORS: [(f64, f64, f64); 5] = [
        (68.0, 1.0, 84.0),
        (59.0, 82.0, 139.0),
        (33.0, 145.0, 140.0),
        (94.0, 201.0, 98.0),
        (253.0, 231.0, 37.0),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (ANCHORS.len() - 1) as f64;
    let i = (x.floor() as usize).min(ANCHORS.len() - 2);
    let f = x - i as f64;
    let (a, b) = (ANCHORS[i], ANCHORS[i + 1]);
    let mix = |p: f64, q: f64| (p + (q - p) * f).round().clamp(0.0, 255.0) as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// A distinct colour per index (UAVs, targets).
pub fn palette(i: usize) -> RGBColor {
    const COLOURS: [RGBColor; 8] = [
        RGBColor(228, 26, 28),
        RGBColor(55, 126, 184),
        RGBColor(77, 175, 74),
        RGBColor(152, 78, 163),
        RGBColor(255, 127, 0),
        RGBColor(166, 86, 40),
        RGBColor(247, 129, 191),
        RGBColor(0, 170, 170),
    ];
    COLOURS[i % COLOURS.len()]
}

/// A value with about three significant digits, as pictures label their points.
pub fn short_number(v: f64) -> String {
    let a = v.abs();
    if a >= 100.0 || a == 0.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else if a >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn viridis_runs_from_purple_to_yellow_and_clamps() {
        assert_eq!(viridis(0.0), RGBColor(68, 1, 84));
        assert_eq!(viridis(1.0), RGBColor(253, 231, 37));
        assert_eq!(viridis(7.0), viridis(1.0));
        assert_eq!(viridis(f64::NAN), viridis(0.0));
    }

    #[test]
    fn bundled_font_registers() {
        register_fonts().unwrap();
    }
}
