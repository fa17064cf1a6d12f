//! Showing: what the run's [`Sink`]s are and what they are shown.
//!
//! [`Showing`] owns the sinks and the little state that only they need: the UAV whose camera
//! frames and sets they show, the plans of the newest guidance round (decoded only when a
//! sink shows plans) and whether the fleet's map changed since the last step shown. It only
//! reads what was measured and never feeds back into the measurement, which is why it stands
//! apart from the loop: the run is the same with sinks or without. The time sinks take is
//! counted to each sink's own phase of the observer's [`PhaseClock`], and what they make
//! (files, failures) goes into the run's [`ObserverReport`].

use std::collections::BTreeMap;

use fleet_process::resources::PhaseClock;
use protocol::codec;
use protocol::frame::CvsFrame;
use protocol::wire::{DropReason, GuidanceToken, PlannedView, TruthState};

use super::metrics::FusedSets;
use super::sink::{Sink, StepView};
use super::{ObserverReport, StepMetrics};

/// The run's sinks and what they are shown (see the [module](self) docs).
pub(super) struct Showing {
    /// What the run is shown to.
    sinks: Vec<Box<dyn Sink>>,
    /// The UAV whose sets are shown (the lowest id's when its estimate of a step is missing).
    shown_uav: u32,
    /// The UAV whose camera frames a sink shows.
    camera: Option<u32>,
    /// Whether a sink shows the guidance plans.
    shows_plans: bool,
    /// The newest guidance round seen and its plans, by UAV (the first plan seen of each).
    plans: (u64, BTreeMap<u32, PlannedView>),
    /// Whether the fleet's map changed since the last step shown.
    oem_changed: bool,
}

impl Showing {
    /// Shows the run to `sinks`, with `shown_uav`'s sets.
    pub(super) fn new(sinks: Vec<Box<dyn Sink>>, shown_uav: u32) -> Showing {
        Showing {
            camera: sinks.iter().find_map(|s| s.camera()),
            shows_plans: sinks.iter().any(|s| s.shows_plans()),
            sinks,
            shown_uav,
            plans: (0, BTreeMap::new()),
            oem_changed: false,
        }
    }

    /// The UAV whose camera frames a sink shows, if one does.
    pub(super) fn camera(&self) -> Option<u32> {
        self.camera
    }

    /// Notes whether the fleet's map changed, for the next step shown.
    pub(super) fn note_map(&mut self, changed: bool) {
        self.oem_changed |= changed;
    }

    /// Hands a camera frame of the shown UAV to the sinks that show it.
    pub(super) fn frame(&mut self, frame: &CvsFrame, clock: &mut PhaseClock) {
        for sink in &mut self.sinks {
            if sink.camera() == self.camera {
                let before = clock.enter(sink.phase());
                sink.frame(frame);
                clock.enter(before);
            }
        }
    }

    /// Reads a guidance token's plans when a sink shows them; an unreadable token is counted
    /// as dropped.
    pub(super) fn token(&mut self, bytes: &[u8], report: &mut ObserverReport) {
        if self.shows_plans {
            match codec::decode::<GuidanceToken>(bytes) {
                Ok(token) => self.note_plans(token),
                Err(e) => {
                    tracing::warn!(error = %e, "unreadable token");
                    report.drop_message("token", DropReason::Malformed);
                }
            }
        }
    }

    /// Keeps the plans of the newest round: a newer round replaces them, and within a round
    /// the first plan seen of each UAV is kept (as the agents merge tokens).
    fn note_plans(&mut self, token: GuidanceToken) {
        let (round, plans) = &mut self.plans;
        if token.round < *round {
            return;
        }
        if token.round > *round {
            *round = token.round;
            plans.clear();
        }
        for plan in token.plans {
            plans.entry(plan.uav).or_insert(plan);
        }
    }

    /// Shows a measured step with the shown UAV's fused sets among `all_fused` (the lowest
    /// id's when its estimate did not arrive: the lowest id comes first, and its sets are the
    /// ones drawn in `sets.png`).
    pub(super) fn show_fused(
        &mut self,
        truth: &TruthState,
        all_fused: &[(u32, FusedSets)],
        step: &StepMetrics,
        clock: &mut PhaseClock,
        report: &mut ObserverReport,
    ) {
        let shown = all_fused
            .iter()
            .find(|(uav, _)| *uav == self.shown_uav)
            .or(all_fused.first())
            .map(|(uav, fused)| (*uav, fused));
        self.show(truth, shown, step, clock, report);
    }

