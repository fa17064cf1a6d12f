//! Roads from OpenStreetMap: the ways cars use, clipped to the region, with every piece that
//! comes too close to a building cut out, and what stays connected kept.
//!
//! The check is the paper's assumption, made on the data: a car keeps more than `r_s + r_t`
//! from every building. A car's centre stays within the lane offset of its road's centreline
//! (the built-in traffic model keeps it on a lane line, and joins lanes at a junction with
//! straight pieces between points that lie within the lane offset of the junction), so a
//! centreline that keeps the lane offset plus the clearance from every building part keeps
//! every lane point the clearance away.

use std::collections::HashMap;

use crate::geometry::{Xy, dist, lerp, segment_convex_distance, segment_near_convex};
use crate::osm::{OsmData, Tags};
use crate::projection::LocalFrame;
use crate::scene::{CutReason, Oneway, RoadCut, RoadEdge, RoadNetwork, SceneBuilding};

/// Resolution of the cuts' ends, metres: a cut reaches this much beyond the last point found
/// too close.
const CUT_TOLERANCE_M: f64 = 0.01;
/// Kept pieces shorter than this are dropped (they carry no car), metres.
const MIN_PIECE_M: f64 = 1e-3;

/// The `highway` values cars drive on.
const DRIVABLE: [&str; 16] = [
    "motorway",
    "motorway_link",
    "trunk",
    "trunk_link",
    "primary",
    "primary_link",
    "secondary",
    "secondary_link",
    "tertiary",
    "tertiary_link",
    "unclassified",
    "residential",
    "living_street",
    "service",
    "road",
    "busway",
];

/// `service` values that are not through roads for cars.
const NOT_FOR_TRAFFIC: [&str; 5] = [
    "parking_aisle",
    "driveway",
    "drive-through",
    "emergency_access",
    "private",
];

/// How the roads are laid out and how far they keep from buildings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoadRules {
    /// Distance from a road's centreline to each lane's, metres.
    pub lane_offset_m: f64,
    /// The least distance every lane point keeps from every building, metres.
    pub clearance_m: f64,
    /// Roads are clipped to the square `[-h, h]²` with `h` the region's half-extent less this,
    /// metres: at least the lane offset plus half a car's width, so that a car stays inside the
    /// region.
    pub border_gap_m: f64,
}

/// Whether a way is for cars, and if it is, whether it is left out of the network.
#[derive(Clone, Debug, PartialEq)]
enum Kind {
    NotForCars,
    Excluded(CutReason),
    Drivable(Oneway),
}

fn classify(tags: &Tags) -> Kind {
    let Some(highway) = tags.get("highway") else {
        return Kind::NotForCars;
    };
    let no_cars = ["access", "motor_vehicle", "motorcar", "vehicle"]
        .iter()
        .any(|k| matches!(tags.get(k), Some("no" | "private")));
    if !DRIVABLE.contains(&highway)
        || tags.get("area") == Some("yes")
        || no_cars
        || tags
            .get("service")
            .is_some_and(|s| NOT_FOR_TRAFFIC.contains(&s))
    {
        return Kind::NotForCars;
    }
    if tags.is_set("tunnel") {
        return Kind::Excluded(CutReason::Tunnel);
    }
    if tags.is_set("bridge") {
        return Kind::Excluded(CutReason::Bridge);
    }
    if tags
        .get("layer")
        .is_some_and(|l| l.trim().parse::<i32>() != Ok(0))
    {
        return Kind::Excluded(CutReason::Layer);
    }
    if tags.is_set("covered") {
        return Kind::Excluded(CutReason::Covered);
    }
    let oneway = match tags.get("oneway") {
        Some("yes" | "true" | "1") => Oneway::Forward,
        Some("-1" | "reverse") => Oneway::Backward,
        Some(_) => Oneway::No,
        None if tags.get("junction") == Some("roundabout") || highway == "motorway" => {
            Oneway::Forward
        }
        None => Oneway::No,
    };
    Kind::Drivable(oneway)
}

/// A point of the network being built: an OSM node, or a point where a way was clipped or cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Key {
    Node(i64),
    Fresh(usize),
}

