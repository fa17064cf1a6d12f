//! The per-step metrics of docs/design.md §6 and the guarantee check, as pure functions of the
//! agents' published estimates and the ground truth (so they are unit-tested without
//! processes).
//!
//! **Per agent.** The paper defines every set metric for one UAV on its own fused sets. For each
//! agent `i` that published an estimate of step `k`, [`FusedSets::of_agent`] rebuilds what `i`
//! holds after its step-`k` fusion: its own estimate fused with the estimates of the peers it
//! fuses at that step, in the order it fuses them (ascending UAV id), with the agents' own law
//! ([`PeerEstimate::fuse`]). Which peers' estimates those are is the agents' own rule
//! ([`Radio::fused_peers`]): the estimates of step `k - d` (`d` the link latency in steps, 0
//! by default; older estimates are dilated by the law), each only if the radio delivered it to
//! `i` ([`Radio::delivers`], drawn from the seed, the link and the step: the observer draws the
//! same) and its sender was in range ([`Radio::in_range`]). [`SetMetrics::measure`] then gives
//! UA, OA, explored, target-set area, localisation error and identified count of those sets, and
//! [`AgentSpread::over`] their mean over agents and their worst agent.
//!
//! `H̄` is the fleet's, as in the paper: ground hidden from any UAV and proven free by none
//! since. At its step `k` agent `i` joins the step's hidden ground (`H^CVS`) of its frame and of
//! every estimate it fuses, then removes the ground any of them proved free (`P^g`), so a cell
//! one UAV saw hidden and another saw free at the step is not in it, whatever the order; late
//! estimates are older news than its own frame ([`Unseen`] states the rule and why). `H̄` is
//! not part of a [`PeerEstimate`]'s fusion law: an agent publishes its `H̄` as it stood after
//! its frame and before the step's fusion (`msg.unseen`), with its frame's `H^CVS` and `P^g`,
//! and [`FusedSets`] rebuilds its fused `H̄` from them and the fused peers' `H^CVS` and `P^g`
//! with the agent's own code ([`Unseen::after_frame`], then [`Unseen::fuse`] per peer), so the
//! two agree bit for bit.
//!
//! What is not reproduced: a peer estimate that reached the agent after its bounded wait is
//! fused by the agent later, dilated; here only the estimates of the same step are fused (in
//! lockstep every live peer's estimate of the step is fused at that step).
//!
//! **Under windows** (`estimator.window_m`) an agent's `X̄` is loose outside its window: its
//! UA and OA are measured over the window ([`SetMetrics::within`]), and the fleet's `X̄`, the
//! intersection of the agents', gives the UA and OA that stand for the mean
//! ([`fleet_areas`]).
//!
//! **Fleet-wide**, where a per-agent reading would say less: the guarantee is checked on each
//! published estimate ([`violations`]), and [`identified_ids`] counts the targets identified by
//! any agent. Every area is a fraction of the grid's area (the region of interest).

use std::collections::{BTreeMap, BTreeSet};

use estimator::fusion::SharedSet;
use estimator::message::{self, EstimateInbox};
use estimator::occupancy::OccupancyMap;
use estimator::{EstimateReadError, EstimatorConfig, PeerEstimate, Unseen};
use protocol::radio::Radio;
use protocol::wire::{AgentStats, TargetTruth};
use sets::grid::{CellIndex, GroundGrid};
use sets::math::Point2;
use sets::raster::{CellBox, CellSet};

/// What the observer keeps of one agent's estimate of one step.
#[derive(Clone, Debug, PartialEq)]
pub struct ObservedEstimate {
    /// The estimate as a peer receives it, its map cells left out (the observer merges them
    /// into its own map once; fusing them again per agent would only cost).
    pub estimate: PeerEstimate,
    /// `H̄`: ground hidden earlier and not seen since, as the sender held it before fusing.
    pub unseen: CellSet,
    /// The sender's counters.
    pub stats: AgentStats,
}

/// Why an estimate could not be read by the observer.
#[derive(Debug, thiserror::Error)]
pub enum EstimateObserveError {
    /// The message does not decode, validate or rebuild as an estimate.
    #[error(transparent)]
    Read(#[from] EstimateReadError),
}

impl ObservedEstimate {
    /// Decodes and validates an estimate's bytes that carry whole sets (a message of deltas
    /// needs [`ObservedEstimate::read`]); also returns the map cells it carries.
    pub fn decode(
        bytes: &[u8],
        config: &EstimatorConfig,
    ) -> Result<(ObservedEstimate, OccupancyMap), EstimateObserveError> {
        Self::read(&mut EstimateInbox::new(), bytes, config)
    }

    /// Decodes, validates and rebuilds an estimate's bytes as an agent does: its sets may be
    /// deltas against the sender's previous message, which `inbox` holds if it read it (the
    /// observer is a receiver like the agents: one that missed a message waits for the
    /// sender's next whole one). Also returns the map cells it carries.
    pub fn read(
        inbox: &mut EstimateInbox,
        bytes: &[u8],
        config: &EstimatorConfig,
    ) -> Result<(ObservedEstimate, OccupancyMap), EstimateObserveError> {
        let msg = message::from_bytes(bytes).map_err(EstimateReadError::from)?;
        let mut estimate = inbox.read(&msg, config)?;
        let unseen = inbox
            .unseen(msg.uav)
            .cloned()
            .unwrap_or_else(|| CellSet::empty(&config.grid));
        let oem = std::mem::replace(&mut estimate.oem, OccupancyMap::new(config.oem_grid));
        let observed = ObservedEstimate {
            estimate,
            unseen,
            stats: msg.stats,
        };
        Ok((observed, oem))
    }

    /// Sender.
    pub fn uav(&self) -> u32 {
        self.estimate.uav
    }

    /// Step of the sets.
    pub fn step(&self) -> u64 {
        self.estimate.step
    }
}

/// One agent's sets after its fusion of one step. The sets are shared (`Arc`): agents that
/// fuse the same estimates share one fusion's sets ([`FusedSets::of_agents`]), not copies.
#[derive(Clone, Debug, PartialEq)]
pub struct FusedSets {
    /// `X̄`.
    pub undetected: SharedSet,
    /// `X_j` per identified id.
    pub targets: BTreeMap<u32, SharedSet>,
    /// `S^o`.
    pub obstacle_neighbourhood: SharedSet,
    /// Explored ground.
    pub explored: SharedSet,
    /// `H̄`.
    pub unseen: CellSet,
}

impl FusedSets {
    /// What agent `own.uav()` holds once it has fused `peers` (in the given order) into its
    /// own estimate, by the agents' law ([`PeerEstimate::fuse`]; `H̄` as the module docs say).
    pub fn fuse<'a>(
        own: &ObservedEstimate,
        peers: impl IntoIterator<Item = &'a ObservedEstimate>,
        config: &EstimatorConfig,
    ) -> FusedSets {
        let mut fused = own.estimate.clone();
        let mut fused_with = Vec::new();
        for peer in peers {
            if !fused.fuse(&peer.estimate, config).grid_mismatch {
                fused_with.push(peer);
            }
        }
        FusedSets::with_unseen(fused, own, &fused_with)
    }

