//! What the guidance needs to know about hidden ground over time.
//!
//! Two views of `H^CVS` (ground hidden by obstacles, targets or doubt in a frame) are kept:
//! - the union over the last `h` slots (the paper's eq. 28), as one set per slot in a short
//!   ring keyed by slot index, so that memory is `h + 1` sets whatever the number of frames per
//!   slot. A slot is one frame when the window counts frames (`guidance.hidden_window =
//!   "frames"`, the paper's time index `k` read as the CVS step) or one guidance period
//!   (`"periods"`);
//! - `H̄`, ground hidden at some earlier frame and not proven free since (what the paper draws in
//!   blue and the `OA` metric measures): [`Unseen`].
//!
//! **`H̄` is the fleet's**, as the paper's is: ground hidden from any UAV (`H^CVS`) and proven
//! free (`P^g`) by no UAV since, as far as the agent knows, i.e. of the UAVs whose estimates it
//! fuses. At a step the step's hidden ground of its frame and of the fused estimates is joined
//! first and the ground any of them proved free removed last, so the order the estimates come
//! in does not matter; late estimates are older news than the agent's own frame. [`Unseen`]
//! states the rule in full, with why late estimates are taken that way.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use sets::grid::GroundGrid;
use sets::raster::CellSet;

use super::snapshot::{cell_set, cell_set_map};

/// Hidden ground over the recent slots, and hidden ground not seen since.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HiddenHistory {
    slot_steps: u64,
    /// Slots kept, the current one included.
    kept: u32,
    #[serde(with = "cell_set_map")]
    slots: BTreeMap<u64, CellSet>,
    unseen: Unseen,
}

impl HiddenHistory {
    /// An empty history remembering `slots` slots of `slot_steps` frames each.
    pub fn new(grid: &GroundGrid, slot_steps: u64, slots: u32) -> Self {
        Self {
            slot_steps: slot_steps.max(1),
            kept: slots.max(1),
            slots: BTreeMap::new(),
            unseen: Unseen::new(grid),
        }
    }

    /// Records the hidden ground of this agent's frame at `step` and the ground it proved free
    /// (`P^g`): the frame starts step `step` of `H̄` ([`Unseen::record_frame`]).
    pub fn record(&mut self, step: u64, hidden: &CellSet, proven_free: &CellSet) {
        self.add_hidden(step, hidden);
        self.unseen.record_frame(step, hidden, proven_free);
    }

    /// Records a peer's estimate of `peer_step`, fused at this agent's `step`: its hidden ground
    /// joins the recent slots (at `step`) and its hidden and proven-free ground (`H^CVS`, `P^g`)
    /// go into `H̄` by the fleet's rule ([`Unseen::fuse`]).
    pub fn fuse(&mut self, step: u64, peer_step: u64, hidden: &CellSet, proven_free: &CellSet) {
        self.add_hidden(step, hidden);
        self.unseen.fuse(peer_step, hidden, proven_free);
    }

    /// Adds hidden ground reported at `step` (by this agent or a peer) to the recent slots.
    fn add_hidden(&mut self, step: u64, hidden: &CellSet) {
        if !hidden.same_shape(self.unseen.cells()) {
            return;
        }
        let slot = step / self.slot_steps;
        let oldest_kept = (slot + 1).saturating_sub(self.kept as u64);
        if slot < oldest_kept {
            return;
        }
        self.slots
            .entry(slot)
            .and_modify(|s| s.or_assign(hidden))
            .or_insert_with(|| hidden.clone());
        self.slots.retain(|&p, _| p >= oldest_kept);
    }

    /// Ground hidden at some frame of the last slots kept (the current one included): the union `H^CVS_{k-h+1:k}` the guidance favours.
    pub fn recently_hidden(&self) -> CellSet {
        // An empty set of the same shape, then the union of the kept slots.
        let mut out = empty_like(self.unseen.cells());
        for s in self.slots.values() {
            out.or_assign(s);
        }
        out
    }

