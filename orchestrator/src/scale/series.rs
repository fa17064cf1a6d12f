//! A series of `fleet bench scale`: the runs of one exchange (`comms.exchange`) and one window
//! (`estimator.window_m`) over every fleet size, one scaling curve ([`Series`]). The window is
//! given by `--window-m` as a [`WindowChoice`]: the whole region (`inf`, as every agent kept
//! it before windows), a half-side in metres, or `auto`, each fleet's guidance reach
//! ([`Scenario::guidance_reach_m`]: 320 m on the paper's scenario).
//!
//! | `--window-m` | [`Series::key`] (run directory, case name) | [`Series::label`] (table, picture) |
//! |---|---|---|
//! | `inf` | `measurements` | `measurements` |
//! | `300` | `measurements_w300` | `measurements, 300 m window` |
//! | `auto` | `measurements_wauto` | `measurements, guidance-reach window` |
//!
//! A window that covers the region is no window (docs/design.md §3): on the paper's 500 m
//! region, an `auto` window of 4 UAVs (320 m half-side) covers it, so the 4-UAV run of that
//! series, the one its ratios are against, gives the whole-region results.

use std::fmt;
use std::str::FromStr;

use protocol::scenario::{Exchange, Scenario};

/// The window of a series, as `--window-m` gives it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WindowChoice {
    /// `inf`: the whole region, no window.
    Whole,
    /// A half-side in metres (finite, positive).
    Metres(f64),
    /// `auto`: each run's [`Scenario::guidance_reach_m`].
    Auto,
}

impl WindowChoice {
    /// The run's `estimator.window_m`: the half-side in metres, `inf` for the whole region.
    pub fn resolve(self, scenario: &Scenario) -> f64 {
        match self {
            WindowChoice::Whole => f64::INFINITY,
            WindowChoice::Metres(m) => m,
            WindowChoice::Auto => scenario.guidance_reach_m(),
        }
    }
}

impl FromStr for WindowChoice {
    type Err = String;

    fn from_str(text: &str) -> Result<WindowChoice, String> {
        match text.trim() {
            "inf" => Ok(WindowChoice::Whole),
            "auto" => Ok(WindowChoice::Auto),
            other => match other.parse::<f64>() {
                Ok(m) if m.is_finite() && m > 0.0 => Ok(WindowChoice::Metres(m)),
                _ => Err(format!(
                    "{other:?}: a window is `inf`, `auto` or a positive number of metres"
                )),
            },
        }
    }
}

impl fmt::Display for WindowChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WindowChoice::Whole => f.write_str("inf"),
            WindowChoice::Metres(m) => write!(f, "{m}"),
            WindowChoice::Auto => f.write_str("auto"),
        }
    }
}

/// One scaling curve: an exchange and a window.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Series {
    /// The exchange (`comms.exchange`).
    pub exchange: Exchange,
    /// The window (`estimator.window_m`).
    pub window: WindowChoice,
}

impl Series {
    /// The series' key: the exchange's name, with `_w<window>` when it has a window. Names the
    /// runs' directory, the report's cases and its headline keys.
    pub fn key(&self) -> String {
        match self.window {
            WindowChoice::Whole => self.exchange.name().to_owned(),
            window => format!("{}_w{window}", self.exchange.name()),
        }
    }

    /// The series' name for a reader: the exchange, and its window.
    pub fn label(&self) -> String {
        let exchange = self.exchange.name();
        match self.window {
            WindowChoice::Whole => exchange.to_owned(),
            WindowChoice::Metres(m) => format!("{exchange}, {m} m window"),
            WindowChoice::Auto => format!("{exchange}, guidance-reach window"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_read_as_inf_auto_or_metres() {
        assert_eq!("inf".parse(), Ok(WindowChoice::Whole));
        assert_eq!(" auto".parse(), Ok(WindowChoice::Auto));
        assert_eq!("150".parse(), Ok(WindowChoice::Metres(150.0)));
        assert_eq!("12.5".parse(), Ok(WindowChoice::Metres(12.5)));
        for bad in ["0", "-3", "NaN", "infinity", "", "big"] {
            let e = bad.parse::<WindowChoice>().unwrap_err();
            assert!(
                e.contains("`inf`, `auto` or a positive number"),
                "{bad}: {e}"
            );
        }
        for text in ["inf", "auto", "150", "12.5"] {
            assert_eq!(text.parse::<WindowChoice>().unwrap().to_string(), text);
        }
    }

    #[test]
    fn a_series_is_named_by_its_exchange_and_window() {
        let series = |window| Series {
            exchange: Exchange::Measurements,
            window,
        };
        let whole = series(WindowChoice::Whole);
        assert_eq!(
            (whole.key(), whole.label()),
            ("measurements".into(), "measurements".into())
        );
        let metres = series(WindowChoice::Metres(300.0));
        assert_eq!(metres.key(), "measurements_w300");
        assert_eq!(metres.label(), "measurements, 300 m window");
        let auto = series(WindowChoice::Auto);
        assert_eq!(auto.key(), "measurements_wauto");
        assert_eq!(auto.label(), "measurements, guidance-reach window");
    }

    #[test]
    fn auto_is_the_scenarios_guidance_reach() {
        let paper = Scenario::default();
        assert_eq!(WindowChoice::Auto.resolve(&paper), paper.guidance_reach_m());
        assert_eq!(WindowChoice::Whole.resolve(&paper), f64::INFINITY);
        assert_eq!(WindowChoice::Metres(80.0).resolve(&paper), 80.0);
    }
}