/// The drivable network of `data` inside the square `[-h + border_gap, h - border_gap]²`, cut
/// clear of `buildings`, and every piece left out with its reason.
pub fn roads(
    data: &OsmData,
    frame: &LocalFrame,
    h: f64,
    rules: &RoadRules,
    buildings: &[SceneBuilding],
) -> (RoadNetwork, Vec<RoadCut>) {
    let hr = h - rules.border_gap_m;
    let need = rules.lane_offset_m + rules.clearance_m;
    let mut cuts = Vec::new();
    let mut keys: HashMap<Key, u32> = HashMap::new();
    let mut points: Vec<Xy> = Vec::new();
    let mut fresh = 0usize;
    let mut point = |key: Key, at: Xy, keys: &mut HashMap<Key, u32>| -> u32 {
        *keys.entry(key).or_insert_with(|| {
            points.push(at);
            (points.len() - 1) as u32
        })
    };
    let mut edges = Vec::new();
    let parts: Vec<(&SceneBuilding, &Vec<Xy>, [f64; 4])> = buildings
        .iter()
        .flat_map(|b| b.parts.iter().map(move |p| (b, p, bbox(p))))
        .collect();

    for w in &data.ways {
        let kind = classify(&w.tags);
        if kind == Kind::NotForCars {
            continue;
        }
        for pair in w.nodes.windows(2) {
            let (Some(&pa), Some(&pb)) = (data.nodes.get(&pair[0]), data.nodes.get(&pair[1]))
            else {
                continue;
            };
            let (a, b) = (frame.project(pa), frame.project(pb));
            let Some((t0, t1)) = clip_to_square(a, b, hr) else {
                continue;
            };
            let (ca, cb) = (lerp(a, b, t0), lerp(a, b, t1));
            let oneway = match &kind {
                Kind::Excluded(reason) => {
                    cuts.push(RoadCut {
                        line: [ca, cb],
                        way: w.id,
                        reason: reason.clone(),
                    });
                    continue;
                }
                Kind::Drivable(o) => *o,
                Kind::NotForCars => continue,
            };
            // The parameter intervals (of `a b`) too close to some building part.
            let mut near: Vec<(f64, f64, &SceneBuilding)> = Vec::new();
            let seg_box = bbox(&[ca, cb]);
            for (bld, part, pb) in &parts {
                if !boxes_within(&seg_box, pb, need) {
                    continue;
                }
                if let Some((s0, s1)) = segment_near_convex(ca, cb, part, need, CUT_TOLERANCE_M) {
                    near.push((s0, s1, bld));
                }
            }
            near.sort_by(|x, y| x.0.total_cmp(&y.0));
            // Walk along the clipped segment: kept pieces between the merged near intervals.
            let mut kept: Vec<(f64, f64)> = Vec::new();
            let mut cut: Vec<(f64, f64, &SceneBuilding)> = Vec::new();
            let mut at = 0.0;
            for (s0, s1, bld) in near {
                if s0 > at {
                    kept.push((at, s0));
                }
                if s1 > at {
                    cut.push((at.max(s0), s1, bld));
                    at = s1;
                }
            }
            if at < 1.0 {
                kept.push((at, 1.0));
            }
            for (s0, s1, bld) in cut {
                let (p, q) = (lerp(ca, cb, s0), lerp(ca, cb, s1));
                let closest_m = bld
                    .parts
                    .iter()
                    .map(|part| segment_convex_distance(p, q, part))
                    .fold(f64::INFINITY, f64::min);
                cuts.push(RoadCut {
                    line: [p, q],
                    way: w.id,
                    reason: CutReason::Clearance {
                        building: bld.osm.clone(),
                        closest_m,
                    },
                });
            }
            for (s0, s1) in kept {
                let (p, q) = (lerp(ca, cb, s0), lerp(ca, cb, s1));
                if dist(p, q) < MIN_PIECE_M {
                    continue;
                }
                // The search above finds the near intervals to a centimetre; this exact check
                // makes the guarantee independent of it.
                if let Some((closest_m, bld)) = parts
                    .iter()
                    .map(|(bld, part, _)| (segment_convex_distance(p, q, part), bld))
                    .filter(|(d, _)| *d < need)
                    .min_by(|x, y| x.0.total_cmp(&y.0))
                {
                    cuts.push(RoadCut {
                        line: [p, q],
                        way: w.id,
                        reason: CutReason::Clearance {
                            building: bld.osm.clone(),
                            closest_m,
                        },
                    });
                    continue;
                }
                let key = |s: f64, node: i64, fresh: &mut usize| {
                    if s == 0.0 && t0 == 0.0 || s == 1.0 && t1 == 1.0 {
                        Key::Node(node)
                    } else {
                        *fresh += 1;
                        Key::Fresh(*fresh)
                    }
                };
                let ka = key(s0, pair[0], &mut fresh);
                let kb = key(s1, pair[1], &mut fresh);
                let ia = point(ka, p, &mut keys);
                let ib = point(kb, q, &mut keys);
                edges.push(RoadEdge {
                    a: ia,
                    b: ib,
                    way: w.id,
                    highway: w.tags.get("highway").unwrap_or("road").to_string(),
                    oneway,
                });
            }
        }
    }
    let network = RoadNetwork {
        lane_offset_m: rules.lane_offset_m,
        centreline_clearance_m: need,
        points,
        edges,
    };
    let network = keep_largest_component(network, &mut cuts);
    (network, cuts)
}