    /// Ground hidden at some earlier frame and not proven free since (`H̄`), by the fleet as
    /// this agent knows it.
    pub fn unseen(&self) -> &CellSet {
        self.unseen.cells()
    }

    /// Whether every set lives on the grid of `probe`.
    pub(crate) fn fits(&self, probe: &CellSet) -> bool {
        self.slots.values().all(|s| s.same_shape(probe)) && self.unseen.fits(probe)
    }
}

/// `H̄` as one agent knows it, through the step of its last frame, kept as the step's news so
/// that estimates fused in any order give one result.
///
/// **`H̄` is the fleet's.** The paper's `H̄` is ground hidden from the fleet and not seen by
/// the fleet since: a cell joins it when any UAV's frame hides it and leaves it when any UAV's
/// frame proves it free (its ground pixels, `P^g`). Agent `i` knows of the UAVs whose
/// estimates it fuses, so at its step `k`, with `F` the peers whose step-`k` estimates it fuses,
///
/// ```text
/// H̄_k = (H̄_{k-1} ∪ H^CVS_{i,k} ∪ ⋃_{ℓ∈F} H^CVS_{ℓ,k}) \ (P^g_{i,k} ∪ ⋃_{ℓ∈F} P^g_{ℓ,k})
/// ```
///
/// The step's hidden ground is joined first and everything proven free at the step removed
/// last, so the result does not depend on the order the estimates come in (a cell one UAV sees
/// hidden and another sees free in the same step was seen). `P^g` is the proven-free set the
/// agent's own frame clears with ([`HiddenHistory::record`]), not `P^g ∪ S^o`: `S^o` says
/// where targets cannot be, not what a camera saw. Hidden ground is only ever added by a frame
/// (the agent's or a peer's); ground that was never hidden is not in `H̄`.
///
/// **Late estimates.** An estimate of an earlier step `k' < k` (a latency of `d` steps fuses
/// step `k - d`'s estimates at step `k`; one that missed its step's wait is fused at a later
/// one) is older news than the agent's own frame of step `k`, so it is applied before it:
/// with `L` the late estimates fused at step `k`,
///
/// ```text
/// H̄_k = (((H̄_{k-1} ∪ ⋃_{ℓ∈L} H^CVS_ℓ) \ ⋃_{ℓ∈L} P^g_ℓ) ∪ H^CVS_{i,k} ∪ ⋃_{ℓ∈F} H^CVS_{ℓ,k})
///          \ (P^g_{i,k} ∪ ⋃_{ℓ∈F} P^g_{ℓ,k})
/// ```
///
/// still independent of the order within the step. A late estimate thus never undoes what the
/// agent's frame of step `k` saw (free stays free, hidden stays hidden), but the frames the
/// agent folded between `k'` and `k` are not replayed: a cell the late estimate saw hidden and
/// the agent saw free in between comes back into `H̄` until a frame proves it free again, and
/// one it saw free that was hidden in between leaves it. Only cells whose status changed within
/// the lag are concerned. `H̄` feeds the `OA` metric and the pictures (the guidance reads the
/// recent `H^CVS`, not `H̄`), never the guaranteed sets, so nothing is at stake but the
/// metric's precision; what counts is that the rule is deterministic, so that the observer
/// rebuilds each agent's `H̄` bit for bit ([`Unseen::after_frame`]).
///
/// The agent goes through [`Unseen::record_frame`] at each frame (which starts the step from
/// [`Unseen::after_frame`]) and [`Unseen::fuse`] for each estimate it fuses; the observer
/// rebuilds the agent's `H̄` from its estimate by the same two calls.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Unseen {
    /// Step of the agent's last frame: the step whose news is gathered.
    step: u64,
    /// `H̄` after the agent's frame of `step`, joined with the `H^CVS` of the late estimates
    /// (of earlier steps) fused at `step`.
    #[serde(with = "cell_set")]
    earlier: CellSet,
    /// `P^g` of the late estimates fused at `step`.
    #[serde(with = "cell_set")]
    late_free: CellSet,
    /// `H^CVS` of step `step`: the agent's frame's and the fused step-`step` estimates'.
    #[serde(with = "cell_set")]
    hidden: CellSet,
    /// `P^g` of step `step`, likewise.
    #[serde(with = "cell_set")]
    free: CellSet,
    /// `H̄ = ((earlier \ late_free) ∪ hidden) \ free`.
    #[serde(with = "cell_set")]
    unseen: CellSet,
}

