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
//!    steps they lag), then the measurements they forward that it has not applied yet. Under the measurement exchange it then sends the observers its sets
//!    (a [`WireKind::State`] message on its estimate service, which peers skip unread);
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
//! deltas against the previous message ([`message`]); a peer's estimate that cannot be
//! rebuilt (a missed message) is dropped, not awaited, and whole sets are asked of its sender.
//!
//! The radio between agents is simulated by the receiver ([`protocol::radio`]): every estimate and
//! token crosses the IPC, and the receiving agent decides from the scenario's seed whether the
//! radio lost it (`comms.loss`), when it arrives (`comms.latency_ms`) and whether its sender
//! was in range (`comms.range_m`; for tokens unless `comms.token_range = "unlimited"`). A lost
//! estimate is not read and not awaited: the agent knows at once that it will not come. A
//! token lost or out of range is taken as its sender having passed the turn with a plan this
//! agent will not see: the ring skips it at once, as it does a holder whose wait ran out
//! ([`TokenRing::receive`]), so a lossy run waits for nothing it will not get and stays
//! reproducible. A token carries its sender's pose for the radio to judge; in lockstep a
//! receiver reads it at the token's step, the pose it judges from its own. With loss,
//! estimates carry whole sets, never deltas: a delta against a lost message could not be
//! rebuilt, and each later one of the chain would fail until whole sets came (the map keeps
//! its deltas: they only add knowledge, see [`message`]). An estimate of step `k` is fused at
//! step `k + d` (`d` the latency in steps), dilated by `d` steps; the agent still awaits
//! (bounded) every peer's step-`k` message at step `k`, so what it fuses at each step does not
//! depend on timing.
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

pub mod checkpoint;
mod links;
mod liveness;

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use fleet_process::resources::{CpuClock, PhaseClock, PhaseTimes, own_peak_rss_kb};
use iceoryx2::prelude::{SignalHandlingMode, WaitSet};
use protocol::codec::{self, EncodeError};
use protocol::flight::UavState;
use protocol::frame::CvsFrame;
use protocol::ipc::{Ipc, IpcOpenError, NodeScanError, RunNode, scan_nodes, wait_for_wake};
use protocol::plan::FLAG_ROUND_START;
use protocol::radio::{Endpoint, LinkKind, Radio};
use protocol::scenario::{Exchange, ExternalRequest, Scenario};
use protocol::service::RunId;
use protocol::timeouts::Timeouts;
use protocol::wire::{
    AgentStats, DropReason, EstimateMsg, GuidanceToken, HELLO_STEP, UavCommand, UavMask, WireKind,
    uav_bit, unix_now_ns,
};
use serde::Serialize;

use crate::guidance::external::{self, Asked, ExternalPlanner, ExternalReport, Fallback, Request};
use crate::guidance::{self, GuidanceParams, ObstacleCell, PlanningInput, TokenRing, Turn};
use checkpoint::{CheckpointFile, CheckpointFlusher, Owner};
use estimator::message::PeerMessage;
use estimator::{
    Estimator, EstimatorConfig, EstimatorStepError, Measurement, Relayed, StepReport, message,
};
use links::{LinkError, Links};
use liveness::LiveView;

/// How an agent runs.
#[derive(Clone, Debug)]
pub struct AgentConfig {
    /// The run to join.
    pub run_id: RunId,
    /// This agent's UAV.
    pub uav: u32,
    /// The run's scenario (the same file as the world's).
    pub scenario: Scenario,
    /// The run's waits (peers, token holders, hellos), the same as the world's.
    pub timeouts: Timeouts,
    /// No frame for this long and no live world node: the world is lost.
    pub world_timeout: Duration,
    /// The file this agent checkpoints its state to and resumes from (none: no checkpoints).
    pub checkpoint: Option<PathBuf>,
    /// Checkpoint after the steps that are multiples of this (at least 1; default
    /// [`DEFAULT_CHECKPOINT_EVERY`]).
    pub checkpoint_every: u64,
    /// Fault-injection hook: how long the agent sits on the token before planning, so tests
    /// can kill a holder mid-turn (0 in normal runs; only with the `test-hooks` feature).
    #[cfg(feature = "test-hooks")]
    pub hold_token: Duration,
}

/// Steps between two checkpoints by default: a checkpoint encodes the whole state, whose
/// rasters cover the region, so saving it at every step cost 6 % of a 16-UAV run's CPU on its
/// 1 km region. A restarted agent resumes at most this many steps back, its sets grown by the
/// motion since, and its peers' whole sets bring back what the fleet learned meanwhile.
pub const DEFAULT_CHECKPOINT_EVERY: u64 = 4;

impl AgentConfig {
    /// The default [`Timeouts`] (with the scenario's external planner budget), no checkpoint.
    pub fn new(run_id: RunId, uav: u32, scenario: Scenario) -> Self {
        let timeouts = Timeouts::default().for_scenario(&scenario);
        Self {
            run_id,
            uav,
            scenario,
            timeouts,
            world_timeout: timeouts.world_lost(),
            checkpoint: None,
            checkpoint_every: DEFAULT_CHECKPOINT_EVERY,
            #[cfg(feature = "test-hooks")]
            hold_token: Duration::ZERO,
        }
    }

    /// The checkpoint file of agent `uav` in directory `dir`: `agent-{uav}.ckpt`.
    pub fn checkpoint_in(dir: &std::path::Path, uav: u32) -> PathBuf {
        dir.join(format!("agent-{uav}.ckpt"))
    }
}

/// Why an agent could not join its run.
#[derive(Debug, thiserror::Error)]
pub enum AgentStartError {
    /// The UAV index is not in the scenario's fleet.
    #[error("UAV {uav} is outside the fleet: the scenario has {count} UAVs (ids 0..{count})")]
    OutsideFleet {
        /// Requested id.
        uav: u32,
        /// UAVs in the scenario.
        count: u32,
    },
    /// Another live process already is this agent.
    #[error("agent {uav} is already live in run {run}: refusing to start a second one")]
    AlreadyLive {
        /// Requested id.
        uav: u32,
        /// The run.
        run: String,
    },
    /// The run's nodes could not be listed.
    #[error(transparent)]
    Scan(#[from] NodeScanError),
}

/// Why an agent stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum AgentError {
    /// It could not join the run.
    #[error(transparent)]
    Start(#[from] AgentStartError),
    /// Its node, services or ports could not be opened.
    #[error(transparent)]
    Open(#[from] IpcOpenError),
    /// A message could not be sent.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// A message could not be encoded.
    #[error(transparent)]
    Encode(#[from] EncodeError),
    /// No frame came for a long while and the world's node is gone.
    #[error(
        "the world-server of run {run} is gone (no frame for {waited:?} and its node is not alive)"
    )]
    WorldLost {
        /// The run.
        run: String,
        /// How long no frame came.
        waited: Duration,
    },
    /// A guidance step came before any pose.
    #[error("no pose to plan from at step {0}")]
    NoPose(u64),
}

impl AgentError {
    /// Whether the error is the caller's (an argument that cannot work), as opposed to a
    /// failure of the run.
    pub fn is_usage(&self) -> bool {
        matches!(
            self,
            AgentError::Start(AgentStartError::OutsideFleet { .. })
        )
    }
}

/// How the agent's loop ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum EndReason {
    /// The world announced the end of the run.
    EndOfRun,
    /// SIGTERM/SIGINT or the shutdown flag.
    Interrupted,
}

