//! What the guidance needs to know about hidden ground over time.
//!
//! Two views of `H^CVS` (ground hidden by obstacles, targets or doubt in a frame) are kept:
//! - the union over the last `h` guidance periods (the paper's eq. 28), as one set per guidance
//!   period in a short ring keyed by period index, so that memory is `h + 1` sets whatever the
//!   number of frames per period;
//! - `H̄`, ground hidden at some earlier frame and not proven free since (what the paper draws in
//!   blue and the `OA` metric measures).

use std::collections::BTreeMap;

use protocol::grid::GroundGrid;
use protocol::raster::CellSet;
use serde::{Deserialize, Serialize};

use super::snapshot::{cell_set, cell_set_map};

/// Hidden ground over recent guidance periods, and hidden ground not seen since.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HiddenHistory {
    period_steps: u64,
    periods: u32,
    #[serde(with = "cell_set_map")]
    slots: BTreeMap<u64, CellSet>,
    #[serde(with = "cell_set")]
    unseen: CellSet,
}

impl HiddenHistory {
    /// An empty history remembering `periods` guidance periods of `period_steps` frames each.
    pub fn new(grid: &GroundGrid, period_steps: u64, periods: u32) -> Self {
        Self {
            period_steps: period_steps.max(1),
            periods: periods.max(1),
            slots: BTreeMap::new(),
            unseen: CellSet::empty(grid),
        }
    }

    /// Records the hidden ground of the frame at `step` and the ground it proved free.
    pub fn record(&mut self, step: u64, hidden: &CellSet, proven_free: &CellSet) {
        self.add_hidden(step, hidden);
        self.unseen.and_not_assign(proven_free);
    }

    /// Adds hidden ground reported at `step` (by this agent or a peer), without any ground
    /// proven free.
    pub fn add_hidden(&mut self, step: u64, hidden: &CellSet) {
        if !hidden.same_shape(&self.unseen) {
            return;
        }
        let period = step / self.period_steps;
        let oldest_kept = (period + 1).saturating_sub(self.periods as u64);
        if period < oldest_kept {
            return;
        }
        self.slots
            .entry(period)
            .and_modify(|s| s.or_assign(hidden))
            .or_insert_with(|| hidden.clone());
        self.slots.retain(|&p, _| p >= oldest_kept);
        self.unseen.or_assign(hidden);
    }

    /// Ground hidden at some frame of the last `periods` guidance periods (the current one
    /// included): the union `H^CVS_{k-h+1:k}` the guidance favours.
    pub fn recently_hidden(&self) -> CellSet {
        // An empty set of the same shape, then the union of the kept periods.
        let mut out = self.unseen.clone();
        out.and_not_assign(&self.unseen);
        for s in self.slots.values() {
            out.or_assign(s);
        }
        out
    }

    /// Ground hidden at some earlier frame and not proven free since (`H̄`).
    pub fn unseen(&self) -> &CellSet {
        &self.unseen
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
