//! Fusion of estimates between UAVs (docs/design.md §3, estimator step 3).
//!
//! Two estimates of the same fleet are combined as a meet of outer sets and a join of proven
//! facts: `X̄` and every `X_j` are intersected (a target one side has not identified uses that
//! side's `X̄` in its place, which also holds it), `S^o`, the explored ground, `H^CVS`, `P^g`
//! and the identified ids are unioned, the maps merged (ground wins, else the taller obstacle).
//! On estimates of the same step this is idempotent, commutative and associative, so the order
//! and repetition of messages do not matter.
//!
//! A state that fuses a peer's estimate also folds the peer's `H^CVS` and `P^g` into its `H̄`
//! ([`super::HiddenHistory::fuse`]): `H̄` is the fleet's, so ground any fused UAV saw hidden at
//! the step joins it and ground any fused UAV proved free at the step leaves it, the step's
//! hidden ground joined first and its free ground removed last, whatever the order the
//! estimates are fused in. An estimate of an earlier step (late) is applied before the state's
//! own frame of its step ([`super::Unseen`] states the rule and why).
//!
//! An estimate of another step `k'` is first dilated by `v_max |k - k'| T`: a target is within
//! that distance of where it was (or will be), so the dilated set still holds it at step `k`.
//! Late messages and restarted peers are handled that way, and an agent that hears nothing
//! simply keeps its own (guaranteed) state.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use protocol::camera::CameraPose;
use protocol::radio::Endpoint;
use protocol::scenario::SetGrowth;
use sets::grid::GroundGrid;
use sets::raster::{CellSet, ReachSet};

use super::predict;
use super::{EstimatorConfig, EstimatorState};
use crate::occupancy::OccupancyMap;

/// A set as estimates carry it: shared between a received estimate and the inbox that keeps
/// it as the base of the sender's next delta, so that neither copies it; a fusion into an
/// estimate copies a set only when it changes one still shared.
pub type SharedSet = Arc<CellSet>;

/// The exchanged sets of one estimate: what a [`PeerEstimate`] carries, what the fusion law
/// meets and joins, and what an outbox and an inbox keep as the base of set deltas
/// ([`super::message`], which adds the sender's `H̄`).
#[derive(Clone, Debug, PartialEq)]
pub struct EstimateSets {
    /// `X̄`, outer.
    pub undetected: SharedSet,
    /// `X_j`, outer, per identified id.
    pub targets: BTreeMap<u32, SharedSet>,
    /// `S^o`, inner.
    pub obstacle_neighbourhood: SharedSet,
    /// Explored ground.
    pub explored: SharedSet,
    /// `H^CVS`.
    pub hidden: SharedSet,
    /// `P^g`: ground the sender's frame of the step proved free (it clears `H̄`).
    pub free_ground: SharedSet,
}

impl EstimateSets {
    /// The exchanged sets of a state (copies: the state keeps changing).
    pub fn of_state(state: &EstimatorState) -> Self {
        let share = |set: &CellSet| Arc::new(set.clone());
        Self {
            undetected: share(state.undetected.cells()),
            targets: state
                .targets
                .iter()
                .map(|(&id, set)| (id, share(set.cells())))
                .collect(),
            obstacle_neighbourhood: share(&state.obstacle_neighbourhood),
            explored: share(&state.explored),
            hidden: share(&state.hidden),
            free_ground: share(&state.free_ground),
        }
    }

    /// Every set, targets last.
    fn iter(&self) -> impl Iterator<Item = &SharedSet> {
        [
            &self.undetected,
            &self.obstacle_neighbourhood,
            &self.explored,
            &self.hidden,
            &self.free_ground,
        ]
        .into_iter()
        .chain(self.targets.values())
    }
}

