//! The importer: an OpenStreetMap file, a centre and a half-extent in; a [`CityScene`] and a
//! report of what was imported out.
//!
//! ```no_run
//! use city::import::{ImportOptions, RoadRules, import};
//! use city::osm::LatLon;
//!
//! let options = ImportOptions {
//!     osm: "assets/cities/helsinki.osm.pbf".into(),
//!     centre: LatLon { lat: 60.1675, lon: 24.9460 },
//!     half_extent_m: 250.0,
//!     roads: RoadRules { lane_offset_m: 2.8, clearance_m: 6.0, border_gap_m: 2.0 },
//! };
//! let imported = import(&options)?;
//! println!("{}", imported.report);
//! imported.scene.write("city.json".as_ref())?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod buildings;
mod roads;

use std::collections::BTreeMap;
use std::fmt;
use std::path::PathBuf;

pub use buildings::BuildingCounts;
pub use roads::RoadRules;

use crate::error::CityImportError;
use crate::osm::{LatLon, OsmData};
use crate::projection::LocalFrame;
use crate::scene::{CityScene, FORMAT_VERSION, SceneSource};

/// The attribution OpenStreetMap data needs wherever it is shown.
pub const OSM_ATTRIBUTION: &str = "© OpenStreetMap contributors, ODbL 1.0";

/// Nodes farther than this beyond the square are not kept, metres: enough for any way piece
/// that crosses the square to keep both its ends.
const NODE_MARGIN_M: f64 = 1000.0;

/// What to import.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportOptions {
    /// The OpenStreetMap PBF file.
    pub osm: PathBuf,
    /// The centre of the square region.
    pub centre: LatLon,
    /// Half the square's side, metres.
    pub half_extent_m: f64,
    /// How the roads keep clear of buildings.
    pub roads: RoadRules,
}

/// An imported city and what the import found.
#[derive(Clone, Debug, PartialEq)]
pub struct Imported {
    /// The scene.
    pub scene: CityScene,
    /// What was imported and what was left out.
    pub report: ImportReport,
}

/// What an import found.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportReport {
    /// The buildings.
    pub buildings: BuildingCounts,
    /// Share of the region's ground under buildings.
    pub ground_share: f64,
    /// Buildings whose height comes from `height`, from `building:levels`, and from neither.
    pub height_sources: [usize; 3],
    /// Drivable road mapped inside the square, before cuts, metres (centreline).
    pub mapped_road_m: f64,
    /// Drivable road kept, metres.
    pub drivable_m: f64,
    /// Metres left out, by [`crate::scene::CutReason::name`].
    pub cut_m: BTreeMap<&'static str, f64>,
    /// How far the ground falls below the flat frame at the region's corners, metres.
    pub flatness_error_m: f64,
}

/// Imports a city (see the module's docs).
pub fn import(options: &ImportOptions) -> Result<Imported, CityImportError> {
    let h = options.half_extent_m;
    check_options(options)?;
    let frame = LocalFrame::new(options.centre);
    let reach = h + NODE_MARGIN_M;
    let (sw, ne) = (
        frame.unproject([-reach, -reach]),
        frame.unproject([reach, reach]),
    );
    let keep = |p: LatLon| p.lat >= sw.lat && p.lat <= ne.lat && p.lon >= sw.lon && p.lon <= ne.lon;
    let data = crate::osm::read_pbf(&options.osm, keep)?;
    import_data(&data, options)
}

