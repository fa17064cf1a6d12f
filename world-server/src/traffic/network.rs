//! Cars on an imported city's road network (`city::scene::RoadNetwork`): the built-in
//! traffic model of a real city.
//!
//! Every road has a lane each way, `RoadNetwork::lane_offset_m` to the right of its
//! centreline (the model drives both ways on every road; `oneway` tags are the SUMO model's
//! to keep). A car drives to the end of its lane, then straight to the start of a lane that
//! leaves the same point, chosen at random among the roads that continue there; at a dead end
//! it turns around onto the other lane of its road. Speeds, stops and the separation are the
//! grid's ([`crate::traffic::Traffic::step`]).
//!
//! **Zones.** Where two cars on different roads could come closer than the separation (at
//! junctions, where roads branch or merge, at sharp bends and dead ends, between roads that
//! meet at a narrow angle), two cars could block each other for good. The network finds those
//! places from its geometry (`Zones`): every point of a path closer than the separation plus
//! a margin to a point of another road (a point it cannot follow, or be followed from, along
//! one road without a branch) is a zone's, and so is every stretch between zones shorter than
//! that, so that a car outside the zones can only be held up by the car ahead of it on its
//! road, and always has room to wait.
//!
//! A car enters a zone only with a **way through**: the zones its path crosses until it
//! leaves them (planned that far before it enters) are held by no other car, and the point
//! where it leaves them is the separation away from every other car and from where every
//! other car inside the zones will leave them. Inside, nobody can come in its way, so it
//! leaves in a bounded time. A blocked car waits: it never turns around in the road.
//!
//! Guarantees, by construction:
//! - **Clearance.** A lane point is the lane offset from a point of its road's centreline, and
//!   a connector joins two lane ends that are each the lane offset from the same network
//!   point, so every point a car's centre reaches is within the lane offset of the centreline
//!   network (a disc is convex). The importer keeps every centreline the lane offset plus
//!   `targets.building_clearance_m` from every building part, so a car's centre keeps the
//!   clearance. The region's border is kept the same way: centrelines end the road's half
//!   width plus 2 m inside it.
//! - **Speed and separation** are the grid's: a car moves at most `v_max dt` along its path
//!   in a step, and only to a point the car separation away from every other car.
//!
//! **Liveness is measured, not guaranteed.** Cars can still jam when a loop of roads fills
//! with queued cars. On the shipped Helsinki square (8 cars on 1.4 km of road), every car
//! drove at least 370 m in 1,000 s on each of seeds 1 to 30 (`world-server/tests/traffic.rs`
//! tests seeds 1 to 3).

use city::scene::RoadNetwork;
use protocol::scenario::Scenario;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use sets::math::{Point2, Real, Vector2};

use super::{Car, EPS, RoadModel, Traffic, Waypoint};
use crate::error::WorldBuildError;

/// A lane: edge `edge` of the network, driven from its point `a` to `b` (`forward`) or back.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct NetLane {
    /// Index of the edge.
    pub edge: u32,
    /// Whether the lane runs from the edge's `a` to its `b`.
    pub forward: bool,
}

impl NetLane {
    /// The lane of the same road the other way.
    pub fn opposite(self) -> NetLane {
        NetLane {
            forward: !self.forward,
            ..self
        }
    }
}

/// The road network as the cars drive it.
#[derive(Clone, Debug)]
pub struct LaneNetwork {
    points: Vec<Point2>,
    edges: Vec<[u32; 2]>,
    /// Per point, the edges that meet there.
    incident: Vec<Vec<u32>>,
    lane_offset: Real,
    car_separation: Real,
    /// Where cars on different lanes can come closer than the separation.
    zones: Zones,
}

