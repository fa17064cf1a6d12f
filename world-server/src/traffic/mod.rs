//! The cars: placed on lanes, driving at their own cruise speed, turning at random at
//! intersections, keeping their distances, and stopping at random if the scenario asks.
//!
//! A car's cruise speed is `v_max (1 - cruise_spread u)`, `u` uniform in `[0, 1)`, drawn once
//! per car or again at every step (`targets.speed_draw`). With `targets.stops_per_min > 0`
//! a car not already stopped stops at each step with probability `stops_per_min * dt / 60`
//! and stands still for a time uniform in `targets.stop_s`. Speeds and stops come from a
//! random stream of their own, so the default (speeds per car, no stops) draws exactly what
//! it always drew.
//!
//! Guarantees, by construction:
//! - a car's centre is always on a lane centreline, or, during a U-turn, on the straight
//!   segment across its road joining its two lanes; together with the city's invariant
//!   ([`crate::scene`]) it stays more than `r_s + r_t` from every building, on the roads, and
//!   inside the RoI (the ring road runs inside the border);
//! - a car never travels more than `cruise * dt <= v_max * dt` along its path in a step, so
//!   its displacement per step never exceeds `v_max * dt`;
//! - at every step, any two cars' centres are at least [`crate::scene::RoadProfile::car_separation`]
//!   (`max(r_s, car length) + margin`) apart: cars move one after the other, and a car only
//!   takes a move (full, or shortened) that keeps that distance to every other car's latest
//!   position, otherwise it waits. A car blocked for [`DEADLOCK_STEPS`] steps turns around
//!   onto its road's other lane, which breaks the rare gridlock at an intersection.
//!
//! A known limit: turning around does not free every gridlock. Where a road meets the ring
//! road, a car halfway through its turn and a car on the ring can block each other's moves and
//! turn-arounds alike; on seed 6 of the default scenario (the only one of seeds 1-60), cars 1
//! and 5 stand so from 57 s to the end of the run. Nothing the estimator proves depends on the
//! cars moving; that seed's metrics see two parked cars.

/// Cars on an imported city's road network.
pub mod network;
/// Cars driven by SUMO.
pub mod sumo;
/// Cars driven by a recorded trace.
pub mod trace;

use std::collections::VecDeque;
use std::sync::Arc;

use protocol::scenario::{Scenario, SpeedDraw};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use sets::math::{Point2, Real};

use crate::error::WorldBuildError;
use crate::scene::{Axis, Lane, RoadGrid, Roads};
use network::{LaneNetwork, NetLane};
use trace::TraceCars;

/// Steps a car waits, blocked, before turning around.
pub const DEADLOCK_STEPS: u32 = 20;
/// Random placements tried per car before giving up.
const PLACEMENT_TRIES: usize = 10_000;
/// Shares of the full move tried, in order, when the full move comes too close to a car.
const MOVE_SHARES: [Real; 4] = [1.0, 0.75, 0.5, 0.25];
/// Tolerance on coordinates along a lane, well below any distance that matters.
const EPS: Real = 1e-6;

/// A point of a car's planned path, and the lane the car is on once it gets there.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Waypoint<L> {
    point: Point2,
    lane: L,
}

/// One car, on the lanes `L` of its road model: the grid's [`Lane`]s, or a road network's
/// ([`network`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Car<L = Lane> {
    /// Target id (its index).
    pub id: u32,
    /// Ground point under the car's centre.
    pub position: Point2,
    /// Heading, radians counter-clockwise from east (the car's long axis points along it).
    pub heading: Real,
    /// The speed the car drives at when nothing is in its way, m/s.
    pub cruise_mps: Real,
    /// Distance travelled along its path in the last step divided by the step, m/s.
    pub speed_mps: Real,
    lane: L,
    path: VecDeque<Waypoint<L>>,
    stalled_steps: u32,
    /// Time left of the car's current stop, seconds (0: not stopped).
    stop_left_s: Real,
}

