//! The fault plan of a run: which faults are due at a simulated time, what was applied when,
//! the pauses waiting for their SIGCONT, and how soon each restarted or resumed agent was
//! back (`summary.json` `faults`).
//!
//! **Resync** measures how soon an agent is back: the steps from the step a restart was
//! applied at (for a pause, the last step the observer had acknowledged when SIGCONT was
//! sent) to the first later step whose estimate from that agent the observer measured
//! ([`StepMetrics::estimated_by`]). 1 is the best there is: the agent's estimate of the very
//! next step arrived in time.

use tokio::time::Instant;

use fleet_observe::faults::{Fault, FaultKind, FaultRecord};
use fleet_observe::observe::StepMetrics;

/// The faults of a run, in the order they apply.
#[derive(Clone, Debug, Default)]
pub struct FaultPlan {
    records: Vec<FaultRecord>,
    next: usize,
}

/// A fault handed out to be applied.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DueFault {
    /// Its index in the plan.
    pub index: usize,
    /// What to do.
    pub kind: FaultKind,
    /// The UAV.
    pub uav: u32,
    /// A pause's duration, seconds of wall time.
    pub pause_s: Option<f64>,
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
                    pause_s: f.pause_s,
                    origin: f.origin,
                    applied_at_step: None,
                    applied_at_s: None,
                    effective: false,
                    resumed_at_step: None,
                    resync_steps: None,
                })
                .collect(),
            next: 0,
        }
    }

    /// The times at which faults are due, ascending.
    pub fn times(&self) -> Vec<f64> {
        self.records.iter().map(|r| r.at_s).collect()
    }

    /// The faults due by `time_s` not handed out yet.
    pub fn due(&mut self, time_s: f64) -> Vec<DueFault> {
        let mut out = Vec::new();
        // The same slack as the observer's, so both agree on the step a fault is due.
        while self.next < self.records.len() && self.records[self.next].at_s <= time_s + 1e-9 {
            let r = &self.records[self.next];
            out.push(DueFault {
                index: self.next,
                kind: r.kind,
                uav: r.uav,
                pause_s: r.pause_s,
            });
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

    /// Notes that the agent of pause `index` was sent SIGCONT after `step`.
    pub fn resumed(&mut self, index: usize, step: u64) {
        if let Some(r) = self.records.get_mut(index) {
            r.resumed_at_step = Some(step);
        }
    }

    /// Effective restarts of `uav`.
    pub fn restarts(&self, uav: u32) -> u64 {
        fleet_observe::faults::restarts(&self.records, uav)
    }

    /// Every fault with what happened to it.
    pub fn records(&self) -> &[FaultRecord] {
        &self.records
    }

    /// Fills every restart's and resumed pause's `resync_steps` from the run's measured
    /// steps. Only the steps before the agent's next effective kill count (its estimates
    /// after that come from another process).
    pub fn measure_resync(&mut self, series: &[StepMetrics]) {
        for i in 0..self.records.len() {
            let r = &self.records[i];
            let from = match r.kind {
                FaultKind::Restart if r.effective => r.applied_at_step,
                FaultKind::Pause if r.effective => r.resumed_at_step,
                _ => None,
            };
            let Some(from) = from else {
                continue;
            };
            let until = self
                .records
                .iter()
                .filter(|o| o.uav == r.uav && o.kind == FaultKind::Kill && o.effective)
                .filter_map(|o| o.applied_at_step)
                .filter(|&s| s > from)
                .min()
                .unwrap_or(u64::MAX);
            let uav = r.uav;
            let back = series
                .iter()
                .filter(|m| m.step > from && m.step <= until)
                .find(|m| m.estimated_by(uav))
                .map(|m| m.step - from);
            self.records[i].resync_steps = back;
        }
    }

    /// The worst and the mean resync over the faults that have one (`None` when none has).
    pub fn resync_max_mean(&self) -> (Option<u64>, Option<f64>) {
        fleet_observe::faults::resync_max_mean(&self.records)
    }
}

/// A stopped agent waiting for its SIGCONT.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PendingResume {
    /// The pause's index in the plan.
    pub index: usize,
    /// The UAV.
    pub uav: u32,
    /// The agent process that was stopped ([`super::children::Children::pause_agent`]).
    pub incarnation: u64,
    /// When to send SIGCONT.
    pub due: Instant,
}

/// The pauses of a run waiting for their SIGCONT.
#[derive(Clone, Debug, Default)]
pub struct Resumes {
    pending: Vec<PendingResume>,
}

impl Resumes {
    /// Adds a pause.
    pub fn push(&mut self, resume: PendingResume) {
        self.pending.push(resume);
    }

    /// The earliest due time, `None` when nothing waits.
    pub fn next_due(&self) -> Option<Instant> {
        self.pending.iter().map(|r| r.due).min()
    }

