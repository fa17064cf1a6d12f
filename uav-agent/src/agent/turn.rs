//! The agent's turns in the guidance ring ([`GuidanceTurn`]), step 4 of [`super`]'s loop.
//!
//! It owns what a turn reads and leaves behind: the planner's parameters, the token ring
//! ([`crate::guidance::ring`]), and the external planner this agent asks, if any, with the
//! request sent at the round's start (`guidance.external_request = "round_start"`) whose answer
//! the turn takes. Tokens come through the same simulated radio as the estimates: one lost or
//! out of range is taken as its sender having passed the turn with a plan this agent will not
//! see ([`TokenRing::receive`]). Only a turn reads and changes the ring and the planner, so they
//! are one part; the ports, the waits and the counters it uses are the process's
//! ([`super::process`]), and whom it waits for is liveness's ([`super::liveness`]).

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use estimator::{Estimator, EstimatorState};
use protocol::codec;
use protocol::flight::UavState;
use protocol::plan::{Answer, FLAG_ROUND_START, RequestHeader};
use protocol::radio::{Endpoint, Radio};
use protocol::scenario::ExternalRequest;
use protocol::wire::{DropReason, GuidanceToken, PlannedView, WireKind};
use sets::raster::CellSet;

use super::config::AgentConfig;
use super::error::AgentError;
use super::liveness::Presence;
use super::phase;
use super::process::{Process, WAIT_SLICE};
use crate::guidance::external::{self, Asked, ExternalPlanner, ExternalReport, Fallback, Request};
use crate::guidance::{GuidanceParams, ObstacleCell, PlanningInput, TokenRing, Turn};

/// How long an agent that asks an external planner waits for one to serve it before its first
/// hello: well within the world's start wait, so a planner started with the run answers from
/// the first decision.
const PLANNER_START_WAIT: Duration = Duration::from_secs(20);

/// What a turn uses and does not own: the process (its ports, waits, clock and counters),
/// whom the agent awaits and knows live, and its estimate (the turn plans from it and judges
/// the tokens' range from its pose).
pub(super) struct TurnContext<'p, 'a> {
    /// The agent process.
    pub(super) process: &'p mut Process<'a>,
    /// Whom the agent awaits and knows live.
    pub(super) presence: &'p mut Presence,
    /// The agent's estimate.
    pub(super) estimator: &'p Estimator,
}

/// The agent's part in the guidance: its planner, its place in the ring, its external planner.
pub(super) struct GuidanceTurn {
    /// The planner's parameters.
    params: GuidanceParams,
    /// The token ring.
    ring: TokenRing,
    /// The simulated links the tokens cross ([`protocol::radio`]).
    radio: Radio,
    /// The external planner this agent asks for its decisions, if it asks one.
    external: Option<ExternalPlanner>,
    /// The request of the current round sent at its start (`guidance.external_request =
    /// "round_start"`), whose answer the agent's turn takes.
    asked: Option<Asked>,
}

impl GuidanceTurn {
    /// The turns of agent `config.uav`, its tokens over `radio`, asking `external` if given.
    pub(super) fn new(
        config: &AgentConfig,
        radio: Radio,
        external: Option<ExternalPlanner>,
    ) -> Self {
        GuidanceTurn {
            params: GuidanceParams::from_scenario(&config.scenario),
            ring: TokenRing::new(config.uav, config.scenario.comms.liveness),
            radio,
            external,
            asked: None,
        }
    }

    /// Whether step `k` starts a guidance round (a decision every guidance period).
    pub(super) fn is_guidance_step(&self, k: u64) -> bool {
        k.is_multiple_of(self.params.steps_per_period as u64)
    }

    /// What the external planner did, for an agent that asks one.
    pub(super) fn external_report(&self) -> Option<ExternalReport> {
        self.external.as_ref().map(ExternalPlanner::report)
    }

    /// Reads every pending token into the ring; the radio decides, from this agent's
    /// estimator state, which ones it carried.
    pub(super) fn drain_tokens(&mut self, process: &mut Process<'_>, estimator: &Estimator) {
        loop {
            let sample = match process.links.token_in.receive() {
                Ok(Some(s)) => s,
                Ok(None) => return,
                Err(e) => {
                    tracing::warn!(error = ?e, "token receive failed");
                    return;
                }
            };
            let header = *sample.user_header();
            if let Err(reason) = header.check(
                sample.payload().len(),
                WireKind::Token,
                process.run_tag,
                None,
            ) {
                drop(sample);
                let detail = format!("from UAV {}", header.sender);
                process.counters.drop_message(reason, "token", &detail);
                continue;
            }
            let parsed: Result<GuidanceToken, _> = codec::decode(sample.payload());
            drop(sample);
            match parsed {
                Ok(token) => {
                    let sender = Endpoint {
                        uav: header.sender,
                        step: header.step,
                        pose: token.pose,
                    };
                    let receiver = token_receiver(process.uav(), estimator.state());
                    let delivered = self.radio.carries_token(&receiver, &sender);
                    if !delivered {
                        process.counters.shared.tokens_lost += 1;
                        tracing::debug!(
                            round = token.round,
                            sender = sender.uav,
                            "token lost by the radio or out of range"
                        );
                    }
                    self.ring.receive(token, sender.uav, delivered);
                }
                Err(e) => {
                    process
                        .counters
                        .drop_message(DropReason::Malformed, "token", &e.to_string());
                }
            }
        }
    }

