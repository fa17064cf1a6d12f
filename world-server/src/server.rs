//! The world-server process loop: publishes every UAV's frame and the truth each step, collects
//! the agents' commands, and advances the [`World`].
//!
//! **Lockstep** (deterministic): at step `k` the server renders frame `k` for every live agent
//! into a loaned sample, sends it and wakes the agent; publishes truth `k` and wakes the
//! observers; then waits (at most `ack_timeout`, at step 0 `start_timeout` more, for the
//! agents' first frame and plan) until every live agent has acked `k` (a
//! [`UavCommand`] with `step == k`) and, if asked, the observer too. An agent that misses the
//! deadline is reported and skipped (no more frames) until it sends a newer command or a hello
//! (it rejoins, and is served from the next frame). Then yaw references are applied and the
//! world advances. Agents the observer reports restarted at step `k`
//! ([`ObserverAck::restarted`]) are waited for (their hello, bounded) before frame `k + 1`, so
//! a restarted agent is served from the step after its restart. Every frame carries the mask
//! of the agents served at its step ([`protocol::frame::FrameHeader::served`]).
//!
//! The waits come from [`protocol::timeouts::Timeouts`], like the agents'.
//!
//! **Rendering ahead** (lockstep): once frame `k` is out, before it waits for the acks, the
//! server steps a copy of the world to `k + 1` with the yaw references it holds and renders
//! the frames of `k + 1` into loaned samples (`Lookahead`). When the acks are in, the copy
//! *is* the next world if no ack changed a commanded yaw reference (stepping is a function of
//! the world and those references alone, compared bit for bit): it replaces the world and its
//! frames go out at once; otherwise copy and frames are dropped and the world steps and
//! renders as without them. Either way every frame is the same bits. The frames are rendered
//! while the agents estimate, instead of after the last of them acked. At steps where agents
//! decide (a multiple of the guidance period), acks bring new references, so nothing is
//! rendered ahead then.
//!
//! Where the process's time goes is in [`ServerReport::phases`] ([`phase`]): CPU time of the
//! whole process (rendering runs on a pool of threads that the stepping thread waits for) and
//! wall time, per phase.
//!
//! **Realtime**: the world advances every `T / speedup` of wall time and applies the commands
//! that arrived meanwhile; nobody is waited for.
//!
//! In both modes the nodes of the run are scanned every step (and during waits), so an agent
//! killed by SIGKILL is detected at once by iceoryx2's node monitoring, not after a timeout; its
//! stale resources are removed. Every service is lossy (safe overflow), so the world never
//! blocks on a dead or stopped subscriber.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use fleet_process::resources::{CpuClock, PhaseClock, PhaseTimes, own_peak_rss_kb};
use iceoryx2::prelude::*;
use iceoryx2::sample_mut::SampleMut;
use protocol::frame::CvsFrame;
use protocol::ipc::{self, EventService, Ipc, IpcOpenError, PubSubService, RunNode, WakeEvent};
use protocol::scenario::Scenario;
use protocol::service::RunId;
use protocol::timeouts::Timeouts;
use protocol::wire::{
    HELLO_STEP, MAX_UAVS, ObserverAck, TruthState, UavCommand, UavMask, uav_bit, uavs_in,
};
use serde::Serialize;

use crate::World;
use crate::error::WorldBuildError;

/// How the world steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StepMode {
    /// Wait for every live agent's ack of each step (deterministic).
    Lockstep,
    /// Advance every `T / speedup` of wall time.
    Realtime {
        /// Simulated seconds per wall second.
        speedup: f64,
    },
}

/// Everything a world-server run needs.
#[derive(Clone, Debug)]
pub struct ServerConfig {
    /// The run: prefixes every service and file.
    pub run_id: RunId,
    /// The scenario.
    pub scenario: Scenario,
    /// Lockstep or realtime.
    pub mode: StepMode,
    /// UAV indices that have an agent.
    pub expected_agents: Vec<u32>,
    /// Whether lockstep waits for an observer's hello and acks.
    pub wait_for_observer: bool,
    /// Longest wait for the hellos at start, and for an agent the observer reports restarted.
    pub start_timeout: Duration,
    /// Longest wait for the acks of one step (lockstep).
    pub ack_timeout: Duration,
}