/// What an agent did, printed at exit.
#[derive(Clone, Debug, Default, Serialize)]
pub struct AgentReport {
    /// Frames folded in.
    pub frames: u64,
    /// Frames refused (malformed, other run).
    pub frames_refused: u64,
    /// Estimates published.
    pub estimates_sent: u64,
    /// Peer estimates fused.
    pub estimates_received: u64,
    /// Peer estimates out of comms range, not fused.
    pub estimates_out_of_range: u64,
    /// Peer estimates the simulated radio lost (`comms.loss`), not read.
    pub estimates_lost: u64,
    /// Tokens the simulated radio lost (`comms.loss`) or that came from out of range
    /// (`comms.range_m` with `comms.token_range = "radio"`): their senders were skipped at once.
    pub tokens_lost: u64,
    /// Peer measurements applied from a copy another agent forwarded (`comms.relay_hops`),
    /// not from their sender.
    pub relayed_applied: u64,
    /// Peer measurements this agent forwarded in its estimates.
    pub relayed_sent: u64,
    /// Decisions taken from an external planner's answer.
    pub external_decisions: u64,
    /// Decisions the fallback planner took for want of a valid answer in time.
    pub external_fallbacks: u64,
    /// Messages dropped, by reason.
    pub dropped: BTreeMap<String, u64>,
    /// Guidance decisions taken.
    pub decisions: u64,
    /// Decisions taken after waiting out a silent holder.
    pub token_timeouts: u64,
    /// Steps whose peers' estimates did not all arrive in time.
    pub peer_timeouts: u64,
    /// Cells of `X̄` after the last fusion.
    pub final_undetected_cells: u64,
    /// Fingerprint of `X̄` after the last fusion ([`sets::raster::CellSet::digest`]):
    /// agents that fused the same estimates hold the same set.
    pub final_undetected_digest: u64,
    /// Step of the last frame.
    pub final_step: u64,
    /// Step of the checkpoint this agent resumed from, if it did.
    pub resumed_from_step: Option<u64>,
    /// Why a checkpoint found at start was refused, if one was.
    pub checkpoint_refused: Option<String>,
    /// Checkpoints written.
    pub checkpoints: u64,
    /// Checkpoints that could not be written.
    pub checkpoint_failures: u64,
    /// Wall time the step loop spent on checkpoints (encoding and writing them, and flushing
    /// them when there is no checkpoint thread), milliseconds.
    pub checkpoint_ms: f64,
    /// Flushes to the disk done by the checkpoint thread (one may serve several checkpoints).
    pub checkpoint_flushes: u64,
    /// Flushes that failed.
    pub checkpoint_flush_failures: u64,
    /// Wall time the checkpoint thread spent flushing, milliseconds.
    pub checkpoint_flush_ms: f64,
    /// How the loop ended.
    pub end: Option<EndReason>,
    /// This process's id, so that whoever started it can join this report to the kernel's
    /// account of the process.
    pub pid: u32,
    /// Where the agent's thread spent its time ([`phase`]): CPU time of the thread and wall
    /// time per phase, from the start of the loop to its end.
    pub phases: PhaseTimes,
    /// The process's own peak resident memory at the end of its loop, KiB
    /// ([`own_peak_rss_kb`]: without the memory of whoever spawned it); `None` if it could not
    /// be read.
    pub peak_rss_kb: Option<u64>,
    /// What the external planner did, for an agent that asks one: decisions, fallbacks by
    /// reason, the time from request to answer and its overhead beyond the planner's own.
    pub external: Option<ExternalReport>,
}

/// The phases of an agent's time ([`AgentReport::phases`]).
pub mod phase {
    /// Folding a frame into the estimator (predict, correct, the OEM).
    pub const ESTIMATE: &str = "estimate";
    /// Composing, encoding and sending the agent's estimate.
    pub const PUBLISH: &str = "publish";
    /// Receiving, decoding and fusing the peers' estimates.
    pub const FUSE: &str = "fuse";
    /// The planner's decision and passing the token.
    pub const PLAN: &str = "plan";
    /// Writing the checkpoint.
    pub const CHECKPOINT: &str = "checkpoint";
    /// Listing the run's nodes (who is alive).
    pub const SCAN: &str = "scan";
    /// Waiting for the next frame.
    pub const WAIT_FRAME: &str = "wait_frame";
    /// Waiting for the peers' estimates of the step.
    pub const WAIT_PEERS: &str = "wait_peers";
    /// Waiting for the token.
    pub const WAIT_TOKEN: &str = "wait_token";
    /// Waiting for an external planner's answer.
    pub const WAIT_PLANNER: &str = "wait_planner";
    /// Everything else (commands, tokens read, start-up after the clock started).
    pub const OTHER: &str = "other";
}

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
    let checkpoint = config.checkpoint.clone().map(|path| {
        CheckpointFile::new(
            path,
            Owner::new(config.run_id.tag(), config.uav, &config.scenario),
        )
    });
    let mut report = AgentReport::default();
    let estimator = restore(checkpoint.as_ref(), &estimator_config, &mut report);
    let exchange = config.scenario.comms.exchange;
    let outbox = match exchange {
        Exchange::Sets => {
            let outbox = message::EstimateOutbox::new(
                config.uav,
                incarnation,
                estimator_config.oem_full_every,
            );
            // A delta against a message the radio lost rebuilds nothing: whole sets under
            // loss.
            if radio.is_lossy() {
                outbox
            } else {
                outbox.with_set_deltas()
            }
        }
        // Whole sets now and then where the radio loses messages or limits the range (they
        // carry what was lost or is out of reach); on perfect links only when a peer
        // (re)joins or asks, and in the first message of an agent resumed from a checkpoint
        // (a fresh one's sets hold nothing its measurements do not carry).
        Exchange::Measurements => {
            let outbox = message::EstimateOutbox::new(
                config.uav,
                incarnation,
                if radio.loses_or_limits() {
                    u64::from(config.scenario.comms.whole_sets_every)
                } else {
                    u64::MAX
                },
            );
            if report.resumed_from_step.is_some() {
                outbox
            } else {
                outbox.starting_fresh()
            }
        }
    };
    let mut agent = Agent {
        run_tag: config.run_id.tag(),
        incarnation,
        outbox,
        exchange,
        missed: 0,
        measurement: None,
        relay_hops: match exchange {
            Exchange::Sets => 0,
            Exchange::Measurements => config.scenario.comms.relay_hops,
        },
        relay_out: Vec::new(),
        applied: BTreeSet::new(),
        // The observers' copy of this agent's sets, over the local IPC (no radio): deltas.
        state_outbox: (exchange == Exchange::Measurements).then(|| {
            message::EstimateOutbox::new(config.uav, incarnation, estimator_config.oem_full_every)
                .with_set_deltas()
                .without_map()
        }),
        // Whole sets of the measurement exchange are never the base of a delta.
        inbox: match exchange {
            Exchange::Sets => message::EstimateInbox::new(),
            Exchange::Measurements => message::EstimateInbox::without_bases(),
        },
        radio,
        lost_by_step: BTreeMap::new(),
        estimator,
        checkpoint_flusher: checkpoint.clone().and_then(|file| {
            CheckpointFlusher::start(file)
                .inspect_err(
                    |e| tracing::warn!(error = %e, "no checkpoint thread: flushing in the loop"),
                )
                .ok()
        }),
        checkpoint,
        served: UavMask::MAX,
        guidance: GuidanceParams::from_scenario(&config.scenario),
        ring: TokenRing::new(config.uav, config.scenario.comms.liveness),
        live_view: LiveView::new(config.scenario.comms.liveness),
        peers: BTreeMap::new(),
        full_map_from: None,
        live: BTreeSet::new(),
        world_live: true,
        links: &links,
        waitset: &waitset,
        config: &config,
        shutdown,
        report,
        end_of_run: false,
        interrupted: false,
        last_frame: Instant::now(),
        clock: PhaseClock::new(CpuClock::Thread, phase::OTHER),
        last_scan: Instant::now(),
        external,
        asked: None,
    };
    agent.await_planner();
    agent.refresh_live();
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

