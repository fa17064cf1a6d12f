//! The fleet in one process and its step: sense, share, steer, advance.

use std::time::{Duration, Instant};

use estimator::message::{self, EstimateOutbox, PeerMessage};
use estimator::{
    ApplyReport, Estimator, EstimatorConfig, FuseReport, Measurement, StepReport, StepTimings,
};
use protocol::frame::CvsFrame;
use protocol::scenario::{Exchange, Scenario};
use protocol::wire::PlannedView;
use uav_agent::guidance::{self, Decision, GuidanceParams};
use world_server::World;

use crate::{FleetCreateError, FleetStepError, PlanningState};

/// How the UAVs' yaw references are set.
#[derive(Clone, Debug, Default)]
pub enum Steering {
    /// By the caller only ([`Fleet::world_mut`]): unless told otherwise, the UAVs keep the
    /// reference the world launched them with.
    #[default]
    Manual,
    /// At every guidance step, a round of decisions in token order with these settings
    /// ([`guidance::decide`]: the planner their `planner` names), each UAV flying the yaw
    /// reference it decided.
    Guided(Box<GuidanceParams>),
}

/// What the fleet's loop does besides folding the frames.
#[derive(Clone, Debug)]
pub struct FleetOptions {
    /// Run tag stamped on the frames.
    pub run_tag: u64,
    /// Whether [`Fleet::step`] exchanges the estimates ([`Fleet::share`]).
    pub exchange: bool,
    /// How often an estimate carries the whole map (every that many messages, and the first);
    /// `None`: the scenario's (`EstimatorConfig::oem_full_every`).
    pub oem_full_every: Option<u64>,
    /// How the yaw references are set.
    pub steering: Steering,
    /// Whether each UAV also encodes its sets for the observers once it fused its peers', as
    /// agents do under the measurement exchange ([`Fleet::states`]).
    pub states: bool,
}

impl Default for FleetOptions {
    /// Run tag 1, estimates exchanged, the scenario's map period, steering left to the caller,
    /// no state messages.
    fn default() -> Self {
        FleetOptions {
            run_tag: 1,
            exchange: true,
            oem_full_every: None,
            steering: Steering::Manual,
            states: false,
        }
    }
}

/// What one step measured, per UAV in the order of the UAVs. Times are wall times of the
/// estimators' and the messages' work only, never of the rendering.
#[derive(Clone, Debug, Default)]
pub struct StepSample {
    /// The step.
    pub step: u64,
    /// Wall time of each UAV's estimator step.
    pub step_time: Vec<Duration>,
    /// The phases of each UAV's estimator step.
    pub timings: Vec<StepTimings>,
    /// Encoded size of each UAV's estimate, bytes.
    pub message_bytes: Vec<usize>,
    /// Time to compose and encode each UAV's estimate.
    pub encode_time: Vec<Duration>,
    /// Time to decode and validate each peer message fused this step (every receiver, every
    /// sender).
    pub decode_time: Vec<Duration>,
    /// Time to fuse each peer estimate (after decoding).
    pub fuse_time: Vec<Duration>,
    /// The decisions of the step's guidance round, in token order (none on other steps).
    pub decisions: Vec<Decision>,
}

/// One UAV's frame, just folded into its estimator ([`Fleet::sense`]).
#[derive(Clone, Copy)]
pub struct Sensed<'a> {
    /// The UAV.
    pub uav: usize,
    /// Its frame of the step.
    pub frame: &'a CvsFrame,
    /// What its estimator's step changed.
    pub report: &'a StepReport,
    /// Its estimator, after the step.
    pub estimator: &'a Estimator,
}

/// One peer's estimate, just fused by a UAV ([`Fleet::share`]).
#[derive(Clone, Copy, Debug)]
pub struct Fused<'a> {
    /// The UAV that fused it.
    pub receiver: usize,
    /// The UAV that sent it.
    pub sender: usize,
    /// What the fusion of its sets changed (none when it carried no sets).
    pub report: Option<&'a FuseReport>,
    /// What applying its measurement changed (under the measurement exchange).
    pub applied: Option<&'a ApplyReport>,
}