impl LaneNetwork {
    /// The network of an imported city, for cars kept `car_separation` apart.
    pub fn new(net: &RoadNetwork, car_separation: Real) -> LaneNetwork {
        let points: Vec<Point2> = net.points.iter().map(|p| Point2::new(p[0], p[1])).collect();
        let mut incident = vec![Vec::new(); points.len()];
        let mut edges = Vec::with_capacity(net.edges.len());
        for e in &net.edges {
            let k = edges.len() as u32;
            incident[e.a as usize].push(k);
            incident[e.b as usize].push(k);
            edges.push([e.a, e.b]);
        }
        LaneNetwork {
            points,
            edges,
            incident,
            lane_offset: net.lane_offset_m,
            car_separation,
            zones: Zones::default(),
        }
        .with_zones()
    }

    /// The roads' centrelines: each edge's two ends.
    pub fn centrelines(&self) -> impl Iterator<Item = (Point2, Point2)> + '_ {
        (self.edges.iter()).map(|&[a, b]| (self.points[a as usize], self.points[b as usize]))
    }

    /// The network with its conflict zones found ([`Zones`]).
    fn with_zones(mut self) -> LaneNetwork {
        self.zones = Zones::find(&self.paths(), self.car_separation + ZONE_MARGIN_M);
        self
    }

    /// Every path a car can follow: each lane, and each connector from a lane's end to the
    /// start of a lane leaving the same point (the other lane of the same road only at a
    /// dead end), with the paths each leads into.
    fn paths(&self) -> Vec<Path> {
        let mut paths = Vec::new();
        let mut lane_index = std::collections::HashMap::new();
        for edge in 0..self.edges.len() as u32 {
            for forward in [true, false] {
                let lane = NetLane { edge, forward };
                lane_index.insert(lane, paths.len());
                paths.push(Path {
                    from: self.lane_point(lane, 0.0),
                    to: self.lane_point(lane, Real::INFINITY),
                    next: Vec::new(),
                });
            }
        }
        for edge in 0..self.edges.len() as u32 {
            for forward in [true, false] {
                let lane = NetLane { edge, forward };
                for next in self.next_lanes(lane) {
                    let k = paths.len();
                    paths.push(Path {
                        from: self.lane_point(lane, Real::INFINITY),
                        to: self.lane_point(next, 0.0),
                        next: vec![lane_index[&next]],
                    });
                    paths[lane_index[&lane]].next.push(k);
                }
            }
        }
        paths
    }

    /// The lanes a car at the end of `lane` may take: the other roads at that point, or the
    /// other lane of its road at a dead end.
    fn next_lanes(&self, lane: NetLane) -> Vec<NetLane> {
        let (_, node) = self.ends(lane);
        let options: Vec<NetLane> = self.incident[node as usize]
            .iter()
            .filter(|&&edge| edge != lane.edge)
            .map(|&edge| NetLane {
                edge,
                forward: self.edges[edge as usize][0] == node,
            })
            .collect();
        if options.is_empty() {
            vec![lane.opposite()]
        } else {
            options
        }
    }

    /// The conflict zone holding `p`, if any.
    fn zone_at(&self, p: &Point2) -> Option<u32> {
        self.zones.at(p)
    }

    /// The points a lane runs from and to.
    fn ends(&self, lane: NetLane) -> (u32, u32) {
        let [a, b] = self.edges[lane.edge as usize];
        if lane.forward { (a, b) } else { (b, a) }
    }

    /// The lane's centreline: start, unit direction, length.
    fn centreline(&self, lane: NetLane) -> (Point2, Vector2, Real) {
        let (from, to) = self.ends(lane);
        let (p, q) = (self.points[from as usize], self.points[to as usize]);
        let d = q - p;
        let len = d.norm();
        let dir = if len > 0.0 { d / len } else { Vector2::x() };
        (p, dir, len)
    }

    /// The lane's point `s` metres from its start (clamped to the lane).
    fn lane_point(&self, lane: NetLane, s: Real) -> Point2 {
        let (p, dir, len) = self.centreline(lane);
        let right = Vector2::new(dir.y, -dir.x);
        p + dir * s.clamp(0.0, len) + right * self.lane_offset
    }

    /// The lane's length.
    fn length(&self, lane: NetLane) -> Real {
        self.centreline(lane).2
    }

    /// Places `targets.count` cars at random on the lanes (edges drawn by length), at least the
    /// car separation apart, with cruise speeds drawn as on the grid. `rng` draws the
    /// placements, the cruise speeds per car and the turns; `speeds` the speeds per step and
    /// the stops.
    pub fn place(
        &self,
        scenario: &Scenario,
        rng: ChaCha8Rng,
        speeds: ChaCha8Rng,
    ) -> Result<Traffic<NetLane>, WorldBuildError> {
        let lengths: Vec<Real> = (0..self.edges.len() as u32)
            .map(|edge| {
                self.length(NetLane {
                    edge,
                    forward: true,
                })
            })
            .collect();
        let total: Real = lengths.iter().sum();
        if total.is_nan() || total <= 0.0 {
            return Err(WorldBuildError::Placement(
                "the road network has no length".into(),
            ));
        }
        let roads = format!("the city's {total:.0} m of road");
        Traffic::place_with(scenario, self.car_separation, &roads, rng, speeds, |rng| {
            let mut at = rng.random::<Real>() * total;
            let edge = lengths
                .iter()
                .position(|&l| {
                    at -= l;
                    at < 0.0
                })
                .unwrap_or(lengths.len() - 1) as u32;
            let lane = NetLane {
                edge,
                forward: rng.random_bool(0.5),
            };
            let (_, dir, len) = self.centreline(lane);
            let p = self.lane_point(lane, rng.random_range(0.0..=len));
            self.zone_at(&p)
                .is_none()
                .then(|| (p, dir.y.atan2(dir.x), lane))
        })
    }
}