    /// The sets of `fused`, with `H̄` of agent `own` once it fused `peers`: the `H̄` it
    /// published after its frame, with its frame's and the peers' hidden and proven-free
    /// ground folded in by the agents' rule (module docs).
    fn with_unseen(
        fused: PeerEstimate,
        own: &ObservedEstimate,
        peers: &[&ObservedEstimate],
    ) -> FusedSets {
        let e = &own.estimate;
        let mut unseen = Unseen::after_frame(
            e.step,
            own.unseen.clone(),
            &e.sets.hidden,
            &e.sets.free_ground,
        );
        for peer in peers {
            let p = &peer.estimate;
            unseen.fuse(p.step, &p.sets.hidden, &p.sets.free_ground);
        }
        let sets = fused.sets;
        FusedSets {
            undetected: sets.undetected,
            targets: sets.targets,
            obstacle_neighbourhood: sets.obstacle_neighbourhood,
            explored: sets.explored,
            unseen: unseen.into_cells(),
        }
    }

    /// The sets of an estimate that holds an agent's sets after its step as they are (an
    /// agent's state message under the measurement exchange): nothing is fused.
    pub fn held(own: &ObservedEstimate) -> FusedSets {
        let e = &own.estimate.sets;
        FusedSets {
            undetected: e.undetected.clone(),
            targets: e.targets.clone(),
            obstacle_neighbourhood: e.obstacle_neighbourhood.clone(),
            explored: e.explored.clone(),
            unseen: own.unseen.clone(),
        }
    }

    /// Agent `own.uav()`'s sets after its fusion of its step, among `sent` the estimates sent
    /// `radio.latency_steps()` steps before it (see [`fused_peers`]).
    pub fn of_agent(
        own: &ObservedEstimate,
        sent: &[ObservedEstimate],
        config: &EstimatorConfig,
        radio: &Radio,
    ) -> FusedSets {
        FusedSets::fuse(own, fused_peers(own, sent, radio), config)
    }

    /// [`FusedSets::of_agent`] of every agent of `all` (the estimates of one step), in `all`'s
    /// order, among `sent` (the estimates of `radio.latency_steps()` steps before: `all` itself
    /// without latency). Without latency, agents that fuse the same estimates (in lockstep
    /// with perfect links, every agent fuses every other) share one fusion: on estimates of one
    /// step the law meets and joins sets, so the result does not depend on whose estimate it
    /// starts from; only `H̄`, which starts from each agent's own, is built per agent. A shared
    /// fusion that met an empty intersection (then the union is kept, which depends on the
    /// order) or another grid is not shared: each agent of it is fused on its own. With
    /// latency the peers' estimates are older than the agent's own and are dilated by the law
    /// as they are fused into it: each agent is fused on its own, as it fuses.
    pub fn of_agents(
        all: &[ObservedEstimate],
        sent: &[ObservedEstimate],
        config: &EstimatorConfig,
        radio: &Radio,
    ) -> Vec<FusedSets> {
        let mut shared: BTreeMap<Vec<u32>, Option<PeerEstimate>> = BTreeMap::new();
        all.iter()
            .map(|own| {
                let peers: Vec<&ObservedEstimate> = fused_peers(own, sent, radio).collect();
                if peers.iter().any(|p| p.step() != own.step()) {
                    return FusedSets::fuse(own, peers, config);
                }
                let mut group: Vec<&ObservedEstimate> = peers.clone();
                group.push(own);
                group.sort_by_key(|e| e.uav());
                let key: Vec<u32> = group.iter().map(|e| e.uav()).collect();
                let fused = shared
                    .entry(key)
                    .or_insert_with(|| fuse_in_order(&group, config))
                    .clone();
                match fused {
                    Some(fused) => FusedSets::with_unseen(fused, own, &peers),
                    None => FusedSets::fuse(own, peers, config),
                }
            })
            .collect()
    }
}

/// The estimates of `group` (one step) fused in order, or `None` when a fusion met an empty
/// intersection or another grid (then the result depends on the order).
fn fuse_in_order(group: &[&ObservedEstimate], config: &EstimatorConfig) -> Option<PeerEstimate> {
    let (first, rest) = group.split_first()?;
    let mut fused = first.estimate.clone();
    for e in rest {
        let report = fused.fuse(&e.estimate, config);
        if report.grid_mismatch || !report.empty_intersections.is_empty() {
            return None;
        }
    }
    Some(fused)
}

/// The estimates among `sent` that agent `own.uav()` fuses at its step `k`, in its order, by
/// the agents' own rule ([`Radio::fused_peers`]): the other agents' estimates of step `k - d`
/// (`d = radio.latency_steps()`) that the radio delivered to it from a sender in range, by
/// ascending UAV id. None before step `d`.
pub fn fused_peers<'a>(
    own: &'a ObservedEstimate,
    sent: &'a [ObservedEstimate],
    radio: &'a Radio,
) -> impl Iterator<Item = &'a ObservedEstimate> + 'a {
    radio
        .fused_peers(&own.estimate.endpoint(), sent, |p| p.estimate.endpoint())
        .into_iter()
}

/// The set metrics of one agent at one step (fractions of the grid's area, distances in
/// metres), or an aggregate of several agents' ([`AgentSpread`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SetMetrics {
    /// `|explored|`.
    pub explored: f64,
    /// `|X̄|` (UA).
    pub ua: f64,
    /// `|X̄ ∩ H̄|` (OA).
    pub oa: f64,
    /// Mean over identified ids of `|X_j|`; `None` when nothing is identified.
    pub target_set_area: Option<f64>,
    /// Mean over identified ids (present in the truth) of the distance between the target
    /// and the barycentre of `X_j`; `None` when there is none.
    pub loc_error_m: Option<f64>,
    /// Identified ids (a count for one agent, a mean over agents in an aggregate).
    pub identified: f64,
}

