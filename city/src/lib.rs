//! # city
//!
//! Real cities for setfleet: the scene format of a city imported from OpenStreetMap, and the
//! importer that makes it (`fleet city`).
//!
//! - [`scene`]: [`scene::CityScene`], the documented format of `city.json`: buildings as
//!   footprints with convex parts, and the road network cars may use, in a local metric frame.
//!   The world reads it with [`scene::CityScene::read`], which checks what the world relies on.
//! - [`import`] (feature `import`): [`import::import`] reads a PBF file, projects it
//!   ([`projection`]), takes the buildings with their holes ([`convex`] cuts them into convex
//!   prisms), keeps the roads cars use and cuts out every piece closer to a building than a
//!   lane may come, and reports what it did.
//! - [`osm`]: the OpenStreetMap elements the importer reads, from a file or by hand.
//! - [`geometry`]: plane geometry on `[x, y]` points.
//!
//! ```
//! use city::import::{ImportOptions, RoadRules, import_data};
//! use city::osm::{LatLon, OsmData, Tags, Way};
//!
//! // One road, east-west through the centre, and nothing else.
//! let mut data = OsmData::default();
//! data.add_node(1, LatLon { lat: 60.0, lon: 24.99 }, true);
//! data.add_node(2, LatLon { lat: 60.0, lon: 25.01 }, true);
//! data.ways.push(Way { id: 10, nodes: vec![1, 2], tags: Tags::of(&[("highway", "residential")]) });
//! let options = ImportOptions {
//!     osm: "hand-written".into(),
//!     centre: LatLon { lat: 60.0, lon: 25.0 },
//!     half_extent_m: 100.0,
//!     roads: RoadRules { lane_offset_m: 2.8, clearance_m: 6.0, border_gap_m: 2.0 },
//! };
//! let city = import_data(&data, &options)?;
//! // The road crosses the square, less the border gap at each end.
//! assert!((city.report.drivable_m - 196.0).abs() < 0.01);
//! # Ok::<(), city::error::CityImportError>(())
//! ```

pub mod error;
pub mod geometry;
pub mod osm;
pub mod projection;
pub mod scene;

#[cfg(feature = "import")]
pub mod convex;
#[cfg(feature = "import")]
pub mod import;