/// A peer's estimate as received and validated ([`super::message`]), or this agent's own
/// exchanged sets ([`EstimatorState::to_peer`]).
#[derive(Clone, Debug, PartialEq)]
pub struct PeerEstimate {
    /// Sender's UAV index.
    pub uav: u32,
    /// Step the sets belong to.
    pub step: u64,
    /// Simulated time of that step, s.
    pub time_s: f64,
    /// Sender's message counter.
    pub seq: u64,
    /// Sender's incarnation (changes when it restarts).
    pub incarnation: u64,
    /// Sender's camera pose at that step.
    pub pose: Option<CameraPose>,
    /// The sets of `step`.
    pub sets: EstimateSets,
    /// The sender's map cells carried by the message (all others unknown).
    pub oem: OccupancyMap,
    /// Whether `oem` is the sender's whole known map rather than a delta.
    pub oem_full: bool,
}

/// What a fusion changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FuseReport {
    /// Steps between the two estimates (the peer's sets were dilated over them).
    pub step_lag: u64,
    /// Ids this side had not identified.
    pub new_targets: Vec<u32>,
    /// Ids whose intersection came out empty (a bug signal; the union was kept).
    pub empty_intersections: Vec<u32>,
    /// Whether the peer's sets were on another grid (then nothing was fused).
    pub grid_mismatch: bool,
}

/// A set the fusion law meets and joins with a peer's raster: an estimate's [`SharedSet`] or
/// a [`ReachSet`] (an agent's own state, whose reach the meet keeps).
pub trait FusedSet: Clone {
    /// The cells of the set.
    fn cells(&self) -> &CellSet;
    /// Whether the set has no cell.
    fn is_empty(&self) -> bool;
    /// Whether the set shares a cell with `other`.
    fn intersects(&self, other: &CellSet) -> bool;
    /// `self ← self ∩ other`.
    fn meet(&mut self, other: &CellSet);
    /// `self ← self ∪ other`.
    fn join(&mut self, other: &CellSet);
}

impl FusedSet for SharedSet {
    fn cells(&self) -> &CellSet {
        self
    }
    fn is_empty(&self) -> bool {
        CellSet::is_empty(self)
    }
    fn intersects(&self, other: &CellSet) -> bool {
        CellSet::intersects(self, other)
    }
    fn meet(&mut self, other: &CellSet) {
        Arc::make_mut(self).and_assign(other);
    }
    fn join(&mut self, other: &CellSet) {
        Arc::make_mut(self).or_assign(other);
    }
}

impl FusedSet for ReachSet {
    fn cells(&self) -> &CellSet {
        ReachSet::cells(self)
    }
    fn is_empty(&self) -> bool {
        ReachSet::is_empty(self)
    }
    fn intersects(&self, other: &CellSet) -> bool {
        ReachSet::intersects(self, other)
    }
    fn meet(&mut self, other: &CellSet) {
        self.intersect(other);
    }
    fn join(&mut self, other: &CellSet) {
        ReachSet::join(self, other);
    }
}

/// Mutable views of the fused parts, so one function serves states and peer estimates.
struct Lattice<'a, S: FusedSet> {
    step: u64,
    undetected: &'a mut S,
    targets: &'a mut BTreeMap<u32, S>,
    obstacle_neighbourhood: &'a mut CellSet,
    explored: &'a mut CellSet,
    hidden: &'a mut CellSet,
    free_ground: &'a mut CellSet,
    oem: &'a mut OccupancyMap,
}