    /// Takes this agent's turn in the ring for the round starting at step `k`; returns the
    /// yaw reference to send. Each holder gets one bounded wait (`token_wait`), started when
    /// it becomes the holder this agent waits for; a holder silent for longer is skipped for
    /// the rest of the round and the next one gets a fresh wait.
    pub(super) fn decide(
        &mut self,
        k: u64,
        ctx: &mut TurnContext<'_, '_>,
    ) -> Result<Option<f64>, AgentError> {
        let round = k / self.params.steps_per_period as u64;
        let mut waiting_for: Option<(u32, Instant)> = None;
        let mut waited_out = false;
        self.asked = None;
        if ctx.process.config.scenario.guidance.external_request == ExternalRequest::RoundStart {
            self.ask_at_round_start(round, k, ctx);
        }
        loop {
            self.drain_tokens(ctx.process, ctx.estimator);
            let live = ctx.presence.ring_live();
            match self.ring.turn(round, &live) {
                Turn::Done => return Ok(None),
                Turn::Decide { others } => {
                    #[cfg(feature = "test-hooks")]
                    if !ctx.process.config.hold_token.is_zero() {
                        let hold = ctx.process.config.hold_token;
                        tracing::info!(round, ?hold, "holding the token");
                        std::thread::sleep(hold);
                    }
                    if waited_out {
                        ctx.process.counters.shared.token_timeouts += 1;
                    }
                    let before = ctx.process.clock.enter(phase::PLAN);
                    let planned = self.plan_and_pass(round, k, &live, &others, ctx);
                    ctx.process.clock.enter(before);
                    return planned.map(Some);
                }
                Turn::Wait { holder } => {
                    if ctx.process.leaving() {
                        return Ok(None);
                    }
                    // A UAV heard at the step (the radio's reading) whose process died since,
                    // or that the world no longer serves, sends no token: give up on it at
                    // once. (Under the world's reading the holder is one of these peers.)
                    if !ctx.presence.awaited().contains(&holder) {
                        tracing::debug!(round, holder, "token holder gone: skipping it");
                        self.ring.holder_silent(round, holder);
                        continue;
                    }
                    let deadline = match waiting_for {
                        Some((h, deadline)) if h == holder => deadline,
                        _ => {
                            let deadline =
                                Instant::now() + ctx.process.config.timeouts.holder_wait();
                            waiting_for = Some((holder, deadline));
                            deadline
                        }
                    };
                    if Instant::now() >= deadline {
                        waited_out = true;
                        tracing::warn!(
                            round,
                            holder,
                            "token holder silent: skipping it this round"
                        );
                        self.ring.holder_silent(round, holder);
                        continue;
                    }
                    let process = &mut *ctx.process;
                    process.wait(deadline.min(Instant::now() + WAIT_SLICE), phase::WAIT_TOKEN);
                    // The holder may have died meanwhile: a dead holder is skipped within a
                    // wait slice (a listing costs milliseconds: not at every token hop).
                    if ctx.presence.is_alive(holder) {
                        ctx.presence.refresh_if_stale(&mut process.clock);
                    }
                }
            }
        }
    }

    /// Plans this agent's turn of `round` (step `k`) around the plans ahead (`others`) among
    /// the round's `live` UAVs, counts the decision and passes the token; the yaw reference.
    fn plan_and_pass(
        &mut self,
        round: u64,
        k: u64,
        live: &BTreeSet<u32>,
        others: &[PlannedView],
        ctx: &mut TurnContext<'_, '_>,
    ) -> Result<f64, AgentError> {
        let estimator = ctx.estimator;
        let Some(pose) = estimator.state().pose else {
            return Err(AgentError::NoPose(k));
        };
        let fleet = self.ring.fleet(round, live);
        let hidden = estimator.state().hidden_history.recently_hidden();
        let answer = self.ask_external(round, k, &hidden, others, &fleet, ctx);
        let process = &mut *ctx.process;
        let state = estimator.state();
        let sets: Vec<&CellSet> = state.target_sets().collect();
        let obstacles = ObstacleCell::known(&state.oem);
        let input = PlanningInput {
            uav: process.uav(),
            state: UavState {
                position: pose.position,
                yaw: pose.yaw,
            },
            sets: &sets,
            recently_hidden: &hidden,
            unseen: state.hidden_history.unseen(),
            obstacles: &obstacles,
            others,
            fleet: &fleet,
        };
        let decision = external::decision(answer, &self.params, &input);
        process.counters.shared.decisions += 1;
        let mut token = self.ring.pass(round, k, live, decision.view);
        token.pose = Some(pose);
        let bytes = codec::encode(&token)?;
        process.send(WireKind::Token, k, &bytes)?;
        tracing::debug!(
            round,
            yaw_ref = decision.yaw_ref,
            cost = decision.cost.total,
            next = token.holder,
            "decided"
        );
        Ok(decision.yaw_ref)
    }

