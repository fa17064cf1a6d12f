//! The episode's run: steps, guidance rounds with the learners' requests, measurement.

use std::collections::{BTreeMap, BTreeSet};

use fleet_observe::observe::{Measurer, StepMetrics};
use fleet_observe::results::timeseries;
use protocol::plan::{Answer, FLAG_ROUND_START, Steer};
use protocol::scenario::{Exchange, ExternalRequest, Scenario};
use protocol::wire::{PlannedView, TruthState, WireKind};
use sim::{Fleet, FleetOptions, PlanningState, Steering};
use uav_agent::guidance::external::{self, Request};
use uav_agent::guidance::{Decision, GuidanceParams};

use crate::{EpisodeError, EpisodeSpec};

/// The run tag of an episode's frames and requests (a process run's is its id's hash).
const RUN_TAG: u64 = 1;

/// A learning UAV's request, waiting for its answer.
#[derive(Clone, Debug, PartialEq)]
pub struct PendingRequest {
    /// The asking UAV.
    pub uav: u32,
    /// The deciding step.
    pub step: u64,
    /// The request's bytes, as an agent sends them (`protocol::plan`).
    pub bytes: Vec<u8>,
}

/// What the learners' decisions came to, over the episode.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EpisodeCounts {
    /// Requests made.
    pub asked: u64,
    /// Decisions taken from an answer.
    pub answered: u64,
    /// Of those, answers that deferred to the UAV's own planner ([`Steer::Defer`]).
    pub deferred: u64,
    /// Answers refused (they did not decode, or were for another step or UAV): the UAV's own
    /// planner decided.
    pub malformed: u64,
}

/// A guidance round under way: the UAVs decide in token order (ascending ids: every UAV is
/// live in process), the learners from their answers.
struct Round {
    /// Its step.
    step: u64,
    /// Its number.
    number: u64,
    /// The next UAV to decide.
    next: u32,
    /// The plans passed on so far, in token order.
    token: Vec<PlannedView>,
    /// Each UAV's yaw reference, once decided.
    yaw_refs: Vec<f64>,
    /// The learners asked this round, by UAV: their answers once given.
    asked: BTreeMap<u32, Option<Answer>>,
}

/// One run of the fleet in one process, its learning UAVs asking the caller (see the crate
/// docs).
pub struct Episode {
    scenario: Scenario,
    fleet: Fleet,
    params: GuidanceParams,
    learners: BTreeSet<u32>,
    /// Every UAV, ascending: the fleet of each round (every UAV is live in process).
    uavs: Vec<u32>,
    round_start: bool,
    total_steps: u64,
    measurer: Measurer,
    measured_kind: WireKind,
    truth: Box<TruthState>,
    round: Option<Round>,
    pending: Vec<PendingRequest>,
    counts: EpisodeCounts,
    finished: bool,
}

impl Episode {
    /// The run `spec` describes, at its step 0 (nothing rendered yet).
    pub fn new(spec: &EpisodeSpec) -> Result<Episode, EpisodeError> {
        Episode::of_scenario(spec.scenario()?)
    }

    /// The run of a resolved scenario; its learners are the UAVs it says ask an external
    /// planner ([`Scenario::asks_external`]).
    pub fn of_scenario(scenario: Scenario) -> Result<Episode, EpisodeError> {
        let options = FleetOptions {
            run_tag: RUN_TAG,
            exchange: true,
            oem_full_every: None,
            steering: Steering::Manual,
            // The observers read the agents' state messages under the measurement exchange,
            // their estimates under the sets exchange.
            states: scenario.comms.exchange == Exchange::Measurements,
        };
        let fleet = Fleet::new(&scenario, options)?;
        let n = fleet.uav_count() as u32;
        Ok(Episode {
            params: GuidanceParams::from_scenario(&scenario),
            learners: (0..n).filter(|&u| scenario.asks_external(u)).collect(),
            uavs: (0..n).collect(),
            round_start: scenario.guidance.external_request == ExternalRequest::RoundStart,
            total_steps: scenario.steps(),
            measurer: Measurer::new(&scenario),
            measured_kind: Measurer::measured_kind(&scenario),
            truth: Box::default(),
            round: None,
            pending: Vec::new(),
            counts: EpisodeCounts::default(),
            finished: false,
            fleet,
            scenario,
        })
    }

