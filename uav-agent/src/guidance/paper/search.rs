//! The paper's MPC search (docs/design.md §4) as a branch and bound that decides exactly as
//! the plain enumeration of `U^h`.
//!
//! 1. **Bounds, cheaply.** Every sequence is simulated (its poses and how far it strays out of
//!    the RoI) and given a lower bound of its cost: its sets predicted with the fields of view
//!    *before* buildings hide anything. Those views hold every cell the true views hold, so the
//!    bound's sets lie inside the true ones at every period (the dilation and the set
//!    differences keep inclusions), and `J` cannot be smaller than the bound's (with
//!    `λ, κ >= 0`, as the sets' areas only grow and `Φ_d >= 0`; rounded sums and products are
//!    monotone). This holds under every reading of the module docs' table: the sets are
//!    predicted on one grid (`guidance.set_resolution`), and on either `Φ_X` is a cell count,
//!    `Φ_h` a sum of non-negative counts over the predicted cells (or over the planning cells
//!    holding one), both monotone in the predicted sets whichever sets and resolution
//!    `hidden_sets` and `hidden_resolution` choose, and `Φ_d` is a distance from whichever
//!    point `distance_from` names. Prefixes are shared: the state after a prefix is computed
//!    once.
//! 2. **Exact costs, best bound first.** Sequences are visited by (stray, bound, order of the
//!    increments); the true sets of a prefix (views less the shadows of known buildings,
//!    rasterised only on the ground of the sets) are computed once, when the first sequence
//!    through it is. A sequence whose prefix is known is bounded again from the prefix's true
//!    sets and its last period's views without shadows, and skipped if that cannot win; `Φ_d`
//!    is computed only when the rest of `J` can still win. The visit stops at the first
//!    sequence whose bound cannot beat the best cost found: the rest cannot either.
//!
//! The winner is the least (stray, `J`, order) sequence, which is the plain enumeration's:
//! it keeps the first in order of the least (stray, `J`). With a negative or non-finite
//! weight the bound does not hold, and every sequence is costed, in order.

use std::collections::BTreeMap;

use protocol::camera::CameraPose;
use protocol::flight::UavState;
use protocol::wire::PlannedView;
use sets::grid::GroundGrid;
use sets::raster::CellSet;

use super::{HiddenMeasure, seen_by_others};
use crate::guidance::view::{self, same_pose};
use crate::guidance::{
    Cost, Decision, GroundPredictor, GuidanceParams, ObstacleCell, PlanningInput, decision,
    fly_step, stray,
};

/// A sequence, simulated, with the lower bound of its cost.
struct Leaf {
    /// Indices of its increments in `U`.
    path: Vec<usize>,
    poses: Vec<CameraPose>,
    stray_m: f64,
    /// `J` of its sets predicted without shadows, with `Φ_d = 0`.
    bound: f64,
}

/// A prefix's predicted true sets, and its sets grown for the next period.
struct Exact {
    state: UavState,
    sets: CellSet,
    grown: Option<CellSet>,
    /// The views (on `grown`) of its children's first viewed poses, by pose: with a view at
    /// every frame, the increments the yaw rate cannot reach in one CVS step (the large turns
    /// to either side) fly the same first step, whose view is computed once.
    first_views: Vec<(CameraPose, CellSet)>,
}

/// The search's fixed inputs and buffers.
struct Search<'a> {
    params: &'a GuidanceParams,
    /// The grid the sets are predicted on (`guidance.set_resolution`).
    grid: GroundGrid,
    obstacles: &'a [ObstacleCell],
    /// Ground the UAVs ahead in the token will see, per period.
    others_seen: Vec<CellSet>,
    /// Recently hidden ground as `Φ_h` counts it.
    hidden: HiddenMeasure,
    predictor: GroundPredictor,
}