impl RoadModel<NetLane> for LaneNetwork {
    fn car_separation(&self) -> Real {
        self.car_separation
    }

    /// To the end of the lane, then to the start of a lane leaving that point: one of the other
    /// roads there at random, or the other lane of the same road at a dead end.
    fn plan(&self, car: &mut Car<NetLane>, rng: &mut ChaCha8Rng) {
        let (_, lane) = car.path_end();
        car.path.push_back(Waypoint {
            point: self.lane_point(lane, Real::INFINITY),
            lane,
        });
        let options = self.next_lanes(lane);
        let next = options[rng.random_range(0..options.len())];
        car.path.push_back(Waypoint {
            point: self.lane_point(next, 0.0),
            lane: next,
        });
    }

    /// A car outside the zones enters one only with a way through: the zones its path crosses
    /// before it leaves them again are held by no other car, and the point where it leaves
    /// them is the separation away from every other car and from where every other car inside
    /// the zones will leave them. A car inside keeps going.
    fn admits(&self, cars: &[Car<NetLane>], i: usize, to: &Point2) -> bool {
        if self.zone_at(to).is_none() || self.zone_at(&cars[i].position).is_some() {
            return true;
        }
        let WayThrough::Through { exit, zones } = self.way_through(&cars[i]) else {
            return false;
        };
        let room = self.car_separation + EPS;
        cars.iter().enumerate().all(|(k, c)| {
            if k == i {
                return true;
            }
            if (c.position - exit).norm() < room {
                return false;
            }
            if self.zone_at(&c.position).is_none() {
                return true;
            }
            match self.way_through(c) {
                WayThrough::Through {
                    exit: theirs,
                    zones: held,
                } => (theirs - exit).norm() >= room && held.iter().all(|z| !zones.contains(z)),
                // Cannot happen to a car that entered with a way through; held back anyway.
                WayThrough::NoZone | WayThrough::Unknown => false,
            }
        })
    }

    /// A car plans on until its path leaves every zone it enters, so that its way through is
    /// known before it enters.
    fn plans_further(&self, car: &Car<NetLane>) -> bool {
        matches!(self.way_through(car), WayThrough::Unknown)
    }

    /// A blocked car waits rather than turning around in the road: a car halfway across its
    /// road blocks both lanes, and cars turning around in a queue block each other.
    fn turn_around(&self, _car: &mut Car<NetLane>, _others: &[Point2]) {}
}