/// The estimator the agent starts from: the checkpoint's when there is one that it accepts,
/// else a fresh one; `report` notes a resumption or a refused checkpoint.
fn restore(
    checkpoint: Option<&CheckpointFile>,
    config: &EstimatorConfig,
    report: &mut AgentReport,
) -> Estimator {
    match checkpoint.map(|c| c.load(config)) {
        Some(Ok(Some(estimator))) => {
            let step = estimator.state().step;
            tracing::info!(step, "resuming from the checkpoint");
            report.resumed_from_step = Some(step);
            estimator
        }
        Some(Err(e)) => {
            tracing::warn!(error = %e, "checkpoint refused: starting fresh");
            report.checkpoint_refused = Some(e.to_string());
            Estimator::new(config.clone())
        }
        Some(Ok(None)) | None => Estimator::new(config.clone()),
    }
}

/// How an agent applies its peers' measurements when it forwards them (`comms.relay_hops`).
struct Relaying<'a> {
    /// How many times a measurement is forwarded (0: never, and nothing is remembered).
    hops: u32,
    /// The measurements applied lately, as (step, UAV).
    applied: &'a mut BTreeSet<(u64, u32)>,
    /// What the next estimate forwards.
    out: &'a mut Vec<Relayed>,
}

impl Relaying<'_> {
    /// Applies `m`, which reached this agent after `hops` forwardings (0: from its sender),
    /// unless it was applied already; keeps it to forward when it has hops left. Whether it
    /// was applied now.
    fn apply(&mut self, estimator: &mut Estimator, m: &Measurement, hops: u32) -> bool {
        if self.hops == 0 {
            estimator.apply(m);
            return true;
        }
        if !self.applied.insert((m.step, m.uav)) {
            return false;
        }
        estimator.apply(m);
        if hops < self.hops {
            self.out.push(Relayed {
                hops: hops + 1,
                measurement: m.clone(),
            });
        }
        true
    }
}

/// A number that grows at each start of an agent process (the wall clock in nanoseconds), so
/// the world and the peers tell a restarted agent from its predecessor and ignore the latter.
fn incarnation() -> u64 {
    unix_now_ns()
}

#[derive(Default)]
struct PeerInfo {
    /// Newest step fused from this peer.
    fused_step: Option<u64>,
    /// Newest step whose message from this peer was handled: queued, lost by the radio or
    /// dropped for want of its base. What [`Agent::gather`] awaits.
    heard_step: Option<u64>,
    incarnation: Option<u64>,
    /// The message counter of the last estimate read from this incarnation.
    last_seq: Option<u64>,
    /// Estimates received ahead of this agent's step.
    pending: Vec<PeerMessage>,
}

struct Agent<'a> {
    config: &'a AgentConfig,
    run_tag: u64,
    incarnation: u64,
    links: &'a Links,
    waitset: &'a WaitSet<Ipc>,
    estimator: Estimator,
    checkpoint: Option<CheckpointFile>,
    /// The thread that flushes the checkpoints to the disk (none: flushed in the loop).
    checkpoint_flusher: Option<CheckpointFlusher>,
    /// The agents the world serves at the current step (the frame's mask).
    served: UavMask,
    outbox: message::EstimateOutbox,
    /// What the estimates carry (`comms.exchange`).
    exchange: Exchange,
    /// This agent's measurement of the current step, under the measurement exchange.
    measurement: Option<Measurement>,
    /// How many times a peer measurement is forwarded (`comms.relay_hops`; 0 under the set
    /// exchange).
    relay_hops: u32,
    /// The peer measurements applied at the last gather that the next estimate forwards.
    relay_out: Vec<Relayed>,
    /// The peer measurements applied lately, as (step, UAV), when relaying: a measurement
    /// that comes again, from its sender or forwarded by another agent, is not applied twice.
    applied: BTreeSet<(u64, u32)>,
    /// Under the measurement exchange, the observers' copy of this agent's sets once it
    /// applied its peers' measurements ([`WireKind::State`]).
    state_outbox: Option<message::EstimateOutbox>,
    /// Peers this agent missed an estimate of since its last estimate: its next estimate asks
    /// them for whole sets.
    missed: UavMask,
    /// The peers' sets, the bases of their deltas.
    inbox: message::EstimateInbox,
    /// The simulated links ([`protocol::radio`]).
    radio: Radio,
    /// Estimates the radio lost, by step, not yet counted in the report: they are counted
    /// once the agent has gathered their step, so the counters its estimates carry do not
    /// depend on when a peer's message of the next step came in.
    lost_by_step: BTreeMap<u64, u64>,
    /// The step from which the next estimate carries the whole map (a peer (re)joined).
    full_map_from: Option<u64>,
    guidance: GuidanceParams,
    ring: TokenRing,
    /// Whom the agent knows live at its step, for the ring (`comms.liveness`).
    live_view: LiveView,
    peers: BTreeMap<u32, PeerInfo>,
    /// Live peers (this agent excluded), from the run's node list.
    live: BTreeSet<u32>,
    world_live: bool,
    shutdown: &'a AtomicBool,
    report: AgentReport,
    end_of_run: bool,
    interrupted: bool,
    last_frame: Instant,
    /// Where the time goes ([`phase`]).
    clock: PhaseClock,
    /// When the run's nodes were last listed.
    last_scan: Instant,
    /// The external planner this agent asks for its decisions, if it asks one.
    external: Option<ExternalPlanner>,
    /// The request of the current round sent at its start (`guidance.external_request =
    /// "round_start"`), whose answer the agent's turn takes.
    asked: Option<Asked>,
}

