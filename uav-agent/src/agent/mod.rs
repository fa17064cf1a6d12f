//! The agent process's loop: one UAV of a run, over iceoryx2.
//!
//! Per frame `k` (docs/design.md §3 "Estimator step" and §4):
//! 1. the estimator folds the frame in (predict, correct);
//! 2. the agent publishes its estimate on `{run}/uav/{i}/estimate`: its corrected sets
//!    (`comms.exchange = "sets"`), or its frame's measurement (`"measurements"`,
//!    [`estimator::exchange`]) with its whole sets for a peer that joined late or
//!    asked, in its first message when it resumed from a checkpoint, and every
//!    `comms.whole_sets_every` messages on lossy or range-limited links; with
//!    `comms.relay_hops` it also forwards the peers' measurements it applied at the last step;
//! 3. it gathers the live peers' step-`k` estimates (a bounded wait; late ones are taken in
//!    when they come) and, once the wait is over, takes them in by ascending peer: it applies
//!    their measurements (late ones at their own clock) and fuses their sets (dilated by the
//!    steps they lag; whole sets of the measurement exchange wait encoded and are rebuilt one
//!    at a time then), then the measurements they forward that it has not applied yet. Under
//!    the measurement exchange it then sends the observers its sets (a
//!    [`WireKind::State`](protocol::wire::WireKind::State) message on its estimate service,
//!    which peers skip unread);
//! 4. on a guidance step it takes its turn in the token ring ([`crate::guidance::ring`]) and
//!    runs the planner the scenario names ([`crate::guidance::decide`]: the paper's MPC or
//!    `setfleet`);
//! 5. it acks step `k` to the world: with its yaw reference after deciding on a guidance
//!    step; on any other step as soon as its estimate is out (before 3), since nothing it
//!    does after that changes what the world does, so the world renders frame `k + 1` while
//!    the agents exchange and fuse step `k`. The next frame waits in the agent's buffer
//!    until the step is done, so every estimator step still folds the same fused state.
//!
//! Every wait is bounded, by the run's [`Timeouts`]. An agent awaits the estimates of the peers
//! the world serves at that step (the frame's `served` mask, the same for every agent) whose
//! iceoryx2 node is alive (a SIGKILLed peer shows up dead at once and its resources are
//! cleaned), whatever the radio then does with them: only once every message of the step is in
//! does what it fuses not depend on timing.
//! Listing the nodes costs milliseconds of CPU, so it is done when the served mask names a
//! peer not known alive, and while waiting at most once per `liveness_scan_period` (250 ms per
//! 4 UAVs of the fleet), not at every step and every wake-up (the world drops a peer that died
//! before the step from the mask). The world-server is presumed lost when no frame came for `world_timeout` (before the first
//! frame, that and the world's start wait) and its node is gone, and the agent exits with an
//! error. Only SIGINT and SIGTERM stop an agent: a stalled agent
//! (SIGSTOP, swapped out) resumes where it was; if the world stopped serving it meanwhile,
//! its late ack, or the hello it repeats while no frame comes, brings it back from the next
//! frame.
//!
//! With a checkpoint file ([`checkpoint`]), the agent saves its estimator state after every
//! [`AgentConfig::checkpoint_every`]-th step it acked, and a restarted agent (same id) resumes
//! from it, grown by the motion since;
//! without one it starts from the full region. Either way it then fuses its peers' estimates;
//! peers that see a new incarnation send it their whole map and whole sets. Sets travel as
//! deltas against the previous message ([`estimator::message`]); a peer's estimate that cannot
//! be rebuilt (a missed message) is dropped, not awaited, and whole sets are asked of its
//! sender.
//!
//! The radio between agents is simulated by the receiver ([`protocol::radio`]): every estimate and
//! token crosses the IPC, and the receiving agent decides from the scenario's seed whether the
//! radio lost it (`comms.loss`), when it arrives (`comms.latency_ms`) and whether its sender
//! was in range (`comms.range_m`; for tokens unless `comms.token_range = "unlimited"`). A lost
//! estimate is not read and not awaited: the agent knows at once that it will not come. A
//! token lost or out of range is taken as its sender having passed the turn with a plan this
//! agent will not see: the ring skips it at once, as it does a holder whose wait ran out
//! ([`crate::guidance::TokenRing::receive`]), so a lossy run waits for nothing it will not get
//! and stays reproducible. A token carries its sender's pose for the radio to judge; in
//! lockstep a receiver reads it at the token's step, the pose it judges from its own. With loss,
//! estimates carry whole sets, never deltas: a delta against a lost message could not be
//! rebuilt, and each later one of the chain would fail until whole sets came (the map keeps
//! its deltas: they only add knowledge, see [`estimator::message`]). An estimate of step `k`
//! is fused at step `k + d` (`d` the latency in steps), dilated by `d` steps; the agent still
//! awaits (bounded) every peer's step-`k` message at step `k`, so what it fuses at each step
//! does not depend on timing.
//!
//! What an agent knows of its peers comes only through what the radio carried to it
//! (`comms.liveness = "radio"`, the default; `agent/liveness.rs`): the UAVs it knows live at a
//! step are the peers whose estimate it fused then, and the plans it plans around are those of
//! the tokens it read (its predecessors' in the ring, [`crate::guidance::ring`]), which carry
//! only what their senders read in turn. So with a finite range neither liveness nor plans of a
//! UAV out of range reach an agent except relayed by a UAV in range, and the `setfleet`
//! planner's range charge and lanes count only those. The frame's `served` mask and the node
//! list still end the agent's waits (they say a message will never be sent: a peer the world
//! does not serve sends no estimate, a dead holder no token) but never make a UAV live to it.
//! `comms.liveness = "world"` gives the ring the served, alive peers instead, the same for
//! every agent (the behaviour before the key).
//!
//! # Parts
//!
//! The loop ([`run`]) composes parts that each own one concept of the agent, and passes each
//! step the parts it uses explicitly:
//!
//! | part | module | owns |
//! |---|---|---|
//! | `Process` | `agent/process.rs` | who the agent is (its [`AgentConfig`], the run's tag, its incarnation), its ports and waits, its phase clock and its [`AgentCounters`] |
//! | `PeerExchange` | `agent/exchange.rs` | steps 2 and 3: the outboxes, the measurement and what it relays, the inbox, each peer's queue, what the radio lost |
//! | `Presence` | `agent/liveness.rs` | whom the agent awaits (the world's mask, the node list) and whom it knows live (`comms.liveness`) |
//! | `GuidanceTurn` | `agent/turn.rs` | step 4: the planner's parameters, the token ring, the external planner |
//! | `Checkpoints` | [`checkpoint`] | the checkpoint file, its flushing thread, when to save |
//!
//! The estimator itself sits beside them: every step reads it and most change it. The agent's
//! report at exit ([`AgentReport`]) gathers what the parts counted; the counters its estimates
//! carry are one record, [`protocol::wire::AgentStats`] ([`AgentCounters::shared`]).

