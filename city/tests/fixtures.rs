//! The importer on small hand-written maps, laid out in metres about the centre, and on the
//! shipped extract.
#![cfg(feature = "import")]

use city::error::CityImportError;
use city::import::{ImportOptions, Imported, RoadRules, import_data};
use city::osm::{LatLon, Member, OsmData, Relation, Tags, Way};
use city::projection::LocalFrame;
use city::scene::{CutReason, HeightSource};

const CENTRE: LatLon = LatLon {
    lat: 60.17,
    lon: 24.94,
};
const RULES: RoadRules = RoadRules {
    lane_offset_m: 2.8,
    clearance_m: 6.0,
    border_gap_m: 2.0,
};

/// A map written in local metres.
#[derive(Default)]
struct Map {
    data: OsmData,
    next: i64,
}

impl Map {
    fn nodes(&mut self, points: &[[f64; 2]]) -> Vec<i64> {
        let frame = LocalFrame::new(CENTRE);
        points
            .iter()
            .map(|&p| {
                self.next += 1;
                self.data.add_node(self.next, frame.unproject(p), true);
                self.next
            })
            .collect()
    }

    fn way(&mut self, id: i64, points: &[[f64; 2]], closed: bool, tags: &[(&str, &str)]) {
        let mut nodes = self.nodes(points);
        if closed {
            nodes.push(nodes[0]);
        }
        self.data.ways.push(Way {
            id,
            nodes,
            tags: Tags::of(tags),
        });
    }

    /// A residential road along `y = 0` across the whole square, so that every map has one.
    fn with_road(mut self) -> Map {
        self.way(
            900,
            &[[-200.0, -90.0], [200.0, -90.0]],
            false,
            &[("highway", "residential")],
        );
        self
    }

    fn import(&self) -> Result<Imported, CityImportError> {
        import_data(
            &self.data,
            &ImportOptions {
                osm: "fixture".into(),
                centre: CENTRE,
                half_extent_m: 100.0,
                roads: RULES,
            },
        )
    }
}

#[test]
fn an_l_shaped_building_becomes_two_convex_parts() {
    let mut map = Map::default().with_road();
    let l = [
        [0.0, 0.0],
        [20.0, 0.0],
        [20.0, 8.0],
        [8.0, 8.0],
        [8.0, 20.0],
        [0.0, 20.0],
    ];
    map.way(1, &l, true, &[("building", "yes"), ("height", "15")]);
    let city = map.import().unwrap();
    let b = &city.scene.buildings[0];
    assert_eq!(b.osm, "way/1");
    assert_eq!(b.parts.len(), 2);
    assert!((b.area() - 256.0).abs() < 0.01, "{}", b.area());
    assert_eq!(b.height(3.0, 12.0), (15.0, HeightSource::Height));
    city.scene.check().unwrap();
}

#[test]
fn a_courtyard_multipolygon_keeps_its_hole_empty() {
    let mut map = Map::default().with_road();
    // The outline in two pieces, one of them drawn backwards, and the courtyard.
    map.way(
        10,
        &[[-20.0, -20.0], [20.0, -20.0], [20.0, 20.0]],
        false,
        &[],
    );
    let closing = map.data.ways[1].nodes.clone();
    let mut second = map.nodes(&[[-20.0, 20.0]]);
    second.insert(0, closing[2]);
    second.push(closing[0]);
    second.reverse();
    map.data.ways.push(Way {
        id: 11,
        nodes: second,
        tags: Tags::default(),
    });
    map.way(
        12,
        &[[-5.0, -5.0], [-5.0, 5.0], [5.0, 5.0], [5.0, -5.0]],
        true,
        &[],
    );
    map.data.relations.push(Relation {
        id: 7,
        members: vec![
            Member {
                way: 10,
                role: "outer".into(),
            },
            Member {
                way: 11,
                role: "outer".into(),
            },
            Member {
                way: 12,
                role: "inner".into(),
            },
        ],
        tags: Tags::of(&[("type", "multipolygon"), ("building", "apartments")]),
    });
    let city = map.import().unwrap();
    assert_eq!(city.scene.buildings.len(), 1);
    let b = &city.scene.buildings[0];
    assert_eq!(b.osm, "relation/7");
    assert_eq!(b.holes.len(), 1);
    assert!((b.area() - (1600.0 - 100.0)).abs() < 0.01, "{}", b.area());
    for part in &b.parts {
        assert!(!city::geometry::convex_contains(part, [0.0, 0.0]));
    }
    assert_eq!(city.report.buildings.multipolygons, 1);
    assert_eq!(city.report.buildings.holes, 1);
}

#[test]
fn a_building_with_only_levels_takes_the_storey_height() {
    let mut map = Map::default().with_road();
    map.way(
        2,
        &[[30.0, 30.0], [40.0, 30.0], [40.0, 40.0], [30.0, 40.0]],
        true,
        &[("building", "yes"), ("building:levels", "4")],
    );
    map.way(
        3,
        &[[50.0, 30.0], [60.0, 30.0], [60.0, 40.0], [50.0, 40.0]],
        true,
        &[("building", "yes")],
    );
    let city = map.import().unwrap();
    let [levels, plain] = [&city.scene.buildings[0], &city.scene.buildings[1]];
    assert_eq!(levels.height(3.2, 12.0), (4.0 * 3.2, HeightSource::Levels));
    assert_eq!(plain.height(3.2, 12.0), (12.0, HeightSource::Default));
    assert_eq!(city.report.height_sources, [0, 1, 1]);
}

