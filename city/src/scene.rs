//! The scene format of an imported city: `city.json`, which `fleet city` writes beside the
//! scenario and the world reads.
//!
//! Coordinates are metres in the local frame of [`crate::projection`]: `x` east, `y` north,
//! the origin at the centre the city was imported around. The region of interest is the
//! square `[-half_extent_m, half_extent_m]²`.
//!
//! - [`CityScene::buildings`]: each building's footprint (outer ring and holes, as mapped)
//!   and its **convex parts**, clipped to the region, which tile the footprint and are what the
//!   world renders and what the roads' clearance is checked against. A building's height is
//!   its `height` tag, else its `building:levels` times a storey height, else a default
//!   ([`SceneBuilding::height`]); the last two are scenario keys, so the scene stores the tags.
//! - [`CityScene::roads`]: the road network cars may use, as points and edges. Every point of
//!   every edge is at least [`RoadNetwork::centreline_clearance_m`] from every building part.
//! - [`CityScene::cuts`]: what the importer left out of the network, and why.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::SceneReadError;
use crate::geometry::{Xy, is_convex_ccw, segment_convex_distance};

/// The format's version; [`CityScene::read`] refuses others.
pub const FORMAT_VERSION: u32 = 1;

/// The largest `city.json` read, bytes.
pub const MAX_SCENE_BYTES: u64 = 256 << 20;

/// Slack allowed when checking coordinates and the clearance, metres: rounding only (JSON
/// numbers round-trip `f64` exactly).
const CHECK_SLACK_M: f64 = 1e-9;

/// An imported city.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CityScene {
    /// [`FORMAT_VERSION`].
    pub format: u32,
    /// Where the data came from.
    pub source: SceneSource,
    /// Half the side of the square region of interest, metres.
    pub half_extent_m: f64,
    /// The buildings.
    pub buildings: Vec<SceneBuilding>,
    /// The road network cars may use.
    pub roads: RoadNetwork,
    /// Road pieces left out of the network.
    pub cuts: Vec<RoadCut>,
}

/// Where an imported city came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneSource {
    /// The OpenStreetMap file's name.
    pub osm_file: String,
    /// The data's attribution, shown with every picture of the city.
    pub attribution: String,
    /// The centre, `[latitude, longitude]` in WGS84 degrees.
    pub centre: [f64; 2],
    /// How the ground falls below the flat frame at the region's corners, metres.
    pub flatness_error_m: f64,
}

/// A building: footprint, convex parts and the tags its height comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneBuilding {
    /// The OSM element, `way/<id>` or `relation/<id>`.
    pub osm: String,
    /// The `height` tag, metres, if it parsed.
    pub height_tag_m: Option<f64>,
    /// The `building:levels` tag, if it parsed.
    pub levels: Option<f64>,
    /// The outer ring as mapped, counter-clockwise (it may reach beyond the region; the parts
    /// are clipped to it).
    pub outer: Vec<Xy>,
    /// The holes (courtyards) as mapped, clockwise.
    pub holes: Vec<Vec<Xy>>,
    /// Convex parts, counter-clockwise, tiling the footprint inside the region.
    pub parts: Vec<Vec<Xy>>,
}

/// Where a building's height came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeightSource {
    /// The `height` tag.
    Height,
    /// `building:levels` times the storey height.
    Levels,
    /// The default height.
    Default,
}

impl SceneBuilding {
    /// The roof's height and where it came from, given the storey height and the default.
    pub fn height(&self, storey_height_m: f64, default_height_m: f64) -> (f64, HeightSource) {
        match (self.height_tag_m, self.levels) {
            (Some(h), _) => (h, HeightSource::Height),
            (None, Some(l)) => (l * storey_height_m, HeightSource::Levels),
            (None, None) => (default_height_m, HeightSource::Default),
        }
    }

    /// The footprint's area inside the region, m².
    pub fn area(&self) -> f64 {
        self.parts
            .iter()
            .map(|p| crate::geometry::signed_area(p))
            .sum()
    }
}

/// The road network: straight edges between points.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RoadNetwork {
    /// Each lane's centreline runs this far from its road's centreline, metres.
    pub lane_offset_m: f64,
    /// The least distance from a road's centreline (an edge) to a building part, metres: the
    /// lane offset plus the clearance every lane point keeps.
    pub centreline_clearance_m: f64,
    /// The points.
    pub points: Vec<Xy>,
    /// The edges.
    pub edges: Vec<RoadEdge>,
}

/// A straight piece of road.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RoadEdge {
    /// Index of its first point.
    pub a: u32,
    /// Index of its second point.
    pub b: u32,
    /// The OSM way it comes from.
    pub way: i64,
    /// The way's `highway` tag.
    pub highway: String,
    /// Which way traffic may go.
    pub oneway: Oneway,
}

/// Which way traffic may go along an edge `a -> b`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Oneway {
    /// Both ways.
    No,
    /// From `a` to `b` only.
    Forward,
    /// From `b` to `a` only.
    Backward,
}

/// A road piece left out of the network.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RoadCut {
    /// The piece's ends.
    pub line: [Xy; 2],
    /// The OSM way it comes from.
    pub way: i64,
    /// Why it was left out.
    pub reason: CutReason,
}