pub mod checkpoint;
mod config;
mod error;
mod exchange;
mod links;
mod liveness;
pub mod phase;
mod process;
mod report;
mod turn;

use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use estimator::{Estimator, EstimatorConfig, EstimatorStepError, StepReport};
use fleet_process::resources::own_peak_rss_kb;
use iceoryx2::prelude::SignalHandlingMode;
use protocol::frame::CvsFrame;
use protocol::ipc::{IpcOpenError, RunNode, scan_nodes};
use protocol::radio::Radio;
use protocol::timeouts::Timeouts;
use protocol::wire::{HELLO_STEP, unix_now_ns};

use crate::guidance::external::ExternalPlanner;
use checkpoint::Checkpoints;
pub use config::{AgentConfig, DEFAULT_CHECKPOINT_EVERY};
pub use error::{AgentError, AgentStartError};
use exchange::PeerExchange;
use links::{LinkError, Links};
use liveness::Presence;
use process::{Process, WAIT_SLICE};
pub use report::{AgentCounters, AgentReport, EndReason};
use turn::{GuidanceTurn, TurnContext};

/// Runs agent `config.uav` until the run ends, the shutdown flag is set or the world is lost.
pub fn run(config: AgentConfig, shutdown: &AtomicBool) -> Result<AgentReport, AgentError> {
    let name = RunNode::agent_name(config.uav);
    check_start(&config, &name)?;
    let node = RunNode::new(
        &config.run_id,
        &name,
        SignalHandlingMode::HandleTerminationRequests,
    )?;
    let links = Links::open(&node, config.uav, config.scenario.uavs.count)?;
    let external = if config.scenario.asks_external(config.uav) {
        Some(ExternalPlanner::open(&node, config.uav)?)
    } else {
        None
    };
    let waitset = node.waitset()?;
    let _guard = waitset
        .attach_notification(&links.wake)
        .map_err(IpcOpenError::from)?;
    let estimator_config = EstimatorConfig::from_scenario(&config.scenario);
    let radio = Radio::from_scenario(&config.scenario);
    let incarnation = incarnation();
    let (checkpoints, estimator) = Checkpoints::open(&config, &estimator_config);
    let resumed = checkpoints.resumed_from().is_some();
    let mut agent = Agent {
        exchange: PeerExchange::new(&config, &estimator_config, incarnation, radio, resumed),
        estimator,
        checkpoints,
        turn: GuidanceTurn::new(&config, radio, external),
        presence: Presence::new(&config),
        world: WorldWatch::new(),
        process: Process::new(&config, incarnation, &links, &waitset, shutdown),
    };
    agent.turn.await_planner(&mut agent.process);
    agent.presence.refresh(&mut agent.process.clock);
    tracing::info!(uav = config.uav, run = %config.run_id, incarnation, "agent started");
    let result = agent.main_loop();
    agent.finish(result)
}