impl ServerConfig {
    /// A lockstep run of every UAV of `scenario`, without observer, with the waits of
    /// `timeouts` (and the external planner's budget the scenario gives,
    /// [`Timeouts::for_scenario`]).
    pub fn new(run_id: RunId, scenario: Scenario, timeouts: &Timeouts) -> ServerConfig {
        ServerConfig {
            run_id,
            expected_agents: (0..scenario.uavs.count).collect(),
            ack_timeout: timeouts.for_scenario(&scenario).ack(),
            scenario,
            mode: StepMode::Lockstep,
            wait_for_observer: false,
            start_timeout: timeouts.start(),
        }
    }
}

/// Why a world-server run failed.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    /// The configuration does not fit the scenario.
    #[error(transparent)]
    Config(#[from] ServerConfigError),
    /// The world cannot be built from the scenario.
    #[error("bad scenario: {0}")]
    World(#[from] WorldBuildError),
    /// The run's node, services or ports could not be opened.
    #[error(transparent)]
    Open(#[from] IpcOpenError),
}

impl ServerError {
    /// Whether the error is the caller's (a configuration or scenario that cannot run), as
    /// opposed to a failure of the run.
    pub fn is_usage(&self) -> bool {
        matches!(self, ServerError::Config(_) | ServerError::World(_))
    }
}

/// Why a [`ServerConfig`] was refused.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ServerConfigError {
    /// An expected agent's index is not a UAV of the scenario.
    #[error("--agents: UAV {uav} does not exist (the scenario has UAVs 0..{count})")]
    UnknownAgent {
        /// The index given.
        uav: u32,
        /// UAVs in the scenario.
        count: u32,
    },
    /// The fleet is larger than the wire format allows.
    #[error("uavs.count: {0} UAVs exceed the largest fleet of {MAX_UAVS}")]
    TooManyUavs(u32),
    /// The realtime speedup is not a positive finite number.
    #[error("--speedup: must be a positive finite number, got {0}")]
    Speedup(f64),
}

impl ServerConfig {
    /// Checks the config against its scenario.
    pub fn validate(&self) -> Result<(), ServerConfigError> {
        let count = self.scenario.uavs.count;
        if count as usize > MAX_UAVS {
            return Err(ServerConfigError::TooManyUavs(count));
        }
        if let Some(&uav) = self.expected_agents.iter().find(|&&u| u >= count) {
            return Err(ServerConfigError::UnknownAgent { uav, count });
        }
        if let StepMode::Realtime { speedup } = self.mode
            && !(speedup.is_finite() && speedup > 0.0)
        {
            return Err(ServerConfigError::Speedup(speedup));
        }
        Ok(())
    }
}

/// What happened to one agent during a run.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct AgentReport {
    /// UAV index.
    pub uav: u32,
    /// Whether it said hello (at start or later).
    pub said_hello: bool,
    /// Steps it acked in time.
    pub acks: u64,
    /// Steps it missed (ack timeout in lockstep; no ack before the next step in realtime).
    pub misses: u64,
    /// Times it rejoined after being skipped or after dying.
    pub rejoins: u64,
    /// Times its process was found dead.
    pub deaths: u64,
    /// Commands ignored because they answered an older step.
    pub stale_commands: u64,
    /// Commands ignored because they carried another run's tag or another UAV's index.
    pub foreign_commands: u64,
    /// Frames that could not be loaned or sent.
    pub send_failures: u64,
    /// Frames rendered ahead (`Lookahead`) and sent.
    pub frames_ahead: u64,
    /// Frames rendered ahead and dropped: an ack changed a yaw reference, or the agent was
    /// no longer served.
    pub frames_ahead_dropped: u64,
}

/// The outcome of a run.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ServerReport {
    /// Steps simulated (frames published per live agent).
    pub steps: u64,
    /// Wall time of the stepping, seconds.
    pub wall_s: f64,
    /// Whether the run was stopped early (shutdown flag, SIGTERM, SIGINT).
    pub interrupted: bool,
    /// Per expected agent.
    pub agents: Vec<AgentReport>,
    /// Steps the observer acked in time (when waited for).
    pub observer_acks: u64,
    /// Steps the observer missed (when waited for).
    pub observer_misses: u64,
    /// This process's id, so that whoever started it can join this report to the kernel's
    /// account of the process.
    pub pid: u32,
    /// Where the process's time went ([`phase`]): process CPU time and wall time per phase,
    /// from opening the world to the end of the run.
    pub phases: PhaseTimes,
    /// The process's own peak resident memory at the end of the run, KiB
    /// ([`own_peak_rss_kb`]: without the memory of whoever spawned it); `None` if it could not
    /// be read.
    pub peak_rss_kb: Option<u64>,
}