/// The world and one estimator per UAV, run in one process as a lockstep run runs them (see
/// the crate docs).
pub struct Fleet {
    world: World,
    config: EstimatorConfig,
    /// What the estimates carry (the scenario's `comms.exchange`).
    exchange: Exchange,
    estimators: Vec<Estimator>,
    outboxes: Vec<EstimateOutbox>,
    /// Each UAV's measurement of the step, under the measurement exchange.
    measurements: Vec<Option<Measurement>>,
    options: FleetOptions,
    frame: Box<CvsFrame>,
    messages: Vec<Vec<u8>>,
    /// The observers' copy of each UAV's sets, as an agent's state outbox composes it.
    state_outboxes: Vec<EstimateOutbox>,
    states: Vec<Vec<u8>>,
}

impl Fleet {
    /// The world of `scenario` and a fresh estimator per UAV.
    pub fn new(scenario: &Scenario, options: FleetOptions) -> Result<Fleet, FleetCreateError> {
        let world = World::new(scenario)?;
        let config = EstimatorConfig::from_scenario(scenario);
        let n = world.uav_count();
        let exchange = scenario.comms.exchange;
        // On perfect links a fresh agent never sends whole sets with its measurements, as
        // agents do (`comms.whole_sets_every` is for lossy or range-limited links).
        let full_every = match exchange {
            Exchange::Sets => options.oem_full_every.unwrap_or(config.oem_full_every),
            Exchange::Measurements => u64::MAX,
        };
        let outbox = |i: usize| {
            let outbox = EstimateOutbox::new(i as u32, 1, full_every);
            match exchange {
                Exchange::Sets => outbox,
                Exchange::Measurements => outbox.starting_fresh(),
            }
        };
        Ok(Fleet {
            estimators: (0..n).map(|_| Estimator::new(config.clone())).collect(),
            outboxes: (0..n).map(outbox).collect(),
            measurements: vec![None; n],
            exchange,
            messages: vec![Vec::new(); n],
            state_outboxes: (0..n)
                .map(|i| {
                    EstimateOutbox::new(i as u32, 1, config.oem_full_every)
                        .with_set_deltas()
                        .without_map()
                })
                .collect(),
            states: vec![Vec::new(); n],
            frame: CvsFrame::new_boxed(),
            world,
            config,
            options,
        })
    }

    /// Number of UAVs.
    pub fn uav_count(&self) -> usize {
        self.estimators.len()
    }

    /// The world (its step, its truth, its city).
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The world, mutably: to set yaw references under [`Steering::Manual`].
    pub fn world_mut(&mut self) -> &mut World {
        &mut self.world
    }

    /// The estimators' configuration (the same for every UAV).
    pub fn config(&self) -> &EstimatorConfig {
        &self.config
    }

    /// The estimators, by UAV.
    pub fn estimators(&self) -> &[Estimator] {
        &self.estimators
    }

    /// Each UAV's encoded estimate of the last exchange (empty before the first).
    pub fn messages(&self) -> &[Vec<u8>] {
        &self.messages
    }

    /// Each UAV's sets of the last exchange as it sends them to the observers, encoded (set
    /// deltas, no map: an agent's state message), with [`FleetOptions::states`]; empty
    /// otherwise.
    pub fn states(&self) -> &[Vec<u8>] {
        &self.states
    }

    /// The options the fleet runs with.
    pub fn options(&self) -> &FleetOptions {
        &self.options
    }

    /// Whether the current step starts a guidance period (never under manual steering).
    pub fn is_guidance_step(&self) -> bool {
        match &self.options.steering {
            Steering::Guided(params) => self
                .world
                .step()
                .is_multiple_of(params.steps_per_period.max(1) as u64),
            Steering::Manual => false,
        }
    }

    /// An empty sample of the current step, for the phases to fill.
    pub fn sample(&self) -> StepSample {
        StepSample {
            step: self.world.step(),
            ..StepSample::default()
        }
    }

    /// One step: [`Fleet::sense`], [`Fleet::share`] (when the options exchange estimates),
    /// [`Fleet::steer`], [`Fleet::advance`].
    pub fn step(&mut self) -> Result<StepSample, FleetStepError> {
        let mut sample = self.sample();
        self.sense(&mut sample, |_| {})?;
        if self.options.exchange {
            self.share(&mut sample, |_| {})?;
        }
        sample.decisions = self.steer()?;
        self.advance();
        Ok(sample)
    }