/// Why a road piece was left out.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum CutReason {
    /// A tunnel: nothing in the camera model hides a car under ground.
    Tunnel,
    /// A bridge: nothing in the camera model hides a car under a deck.
    Bridge,
    /// A `layer` other than 0: above or below something else.
    Layer,
    /// `covered=yes`: under a roof.
    Covered,
    /// Closer to a building than a lane may come.
    Clearance {
        /// The building, `way/<id>` or `relation/<id>`.
        building: String,
        /// The road centreline's least distance to it, metres.
        closest_m: f64,
    },
    /// Not connected to the largest piece of the network once the rest was cut.
    Unreachable,
}

impl CutReason {
    /// A short name, for reports.
    pub fn name(&self) -> &'static str {
        match self {
            CutReason::Tunnel => "tunnel",
            CutReason::Bridge => "bridge",
            CutReason::Layer => "layer",
            CutReason::Covered => "covered",
            CutReason::Clearance { .. } => "clearance",
            CutReason::Unreachable => "unreachable",
        }
    }
}

impl RoadCut {
    /// The piece's length, metres.
    pub fn length_m(&self) -> f64 {
        crate::geometry::dist(self.line[0], self.line[1])
    }
}

impl RoadNetwork {
    /// The network's total centreline length, metres.
    pub fn length_m(&self) -> f64 {
        self.edges
            .iter()
            .fold(0.0, |sum, e| sum + self.edge_length_m(e))
    }

    /// One edge's length, metres.
    pub fn edge_length_m(&self, e: &RoadEdge) -> f64 {
        crate::geometry::dist(self.points[e.a as usize], self.points[e.b as usize])
    }
}

impl CityScene {
    /// Reads and checks a scene file.
    pub fn read(path: &Path) -> Result<CityScene, SceneReadError> {
        let io = |e: std::io::Error| SceneReadError::Io {
            path: path.to_path_buf(),
            source: e,
        };
        let size = std::fs::metadata(path).map_err(io)?.len();
        if size > MAX_SCENE_BYTES {
            return Err(SceneReadError::TooLarge {
                path: path.to_path_buf(),
                bytes: size,
            });
        }
        let text = std::fs::read_to_string(path).map_err(io)?;
        let scene: CityScene = serde_json::from_str(&text).map_err(|e| SceneReadError::Parse {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        scene.check().map_err(|reason| SceneReadError::Invalid {
            path: path.to_path_buf(),
            reason,
        })?;
        Ok(scene)
    }

    /// Writes the scene as JSON.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let text = serde_json::to_string(self).map_err(std::io::Error::other)?;
        std::fs::write(path, text)
    }

    /// Checks what the world relies on: the version, finite coordinates inside the region,
    /// convex parts, edges between existing points, and every edge's clearance from every part.
    pub fn check(&self) -> Result<(), String> {
        if self.format != FORMAT_VERSION {
            return Err(format!(
                "format {} (this build reads {FORMAT_VERSION})",
                self.format
            ));
        }
        let h = self.half_extent_m;
        if !(h.is_finite() && h > 0.0) {
            return Err(format!("half_extent_m = {h}: must be a positive number"));
        }
        let inside = |p: &Xy| {
            p.iter()
                .all(|c| c.is_finite() && c.abs() <= h + CHECK_SLACK_M)
        };
        for b in &self.buildings {
            for (what, v) in [("height_tag_m", b.height_tag_m), ("levels", b.levels)] {
                if v.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
                    return Err(format!(
                        "building {}: {what} must be a positive number",
                        b.osm
                    ));
                }
            }
            if b.parts.is_empty() {
                return Err(format!("building {}: no parts", b.osm));
            }
            for part in &b.parts {
                if !part.iter().all(inside) {
                    return Err(format!("building {}: a part leaves the region", b.osm));
                }
                if !is_convex_ccw(part) {
                    return Err(format!(
                        "building {}: a part is not convex and counter-clockwise",
                        b.osm
                    ));
                }
            }
        }
        let roads = &self.roads;
        if !roads.points.iter().all(inside) {
            return Err("a road point lies outside the region".into());
        }
        let n = roads.points.len();
        for e in &roads.edges {
            if e.a as usize >= n || e.b as usize >= n || e.a == e.b {
                return Err(format!(
                    "road edge {}-{} (way {}): no such points",
                    e.a, e.b, e.way
                ));
            }
        }
        // The importer's guarantee, checked rather than assumed from the file.
        for e in &roads.edges {
            let (a, b) = (roads.points[e.a as usize], roads.points[e.b as usize]);
            for bld in &self.buildings {
                for part in &bld.parts {
                    let d = segment_convex_distance(a, b, part);
                    if d < roads.centreline_clearance_m - CHECK_SLACK_M {
                        return Err(format!(
                            "a road edge of way {} passes {d:.3} m from building {} (at least {:.3} m)",
                            e.way, bld.osm, roads.centreline_clearance_m
                        ));
                    }
                }
            }
        }
        Ok(())
    }
}