/// How long an agent that asks an external planner waits for one to serve it before its first
/// hello: well within the world's start wait, so a planner started with the run answers from
/// the first decision.
const PLANNER_START_WAIT: Duration = Duration::from_secs(20);

/// Longest single wait, so the shutdown flag and dead processes are noticed promptly.
const WAIT_SLICE: Duration = Duration::from_millis(50);

/// How old the last listing of the run's nodes may grow while the agent waits for peers or the
/// token before it lists them again, for a fleet of up to [`UAVS_PER_SCAN_PERIOD`] UAVs: a peer
/// that died meanwhile stops being awaited within this time. A listing costs about a
/// millisecond of CPU; at every wait slice it was about 5 % of a run's CPU. The world lists
/// them before every step anyway and serves only the live agents.
const LIVENESS_SCAN_PERIOD: Duration = Duration::from_millis(250);

/// A listing reads every node of the run, so it costs more in a larger fleet, and every agent
/// of it lists: the period grows by [`LIVENESS_SCAN_PERIOD`] for every this many UAVs
/// ([`liveness_scan_period`]).
const UAVS_PER_SCAN_PERIOD: u32 = 4;

/// How old the last listing may grow in a fleet of `uavs` UAVs: [`LIVENESS_SCAN_PERIOD`] up to
/// [`UAVS_PER_SCAN_PERIOD`] UAVs, and as many times that as it has groups of them (1 s for 16
/// UAVs, 4 s for 64). With a period that stays, the listings of a 64-UAV fleet on one machine
/// took about 80 % of its agents' CPU. A dead peer still costs at most the peer wait of the
/// step it died in: the world's listing before the next step no longer serves it.
fn liveness_scan_period(uavs: u32) -> Duration {
    LIVENESS_SCAN_PERIOD * uavs.div_ceil(UAVS_PER_SCAN_PERIOD).max(1)
}