    /// Every UAV's frame of the current step, rendered and folded into its estimator, in the
    /// order of the UAVs; `look` sees each one once folded. Each estimator step is timed into
    /// `sample`.
    pub fn sense(
        &mut self,
        sample: &mut StepSample,
        mut look: impl FnMut(Sensed<'_>),
    ) -> Result<(), FleetStepError> {
        for (uav, estimator) in self.estimators.iter_mut().enumerate() {
            self.world
                .render(uav, self.options.run_tag, &mut self.frame);
            let start = Instant::now();
            let report =
                match self.exchange {
                    Exchange::Sets => estimator.step(&self.frame),
                    Exchange::Measurements => estimator.step_sharing(&self.frame, uav as u32).map(
                        |(report, measurement)| {
                            self.measurements[uav] = Some(measurement);
                            report
                        },
                    ),
                }
                .map_err(|source| FleetStepError::Frame { uav, source })?;
            sample.step_time.push(start.elapsed());
            sample.timings.push(report.timings);
            look(Sensed {
                uav,
                frame: &self.frame,
                report: &report,
                estimator,
            });
        }
        Ok(())
    }

    /// Every UAV's estimate composed and encoded as on the wire ([`Fleet::messages`]), then
    /// decoded by every other UAV, which applies its measurement (the measurement exchange)
    /// and fuses its sets: receivers in the order of the UAVs, each taking its peers by
    /// ascending id (perfect links: what `protocol::radio::Radio::perfect` delivers). `look`
    /// sees each message taken in. The encoding, each decoding and each fusion or application
    /// are timed into `sample`. With [`FleetOptions::states`], each UAV then encodes its sets
    /// for the observers ([`Fleet::states`]).
    pub fn share(
        &mut self,
        sample: &mut StepSample,
        mut look: impl FnMut(Fused<'_>),
    ) -> Result<(), FleetStepError> {
        let sending = self.estimators.iter_mut().zip(&mut self.outboxes);
        for (uav, (estimator, outbox)) in sending.enumerate() {
            let start = Instant::now();
            let msg = match &self.measurements[uav] {
                Some(m) if self.exchange == Exchange::Measurements => {
                    outbox.compose_measurement(estimator.state_mut(), m, &[])
                }
                _ => outbox.compose(estimator.state_mut()),
            };
            let bytes =
                message::to_bytes(&msg).map_err(|source| FleetStepError::Encode { uav, source })?;
            sample.encode_time.push(start.elapsed());
            sample.message_bytes.push(bytes.len());
            self.messages[uav] = bytes;
        }
        for (receiver, estimator) in self.estimators.iter_mut().enumerate() {
            for (sender, bytes) in self.messages.iter().enumerate() {
                if receiver == sender {
                    continue;
                }
                let start = Instant::now();
                let peer =
                    PeerMessage::from_bytes(bytes, estimator.config()).map_err(|source| {
                        FleetStepError::Decode {
                            uav: sender,
                            source,
                        }
                    })?;
                sample.decode_time.push(start.elapsed());
                let start = Instant::now();
                let applied = peer.measurement.as_ref().map(|m| estimator.apply(m));
                let report = peer.estimate.as_ref().map(|e| estimator.fuse(e));
                sample.fuse_time.push(start.elapsed());
                look(Fused {
                    receiver,
                    sender,
                    report: report.as_ref(),
                    applied: applied.as_ref(),
                });
            }
        }
        if self.options.states {
            let composing = self.estimators.iter_mut().zip(&mut self.state_outboxes);
            for (uav, (estimator, outbox)) in composing.enumerate() {
                let msg = outbox.compose(estimator.state_mut());
                self.states[uav] = message::to_bytes(&msg)
                    .map_err(|source| FleetStepError::Encode { uav, source })?;
            }
        }
        Ok(())
    }

    /// On a guidance step under [`Steering::Guided`], the round of decisions in token order
    /// ([`Fleet::plan_round`] with the steering's settings), each UAV's yaw reference set to
    /// the one it decided; returns the decisions (none on other steps).
    pub fn steer(&mut self) -> Result<Vec<Decision>, FleetStepError> {
        if !self.is_guidance_step() {
            return Ok(Vec::new());
        }
        let Steering::Guided(params) = &self.options.steering else {
            return Ok(Vec::new());
        };
        let decisions = self.plan_round(params, &[])?;
        for (uav, decision) in decisions.iter().enumerate() {
            self.world.set_yaw_ref(uav, decision.yaw_ref);
        }
        Ok(decisions)
    }

    /// The world moves on by one step (cars and UAVs, toward their yaw references).
    pub fn advance(&mut self) {
        self.world.advance();
    }

    /// One guidance round in token order at the current state, with `params`: each UAV
    /// decides ([`guidance::decide`]) around the plans of the UAVs before it (after
    /// `extra`); returns the decisions, by UAV. Nothing is flown.
    pub fn plan_round(
        &self,
        params: &GuidanceParams,
        extra: &[PlannedView],
    ) -> Result<Vec<Decision>, FleetStepError> {
        let mut token: Vec<PlannedView> = extra.to_vec();
        let mut decisions = Vec::with_capacity(self.uav_count());
        // Every UAV is live in process: the round's fleet is all of them.
        let fleet: Vec<u32> = (0..self.uav_count() as u32).collect();
        for (uav, estimator) in self.estimators.iter().enumerate() {
            let state = PlanningState::of(uav, estimator)?;
            let decision = guidance::decide(params, &state.input(uav as u32, &token, &fleet));
            token.push(decision.view.clone());
            decisions.push(decision);
        }
        Ok(decisions)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two UAVs over a small region with a small camera, guided by the scenario's planner.
    fn small() -> (Scenario, FleetOptions) {
        let scenario = Scenario::load(
            None,
            &[
                "region.half_extent_m=50".to_owned(),
                "uavs.count=2".to_owned(),
                "targets.count=3".to_owned(),
                "camera.rows=60".to_owned(),
                "camera.cols=80".to_owned(),
            ],
        )
        .expect("scenario");
        let options = FleetOptions {
            steering: Steering::Guided(Box::new(GuidanceParams::from_scenario(&scenario))),
            ..FleetOptions::default()
        };
        (scenario, options)
    }

    /// Everything a fleet holds after `steps` steps that the results depend on: each UAV's
    /// last message, its sets' digest and its pose.
    fn outcome(fleet: &Fleet) -> Vec<(Vec<u8>, u64, Option<[u64; 4]>)> {
        fleet
            .messages()
            .iter()
            .zip(fleet.estimators())
            .map(|(message, e)| {
                let st = e.state();
                let pose = st
                    .pose
                    .map(|p| [p.position.x, p.position.y, p.position.z, p.yaw].map(f64::to_bits));
                (message.clone(), st.undetected.cells().digest(), pose)
            })
            .collect()
    }

    /// The same scenario flown twice gives the same messages, sets and poses, bit for bit,
    /// whether the steps are run whole or phase by phase.
    #[test]
    fn a_fleet_flies_the_same_twice_whole_steps_or_phases() {
        let (scenario, options) = small();
        let steps = 9;
        let mut whole = Fleet::new(&scenario, options.clone()).expect("fleet");
        let mut rounds = 0;
        for _ in 0..steps {
            rounds += usize::from(!whole.step().expect("step").decisions.is_empty());
        }
        assert!(rounds > 1, "the run has guidance rounds");
        let mut phased = Fleet::new(&scenario, options).expect("fleet");
        let (mut sensed, mut fused) = (0, 0);
        for _ in 0..steps {
            let mut sample = phased.sample();
            phased.sense(&mut sample, |_| sensed += 1).expect("sense");
            phased.share(&mut sample, |_| fused += 1).expect("share");
            phased.steer().expect("steer");
            phased.advance();
        }
        assert_eq!((sensed, fused), (2 * steps, 2 * steps));
        assert_eq!(outcome(&whole), outcome(&phased));
        assert!(whole.messages().iter().all(|m| !m.is_empty()));
    }

    /// Without exchange and with manual steering, nothing is sent and the yaw references are
    /// the caller's; a plan needs a folded frame.
    #[test]
    fn a_manual_fleet_without_exchange_sends_nothing() {
        let (scenario, _) = small();
        let options = FleetOptions {
            exchange: false,
            ..FleetOptions::default()
        };
        let mut fleet = Fleet::new(&scenario, options).expect("fleet");
        let params = GuidanceParams::from_scenario(&scenario);
        assert!(matches!(
            fleet.plan_round(&params, &[]),
            Err(FleetStepError::NoPose { uav: 0, step: 0 })
        ));
        for _ in 0..3 {
            let sample = fleet.step().expect("step");
            assert!(sample.message_bytes.is_empty() && sample.decisions.is_empty());
            assert_eq!(sample.step_time.len(), 2);
        }
        assert!(fleet.messages().iter().all(Vec::is_empty));
        assert!(!fleet.is_guidance_step());
        assert_eq!(fleet.plan_round(&params, &[]).expect("round").len(), 2);
    }
}