/// Refuses an agent outside the fleet, or whose UAV has a live agent (node `name`) already.
fn check_start(config: &AgentConfig, name: &str) -> Result<(), AgentError> {
    let count = config.scenario.uavs.count;
    if config.uav >= count {
        return Err(AgentStartError::OutsideFleet {
            uav: config.uav,
            count,
        }
        .into());
    }
    let scan = scan_nodes(&config.run_id, true).map_err(AgentStartError::from)?;
    if scan.is_alive(name) {
        return Err(AgentStartError::AlreadyLive {
            uav: config.uav,
            run: config.run_id.to_string(),
        }
        .into());
    }
    Ok(())
}

/// A number that grows at each start of an agent process (the wall clock in nanoseconds), so
/// the world and the peers tell a restarted agent from its predecessor and ignore the latter.
fn incarnation() -> u64 {
    unix_now_ns()
}

/// One agent: the composition of its parts that runs the steps (see the module docs).
struct Agent<'a> {
    /// Who it is, its ports, waits, clock and counters.
    process: Process<'a>,
    /// Its estimator: its sets and map.
    estimator: Estimator,
    /// Whom it awaits and knows live.
    presence: Presence,
    /// The exchange with its peers.
    exchange: PeerExchange,
    /// Its turns in the guidance ring.
    turn: GuidanceTurn,
    /// Its checkpoints.
    checkpoints: Checkpoints,
    /// Whether the world is there: its frames, this agent's hellos.
    world: WorldWatch,
}

/// What a step still owes the world once the agent published its estimate.
enum Ack {
    /// The ack went out early (off a guidance step): nothing.
    Sent,
    /// The ack, with the turn's yaw reference if it decided one.
    Owed {
        /// The yaw reference to send.
        yaw_ref: Option<f64>,
    },
}

/// Whether the world is there, as the frames say: when the last came, and the hellos this
/// agent sends until the first comes and again whenever frames stop coming.
struct WorldWatch {
    /// A frame came since the agent started.
    first_frame: bool,
    /// When the last frame came (the agent's start before the first).
    last_frame: Instant,
    /// When the last hello went out.
    last_hello: Option<Instant>,
}

impl WorldWatch {
    /// No frame and no hello yet.
    fn new() -> Self {
        WorldWatch {
            first_frame: false,
            last_frame: Instant::now(),
            last_hello: None,
        }
    }