impl Agent<'_> {
    /// The agent's report once its loop ended with `result`: the checkpoint thread's figures,
    /// where the time went and a summary of its last `X̄`.
    fn finish(mut self, result: Result<EndReason, AgentError>) -> Result<AgentReport, AgentError> {
        if let Some(flusher) = self.checkpoint_flusher.take() {
            let stats = flusher.finish();
            self.report.checkpoint_flushes = stats.flushes;
            self.report.checkpoint_flush_failures = stats.failed;
            self.report.checkpoint_flush_ms = stats.flush_ms;
        }
        let state = self.estimator.state();
        let report = AgentReport {
            pid: std::process::id(),
            phases: self.clock.times(),
            peak_rss_kb: own_peak_rss_kb(),
            final_undetected_cells: state.undetected.cells().count(),
            final_undetected_digest: state.undetected.cells().digest(),
            final_step: state.step,
            external: self.external.as_ref().map(ExternalPlanner::report),
            ..self.report
        };
        result.map(|end| AgentReport {
            end: Some(end),
            ..report
        })
    }

    fn main_loop(&mut self) -> Result<EndReason, AgentError> {
        let mut last_hello: Option<Instant> = None;
        let mut first_frame = false;
        let timeouts = self.config.timeouts;
        loop {
            // Hello until the first frame; then again whenever frames stop coming, in case the
            // world stopped serving this agent (it was stalled past the ack wait). A hello
            // from an agent the world serves changes nothing.
            let hello_due = if first_frame {
                self.last_frame.elapsed() >= timeouts.rehello()
                    && last_hello.is_none_or(|t| t.elapsed() >= timeouts.rehello())
            } else {
                last_hello.is_none_or(|t| t.elapsed() >= timeouts.hello_interval())
            };
            if hello_due {
                self.links.send_command(self.command(HELLO_STEP, None))?;
                last_hello = Some(Instant::now());
            }
            while let Some(sample) = self.links.frames.receive().map_err(LinkError::from)? {
                first_frame = true;
                self.last_frame = Instant::now();
                self.on_frame(sample.payload())?;
            }
            let before = self.clock.enter(phase::FUSE);
            self.drain_estimates();
            self.clock.enter(before);
            self.drain_tokens();
            if self.end_of_run {
                return Ok(EndReason::EndOfRun);
            }
            if self.interrupted || self.shutdown.load(Ordering::Relaxed) {
                return Ok(EndReason::Interrupted);
            }
            // Before the first frame the world may still be waiting out the slowest agents'
            // hellos, up to its start wait; and a world on another host never shows its node
            // here, so only frames can tell that it is there.
            let lost_after = if first_frame {
                self.config.world_timeout
            } else {
                self.config.world_timeout + timeouts.start()
            };
            if self.last_frame.elapsed() >= lost_after {
                self.refresh_live();
                if !self.world_live {
                    return Err(AgentError::WorldLost {
                        run: self.config.run_id.to_string(),
                        waited: lost_after,
                    });
                }
            }
            self.wait(Instant::now() + WAIT_SLICE, phase::WAIT_FRAME);
        }
    }

    /// Waits for a wake-up until `deadline` at most, counting the time to `phase`; notes
    /// end-of-run and interrupts.
    fn wait(&mut self, deadline: Instant, phase: &'static str) {
        let timeout = deadline.saturating_duration_since(Instant::now());
        if timeout.is_zero() {
            return;
        }
        let before = self.clock.enter(phase);
        let woken = wait_for_wake(self.waitset, &self.links.wake, timeout);
        self.clock.enter(before);
        match woken {
            Ok(wake) => {
                self.end_of_run |= wake.end_of_run;
                self.interrupted |= wake.interrupted;
            }
            Err(e) => {
                tracing::warn!(error = ?e, "wait failed");
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    }

    /// Lists the run's nodes if the last listing is [`liveness_scan_period`] old: while
    /// waiting, a peer that died is noticed within that time.
    fn refresh_live_if_stale(&mut self) {
        if self.last_scan.elapsed() >= liveness_scan_period(self.config.scenario.uavs.count) {
            self.refresh_live();
        }
    }

    fn stopping(&self) -> bool {
        self.interrupted || self.shutdown.load(Ordering::Relaxed)
    }

    /// Re-reads which peers and whether the world are alive (and cleans dead nodes).
    fn refresh_live(&mut self) {
        let before = self.clock.enter(phase::SCAN);
        let scanned = scan_nodes(&self.config.run_id, true);
        self.clock.enter(before);
        self.last_scan = Instant::now();
        match scanned {
            Ok(scan) => {
                self.world_live = scan.is_alive(RunNode::WORLD);
                self.live = (0..self.config.scenario.uavs.count)
                    .filter(|&j| j != self.config.uav && scan.is_alive(&RunNode::agent_name(j)))
                    .collect();
                for dead in &scan.dead {
                    tracing::info!(node = %dead, "cleaned up a dead node");
                }
            }
            Err(e) => tracing::warn!(error = %e, "cannot list the run's nodes"),
        }
    }

    fn drop_message(&mut self, reason: DropReason, what: &str, detail: &str) {
        tracing::warn!(?reason, what, detail, "message dropped");
        *self
            .report
            .dropped
            .entry(format!("{what}:{reason:?}"))
            .or_default() += 1;
    }

    fn on_frame(&mut self, frame: &CvsFrame) -> Result<(), AgentError> {
        let k = frame.header.step;
        if frame.header.run_tag != self.run_tag || frame.header.uav != self.config.uav {
            self.report.frames_refused += 1;
            tracing::warn!(step = k, "frame of another run or UAV dropped");
            return Ok(());
        }
        // Every token of the rounds before this frame was sent before the world sent it: read
        // them now, so the counters this step's estimate carries do not depend on timing.
        self.drain_tokens();
        let mut yaw_ref = None;
        let mut acked = false;
        let guidance_step = k.is_multiple_of(self.guidance.steps_per_period as u64);
        let before = self.clock.enter(phase::ESTIMATE);
        let folded = self.fold(frame);
        self.clock.enter(before);
        match &folded {
            Ok(_) => {
                self.report.frames += 1;
                self.served = match frame.header.served {
                    // A world that does not say whom it serves: await every live peer.
                    0 => UavMask::MAX,
                    mask => mask,
                };
                let before = self.clock.enter(phase::PUBLISH);
                let published = self.publish_estimate(k);
                self.clock.enter(before);
                published?;
                if !guidance_step {
                    // Nothing left to tell the world: it may render the next frame now.
                    self.links.send_command(self.command(k, None))?;
                    acked = true;
                }
                self.gather(k);
                let before = self.clock.enter(phase::PUBLISH);
                let published = self.publish_state(k);
                self.clock.enter(before);
                published?;
                if guidance_step {
                    yaw_ref = self.decide(k)?;
                }
            }
            Err(e) => {
                self.report.frames_refused += 1;
                tracing::warn!(step = k, error = %e, "frame refused");
            }
        }
        if !acked {
            self.links.send_command(self.command(k, yaw_ref))?;
        }
        if folded.is_ok() && k.is_multiple_of(self.config.checkpoint_every.max(1)) {
            self.save_checkpoint();
        }
        Ok(())
    }

    /// The command answering step `step` (or a hello), with a new yaw reference if any.
    fn command(&self, step: u64, yaw_ref: Option<f64>) -> UavCommand {
        UavCommand {
            run_tag: self.run_tag,
            step,
            uav: self.config.uav,
            has_yaw_ref: u32::from(yaw_ref.is_some()),
            yaw_ref_rad: yaw_ref.unwrap_or(0.0),
            incarnation: self.incarnation,
        }
    }

    /// Folds a frame into the estimator. A resumed agent whose checkpoint is ahead of the
    /// run's first frame (a checkpoint of a run that was started over) drops it and starts
    /// fresh.
    fn fold(&mut self, frame: &CvsFrame) -> Result<StepReport, EstimatorStepError> {
        match self.fold_once(frame) {
            Err(EstimatorStepError::Stale { state_step, .. })
                if self.report.frames == 0 && self.report.resumed_from_step.is_some() =>
            {
                tracing::warn!(
                    checkpoint_step = state_step,
                    frame_step = frame.header.step,
                    "the checkpoint is ahead of the run: starting fresh"
                );
                self.report.resumed_from_step = None;
                self.estimator = Estimator::new(self.estimator.config().clone());
                self.fold_once(frame)
            }
            other => other,
        }
    }

    /// One estimator step; under the measurement exchange it keeps the frame's measurement
    /// for this step's estimate.
    fn fold_once(&mut self, frame: &CvsFrame) -> Result<StepReport, EstimatorStepError> {
        match self.exchange {
            Exchange::Sets => self.estimator.step(frame),
            Exchange::Measurements => {
                let (report, measurement) = self.estimator.step_sharing(frame, self.config.uav)?;
                self.measurement = Some(measurement);
                Ok(report)
            }
        }
    }

    /// Saves the state to the checkpoint file, if there is one (a failure is logged and
    /// counted: the run goes on without it).
    /// Encodes the state and replaces the checkpoint with it; the checkpoint thread flushes it
    /// to the disk (without a thread, it is flushed here).
    fn save_checkpoint(&mut self) {
        let Some(file) = &self.checkpoint else {
            return;
        };
        let started = Instant::now();
        let before = self.clock.enter(phase::CHECKPOINT);
        let saved =
            file.encode(self.estimator.state())
                .and_then(|bytes| match &self.checkpoint_flusher {
                    Some(flusher) => {
                        file.replace(&bytes)?;
                        flusher.request();
                        Ok(())
                    }
                    None => file.write(&bytes),
                });
        self.clock.enter(before);
        self.report.checkpoint_ms += started.elapsed().as_secs_f64() * 1e3;
        match saved {
            Ok(()) => self.report.checkpoints += 1,
            Err(e) => {
                self.report.checkpoint_failures += 1;
                tracing::warn!(error = %e, "cannot write the checkpoint");
            }
        }
    }

    /// The peers awaited at the current step: served by the world and alive.
    fn awaited_peers(&self) -> BTreeSet<u32> {
        self.live
            .iter()
            .copied()
            .filter(|&j| self.served & uav_bit(j) != 0)
            .collect()
    }

    /// The UAVs this agent knows live at its step, itself included, as `comms.liveness` reads
    /// it: what the token ring waits for and the round's fleet.
    fn ring_live(&self) -> BTreeSet<u32> {
        self.live_view.live(self.config.uav, self.awaited_peers())
    }

    fn publish_estimate(&mut self, k: u64) -> Result<(), AgentError> {
        if self.full_map_from.is_some_and(|from| k >= from) {
            self.outbox.request_full();
            self.full_map_from = None;
        }
        let relayed = std::mem::take(&mut self.relay_out);
        let mut msg = match (&self.measurement, self.exchange) {
            (Some(m), Exchange::Measurements) => {
                self.report.relayed_sent += relayed.len() as u64;
                self.outbox
                    .compose_measurement(self.estimator.state_mut(), m, &relayed)
            }
            _ => self.outbox.compose(self.estimator.state_mut()),
        };
        msg.stats = self.stats();
        msg.want_whole = self.inbox.wanted() | std::mem::take(&mut self.missed);
        let bytes = message::to_bytes(&msg)?;
        self.links
            .send_wire(WireKind::Estimate, self.run_tag, self.config.uav, k, &bytes)?;
        self.report.estimates_sent += 1;
        Ok(())
    }

    /// Under the measurement exchange, sends the observers this agent's sets once it applied
    /// its peers' measurements of step `k` (the guarantee is checked on them).
    fn publish_state(&mut self, k: u64) -> Result<(), AgentError> {
        let Some(outbox) = &mut self.state_outbox else {
            return Ok(());
        };
        let mut msg = outbox.compose(self.estimator.state_mut());
        msg.stats = self.stats();
        let bytes = message::to_bytes(&msg)?;
        self.links
            .send_wire(WireKind::State, self.run_tag, self.config.uav, k, &bytes)?;
        Ok(())
    }

    /// The counters an estimate carries.
    fn stats(&self) -> AgentStats {
        AgentStats {
            frames: self.report.frames,
            frames_refused: self.report.frames_refused,
            estimates_received: self.report.estimates_received,
            messages_dropped: self.report.dropped.values().sum(),
            decisions: self.report.decisions,
            token_timeouts: self.report.token_timeouts,
            estimates_lost: self.report.estimates_lost,
            tokens_lost: self.report.tokens_lost,
            relayed_applied: self.report.relayed_applied,
            relayed_sent: self.report.relayed_sent,
            external_decisions: self.report.external_decisions,
            external_fallbacks: self.report.external_fallbacks,
        }
    }

    /// Fuses the awaited peers' estimates of step `k`, waiting for them (bounded). Sets are
    /// fused as they come (intersection does not depend on the order, so the work overlaps
    /// the wait); measurements are applied once the wait is over, all together in the order
    /// of the peers, not in whatever order they happened to come.
    fn gather(&mut self, k: u64) {
        // The world lists the nodes before every step: a peer it serves is alive unless it
        // died since, which the waits below notice. Only a peer that (re)joined needs a look.
        let newcomer = (0..self.config.scenario.uavs.count).any(|j| {
            j != self.config.uav && self.served & uav_bit(j) != 0 && !self.live.contains(&j)
        });
        if newcomer {
            self.refresh_live();
        }
        self.live_view.start_step();
        let deadline = Instant::now() + self.config.timeouts.peer_wait;
        loop {
            let before = self.clock.enter(phase::FUSE);
            self.drain_estimates();
            if self.exchange == Exchange::Sets {
                self.fuse_pending(k);
            }
            self.clock.enter(before);
            let missing = self.awaited_peers().iter().any(|j| {
                self.peers
                    .get(j)
                    .and_then(|p| p.heard_step)
                    .is_none_or(|s| s < k)
            });
            if !missing || self.stopping() || self.end_of_run {
                break;
            }
            if Instant::now() >= deadline {
                self.report.peer_timeouts += 1;
                tracing::debug!(step = k, "some peers' estimates did not arrive in time");
                break;
            }
            self.wait(deadline.min(Instant::now() + WAIT_SLICE), phase::WAIT_PEERS);
            // A peer that died meanwhile is no longer awaited.
            self.refresh_live_if_stale();
        }
        let before = self.clock.enter(phase::FUSE);
        self.fuse_pending(k);
        self.clock.enter(before);
    }

    /// Reads every pending peer estimate into the peers' queues.
    fn drain_estimates(&mut self) {
        for idx in 0..self.links.estimates_in.len() {
            loop {
                let (sender, sub) = &self.links.estimates_in[idx];
                let sender = *sender;
                let sample = match sub.receive() {
                    Ok(Some(s)) => s,
                    Ok(None) => break,
                    Err(e) => {
                        tracing::warn!(error = ?e, peer = sender, "receive failed");
                        break;
                    }
                };
                let header = *sample.user_header();
                if header.kind == WireKind::State as u32 {
                    // The peer's sets for the observers: nothing for an agent.
                    continue;
                }
                let checked = header.check(
                    sample.payload().len(),
                    WireKind::Estimate,
                    self.run_tag,
                    Some(sender),
                );
                if let Err(reason) = checked {
                    drop(sample);
                    self.drop_message(reason, "estimate", &format!("from UAV {sender}"));
                    continue;
                }
                let parsed = message::from_bytes(sample.payload());
                drop(sample);
                match parsed {
                    Ok(m) if m.uav == sender => {
                        let me = self.config.uav;
                        if self.radio.delivers(LinkKind::Estimate, sender, me, m.step) {
                            self.read_peer(&m);
                        } else {
                            self.lose_estimate(&m);
                        }
                    }
                    Ok(m) => self.drop_message(
                        DropReason::Sender,
                        "estimate",
                        &format!("claims UAV {} on UAV {sender}'s service", m.uav),
                    ),
                    Err(e) => self.drop_message(DropReason::Malformed, "estimate", &e.to_string()),
                }
            }
        }
    }

    /// Takes note of an estimate the radio lost: it is not read (nor its request for whole
    /// sets, nor its incarnation), and not awaited any longer.
    fn lose_estimate(&mut self, m: &EstimateMsg) {
        let info = self.peers.entry(m.uav).or_default();
        if info.incarnation.is_none_or(|i| m.incarnation >= i) {
            info.heard_step = info.heard_step.max(Some(m.step));
        }
        *self.lost_by_step.entry(m.step).or_default() += 1;
    }

    /// Rebuilds a peer's estimate and queues it. One that cannot be rebuilt for want of its
    /// base is not awaited any longer (this agent keeps its own sets for that step) and makes
    /// this agent ask for whole sets; a peer that asks them of this agent gets them next.
    fn read_peer(&mut self, m: &EstimateMsg) {
        if m.want_whole & uav_bit(self.config.uav) != 0 {
            self.outbox.request_full();
        }
        match self.inbox.read_message(m, self.estimator.config()) {
            Ok(p) => self.queue_peer(p),
            Err(e) => {
                let reason = e.drop_reason();
                if reason == DropReason::NoBase {
                    let info = self.peers.entry(m.uav).or_default();
                    if info.incarnation.is_none_or(|i| i == m.incarnation) {
                        info.fused_step = Some(info.fused_step.map_or(m.step, |s| s.max(m.step)));
                        info.heard_step = info.heard_step.max(Some(m.step));
                    }
                }
                self.drop_message(reason, "estimate", &e.to_string());
            }
        }
    }

    fn queue_peer(&mut self, p: PeerMessage) {
        let info = self.peers.entry(p.uav).or_default();
        if info.incarnation.is_some_and(|i| p.incarnation < i) {
            let detail = format!("from UAV {}'s replaced process", p.uav);
            self.drop_message(DropReason::Superseded, "estimate", &detail);
            return;
        }
        if info.incarnation != Some(p.incarnation) {
            if info.incarnation.is_some() {
                tracing::info!(peer = p.uav, "peer restarted: sending it the whole map");
            }
            // A newcomer or a restarted peer needs the whole map to rebuild its own. It goes
            // with the estimate of the step after the peer's, whenever this message arrived:
            // in lockstep that keeps the traffic, like everything else, reproducible. Under
            // the measurement exchange a peer that starts with the run (its first estimate is
            // of step 0) has missed nothing: the measurements bring it everything.
            let started_with_run = p.step == 0 && info.incarnation.is_none();
            if !(started_with_run && self.exchange == Exchange::Measurements) {
                let from = p.step + 1;
                self.full_map_from = Some(self.full_map_from.map_or(from, |f| f.min(from)));
            }
            info.incarnation = Some(p.incarnation);
            info.fused_step = None;
            info.last_seq = None;
        }
        // Under the measurement exchange on links that lose nothing, a message missed (this
        // agent was stalled, its buffer overflowed) is a measurement never applied: ask the
        // peer for its whole sets. Lossy and limited links have them periodically instead.
        let missed = info.last_seq.is_some_and(|last| p.seq > last + 1);
        info.last_seq = Some(p.seq);
        if missed && self.exchange == Exchange::Measurements && !self.radio.loses_or_limits() {
            tracing::info!(
                peer = p.uav,
                seq = p.seq,
                "estimates missed: asking for whole sets"
            );
            self.missed |= uav_bit(p.uav);
        }
        info.heard_step = info.heard_step.max(Some(p.step));
        info.pending.push(p);
    }

    /// Fuses every queued estimate that has arrived by step `k` (of step `k - d` and older
    /// with a latency of `d` steps; older ones than `k` are dilated by the fusion), in
    /// ascending order of peer, as the radio's rule says ([`Radio::fuses`]: the queue holds
    /// only delivered estimates, so what is left out is out of range), and counts the lost
    /// estimates of the steps up to `k`.
    fn fuse_pending(&mut self, k: u64) {
        let me = Endpoint {
            uav: self.config.uav,
            step: k,
            pose: self.estimator.state().pose,
        };
        let radio = self.radio;
        let later = self.lost_by_step.split_off(&k.saturating_add(1));
        let lost = std::mem::replace(&mut self.lost_by_step, later);
        self.report.estimates_lost += lost.values().sum::<u64>();
        // Measurements other agents forward, by (step, UAV), each with its fewest hops:
        // applied after the senders' own, in that order, so runs stay reproducible.
        let mut forwarded: BTreeMap<(u64, u32), Relayed> = BTreeMap::new();
        let fleet = self.config.scenario.uavs.count;
        let mut relay = Relaying {
            hops: self.relay_hops,
            applied: &mut self.applied,
            out: &mut self.relay_out,
        };
        for info in self.peers.values_mut() {
            let (ready, later): (Vec<_>, Vec<_>) = info
                .pending
                .drain(..)
                .partition(|p| radio.arrived(p.step, k));
            info.pending = later;
            for p in ready {
                if info.fused_step.is_some_and(|s| s >= p.step) {
                    continue;
                }
                info.fused_step = Some(p.step);
                if self.live_view.fuses(&radio, &me, &p.endpoint()) {
                    if let Some(m) = &p.measurement {
                        relay.apply(&mut self.estimator, m, 0);
                    }
                    if let Some(e) = &p.estimate {
                        self.estimator.fuse(e);
                    }
                    for r in p.relayed {
                        let m = &r.measurement;
                        if m.uav == me.uav || m.uav >= fleet {
                            continue;
                        }
                        let key = (m.step, m.uav);
                        if forwarded.get(&key).is_none_or(|kept| r.hops < kept.hops) {
                            forwarded.insert(key, r);
                        }
                    }
                    self.report.estimates_received += 1;
                } else {
                    self.report.estimates_out_of_range += 1;
                }
            }
        }
        for r in forwarded.into_values() {
            if relay.apply(&mut self.estimator, &r.measurement, r.hops) {
                self.report.relayed_applied += 1;
            }
        }
        // A copy comes at most a step and the radio's delay per hop after the measurement's
        // own step: older ones need no memory (one that came later still would be applied
        // again, which keeps the guarantee like any measurement).
        let keep = (u64::from(self.relay_hops) + 1) * (radio.latency_steps() + 1) + 1;
        let oldest = k.saturating_sub(keep);
        self.applied = self.applied.split_off(&(oldest, 0));
    }

    fn drain_tokens(&mut self) {
        loop {
            let sample = match self.links.token_in.receive() {
                Ok(Some(s)) => s,
                Ok(None) => return,
                Err(e) => {
                    tracing::warn!(error = ?e, "token receive failed");
                    return;
                }
            };
            let header = *sample.user_header();
            if let Err(reason) =
                header.check(sample.payload().len(), WireKind::Token, self.run_tag, None)
            {
                drop(sample);
                self.drop_message(reason, "token", &format!("from UAV {}", header.sender));
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
                    let delivered = self.radio.carries_token(&self.token_receiver(), &sender);
                    if !delivered {
                        self.report.tokens_lost += 1;
                        tracing::debug!(
                            round = token.round,
                            sender = sender.uav,
                            "token lost by the radio or out of range"
                        );
                    }
                    self.ring.receive(token, sender.uav, delivered);
                }
                Err(e) => self.drop_message(DropReason::Malformed, "token", &e.to_string()),
            }
        }
    }

    /// This agent as the receiving end of a token: its current step and pose. In lockstep a
    /// token of step `k` is read at step `k` (see [`protocol::radio`]); a token read at
    /// another step (a late or stalled agent, or realtime stepping) is judged from the pose the
    /// agent has.
    fn token_receiver(&self) -> Endpoint {
        let state = self.estimator.state();
        Endpoint {
            uav: self.config.uav,
            step: state.step,
            pose: state.pose,
        }
    }

    /// Takes this agent's turn in the ring for the round starting at step `k`; returns the
    /// yaw reference to send. Each holder gets one bounded wait (`token_wait`), started when
    /// it becomes the holder this agent waits for; a holder silent for longer is skipped for
    /// the rest of the round and the next one gets a fresh wait.
    fn decide(&mut self, k: u64) -> Result<Option<f64>, AgentError> {
        let round = k / self.guidance.steps_per_period as u64;
        let mut waiting_for: Option<(u32, Instant)> = None;
        let mut waited_out = false;
        self.asked = None;
        if self.config.scenario.guidance.external_request == ExternalRequest::RoundStart {
            self.ask_at_round_start(round, k);
        }
        loop {
            self.drain_tokens();
            let live = self.ring_live();
            match self.ring.turn(round, &live) {
                Turn::Done => return Ok(None),
                Turn::Decide { others } => {
                    #[cfg(feature = "test-hooks")]
                    if !self.config.hold_token.is_zero() {
                        tracing::info!(round, hold = ?self.config.hold_token, "holding the token");
                        std::thread::sleep(self.config.hold_token);
                    }
                    if waited_out {
                        self.report.token_timeouts += 1;
                    }
                    let before = self.clock.enter(phase::PLAN);
                    let planned = self.plan_and_pass(round, k, &live, &others);
                    self.clock.enter(before);
                    return planned.map(Some);
                }
                Turn::Wait { holder } => {
                    if self.stopping() || self.end_of_run {
                        return Ok(None);
                    }
                    // A UAV heard at the step (the radio's reading) whose process died since,
                    // or that the world no longer serves, sends no token: give up on it at
                    // once. (Under the world's reading the holder is one of these peers.)
                    if !self.awaited_peers().contains(&holder) {
                        tracing::debug!(round, holder, "token holder gone: skipping it");
                        self.ring.holder_silent(round, holder);
                        continue;
                    }
                    let deadline = match waiting_for {
                        Some((h, deadline)) if h == holder => deadline,
                        _ => {
                            let deadline = Instant::now() + self.config.timeouts.holder_wait();
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
                    self.wait(deadline.min(Instant::now() + WAIT_SLICE), phase::WAIT_TOKEN);
                    // The holder may have died meanwhile: a dead holder is skipped within a
                    // wait slice (a listing costs milliseconds: not at every token hop).
                    if self.live.contains(&holder) {
                        self.refresh_live_if_stale();
                    }
                }
            }
        }
    }

    fn plan_and_pass(
        &mut self,
        round: u64,
        k: u64,
        live: &BTreeSet<u32>,
        others: &[protocol::wire::PlannedView],
    ) -> Result<f64, AgentError> {
        let Some(pose) = self.estimator.state().pose else {
            return Err(AgentError::NoPose(k));
        };
        let fleet = self.ring.fleet(round, live);
        let hidden = self.estimator.state().hidden_history.recently_hidden();
        let answer = self.ask_external(round, k, &hidden, others, &fleet);
        let state = self.estimator.state();
        let sets: Vec<&sets::raster::CellSet> = state.target_sets().collect();
        let obstacles = ObstacleCell::known(&state.oem);
        let input = PlanningInput {
            uav: self.config.uav,
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
        let decision = match answer {
            Some(answer) => external::decision(answer, &input),
            None => guidance::decide(&self.guidance, &input),
        };
        self.report.decisions += 1;
        let mut token = self.ring.pass(round, k, live, decision.view);
        token.pose = Some(pose);
        let bytes = codec::encode(&token)?;
        self.links
            .send_wire(WireKind::Token, self.run_tag, self.config.uav, k, &bytes)?;
        tracing::debug!(
            round,
            yaw_ref = decision.yaw_ref,
            cost = decision.cost.total,
            next = token.holder,
            "decided"
        );
        Ok(decision.yaw_ref)
    }
}

impl Agent<'_> {
    /// Waits, before the first hello, for an external planner to serve this agent (at most
    /// [`PLANNER_START_WAIT`]); an agent that asks none goes on at once.
    fn await_planner(&mut self) {
        let Some(planner) = &self.external else {
            return;
        };
        let until = Instant::now() + PLANNER_START_WAIT;
        if planner.has_server() {
            return;
        }
        tracing::info!(
            uav = self.config.uav,
            "waiting for an external planner to serve this UAV"
        );
        while Instant::now() < until && !self.stopping() {
            if self
                .external
                .as_ref()
                .is_some_and(ExternalPlanner::has_server)
            {
                tracing::info!(uav = self.config.uav, "external planner connected");
                return;
            }
            self.wait(Instant::now() + WAIT_SLICE, phase::WAIT_PLANNER);
        }
        tracing::warn!(
            uav = self.config.uav,
            waited = ?PLANNER_START_WAIT,
            "no external planner came: the fallback planner decides until one does"
        );
    }

    /// The scalar fields of this agent's request at step `k` of `round`.
    fn request_header(&self, round: u64, k: u64, flags: u32) -> protocol::plan::RequestHeader {
        let state = self.estimator.state();
        let pose = state.pose.unwrap_or(protocol::camera::CameraPose {
            position: sets::math::Point3::origin(),
            yaw: 0.0,
        });
        let scenario = &self.config.scenario;
        protocol::plan::RequestHeader {
            run_tag: self.run_tag,
            step: k,
            round,
            total_steps: scenario.steps(),
            uav: self.config.uav,
            fleet_size: scenario.uavs.count,
            deadline_ms: scenario.timing.external_planner_ms,
            flags,
            ..Request::header(&self.guidance, state, &pose)
        }
    }

    /// The external planner's answer for this turn, if this agent asks one and a valid
    /// answer came in time (the request sent at the round's start, or one sent now with
    /// `recently_hidden`, the plans ahead and the round's fleet); counts the decision or the
    /// fallback.
    fn ask_external(
        &mut self,
        round: u64,
        k: u64,
        recently_hidden: &sets::raster::CellSet,
        others: &[protocol::wire::PlannedView],
        fleet: &[u32],
    ) -> Option<protocol::plan::Answer> {
        let mut planner = self.external.take()?;
        let asked = match self.asked.take() {
            Some(asked) => Ok(asked),
            None => planner.ask(&Request {
                header: self.request_header(round, k, 0),
                grids: &self.guidance.grids,
                increments: &self.guidance.increments,
                state: self.estimator.state(),
                recently_hidden,
                others,
                fleet,
            }),
        };
        let answer = asked.and_then(|asked| self.await_answer(&mut planner, &asked));
        match &answer {
            Ok(_) => {
                planner.answered();
                self.report.external_decisions += 1;
            }
            Err(why) => {
                planner.fell_back(*why, k);
                self.report.external_fallbacks += 1;
            }
        }
        self.external = Some(planner);
        answer.ok()
    }

    /// Sends the round's request before the token comes (`"round_start"`), without the plans
    /// ahead; the agent's turn takes its answer.
    fn ask_at_round_start(&mut self, round: u64, k: u64) {
        let Some(mut planner) = self.external.take() else {
            return;
        };
        let fleet = self.ring.fleet(round, &self.ring_live());
        let state = self.estimator.state();
        let hidden = state.hidden_history.recently_hidden();
        let asked = planner.ask(&Request {
            header: self.request_header(round, k, FLAG_ROUND_START),
            grids: &self.guidance.grids,
            increments: &self.guidance.increments,
            state,
            recently_hidden: &hidden,
            others: &[],
            fleet: &fleet,
        });
        // Without a planner now, the turn asks again (and falls back if there is still none).
        self.asked = asked.ok();
        self.external = Some(planner);
    }

    /// Waits for the answer to `asked`, at most `timing.external_planner_ms` from now; a
    /// planner that died is noticed at the next listing of the run's nodes, which cleans its
    /// node and with it its server.
    fn await_answer(
        &mut self,
        planner: &mut ExternalPlanner,
        asked: &Asked,
    ) -> Result<protocol::plan::Answer, Fallback> {
        let deadline = Instant::now() + self.config.timeouts.planner;
        loop {
            if let Some(answer) = planner.poll(asked) {
                return answer;
            }
            if Instant::now() >= deadline || self.stopping() || self.end_of_run {
                return Err(Fallback::Late);
            }
            self.wait(
                deadline.min(Instant::now() + WAIT_SLICE),
                phase::WAIT_PLANNER,
            );
            self.refresh_live_if_stale();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_liveness_listing_slows_down_with_the_fleet() {
        let ms = |uavs| liveness_scan_period(uavs).as_millis();
        assert_eq!([ms(0), ms(1), ms(4)], [250, 250, 250]);
        assert_eq!([ms(5), ms(8), ms(16), ms(64)], [500, 500, 1000, 4000]);
    }
}