/// The phases of the world-server's time ([`ServerReport::phases`]).
pub mod phase {
    /// Rendering the frames into their samples and sending them.
    pub const RENDER: &str = "render";
    /// Publishing the truth and waking the processes.
    pub const PUBLISH: &str = "publish";
    /// Waiting for hellos and acks (lockstep) or for the next tick (realtime).
    pub const WAIT: &str = "wait";
    /// Listing the run's nodes (who is alive).
    pub const SCAN: &str = "scan";
    /// Advancing the world by a step (cars, UAVs).
    pub const ADVANCE: &str = "advance";
    /// Everything else (building the world, commands, acks).
    pub const OTHER: &str = "other";
}

/// Runs the world of `config` until the last step or `shutdown`.
pub fn run(config: ServerConfig, shutdown: &AtomicBool) -> Result<ServerReport, ServerError> {
    config.validate()?;
    let clock = PhaseClock::new(CpuClock::Process, phase::OTHER);
    let world = World::new(&config.scenario)?;
    let run = config.run_id.clone();
    if let Ok(dead) = ipc::cleanup_stale(&run)
        && !dead.is_empty()
    {
        tracing::info!(?dead, "removed stale resources of dead nodes");
    }
    let node = RunNode::new(
        &run,
        RunNode::WORLD,
        SignalHandlingMode::HandleTerminationRequests,
    )?;
    let ports = Ports::open(&node, world.uav_count() as u32)?;
    let waitset = node.waitset()?;
    let _guard = waitset
        .attach_notification(&ports.wake)
        .map_err(IpcOpenError::from)?;
    let mut server = Server {
        run_tag: run.tag(),
        run,
        world,
        ports: &ports,
        waitset: &waitset,
        agents: (0..MAX_UAVS as u32)
            .map(|uav| Link {
                expected: config.expected_agents.contains(&uav),
                report: AgentReport {
                    uav,
                    ..AgentReport::default()
                },
                ..Link::default()
            })
            .collect(),
        observer: ObserverLink {
            expected: config.wait_for_observer,
            ..ObserverLink::default()
        },
        published: None,
        restarted: 0,
        start_timeout: config.start_timeout,
        interrupted: false,
        shutdown,
        clock,
        ahead: None,
    };
    let started = Instant::now();
    server.start(config.start_timeout);
    let steps = config.scenario.steps();
    let mut done = 0;
    if !server.interrupted {
        done = match config.mode {
            StepMode::Lockstep => server.lockstep(steps, config.ack_timeout),
            StepMode::Realtime { speedup } => server.realtime(steps, speedup),
        };
    }
    server.end_of_run();
    let wall_s = started.elapsed().as_secs_f64();
    let report = ServerReport {
        steps: done,
        wall_s,
        interrupted: server.interrupted,
        agents: server
            .agents
            .iter()
            .filter(|a| a.expected || a.report.said_hello)
            .map(|a| a.report.clone())
            .collect(),
        observer_acks: server.observer.acks,
        observer_misses: server.observer.misses,
        pid: std::process::id(),
        phases: server.clock.times(),
        peak_rss_kb: own_peak_rss_kb(),
    };
    tracing::info!(
        steps = report.steps,
        wall_s = report.wall_s,
        interrupted = report.interrupted,
        "run ended"
    );
    Ok(report)
}

/// The world's ports. Frames and commands exist for every UAV of the scenario.
struct Ports {
    cvs: Vec<iceoryx2::port::publisher::Publisher<Ipc, CvsFrame, ()>>,
    cmd: Vec<iceoryx2::port::subscriber::Subscriber<Ipc, UavCommand, ()>>,
    agent_wake: Vec<iceoryx2::port::notifier::Notifier<Ipc>>,
    truth: iceoryx2::port::publisher::Publisher<Ipc, TruthState, ()>,
    observer_ack: iceoryx2::port::subscriber::Subscriber<Ipc, ObserverAck, ()>,
    observer_wake: iceoryx2::port::notifier::Notifier<Ipc>,
    wake: iceoryx2::port::listener::Listener<Ipc>,
    // Keep the services open for the ports' lifetime.
    _services: Services,
}

struct Services {
    _cvs: Vec<PubSubService<CvsFrame>>,
    _cmd: Vec<PubSubService<UavCommand>>,
    _events: Vec<EventService>,
    _truth: PubSubService<TruthState>,
    _observer_ack: PubSubService<ObserverAck>,
}

