//! The fault plan of a run: which faults are due at a simulated time, and what was applied
//! when (`summary.json` `faults`).

use serde::Serialize;

use super::config::{Fault, FaultKind};

/// One fault as injected.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FaultRecord {
    /// `kill` or `restart`.
    pub kind: FaultKind,
    /// The UAV.
    pub uav: u32,
    /// The time asked for, seconds.
    pub at_s: f64,
    /// The step at which it was applied (`null` if the run ended first).
    pub applied_at_step: Option<u64>,
    /// The simulated time of that step, seconds.
    pub applied_at_s: Option<f64>,
    /// Whether it took effect (a kill found a running agent, a restart started one).
    pub effective: bool,
}

/// The faults of a run, in the order they apply.
#[derive(Clone, Debug, Default)]
pub struct FaultPlan {
    records: Vec<FaultRecord>,
    next: usize,
}

impl FaultPlan {
    /// The plan of `faults`, already in application order.
    pub fn new(faults: &[Fault]) -> FaultPlan {
        FaultPlan {
            records: faults
                .iter()
                .map(|f| FaultRecord {
                    kind: f.kind,
                    uav: f.uav,
                    at_s: f.at_s,
                    applied_at_step: None,
                    applied_at_s: None,
                    effective: false,
                })
                .collect(),
            next: 0,
        }
    }

    /// The times at which faults are due, ascending.
    pub fn times(&self) -> Vec<f64> {
        self.records.iter().map(|r| r.at_s).collect()
    }

    /// The faults due by `time_s` not handed out yet, as (index, kind, uav).
    pub fn due(&mut self, time_s: f64) -> Vec<(usize, FaultKind, u32)> {
        let mut out = Vec::new();
        // The same slack as the observer's, so both agree on the step a fault is due.
        while self.next < self.records.len() && self.records[self.next].at_s <= time_s + 1e-9 {
            let r = &self.records[self.next];
            out.push((self.next, r.kind, r.uav));
            self.next += 1;
        }
        out
    }

    /// Notes that fault `index` was applied at `step` (`time_s`).
    pub fn applied(&mut self, index: usize, step: u64, time_s: f64, effective: bool) {
        if let Some(r) = self.records.get_mut(index) {
            r.applied_at_step = Some(step);
            r.applied_at_s = Some(time_s);
            r.effective = effective;
        }
    }

    /// Effective restarts of `uav`.
    pub fn restarts(&self, uav: u32) -> u64 {
        self.records
            .iter()
            .filter(|r| r.uav == uav && r.kind == FaultKind::Restart && r.effective)
            .count() as u64
    }

    /// Every fault with what happened to it.
    pub fn records(&self) -> &[FaultRecord] {
        &self.records
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_come_due_once_in_order() {
        let faults: Vec<Fault> = ["kill:1@1", "restart:1@2.5"]
            .iter()
            .map(|t| t.parse().unwrap())
            .collect();
        let mut plan = FaultPlan::new(&faults);
        assert_eq!(plan.times(), vec![1.0, 2.5]);
        assert!(plan.due(0.5).is_empty());
        assert_eq!(plan.due(1.0), vec![(0, FaultKind::Kill, 1)]);
        assert!(plan.due(2.0).is_empty());
        plan.applied(0, 2, 1.0, true);
        assert_eq!(plan.due(9.0), vec![(1, FaultKind::Restart, 1)]);
        plan.applied(1, 5, 2.5, true);
        assert_eq!(plan.restarts(1), 1);
        assert_eq!(plan.restarts(0), 0);
        assert_eq!(plan.records()[0].applied_at_step, Some(2));
    }
}