/// Where a car is, whichever road model drives it: what the cameras and the truth see.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CarPose {
    /// Target id.
    pub id: u32,
    /// Ground point under the car's centre.
    pub position: Point2,
    /// Heading, radians counter-clockwise from east.
    pub heading: Real,
    /// Distance travelled in the last step divided by the step, m/s.
    pub speed_mps: Real,
}

impl<L: Copy> Car<L> {
    /// Where the car is.
    pub fn pose(&self) -> CarPose {
        CarPose {
            id: self.id,
            position: self.position,
            heading: self.heading,
            speed_mps: self.speed_mps,
        }
    }

    /// A car standing at `position` on `lane`, heading `heading`, with nothing planned.
    fn standing(id: u32, position: Point2, heading: Real, cruise_mps: Real, lane: L) -> Car<L> {
        Car {
            id,
            position,
            heading,
            cruise_mps,
            speed_mps: 0.0,
            lane,
            path: VecDeque::new(),
            stalled_steps: 0,
            stop_left_s: 0.0,
        }
    }

    /// The lane the car is on (during a turn, the lane it is leaving).
    pub fn lane(&self) -> L {
        self.lane
    }

    /// Where the path ahead ends and on which lane.
    fn path_end(&self) -> (Point2, L) {
        self.path
            .back()
            .map_or((self.position, self.lane), |w| (w.point, w.lane))
    }

    fn path_length(&self) -> Real {
        let mut from = self.position;
        let mut len = 0.0;
        for w in &self.path {
            len += (w.point - from).norm();
            from = w.point;
        }
        len
    }

    /// The car after travelling `dist` along its path (the path must be long enough).
    fn travelled(&self, dist: Real) -> Car<L> {
        let mut car = self.clone();
        let mut left = dist;
        while left > 0.0 {
            let Some(w) = car.path.front().copied() else {
                break;
            };
            let seg = w.point - car.position;
            let len = seg.norm();
            if len > 0.0 {
                car.heading = seg.y.atan2(seg.x);
            }
            if len <= left {
                car.position = w.point;
                car.lane = w.lane;
                car.path.pop_front();
                left -= len;
            } else {
                car.position += seg * (left / len);
                left = 0.0;
            }
        }
        car
    }
}

/// How the cars' speeds are drawn and when they stop (`[targets]`).
#[derive(Clone, Copy, Debug)]
struct SpeedModel {
    max_speed: Real,
    spread: Real,
    draw: SpeedDraw,
    stops_per_min: Real,
    stop_s: [Real; 2],
}

impl SpeedModel {
    /// The scenario's `[targets]` speeds and stops.
    fn of(scenario: &Scenario) -> SpeedModel {
        let t = &scenario.targets;
        SpeedModel {
            max_speed: t.max_speed_mps,
            spread: t.cruise_spread,
            draw: t.speed_draw,
            stops_per_min: t.stops_per_min,
            stop_s: t.stop_s,
        }
    }

    fn cruise(&self, rng: &mut ChaCha8Rng) -> Real {
        self.max_speed * (1.0 - self.spread * rng.random::<Real>())
    }
}

/// What a road model tells the cars that drive on it: where to go next, how to turn around
/// when blocked, and how far apart to keep.
pub trait RoadModel<L> {
    /// Smallest centre-to-centre distance between two cars.
    fn car_separation(&self) -> Real;
    /// Extends a car's path to its next decision.
    fn plan(&self, car: &mut Car<L>, rng: &mut ChaCha8Rng);
    /// Replaces a blocked car's path by a crossing onto its road's other lane, right where it
    /// is; `others` are the other cars' positions.
    fn turn_around(&self, car: &mut Car<L>, others: &[Point2]);
    /// Whether car `i` of `cars` may move to `to`, beyond keeping its distance (a junction
    /// taken one car at a time); every move by default.
    fn admits(&self, _cars: &[Car<L>], _i: usize, _to: &Point2) -> bool {
        true
    }
    /// Whether a car's path must reach further before it can decide its next move (beyond
    /// the step's travel, which is always planned); never by default.
    fn plans_further(&self, _car: &Car<L>) -> bool {
        false
    }
}