impl Ports {
    fn open(node: &RunNode, uavs: u32) -> Result<Ports, IpcOpenError> {
        let mut services = Services {
            _cvs: Vec::new(),
            _cmd: Vec::new(),
            _events: Vec::new(),
            _truth: node.open_truth()?,
            _observer_ack: node.open_observer_ack()?,
        };
        let (mut cvs, mut cmd, mut agent_wake) = (Vec::new(), Vec::new(), Vec::new());
        for uav in 0..uavs {
            let s = node.open_cvs(uav)?;
            cvs.push(s.publisher_builder().max_loaned_samples(1).create()?);
            services._cvs.push(s);
            let s = node.open_cmd(uav)?;
            cmd.push(s.subscriber_builder().create()?);
            services._cmd.push(s);
            let s = node.open_agent_wake(uav)?;
            agent_wake.push(s.notifier_builder().create()?);
            services._events.push(s);
        }
        let truth = services._truth.publisher_builder().create()?;
        let observer_ack = services._observer_ack.subscriber_builder().create()?;
        let s = node.open_observer_wake()?;
        let observer_wake = s.notifier_builder().create()?;
        services._events.push(s);
        let s = node.open_world_wake()?;
        let wake = s.listener_builder().create()?;
        services._events.push(s);
        Ok(Ports {
            cvs,
            cmd,
            agent_wake,
            truth,
            observer_ack,
            observer_wake,
            wake,
            _services: services,
        })
    }
}

/// The world's view of one agent.
#[derive(Default)]
struct Link {
    expected: bool,
    /// Frames go to it and its ack is awaited.
    live: bool,
    /// Newest step it answered (hello excluded).
    last_step: Option<u64>,
    /// Newest step whose frame it was sent: only that frame's ack is awaited, so an agent
    /// that (re)joins while a step is out is awaited from the next one.
    sent: Option<u64>,
    /// The incarnation of the agent's process that last spoke.
    incarnation: Option<u64>,
    report: AgentReport,
}

#[derive(Default)]
struct ObserverLink {
    expected: bool,
    live: bool,
    last_step: Option<u64>,
    acks: u64,
    misses: u64,
}

struct Server<'a> {
    run: RunId,
    run_tag: u64,
    world: World,
    ports: &'a Ports,
    waitset: &'a WaitSet<Ipc>,
    agents: Vec<Link>,
    observer: ObserverLink,
    /// Newest step whose frames went out.
    published: Option<u64>,
    /// Agents the observer reported restarted and the world has not heard from since.
    restarted: UavMask,
    start_timeout: Duration,
    interrupted: bool,
    shutdown: &'a AtomicBool,
    /// Where the time goes ([`phase`]).
    clock: PhaseClock,
    /// The next step being rendered while this one's acks are awaited.
    ahead: Option<Lookahead>,
}

/// The world one step ahead and its frames, rendered while the acks of the current step are
/// awaited (lockstep; see the module docs).
struct Lookahead {
    /// The world stepped on with `refs`.
    world: World,
    /// Every UAV's commanded yaw reference when the copy was stepped, as bits.
    refs: Vec<u64>,
    /// Frames of the next step by UAV, rendered and not sent.
    frames: Vec<Option<SampleMut<Ipc, CvsFrame, ()>>>,
}

/// Every UAV's commanded yaw reference, as bits (what stepping the UAVs reads besides their
/// state).
fn commanded_refs(world: &World) -> Vec<u64> {
    world
        .uavs()
        .iter()
        .map(|u| u.commanded_yaw_ref.to_bits())
        .collect()
}

/// Longest single wait, so the shutdown flag and dead processes are noticed promptly.
const WAIT_SLICE: Duration = Duration::from_millis(50);