impl SetMetrics {
    /// Measures one agent's fused sets against the truth.
    pub fn measure(fused: &FusedSets, truth: &[TargetTruth], grid: &GroundGrid) -> SetMetrics {
        let cells = grid.cell_count().max(1) as f64;
        let frac = |n: u64| n as f64 / cells;
        let undetected = &fused.undetected;
        let mut areas = Vec::new();
        let mut errors = Vec::new();
        for (id, set) in &fused.targets {
            areas.push(frac(set.count()));
            let target = truth.iter().find(|t| t.id == *id);
            if let (Some(t), Some(b)) = (target, set.barycentre(grid)) {
                errors.push((b - ground_point(t)).norm());
            }
        }
        SetMetrics {
            explored: frac(fused.explored.count()),
            ua: frac(undetected.count()),
            oa: frac(undetected.intersection_count(&fused.unseen)),
            target_set_area: mean(&areas),
            loc_error_m: mean(&errors),
            identified: fused.targets.len() as f64,
        }
    }
}

impl SetMetrics {
    /// These metrics with UA and OA over an agent's `window` only (`estimator.window_m`): the
    /// shares of the window, not of the region, that its `X̄` and `X̄ ∩ H̄` cover. Outside its
    /// window an agent keeps `X̄` loose (coarse bounds of the reach), so its own UA says what it
    /// knows where its guidance reads; the fleet's is [`fleet_areas`].
    pub fn within(self, fused: &FusedSets, window: &CellBox) -> SetMetrics {
        let cells = window.cell_count().max(1) as f64;
        let undetected = &fused.undetected;
        SetMetrics {
            ua: undetected.count_in_box(window) as f64 / cells,
            oa: undetected.intersection_count_in_box(&fused.unseen, window) as f64 / cells,
            ..self
        }
    }
}

/// The fleet's UA and OA when the agents keep `X̄` over windows: the fleet's `X̄` is the
/// intersection of the agents' (each an outer set of the cars not yet identified, so their
/// intersection is one too), UA its share of the region, and OA the mean over agents of the
/// share of the region in both it and the agent's `H̄`. When every agent holds the same
/// `X̄` (lockstep, perfect links, no windows) they are the means over agents of UA and OA.
/// `None` for no agent.
pub fn fleet_areas<'a>(
    agents: impl IntoIterator<Item = &'a FusedSets>,
    grid: &GroundGrid,
) -> Option<(f64, f64)> {
    let agents: Vec<&FusedSets> = agents.into_iter().collect();
    let (first, rest) = agents.split_first()?;
    let mut fleet = (*first.undetected).clone();
    for a in rest {
        fleet.and_assign(&a.undetected);
    }
    let cells = grid.cell_count().max(1) as f64;
    let occluded: Vec<f64> = agents
        .iter()
        .map(|a| fleet.intersection_count(&a.unseen) as f64 / cells)
        .collect();
    Some((
        fleet.count() as f64 / cells,
        mean(&occluded).unwrap_or_default(),
    ))
}

/// Several agents' metrics of one step summarised: each metric's mean over the agents that
/// have it, and its worst value (largest UA, OA, target-set area and localisation error;
/// smallest explored ground and identified count).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AgentSpread {
    /// Mean over agents.
    pub mean: SetMetrics,
    /// Worst agent, metric by metric (not necessarily one agent for all).
    pub worst: SetMetrics,
}

impl AgentSpread {
    /// Summarises per-agent metrics; `None` for none.
    pub fn over<'a>(agents: impl IntoIterator<Item = &'a SetMetrics>) -> Option<AgentSpread> {
        let agents: Vec<&SetMetrics> = agents.into_iter().collect();
        if agents.is_empty() {
            return None;
        }
        let spread = |f: fn(&SetMetrics) -> Option<f64>| {
            let v: Vec<f64> = agents.iter().filter_map(|s| f(s)).collect();
            let min = v.iter().copied().reduce(f64::min);
            let max = v.iter().copied().reduce(f64::max);
            (mean(&v), min, max)
        };
        let (explored, explored_min, _) = spread(|s| Some(s.explored));
        let (ua, _, ua_max) = spread(|s| Some(s.ua));
        let (oa, _, oa_max) = spread(|s| Some(s.oa));
        let (area, _, area_max) = spread(|s| s.target_set_area);
        let (error, _, error_max) = spread(|s| s.loc_error_m);
        let (identified, identified_min, _) = spread(|s| Some(s.identified));
        // Never empty: there is at least one agent.
        let always = |v: Option<f64>| v.unwrap_or_default();
        Some(AgentSpread {
            mean: SetMetrics {
                explored: always(explored),
                ua: always(ua),
                oa: always(oa),
                target_set_area: area,
                loc_error_m: error,
                identified: always(identified),
            },
            worst: SetMetrics {
                explored: always(explored_min),
                ua: always(ua_max),
                oa: always(oa_max),
                target_set_area: area_max,
                loc_error_m: error_max,
                identified: always(identified_min),
            },
        })
    }
}

fn mean(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// The target's ground point.
pub fn ground_point(t: &TargetTruth) -> Point2 {
    Point2::new(t.ground[0], t.ground[1])
}

/// Which set a target was found outside of.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ViolatedSet {
    /// The agent had not identified the target and it was outside `X̄`.
    Undetected,
    /// The agent had identified the target and it was outside `X_j`.
    Target,
}

impl ViolatedSet {
    /// The set's name in logs.
    pub fn name(self) -> &'static str {
        match self {
            ViolatedSet::Undetected => "undetected set",
            ViolatedSet::Target => "target set",
        }
    }
}

/// One truth-outside-set event: target `target` outside agent `uav`'s set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Violation {
    /// The agent whose estimate was wrong.
    pub uav: u32,
    /// The target.
    pub target: u32,
    /// The set that missed it.
    pub set: ViolatedSet,
    /// Distance from the target's ground point to the nearest cell of the set, metres
    /// (infinite for an empty set).
    pub distance_m: f64,
}

