//! The per-step metrics of DESIGN.md §6 and the guarantee check, as pure functions of the
//! agents' published estimates and the ground truth (so they are unit-tested without
//! processes).
//!
//! The fleet's knowledge at a step is the fusion of what its agents published for that step:
//! `X̄` and `H̄` are intersected (each is an outer set, so is their meet), the explored ground
//! and `S^o` are unioned (each is proven), and `X_j` is intersected over the agents that
//! identified `j`. Every area is a fraction of the grid's area (the region of interest).

use std::collections::{BTreeMap, BTreeSet};

use protocol::grid::{CellIndex, GroundGrid};
use protocol::math::Point2;
use protocol::raster::{CellSet, SetDecodeError};
use protocol::wire::{AgentStats, TargetTruth};
use uav_agent::estimator::{EstimateReadError, EstimatorConfig, PeerEstimate, message};
use uav_agent::occupancy::OccupancyMap;

/// What the observer keeps of one agent's estimate of one step.
#[derive(Clone, Debug, PartialEq)]
pub struct ObservedEstimate {
    /// Sender.
    pub uav: u32,
    /// Step of the sets.
    pub step: u64,
    /// Sender's incarnation (changes when it restarts).
    pub incarnation: u64,
    /// Sender's message counter in this incarnation.
    pub seq: u64,
    /// `X̄`.
    pub undetected: CellSet,
    /// `X_j` per identified id.
    pub targets: BTreeMap<u32, CellSet>,
    /// `S^o`.
    pub obstacle_free: CellSet,
    /// Ground proven free at some frame.
    pub explored: CellSet,
    /// `H̄`: ground hidden earlier and not seen since.
    pub unseen: CellSet,
    /// The sender's counters.
    pub stats: AgentStats,
}

/// Why an estimate could not be read by the observer.
#[derive(Debug, thiserror::Error)]
pub enum EstimateObserveError {
    /// The message does not decode or validate as an estimate.
    #[error(transparent)]
    Read(#[from] EstimateReadError),
    /// Its `H̄` set is malformed or on another grid.
    #[error("bad unseen set: {0}")]
    Unseen(#[from] SetDecodeError),
}

impl ObservedEstimate {
    /// Decodes and validates an estimate's bytes; also returns the map cells it carries.
    pub fn decode(
        bytes: &[u8],
        config: &EstimatorConfig,
    ) -> Result<(ObservedEstimate, OccupancyMap), EstimateObserveError> {
        let msg = message::from_bytes(bytes).map_err(EstimateReadError::from)?;
        let peer = PeerEstimate::from_msg(&msg, config)?;
        let unseen = CellSet::decode(&config.grid, &msg.unseen)?;
        let observed = ObservedEstimate {
            uav: peer.uav,
            step: peer.step,
            incarnation: peer.incarnation,
            seq: peer.seq,
            undetected: peer.undetected,
            targets: peer.targets,
            obstacle_free: peer.obstacle_free,
            explored: peer.explored,
            unseen,
            stats: msg.stats,
        };
        Ok((observed, peer.oem))
    }
}

/// The fleet's fused sets at one step.
#[derive(Clone, Debug, PartialEq)]
pub struct FusedSets {
    /// `∩ X̄`.
    pub undetected: CellSet,
    /// `∩ X_j` over the agents that identified `j`.
    pub targets: BTreeMap<u32, CellSet>,
    /// `∪ S^o`.
    pub obstacle_free: CellSet,
    /// `∪ explored`.
    pub explored: CellSet,
    /// `∩ H̄`.
    pub unseen: CellSet,
}

impl FusedSets {
    /// Fuses the estimates of one step; `None` when there is none.
    pub fn fuse<'a>(estimates: impl IntoIterator<Item = &'a ObservedEstimate>) -> Option<Self> {
        let mut it = estimates.into_iter();
        let first = it.next()?;
        let mut fused = FusedSets {
            undetected: first.undetected.clone(),
            targets: first.targets.clone(),
            obstacle_free: first.obstacle_free.clone(),
            explored: first.explored.clone(),
            unseen: first.unseen.clone(),
        };
        for e in it {
            fused.undetected.and_assign(&e.undetected);
            for (id, set) in &e.targets {
                match fused.targets.get_mut(id) {
                    Some(mine) => mine.and_assign(set),
                    None => {
                        fused.targets.insert(*id, set.clone());
                    }
                }
            }
            fused.obstacle_free.or_assign(&e.obstacle_free);
            fused.explored.or_assign(&e.explored);
            fused.unseen.and_assign(&e.unseen);
        }
        Some(fused)
    }
}

/// The set metrics of one step (fractions of the grid's area, distances in metres).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SetMetrics {
    /// `|∪ explored|`.
    pub explored: f64,
    /// `|∩ X̄|` (UA).
    pub ua: f64,
    /// `|∩ X̄ ∩ ∩ H̄|` (OA).
    pub oa: f64,
    /// Mean over identified ids of `|∩ X_j|`; `None` when nothing is identified.
    pub target_set_area: Option<f64>,
    /// Mean over identified ids (present in the truth) of the distance between the target
    /// and the barycentre of `∩ X_j`; `None` when there is none.
    pub loc_error_m: Option<f64>,
    /// `|∪ identified lists|`.
    pub identified: u32,
}