/// Imports a city from data already read (the hand-written data of tests, or a file read by
/// [`crate::osm::read_pbf`]).
pub fn import_data(data: &OsmData, options: &ImportOptions) -> Result<Imported, CityImportError> {
    check_options(options)?;
    let h = options.half_extent_m;
    let c = options.centre;
    let [south, west, north, east] = data.bounds.ok_or(CityImportError::Empty)?;
    if !(south..=north).contains(&c.lat) || !(west..=east).contains(&c.lon) {
        return Err(CityImportError::CentreOutside {
            lat: c.lat,
            lon: c.lon,
            south,
            west,
            north,
            east,
        });
    }
    let frame = LocalFrame::new(c);
    let (buildings, counts) = buildings::buildings(data, &frame, h);
    let (network, cuts) = roads::roads(data, &frame, h, &options.roads, &buildings);

    let mut cut_m: BTreeMap<&'static str, f64> = BTreeMap::new();
    for cut in &cuts {
        *cut_m.entry(cut.reason.name()).or_default() += cut.length_m();
    }
    let drivable_m = network.length_m();
    let cut_total = cut_m.values().fold(0.0, |sum, m| sum + m);
    let mapped_road_m = drivable_m + cut_total;
    if network.edges.is_empty() {
        let reasons = cut_m
            .iter()
            .map(|(name, m)| format!("{name}: {m:.0} m"))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(CityImportError::NoDrivableRoad {
            mapped_m: mapped_road_m,
            cut_m: cut_total,
            reasons: if reasons.is_empty() {
                "none mapped".into()
            } else {
                reasons
            },
        });
    }
    let mut height_sources = [0; 3];
    for b in &buildings {
        let k = match (b.height_tag_m, b.levels) {
            (Some(_), _) => 0,
            (None, Some(_)) => 1,
            (None, None) => 2,
        };
        height_sources[k] += 1;
    }
    let ground_share = buildings.iter().map(|b| b.area()).sum::<f64>() / (4.0 * h * h);
    let flatness_error_m = LocalFrame::flatness_error_m(h);
    let scene = CityScene {
        format: FORMAT_VERSION,
        source: SceneSource {
            osm_file: options
                .osm
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            attribution: OSM_ATTRIBUTION.into(),
            centre: [c.lat, c.lon],
            flatness_error_m,
        },
        half_extent_m: h,
        buildings,
        roads: network,
        cuts,
    };
    Ok(Imported {
        scene,
        report: ImportReport {
            buildings: counts,
            ground_share,
            height_sources,
            mapped_road_m,
            drivable_m,
            cut_m,
            flatness_error_m,
        },
    })
}

fn check_options(o: &ImportOptions) -> Result<(), CityImportError> {
    let option = |option, value: String, expected| CityImportError::Option {
        option,
        value,
        expected,
    };
    if !(o.half_extent_m.is_finite() && (10.0..=5000.0).contains(&o.half_extent_m)) {
        return Err(option(
            "--half-extent",
            o.half_extent_m.to_string(),
            "metres, from 10 to 5000",
        ));
    }
    let c = o.centre;
    if !(c.lat.is_finite() && c.lat.abs() <= 85.0 && c.lon.is_finite() && c.lon.abs() <= 180.0) {
        return Err(option(
            "--center",
            format!("{},{}", c.lat, c.lon),
            "LAT,LON in degrees, latitude within ±85",
        ));
    }
    let r = &o.roads;
    if !(r.border_gap_m.is_finite()
        && r.border_gap_m >= 0.0
        && r.border_gap_m < o.half_extent_m / 2.0)
    {
        return Err(option(
            "border gap",
            r.border_gap_m.to_string(),
            "metres, at least 0 and under a quarter of the square",
        ));
    }
    for (name, v) in [
        ("lane offset", r.lane_offset_m),
        ("clearance", r.clearance_m),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(option(name, v.to_string(), "metres, at least 0"));
        }
    }
    Ok(())
}

impl fmt::Display for ImportReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let b = &self.buildings;
        let [tag, levels, default] = self.height_sources;
        writeln!(
            f,
            "buildings: {} ({} multipolygons, {} courtyards), {} convex parts, {:.1} % of the ground",
            b.kept,
            b.multipolygons,
            b.holes,
            b.parts,
            100.0 * self.ground_share
        )?;
        writeln!(
            f,
            "heights: {tag} from `height`, {levels} from `building:levels`, {default} default"
        )?;
        if b.incomplete + b.broken > 0 {
            writeln!(
                f,
                "skipped: {} buildings with nodes or rings missing; {} with crossing rings kept as their parts",
                b.incomplete, b.broken
            )?;
        }
        writeln!(
            f,
            "roads: {:.0} m drivable of {:.0} m mapped inside the square",
            self.drivable_m, self.mapped_road_m
        )?;
        for (reason, m) in &self.cut_m {
            writeln!(f, "  cut {m:.0} m: {}", cut_why(reason))?;
        }
        write!(
            f,
            "frame: tangent plane at the centre; the ground falls {:.3} m below it at the corners",
            self.flatness_error_m
        )
    }
}

/// What a cut's reason means, for the report.
fn cut_why(reason: &str) -> &'static str {
    match reason {
        "tunnel" => "tunnels (the camera model has nothing that hides a car under ground)",
        "bridge" => "bridges (the camera model has nothing that hides a car under a deck)",
        "layer" => "layer other than 0 (above or below something else)",
        "covered" => "covered (under a roof)",
        "clearance" => "closer to a building than a lane may come",
        _ => "cut off from the rest of the network",
    }
}