/// Checks one agent's estimate against the truth of the same step: an identified target must
/// lie in its `X_j`, any other in `X̄` (the cell under its ground point is what is checked; a
/// target off the grid lies in no set).
pub fn violations(
    estimate: &ObservedEstimate,
    truth: &[TargetTruth],
    grid: &GroundGrid,
) -> Vec<Violation> {
    let mut out = Vec::new();
    for t in truth {
        let p = ground_point(t);
        let (set, kind) = match estimate.estimate.sets.targets.get(&t.id) {
            Some(set) => (set, ViolatedSet::Target),
            None => (&estimate.estimate.sets.undetected, ViolatedSet::Undetected),
        };
        let inside = cell_of_closed(grid, &p).is_some_and(|c| set.contains(c));
        if !inside {
            out.push(Violation {
                uav: estimate.uav(),
                target: t.id,
                set: kind,
                distance_m: distance_to_set(set, grid, &p),
            });
        }
    }
    out
}

/// The cell holding `p`, counting the grid's far edges as inside (cells are half-open, but a
/// point exactly on the region's north or east border still belongs to the region).
fn cell_of_closed(grid: &GroundGrid, p: &Point2) -> Option<CellIndex> {
    grid.cell_of(p).or_else(|| {
        let b = grid.bounds();
        b.contains(p).then(|| {
            let ix = ((p.x - grid.origin.x) / grid.cell_m).floor() as u32;
            let iy = ((p.y - grid.origin.y) / grid.cell_m).floor() as u32;
            (
                ix.min(grid.nx.saturating_sub(1)),
                iy.min(grid.ny.saturating_sub(1)),
            )
        })
    })
}

/// Distance from `p` to the nearest cell of `set` (0 inside, infinite for an empty set).
pub fn distance_to_set(set: &CellSet, grid: &GroundGrid, p: &Point2) -> f64 {
    set.iter()
        .map(|c| {
            let r = grid.cell_rect(c);
            let dx = (r.min.x - p.x).max(0.0).max(p.x - r.max.x);
            let dy = (r.min.y - p.y).max(0.0).max(p.y - r.max.y);
            dx.hypot(dy)
        })
        .fold(f64::INFINITY, f64::min)
}