/// The most decisions planned for one car in one step beyond its step's travel
/// ([`RoadModel::plans_further`]).
const MAX_PLANS_AHEAD: usize = 64;

/// Every car of the run, and the random sources of their decisions.
#[derive(Clone, Debug)]
pub struct Traffic<L = Lane> {
    cars: Vec<Car<L>>,
    rng: ChaCha8Rng,
    speeds: ChaCha8Rng,
    model: SpeedModel,
}

impl Traffic<Lane> {
    /// Places `targets.count` cars at random on the lanes, at least the car separation apart,
    /// each with a cruise speed `v_max (1 - cruise_spread u)`. `rng` draws the placements,
    /// the cruise speeds per car and the turns; `speeds`, an independent source, the speeds
    /// per step and the stops.
    pub fn place(
        roads: &RoadGrid,
        scenario: &Scenario,
        rng: ChaCha8Rng,
        speeds: ChaCha8Rng,
    ) -> Result<Traffic, WorldBuildError> {
        let sep = roads.profile.car_separation;
        Traffic::place_with(scenario, sep, "the roads", rng, speeds, |rng| {
            let axis = if rng.random_bool(0.5) {
                Axis::X
            } else {
                Axis::Y
            };
            let road = rng.random_range(0..roads.roads(axis).len());
            let dir = if rng.random_bool(0.5) { 1 } else { -1 };
            let lane = Lane { axis, road, dir };
            let cs = roads.crossings(axis);
            let (lo, hi) = (cs[0], cs[cs.len() - 1]);
            let p = roads.point_on_lane(lane, rng.random_range(lo..=hi));
            let h = lane.heading();
            Some((p, h.y.atan2(h.x), lane))
        })
    }
}

impl<L: Copy> Traffic<L> {
    /// Places `targets.count` cars, each at the first of up to [`PLACEMENT_TRIES`] spots
    /// `draw` gives (point, heading, lane; none for a spot the road model refuses) that is
    /// `sep` from every car placed before, with a cruise speed drawn after it. `roads` names
    /// the roads in the error.
    fn place_with(
        scenario: &Scenario,
        sep: Real,
        roads: &str,
        mut rng: ChaCha8Rng,
        speeds: ChaCha8Rng,
        mut draw: impl FnMut(&mut ChaCha8Rng) -> Option<(Point2, Real, L)>,
    ) -> Result<Traffic<L>, WorldBuildError> {
        let t = &scenario.targets;
        let model = SpeedModel::of(scenario);
        let mut cars: Vec<Car<L>> = Vec::with_capacity(t.count as usize);
        for id in 0..t.count {
            let placed = (0..PLACEMENT_TRIES).find_map(|_| {
                let (p, heading, lane) = draw(&mut rng)?;
                cars.iter()
                    .all(|c| (c.position - p).norm() >= sep + EPS)
                    .then(|| Car::standing(id, p, heading, model.cruise(&mut rng), lane))
            });
            let Some(car) = placed else {
                return Err(WorldBuildError::Placement(format!(
                    "cannot place car {id} of targets.count = {} on {roads} at least {sep:.2} m \
                     from the others",
                    t.count
                )));
            };
            cars.push(car);
        }
        Ok(Traffic {
            cars,
            rng,
            speeds,
            model,
        })
    }

    /// The cars, by id.
    pub fn cars(&self) -> &[Car<L>] {
        &self.cars
    }

