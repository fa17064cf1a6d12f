//! `fleet city`: imports a real city from an OpenStreetMap PBF file into a directory: the
//! scene (`city.json`, the `city` crate's format) and its picture from above (`city.png`), and
//! prints what was imported and what was cut.
//!
//! The roads must fit the scenario's cars: each lane runs the road profile's lane offset from
//! its road's centreline, and every lane point keeps `targets.building_clearance_m` from every
//! building, as the generated city's lanes do. Roads end the profile's half width plus 2 m
//! inside the region's border, as the generated city's ring road runs.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use city::error::CityImportError;
use city::import::{ImportOptions, RoadRules, import};
use city::osm::LatLon;
use clap::Args;
use protocol::usage::{ScenarioArgs, UsageError};
use world_server::scene::{RING_BORDER_GAP_M, RoadProfile};

use crate::Outcome;

/// `fleet city`.
#[derive(Debug, Args)]
pub struct CityArgs {
    /// The OpenStreetMap PBF file.
    #[arg(long)]
    pub osm: PathBuf,
    /// The centre of the square region, `LAT,LON` in degrees.
    #[arg(long, value_name = "LAT,LON")]
    pub center: String,
    /// Half the square's side, metres (default: the scenario's `region.half_extent_m`).
    #[arg(long, value_name = "M")]
    pub half_extent: Option<f64>,
    /// The height of a storey, for buildings tagged with `building:levels` only, metres.
    #[arg(long, value_name = "M", default_value_t = 3.0)]
    pub storey_height: f64,
    /// The height of buildings tagged with neither `height` nor `building:levels`, metres.
    #[arg(long, value_name = "M", default_value_t = 12.0)]
    pub default_height: f64,
    /// The scenario whose cars the roads must fit (`targets.*`).
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// Output directory (created if needed).
    #[arg(long)]
    pub out: PathBuf,
}

/// A validated `fleet city`.
#[derive(Debug, Clone)]
pub struct CityConfig {
    /// What to import.
    pub import: ImportOptions,
    /// Storey height, metres.
    pub storey_height_m: f64,
    /// Default building height, metres.
    pub default_height_m: f64,
    /// Output directory.
    pub out: PathBuf,
}

impl CityArgs {
    /// Checks the flags and derives the road rules from the scenario.
    pub fn validate(&self) -> Result<CityConfig, UsageError> {
        let scenario = self.scenario.load()?;
        let centre = parse_centre(&self.center)?;
        let half_extent_m = self.half_extent.unwrap_or(scenario.region.half_extent_m);
        for (flag, v) in [
            ("--half-extent", half_extent_m),
            ("--storey-height", self.storey_height),
            ("--default-height", self.default_height),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(UsageError(format!(
                    "{flag} {v}: must be a positive number of metres"
                )));
            }
        }
        let profile = RoadProfile::for_scenario(&scenario);
        // As the ring road of the generated city: a car's whole body stays 2 m inside the
        // region.
        let border_gap_m = profile.half_width + RING_BORDER_GAP_M;
        if half_extent_m <= 4.0 * border_gap_m {
            return Err(UsageError(format!(
                "--half-extent {half_extent_m}: must be more than {:.1} m, four times the gap \
                 roads keep from the border ({border_gap_m:.1} m for the scenario's cars)",
                4.0 * border_gap_m
            )));
        }
        Ok(CityConfig {
            import: ImportOptions {
                osm: self.osm.clone(),
                centre,
                half_extent_m,
                roads: RoadRules {
                    lane_offset_m: profile.lane_offset,
                    clearance_m: profile.building_clearance,
                    border_gap_m,
                },
            },
            storey_height_m: self.storey_height,
            default_height_m: self.default_height,
            out: self.out.clone(),
        })
    }
}

fn parse_centre(text: &str) -> Result<LatLon, UsageError> {
    let bad = || {
        UsageError(format!(
            "--center {text}: expected LAT,LON in degrees, e.g. 60.1716,24.9443"
        ))
    };
    let (lat, lon) = text.split_once(',').ok_or_else(bad)?;
    let lat: f64 = lat.trim().parse().map_err(|_| bad())?;
    let lon: f64 = lon.trim().parse().map_err(|_| bad())?;
    Ok(LatLon { lat, lon })
}

/// Runs `fleet city`. Data the importer cannot use (not PBF, a centre outside it, no drivable
/// road left) is bad input: exit code 2.
pub fn command(config: &CityConfig) -> anyhow::Result<Outcome> {
    let started = Instant::now();
    let imported = match import(&config.import) {
        Ok(imported) => imported,
        Err(e @ CityImportError::Read { .. })
        | Err(e @ CityImportError::Option { .. })
        | Err(e @ CityImportError::CentreOutside { .. })
        | Err(e @ CityImportError::Empty)
        | Err(e @ CityImportError::NoDrivableRoad { .. }) => {
            eprintln!("fleet city: {e}");
            return Ok(Outcome::BadInput);
        }
    };
    let elapsed = started.elapsed();
    std::fs::create_dir_all(&config.out)
        .with_context(|| format!("creating {}", config.out.display()))?;
    let scene_path = config.out.join("city.json");
    imported
        .scene
        .write(&scene_path)
        .with_context(|| format!("writing {}", scene_path.display()))?;
    let picture = config.out.join("city.png");
    fleet_observe::pictures::city::draw_city(
        &imported.scene,
        config.storey_height_m,
        config.default_height_m,
        &picture,
    )?;
    println!("{}", imported.report);
    println!("imported in {:.0} ms", elapsed.as_secs_f64() * 1e3);
    println!("wrote {} and {}", scene_path.display(), picture.display());
    Ok(Outcome::Success)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centres_parse_as_lat_lon() {
        assert_eq!(
            parse_centre("60.1716, 24.9443").unwrap(),
            LatLon {
                lat: 60.1716,
                lon: 24.9443
            }
        );
        assert!(parse_centre("60.1716").is_err());
        assert!(parse_centre("north,24.9").is_err());
    }
}