impl Server<'_> {
    fn uavs(&self) -> usize {
        self.world.uav_count()
    }

    /// Waits for the hellos of every expected agent (and the observer if asked).
    fn start(&mut self, timeout: Duration) {
        let deadline = Instant::now() + timeout;
        loop {
            self.drain_commands(None);
            self.drain_observer(None);
            let agents_ready = self
                .agents
                .iter()
                .all(|a| !a.expected || a.report.said_hello);
            let observer_ready = !self.observer.expected || self.observer.live;
            if agents_ready && observer_ready {
                return;
            }
            if !self.wait_until(deadline) {
                break;
            }
        }
        if self.interrupted {
            return;
        }
        for a in self
            .agents
            .iter()
            .filter(|a| a.expected && !a.report.said_hello)
        {
            tracing::warn!(
                uav = a.report.uav,
                "agent never said hello; running without it"
            );
        }
        if self.observer.expected && !self.observer.live {
            tracing::warn!("observer never said hello; running without waiting for it");
        }
    }

    fn lockstep(&mut self, steps: u64, ack_timeout: Duration) -> u64 {
        for k in 0..steps {
            if self.stop_requested() {
                return k;
            }
            self.check_liveness();
            // Late acks and hellos of the previous step: an agent skipped for missing it
            // rejoins here, and is served frame `k`.
            self.drain_commands(None);
            self.drain_observer(None);
            self.wait_for_restarted();
            if self.interrupted {
                return k;
            }
            self.publish(k);
            // The next frames are rendered anyway before the next step: now, while the agents
            // work, unless the acks may change the references they depend on.
            self.look_ahead(k, steps);
            // The first step is every agent's first frame, the token's first pass round the
            // ring and, over hosts, the first messages through bridges still connecting: it is
            // waited for as long again as the hellos are ([`Timeouts::first_step_extra`]).
            let wait = if k == 0 {
                ack_timeout + self.start_timeout
            } else {
                ack_timeout
            };
            let deadline = Instant::now() + wait;
            loop {
                self.drain_commands(Some(k));
                self.drain_observer(Some(k));
                if self.all_acked(k) {
                    break;
                }
                if !self.wait_until(deadline) {
                    if self.interrupted {
                        return k;
                    }
                    self.report_misses(k);
                    break;
                }
            }
            self.advance();
        }
        steps
    }

    fn realtime(&mut self, steps: u64, speedup: f64) -> u64 {
        let period = Duration::from_secs_f64(self.world.scenario().timing.cvs_period_s / speedup);
        let start = Instant::now();
        for k in 0..steps {
            if self.stop_requested() {
                return k;
            }
            self.check_liveness();
            if k > 0 {
                // A live agent that has not answered the previous frame missed it.
                for a in self.agents.iter_mut().filter(|a| a.live) {
                    if a.sent == Some(k - 1) && a.last_step != Some(k - 1) {
                        a.report.misses += 1;
                    }
                }
            }
            self.publish(k);
            let next = start + period.mul_f64((k + 1) as f64);
            loop {
                self.drain_commands(Some(k));
                self.drain_observer(Some(k));
                if !self.wait_until(next) {
                    break;
                }
            }
            if self.interrupted {
                return k;
            }
            self.drain_commands(Some(k));
            self.advance();
        }
        steps
    }

    /// Steps the world; the [`Lookahead`]'s copy is the stepped world when no yaw reference
    /// changed since it was made, and its frames are kept for [`Server::publish`].
    fn advance(&mut self) {
        let before = self.clock.enter(phase::ADVANCE);
        match self.ahead.take() {
            Some(mut ahead) if ahead.refs == commanded_refs(&self.world) => {
                std::mem::swap(&mut self.world, &mut ahead.world);
                self.ahead = Some(ahead);
            }
            stale => {
                if let Some(ahead) = stale {
                    self.drop_frames_ahead(ahead);
                }
                self.world.advance();
            }
        }
        self.clock.enter(before);
    }

    /// Steps a copy of the world to `k + 1` and renders its frames for the live agents,
    /// unless `k + 1` is past the run or `k` is a step at which agents decide (their acks
    /// then bring new yaw references).
    fn look_ahead(&mut self, k: u64, steps: u64) {
        let per_guidance = self.world.scenario().steps_per_guidance();
        if k + 1 >= steps || k.is_multiple_of(per_guidance) || !self.agents.iter().any(|a| a.live) {
            return;
        }
        let before = self.clock.enter(phase::ADVANCE);
        let mut world = self.world.clone();
        world.advance();
        self.clock.enter(before);
        let before = self.clock.enter(phase::RENDER);
        let frames = (0..self.uavs())
            .map(|uav| {
                if !self.agents[uav].live {
                    return None;
                }
                // A frame that cannot be loaned now is rendered when published.
                render_frame(&self.ports.cvs[uav], &world, uav, self.run_tag)
                    .inspect_err(|e| tracing::debug!(uav, error = %e, "cannot render ahead"))
                    .ok()
            })
            .collect();
        self.clock.enter(before);
        self.ahead = Some(Lookahead {
            refs: commanded_refs(&self.world),
            frames,
            world,
        });
    }

    /// Counts the unsent frames of `ahead` as dropped (they return to the pool).
    fn drop_frames_ahead(&mut self, ahead: Lookahead) {
        for (uav, frame) in ahead.frames.into_iter().enumerate() {
            if frame.is_some() {
                self.agents[uav].report.frames_ahead_dropped += 1;
            }
        }
    }

    fn stop_requested(&mut self) -> bool {
        if self.shutdown.load(Ordering::Relaxed) {
            self.interrupted = true;
        }
        self.interrupted
    }

    /// Waits for a wake-up until `deadline` (in slices, checking liveness and the shutdown
    /// flag); false once the deadline passed or the run was interrupted.
    fn wait_until(&mut self, deadline: Instant) -> bool {
        if self.stop_requested() {
            return false;
        }
        let now = Instant::now();
        if now >= deadline {
            return false;
        }
        let slice = (deadline - now).min(WAIT_SLICE);
        let before = self.clock.enter(phase::WAIT);
        let waited = ipc::wait_for_wake(self.waitset, &self.ports.wake, slice);
        self.clock.enter(before);
        let woken = match waited {
            Ok(wake) if wake.interrupted => {
                tracing::info!("termination requested");
                self.interrupted = true;
                return false;
            }
            Ok(wake) => wake.woken,
            Err(e) => {
                tracing::warn!(error = %e, "wait failed");
                std::thread::sleep(slice.min(Duration::from_millis(5)));
                false
            }
        };
        if !woken {
            self.check_liveness();
        }
        true
    }

    /// Waits (bounded by the start timeout) until every agent the observer reported restarted
    /// said hello, so that it is served from the next frame.
    fn wait_for_restarted(&mut self) {
        if self.restarted == 0 {
            return;
        }
        let deadline = Instant::now() + self.start_timeout;
        loop {
            self.drain_commands(None);
            let waiting: Vec<u32> = uavs_in(self.restarted)
                .filter(|&u| !self.agents.get(u as usize).is_some_and(|a| a.live))
                .collect();
            if waiting.is_empty() {
                break;
            }
            if !self.wait_until(deadline) {
                if !self.interrupted {
                    tracing::warn!(?waiting, "restarted agents did not say hello in time");
                }
                break;
            }
        }
        self.restarted = 0;
    }

    /// Marks agents whose process died as not live (and cleans their resources).
    fn check_liveness(&mut self) {
        let before = self.clock.enter(phase::SCAN);
        let scanned = ipc::scan_nodes(&self.run, true);
        self.clock.enter(before);
        let scan = match scanned {
            Ok(scan) => scan,
            Err(e) => {
                tracing::warn!(error = %e, "cannot list the run's nodes");
                return;
            }
        };
        if !scan.dead.is_empty() {
            tracing::info!(dead = ?scan.dead, "removed stale resources of dead nodes");
        }
        for a in self.agents.iter_mut().filter(|a| a.live) {
            if !scan.is_alive(&RunNode::agent_name(a.report.uav)) {
                tracing::warn!(uav = a.report.uav, "agent process died");
                a.live = false;
                a.report.deaths += 1;
            }
        }
        if self.observer.live && !scan.is_alive(RunNode::OBSERVER) {
            tracing::warn!("observer process died");
            self.observer.live = false;
        }
    }

    /// Reads every pending command; `current` is the step whose acks are awaited (None between
    /// steps: a command answering a published step then rejoins a skipped agent, without
    /// counting as an ack in time).
    fn drain_commands(&mut self, current: Option<u64>) {
        for uav in 0..self.uavs() {
            loop {
                let cmd = match self.ports.cmd[uav].receive() {
                    Ok(Some(sample)) => *sample.payload(),
                    Ok(None) => break,
                    Err(e) => {
                        tracing::warn!(uav, error = %e, "cannot receive commands");
                        break;
                    }
                };
                self.handle_command(uav, cmd, current);
            }
        }
    }

    fn handle_command(&mut self, uav: usize, cmd: UavCommand, current: Option<u64>) {
        let link = &mut self.agents[uav];
        if cmd.run_tag != self.run_tag || cmd.uav as usize != uav {
            link.report.foreign_commands += 1;
            return;
        }
        if link.incarnation.is_some_and(|i| cmd.incarnation < i) {
            // Left behind by a process that was replaced.
            link.report.stale_commands += 1;
            return;
        }
        if link.incarnation != Some(cmd.incarnation) {
            // A new process of this agent: the previous one is gone, even if its death was not
            // noticed yet, and whatever it was sent is no longer awaited.
            if link.incarnation.is_some() {
                tracing::info!(uav, "agent restarted");
                if link.live {
                    link.report.deaths += 1;
                    link.live = false;
                }
            }
            link.incarnation = Some(cmd.incarnation);
            link.last_step = None;
            link.sent = None;
        }
        if cmd.step == HELLO_STEP {
            if !link.report.said_hello {
                tracing::info!(uav, "agent said hello");
            } else if !link.live {
                tracing::info!(uav, "agent rejoined");
                link.report.rejoins += 1;
            }
            link.report.said_hello = true;
            link.live = true;
            return;
        }
        let newer = link.last_step.is_none_or(|s| cmd.step > s);
        let answers_sent_frame = self.published.is_some_and(|k| cmd.step <= k);
        if !newer || !answers_sent_frame {
            link.report.stale_commands += 1;
            return;
        }
        if !link.live {
            tracing::info!(uav, step = cmd.step, "agent rejoined");
            link.report.rejoins += 1;
            link.report.said_hello = true;
            link.live = true;
        }
        link.last_step = Some(cmd.step);
        if current == Some(cmd.step) {
            link.report.acks += 1;
        }
        if cmd.has_yaw_ref != 0 {
            self.world.set_yaw_ref(uav, cmd.yaw_ref_rad);
        }
    }

    fn drain_observer(&mut self, current: Option<u64>) {
        loop {
            let ack = match self.ports.observer_ack.receive() {
                Ok(Some(sample)) => *sample.payload(),
                Ok(None) => break,
                Err(e) => {
                    tracing::warn!(error = %e, "cannot receive observer acks");
                    break;
                }
            };
            let obs = &mut self.observer;
            if ack.run_tag != self.run_tag {
                continue;
            }
            if ack.step == HELLO_STEP {
                obs.live = true;
                continue;
            }
            if obs.last_step.is_none_or(|s| ack.step > s)
                && self.published.is_some_and(|k| ack.step <= k)
            {
                obs.live = true;
                obs.last_step = Some(ack.step);
                self.restarted |= ack.restarted;
                if current == Some(ack.step) {
                    obs.acks += 1;
                }
            }
        }
    }

    fn all_acked(&self, k: u64) -> bool {
        let agents = self
            .agents
            .iter()
            .all(|a| !a.live || a.sent != Some(k) || a.last_step == Some(k));
        let observer =
            !self.observer.expected || !self.observer.live || self.observer.last_step == Some(k);
        agents && observer
    }

    fn report_misses(&mut self, k: u64) {
        for a in self
            .agents
            .iter_mut()
            .filter(|a| a.live && a.sent == Some(k) && a.last_step != Some(k))
        {
            tracing::warn!(
                uav = a.report.uav,
                step = k,
                "agent missed the ack deadline; skipped until it answers"
            );
            a.report.misses += 1;
            a.live = false;
        }
        let obs = &mut self.observer;
        if obs.expected && obs.live && obs.last_step != Some(k) {
            tracing::warn!(step = k, "observer missed the ack deadline");
            obs.misses += 1;
            obs.live = false;
        }
    }

    /// Renders and sends frame `k` to every live agent, then truth `k`.
    fn publish(&mut self, k: u64) {
        debug_assert_eq!(self.world.step(), k);
        let before = self.clock.enter(phase::PUBLISH);
        self.published = Some(k);
        let served = (0..self.uavs() as u32)
            .filter(|&u| self.agents[u as usize].live)
            .fold(0, |mask, u| mask | uav_bit(u));
        for uav in 0..self.uavs() {
            if !self.agents[uav].live {
                continue;
            }
            let ready = self.ahead.as_mut().and_then(|a| a.frames[uav].take());
            let before = self.clock.enter(phase::RENDER);
            let sent = match ready {
                Some(frame) => {
                    self.agents[uav].report.frames_ahead += 1;
                    send_rendered(frame, served)
                }
                None => self.send_frame(uav, served),
            };
            self.clock.enter(before);
            if let Err(e) = sent {
                tracing::warn!(uav, step = k, error = %e, "cannot send frame");
                self.agents[uav].report.send_failures += 1;
                continue;
            }
            self.agents[uav].sent = Some(k);
            notify(&self.ports.agent_wake[uav], WakeEvent::Frame);
        }
        match self.ports.truth.loan_uninit() {
            Ok(sample) => {
                let mut sample = sample.write_payload(TruthState::default());
                let truth = sample.payload_mut();
                self.world.truth(self.run_tag, truth);
                let n = truth.uav_count as usize;
                for (i, u) in truth.uavs.iter_mut().enumerate().take(n) {
                    u.agent_live = self.agents[i].live as u32;
                }
                if let Err(e) = sample.send() {
                    tracing::warn!(step = k, error = %e, "cannot send truth");
                }
            }
            Err(e) => tracing::warn!(step = k, error = %e, "cannot loan truth"),
        }
        notify(&self.ports.observer_wake, WakeEvent::Truth);
        if let Some(ahead) = self.ahead.take() {
            self.drop_frames_ahead(ahead);
        }
        self.clock.enter(before);
    }

    fn send_frame(&self, uav: usize, served: UavMask) -> Result<(), FrameSendError> {
        let frame = render_frame(&self.ports.cvs[uav], &self.world, uav, self.run_tag)?;
        send_rendered(frame, served)
    }

    fn end_of_run(&self) {
        for n in &self.ports.agent_wake {
            notify(n, WakeEvent::EndOfRun);
        }
        notify(&self.ports.observer_wake, WakeEvent::EndOfRun);
    }
}