    /// Advances every car by `dt` seconds, in id order.
    pub fn step(&mut self, roads: &impl RoadModel<L>, dt: Real) {
        let separation = roads.car_separation();
        for i in 0..self.cars.len() {
            if self.stands_still(i, dt) {
                continue;
            }
            let budget = (self.cars[i].cruise_mps.min(self.model.max_speed) * dt).max(0.0);
            if self.cars[i].stalled_steps >= DEADLOCK_STEPS {
                let others: Vec<Point2> = (self.cars.iter().enumerate())
                    .filter(|&(j, _)| j != i)
                    .map(|(_, c)| c.position)
                    .collect();
                let car = &mut self.cars[i];
                tracing::debug!(
                    car = car.id,
                    "car blocked for {} steps turns around",
                    car.stalled_steps
                );
                roads.turn_around(car, &others);
                car.stalled_steps = 0;
            }
            while self.cars[i].path_length() < budget + EPS {
                let car = &mut self.cars[i];
                roads.plan(car, &mut self.rng);
            }
            for _ in 0..MAX_PLANS_AHEAD {
                if !roads.plans_further(&self.cars[i]) {
                    break;
                }
                roads.plan(&mut self.cars[i], &mut self.rng);
            }
            let mut moved = None;
            for share in MOVE_SHARES {
                let cand = self.cars[i].travelled(budget * share);
                if self.keeps_clear(i, &cand.position, separation)
                    && roads.admits(&self.cars, i, &cand.position)
                {
                    moved = Some((cand, budget * share));
                    break;
                }
            }
            let car = &mut self.cars[i];
            match moved {
                Some((c, d)) if d > 0.0 => {
                    *car = Car {
                        speed_mps: d / dt,
                        stalled_steps: 0,
                        ..c
                    };
                }
                _ => {
                    car.speed_mps = 0.0;
                    car.stalled_steps += 1;
                }
            }
        }
    }

    /// Draws car `i`'s speed for this step and whether it stops; true if it stands still
    /// this step (a stop is not a blockage: it does not count towards turning around).
    fn stands_still(&mut self, i: usize, dt: Real) -> bool {
        let model = self.model;
        let car = &mut self.cars[i];
        if model.draw == SpeedDraw::PerStep {
            car.cruise_mps = model.cruise(&mut self.speeds);
        }
        if car.stop_left_s <= 0.0
            && model.stops_per_min > 0.0
            && self.speeds.random::<Real>() < model.stops_per_min * dt / 60.0
        {
            let [lo, hi] = model.stop_s;
            car.stop_left_s = lo + (hi - lo) * self.speeds.random::<Real>();
        }
        if car.stop_left_s > 0.0 {
            car.stop_left_s -= dt;
            car.speed_mps = 0.0;
            return true;
        }
        false
    }

    fn keeps_clear(&self, i: usize, p: &Point2, separation: Real) -> bool {
        self.cars
            .iter()
            .enumerate()
            .all(|(j, c)| j == i || (c.position - p).norm() >= separation + EPS)
    }
}

/// The cars of a run, whichever drives them: the world's model on the grid or on an
/// imported network, or a checked trace (SUMO's, or a file's).
#[derive(Clone, Debug)]
pub enum Cars {
    /// Cars on the generated city's grid.
    Grid(Traffic<Lane>, Arc<RoadGrid>),
    /// Cars on an imported city's network.
    Network(Traffic<NetLane>, Arc<LaneNetwork>),
    /// Cars replaying a trace ([`trace`]).
    Trace(TraceCars),
}

impl Cars {
    /// Places the scenario's cars on `roads` ([`Traffic::place`], [`LaneNetwork::place`]).
    pub fn place(
        roads: &Roads,
        scenario: &Scenario,
        rng: ChaCha8Rng,
        speeds: ChaCha8Rng,
    ) -> Result<Cars, WorldBuildError> {
        Ok(match roads {
            Roads::Grid(grid) => Cars::Grid(
                Traffic::place(grid, scenario, rng, speeds)?,
                Arc::clone(grid),
            ),
            Roads::Network(net) => {
                Cars::Network(net.place(scenario, rng, speeds)?, Arc::clone(net))
            }
        })
    }