/// What lies on a car's planned path: no zone within its reach, or the zones it crosses and
/// where it leaves them, or a path that ends inside a zone.
#[derive(Clone, Debug, PartialEq)]
enum WayThrough {
    /// No zone before the path has run [`LOOKAHEAD_M`] outside them.
    NoZone,
    /// The zones the path crosses from its start, and its first point outside them after.
    Through { exit: Point2, zones: Vec<u32> },
    /// The path ends inside a zone.
    Unknown,
}

/// How far a path is searched for a zone ahead, metres: more than a step's travel.
const LOOKAHEAD_M: Real = 8.0;
/// Step of the walk along a path that finds its zones, metres (under a sample spacing).
const WALK_M: Real = 0.05;

impl LaneNetwork {
    /// The zones `car`'s path crosses from where the car is, and where it leaves them.
    fn way_through(&self, car: &Car<NetLane>) -> WayThrough {
        let mut zones: Vec<u32> = Vec::new();
        let mut outside = 0.0;
        let mut from = car.position;
        let points = std::iter::once((from, 0.0)).chain(car.path.iter().flat_map(|w| {
            let (a, b) = (from, w.point);
            from = b;
            let len = (b - a).norm();
            let n = (len / WALK_M).ceil() as usize;
            (1..=n).map(move |k| (a + (b - a) * (k as Real / n as Real), len / n as Real))
        }));
        for (p, step) in points {
            match self.zone_at(&p) {
                Some(z) => {
                    if !zones.contains(&z) {
                        zones.push(z);
                    }
                }
                None if !zones.is_empty() => return WayThrough::Through { exit: p, zones },
                None => {
                    outside += step;
                    if outside > LOOKAHEAD_M {
                        return WayThrough::NoZone;
                    }
                }
            }
        }
        if zones.is_empty() {
            WayThrough::NoZone
        } else {
            WayThrough::Unknown
        }
    }
}

/// Conflicts are taken this much beyond the separation, metres.
const ZONE_MARGIN_M: Real = 0.25;
/// Spacing of the samples along the paths that find the zones, metres.
const SAMPLE_M: Real = 0.1;

/// A piece a car can drive: a lane or a connector, straight from `from` to `to`.
#[derive(Clone, Debug)]
struct Path {
    from: Point2,
    to: Point2,
    /// The paths it leads into.
    next: Vec<usize>,
}

/// The conflict zones: where two cars that are not following each other on one path can come
/// closer than the separation.
///
/// Every path is sampled every [`SAMPLE_M`]. Two samples conflict when they are closer than
/// `reach` unless one can follow the other within `reach` along the paths (a car and the car
/// behind it, which the separation keeps apart without any zone). Conflicting samples, and
/// samples within a spacing of each other on one path, are joined into zones.
#[derive(Clone, Debug, Default)]
struct Zones {
    /// Conflicting samples by grid cell of side `reach`: point and zone.
    cells: std::collections::HashMap<(i64, i64), Vec<(Point2, u32)>>,
}

/// Side of the cells [`Zones::at`] looks a point up in, metres: a sample spacing, so that a
/// lookup reads the few samples around the point.
const LOOKUP_CELL_M: Real = SAMPLE_M;

/// The lookup cell of a point.
fn lookup_cell(p: &Point2) -> (i64, i64) {
    (
        (p.x / LOOKUP_CELL_M).floor() as i64,
        (p.y / LOOKUP_CELL_M).floor() as i64,
    )
}