impl SetMetrics {
    /// Measures the fused sets against the truth.
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
            identified: fused.targets.len() as u32,
        }
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
        let (set, kind) = match estimate.targets.get(&t.id) {
            Some(set) => (set, ViolatedSet::Target),
            None => (&estimate.undetected, ViolatedSet::Undetected),
        };
        let inside = cell_of_closed(grid, &p).is_some_and(|c| set.contains(c));
        if !inside {
            out.push(Violation {
                uav: estimate.uav,
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
        .flat_map(|e| e.targets.keys().copied())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 10 x 10 grid of 1 m cells over [-5, 5]^2.
    fn grid() -> GroundGrid {
        GroundGrid::new(5.0, 1.0)
    }

    fn set(cells: &[CellIndex]) -> CellSet {
        CellSet::from_cells(&grid(), cells.iter().copied())
    }

    fn estimate(uav: u32, undetected: CellSet, targets: &[(u32, CellSet)]) -> ObservedEstimate {
        let g = grid();
        ObservedEstimate {
            uav,
            step: 3,
            incarnation: 1,
            seq: 3,
            undetected,
            targets: targets.iter().cloned().collect(),
            obstacle_free: CellSet::empty(&g),
            explored: CellSet::empty(&g),
            unseen: CellSet::full(&g),
            stats: AgentStats::default(),
        }
    }

    fn target(id: u32, x: f64, y: f64) -> TargetTruth {
        TargetTruth {
            id,
            ground: [x, y],
            ..TargetTruth::default()
        }
    }

    #[test]
    fn fusion_meets_outer_sets_and_joins_proven_ones() {
        let g = grid();
        let mut a = estimate(
            0,
            set(&[(0, 0), (1, 0), (2, 0)]),
            &[(4, set(&[(5, 5), (6, 5)]))],
        );
        a.explored = set(&[(9, 9)]);
        a.unseen = set(&[(1, 0), (2, 0)]);
        let mut b = estimate(
            1,
            set(&[(1, 0), (2, 0), (3, 0)]),
            &[(4, set(&[(6, 5)])), (7, set(&[(0, 9)]))],
        );
        b.explored = set(&[(8, 9)]);
        b.unseen = set(&[(2, 0), (3, 0)]);
        let f = FusedSets::fuse([&a, &b]).unwrap();
        assert_eq!(&f.undetected, &set(&[(1, 0), (2, 0)]));
        assert_eq!(f.targets[&4], set(&[(6, 5)]));
        assert_eq!(f.targets[&7], set(&[(0, 9)]));
        assert_eq!(f.explored, set(&[(8, 9), (9, 9)]));
        let truth = [target(4, 1.5, 1.5), target(7, -4.5, 4.5)];
        let m = SetMetrics::measure(&f, &truth, &g);
        assert_eq!(m.ua, 0.02);
        assert_eq!(m.oa, 0.01);
        assert_eq!(m.explored, 0.02);
        assert_eq!(m.identified, 2);
        assert_eq!(m.target_set_area, Some(0.01));
        // Target 4 is 1 m from the centre (1.5, 0.5) of cell (6, 5); target 7 sits on its own.
        assert!((m.loc_error_m.unwrap() - 0.5).abs() < 1e-12);
        assert!(FusedSets::fuse(std::iter::empty()).is_none());
    }

    #[test]
    fn nothing_identified_leaves_the_target_metrics_empty() {
        let e = estimate(0, CellSet::full(&grid()), &[]);
        let m = SetMetrics::measure(&FusedSets::fuse([&e]).unwrap(), &[], &grid());
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