    /// Shows a measured step to every sink; a sink that fails is abandoned.
    fn show(
        &mut self,
        truth: &TruthState,
        sets: Option<(u32, &FusedSets)>,
        step: &StepMetrics,
        clock: &mut PhaseClock,
        report: &mut ObserverReport,
    ) {
        let view = StepView {
            truth,
            sets,
            oem: &report.oem,
            oem_changed: std::mem::take(&mut self.oem_changed),
            plans: &self.plans.1,
            metrics: step,
        };
        let mut failed = Vec::new();
        for (i, sink) in self.sinks.iter_mut().enumerate() {
            let before = clock.enter(sink.phase());
            if let Err(e) = sink.step(&view) {
                failed.push((i, e));
            }
            clock.enter(before);
        }
        for (i, e) in failed.into_iter().rev() {
            let sink = self.sinks.remove(i);
            sink_failed(sink.essential(), &*e, report);
        }
    }

    /// Ends every sink, keeping the files they made.
    pub(super) fn finish(&mut self, report: &mut ObserverReport) {
        for sink in std::mem::take(&mut self.sinks) {
            let essential = sink.essential();
            match sink.finish() {
                Ok(file) => report.files.extend(file),
                Err(e) => sink_failed(essential, &*e, report),
            }
        }
    }
}

/// Logs a sink's failure; an essential sink's fails the run.
fn sink_failed(
    essential: bool,
    e: &(dyn std::error::Error + Send + Sync),
    report: &mut ObserverReport,
) {
    if essential {
        tracing::error!(error = %e, "a view of the run failed");
        report.sink_failure.get_or_insert_with(|| e.to_string());
    } else {
        tracing::warn!(error = %e, "a view of the run abandoned");
    }
}

#[cfg(test)]
mod tests {
    use protocol::camera::CameraPose;
    use sets::grid::GroundGrid;
    use sets::math::Point3;

    use super::super::sink::{SinkError, SinkFile};
    use super::*;

    /// A sink that only says what it wants.
    struct Wants {
        camera: Option<u32>,
        plans: bool,
    }

    impl Sink for Wants {
        fn phase(&self) -> &'static str {
            "test"
        }

        fn essential(&self) -> bool {
            false
        }

        fn camera(&self) -> Option<u32> {
            self.camera
        }

        fn shows_plans(&self) -> bool {
            self.plans
        }

        fn step(&mut self, _view: &StepView<'_>) -> Result<(), SinkError> {
            Ok(())
        }

        fn finish(self: Box<Self>) -> Result<Option<SinkFile>, SinkError> {
            Ok(None)
        }
    }

    fn showing(camera: Option<u32>, plans: bool) -> Showing {
        Showing::new(vec![Box::new(Wants { camera, plans })], 0)
    }

    fn token(round: u64, plans: &[(u32, usize)]) -> Vec<u8> {
        let token = GuidanceToken {
            round,
            step: round,
            order: Vec::new(),
            holder: 0,
            issued_by: 0,
            plans: plans
                .iter()
                .map(|&(uav, poses)| PlannedView {
                    uav,
                    poses: vec![
                        CameraPose {
                            position: Point3::new(0.0, 0.0, 40.0),
                            yaw: 0.0,
                        };
                        poses
                    ],
                })
                .collect(),
            pose: None,
        };
        codec::encode(&token).expect("a token encodes")
    }

    fn plans(showing: &Showing) -> (u64, Vec<(u32, usize)>) {
        let (round, plans) = &showing.plans;
        (
            *round,
            plans.values().map(|p| (p.uav, p.poses.len())).collect(),
        )
    }

    #[test]
    fn the_sinks_say_which_camera_and_whether_plans_are_shown() {
        let s = showing(Some(3), false);
        assert_eq!((s.camera(), s.shows_plans), (Some(3), false));
        let s = showing(None, true);
        assert_eq!((s.camera(), s.shows_plans), (None, true));
    }

    #[test]
    fn the_newest_round_replaces_the_plans_and_the_first_plan_of_a_uav_is_kept() {
        let mut report = ObserverReport::new(1, GroundGrid::new(5.0, 1.0));
        let mut s = showing(None, true);
        s.token(&token(2, &[(0, 1), (1, 1)]), &mut report);
        s.token(&token(2, &[(1, 2), (2, 2)]), &mut report);
        assert_eq!(plans(&s), (2, vec![(0, 1), (1, 1), (2, 2)]));
        s.token(&token(1, &[(3, 1)]), &mut report);
        assert_eq!(plans(&s), (2, vec![(0, 1), (1, 1), (2, 2)]));
        s.token(&token(3, &[(3, 1)]), &mut report);
        assert_eq!(plans(&s), (3, vec![(3, 1)]));
        assert!(report.dropped.is_empty());
    }

    #[test]
    fn tokens_are_read_only_when_a_sink_shows_plans() {
        let mut report = ObserverReport::new(1, GroundGrid::new(5.0, 1.0));
        let mut s = showing(None, false);
        s.token(&token(2, &[(0, 1)]), &mut report);
        s.token(&[], &mut report);
        assert_eq!(plans(&s), (0, vec![]));
        assert!(report.dropped.is_empty());
        let mut s = showing(None, true);
        s.token(&[], &mut report);
        assert_eq!(report.dropped.get("token:malformed"), Some(&1));
    }
}