/// Makes the zones cover every stretch of path shorter than `gap` between two zone samples
/// (along the paths, either way at a junction), so that outside the zones a car is always on
/// a stretch long enough to wait on without standing in the way of a car leaving a zone.
/// `samples` are in path order, each path's from its start to its end.
fn fill_short_gaps(
    paths: &[Path],
    samples: &[(Point2, usize, Real)],
    conflict: &mut [bool],
    gap: Real,
) {
    let n = samples.len();
    let first: Vec<usize> = (0..paths.len())
        .map(|k| samples.partition_point(|x| x.1 < k))
        .collect();
    let last = |k: usize| first.get(k + 1).copied().unwrap_or(n) - 1;
    let mut predecessors = vec![Vec::new(); paths.len()];
    for (k, p) in paths.iter().enumerate() {
        for &m in &p.next {
            predecessors[m].push(k);
        }
    }
    // Distance along the paths to the nearest zone sample ahead and behind, up to `gap`.
    let (mut ahead, mut behind) = (vec![Real::INFINITY; n], vec![Real::INFINITY; n]);
    // One pass along a path's samples in `order`, `d` coming in from the path before: each
    // sample's distance is the least of its own and the last one's plus the spacing (0 on a
    // zone sample). Whether any shrank.
    let relax = |dist: &mut [Real], order: &mut dyn Iterator<Item = usize>, mut d: Real| {
        let (mut changed, mut last_i): (bool, Option<usize>) = (false, None);
        for i in order {
            if let Some(j) = last_i {
                let step: Real = samples[i].2 - samples[j].2;
                d += step.abs();
                if d >= gap {
                    d = Real::INFINITY;
                }
            }
            if conflict[i] {
                d = 0.0;
            }
            if d < dist[i] {
                dist[i] = d;
                changed = true;
            }
            d = dist[i];
            last_i = Some(i);
        }
        changed
    };
    let mut changed = true;
    while changed {
        changed = false;
        for (k, p) in paths.iter().enumerate() {
            let (a, b) = (first[k], last(k));
            let from_next = (p.next.iter()).map(|&m| ahead[first[m]]);
            let d = from_next.fold(Real::INFINITY, Real::min);
            changed |= relax(&mut ahead, &mut (a..=b).rev(), d);
            let from_previous = (predecessors[k].iter()).map(|&m| behind[last(m)]);
            let d = from_previous.fold(Real::INFINITY, Real::min);
            changed |= relax(&mut behind, &mut (a..=b), d);
        }
    }
    for i in 0..n {
        if !conflict[i] && ahead[i] + behind[i] < gap {
            conflict[i] = true;
        }
    }
}