    /// The scenario the episode runs.
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// The fleet (its world, its estimators).
    pub fn fleet(&self) -> &Fleet {
        &self.fleet
    }

    /// The UAVs whose decisions the caller takes.
    pub fn learners(&self) -> &BTreeSet<u32> {
        &self.learners
    }

    /// Steps until a learning UAV asks for a decision ([`Episode::pending`]: `Ok(true)`) or the
    /// run has taken its last step (`Ok(false)`). Each step renders every UAV's frame, folds it,
    /// exchanges and fuses the estimates, measures the step, and on a guidance step lets the
    /// UAVs decide in token order; a learner's turn waits for its answer. Every pending request
    /// must be answered first.
    pub fn run(&mut self) -> Result<bool, EpisodeError> {
        if let Some(unanswered) = self.pending.first() {
            return Err(EpisodeError::Unanswered(unanswered.uav));
        }
        loop {
            if self.finished {
                return Ok(false);
            }
            if self.round.is_some() {
                if self.continue_round()? {
                    return Ok(true);
                }
                continue;
            }
            let k = self.fleet.world().step();
            if k >= self.total_steps {
                self.finished = true;
                continue;
            }
            self.sense_and_measure()?;
            if k.is_multiple_of(u64::from(self.params.steps_per_period.max(1))) {
                self.round = Some(Round {
                    step: k,
                    number: k / u64::from(self.params.steps_per_period.max(1)),
                    next: 0,
                    token: Vec::new(),
                    yaw_refs: vec![f64::NAN; self.fleet.uav_count()],
                    asked: BTreeMap::new(),
                });
                if self.round_start {
                    self.ask_at_round_start();
                    if !self.pending.is_empty() {
                        return Ok(true);
                    }
                }
            } else {
                self.fleet.advance();
            }
        }
    }

    /// The requests waiting for an answer (in token order).
    pub fn pending(&self) -> &[PendingRequest] {
        &self.pending
    }

    /// Answers `uav`'s pending request with an answer's bytes. Bytes that do not decode as an
    /// answer to that request are refused as an agent refuses them: the UAV's own planner
    /// decides ([`EpisodeCounts::malformed`]).
    pub fn answer(&mut self, uav: u32, bytes: &[u8]) -> Result<(), EpisodeError> {
        let at = self
            .pending
            .iter()
            .position(|p| p.uav == uav)
            .ok_or(EpisodeError::NotAsked(uav))?;
        let request = self.pending.remove(at);
        let answer = Answer::decode(bytes, request.step, uav).ok();
        match &answer {
            Some(a) => {
                self.counts.answered += 1;
                self.counts.deferred += u64::from(a.steer == Steer::Defer);
            }
            None => self.counts.malformed += 1,
        }
        if let Some(round) = &mut self.round {
            round.asked.insert(uav, answer);
        }
        Ok(())
    }

    /// Whether the run has taken its last step.
    pub fn finished(&self) -> bool {
        self.finished
    }

    /// The metrics of every step measured so far.
    pub fn series(&self) -> &[StepMetrics] {
        self.measurer.series()
    }

    /// `timeseries.csv` of the steps measured so far: the text `fleet run` writes.
    pub fn timeseries_csv(&self) -> String {
        timeseries::to_csv(self.measurer.series())
    }

    /// Guarantee violations over the steps measured so far.
    pub fn violations(&self) -> u64 {
        self.series().iter().map(|m| u64::from(m.violations)).sum()
    }