impl Unseen {
    /// Nothing hidden yet, at step 0.
    pub fn new(grid: &GroundGrid) -> Self {
        let empty = CellSet::empty(grid);
        Self {
            step: 0,
            earlier: empty.clone(),
            late_free: empty.clone(),
            hidden: empty.clone(),
            free: empty.clone(),
            unseen: empty,
        }
    }

    /// What an agent holds once its frame of `step` is folded in, before it fuses any
    /// estimate: `published` is its `H̄` then (what its estimate of `step` carries), `hidden`
    /// and `free` the frame's `H^CVS` and `P^g` (which its estimate carries too). The sets
    /// must share one grid (`published`'s); others are ignored.
    pub fn after_frame(step: u64, published: CellSet, hidden: &CellSet, free: &CellSet) -> Self {
        let empty = empty_like(&published);
        let or_empty = |s: &CellSet| {
            if s.same_shape(&published) {
                s.clone()
            } else {
                empty.clone()
            }
        };
        let mut out = Self {
            step,
            hidden: or_empty(hidden),
            free: or_empty(free),
            late_free: empty.clone(),
            unseen: empty,
            earlier: published,
        };
        out.settle();
        out
    }

    /// Folds the agent's own frame of `step` in: `H̄` as the last step left it, joined with the
    /// frame's hidden ground, less the ground it proved free, starts step `step`.
    pub fn record_frame(&mut self, step: u64, hidden: &CellSet, free: &CellSet) {
        let mut published = self.unseen.clone();
        if hidden.same_shape(&published) && free.same_shape(&published) {
            published.or_assign(hidden);
            published.and_not_assign(free);
        }
        *self = Self::after_frame(step, published, hidden, free);
    }

    /// Folds in the hidden and proven-free ground (`H^CVS`, `P^g`) of an estimate of `step`
    /// that the agent fuses: with the step's news when `step` is the agent's (or later), else
    /// as a late estimate, before the agent's own frame (module docs). Sets of another grid
    /// are ignored.
    pub fn fuse(&mut self, step: u64, hidden: &CellSet, free: &CellSet) {
        if !(self.fits(hidden) && self.fits(free)) {
            return;
        }
        if step < self.step {
            self.earlier.or_assign(hidden);
            self.late_free.or_assign(free);
        } else {
            self.hidden.or_assign(hidden);
            self.free.or_assign(free);
        }
        self.settle();
    }

    /// `H̄`.
    pub fn cells(&self) -> &CellSet {
        &self.unseen
    }

    /// `H̄`, by value.
    pub fn into_cells(self) -> CellSet {
        self.unseen
    }

    /// Whether every set lives on the grid of `probe`.
    fn fits(&self, probe: &CellSet) -> bool {
        [
            &self.earlier,
            &self.late_free,
            &self.hidden,
            &self.free,
            &self.unseen,
        ]
        .into_iter()
        .all(|s| s.same_shape(probe))
    }

    /// Recomputes `H̄` from the step's news.
    fn settle(&mut self) {
        self.unseen.clone_from(&self.earlier);
        self.unseen.and_not_assign(&self.late_free);
        self.unseen.or_assign(&self.hidden);
        self.unseen.and_not_assign(&self.free);
    }
}