/// The fusion law: every set of `dst` meets the matching set of `src` (its `X̄` for an id it
/// has not identified), proven facts are joined. In place: a target's set is only copied when
/// `dst` learns its id, as `learn(X̄, theirs)` makes it (`X̄` or any outer raster of the
/// target that holds `X̄ ∩ theirs`).
fn fuse_into<S: FusedSet>(
    dst: Lattice<'_, S>,
    src: &PeerEstimate,
    grid: &GroundGrid,
    radius_per_step: f64,
    learn: impl Fn(&S, &CellSet) -> S,
) -> FuseReport {
    let mut report = FuseReport {
        step_lag: dst.step.abs_diff(src.step),
        ..FuseReport::default()
    };
    let sets = &src.sets;
    let shapes_ok = sets.iter().all(|s| s.same_shape(dst.undetected.cells()));
    if !shapes_ok {
        report.grid_mismatch = true;
        return report;
    }
    let radius = report.step_lag as f64 * radius_per_step;
    let src_undetected = predict::grow(&sets.undetected, grid, radius);
    let ids: BTreeSet<u32> = dst
        .targets
        .keys()
        .chain(sets.targets.keys())
        .copied()
        .collect();
    for id in ids {
        let theirs = sets
            .targets
            .get(&id)
            .map(|s| predict::grow(s, grid, radius));
        let theirs: &CellSet = theirs.as_deref().unwrap_or(&src_undetected);
        let mine = match dst.targets.entry(id) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(e) => {
                report.new_targets.push(id);
                e.insert(learn(dst.undetected, theirs))
            }
        };
        if mine.intersects(theirs) || (mine.is_empty() && theirs.is_empty()) {
            mine.meet(theirs);
        } else {
            tracing::error!(
                target_id = id,
                step = dst.step,
                peer = src.uav,
                peer_step = src.step,
                "fused target set is empty: keeping the union"
            );
            report.empty_intersections.push(id);
            mine.join(theirs);
        }
    }
    dst.undetected.meet(&src_undetected);
    dst.obstacle_neighbourhood
        .or_assign(&sets.obstacle_neighbourhood);
    dst.explored.or_assign(&sets.explored);
    dst.hidden.or_assign(&sets.hidden);
    dst.free_ground.or_assign(&sets.free_ground);
    dst.oem.merge(&src.oem);
    report
}

impl EstimatorState {
    /// Fuses a peer's estimate into this state, at this state's step.
    pub fn fuse(&mut self, peer: &PeerEstimate, config: &EstimatorConfig) -> FuseReport {
        let step = self.step;
        let report = fuse_into(
            Lattice {
                step,
                undetected: &mut self.undetected,
                targets: &mut self.targets,
                obstacle_neighbourhood: &mut self.obstacle_neighbourhood,
                explored: &mut self.explored,
                hidden: &mut self.hidden,
                free_ground: &mut self.free_ground,
                oem: &mut self.oem,
            },
            peer,
            &config.grid,
            predict::motion_radius(1, config.period_s, config.max_speed_mps),
            |undetected: &ReachSet, theirs: &CellSet| learned_set(undetected, theirs, config),
        );
        if !report.grid_mismatch {
            self.hidden_history
                .fuse(step, peer.step, &peer.sets.hidden, &peer.sets.free_ground);
        }
        // A target learned from a peer starts from this side's X̄, whose reach knows nothing
        // near the target: its set must be bounded by its box (whole-cell growth keeps none).
        // The copy of X̄ it starts from is bounded already ([`learned_set`]); only the union
        // kept when the two sets did not meet is bounded here.
        let new_targets = match config.sets {
            SetGrowth::Cells => &[][..],
            SetGrowth::Reach | SetGrowth::Geodesic => &report.new_targets[..],
        };
        let unions = new_targets
            .iter()
            .filter(|id| report.empty_intersections.contains(id));
        for id in unions {
            if let Some(set) = self.targets.get_mut(id) {
                set.bound_by_box(&config.grid);
            }
        }
        report
    }

    /// The exchanged part of this state as an estimate (the whole map, marked full).
    pub fn to_peer(&self, uav: u32) -> PeerEstimate {
        PeerEstimate {
            uav,
            step: self.step,
            time_s: self.time_s,
            seq: 0,
            incarnation: 0,
            pose: self.pose,
            sets: EstimateSets::of_state(self),
            oem: self.oem.clone(),
            oem_full: true,
        }
    }
}

impl PeerEstimate {
    /// Its sender, its step and the sender's pose then: the estimate's end of its link, which
    /// the radio judges ([`protocol::radio::Radio::fuses`]).
    pub fn endpoint(&self) -> Endpoint {
        Endpoint {
            uav: self.uav,
            step: self.step,
            pose: self.pose,
        }
    }

