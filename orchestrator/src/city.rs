//! `fleet city`: imports a real city from an OpenStreetMap PBF file into a directory that
//! `fleet run --scenario DIR/scenario.toml` flies: the scene (`city.json`, the `city` crate's
//! format), the scenario (`scenario.toml`: the keys that differ from the paper's, with
//! `city.scene = "city.json"`), and the city's picture from above (`city.png`); it prints what
//! was imported and what was cut, and checks that the world builds from the scenario.
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
use city::scene::CityScene;
use clap::Args;
use fleet_process::usage::{ScenarioArgs, UsageError};
use protocol::scenario::Scenario;
use world_server::scene::{RING_BORDER_GAP_M, RoadProfile};

use crate::outcome::Outcome;

/// The scene's file name in the output directory, as `scenario.toml` names it.
const SCENE_FILE: &str = "city.json";

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
    /// The height of a storey, for buildings tagged with `building:levels` only, metres
    /// (default: the scenario's `city.storey_height_m`, 3).
    #[arg(long, value_name = "M")]
    pub storey_height: Option<f64>,
    /// The height of buildings tagged with neither `height` nor `building:levels`, metres
    /// (default: the scenario's `city.default_height_m`, 12).
    #[arg(long, value_name = "M")]
    pub default_height: Option<f64>,
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
    /// The scenario to write beside the scene: the one given, with the region, the heights and
    /// the scene set.
    pub scenario: Scenario,
    /// Output directory.
    pub out: PathBuf,
}

impl CityArgs {
    /// Checks the flags and derives the road rules from the scenario.
    pub fn validate(&self) -> Result<CityConfig, UsageError> {
        let mut scenario = self.scenario.load()?;
        let centre = parse_centre(&self.center)?;
        let half_extent_m = self.half_extent.unwrap_or(scenario.region.half_extent_m);
        let storey_height_m = self.storey_height.unwrap_or(scenario.city.storey_height_m);
        let default_height_m = self
            .default_height
            .unwrap_or(scenario.city.default_height_m);
        for (flag, v) in [
            ("--half-extent", half_extent_m),
            ("--storey-height", storey_height_m),
            ("--default-height", default_height_m),
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
        scenario.region.half_extent_m = half_extent_m;
        scenario.city.storey_height_m = storey_height_m;
        scenario.city.default_height_m = default_height_m;
        scenario.city.scene = SCENE_FILE.into();
        scenario
            .validate()
            .map_err(|e| UsageError(format!("the city's scenario: {e}")))?;
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
            scenario,
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
    let scene = &imported.scene;
    let scene_path = config.out.join(SCENE_FILE);
    scene
        .write(&scene_path)
        .with_context(|| format!("writing {}", scene_path.display()))?;
    let (storey, default) = (
        config.scenario.city.storey_height_m,
        config.scenario.city.default_height_m,
    );
    let picture = config.out.join("city.png");
    fleet_observe::pictures::city::draw_city(scene, storey, default, &picture)?;
    let mut scenario = config.scenario.clone();
    if let Some(range) = roof_range(scene, storey, default) {
        scenario.region.building_height_m = range;
    }
    let scenario_path = config.out.join("scenario.toml");
    let header = format!(
        "# An imported city: `fleet city` from {} around {:.6},{:.6}.\n\
         # Map data {}. `region.building_height_m` is the range of its roofs.\n\n",
        scene.source.osm_file,
        scene.source.centre[0],
        scene.source.centre[1],
        scene.source.attribution
    );
    std::fs::write(&scenario_path, header + &scenario.to_toml_changes())
        .with_context(|| format!("writing {}", scenario_path.display()))?;
    println!("{}", imported.report);
    println!("imported in {:.0} ms", elapsed.as_secs_f64() * 1e3);
    // What `fleet run --scenario` will do: load the file and build the world from it.
    let world = Scenario::load(Some(&scenario_path), &[])
        .map_err(anyhow::Error::from)
        .and_then(|s| Ok(world_server::World::new(&s)?));
    match world {
        Ok(world) => println!(
            "the world builds: {} buildings, {} cars placed, UAVs from {:.0} m",
            world.scene().buildings.len(),
            world.targets().len(),
            world.uavs().first().map_or(0.0, |u| u.state.position.z)
        ),
        Err(e) => {
            eprintln!("fleet city: the imported city does not build a world: {e:#}");
            return Ok(Outcome::BadInput);
        }
    }
    println!(
        "wrote {}, {} and {}",
        scenario_path.display(),
        scene_path.display(),
        picture.display()
    );
    Ok(Outcome::Success)
}

/// The lowest and highest roof of the scene (none without buildings).
fn roof_range(scene: &CityScene, storey_m: f64, default_m: f64) -> Option<[f64; 2]> {
    let heights = scene
        .buildings
        .iter()
        .map(|b| b.height(storey_m, default_m).0);
    let lo = heights.clone().reduce(f64::min)?;
    let hi = heights.reduce(f64::max)?;
    Some([lo, hi])
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
