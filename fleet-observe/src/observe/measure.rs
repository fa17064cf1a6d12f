//! Measuring one step: the agents' estimates of the step checked against the truth, fused as
//! each agent fused them, and measured ([`StepMetrics`]). The observer's loop measures each
//! step it acknowledges with it; [`Measurer`] is the same measurement for a fleet that runs in
//! the caller's process and hands it the agents' messages itself (the in-process backend of
//! the Python environments), so both write the same `timeseries.csv`.

use std::collections::BTreeMap;

use protocol::scenario::Scenario;
use protocol::wire::{TruthState, WireKind};
use sets::grid::GroundGrid;

use super::metrics::{
    AgentSpread, FusedSets, ObservedEstimate, SetMetrics, fleet_areas, identified_ids, violations,
};
use super::reception::Reception;
use super::{FinalState, ObserverReport, StepMetrics};

/// Measures step `truth.step` from the estimates of it that `reception` holds: checks them
/// against the truth, fuses them as the agents did and measures each agent's sets (over its
/// window, under windows); records what the report keeps of a step (each agent's last `X̄`,
/// the windows' tally, the tracks). Returns the step's metrics and each agent's fused sets,
/// ascending by UAV.
pub(super) fn measure_step(
    reception: &mut Reception,
    truth: &TruthState,
    live_agents: u32,
    report: &mut ObserverReport,
) -> (StepMetrics, Vec<(u32, FusedSets)>) {
    let k = truth.step;
    let grid = reception.grid();
    let estimates = reception.take(k);
    let violation_count = check_guarantee(truth, &estimates, &grid);
    let all_fused = reception.fuse(k, &estimates);
    let mut agents = BTreeMap::new();
    let mut windowed = false;
    for ((uav, fused), estimate) in all_fused.iter().zip(&estimates) {
        // Its `X̄` after this step's fusion, the last it holds if its run ends here.
        report
            .final_undetected
            .insert(*uav, (k, fused.undetected.clone()));
        let mut metrics = SetMetrics::measure(fused, truth.targets(), &grid);
        // A window over the whole region is no window: the metrics stay today's.
        let window = reception.window_of(estimate);
        if let Some(window) = window.filter(|w| w.cell_count() < grid.cell_count() as u64) {
            metrics = metrics.within(fused, &window);
            report.windows.count(fused, &window);
            windowed = true;
        }
        agents.insert(*uav, metrics);
    }
    let mut spread = AgentSpread::over(agents.values());
    // Under windows the fleet's UA and OA stand for the agents' mean (docs/design.md §6).
    if let (true, Some(spread), Some((ua, oa))) = (
        windowed,
        spread.as_mut(),
        fleet_areas(all_fused.iter().map(|(_, f)| f), &grid),
    ) {
        spread.mean.ua = ua;
        spread.mean.oa = oa;
    }
    let estimate_count = estimates.len() as u32;
    let identified_any = identified_ids(&estimates).len() as u32;
    reception.keep_sent(k, estimates);
    report.record_fleet(truth, live_agents);
    report.steps += 1;
    let step = StepMetrics {
        step: k,
        time_s: truth.time_s,
        live_agents,
        estimates: estimate_count,
        identified_any,
        mean: spread.map(|s| s.mean),
        worst: spread.map(|s| s.worst),
        agents,
        violations: violation_count,
    };
    (step, all_fused)
}

/// Keeps the lowest id's fused sets of the step as the run's final state (drawn in
/// `sets.png`).
pub(super) fn keep_final_state(
    report: &mut ObserverReport,
    truth: &TruthState,
    all_fused: Vec<(u32, FusedSets)>,
) {
    if let Some((uav, sets)) = all_fused.into_iter().next() {
        report.final_state = Some(FinalState {
            step: truth.step,
            time_s: truth.time_s,
            uav,
            sets,
            targets: truth.targets().to_vec(),
        });
    }
}

/// Checks every estimate against the truth, logs each violation and returns their count.
fn check_guarantee(truth: &TruthState, estimates: &[ObservedEstimate], grid: &GroundGrid) -> u32 {
    let k = truth.step;
    let mut violation_count = 0;
    for e in estimates {
        for v in violations(e, truth.targets(), grid) {
            violation_count += 1;
            tracing::error!(
                step = k,
                agent = v.uav,
                target = v.target,
                set = v.set.name(),
                distance_m = v.distance_m,
                "guarantee violated: target outside its set"
            );
        }
    }
    violation_count
}

/// The observer's measurement of a fleet that runs in the caller's process: the caller hands
/// it each agent's messages of a step as an agent publishes them ([`Measurer::receive`]), then
/// the step's truth ([`Measurer::measure`]). What it measures is what the observer of a run
/// of the same fleet measures, step for step: the same decoding, fusion, guarantee check and
/// metrics (the observer's own loop calls the same code).
///
/// ```no_run
/// # use fleet_observe::observe::Measurer;
/// # use protocol::scenario::Scenario;
/// # use protocol::wire::{TruthState, WireKind};
/// # fn state_bytes(uav: u32) -> Vec<u8> { Vec::new() }
/// let scenario = Scenario::default();
/// let mut measurer = Measurer::new(&scenario);
/// let truth = TruthState::default(); // the world's truth of the step
/// for uav in 0..scenario.uavs.count {
///     // Under the measurement exchange the observers read the agents' state messages.
///     measurer.receive(uav, WireKind::State, &state_bytes(uav));
/// }
/// let metrics = measurer.measure(&truth);
/// println!("step {}: {} violations", metrics.step, metrics.violations);
/// ```
pub struct Measurer {
    reception: Reception,
    report: ObserverReport,
    series: Vec<StepMetrics>,
}