    /// Waits, before the first hello, for an external planner to serve this agent (at most
    /// [`PLANNER_START_WAIT`]); an agent that asks none goes on at once.
    pub(super) fn await_planner(&mut self, process: &mut Process<'_>) {
        let Some(planner) = &self.external else {
            return;
        };
        let until = Instant::now() + PLANNER_START_WAIT;
        if planner.has_server() {
            return;
        }
        let uav = process.uav();
        tracing::info!(uav, "waiting for an external planner to serve this UAV");
        while Instant::now() < until && !process.stopping() {
            if self
                .external
                .as_ref()
                .is_some_and(ExternalPlanner::has_server)
            {
                tracing::info!(uav, "external planner connected");
                return;
            }
            process.wait(Instant::now() + WAIT_SLICE, phase::WAIT_PLANNER);
        }
        tracing::warn!(
            uav,
            waited = ?PLANNER_START_WAIT,
            "no external planner came: the fallback planner decides until one does"
        );
    }

    /// The scalar fields of this agent's request at step `k` of `round`, from `state`.
    fn request_header(
        &self,
        round: u64,
        k: u64,
        flags: u32,
        process: &Process<'_>,
        state: &EstimatorState,
    ) -> RequestHeader {
        Request::header_at(
            &process.config.scenario,
            &self.params,
            state,
            process.run_tag,
            process.uav(),
            round,
            k,
            flags,
        )
    }

    /// The external planner's answer for this turn, if this agent asks one and a valid
    /// answer came in time (the request sent at the round's start, or one sent now with
    /// `recently_hidden`, the plans ahead and the round's fleet); counts the decision or the
    /// fallback.
    fn ask_external(
        &mut self,
        round: u64,
        k: u64,
        recently_hidden: &CellSet,
        others: &[PlannedView],
        fleet: &[u32],
        ctx: &mut TurnContext<'_, '_>,
    ) -> Option<Answer> {
        let mut planner = self.external.take()?;
        let state = ctx.estimator.state();
        let asked = match self.asked.take() {
            Some(asked) => Ok(asked),
            None => planner.ask(&Request {
                header: self.request_header(round, k, 0, ctx.process, state),
                grids: &self.params.grids,
                increments: &self.params.increments,
                state,
                recently_hidden,
                others,
                fleet,
            }),
        };
        let answer = asked.and_then(|asked| await_answer(&mut planner, &asked, ctx));
        let counters = &mut ctx.process.counters.shared;
        match &answer {
            Ok(answer) => {
                planner.answered(answer);
                counters.external_decisions += 1;
            }
            Err(why) => {
                planner.fell_back(*why, k);
                counters.external_fallbacks += 1;
            }
        }
        self.external = Some(planner);
        answer.ok()
    }

    /// Sends the round's request before the token comes (`"round_start"`), without the plans
    /// ahead; the agent's turn takes its answer.
    fn ask_at_round_start(&mut self, round: u64, k: u64, ctx: &TurnContext<'_, '_>) {
        let Some(mut planner) = self.external.take() else {
            return;
        };
        let fleet = self.ring.fleet(round, &ctx.presence.ring_live());
        let state = ctx.estimator.state();
        let hidden = state.hidden_history.recently_hidden();
        let asked = planner.ask(&Request {
            header: self.request_header(round, k, FLAG_ROUND_START, ctx.process, state),
            grids: &self.params.grids,
            increments: &self.params.increments,
            state,
            recently_hidden: &hidden,
            others: &[],
            fleet: &fleet,
        });
        // Without a planner now, the turn asks again (and falls back if there is still none).
        self.asked = asked.ok();
        self.external = Some(planner);
    }
}

/// Agent `uav` as the receiving end of a token: its current step and pose (from `state`). In
/// lockstep a token of step `k` is read at step `k` (see [`protocol::radio`]); a token read at
/// another step (a late or stalled agent, or realtime stepping) is judged from the pose the
/// agent has.
fn token_receiver(uav: u32, state: &EstimatorState) -> Endpoint {
    Endpoint {
        uav,
        step: state.step,
        pose: state.pose,
    }
}

/// Waits for the answer to `asked`, at most `timing.external_planner_ms` from now; a
/// planner that died is noticed at the next listing of the run's nodes, which cleans its
/// node and with it its server.
fn await_answer(
    planner: &mut ExternalPlanner,
    asked: &Asked,
    ctx: &mut TurnContext<'_, '_>,
) -> Result<Answer, Fallback> {
    let TurnContext {
        process, presence, ..
    } = ctx;
    let deadline = Instant::now() + process.config.timeouts.planner;
    loop {
        if let Some(answer) = planner.poll(asked) {
            return answer;
        }
        if Instant::now() >= deadline || process.leaving() {
            return Err(Fallback::Late);
        }
        process.wait(
            deadline.min(Instant::now() + WAIT_SLICE),
            phase::WAIT_PLANNER,
        );
        presence.refresh_if_stale(&mut process.clock);
    }
}