    /// Whether to say hello now: until the first frame, every hello interval; then again
    /// whenever frames stop coming, in case the world stopped serving this agent (it was
    /// stalled past the ack wait). A hello from an agent the world serves changes nothing.
    fn hello_due(&self, timeouts: &Timeouts) -> bool {
        if self.first_frame {
            self.last_frame.elapsed() >= timeouts.rehello()
                && self
                    .last_hello
                    .is_none_or(|t| t.elapsed() >= timeouts.rehello())
        } else {
            self.last_hello
                .is_none_or(|t| t.elapsed() >= timeouts.hello_interval())
        }
    }

    /// A hello went out now.
    fn said_hello(&mut self) {
        self.last_hello = Some(Instant::now());
    }

    /// A frame came now.
    fn frame_came(&mut self) {
        self.first_frame = true;
        self.last_frame = Instant::now();
    }

    /// How long without a frame makes the world presumed lost, if that long has passed.
    /// Before the first frame the world may still be waiting out the slowest agents' hellos,
    /// up to its start wait; and a world on another host never shows its node here, so only
    /// frames can tell that it is there.
    fn silent_for(&self, world_timeout: Duration, timeouts: &Timeouts) -> Option<Duration> {
        let lost_after = if self.first_frame {
            world_timeout
        } else {
            world_timeout + timeouts.start()
        };
        (self.last_frame.elapsed() >= lost_after).then_some(lost_after)
    }
}