#[test]
fn a_tunnel_is_cut_out_with_its_reason() {
    let mut map = Map::default().with_road();
    map.way(
        20,
        &[[-50.0, 40.0], [50.0, 40.0]],
        false,
        &[("highway", "primary"), ("tunnel", "yes"), ("layer", "-1")],
    );
    let city = map.import().unwrap();
    let tunnel: Vec<_> = city.scene.cuts.iter().filter(|c| c.way == 20).collect();
    assert_eq!(tunnel.len(), 1);
    assert_eq!(tunnel[0].reason, CutReason::Tunnel);
    assert!((city.report.cut_m["tunnel"] - 100.0).abs() < 1e-6);
    assert!(city.scene.roads.edges.iter().all(|e| e.way != 20));
}

#[test]
fn a_road_too_close_to_a_wall_is_cut_there_and_only_there() {
    let mut map = Map::default().with_road();
    // A wall from x = -10 to 10 whose face is 6 m from the road's centreline: closer than the
    // 2.8 m lane offset plus the 6 m clearance (8.8 m).
    map.way(
        4,
        &[[-10.0, 6.0], [10.0, 6.0], [10.0, 16.0], [-10.0, 16.0]],
        true,
        &[("building", "yes")],
    );
    map.way(
        30,
        &[[-60.0, 0.0], [60.0, 0.0]],
        false,
        &[("highway", "residential")],
    );
    let city = map.import().unwrap();
    let (cut, rest): (Vec<_>, Vec<_>) = city
        .scene
        .cuts
        .iter()
        .filter(|c| c.way == 30)
        .partition(|c| matches!(c.reason, CutReason::Clearance { .. }));
    assert_eq!(cut.len(), 1);
    // The two ends no longer meet each other nor the other road: both are cut as unreachable.
    assert_eq!(rest.len(), 2);
    assert!(rest.iter().all(|c| c.reason == CutReason::Unreachable));
    let CutReason::Clearance {
        building,
        closest_m,
    } = &cut[0].reason
    else {
        panic!("{:?}", cut[0].reason)
    };
    assert_eq!(building, "way/4");
    assert!((closest_m - 6.0).abs() < 1e-6);
    // The corners' discs of radius 8.8 m meet the line y = 0 at x = ±(10 + sqrt(8.8² - 6²)).
    let reach = 10.0 + (8.8_f64 * 8.8 - 36.0).sqrt();
    let [a, b] = cut[0].line;
    let (x0, x1) = (a[0].min(b[0]), a[0].max(b[0]));
    assert!(x0 <= -reach && x0 > -reach - 0.05, "{x0}");
    assert!(x1 >= reach && x1 < reach + 0.05, "{x1}");
    // What is left of the road keeps the clearance, and the scene says so.
    city.scene.check().unwrap();
    assert!(city.scene.roads.edges.iter().all(|e| e.way == 900));
}

#[test]
fn a_square_without_roads_is_refused() {
    let mut map = Map::default();
    map.way(
        1,
        &[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]],
        true,
        &[("building", "yes")],
    );
    map.way(
        2,
        &[[-50.0, 50.0], [50.0, 50.0]],
        false,
        &[("highway", "footway")],
    );
    let e = map.import().unwrap_err();
    assert!(matches!(e, CityImportError::NoDrivableRoad { .. }), "{e}");
}

#[test]
fn a_centre_outside_the_data_is_refused() {
    let map = Map::default().with_road();
    let e = import_data(
        &map.data,
        &ImportOptions {
            osm: "fixture".into(),
            centre: LatLon {
                lat: 61.0,
                lon: 24.94,
            },
            half_extent_m: 100.0,
            roads: RULES,
        },
    )
    .unwrap_err();
    assert!(matches!(e, CityImportError::CentreOutside { .. }), "{e}");
}

/// The shipped extract (assets/cities/README.md says how it was made).
fn helsinki() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/cities/helsinki.osm.pbf")
}

#[test]
fn the_shipped_extract_imports_as_it_did() {
    let city = city::import::import(&ImportOptions {
        osm: helsinki(),
        centre: LatLon {
            lat: 60.1716,
            lon: 24.9443,
        },
        half_extent_m: 250.0,
        roads: RULES,
    })
    .unwrap();
    let r = &city.report;
    assert_eq!(
        (
            r.buildings.kept,
            r.buildings.multipolygons,
            r.buildings.holes
        ),
        (78, 8, 11)
    );
    assert_eq!(r.buildings.parts, 492);
    assert_eq!(r.height_sources, [0, 24, 54]);
    assert_eq!((1000.0 * r.ground_share).round(), 391.0);
    assert_eq!(r.drivable_m.round(), 1405.0);
    assert_eq!(r.mapped_road_m.round(), 4147.0);
    city.scene.check().unwrap();
}

#[test]
fn a_file_that_is_not_pbf_is_refused() {
    let path = std::env::temp_dir().join(format!("city-not-pbf-{}.osm.pbf", std::process::id()));
    std::fs::write(&path, "<osm version=\"0.6\"></osm>\n").unwrap();
    let e = city::import::import(&ImportOptions {
        osm: path.clone(),
        centre: CENTRE,
        half_extent_m: 100.0,
        roads: RULES,
    })
    .unwrap_err();
    std::fs::remove_file(&path).unwrap();
    assert!(matches!(e, CityImportError::Read { .. }), "{e}");
}