/// Picks the best sequence of yaw increments: see the module docs.
pub(super) fn plan(params: &GuidanceParams, input: &PlanningInput<'_>) -> Decision {
    let grid = params.paper_grids().coarse;
    let sets = params.start_sets(input.sets);
    let obstacles = &view::tallest_first(if params.use_map { input.obstacles } else { &[] });
    // Every pose is predicted for the bounds, then again for the exact costs.
    let mut predictor = GroundPredictor::remembering_footprints(&grid);
    let others_seen = others_seen(params, input.others, &sets, obstacles, &mut predictor);
    let mut search = Search {
        params,
        grid,
        obstacles,
        others_seen,
        hidden: params.hidden_measure(input.sets, input.recently_hidden),
        predictor,
    };
    let bounded = [params.lambda, params.kappa]
        .iter()
        .all(|w| w.is_finite() && *w >= 0.0);
    let leaves = search.leaves(input.state, &sets, bounded);
    let sequences = leaves.len();
    let excluded = leaves.iter().filter(|l| l.stray_m > 0.0).count();
    let best = search
        .best(&leaves, input.state, sets, bounded)
        .map(|(cost, leaf)| {
            let increments = leaf.path.iter().map(|&i| params.increments[i]).collect();
            (increments, cost, leaf.poses.clone())
        });
    decision(input, best, sequences, excluded)
}

/// The ground the UAVs ahead in the token will see in each period of the horizon, where it
/// can change the predicted sets: where the sets can be by the period's end (the sets only
/// grow by the dilation of each period, so every prediction stays inside the sets dilated
/// once per period so far).
fn others_seen(
    params: &GuidanceParams,
    others: &[PlannedView],
    sets: &CellSet,
    obstacles: &[ObstacleCell],
    predictor: &mut GroundPredictor,
) -> Vec<CellSet> {
    let grid = params.paper_grids().coarse;
    let mut reachable = sets.clone();
    (0..params.horizon)
        .map(|period| {
            if others.is_empty() {
                return CellSet::empty(&grid);
            }
            reachable = reachable.dilate(&grid, growth_m(params));
            seen_by_others(params, others, period, obstacles, predictor, &reachable)
        })
        .collect()
}

/// A sequence's rank: how far it strays out of the RoI, `J` (or a bound of it), and the
/// indices of its increments.
type Key<'p> = (f64, f64, &'p [usize]);

/// Whether `key` ranks strictly before `best` (always, when there is no best yet).
fn beats(key: Key<'_>, best: Option<&Key<'_>>) -> bool {
    best.is_none_or(|b| key < *b)
}

/// How far the targets can go in a guidance period, m.
fn growth_m(params: &GuidanceParams) -> f64 {
    params.target_max_speed * params.steps_per_period as f64 * params.dt
}

/// The cost of predicted sets `sets` (on `grid`) with `Φ_d = distance_m`.
fn terms(
    params: &GuidanceParams,
    grid: &GroundGrid,
    sets: &CellSet,
    hidden: &HiddenMeasure,
    distance_m: f64,
) -> Cost {
    let area_m2 = sets.count() as f64 * grid.cell_area();
    let hidden_m2 = hidden.area_in(sets);
    Cost {
        area_m2,
        distance_m,
        hidden_m2,
        total: area_m2 + params.lambda * distance_m + params.kappa * hidden_m2,
    }
}