    /// What the learners' decisions came to.
    pub fn counts(&self) -> EpisodeCounts {
        self.counts
    }

    /// Renders, folds, exchanges and fuses the current step, then measures it as the observer
    /// does: from each UAV's message to the observers and the world's truth.
    fn sense_and_measure(&mut self) -> Result<(), EpisodeError> {
        let mut sample = self.fleet.sample();
        self.fleet.sense(&mut sample, |_| {})?;
        self.fleet.share(&mut sample, |_| {})?;
        let measured = match self.measured_kind {
            WireKind::State => self.fleet.states(),
            _ => self.fleet.messages(),
        };
        for (uav, bytes) in measured.iter().enumerate() {
            self.measurer.receive(uav as u32, self.measured_kind, bytes);
        }
        self.fleet.world().truth(RUN_TAG, &mut self.truth);
        self.measurer.measure(&self.truth);
        Ok(())
    }

    /// The request of learner `uav` at the round's current state: at the round's start (no
    /// plans ahead) or in its turn (the plans passed on so far).
    fn request(&self, round: &Round, uav: u32, at_start: bool) -> PendingRequest {
        let state = self.fleet.estimators()[uav as usize].state();
        let hidden = state.hidden_history.recently_hidden();
        let (others, flags): (&[PlannedView], u32) = match at_start {
            true => (&[], FLAG_ROUND_START),
            false => (&round.token, 0),
        };
        let request = Request {
            header: Request::header_at(
                &self.scenario,
                &self.params,
                state,
                RUN_TAG,
                uav,
                round.number,
                round.step,
                flags,
            ),
            grids: &self.params.grids,
            increments: &self.params.increments,
            state,
            recently_hidden: &hidden,
            others,
            fleet: &self.uavs,
        };
        PendingRequest {
            uav,
            step: round.step,
            bytes: request.to_bytes(),
        }
    }

    /// Asks every learner at the round's start (`guidance.external_request =
    /// "round_start"`).
    fn ask_at_round_start(&mut self) {
        let round = self.round.take().expect("a round under way");
        for &uav in &self.learners {
            let request = self.request(&round, uav, true);
            self.pending.push(request);
            self.counts.asked += 1;
        }
        self.round = Some(round);
    }

    /// Lets the round's UAVs decide in turn until a learner's turn needs its answer
    /// (`Ok(true)`: its request is pending) or every UAV decided: then each flies its decision
    /// and the world moves on (`Ok(false)`).
    fn continue_round(&mut self) -> Result<bool, EpisodeError> {
        let mut round = self.round.take().expect("a round under way");
        while (round.next as usize) < self.uavs.len() {
            let uav = round.next;
            let answer = match self.learners.contains(&uav) {
                false => None,
                true => match round.asked.get_mut(&uav) {
                    Some(answer) => answer.take(),
                    None => {
                        let request = self.request(&round, uav, false);
                        self.pending.push(request);
                        self.counts.asked += 1;
                        round.asked.insert(uav, None);
                        self.round = Some(round);
                        return Ok(true);
                    }
                },
            };
            let decision = self.decide(&round, uav, answer)?;
            round.yaw_refs[uav as usize] = decision.yaw_ref;
            round.token.push(decision.view);
            round.next += 1;
        }
        for (uav, yaw_ref) in round.yaw_refs.iter().enumerate() {
            self.fleet.world_mut().set_yaw_ref(uav, *yaw_ref);
        }
        self.fleet.advance();
        Ok(false)
    }

    /// UAV `uav`'s decision in its turn: from its answer, or by its own planner.
    fn decide(
        &self,
        round: &Round,
        uav: u32,
        answer: Option<Answer>,
    ) -> Result<Decision, EpisodeError> {
        let estimator = &self.fleet.estimators()[uav as usize];
        let state = PlanningState::of(uav as usize, estimator)?;
        let input = state.input(uav, &round.token, &self.uavs);
        Ok(external::decision(answer, &self.params, &input))
    }
}