impl Zones {
    fn find(paths: &[Path], reach: Real) -> Zones {
        // Samples: (point, path, distance along it).
        let mut samples: Vec<(Point2, usize, Real)> = Vec::new();
        for (k, p) in paths.iter().enumerate() {
            let len = (p.to - p.from).norm();
            let n = (len / SAMPLE_M).ceil().max(1.0) as usize;
            for i in 0..=n {
                let s = len * i as Real / n as Real;
                let t = if len > 0.0 { s / len } else { 0.0 };
                samples.push((p.from + (p.to - p.from) * t, k, s));
            }
        }
        let lengths: Vec<Real> = paths.iter().map(|p| (p.to - p.from).norm()).collect();
        let cell = |p: &Point2| ((p.x / reach).floor() as i64, (p.y / reach).floor() as i64);
        let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> = Default::default();
        for (i, (p, _, _)) in samples.iter().enumerate() {
            grid.entry(cell(p)).or_default().push(i);
        }
        // A path's successor when the two make one road with no other way in or out: a
        // lane and the connector after it at a bend or a dead end, and that connector and the
        // lane it leads into.
        let mut predecessors = vec![0usize; paths.len()];
        for p in paths {
            for &n in &p.next {
                predecessors[n] += 1;
            }
        }
        let linear_next: Vec<Option<usize>> = paths
            .iter()
            .map(|p| match p.next[..] {
                [n] if predecessors[n] == 1 => Some(n),
                _ => None,
            })
            .collect();
        // The distance along one road from sample x forward to sample y, if under `reach`.
        let along = |x: &(Point2, usize, Real), y: &(Point2, usize, Real)| -> Real {
            if x.1 == y.1 && y.2 >= x.2 {
                return y.2 - x.2;
            }
            let (mut k, mut done) = (x.1, lengths[x.1] - x.2);
            while done < reach {
                let Some(n) = linear_next[k] else {
                    break;
                };
                if n == y.1 {
                    return done + y.2;
                }
                if n == x.1 {
                    break;
                }
                (k, done) = (n, done + lengths[n]);
            }
            Real::INFINITY
        };
        // Whether one of the two can follow the other within `reach` along one road (a car
        // and the car behind it, which the separation keeps apart without any zone). Where
        // roads branch or merge, it cannot: the points near a junction are the junction's.
        let follows = |a: &(Point2, usize, Real), b: &(Point2, usize, Real)| {
            along(a, b).min(along(b, a)) < reach
        };
        let mut parent: Vec<usize> = (0..samples.len()).collect();
        fn root(parent: &mut [usize], mut x: usize) -> usize {
            while parent[x] != x {
                parent[x] = parent[parent[x]];
                x = parent[x];
            }
            x
        }
        let mut conflict = vec![false; samples.len()];
        for (i, a) in samples.iter().enumerate() {
            let (cx, cy) = cell(&a.0);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    let Some(near) = grid.get(&(cx + dx, cy + dy)) else {
                        continue;
                    };
                    for &j in near {
                        if j <= i {
                            continue;
                        }
                        let b = &samples[j];
                        if (a.0 - b.0).norm() < reach && !follows(a, b) {
                            conflict[i] = true;
                            conflict[j] = true;
                            let (ri, rj) = (root(&mut parent, i), root(&mut parent, j));
                            parent[ri] = rj;
                        }
                    }
                }
            }
        }
        fill_short_gaps(paths, &samples, &mut conflict, reach);
        // Conflicting samples next to each other on a path, or where a path leads into the
        // next, are one zone.
        let first: Vec<usize> = (0..paths.len())
            .map(|k| samples.partition_point(|x| x.1 < k))
            .collect();
        for i in 1..samples.len() {
            if conflict[i] && conflict[i - 1] && samples[i].1 == samples[i - 1].1 {
                let (ri, rj) = (root(&mut parent, i), root(&mut parent, i - 1));
                parent[ri] = rj;
            }
        }
        for (k, p) in paths.iter().enumerate() {
            let end = first.get(k + 1).copied().unwrap_or(samples.len()) - 1;
            for &n in &p.next {
                if conflict[end] && conflict[first[n]] {
                    let (ri, rj) = (root(&mut parent, end), root(&mut parent, first[n]));
                    parent[ri] = rj;
                }
            }
        }
        let mut ids = std::collections::HashMap::new();
        let mut cells: std::collections::HashMap<(i64, i64), Vec<(Point2, u32)>> =
            Default::default();
        for i in 0..samples.len() {
            if !conflict[i] {
                continue;
            }
            let r = root(&mut parent, i);
            let next = ids.len() as u32;
            let id = *ids.entry(r).or_insert(next);
            cells
                .entry(lookup_cell(&samples[i].0))
                .or_default()
                .push((samples[i].0, id));
        }
        Zones { cells }
    }

    /// The zone of the conflicting sample nearest `p` within half a sample spacing, if any.
    fn at(&self, p: &Point2) -> Option<u32> {
        let (cx, cy) = lookup_cell(p);
        let mut best: Option<(Real, u32)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for (q, id) in self.cells.get(&(cx + dx, cy + dy)).into_iter().flatten() {
                    let d = (q - p).norm();
                    if d <= SAMPLE_M / 2.0 + 1e-9 && best.is_none_or(|(bd, _)| d < bd) {
                        best = Some((d, *id));
                    }
                }
            }
        }
        best.map(|(_, id)| id)
    }
}

#[cfg(test)]
mod tests {
    use city::scene::{Oneway, RoadEdge};
    use rand::SeedableRng;

    use super::*;