impl Search<'_> {
    /// Step 1 of the module docs: every sequence simulated from `start` (whose sets are
    /// `sets`) and bounded, in the order of the increments, then, when the bounds hold
    /// (`bounded`), sorted by (stray, bound); the sort is stable, so equal keys keep the
    /// order of the increments.
    fn leaves(&mut self, start: UavState, sets: &CellSet, bounded: bool) -> Vec<Leaf> {
        let mut leaves = Vec::new();
        self.bound(
            &mut Vec::new(),
            start,
            &mut Vec::new(),
            0.0,
            sets,
            &mut leaves,
        );
        if bounded {
            leaves.sort_by(|a, b| {
                a.stray_m
                    .total_cmp(&b.stray_m)
                    .then(a.bound.total_cmp(&b.bound))
            });
        }
        leaves
    }

    /// Step 2 of the module docs: the sequences of `leaves` costed exactly in their order,
    /// from `start` and its sets `sets`, skipping those whose bound cannot win and stopping at
    /// the first whose bound cannot beat the best cost (every sequence is costed when the
    /// bounds do not hold); the least (stray, `J`, order) sequence and its cost.
    fn best<'l>(
        &mut self,
        leaves: &'l [Leaf],
        start: UavState,
        sets: CellSet,
        bounded: bool,
    ) -> Option<(Cost, &'l Leaf)> {
        let params = self.params;
        let mut exact: BTreeMap<Vec<usize>, Exact> = BTreeMap::new();
        exact.insert(
            Vec::new(),
            Exact {
                state: start,
                sets,
                grown: None,
                first_views: Vec::new(),
            },
        );
        // The best so far: its key, its cost and its leaf.
        let mut best: Option<(Key<'_>, Cost, &Leaf)> = None;
        for leaf in leaves {
            let best_key = best.as_ref().map(|(key, ..)| key);
            if bounded && !beats((leaf.stray_m, leaf.bound, &leaf.path), best_key) {
                break;
            }
            // Once the true sets of its prefix are known, a sequence's bound tightens to its
            // last period's views without shadows taken from them.
            if bounded
                && self
                    .tighter_bound(&mut exact, leaf)
                    .is_some_and(|bound| !beats((leaf.stray_m, bound, &leaf.path), best_key))
            {
                continue;
            }
            let Some(sets) = self.exact_sets(&mut exact, &leaf.path) else {
                continue;
            };
            let optimistic = terms(params, &self.grid, sets, &self.hidden, 0.0);
            if bounded && !beats((leaf.stray_m, optimistic.total, &leaf.path), best_key) {
                continue;
            }
            let distance_m = match leaf.poses.last() {
                Some(pose) => params.distance_term(sets, pose, self.obstacles),
                None => 0.0,
            };
            let cost = terms(params, &self.grid, sets, &self.hidden, distance_m);
            let key = (leaf.stray_m, cost.total, &leaf.path[..]);
            if beats(key, best.as_ref().map(|(key, ..)| key)) {
                best = Some((key, cost, leaf));
            }
        }
        best.map(|(_, cost, leaf)| (cost, leaf))
    }

    /// Simulates the period after `state` with increment `u`: the new state, how far it
    /// strayed, and the poses appended to `poses`.
    fn fly(
        &self,
        state: UavState,
        u: f64,
        stray_m: f64,
        poses: &mut Vec<CameraPose>,
    ) -> (UavState, f64) {
        let params = self.params;
        let yaw_ref = state.yaw + u;
        let (mut state, mut stray_m) = (state, stray_m);
        for _ in 0..params.steps_per_period {
            let pose;
            (state, pose) = fly_step(params, state, yaw_ref);
            stray_m = stray_m.max(stray(&params.region, &state.position));
            poses.push(pose);
        }
        (state, stray_m)
    }

    /// Every sequence after the prefix `path` (whose lower-bound sets are `sets`), with its
    /// bound, into `leaves`, in the order of the increments.
    fn bound(
        &mut self,
        path: &mut Vec<usize>,
        state: UavState,
        poses: &mut Vec<CameraPose>,
        stray_m: f64,
        sets: &CellSet,
        leaves: &mut Vec<Leaf>,
    ) {
        let params = self.params;
        let grid = self.grid;
        let period = path.len();
        if period == params.horizon as usize {
            leaves.push(Leaf {
                path: path.clone(),
                poses: poses.clone(),
                stray_m,
                bound: terms(params, &grid, sets, &self.hidden, 0.0).total,
            });
            return;
        }
        let mut grown = sets.dilate(&grid, growth_m(params));
        if let Some(seen) = self.others_seen.get(period) {
            grown.and_not_assign(seen);
        }
        for (i, &u) in params.increments.iter().enumerate() {
            let start = poses.len();
            let (next, stray_next) = self.fly(state, u, stray_m, poses);
            let mut footprints = CellSet::empty(&grid);
            for pose in params.viewed(&poses[start..]) {
                self.predictor.add_footprint_within(
                    &mut footprints,
                    &grid,
                    &params.camera,
                    pose,
                    &grown,
                );
            }
            let mut child = grown.clone();
            child.and_not_assign(&footprints);
            path.push(i);
            self.bound(path, next, poses, stray_next, &child, leaves);
            path.pop();
            poses.truncate(start);
        }
    }

    /// The sets `sets` at the start of `period` grown over it, less what the UAVs ahead will
    /// see in it.
    fn grow(&self, sets: &CellSet, period: usize) -> CellSet {
        let mut grown = sets.dilate(&self.grid, growth_m(self.params));
        if let Some(seen) = self.others_seen.get(period) {
            grown.and_not_assign(seen);
        }
        grown
    }

    /// The bound of `leaf` from the true sets of its prefix, if they are known: its last
    /// period's views without shadows taken from them.
    fn tighter_bound(
        &mut self,
        exact: &mut BTreeMap<Vec<usize>, Exact>,
        leaf: &Leaf,
    ) -> Option<f64> {
        let params = self.params;
        let grid = self.grid;
        let k = leaf.path.len().checked_sub(1)?;
        let parent = exact.get_mut(&leaf.path[..k])?;
        let grown = parent
            .grown
            .get_or_insert_with(|| self.grow(&parent.sets, k));
        let poses = leaf.poses.get(k * params.steps_per_period as usize..)?;
        let mut footprints = CellSet::empty(&grid);
        for pose in params.viewed(poses) {
            self.predictor.add_footprint_within(
                &mut footprints,
                &grid,
                &params.camera,
                pose,
                grown,
            );
        }
        let mut sets = grown.clone();
        sets.and_not_assign(&footprints);
        Some(terms(params, &grid, &sets, &self.hidden, 0.0).total)
    }

    /// The true predicted sets at the end of the prefix `path`, computed (with those of its
    /// own prefixes) the first time they are asked for; `None` only for a path that leaves
    /// `U`.
    fn exact_sets<'m>(
        &mut self,
        exact: &'m mut BTreeMap<Vec<usize>, Exact>,
        path: &[usize],
    ) -> Option<&'m CellSet> {
        let params = self.params;
        let grid = self.grid;
        // The longest prefix already known; the root always is.
        let known = (0..=path.len())
            .rev()
            .find(|&k| exact.contains_key(&path[..k]))
            .unwrap_or(0);
        for k in known..path.len() {
            let Some(parent) = exact.get_mut(&path[..k]) else {
                break;
            };
            let grown = parent
                .grown
                .get_or_insert_with(|| self.grow(&parent.sets, k));
            let mut poses = Vec::new();
            let Some(&u) = params.increments.get(path[k]) else {
                break;
            };
            let (state, _) = self.fly(parent.state, u, 0.0, &mut poses);
            let mut seen = CellSet::empty(&grid);
            // Only the ground of the grown sets can change them.
            for (step, pose) in params.viewed(&poses).iter().enumerate() {
                if step > 0 {
                    self.predictor.add_visible_ground_within(
                        &mut seen,
                        &grid,
                        &params.camera,
                        pose,
                        self.obstacles,
                        grown,
                    );
                    continue;
                }
                let views = &mut parent.first_views;
                let known = views.iter().position(|(p, _)| same_pose(p, pose));
                let i = known.unwrap_or_else(|| {
                    let mut view = CellSet::empty(&grid);
                    self.predictor.add_visible_ground_within(
                        &mut view,
                        &grid,
                        &params.camera,
                        pose,
                        self.obstacles,
                        grown,
                    );
                    views.push((*pose, view));
                    views.len() - 1
                });
                seen.or_assign(&views[i].1);
            }
            let mut sets = grown.clone();
            sets.and_not_assign(&seen);
            exact.insert(
                path[..=k].to_vec(),
                Exact {
                    state,
                    sets,
                    grown: None,
                    first_views: Vec::new(),
                },
            );
        }
        exact.get(path).map(|node| &node.sets)
    }
}