    /// Fuses another estimate into this one, at this one's step (the same law as
    /// [`EstimatorState::fuse`]).
    pub fn fuse(&mut self, other: &PeerEstimate, config: &EstimatorConfig) -> FuseReport {
        let sets = &mut self.sets;
        fuse_into(
            Lattice {
                step: self.step,
                undetected: &mut sets.undetected,
                targets: &mut sets.targets,
                obstacle_neighbourhood: Arc::make_mut(&mut sets.obstacle_neighbourhood),
                explored: Arc::make_mut(&mut sets.explored),
                hidden: Arc::make_mut(&mut sets.hidden),
                free_ground: Arc::make_mut(&mut sets.free_ground),
                oem: &mut self.oem,
            },
            other,
            &config.grid,
            predict::motion_radius(1, config.period_s, config.max_speed_mps),
            |undetected: &SharedSet, _: &CellSet| undetected.clone(),
        )
    }
}

/// A target's set as a state first learns it from a peer's set of it (`theirs`, grown to the
/// state's step): a copy of `X̄` that keeps its reach, stored over the rows near `theirs`
/// ([`ReachSet::restricted_copy`]) when the two meet, else the whole of `X̄` (fusion then
/// keeps the union). Whole-cell sets keep no reach: `X̄` whole.
fn learned_set(undetected: &ReachSet, theirs: &CellSet, config: &EstimatorConfig) -> ReachSet {
    let margin = super::target_reach_margin(&config.grid);
    match config.sets {
        SetGrowth::Reach | SetGrowth::Geodesic if undetected.intersects(theirs) => {
            undetected.restricted_copy(&config.grid, theirs, margin)
        }
        SetGrowth::Reach | SetGrowth::Geodesic => undetected.clone().with_margin(margin),
        SetGrowth::Cells => undetected.clone(),
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use proptest::prelude::*;
    use proptest::strategy::ValueTree;
    use sets::grid::CellIndex;
    use sets::math::Point2;

    use super::*;
    use crate::occupancy::OemCell;

    pub(crate) fn config() -> EstimatorConfig {
        let mut scenario = protocol::scenario::Scenario::default();
        scenario.region.half_extent_m = 8.0;
        scenario.estimator.cell_m = 0.5;
        scenario.estimator.oem_cell_m = 4.0;
        EstimatorConfig::from_scenario(&scenario)
    }

    fn set_strategy(grid: GroundGrid, density: f64) -> impl Strategy<Value = CellSet> {
        proptest::collection::vec(proptest::bool::weighted(density), grid.cell_count()).prop_map(
            move |bits| {
                let mut s = CellSet::empty(&grid);
                for (i, b) in bits.into_iter().enumerate() {
                    s.set(((i as u32) % grid.nx, (i as u32) / grid.nx), b);
                }
                s
            },
        )
    }

    pub(crate) fn peer_strategy(step: u64) -> impl Strategy<Value = PeerEstimate> {
        let cfg = config();
        let g = cfg.grid;
        let og = cfg.oem_grid;
        (
            set_strategy(g, 0.8),
            proptest::collection::btree_map(0u32..6, set_strategy(g, 0.7), 0..3),
            set_strategy(g, 0.2),
            set_strategy(g, 0.3),
            set_strategy(g, 0.3),
            set_strategy(g, 0.3),
            proptest::collection::vec((0u32..og.nx, 0u32..og.ny, 0u8..3, 0.0f32..60.0), 0..10),
            any::<u32>(),
        )
            .prop_map(
                move |(undetected, targets, so, explored, hidden, free_ground, cells, uav)| {
                    let mut oem = OccupancyMap::new(og);
                    for (ix, iy, s, h) in cells {
                        let status = crate::occupancy::OemStatus::from_code(s).unwrap_or_default();
                        let height_m = if s == 1 { h } else { 0.0 };
                        oem.merge_cell((ix, iy), OemCell { status, height_m });
                    }
                    PeerEstimate {
                        uav,
                        step,
                        time_s: step as f64 * 0.5,
                        seq: 0,
                        incarnation: 0,
                        pose: None,
                        sets: EstimateSets {
                            undetected: undetected.into(),
                            targets: targets.into_iter().map(|(id, s)| (id, s.into())).collect(),
                            obstacle_neighbourhood: so.into(),
                            explored: explored.into(),
                            hidden: hidden.into(),
                            free_ground: free_ground.into(),
                        },
                        oem,
                        oem_full: false,
                    }
                },
            )
    }

    /// The fused content, without sender bookkeeping or the map's pending changes.
    type Content = (EstimateSets, Vec<((u32, u32), OemCell)>);

    fn content(p: &PeerEstimate) -> Content {
        (p.sets.clone(), p.oem.known_cells().collect::<Vec<_>>())
    }

    fn fused(a: &PeerEstimate, b: &PeerEstimate) -> PeerEstimate {
        let mut out = a.clone();
        out.fuse(b, &config());
        out
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        #[test]
        fn fusion_is_idempotent(a in peer_strategy(3)) {
            prop_assert_eq!(content(&fused(&a, &a)), content(&a));
        }

        #[test]
        fn fusion_is_commutative(a in peer_strategy(3), b in peer_strategy(3)) {
            prop_assert_eq!(content(&fused(&a, &b)), content(&fused(&b, &a)));
        }

        #[test]
        fn fusion_is_associative(
            a in peer_strategy(3), b in peer_strategy(3), c in peer_strategy(3)
        ) {
            let left = fused(&fused(&a, &b), &c);
            let right = fused(&a, &fused(&b, &c));
            prop_assert_eq!(content(&left), content(&right));
        }

        #[test]
        fn fusion_keeps_what_both_sides_contain(a in peer_strategy(3), b in peer_strategy(3)) {
            // A point both sides hold (for each target, in X_j or, if unidentified, X̄) stays
            // held: the meet loses nothing the two estimates agree on.
            let f = fused(&a, &b);
            let g = config().grid;
            for iy in 0..g.ny {
                for ix in 0..g.nx {
                    let c = (ix, iy);
                    if a.sets.undetected.contains(c) && b.sets.undetected.contains(c) {
                        prop_assert!(f.sets.undetected.contains(c));
                    }
                    for (id, x) in &f.sets.targets {
                        let ina = a.sets.targets.get(id).unwrap_or(&a.sets.undetected).contains(c);
                        let inb = b.sets.targets.get(id).unwrap_or(&b.sets.undetected).contains(c);
                        if ina && inb {
                            prop_assert!(x.contains(c));
                        }
                    }
                }
            }
        }

        #[test]
        fn an_older_estimate_is_widened_before_the_meet(
            a in peer_strategy(10), b in peer_strategy(8)
        ) {
            // A target b held at step 8 moved at most 2 steps of v_max T = 2 m by step 10.
            let f = fused(&a, &b);
            let g = config().grid;
            for (ix, iy) in b.sets.undetected.iter() {
                let p = g.cell_centre((ix, iy));
                let moved = Point2::new(p.x + 1.9, p.y);
                if let Some(c) = g.cell_of(&moved)
                    && a.sets.undetected.contains(c)
                {
                    prop_assert!(f.sets.undetected.contains(c));
                }
            }
        }
    }

    #[test]
    fn fusing_a_state_matches_fusing_its_estimate() {
        let cfg = config();
        let mut runner = proptest::test_runner::TestRunner::deterministic();
        let a = peer_strategy(0)
            .new_tree(&mut runner)
            .expect("tree")
            .current();
        let b = peer_strategy(0)
            .new_tree(&mut runner)
            .expect("tree")
            .current();
        let mut state = EstimatorState::new(&cfg);
        state.undetected = ReachSet::with_cells((*a.sets.undetected).clone());
        state.targets = a
            .sets
            .targets
            .iter()
            .map(|(k, v)| (*k, ReachSet::with_cells((**v).clone())))
            .collect();
        state.obstacle_neighbourhood = (*a.sets.obstacle_neighbourhood).clone();
        state.explored = (*a.sets.explored).clone();
        state.hidden = (*a.sets.hidden).clone();
        state.free_ground = (*a.sets.free_ground).clone();
        state.oem = a.oem.clone();
        state.fuse(&b, &cfg);
        assert_eq!(content(&state.to_peer(0)), content(&fused(&a, &b)));
        assert!(state.hidden_history.recently_hidden().count() >= b.sets.hidden.count());
    }

    #[test]
    fn sets_of_another_grid_are_not_fused() {
        let cfg = config();
        let mut state = EstimatorState::new(&cfg);
        let mut other = state.to_peer(1);
        other.sets.undetected = CellSet::empty(&GroundGrid::new(4.0, 0.5)).into();
        let r = state.fuse(&other, &cfg);
        assert!(r.grid_mismatch);
        assert_eq!(state.undetected.cells(), &CellSet::full(&cfg.grid));
    }

    fn cells(cells: &[CellIndex]) -> CellSet {
        CellSet::from_cells(&config().grid, cells.iter().copied())
    }

    /// A fresh state whose own frames hid and proved free these cells, a frame a step: the last
    /// one of step `frames.last().0`.
    fn state_after(frames: &[(u64, &[CellIndex], &[CellIndex])]) -> EstimatorState {
        let mut state = EstimatorState::new(&config());
        for &(step, hidden, free) in frames {
            state.step = step;
            state
                .hidden_history
                .record(step, &cells(hidden), &cells(free));
        }
        state
    }

    /// UAV `uav`'s estimate of `step`, knowing nothing but that its frame hid `hidden` and
    /// proved `free` free.
    fn news(uav: u32, step: u64, hidden: &[CellIndex], free: &[CellIndex]) -> PeerEstimate {
        let mut p = EstimatorState::new(&config()).to_peer(uav);
        p.step = step;
        p.sets.hidden = cells(hidden).into();
        p.sets.free_ground = cells(free).into();
        p
    }

    #[test]
    fn ground_hidden_from_one_uav_and_proven_free_by_another_in_the_step_is_not_unseen() {
        let cfg = config();
        let (k, c) = (4, (3, 3));
        // C fuses A's and B's step-k estimates: A's frame hid c, B's proved it free.
        let a = news(0, k, &[c], &[]);
        let b = news(1, k, &[], &[c]);
        for order in [[&a, &b], [&b, &a]] {
            let mut state = state_after(&[(k, &[], &[])]);
            for p in order {
                state.fuse(p, &cfg);
            }
            assert!(
                !state.hidden_history.unseen().contains(c),
                "order {order:?}"
            );
        }
        // Without B's estimate c is unseen, and stays so while no fused frame proves it free.
        let mut state = state_after(&[(k, &[], &[])]);
        state.fuse(&a, &cfg);
        assert!(state.hidden_history.unseen().contains(c));
        state.step = k + 1;
        state.hidden_history.record(k + 1, &cells(&[]), &cells(&[]));
        assert!(state.hidden_history.unseen().contains(c));
        state.fuse(&news(1, k + 1, &[], &[c]), &cfg);
        assert!(!state.hidden_history.unseen().contains(c));
        // C's own frame plays either part the same way.
        let mut saw_free = state_after(&[(k, &[], &[c])]);
        saw_free.fuse(&a, &cfg);
        assert!(!saw_free.hidden_history.unseen().contains(c));
        let mut saw_hidden = state_after(&[(k, &[c], &[])]);
        assert!(saw_hidden.hidden_history.unseen().contains(c));
        saw_hidden.fuse(&b, &cfg);
        assert!(!saw_hidden.hidden_history.unseen().contains(c));
    }

    #[test]
    fn a_late_estimate_is_older_news_than_the_agents_own_frame() {
        let cfg = config();
        let k = 6;
        // Before step k, C's H̄ holds e. At step k its frame hid c and proved d free.
        let (c, d, e, f) = ((1, 1), (2, 2), (3, 3), (4, 4));
        let frames: &[(u64, &[CellIndex], &[CellIndex])] = &[(k - 1, &[e], &[]), (k, &[c], &[d])];
        // A late estimate of step k - 2 proved c and e free and hid d and f; a step-k one
        // proved f free.
        let late = news(0, k - 2, &[d, f], &[c, e]);
        let now = news(1, k, &[], &[f]);
        let mut alone = state_after(frames);
        alone.fuse(&late, &cfg);
        // What C's frame of step k saw stands; the older H̄ is updated by the late news.
        assert_eq!(alone.hidden_history.unseen(), &cells(&[c, f]));
        for order in [[&late, &now], [&now, &late]] {
            let mut state = state_after(frames);
            for p in order {
                state.fuse(p, &cfg);
            }
            assert_eq!(state.hidden_history.unseen(), &cells(&[c]), "{order:?}");
        }
    }
}