/// Ids identified by any of the estimates.
pub fn identified_ids<'a>(
    estimates: impl IntoIterator<Item = &'a ObservedEstimate>,
) -> BTreeSet<u32> {
    estimates
        .into_iter()
        .flat_map(|e| e.estimate.sets.targets.keys().copied())
        .collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use std::sync::Arc;

    use estimator::{EstimateSets, EstimatorState};
    use protocol::camera::CameraPose;
    use protocol::radio::LinkKind;
    use protocol::scenario::Scenario;
    use sets::math::Point3;
    use sets::raster::ReachSet;

    use super::*;

    /// The world and the estimators of `scenario`'s fleet in one process, flown by the
    /// scenario's planner in token order.
    pub(crate) fn guided_fleet(scenario: &Scenario) -> Result<sim::Fleet, sim::FleetCreateError> {
        let options = sim::FleetOptions {
            steering: sim::Steering::Guided(Box::new(
                uav_agent::guidance::GuidanceParams::from_scenario(scenario),
            )),
            ..sim::FleetOptions::default()
        };
        sim::Fleet::new(scenario, options)
    }

    /// A 10 x 10 grid of 1 m cells over [-5, 5]^2.
    fn grid() -> GroundGrid {
        GroundGrid::new(5.0, 1.0)
    }

    /// The estimator configuration of [`grid`].
    fn config() -> EstimatorConfig {
        let mut scenario = Scenario::default();
        scenario.region.half_extent_m = 5.0;
        scenario.estimator.cell_m = 1.0;
        scenario.estimator.oem_cell_m = 5.0;
        let config = EstimatorConfig::from_scenario(&scenario);
        assert_eq!(config.grid, grid());
        config
    }

    fn set(cells: &[CellIndex]) -> CellSet {
        CellSet::from_cells(&grid(), cells.iter().copied())
    }

    /// An estimate on `grid` knowing nothing: `X̄` full, every other set empty.
    pub(crate) fn blank(grid: &GroundGrid, uav: u32, step: u64) -> ObservedEstimate {
        ObservedEstimate {
            estimate: PeerEstimate {
                uav,
                step,
                time_s: step as f64 * 0.5,
                seq: step,
                incarnation: 1,
                pose: None,
                sets: EstimateSets {
                    undetected: CellSet::full(grid).into(),
                    targets: BTreeMap::new(),
                    obstacle_neighbourhood: CellSet::empty(grid).into(),
                    explored: CellSet::empty(grid).into(),
                    hidden: CellSet::empty(grid).into(),
                    free_ground: CellSet::empty(grid).into(),
                },
                oem: OccupancyMap::new(*grid),
                oem_full: false,
            },
            unseen: CellSet::empty(grid),
            stats: AgentStats::default(),
        }
    }

    fn estimate(uav: u32, undetected: CellSet, targets: &[(u32, CellSet)]) -> ObservedEstimate {
        let mut e = blank(&grid(), uav, 3);
        e.estimate.sets.undetected = undetected.into();
        e.estimate.sets.targets = targets
            .iter()
            .map(|(id, s)| (*id, s.clone().into()))
            .collect();
        e
    }

    /// A camera at `(x, 0)`, 40 m up.
    fn at(x: f64) -> Option<CameraPose> {
        Some(CameraPose {
            position: Point3::new(x, 0.0, 40.0),
            yaw: 0.0,
        })
    }

    /// A reproducible pseudo-random set of about `density` of the grid.
    fn scattered(seed: u64, density: f64) -> CellSet {
        let g = grid();
        let mut x = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut s = CellSet::empty(&g);
        for iy in 0..g.ny {
            for ix in 0..g.nx {
                x = x
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                s.set((ix, iy), ((x >> 33) as f64 / (1u64 << 31) as f64) < density);
            }
        }
        s
    }

    fn target(id: u32, x: f64, y: f64) -> TargetTruth {
        TargetTruth {
            id,
            ground: [x, y],
            ..TargetTruth::default()
        }
    }

    #[test]
    fn an_agents_fused_sets_are_what_its_estimator_holds_after_fusing() {
        let cfg = config();
        // Three agents of one step with overlapping knowledge; target 1 identified by all,
        // 2 by the first only, 3 by the others only.
        let mut all: Vec<ObservedEstimate> = (0..3)
            .map(|uav| {
                let seed = 10 * u64::from(uav);
                let mut e = blank(&grid(), uav, 3);
                let mut x1 = scattered(seed + 1, 0.5);
                x1.or_assign(&set(&[(4, 4), (5, 4)]));
                e.estimate.sets.undetected = scattered(seed + 2, 0.8).into();
                e.estimate.sets.targets.insert(1, x1.into());
                if uav == 0 {
                    e.estimate
                        .sets
                        .targets
                        .insert(2, scattered(seed + 3, 0.5).into());
                } else {
                    e.estimate
                        .sets
                        .targets
                        .insert(3, scattered(seed + 4, 0.6).into());
                }
                e.estimate.sets.obstacle_neighbourhood = scattered(seed + 5, 0.1).into();
                e.estimate.sets.explored = scattered(seed + 6, 0.3).into();
                e.estimate.sets.hidden = scattered(seed + 7, 0.2).into();
                e.estimate.sets.free_ground = scattered(seed + 9, 0.2).into();
                e.unseen = scattered(seed + 8, 0.3);
                as_published(&mut e);
                e
            })
            .collect();
        for e in &mut all {
            e.estimate.pose = at(f64::from(e.uav()));
        }
        for own in &all {
            // The agent: its state as published, then the peers fused in its order.
            let mut state = state_of(own, &cfg);
            assert_eq!(state.hidden_history.unseen(), &own.unseen);
            for peer in all.iter().filter(|p| p.uav() != own.uav()) {
                state.fuse(&peer.estimate, &cfg);
            }
            let observed = FusedSets::of_agent(own, &all, &cfg, &Radio::perfect());
            assert_eq!(
                &*observed.undetected,
                state.undetected.cells(),
                "X̄ of {}",
                own.uav()
            );
            let cells: BTreeMap<u32, SharedSet> = state
                .targets
                .iter()
                .map(|(id, s)| (*id, Arc::new(s.cells().clone())))
                .collect();
            assert_eq!(observed.targets, cells, "X_j of {}", own.uav());
            assert_eq!(
                *observed.obstacle_neighbourhood,
                state.obstacle_neighbourhood
            );
            assert_eq!(*observed.explored, state.explored);
            assert_eq!(&observed.unseen, state.hidden_history.unseen());
            assert_eq!(
                observed.targets.keys().copied().collect::<Vec<_>>(),
                vec![1, 2, 3]
            );
        }
    }

    #[test]
    fn agents_that_fuse_the_same_estimates_share_one_fusion_with_the_same_result() {
        let cfg = config();
        let g = grid();
        // Four agents of one step, each with scattered sets of its own; targets 1 and 2 are
        // identified by some only; agent 3 is out of a 100 m range; agent 0's target 7 and
        // agent 1's do not meet (an empty intersection, where the order matters).
        let all: Vec<ObservedEstimate> = (0..4u32)
            .map(|uav| {
                let seed = u64::from(uav) * 10;
                let mut e = blank(&g, uav, 3);
                e.estimate.pose = at(if uav == 3 {
                    500.0
                } else {
                    10.0 * f64::from(uav)
                });
                e.estimate.sets.undetected = scattered(seed + 1, 0.8).into();
                e.estimate.sets.explored = scattered(seed + 2, 0.3).into();
                e.estimate.sets.hidden = scattered(seed + 3, 0.1).into();
                e.estimate.sets.free_ground = scattered(seed + 7, 0.2).into();
                e.unseen = scattered(seed + 4, 0.2);
                as_published(&mut e);
                let mut targets = vec![(1, scattered(seed + 5, 0.9))];
                if uav % 2 == 0 {
                    targets.push((2, scattered(seed + 6, 0.9)));
                }
                e.estimate.sets.targets =
                    targets.into_iter().map(|(id, s)| (id, s.into())).collect();
                e
            })
            .collect();
        let mut clashing = all.clone();
        clashing[0]
            .estimate
            .sets
            .targets
            .insert(7, set(&[(1, 1)]).into());
        clashing[1]
            .estimate
            .sets
            .targets
            .insert(7, set(&[(8, 8)]).into());
        for estimates in [&all, &clashing] {
            for range in [f64::INFINITY, 100.0] {
                for loss in [0.0, 0.5] {
                    let radio = Radio::perfect().with_range(range).with_loss(7, loss);
                    let shared = FusedSets::of_agents(estimates, estimates, &cfg, &radio);
                    for (own, fused) in estimates.iter().zip(&shared) {
                        let alone = FusedSets::of_agent(own, estimates, &cfg, &radio);
                        assert_eq!(fused, &alone, "agent {} at {radio:?}", own.uav());
                    }
                }
            }
        }
    }

    #[test]
    fn a_target_one_agent_has_not_identified_is_met_with_its_undetected_set() {
        let cfg = config();
        // Agent 0 identified target 4 over a 2 x 1 block; agent 1 has not, and has proven the
        // block's east cell free (not in its X̄).
        let a = estimate(0, CellSet::full(&grid()), &[(4, set(&[(5, 5), (6, 5)]))]);
        let mut b_undetected = CellSet::full(&grid());
        b_undetected.set((6, 5), false);
        let b = estimate(1, b_undetected, &[]);
        let all = [a, b];
        for own in &all {
            let fused = FusedSets::of_agent(own, &all, &cfg, &Radio::perfect());
            assert_eq!(
                *fused.targets[&4],
                set(&[(5, 5)]),
                "seen from {}",
                own.uav()
            );
        }
    }

    #[test]
    fn with_a_finite_range_each_agent_measures_what_it_fused_itself() {
        let cfg = config();
        let g = grid();
        // Three agents along x, the first two 50 m apart and the third 500 m away, links of
        // 100 m. Each holds occluded ground of its own in its X̄: row `uav`, never seen by
        // the others (whose X̄ keeps it too).
        let all: Vec<ObservedEstimate> = [0.0, 50.0, 550.0]
            .into_iter()
            .enumerate()
            .map(|(i, x)| {
                let uav = i as u32;
                let mut e = blank(&g, uav, 3);
                e.estimate.pose = at(x);
                let row: Vec<CellIndex> = (0..g.nx).map(|ix| (ix, uav)).collect();
                e.unseen = set(&row);
                // Each agent explored a column of its own.
                let column: Vec<CellIndex> = (0..g.ny).map(|iy| (9 - uav, iy)).collect();
                let mut undetected = CellSet::full(&g);
                undetected.and_not_assign(&set(&column));
                e.estimate.sets.explored = set(&column).into();
                e.estimate.sets.undetected = undetected.into();
                e
            })
            .collect();
        let measure = |range: f64| -> Vec<SetMetrics> {
            all.iter()
                .map(|own| {
                    let radio = Radio::perfect().with_range(range);
                    SetMetrics::measure(&FusedSets::of_agent(own, &all, &cfg, &radio), &[], &g)
                })
                .collect()
        };
        let near_links = Radio::perfect().with_range(100.0);
        assert_eq!(
            fused_peers(&all[0], &all, &near_links)
                .map(ObservedEstimate::uav)
                .collect::<Vec<_>>(),
            vec![1]
        );
        assert_eq!(fused_peers(&all[2], &all, &near_links).count(), 0);
        let near = measure(100.0);
        let perfect = measure(f64::INFINITY);
        // Agents 0 and 1 removed each other's column; agent 2 only its own.
        assert_eq!((near[0].ua, near[1].ua, near[2].ua), (0.8, 0.8, 0.9));
        assert_eq!((near[0].explored, near[2].explored), (0.2, 0.1));
        assert!(perfect.iter().all(|m| m.ua == 0.7 && m.explored == 0.3));
        // Each agent's occluded ground is still in its X̄: OA is not 0. (The intersection of
        // every agent's H̄ is empty, which the fleet-wide reading used to report.)
        assert_eq!((near[0].oa, near[1].oa, near[2].oa), (0.08, 0.08, 0.09));
        assert!(perfect.iter().all(|m| m.oa > 0.0));
        let spread = AgentSpread::over(&near).unwrap();
        assert!((spread.mean.ua - (0.8 + 0.8 + 0.9) / 3.0).abs() < 1e-12);
        assert_eq!((spread.worst.ua, spread.worst.explored), (0.9, 0.1));
        let all_to_all = AgentSpread::over(&perfect).unwrap();
        assert!(spread.mean.ua > all_to_all.mean.ua);
    }

    /// Four agents, each with scattered sets of its own, at `step`.
    fn scattered_fleet(step: u64, salt: u64) -> Vec<ObservedEstimate> {
        (0..4u32)
            .map(|uav| {
                let seed = u64::from(uav) * 10 + salt;
                let mut e = blank(&grid(), uav, step);
                e.estimate.pose = at(10.0 * f64::from(uav));
                e.estimate.sets.undetected = scattered(seed + 1, 0.8).into();
                e.estimate.sets.explored = scattered(seed + 2, 0.3).into();
                e.estimate.sets.hidden = scattered(seed + 3, 0.1).into();
                e.estimate.sets.free_ground = scattered(seed + 6, 0.2).into();
                e.unseen = scattered(seed + 4, 0.2);
                as_published(&mut e);
                e.estimate.sets.targets = [(1, scattered(seed + 5, 0.9).into())].into();
                e
            })
            .collect()
    }

    /// An agent's state as it published `own`.
    fn state_of(own: &ObservedEstimate, cfg: &EstimatorConfig) -> EstimatorState {
        let step = own.estimate.step;
        let e = &own.estimate.sets;
        let mut state = EstimatorState::new(cfg);
        state.step = step;
        state.undetected = ReachSet::with_cells((*e.undetected).clone());
        state.targets = e
            .targets
            .iter()
            .map(|(id, s)| (*id, ReachSet::with_cells((**s).clone())))
            .collect();
        state.obstacle_neighbourhood = (*e.obstacle_neighbourhood).clone();
        state.explored = (*e.explored).clone();
        state.hidden = (*e.hidden).clone();
        state.free_ground = (*e.free_ground).clone();
        // The H̄ it held before its frame of the step (what it published, less the frame's
        // hidden ground, would do as well), then the frame.
        let none = CellSet::empty(&cfg.grid);
        let history = &mut state.hidden_history;
        history.record(step.saturating_sub(1), &own.unseen, &none);
        history.record(step, &e.hidden, &e.free_ground);
        assert_eq!(history.unseen(), &own.unseen, "a consistent fixture");
        state
    }

    /// Makes `e`'s published `H̄` what an agent publishes after its frame: holding the frame's
    /// hidden ground and none of the ground it proved free (which it did not see hidden).
    fn as_published(e: &mut ObservedEstimate) {
        let mut hidden = (*e.estimate.sets.hidden).clone();
        hidden.and_not_assign(&e.estimate.sets.free_ground);
        e.unseen.or_assign(&hidden);
        e.unseen.and_not_assign(&e.estimate.sets.free_ground);
        e.estimate.sets.hidden = hidden.into();
    }

    #[test]
    fn on_lossy_links_each_agent_measures_the_estimates_its_radio_delivered() {
        let cfg = config();
        let all = scattered_fleet(3, 0);
        let radio = Radio::perfect().with_loss(11, 0.5);
        let mut lost = 0;
        for own in &all {
            let delivered: Vec<u32> = all
                .iter()
                .map(ObservedEstimate::uav)
                .filter(|&j| j != own.uav())
                .filter(|&j| radio.delivers(LinkKind::Estimate, j, own.uav(), 3))
                .collect();
            lost += 3 - delivered.len();
            let peers: Vec<u32> = fused_peers(own, &all, &radio)
                .map(ObservedEstimate::uav)
                .collect();
            assert_eq!(peers, delivered, "agent {}", own.uav());
            // The agent: its own state, then what the radio delivered, ascending.
            let mut state = state_of(own, &cfg);
            for peer in all.iter().filter(|p| delivered.contains(&p.uav())) {
                state.fuse(&peer.estimate, &cfg);
            }
            let observed = FusedSets::of_agent(own, &all, &cfg, &radio);
            assert_eq!(&*observed.undetected, state.undetected.cells());
            assert_eq!(*observed.explored, state.explored);
            assert_eq!(&observed.unseen, state.hidden_history.unseen());
        }
        assert!(
            lost > 0 && lost < 12,
            "the seed loses some and not all: {lost}"
        );
        // At full loss an agent fuses nothing but its own estimate.
        let deaf = Radio::perfect().with_loss(11, 1.0);
        assert!(
            all.iter()
                .all(|own| fused_peers(own, &all, &deaf).count() == 0)
        );
    }

    #[test]
    fn with_latency_each_agent_fuses_the_estimates_sent_that_many_steps_before() {
        let cfg = config();
        let before = scattered_fleet(5, 100);
        let now = scattered_fleet(7, 200);
        let radio = Radio::perfect().with_latency_steps(2).with_loss(3, 0.3);
        let fused = FusedSets::of_agents(&now, &before, &cfg, &radio);
        let mut fused_any = false;
        for (own, observed) in now.iter().zip(&fused) {
            let mut state = state_of(own, &cfg);
            for peer in fused_peers(own, &before, &radio) {
                assert_eq!(peer.step(), 5);
                let report = state.fuse(&peer.estimate, &cfg);
                assert_eq!(report.step_lag, 2, "dilated by the latency");
                fused_any = true;
            }
            assert_eq!(&*observed.undetected, state.undetected.cells());
            let cells: BTreeMap<u32, SharedSet> = state
                .targets
                .iter()
                .map(|(id, s)| (*id, Arc::new(s.cells().clone())))
                .collect();
            assert_eq!(observed.targets, cells);
            assert_eq!(&observed.unseen, state.hidden_history.unseen());
            assert_eq!(observed, &FusedSets::of_agent(own, &before, &cfg, &radio));
        }
        assert!(fused_any);
        // Estimates of any other step are not fused, and nothing before step d.
        assert!(
            now.iter()
                .all(|own| fused_peers(own, &now, &radio).count() == 0)
        );
        let early = scattered_fleet(1, 0);
        assert!(
            early
                .iter()
                .all(|own| fused_peers(own, &early, &radio).count() == 0)
        );
    }

    #[test]
    fn unseen_is_ground_hidden_from_the_fleet_and_seen_by_no_fused_uav_since() {
        let cfg = config();
        let g = grid();
        // Step 3: A's frame hid c, B's proved c and d free, C's held d in its H̄ and saw
        // neither. A and C are 10 m apart, B 200 m away from both.
        let (c, d) = ((2, 2), (7, 7));
        let uav = |id: u32, x: f64, hidden: &[CellIndex], free: &[CellIndex], unseen| {
            let mut e = blank(&g, id, 3);
            e.estimate.pose = at(x);
            e.estimate.sets.hidden = set(hidden).into();
            e.estimate.sets.free_ground = set(free).into();
            e.unseen = unseen;
            as_published(&mut e);
            e
        };
        let a = uav(0, 0.0, &[c], &[], CellSet::empty(&g));
        let b = uav(1, 200.0, &[], &[c, d], CellSet::empty(&g));
        let own = uav(2, 10.0, &[], &[], set(&[d]));
        let all = [a.clone(), b.clone(), own.clone()];
        // C fuses A's and B's estimates of the step, in either order: c and d were seen.
        for order in [[&a, &b], [&b, &a]] {
            let fused = FusedSets::fuse(&own, order, &cfg);
            assert!(fused.unseen.is_empty(), "{:?}", fused.unseen);
        }
        // Which is what every agent holds, with every link up, and what its estimator holds.
        let radio = Radio::perfect();
        let shared = FusedSets::of_agents(&all, &all, &cfg, &radio);
        for (e, fused) in all.iter().zip(&shared) {
            assert!(fused.unseen.is_empty(), "agent {}", e.uav());
        }
        // With links of 100 m, C hears A only: c is unseen, and d is still.
        let near = Radio::perfect().with_range(100.0);
        let shared = FusedSets::of_agents(&all, &all, &cfg, &near);
        assert_eq!(shared[0].unseen, set(&[c]), "A hears C, which saw no c");
        assert_eq!(shared[1].unseen, CellSet::empty(&g), "B hears nobody");
        assert_eq!(shared[2].unseen, set(&[c, d]));
        for (e, fused) in all.iter().zip(&shared) {
            let mut state = state_of(e, &cfg);
            for peer in fused_peers(e, &all, &near) {
                state.fuse(&peer.estimate, &cfg);
            }
            assert_eq!(&fused.unseen, state.hidden_history.unseen(), "{}", e.uav());
        }
    }

    /// The agents' own code over rendered frames (the in-process fleet of `fleet bench`): at
    /// every step, what the observer rebuilds from the estimates each agent published is what
    /// its estimator holds once it fused its peers' (every one, as with perfect links). Under
    /// the set exchange: the measurement exchange's estimates carry no sets to rebuild from,
    /// and its observer measures the agents' state messages instead.
    #[test]
    fn the_observer_rebuilds_each_estimators_fused_sets_over_a_rendered_run() {
        let scenario = Scenario::load(
            None,
            &[
                "region.half_extent_m=60".into(),
                "targets.count=3".into(),
                "uavs.count=3".into(),
                "comms.exchange=sets".into(),
            ],
        )
        .expect("scenario");
        let cfg = EstimatorConfig::from_scenario(&scenario);
        let mut sim = guided_fleet(&scenario).expect("fleet");
        // Cells that a peer's frame of the step proved free, which the old rule (the agent's
        // published H̄ joined with its peers' hidden ground) kept.
        let mut cleared_by_peers = 0;
        for _ in 0..16 {
            sim.step().expect("step");
            let observed: Vec<ObservedEstimate> = sim
                .messages()
                .iter()
                .map(|bytes| ObservedEstimate::decode(bytes, &cfg).expect("decode").0)
                .collect();
            let fused = FusedSets::of_agents(&observed, &observed, &cfg, &Radio::perfect());
            for ((own, sets), estimator) in observed.iter().zip(&fused).zip(sim.estimators()) {
                let state = estimator.state();
                let at = (own.uav(), own.step());
                assert_eq!(&sets.unseen, state.hidden_history.unseen(), "H̄ of {at:?}");
                assert_eq!(&*sets.undetected, state.undetected.cells(), "X̄ of {at:?}");
                assert_eq!(*sets.explored, state.explored, "explored of {at:?}");
                let mut old_rule = own.unseen.clone();
                for peer in observed.iter().filter(|p| p.uav() != own.uav()) {
                    old_rule.or_assign(&peer.estimate.sets.hidden);
                }
                assert!(sets.unseen.is_subset_of(&old_rule));
                cleared_by_peers += old_rule.difference_count(&sets.unseen);
            }
        }
        assert!(cleared_by_peers > 0, "the run exercises the fleet's rule");
    }

    #[test]
    fn measures_and_spread_over_agents() {
        let g = grid();
        let mut a = estimate(
            0,
            set(&[(0, 0), (1, 0), (2, 0)]),
            &[(4, set(&[(5, 5), (6, 5)])), (7, set(&[(0, 9)]))],
        );
        a.estimate.sets.explored = set(&[(8, 9), (9, 9)]).into();
        a.unseen = set(&[(1, 0), (5, 5)]);
        let fused = FusedSets::fuse(&a, [], &config());
        let truth = [target(4, 1.5, 1.5), target(7, -4.5, 4.5)];
        let m = SetMetrics::measure(&fused, &truth, &g);
        assert_eq!(m.ua, 0.03);
        assert_eq!(m.oa, 0.01);
        assert_eq!(m.explored, 0.02);
        assert_eq!(m.identified, 2.0);
        assert_eq!(m.target_set_area, Some(0.015));
        // Target 4's set has its barycentre at (1.0, 0.5), 0.5 m west and 1 m south of it;
        // target 7 sits on its set's only cell centre.
        let expected = (0.5_f64.hypot(1.0) + 0.0) / 2.0;
        assert!((m.loc_error_m.unwrap() - expected).abs() < 1e-12);

        let b = SetMetrics {
            explored: 0.5,
            ua: 0.01,
            oa: 0.0,
            target_set_area: None,
            loc_error_m: None,
            identified: 0.0,
        };
        let s = AgentSpread::over([&m, &b]).unwrap();
        assert_eq!(s.mean.identified, 1.0);
        assert_eq!(s.worst.identified, 0.0);
        assert_eq!(
            (s.worst.ua, s.worst.oa, s.worst.explored),
            (0.03, 0.01, 0.02)
        );
        assert!((s.mean.ua - 0.02).abs() < 1e-12);
        // Only the agent that has a target set counts for the target metrics.
        assert_eq!(s.mean.target_set_area, Some(0.015));
        assert_eq!(s.worst.loc_error_m, m.loc_error_m);
        assert!(AgentSpread::over([]).is_none());
    }

    #[test]
    fn under_windows_an_agent_is_measured_over_its_window_and_the_fleet_over_the_intersection() {
        let g = grid();
        // Agent 0 still holds the cells of columns 0-4 of row 0, agent 1 those of columns 3-7:
        // the fleet's X̄ is columns 3 and 4.
        let row = |x0: u32, x1: u32| set(&(x0..=x1).map(|x| (x, 0)).collect::<Vec<_>>());
        let mut a = estimate(0, row(0, 4), &[]);
        a.unseen = set(&[(0, 0), (4, 0), (9, 9)]);
        let b = estimate(1, row(3, 7), &[]);
        let (fa, fb) = (
            FusedSets::fuse(&a, [], &config()),
            FusedSets::fuse(&b, [], &config()),
        );
        // Agent 0's window: columns 0-1 of rows 0-4, 10 cells, 2 of them in X̄, 1 hidden.
        let window = CellBox {
            x0: 0,
            y0: 0,
            x1: 1,
            y1: 4,
        };
        let whole = SetMetrics::measure(&fa, &[], &g);
        let m = whole.within(&fa, &window);
        assert_eq!((whole.ua, whole.oa), (0.05, 0.02));
        assert_eq!((m.ua, m.oa), (0.2, 0.1));
        assert_eq!(m.explored, whole.explored);
        // The fleet: 2 cells of 100; agent 0's H̄ holds one of them, agent 1's none.
        assert_eq!(fleet_areas([&fa, &fb], &g), Some((0.02, 0.005)));
        // Agents that hold the same X̄: the fleet's UA and OA are theirs.
        assert_eq!(fleet_areas([&fa, &fa], &g), Some((whole.ua, whole.oa)));
        assert_eq!(fleet_areas([], &g), None);
    }

    #[test]
    fn the_window_tally_counts_the_cars_sets_that_meet_an_agents_window() {
        use super::super::tally::WindowTally;
        use crate::results::summary::WindowsSummary;
        // Car 1's set meets the window (columns 0-1 of rows 0-4) by one of its 3 cells; car
        // 2's, of 1 cell, lies outside it.
        let e = estimate(
            0,
            CellSet::full(&grid()),
            &[(1, set(&[(1, 4), (2, 4), (3, 4)])), (2, set(&[(8, 8)]))],
        );
        let fused = FusedSets::fuse(&e, [], &config());
        let window = CellBox {
            x0: 0,
            y0: 0,
            x1: 1,
            y1: 4,
        };
        let mut tally = WindowTally::default();
        tally.count(&fused, &window);
        tally.count(&fused, &CellBox { x0: 5, ..window });
        assert_eq!(
            tally,
            WindowTally {
                agent_steps: 2,
                targets: 4,
                targets_meeting: 1,
                target_cells: 8,
                target_cells_meeting: 3,
            }
        );
        let summary = WindowsSummary::of(&tally).expect("two agent-steps");
        assert_eq!(summary.targets_held_mean, 2.0);
        assert_eq!(summary.targets_meeting_window_mean, 0.5);
        assert_eq!(summary.targets_meeting_window_share, Some(0.25));
        assert_eq!(summary.target_cells_meeting_window_share, Some(0.375));
        assert_eq!(WindowsSummary::of(&WindowTally::default()), None);
    }

    #[test]
    fn nothing_identified_leaves_the_target_metrics_empty() {
        let e = estimate(0, CellSet::full(&grid()), &[]);
        let m = SetMetrics::measure(&FusedSets::fuse(&e, [], &config()), &[], &grid());
        assert_eq!((m.ua, m.target_set_area, m.loc_error_m), (1.0, None, None));
    }

    #[test]
    fn a_target_outside_its_set_is_one_violation_with_its_distance() {
        let g = grid();
        // Target 1 unidentified at cell (0, 0), inside X̄; target 2 identified, 2 m away from
        // its set; target 3 unidentified, outside X̄.
        let e = estimate(2, set(&[(0, 0)]), &[(2, set(&[(5, 5)]))]);
        let truth = [
            target(1, -4.5, -4.5),
            target(2, 3.5, 0.5),
            target(3, 4.5, 4.5),
        ];
        let v = violations(&e, &truth, &g);
        assert_eq!(v.len(), 2);
        assert_eq!(
            (v[0].uav, v[0].target, v[0].set),
            (2, 2, ViolatedSet::Target)
        );
        assert!((v[0].distance_m - 2.5).abs() < 1e-12);
        assert_eq!((v[1].target, v[1].set), (3, ViolatedSet::Undetected));
        assert!(v[1].distance_m > 10.0);
        assert_eq!(identified_ids([&e]), BTreeSet::from([2]));
    }

    #[test]
    fn a_target_on_the_far_border_belongs_to_the_last_cell() {
        let g = grid();
        let e = estimate(0, set(&[(9, 9)]), &[]);
        assert!(violations(&e, &[target(1, 5.0, 5.0)], &g).is_empty());
        assert_eq!(violations(&e, &[target(1, 5.5, 5.0)], &g).len(), 1);
        let empty = estimate(0, CellSet::empty(&g), &[]);
        assert_eq!(
            violations(&empty, &[target(1, 0.0, 0.0)], &g)[0].distance_m,
            f64::INFINITY
        );
    }
}