    /// A loop of four roads, a diagonal across it, a spur to a dead end and a crooked road
    /// leaving a corner at 16°, as an import makes them (one edge per piece of way).
    fn network() -> RoadNetwork {
        // About 1.4 km of road, as much as the shipped Helsinki square keeps.
        let points = vec![
            [-120.0, -120.0],
            [120.0, -120.0],
            [120.0, 120.0],
            [-120.0, 120.0],
            [200.0, 120.0],
            [20.0, 160.0],
            [-40.0, 190.0],
        ];
        let pairs = [
            (0, 1),
            (1, 2),
            (2, 3),
            (3, 0),
            (0, 2),
            (2, 4),
            (3, 5),
            (5, 6),
        ];
        RoadNetwork {
            lane_offset_m: 2.8,
            centreline_clearance_m: 8.8,
            points,
            edges: pairs
                .iter()
                .enumerate()
                .map(|(k, &(a, b))| RoadEdge {
                    a,
                    b,
                    way: k as i64,
                    highway: "residential".into(),
                    oneway: Oneway::No,
                })
                .collect(),
        }
    }

    fn distance_to_network(net: &RoadNetwork, p: &Point2) -> Real {
        net.edges
            .iter()
            .map(|e| {
                let (a, b) = (net.points[e.a as usize], net.points[e.b as usize]);
                city::geometry::point_segment_distance([p.x, p.y], a, b)
            })
            .fold(Real::INFINITY, Real::min)
    }

    fn traffic(seed: u64, count: u32) -> Result<(LaneNetwork, Traffic<NetLane>), WorldBuildError> {
        let mut scenario = Scenario::default();
        scenario.targets.count = count;
        let lanes = LaneNetwork::new(&network(), 5.1);
        let rng = ChaCha8Rng::seed_from_u64(seed);
        let mut speeds = ChaCha8Rng::seed_from_u64(seed);
        speeds.set_stream(3);
        let traffic = lanes.place(&scenario, rng, speeds)?;
        Ok((lanes, traffic))
    }

    #[test]
    fn cars_keep_to_the_lanes_their_speed_and_their_distance() {
        for seed in 1..=12 {
            drive(seed, 8);
        }
        drive(3, 12);
    }

    fn drive(seed: u64, count: u32) {
        let net = network();
        let (lanes, mut traffic) = traffic(seed, count).unwrap();
        let dt = 0.5;
        let v_max = Scenario::default().targets.max_speed_mps;
        let start: Vec<Point2> = traffic.cars().iter().map(|c| c.position).collect();
        let mut travelled = vec![0.0; count as usize];
        for _ in 0..2_000 {
            let before: Vec<Point2> = traffic.cars().iter().map(|c| c.position).collect();
            traffic.step(&lanes, dt);
            let cars = traffic.cars();
            for (i, c) in cars.iter().enumerate() {
                let moved = (c.position - before[i]).norm();
                assert!(moved <= v_max * dt + 1e-9, "car {i} moved {moved} m");
                travelled[i] += moved;
                let off = distance_to_network(&net, &c.position);
                assert!(
                    off <= net.lane_offset_m + 1e-9,
                    "car {i} is {off} m from every centreline"
                );
                for d in &cars[i + 1..] {
                    assert!(
                        (c.position - d.position).norm() >= 5.1,
                        "cars {i} and {} too close",
                        d.id
                    );
                }
            }
        }
        // Every car got somewhere: the spur's dead end and the junctions do not trap them.
        for (i, t) in travelled.iter().enumerate() {
            assert!(
                *t > 200.0,
                "seed {seed}: car {i} travelled {t} m from {:?}",
                start[i]
            );
        }
    }

    #[test]
    fn the_same_seed_drives_the_same_cars() {
        let run = |seed| {
            let (lanes, mut traffic) = traffic(seed, 6).unwrap();
            for _ in 0..300 {
                traffic.step(&lanes, 0.5);
            }
            traffic
                .cars()
                .iter()
                .map(|c| (c.position, c.heading))
                .collect::<Vec<_>>()
        };
        assert_eq!(run(11), run(11));
        assert_ne!(run(11), run(12));
    }

    #[test]
    fn more_cars_than_the_roads_hold_apart_are_refused() {
        match traffic(1, 2_000) {
            Err(WorldBuildError::Placement(m)) => assert!(m.contains("cannot place car"), "{m}"),
            other => panic!("{:?}", other.map(|_| ())),
        }
    }
}