    /// Removes and returns the pauses due by `now`, earliest first.
    pub fn take_due(&mut self, now: Instant) -> Vec<PendingResume> {
        let (mut due, later): (Vec<_>, Vec<_>) = std::mem::take(&mut self.pending)
            .into_iter()
            .partition(|r| r.due <= now);
        self.pending = later;
        due.sort_by_key(|r| r.due);
        due
    }

    /// Removes and returns every pause still waiting.
    pub fn take_all(&mut self) -> Vec<PendingResume> {
        std::mem::take(&mut self.pending)
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;
    use std::time::Duration;

    use super::*;
    use fleet_observe::observe::metrics::SetMetrics;

    fn plan(faults: &[&str]) -> FaultPlan {
        let faults: Vec<Fault> = faults.iter().map(|t| t.parse().unwrap()).collect();
        FaultPlan::new(&faults)
    }

    #[test]
    fn faults_come_due_once_in_order() {
        let mut plan = plan(&["kill:1@1", "restart:1@2.5", "pause:0@3+1.5"]);
        assert_eq!(plan.times(), vec![1.0, 2.5, 3.0]);
        assert!(plan.due(0.5).is_empty());
        let due = plan.due(1.0);
        assert_eq!(due.len(), 1);
        assert_eq!(
            (due[0].index, due[0].kind, due[0].uav),
            (0, FaultKind::Kill, 1)
        );
        assert!(plan.due(2.0).is_empty());
        plan.applied(0, 2, 1.0, true);
        let due = plan.due(9.0);
        assert_eq!(due.len(), 2);
        assert_eq!(
            (due[0].kind, due[1].kind),
            (FaultKind::Restart, FaultKind::Pause)
        );
        assert_eq!(due[1].pause_s, Some(1.5));
        plan.applied(1, 5, 2.5, true);
        assert_eq!(plan.restarts(1), 1);
        assert_eq!(plan.restarts(0), 0);
        assert_eq!(plan.records()[0].applied_at_step, Some(2));
        assert_eq!(plan.records()[2].pause_s, Some(1.5));
    }

    /// Steps 0..n, each measured from the estimates of the agents `by(step)` names.
    fn series(n: u64, by: impl Fn(u64) -> Vec<u32>) -> Vec<StepMetrics> {
        (0..n)
            .map(|step| StepMetrics {
                step,
                agents: by(step)
                    .into_iter()
                    .map(|u| (u, SetMetrics::default()))
                    .collect::<BTreeMap<_, _>>(),
                ..StepMetrics::default()
            })
            .collect()
    }

    #[test]
    fn resync_counts_the_steps_until_the_agents_estimates_are_back() {
        let mut plan = plan(&[
            "kill:1@1",
            "restart:1@2",
            "pause:0@3+1",
            "pause:1@5+1",
            "kill:1@6",
            "restart:1@7",
        ]);
        // Kill at step 2, restart at step 4, back at step 7; agent 0 paused at step 6,
        // resumed after step 6, back at step 8; agent 1 paused at step 10, resumed after
        // 10, killed at 12 before it was back, restarted at 14 and never back.
        for (i, step) in [2, 4, 6, 10, 12, 14].into_iter().enumerate() {
            plan.applied(i, step, step as f64 * 0.5, true);
        }
        plan.resumed(2, 6);
        plan.resumed(3, 10);
        let s = series(20, |k| {
            let mut by = Vec::new();
            if k <= 6 || k >= 8 {
                by.push(0);
            }
            if k <= 2 || (7..=10).contains(&k) {
                by.push(1);
            }
            by
        });
        plan.measure_resync(&s);
        let resync: Vec<Option<u64>> = plan.records().iter().map(|r| r.resync_steps).collect();
        assert_eq!(resync, vec![None, Some(3), Some(2), None, None, None]);
        assert_eq!(plan.resync_max_mean(), (Some(3), Some(2.5)));
        assert_eq!(FaultPlan::default().resync_max_mean(), (None, None));
    }

    #[test]
    fn pending_resumes_come_due_in_time_order() {
        let now = Instant::now();
        let at = |ms| now + Duration::from_millis(ms);
        let mut resumes = Resumes::default();
        assert_eq!(resumes.next_due(), None);
        for (index, ms) in [(0, 300), (1, 100), (2, 200)] {
            resumes.push(PendingResume {
                index,
                uav: 0,
                incarnation: 1,
                due: at(ms),
            });
        }
        assert_eq!(resumes.next_due(), Some(at(100)));
        let due: Vec<usize> = resumes.take_due(at(250)).iter().map(|r| r.index).collect();
        assert_eq!(due, vec![1, 2]);
        assert_eq!(resumes.next_due(), Some(at(300)));
        assert_eq!(resumes.take_all().len(), 1);
        assert_eq!(resumes.next_due(), None);
    }
}