impl Agent<'_> {
    /// Runs steps until the run ends, the agent is stopped or the world is lost: says hello
    /// when due, folds in the frames that came, takes in the messages, and waits.
    fn main_loop(&mut self) -> Result<EndReason, AgentError> {
        let timeouts = self.process.config.timeouts;
        loop {
            if self.world.hello_due(&timeouts) {
                self.process.send_command(HELLO_STEP, None)?;
                self.world.said_hello();
            }
            let links = self.process.links;
            while let Some(sample) = links.frames.receive().map_err(LinkError::from)? {
                self.world.frame_came();
                self.on_frame(sample.payload())?;
            }
            self.take_in_messages();
            if let Some(end) = self.process.ended() {
                return Ok(end);
            }
            self.check_world(&timeouts)?;
            self.process
                .wait(Instant::now() + WAIT_SLICE, phase::WAIT_FRAME);
        }
    }

    /// Reads what came between steps: the peers' estimates into their queues (fused at the
    /// step that awaits them) and the tokens into the ring.
    fn take_in_messages(&mut self) {
        let before = self.process.clock.enter(phase::FUSE);
        self.exchange
            .drain(&mut self.process, self.estimator.config());
        self.process.clock.enter(before);
        self.turn.drain_tokens(&mut self.process, &self.estimator);
    }

    /// Fails with [`AgentError::WorldLost`] when no frame came for long and the world's node
    /// is gone.
    fn check_world(&mut self, timeouts: &Timeouts) -> Result<(), AgentError> {
        let Some(waited) = self
            .world
            .silent_for(self.process.config.world_timeout, timeouts)
        else {
            return Ok(());
        };
        self.presence.refresh(&mut self.process.clock);
        if self.presence.world_live() {
            return Ok(());
        }
        Err(AgentError::WorldLost {
            run: self.process.config.run_id.to_string(),
            waited,
        })
    }

    /// One frame: folds it in (step 1), then exchanges, decides and acks (steps 2 to 5), and
    /// saves a checkpoint when one is due. A frame of another run or UAV, or one the estimator
    /// refuses, is counted and dropped (a refused one is still acked).
    fn on_frame(&mut self, frame: &CvsFrame) -> Result<(), AgentError> {
        let k = frame.header.step;
        if frame.header.run_tag != self.process.run_tag || frame.header.uav != self.process.uav() {
            self.process.counters.shared.frames_refused += 1;
            tracing::warn!(step = k, "frame of another run or UAV dropped");
            return Ok(());
        }
        // Every token of the rounds before this frame was sent before the world sent it: read
        // them now, so the counters this step's estimate carries do not depend on timing.
        self.turn.drain_tokens(&mut self.process, &self.estimator);
        let guidance_step = self.turn.is_guidance_step(k);
        let before = self.process.clock.enter(phase::ESTIMATE);
        let folded = self.fold(frame);
        self.process.clock.enter(before);
        let ack = match &folded {
            Ok(_) => {
                self.process.counters.shared.frames += 1;
                self.presence.serve(frame.header.served);
                self.exchange_and_decide(k, guidance_step)?
            }
            Err(e) => {
                self.process.counters.shared.frames_refused += 1;
                tracing::warn!(step = k, error = %e, "frame refused");
                Ack::Owed { yaw_ref: None }
            }
        };
        if let Ack::Owed { yaw_ref } = ack {
            self.process.send_command(k, yaw_ref)?;
        }
        if folded.is_ok() && self.checkpoints.due(k) {
            self.checkpoints
                .save(self.estimator.state(), &mut self.process.clock);
        }
        Ok(())
    }

    /// Steps 2 to 5 of a frame `k` folded in: publishes the estimate, acks at once off a
    /// guidance step, gathers and fuses the peers' estimates, sends the observers the sets,
    /// and on a guidance step takes the turn. What is left to ack.
    fn exchange_and_decide(&mut self, k: u64, guidance_step: bool) -> Result<Ack, AgentError> {
        let before = self.process.clock.enter(phase::PUBLISH);
        let published = self
            .exchange
            .publish_estimate(k, &mut self.process, &mut self.estimator);
        self.process.clock.enter(before);
        published?;
        if !guidance_step {
            // Nothing left to tell the world: it may render the next frame now.
            self.process.send_command(k, None)?;
        }
        self.exchange.gather(
            k,
            &mut self.process,
            &mut self.presence,
            &mut self.estimator,
        );
        let before = self.process.clock.enter(phase::PUBLISH);
        let published = self
            .exchange
            .publish_state(k, &mut self.process, &mut self.estimator);
        self.process.clock.enter(before);
        published?;
        if !guidance_step {
            return Ok(Ack::Sent);
        }
        let mut ctx = TurnContext {
            process: &mut self.process,
            presence: &mut self.presence,
            estimator: &self.estimator,
        };
        let yaw_ref = self.turn.decide(k, &mut ctx)?;
        Ok(Ack::Owed { yaw_ref })
    }

    /// Folds a frame into the estimator. A resumed agent whose checkpoint is ahead of the
    /// run's first frame (a checkpoint of a run that was started over) drops it and starts
    /// fresh.
    fn fold(&mut self, frame: &CvsFrame) -> Result<StepReport, EstimatorStepError> {
        match self.exchange.step_estimator(&mut self.estimator, frame) {
            Err(EstimatorStepError::Stale { state_step, .. })
                if self.process.counters.shared.frames == 0
                    && self.checkpoints.resumed_from().is_some() =>
            {
                tracing::warn!(
                    checkpoint_step = state_step,
                    frame_step = frame.header.step,
                    "the checkpoint is ahead of the run: starting fresh"
                );
                self.checkpoints.start_fresh();
                self.estimator = Estimator::new(self.estimator.config().clone());
                self.exchange.step_estimator(&mut self.estimator, frame)
            }
            other => other,
        }
    }

    /// The agent's report once its loop ended with `result`: what it counted, the checkpoint
    /// thread's figures, where the time went and a summary of its last `X̄`.
    fn finish(self, result: Result<EndReason, AgentError>) -> Result<AgentReport, AgentError> {
        let Agent {
            mut process,
            estimator,
            turn,
            checkpoints,
            ..
        } = self;
        let checkpoint = checkpoints.finish();
        let state = estimator.state();
        let report = AgentReport {
            pid: std::process::id(),
            phases: process.clock.times(),
            peak_rss_kb: own_peak_rss_kb(),
            final_undetected_cells: state.undetected.cells().count(),
            final_undetected_digest: state.undetected.cells().digest(),
            final_step: state.step,
            external: turn.external_report(),
            counters: process.counters,
            checkpoint,
            end: None,
        };
        result.map(|end| AgentReport {
            end: Some(end),
            ..report
        })
    }
}