impl Measurer {
    /// The measurement of `scenario`'s fleet, before any step.
    pub fn new(scenario: &Scenario) -> Measurer {
        let reception = Reception::new(scenario);
        Measurer {
            report: ObserverReport::new(scenario.uavs.count, reception.oem_grid()),
            reception,
            series: Vec::new(),
        }
    }

    /// The message kind the observer measures the agents' sets from: their state messages
    /// under the measurement exchange, their estimates under the sets exchange.
    pub fn measured_kind(scenario: &Scenario) -> WireKind {
        match scenario.comms.exchange {
            protocol::scenario::Exchange::Measurements => WireKind::State,
            protocol::scenario::Exchange::Sets => WireKind::Estimate,
        }
    }

    /// Takes in one message of agent `sender` of `kind` (its payload, as published); one
    /// that cannot be read is counted as dropped in the report, as the observer counts it.
    pub fn receive(&mut self, sender: u32, kind: WireKind, payload: &[u8]) {
        self.reception
            .receive_payload(sender, kind, payload, &mut self.report);
    }

    /// Measures step `truth.step` from the messages received for it (the agents the truth
    /// says live are the step's live agents) and appends its metrics to the series.
    pub fn measure(&mut self, truth: &TruthState) -> &StepMetrics {
        let live_agents = truth.uavs().iter().filter(|u| u.agent_live != 0).count() as u32;
        let (step, all_fused) =
            measure_step(&mut self.reception, truth, live_agents, &mut self.report);
        keep_final_state(&mut self.report, truth, all_fused);
        self.series.push(step);
        self.series.last().expect("a step was just pushed")
    }

    /// Every step measured so far, in order (`timeseries.csv`:
    /// [`crate::results::timeseries::to_csv`]).
    pub fn series(&self) -> &[StepMetrics] {
        &self.series
    }

    /// What was gathered so far (counters, tracks, the final sets).
    pub fn report(&self) -> &ObserverReport {
        &self.report
    }
}

#[cfg(test)]
mod tests {
    use protocol::scenario::{Exchange, Scenario};
    use protocol::wire::{TruthState, WireKind};

    use super::Measurer;

    /// A small fleet of 3 UAVs flown in process for `steps` steps under `exchange`, each step
    /// measured from the messages the observers read and checked against the estimators;
    /// the series.
    fn measured(exchange: Exchange, steps: u64) -> Vec<super::StepMetrics> {
        let mut scenario = Scenario::load(
            None,
            &[
                "region.half_extent_m=50".to_owned(),
                "uavs.count=3".to_owned(),
                "targets.count=3".to_owned(),
                "camera.rows=60".to_owned(),
                "camera.cols=80".to_owned(),
            ],
        )
        .expect("scenario");
        scenario.comms.exchange = exchange;
        let options = sim::FleetOptions {
            states: true,
            ..sim::FleetOptions::default()
        };
        let mut fleet = sim::Fleet::new(&scenario, options).expect("fleet");
        let mut measurer = Measurer::new(&scenario);
        let kind = Measurer::measured_kind(&scenario);
        let mut truth = Box::<TruthState>::default();
        for _ in 0..steps {
            let mut sample = fleet.sample();
            fleet.sense(&mut sample, |_| {}).expect("sense");
            fleet.share(&mut sample, |_| {}).expect("share");
            let messages = match kind {
                WireKind::State => fleet.states(),
                _ => fleet.messages(),
            };
            for (uav, bytes) in messages.iter().enumerate() {
                measurer.receive(uav as u32, kind, bytes);
            }
            fleet.world().truth(1, &mut truth);
            let m = measurer.measure(&truth);
            // Each agent is measured on the sets its estimator holds after fusing.
            let cells = fleet.config().grid.cell_count() as f64;
            for (uav, estimator) in fleet.estimators().iter().enumerate() {
                let st = estimator.state();
                let own = &m.agents[&(uav as u32)];
                assert_eq!(own.ua, st.undetected.cells().count() as f64 / cells);
                assert_eq!(own.identified, st.targets.len() as f64);
            }
            fleet.advance();
        }
        assert_eq!(measurer.report().steps, steps);
        assert!(
            measurer.report().dropped.is_empty(),
            "every message was read"
        );
        measurer.series().to_vec()
    }

    #[test]
    fn a_fleet_in_process_is_measured_step_by_step_from_what_its_agents_publish() {
        for exchange in [Exchange::Measurements, Exchange::Sets] {
            let series = measured(exchange, 6);
            let steps: Vec<u64> = series.iter().map(|m| m.step).collect();
            assert_eq!(steps, [0, 1, 2, 3, 4, 5], "{exchange:?}");
            for m in &series {
                assert_eq!((m.live_agents, m.estimates), (3, 3), "{exchange:?}");
                assert_eq!(m.violations, 0);
                let mean = m.mean.expect("every agent measured");
                assert!(
                    mean.ua > 0.0 && mean.ua < 1.0,
                    "{exchange:?}: UA {}",
                    mean.ua
                );
            }
        }
        // A message that cannot be read is counted as the observer counts it.
        let scenario = Scenario::default();
        let mut measurer = Measurer::new(&scenario);
        measurer.receive(0, WireKind::State, b"not a message");
        assert_eq!(measurer.report().dropped.values().sum::<u64>(), 1);
    }
}