/// Why a frame could not go out.
#[derive(Debug, thiserror::Error)]
enum FrameSendError {
    #[error("cannot loan a frame: {0}")]
    Loan(#[from] iceoryx2::port::LoanError),
    #[error("cannot send a frame: {0}")]
    Send(#[from] iceoryx2::port::SendError),
}

/// Renders UAV `uav`'s frame of `world` in place, into a sample loaned from `publisher`.
fn render_frame(
    publisher: &iceoryx2::port::publisher::Publisher<Ipc, CvsFrame, ()>,
    world: &World,
    uav: usize,
    run_tag: u64,
) -> Result<SampleMut<Ipc, CvsFrame, ()>, iceoryx2::port::LoanError> {
    let mut sample = publisher.loan_uninit()?;
    let frame = CvsFrame::init_in_place(sample.payload_mut());
    world.render(uav, run_tag, frame);
    // SAFETY: init_in_place initialised every byte of the payload.
    Ok(unsafe { sample.assume_init() })
}

/// Sends a rendered frame with the mask of the agents served at its step.
fn send_rendered(
    mut frame: SampleMut<Ipc, CvsFrame, ()>,
    served: UavMask,
) -> Result<(), FrameSendError> {
    frame.payload_mut().header.served = served;
    frame.send()?;
    Ok(())
}

/// Wakes listeners; a listener that is gone is not an error of the world's.
fn notify(notifier: &iceoryx2::port::notifier::Notifier<Ipc>, event: WakeEvent) {
    if let Err(e) = notifier.notify_with_custom_event_id(event.id()) {
        tracing::debug!(?event, error = %e, "notify failed");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> ServerConfig {
        ServerConfig {
            run_id: RunId::new("server-unit").unwrap(),
            scenario: Scenario::default(),
            mode: StepMode::Lockstep,
            expected_agents: vec![0, 3],
            wait_for_observer: false,
            start_timeout: Duration::from_secs(1),
            ack_timeout: Duration::from_secs(1),
        }
    }

    #[test]
    fn an_agent_that_never_says_hello_is_reported_and_the_run_still_ends() {
        let mut c = config();
        c.run_id = RunId::new(&format!("server-unit-{}", std::process::id())).unwrap();
        c.scenario.duration_s = 1.0;
        c.scenario.region.half_extent_m = 100.0;
        c.scenario.targets.count = 2;
        c.scenario.uavs.count = 2;
        c.scenario.camera.rows = 12;
        c.scenario.camera.cols = 16;
        c.expected_agents = vec![1];
        c.start_timeout = Duration::from_millis(100);
        let report = run(c.clone(), &AtomicBool::new(false)).unwrap();
        assert_eq!(report.steps, 2);
        assert!(!report.interrupted);
        assert_eq!(report.agents.len(), 1);
        assert_eq!(report.agents[0].uav, 1);
        assert!(!report.agents[0].said_hello);
        assert_eq!(report.agents[0].acks, 0);
        let _ = ipc::remove_run_files(&c.run_id);
    }

    #[test]
    fn a_raised_shutdown_flag_stops_the_run_before_stepping() {
        let mut c = config();
        c.run_id = RunId::new(&format!("server-stop-{}", std::process::id())).unwrap();
        c.scenario.region.half_extent_m = 100.0;
        c.scenario.camera.rows = 12;
        c.scenario.camera.cols = 16;
        let report = run(c.clone(), &AtomicBool::new(true)).unwrap();
        assert!(report.interrupted);
        assert_eq!(report.steps, 0);
        let _ = ipc::remove_run_files(&c.run_id);
    }

    #[test]
    fn agents_outside_the_fleet_are_refused() {
        assert_eq!(config().validate(), Ok(()));
        let mut c = config();
        c.expected_agents = vec![4];
        assert_eq!(
            c.validate(),
            Err(ServerConfigError::UnknownAgent { uav: 4, count: 4 })
        );
        c.expected_agents = vec![];
        c.mode = StepMode::Realtime { speedup: 0.0 };
        assert!(matches!(c.validate(), Err(ServerConfigError::Speedup(_))));
    }
}