    /// Advances every car by `dt` seconds.
    pub fn step(&mut self, dt: Real) {
        match self {
            Cars::Grid(traffic, grid) => traffic.step(grid.as_ref(), dt),
            Cars::Network(traffic, net) => traffic.step(net.as_ref(), dt),
            Cars::Trace(cars) => cars.step(),
        }
    }

    /// Where the cars are, by id.
    pub fn poses(&self) -> Vec<CarPose> {
        match self {
            Cars::Grid(traffic, _) => traffic.cars().iter().map(Car::pose).collect(),
            Cars::Network(traffic, _) => traffic.cars().iter().map(Car::pose).collect(),
            Cars::Trace(cars) => cars.poses(),
        }
    }

    /// The number of cars.
    pub fn len(&self) -> usize {
        match self {
            Cars::Grid(traffic, _) => traffic.cars().len(),
            Cars::Network(traffic, _) => traffic.cars().len(),
            Cars::Trace(cars) => cars.len(),
        }
    }

    /// Whether there are no cars.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl RoadModel<Lane> for RoadGrid {
    fn car_separation(&self) -> Real {
        self.profile.car_separation
    }

    fn plan(&self, car: &mut Car, rng: &mut ChaCha8Rng) {
        plan(self, car, rng);
    }

    fn turn_around(&self, car: &mut Car, _others: &[Point2]) {
        let opposite = car.lane.opposite();
        let s = RoadGrid::along(car.lane.axis, &car.position);
        car.path.clear();
        car.path.push_back(Waypoint {
            point: self.point_on_lane(opposite, s),
            lane: opposite,
        });
    }
}

/// Extends a car's path to the next decision: the next intersection ahead, where it goes
/// straight, turns left or turns right at random among the roads that continue, or turns
/// around at a dead end.
fn plan(roads: &RoadGrid, car: &mut Car, rng: &mut ChaCha8Rng) {
    let (start, lane) = car.path_end();
    let off = roads.profile.lane_offset;
    let s = RoadGrid::along(lane.axis, &start);
    let cs = roads.crossings(lane.axis);
    // The next crossing road ahead; crossings within a lane offset are the one being passed.
    let node = if lane.dir > 0 {
        cs.iter().position(|&c| c > s + off + EPS)
    } else {
        cs.iter().rposition(|&c| c < s - off - EPS)
    };
    let Some(m) = node else {
        push_u_turn(roads, car, lane, s);
        return;
    };
    let mut options: [Option<Waypoint<Lane>>; 3] = [None; 3];
    let continues = if lane.dir > 0 {
        m + 1 < cs.len()
    } else {
        m > 0
    };
    if continues {
        options[0] = Some(Waypoint {
            point: roads.point_on_lane(lane, cs[m]),
            lane,
        });
    }
    let here = lane.road;
    let along_new = roads.crossings(lane.axis.other()).len();
    for (k, dir) in [(1, 1i8), (2, -1i8)] {
        let ok = if dir > 0 {
            here + 1 < along_new
        } else {
            here > 0
        };
        if ok {
            let new = Lane {
                axis: lane.axis.other(),
                road: m,
                dir,
            };
            let l_new = roads.lane_line(new);
            let l_cur = roads.lane_line(lane);
            let point = match lane.axis {
                Axis::X => Point2::new(l_new, l_cur),
                Axis::Y => Point2::new(l_cur, l_new),
            };
            options[k] = Some(Waypoint { point, lane: new });
        }
    }
    let count = options.iter().flatten().count();
    if count == 0 {
        car.path.push_back(Waypoint {
            point: roads.point_on_lane(lane, cs[m]),
            lane,
        });
        push_u_turn(roads, car, lane, cs[m]);
        return;
    }
    let pick = rng.random_range(0..count);
    if let Some(w) = options.iter().flatten().nth(pick) {
        car.path.push_back(*w);
    }
}

fn push_u_turn(roads: &RoadGrid, car: &mut Car, lane: Lane, s: Real) {
    let opposite = lane.opposite();
    car.path.push_back(Waypoint {
        point: roads.point_on_lane(opposite, s),
        lane: opposite,
    });
}