/// An empty set on the grid of `set`.
fn empty_like(set: &CellSet) -> CellSet {
    let mut empty = set.clone();
    empty.and_not_assign(set);
    empty
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    fn grid() -> GroundGrid {
        GroundGrid::new(4.0, 1.0)
    }

    fn set_strategy() -> impl Strategy<Value = CellSet> {
        let g = grid();
        proptest::collection::vec(proptest::bool::weighted(0.3), g.cell_count()).prop_map(
            move |bits| {
                let cells = bits.into_iter().enumerate().filter(|(_, b)| *b);
                CellSet::from_cells(
                    &g,
                    cells.map(|(i, _)| ((i as u32) % g.nx, (i as u32) / g.nx)),
                )
            },
        )
    }

    /// `(steps late, H^CVS, P^g)` of an estimate.
    type News = (u64, CellSet, CellSet);

    fn news_strategy() -> impl Strategy<Value = Vec<News>> {
        proptest::collection::vec((0u64..3, set_strategy(), set_strategy()), 0..5)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        #[test]
        fn unseen_is_the_fleet_rule_whatever_the_order_of_the_estimates(
            before in set_strategy(),
            own_hidden in set_strategy(),
            own_free in set_strategy(),
            news in news_strategy(),
            rotation in 0usize..5,
        ) {
            let k = 10;
            let none = CellSet::empty(&grid());
            let mut h = HiddenHistory::new(&grid(), 1, 2);
            h.record(k - 1, &before, &none);
            h.record(k, &own_hidden, &own_free);
            let published = h.unseen().clone();
            let mut orders = vec![news.clone(), news.iter().rev().cloned().collect()];
            let mut rotated = news.clone();
            rotated.rotate_left(rotation.min(news.len()));
            orders.push(rotated);
            // The closed form of the module docs, from `H̄` before the step.
            let (mut late_hidden, mut late_free) = (none.clone(), none.clone());
            let (mut hidden, mut free) = (own_hidden.clone(), own_free.clone());
            for (lag, nh, nf) in &news {
                let (h, f) = if *lag > 0 {
                    (&mut late_hidden, &mut late_free)
                } else {
                    (&mut hidden, &mut free)
                };
                h.or_assign(nh);
                f.or_assign(nf);
            }
            let mut expected = before.clone();
            expected.or_assign(&late_hidden);
            expected.and_not_assign(&late_free);
            expected.or_assign(&hidden);
            expected.and_not_assign(&free);
            for order in orders {
                let mut agent = h.clone();
                // The observer's rebuild, from what the agent's estimate carries.
                let mut observer =
                    Unseen::after_frame(k, published.clone(), &own_hidden, &own_free);
                for (lag, nh, nf) in &order {
                    agent.fuse(k, k - lag, nh, nf);
                    observer.fuse(k - lag, nh, nf);
                }
                prop_assert_eq!(agent.unseen(), &expected);
                prop_assert_eq!(observer.cells(), &expected);
            }
        }
    }

    #[test]
    fn old_periods_are_forgotten_but_unseen_stays_until_seen() {
        let grid = GroundGrid::new(10.0, 1.0);
        let mut h = HiddenHistory::new(&grid, 6, 2);
        let mut a = CellSet::empty(&grid);
        a.set((1, 1), true);
        let mut b = CellSet::empty(&grid);
        b.set((2, 2), true);
        let none = CellSet::empty(&grid);
        h.record(0, &a, &none);
        h.record(7, &b, &none);
        assert_eq!(h.recently_hidden().count(), 2);
        h.record(12, &none, &b);
        // Period 2 keeps periods 1 and 2 only: a (period 0) is gone, b stays.
        let recent = h.recently_hidden();
        assert!(!recent.contains((1, 1)) && recent.contains((2, 2)));
        // b was proven free, a never was.
        assert!(h.unseen().contains((1, 1)) && !h.unseen().contains((2, 2)));
    }
}