/// The network's largest connected piece (by length); the other pieces join `cuts` as
/// unreachable, and unused points are dropped.
fn keep_largest_component(net: RoadNetwork, cuts: &mut Vec<RoadCut>) -> RoadNetwork {
    let n = net.points.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for e in &net.edges {
        let (ra, rb) = (
            find(&mut parent, e.a as usize),
            find(&mut parent, e.b as usize),
        );
        parent[ra] = rb;
    }
    let mut lengths: HashMap<usize, f64> = HashMap::new();
    for e in &net.edges {
        let root = find(&mut parent, e.a as usize);
        *lengths.entry(root).or_default() += net.edge_length_m(e);
    }
    let best = lengths
        .iter()
        .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(a.0)))
        .map(|(&root, _)| root);
    let mut index: Vec<Option<u32>> = vec![None; n];
    let mut points = Vec::new();
    let mut edges = Vec::new();
    for e in &net.edges {
        let (a, b) = (net.points[e.a as usize], net.points[e.b as usize]);
        if Some(find(&mut parent, e.a as usize)) != best {
            cuts.push(RoadCut {
                line: [a, b],
                way: e.way,
                reason: CutReason::Unreachable,
            });
            continue;
        }
        let mut id = |i: u32, p: Xy| {
            *index[i as usize].get_or_insert_with(|| {
                points.push(p);
                (points.len() - 1) as u32
            })
        };
        let (ia, ib) = (id(e.a, a), id(e.b, b));
        edges.push(RoadEdge {
            a: ia,
            b: ib,
            ..e.clone()
        });
    }
    RoadNetwork {
        points,
        edges,
        ..net
    }
}

/// The parameter interval of `a b` inside the square `[-h, h]²` (Liang and Barsky), if any.
fn clip_to_square(a: Xy, b: Xy, h: f64) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
    let d = [b[0] - a[0], b[1] - a[1]];
    for axis in 0..2 {
        for (p, q) in [(-d[axis], a[axis] + h), (d[axis], h - a[axis])] {
            if p == 0.0 {
                if q < 0.0 {
                    return None;
                }
            } else {
                let r = q / p;
                if p < 0.0 {
                    t0 = t0.max(r);
                } else {
                    t1 = t1.min(r);
                }
            }
        }
    }
    (t0 < t1).then_some((t0, t1))
}

/// `[min x, min y, max x, max y]` of some points.
fn bbox(points: &[Xy]) -> [f64; 4] {
    points.iter().fold(
        [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ],
        |b, p| {
            [
                b[0].min(p[0]),
                b[1].min(p[1]),
                b[2].max(p[0]),
                b[3].max(p[1]),
            ]
        },
    )
}

/// Whether two boxes come within `d` of each other.
fn boxes_within(a: &[f64; 4], b: &[f64; 4], d: f64) -> bool {
    a[0] - d <= b[2] && b[0] - d <= a[2] && a[1] - d <= b[3] && b[1] - d <= a[3]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ways_are_sorted_by_what_cars_may_use() {
        let kind = |pairs: &[(&str, &str)]| classify(&Tags::of(pairs));
        assert_eq!(
            kind(&[("highway", "residential")]),
            Kind::Drivable(Oneway::No)
        );
        assert_eq!(kind(&[("highway", "footway")]), Kind::NotForCars);
        assert_eq!(kind(&[("highway", "steps")]), Kind::NotForCars);
        assert_eq!(
            kind(&[("highway", "service"), ("service", "parking_aisle")]),
            Kind::NotForCars
        );
        assert_eq!(
            kind(&[("highway", "primary"), ("access", "no")]),
            Kind::NotForCars
        );
        assert_eq!(
            kind(&[("highway", "primary"), ("tunnel", "yes")]),
            Kind::Excluded(CutReason::Tunnel)
        );
        assert_eq!(
            kind(&[("highway", "primary"), ("bridge", "viaduct")]),
            Kind::Excluded(CutReason::Bridge)
        );
        assert_eq!(
            kind(&[("highway", "primary"), ("layer", "-1")]),
            Kind::Excluded(CutReason::Layer)
        );
        assert_eq!(
            kind(&[("highway", "primary"), ("layer", "0")]),
            Kind::Drivable(Oneway::No)
        );
        assert_eq!(
            kind(&[("highway", "primary"), ("tunnel", "no")]),
            Kind::Drivable(Oneway::No)
        );
        assert_eq!(
            kind(&[("highway", "primary"), ("oneway", "-1")]),
            Kind::Drivable(Oneway::Backward)
        );
        assert_eq!(
            kind(&[("highway", "tertiary"), ("junction", "roundabout")]),
            Kind::Drivable(Oneway::Forward)
        );
    }

    #[test]
    fn segments_are_clipped_to_the_square() {
        let (t0, t1) = clip_to_square([-20.0, 0.0], [20.0, 0.0], 10.0).unwrap();
        assert!((t0 - 0.25).abs() < 1e-12 && (t1 - 0.75).abs() < 1e-12);
        assert!(clip_to_square([-20.0, 11.0], [20.0, 11.0], 10.0).is_none());
        assert_eq!(
            clip_to_square([0.0, 0.0], [5.0, 5.0], 10.0),
            Some((0.0, 1.0))
        );
    }
}
