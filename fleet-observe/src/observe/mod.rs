//! The observer: a dedicated thread with its own iceoryx2 node ([`RunNode::OBSERVER`]) that
//! reads the truth, every agent's estimates and the guidance token, computes the metrics of
//! each step ([`metrics`]), checks the guarantee, and acknowledges each step to a lockstep
//! world that waits for it (`world-server --wait-observer`).
//!
//! iceoryx2 ports are not `Send`, so everything lives on this thread; the tokio side gets one
//! [`ObserverEvent::Step`] per step over a channel and the [`ObserverReport`] when the thread
//! ends (at the world's end of run, or when told to stop).
//!
//! Per truth step `k`: wait (bounded) until every agent the world sent frame `k` to has
//! published its estimate of `k` (agents publish before they ack, so it is normally there
//! already; an agent whose node died is not waited for), let the orchestrator apply the
//! faults due at that time ([`ObserverEvent::FaultsDue`]), ack `k`, then fuse and measure,
//! and check each agent's own estimate against the truth while the world renders the next
//! step. In lockstep a killed agent is gone before frame `k + 1`, so fault runs are
//! reproducible too.
//!
//! What is measured ([`metrics`] has the details):
//! - **per agent**, on the sets that agent holds after its own fusion of the step (its
//!   estimate fused with those of the peers it fuses, by the agents' law and the agents' own
//!   radio: range, loss and latency, [`protocol::radio`]; with a latency of `d`
//!   steps the observer keeps the estimates of the last `d` steps it measured):
//!   explored, UA, OA, target-set area, localisation error, identified count
//!   ([`StepMetrics::agents`]), summarised as the mean over agents ([`StepMetrics::mean`])
//!   and the worst agent ([`StepMetrics::worst`]);
//! - **fleet-wide**: guarantee violations (each published estimate against the truth), the
//!   targets identified by any agent ([`StepMetrics::identified_any`]), traffic, and the
//!   fleet's map (every map update merged).
//!
//! What is shown: each measured step goes to the run's [`sink::Sink`]s
//! ([`ObserverConfig::sinks`]: the Foxglove viewer, `run.gif`), with the camera frames of the
//! UAV a sink asks for (the observer subscribes to that UAV's frames, lossy like every frame
//! subscriber) and the guidance token's plans (decoded then). Sinks only read what was
//! measured: the run is the same with them or without.
//!
//! Signals are left to the tokio side ([`SignalHandlingMode::Disabled`]).

pub mod metrics;
pub mod sink;
pub mod tally;

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use estimator::EstimateReadError;
use estimator::EstimatorConfig;
use estimator::fusion::SharedSet;
use estimator::message::{self, EstimateInbox, PeerMessage};
use estimator::occupancy::OccupancyMap;
use fleet_process::resources::{CpuClock, PhaseClock, PhaseTimes};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{SignalHandlingMode, WaitSet};
use protocol::codec;
use protocol::frame::CvsFrame;
use protocol::ipc::{
    EventService, Ipc, PubSubService, RunNode, WakeEvent, WireService, WireSubscriber, scan_nodes,
    wait_for_wake,
};
use protocol::radio::Radio;
use protocol::scenario::{Exchange, Scenario};
use protocol::service::RunId;
use protocol::wire::{
    DropReason, GuidanceToken, HELLO_STEP, ObserverAck, PlannedView, TargetTruth, TruthState,
    UavCommand, UavMask, WireHeader, WireKind, unix_now_ns,
};
use tokio::sync::mpsc::UnboundedSender;

use metrics::{
    AgentSpread, EstimateObserveError, FusedSets, ObservedEstimate, SetMetrics, identified_ids,
    violations,
};
use sink::{Sink, SinkMaker, StepView};
use tally::{AgentTally, Comms, ServiceKind};

/// What the observer needs to know about the run.
pub struct ObserverConfig {
    /// The run.
    pub run: RunId,
    /// The run's scenario (the grids, the fleet).
    pub scenario: Scenario,
    /// Longest wait for the agents' estimates of a step.
    pub estimate_wait: Duration,
    /// Simulated times at which faults are due, ascending.
    pub fault_times: Vec<f64>,
    /// Longest wait for the orchestrator to apply due faults.
    pub fault_wait: Duration,
    /// Agents the orchestrator continued (SIGCONT) since the last ack, bit `i` for UAV `i`.
    /// The next ack announces them to the world as it does restarts, so a lockstep world
    /// that skipped a stopped agent waits for it before its next frame instead of running on.
    pub resumed: Arc<AtomicU64>,
    /// What the run is shown to (Foxglove, `run.gif`).
    pub sinks: Vec<SinkMaker>,
    /// The UAV whose sets are shown (the lowest id's when its estimate of a step is missing).
    pub shown_uav: u32,
}

/// The metrics of one step.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepMetrics {
    /// Step.
    pub step: u64,
    /// Simulated time, seconds.
    pub time_s: f64,
    /// Agents the world sent this step's frame to.
    pub live_agents: u32,
    /// Estimates of this step the metrics were computed from.
    pub estimates: u32,
    /// Each agent's set metrics on its own fused sets, by UAV (the agents whose estimate of
    /// the step arrived).
    pub agents: BTreeMap<u32, SetMetrics>,
    /// Mean over [`StepMetrics::agents`], `None` when no estimate of the step arrived.
    pub mean: Option<SetMetrics>,
    /// Worst agent, metric by metric, `None` when no estimate of the step arrived.
    pub worst: Option<SetMetrics>,
    /// Targets identified by at least one agent (fleet-wide).
    pub identified_any: u32,
    /// Truth-outside-set events this step.
    pub violations: u32,
}

impl StepMetrics {
    /// Whether the estimate of `uav` of this step arrived in time to be measured: the
    /// agents of [`StepMetrics::agents`] are exactly those whose estimate of the step the
    /// observer received before it measured the step (a late one is dropped).
    pub fn estimated_by(&self, uav: u32) -> bool {
        self.agents.contains_key(&uav)
    }

    /// The agents whose estimate of this step arrived in time, ascending.
    pub fn estimated(&self) -> impl Iterator<Item = u32> + '_ {
        self.agents.keys().copied()
    }
}

/// What the observer tells the tokio side.
#[derive(Debug)]
pub enum ObserverEvent {
    /// A step was measured and acknowledged.
    Step(StepMetrics),
    /// Faults are due at `time_s` (step `step`): apply them, then send on `done`. The observer
    /// acknowledges the step only then (or after its bounded wait).
    FaultsDue {
        /// The step.
        step: u64,
        /// Its simulated time.
        time_s: f64,
        /// Signalled once the faults are applied, with the mask of the agents restarted (bit
        /// `i` for UAV `i`): the world waits for their hellos before the next step.
        done: std::sync::mpsc::Sender<UavMask>,
    },
}

/// How the observer's loop ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObserverEnd {
    /// The world announced the end of the run and every truth received was processed.
    EndOfRun,
    /// The orchestrator stopped it.
    Stopped,
}

/// One agent's final knowledge, for the pictures.
#[derive(Clone, Debug)]
pub struct FinalState {
    /// Step.
    pub step: u64,
    /// Simulated time, seconds.
    pub time_s: f64,
    /// The agent whose sets these are (the lowest id measured at that step).
    pub uav: u32,
    /// That agent's fused sets of the step.
    pub sets: FusedSets,
    /// The targets' truth at that step.
    pub targets: Vec<TargetTruth>,
}

/// Everything the observer gathered, returned when its thread ends.
#[derive(Clone, Debug)]
pub struct ObserverReport {
    /// Truth steps processed.
    pub steps: u64,
    /// How it ended.
    pub end: ObserverEnd,
    /// Per agent.
    pub agents: BTreeMap<u32, AgentTally>,
    /// Traffic per service kind.
    pub comms: Comms,
    /// Messages the observer could not use, by reason.
    pub dropped: BTreeMap<String, u64>,
    /// The last measured step's fused sets of one agent.
    pub final_state: Option<FinalState>,
    /// Per agent, its last measured step and its `X̄` after that step's fusion as the
    /// observer rebuilt it: an agent whose run ended there holds the same set.
    pub final_undetected: BTreeMap<u32, (u64, SharedSet)>,
    /// The fleet's map: every map update of every estimate merged.
    pub oem: OccupancyMap,
    /// Each UAV's ground track (x, y) per step.
    pub tracks: Vec<Vec<[f64; 2]>>,
    /// Every UAV's true pose at every step processed (`tracks.csv`).
    pub poses: Vec<crate::results::tracks::UavPose>,
    /// Per UAV, the steps at which the world's geofence overrode its agent's command
    /// ([`protocol::wire::UavTruth::geofence_override`]).
    pub geofence_overrides: Vec<u64>,
    /// Wall time from the first truth to the last step's ack.
    pub stepping: Option<Duration>,
    /// Where the observer thread's time went ([`phase`]): thread CPU and wall time.
    pub phases: PhaseTimes,
    /// The files the sinks made (`run.gif`), to be written into the run's output.
    pub files: Vec<sink::SinkFile>,
    /// Why an essential sink (the recording or the live view) failed, if one did.
    pub sink_failure: Option<String>,
}

/// What the observer says once it has started.
#[derive(Clone, Debug, Default)]
pub struct ObserverStarted {
    /// The live view's address, with `--live`.
    pub live_url: Option<String>,
}

/// The phases of the observer thread's time ([`ObserverReport::phases`]).
pub mod phase {
    /// Receiving and decoding estimates, measuring the steps.
    pub const OBSERVE: &str = "observe";
    /// Waiting for truths and estimates, and for faults to be applied.
    pub const WAIT: &str = "observe_wait";
    /// Everything else on the observer thread (acks, node scans, start-up).
    pub const OTHER: &str = "observe_other";
    /// Showing the run in Foxglove (`--record`, `--live`).
    pub const VIEW: &str = "observe_view";
    /// Drawing `run.gif`.
    pub const ANIMATION: &str = "observe_animation";
}

/// Starts the observer thread and returns once its iceoryx2 node exists (and the viewer it
/// was asked for started), so the run has a node listed before any child starts: if the
/// fleet is then killed, the node is listed dead and the next run cleans the run's files at
/// once (a run with files but no node listed counts as starting). Events go to `events`; the
/// thread ends at the world's end of run or once `stop` is raised (checked every few tens of
/// milliseconds).
pub fn spawn(
    mut config: ObserverConfig,
    stop: Arc<AtomicBool>,
    events: UnboundedSender<ObserverEvent>,
) -> anyhow::Result<(JoinHandle<anyhow::Result<ObserverReport>>, ObserverStarted)> {
    let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel(1);
    let thread = std::thread::Builder::new()
        .name("observer".into())
        .spawn(move || {
            let sinks = std::mem::take(&mut config.sinks);
            observe(&config, sinks, &stop, &events, &ready_tx)
        })
        .context("cannot start the observer thread")?;
    match ready_rx.recv() {
        Ok(started) => Ok((thread, started)),
        // The thread ended before its node existed: its result says why.
        Err(_) => match thread.join() {
            Ok(Err(e)) => Err(e),
            Ok(Ok(_)) => Err(anyhow::anyhow!("the observer ended before it started")),
            Err(_) => Err(anyhow::anyhow!("the observer thread panicked")),
        },
    }
}

/// Longest single wait, so the stop flag is noticed promptly.
const WAIT_SLICE: Duration = Duration::from_millis(20);
/// Interval of hellos until the first truth arrives.
const HELLO_INTERVAL: Duration = Duration::from_millis(200);
/// Interval of node scans while waiting for estimates.
const SCAN_INTERVAL: Duration = Duration::from_millis(100);
/// Steps of estimates kept per agent ahead of the truth being processed.
const MAX_STORED_STEPS: usize = 64;

struct Ports {
    truth: Subscriber<Ipc, TruthState, ()>,
    estimates: Vec<(u32, WireSubscriber)>,
    tokens: WireSubscriber,
    /// The shown UAV's camera frames, when a viewer is on.
    frames: Option<Subscriber<Ipc, CvsFrame, ()>>,
    ack: Publisher<Ipc, ObserverAck, ()>,
    world_wake: Notifier<Ipc>,
    wake: Listener<Ipc>,
    _services: Services,
}

/// The services the ports belong to, kept open as long as the ports.
struct Services {
    _truth: PubSubService<TruthState>,
    _estimates: Vec<WireService>,
    _guidance: WireService,
    _ack: PubSubService<ObserverAck>,
    _events: Vec<EventService>,
    _frames: Option<PubSubService<CvsFrame>>,
}

impl Ports {
    /// The observer's ports; with `camera`, also a subscriber to that UAV's frames.
    fn open(node: &RunNode, uavs: u32, camera: Option<u32>) -> anyhow::Result<Ports> {
        let truth_service = node.open_truth()?;
        let truth = truth_service.subscriber_builder().create()?;
        let mut estimate_services = Vec::new();
        let mut estimates = Vec::new();
        for uav in 0..uavs {
            let s = node.open_estimate(uav)?;
            estimates.push((uav, s.subscriber_builder().create()?));
            estimate_services.push(s);
        }
        let guidance = node.open_guidance()?;
        let tokens = guidance.subscriber_builder().create()?;
        let ack_service = node.open_observer_ack()?;
        let ack = ack_service.publisher_builder().create()?;
        let world = node.open_world_wake()?;
        let world_wake = world.notifier_builder().create()?;
        let own = node.open_observer_wake()?;
        let wake = own.listener_builder().create()?;
        let frame_service = camera.map(|uav| node.open_cvs(uav)).transpose()?;
        let frames = frame_service
            .as_ref()
            .map(|s| s.subscriber_builder().create())
            .transpose()?;
        Ok(Ports {
            truth,
            estimates,
            tokens,
            frames,
            ack,
            world_wake,
            wake,
            _services: Services {
                _truth: truth_service,
                _estimates: estimate_services,
                _guidance: guidance,
                _ack: ack_service,
                _events: vec![world, own],
                _frames: frame_service,
            },
        })
    }
}

fn observe(
    config: &ObserverConfig,
    makers: Vec<SinkMaker>,
    stop: &AtomicBool,
    events: &UnboundedSender<ObserverEvent>,
    ready: &std::sync::mpsc::SyncSender<ObserverStarted>,
) -> anyhow::Result<ObserverReport> {
    let clock = PhaseClock::new(CpuClock::Thread, phase::OTHER);
    let uavs = config.scenario.uavs.count;
    let node = RunNode::new(&config.run, RunNode::OBSERVER, SignalHandlingMode::Disabled)
        .context("cannot create the observer's iceoryx2 node")?;
    // The city, for the sinks (the same the world builds).
    let city = world_server::World::city(&config.scenario)
        .context("cannot rebuild the city for the run's views")?;
    let buildings = &city.buildings;
    let mut sinks = Vec::new();
    for make in makers {
        if let Some(sink) = make(&config.scenario, buildings).map_err(|e| anyhow::anyhow!(e))? {
            sinks.push(sink);
        }
    }
    let started = ObserverStarted {
        live_url: sinks.iter().find_map(|s| s.live_url()),
    };
    // The spawner waits for this; it is gone only if the spawner is.
    let _ = ready.send(started);
    drop(city);
    let camera = sinks.iter().find_map(|s| s.camera());
    let ports = Ports::open(&node, uavs, camera).context("cannot open the observer's ports")?;
    let waitset = node.waitset()?;
    let _guard = waitset
        .attach_notification(&ports.wake)
        .context("cannot wait on the observer's wake-up event")?;
    let estimator = EstimatorConfig::from_scenario(&config.scenario);
    let mut observer = Observer {
        radio: Radio::from_scenario(&config.scenario),
        sent: BTreeMap::new(),
        config,
        run_tag: config.run.tag(),
        ports: &ports,
        waitset: &waitset,
        stop,
        events,
        report: ObserverReport {
            steps: 0,
            end: ObserverEnd::Stopped,
            agents: BTreeMap::new(),
            comms: Comms::default(),
            dropped: BTreeMap::new(),
            final_state: None,
            final_undetected: BTreeMap::new(),
            oem: OccupancyMap::new(estimator.oem_grid),
            tracks: vec![Vec::new(); uavs as usize],
            poses: Vec::new(),
            geofence_overrides: vec![0; uavs as usize],
            stepping: None,
            phases: PhaseTimes::new(),
            files: Vec::new(),
            sink_failure: None,
        },
        estimator,
        truths: VecDeque::new(),
        store: BTreeMap::new(),
        inbox: EstimateInbox::new(),
        exchange: config.scenario.comms.exchange,
        next_fault: 0,
        end_of_run: false,
        first_truth: None,
        clock,
        camera,
        shows_plans: sinks.iter().any(|s| s.shows_plans()),
        sinks,
        plans: (0, BTreeMap::new()),
        oem_changed: false,
    };
    let ended = observer.main_loop();
    observer.finish_showing();
    ended?;
    observer.report.phases = observer.clock.times();
    Ok(observer.report)
}

struct Observer<'a> {
    config: &'a ObserverConfig,
    run_tag: u64,
    ports: &'a Ports,
    waitset: &'a WaitSet<Ipc>,
    stop: &'a AtomicBool,
    events: &'a UnboundedSender<ObserverEvent>,
    estimator: EstimatorConfig,
    report: ObserverReport,
    truths: VecDeque<TruthState>,
    /// Decoded estimates per agent, by step, not yet measured.
    store: BTreeMap<u32, BTreeMap<u64, ObservedEstimate>>,
    /// The agents' links.
    radio: Radio,
    /// With a latency of `d` steps, the estimates of the last `d` steps measured, by step:
    /// those the agents fuse in the next `d` steps.
    sent: BTreeMap<u64, Vec<ObservedEstimate>>,
    /// The agents' last sets, the bases of their deltas.
    inbox: EstimateInbox,
    /// What the agents' estimates carry (`comms.exchange`).
    exchange: Exchange,
    next_fault: usize,
    end_of_run: bool,
    first_truth: Option<Instant>,
    clock: PhaseClock,
    /// What the run is shown to.
    sinks: Vec<Box<dyn Sink>>,
    /// The UAV whose camera frames a sink shows.
    camera: Option<u32>,
    /// Whether a sink shows the guidance plans.
    shows_plans: bool,
    /// The newest guidance round seen and its plans, by UAV (the first plan seen of each).
    plans: (u64, BTreeMap<u32, PlannedView>),
    /// Whether the fleet's map changed since the last step shown.
    oem_changed: bool,
}

impl Observer<'_> {
    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    fn main_loop(&mut self) -> anyhow::Result<()> {
        let mut last_hello: Option<Instant> = None;
        loop {
            if self.stopping() {
                self.report.end = ObserverEnd::Stopped;
                return Ok(());
            }
            if self.first_truth.is_none()
                && last_hello.is_none_or(|t| t.elapsed() >= HELLO_INTERVAL)
            {
                self.send_ack(HELLO_STEP, 0)?;
                last_hello = Some(Instant::now());
            }
            self.drain();
            if let Some(truth) = self.truths.pop_front() {
                self.process(&truth)?;
                continue;
            }
            if self.end_of_run {
                self.report.end = ObserverEnd::EndOfRun;
                return Ok(());
            }
            self.wait(WAIT_SLICE);
        }
    }

    /// Waits for a wake-up at most `timeout`; notes the end of the run.
    fn wait(&mut self, timeout: Duration) {
        let before = self.clock.enter(phase::WAIT);
        let woken = wait_for_wake(self.waitset, &self.ports.wake, timeout);
        self.clock.enter(before);
        match woken {
            Ok(wake) => self.end_of_run |= wake.end_of_run,
            Err(e) => {
                tracing::warn!(error = ?e, "observer wait failed");
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    }

    fn send_ack(&self, step: u64, restarted: UavMask) -> anyhow::Result<()> {
        self.ports
            .ack
            .send_copy(ObserverAck {
                run_tag: self.run_tag,
                step,
                restarted,
            })
            .context("cannot send the observer's ack")?;
        if let Err(e) = self
            .ports
            .world_wake
            .notify_with_custom_event_id(WakeEvent::ObserverAck.id())
        {
            tracing::debug!(error = ?e, "cannot wake the world");
        }
        Ok(())
    }

    /// Reads everything pending: truths into the queue, estimates decoded into the store,
    /// tokens counted.
    fn drain(&mut self) {
        let before = self.clock.enter(phase::OBSERVE);
        self.drain_all();
        self.clock.enter(before);
    }

    fn drain_all(&mut self) {
        loop {
            match self.ports.truth.receive() {
                Ok(Some(sample)) => {
                    let truth = *sample.payload();
                    drop(sample);
                    if truth.run_tag == self.run_tag {
                        self.first_truth.get_or_insert_with(Instant::now);
                        self.report.comms.count(
                            ServiceKind::Truth,
                            1,
                            std::mem::size_of::<TruthState>() as u64,
                        );
                        self.truths.push_back(truth);
                    } else {
                        self.drop_message("truth", DropReason::OtherRun);
                    }
                }
                Ok(None) => break,
                Err(e) => {
                    tracing::warn!(error = ?e, "cannot receive truth");
                    break;
                }
            }
        }
        for idx in 0..self.ports.estimates.len() {
            self.drain_estimates(idx);
        }
        self.drain_tokens();
        self.drain_frames();
    }

    /// Hands the shown UAV's frames of this run to the sinks that show them.
    fn drain_frames(&mut self) {
        let Some(frames) = &self.ports.frames else {
            return;
        };
        loop {
            match frames.receive() {
                Ok(Some(sample)) => {
                    let frame = sample.payload();
                    if frame.header.run_tag == self.run_tag && frame.is_well_formed() {
                        for sink in &mut self.sinks {
                            if sink.camera() == self.camera {
                                let before = self.clock.enter(sink.phase());
                                sink.frame(frame);
                                self.clock.enter(before);
                            }
                        }
                    }
                }
                Ok(None) => return,
                Err(e) => {
                    tracing::warn!(error = ?e, "cannot receive the shown UAV's frames");
                    return;
                }
            }
        }
    }

    /// Counts a dropped message as `{what}:{reason}` (e.g. `estimate:other-run`).
    fn drop_message(&mut self, what: &str, reason: DropReason) {
        let key = format!("{what}:{}", reason.label());
        *self.report.dropped.entry(key).or_default() += 1;
    }

    fn drain_estimates(&mut self, idx: usize) {
        let (sender, sub) = &self.ports.estimates[idx];
        let sender = *sender;
        loop {
            let sample = match sub.receive() {
                Ok(Some(s)) => s,
                Ok(None) => return,
                Err(e) => {
                    tracing::warn!(error = ?e, uav = sender, "cannot receive estimates");
                    return;
                }
            };
            let header = *sample.user_header();
            let len = sample.payload().len();
            // Under the measurement exchange the agents' sets come in state messages, for the
            // observers only; their estimates carry measurements, for the traffic and the map.
            let (kind, service) = match self.exchange {
                Exchange::Measurements if header.kind == WireKind::State as u32 => {
                    (WireKind::State, ServiceKind::States)
                }
                _ => (WireKind::Estimate, ServiceKind::Estimates),
            };
            self.report.comms.count_timed(
                service,
                (len + std::mem::size_of::<WireHeader>()) as u64,
                header.sent_unix_ns,
                unix_now_ns(),
            );
            if let Err(reason) = header.check(len, kind, self.run_tag, Some(sender)) {
                drop(sample);
                self.drop_estimate(sender, reason);
                continue;
            }
            if self.exchange == Exchange::Measurements && kind == WireKind::Estimate {
                let read = message::from_bytes(sample.payload())
                    .map_err(EstimateReadError::from)
                    .and_then(|msg| PeerMessage::from_msg(&msg, &self.estimator).map(|_| msg));
                drop(sample);
                match read {
                    Ok(msg) if msg.uav == sender => {
                        let tally = self.report.agents.entry(sender).or_default();
                        tally.observe_message(msg.step, msg.incarnation, msg.seq, msg.stats);
                        for u in &msg.oem {
                            if let Ok((index, cell)) =
                                OccupancyMap::cell_of_update(&self.estimator.oem_grid, u)
                            {
                                self.oem_changed |= self.report.oem.merge_cell(index, cell);
                            }
                        }
                    }
                    Ok(_) => self.drop_estimate(sender, DropReason::Sender),
                    Err(err) => {
                        tracing::warn!(uav = sender, error = %err, "unreadable estimate dropped");
                        self.drop_estimate(sender, err.drop_reason());
                    }
                }
                continue;
            }
            let decoded =
                ObservedEstimate::read(&mut self.inbox, sample.payload(), &self.estimator);
            drop(sample);
            match decoded {
                Ok((e, _)) if e.uav() != sender => {
                    self.drop_estimate(sender, DropReason::Sender);
                    tracing::warn!(
                        uav = sender,
                        claims = e.uav(),
                        "estimate of another UAV dropped"
                    );
                }
                Ok((e, map)) => {
                    self.oem_changed |= self.report.oem.merge(&map);
                    if self.exchange == Exchange::Sets {
                        self.report.agents.entry(sender).or_default().observe(&e);
                    }
                    let steps = self.store.entry(sender).or_default();
                    steps.insert(e.step(), e);
                    while steps.len() > MAX_STORED_STEPS {
                        steps.pop_first();
                    }
                }
                Err(EstimateObserveError::Read(err)) => {
                    tracing::warn!(uav = sender, error = %err, "unreadable estimate dropped");
                    self.drop_estimate(sender, err.drop_reason());
                }
            }
        }
    }

    fn drop_estimate(&mut self, uav: u32, reason: DropReason) {
        self.report.agents.entry(uav).or_default().estimates_dropped += 1;
        self.drop_message("estimate", reason);
    }

    fn drain_tokens(&mut self) {
        loop {
            let sample = match self.ports.tokens.receive() {
                Ok(Some(s)) => s,
                Ok(None) => return,
                Err(e) => {
                    tracing::warn!(error = ?e, "cannot receive tokens");
                    return;
                }
            };
            let header = *sample.user_header();
            let len = sample.payload().len();
            // Any agent may send the token: the sender is not checked.
            if let Err(reason) = header.check(len, WireKind::Token, self.run_tag, None) {
                drop(sample);
                self.drop_message("token", reason);
                continue;
            }
            if self.shows_plans {
                match codec::decode::<GuidanceToken>(sample.payload()) {
                    Ok(token) => self.note_plans(token),
                    Err(e) => {
                        tracing::warn!(error = %e, "unreadable token");
                        self.drop_message("token", DropReason::Malformed);
                    }
                }
            }
            drop(sample);
            self.report.comms.count_timed(
                ServiceKind::Tokens,
                (len + std::mem::size_of::<WireHeader>()) as u64,
                header.sent_unix_ns,
                unix_now_ns(),
            );
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

    /// Ends every sink, keeping the files they made.
    fn finish_showing(&mut self) {
        for sink in std::mem::take(&mut self.sinks) {
            let essential = sink.essential();
            match sink.finish() {
                Ok(file) => self.report.files.extend(file),
                Err(e) => self.sink_failed(essential, &*e),
            }
        }
    }

    /// Shows a measured step to every sink; a sink that fails is abandoned.
    fn show(&mut self, truth: &TruthState, sets: Option<(u32, &FusedSets)>, step: &StepMetrics) {
        let view = StepView {
            truth,
            sets,
            oem: &self.report.oem,
            oem_changed: std::mem::take(&mut self.oem_changed),
            plans: &self.plans.1,
            metrics: step,
        };
        let mut failed = Vec::new();
        for (i, sink) in self.sinks.iter_mut().enumerate() {
            let before = self.clock.enter(sink.phase());
            if let Err(e) = sink.step(&view) {
                failed.push((i, e));
            }
            self.clock.enter(before);
        }
        for (i, e) in failed.into_iter().rev() {
            let sink = self.sinks.remove(i);
            self.sink_failed(sink.essential(), &*e);
        }
    }

    /// Logs a sink's failure; an essential sink's fails the run.
    fn sink_failed(&mut self, essential: bool, e: &(dyn std::error::Error + Send + Sync)) {
        if essential {
            tracing::error!(error = %e, "a view of the run failed");
            self.report
                .sink_failure
                .get_or_insert_with(|| e.to_string());
        } else {
            tracing::warn!(error = %e, "a view of the run abandoned");
        }
    }

    /// Measures one truth step, applies due faults and acks it.
    fn process(&mut self, truth: &TruthState) -> anyhow::Result<()> {
        let k = truth.step;
        let mut awaited: Vec<u32> = truth
            .uavs()
            .iter()
            .filter(|u| u.agent_live != 0)
            .map(|u| u.id)
            .collect();
        let live_agents = awaited.len() as u32;
        let deadline = Instant::now() + self.config.estimate_wait;
        let mut last_scan = Instant::now();
        loop {
            self.drain();
            awaited.retain(|uav| !self.store.get(uav).is_some_and(|s| s.contains_key(&k)));
            if awaited.is_empty() || self.stopping() {
                break;
            }
            let now = Instant::now();
            if now >= deadline {
                tracing::warn!(step = k, missing = ?awaited, "estimates did not arrive in time");
                break;
            }
            if now.duration_since(last_scan) >= SCAN_INTERVAL {
                last_scan = now;
                if let Ok(scan) = scan_nodes(&self.config.run, false) {
                    awaited.retain(|&uav| scan.is_alive(&RunNode::agent_name(uav)));
                }
            }
            self.wait(WAIT_SLICE.min(deadline - now));
        }
        if self.stopping() {
            return Ok(());
        }
        // Faults first (a killed agent is gone before frame k + 1), then the ack, so the world
        // renders the next step while this one is measured.
        let restarted = self.apply_faults(truth) | self.config.resumed.swap(0, Ordering::AcqRel);
        self.send_ack(k, restarted)?;
        let before = self.clock.enter(phase::OBSERVE);
        let step = self.measure(truth, live_agents);
        self.clock.enter(before);
        self.report.steps += 1;
        if let Some(t) = self.first_truth {
            self.report.stepping = Some(t.elapsed());
        }
        // The receiver is gone only when the tokio side gave up on the run.
        let _ = self.events.send(ObserverEvent::Step(step));
        Ok(())
    }

    /// Measures step `truth.step`: checks and fuses the agents' estimates, counts the step's
    /// traffic, shows the step to the sinks and returns its metrics.
    fn measure(&mut self, truth: &TruthState, live_agents: u32) -> StepMetrics {
        let k = truth.step;
        let estimates = self.take_estimates(k);
        let violation_count = self.check_guarantee(truth, &estimates);
        let (all_fused, agents) = self.fuse_and_measure(truth, &estimates);
        let spread = AgentSpread::over(agents.values());
        let estimate_count = estimates.len() as u32;
        let identified_any = identified_ids(&estimates).len() as u32;
        self.keep_sent(k, estimates);
        self.record_fleet(truth, live_agents);
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
        self.show_fused(truth, all_fused, &step);
        step
    }

    /// Takes every agent's estimate of step `k` out of the store, dropping older ones.
    fn take_estimates(&mut self, k: u64) -> Vec<ObservedEstimate> {
        self.store
            .values_mut()
            .filter_map(|steps| {
                let e = steps.remove(&k);
                // Older steps will never be measured now.
                steps.retain(|&s, _| s > k);
                e
            })
            .collect()
    }

    /// Checks every estimate against the truth, logs each violation and returns their count.
    fn check_guarantee(&self, truth: &TruthState, estimates: &[ObservedEstimate]) -> u32 {
        let k = truth.step;
        let grid = self.estimator.grid;
        let mut violation_count = 0;
        for e in estimates {
            for v in violations(e, truth.targets(), &grid) {
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

    /// Fuses each agent's sets as the agent did (with the estimates its links delivered),
    /// keeps its `X̄` as its last, and measures them against the truth.
    fn fuse_and_measure(
        &mut self,
        truth: &TruthState,
        estimates: &[ObservedEstimate],
    ) -> (Vec<(u32, FusedSets)>, BTreeMap<u32, SetMetrics>) {
        let k = truth.step;
        let grid = self.estimator.grid;
        let mut agents = BTreeMap::new();
        let d = self.radio.latency_steps();
        let sent: &[ObservedEstimate] = if d == 0 {
            estimates
        } else {
            k.checked_sub(d)
                .and_then(|from| self.sent.get(&from))
                .map_or(&[], Vec::as_slice)
        };
        let all_fused = match self.exchange {
            Exchange::Sets => FusedSets::of_agents(estimates, sent, &self.estimator, &self.radio),
            // The agents' state messages hold their sets once they applied their peers'.
            Exchange::Measurements => estimates.iter().map(FusedSets::held).collect(),
        };
        let all_fused: Vec<(u32, FusedSets)> = estimates
            .iter()
            .map(ObservedEstimate::uav)
            .zip(all_fused)
            .collect();
        for (uav, fused) in &all_fused {
            self.report
                .final_undetected
                .insert(*uav, (k, fused.undetected.clone()));
            agents.insert(*uav, SetMetrics::measure(fused, truth.targets(), &grid));
        }
        (all_fused, agents)
    }

    /// With a link latency, keeps step `k`'s estimates for the steps that fuse them.
    fn keep_sent(&mut self, k: u64, estimates: Vec<ObservedEstimate>) {
        let d = self.radio.latency_steps();
        // Under the measurement exchange the agents' own state messages are measured: nothing
        // is fused later.
        if d > 0 && self.exchange == Exchange::Sets {
            // Kept for the steps `k + 1 ..= k + d`, which fuse them.
            self.sent.insert(k, estimates);
            self.sent = self.sent.split_off(&k.saturating_add(1).saturating_sub(d));
        }
    }

    /// Records the UAVs' tracks and geofence overrides and counts the step's frames and
    /// commands of the `live_agents`.
    fn record_fleet(&mut self, truth: &TruthState, live_agents: u32) {
        for u in truth.uavs() {
            if let Some(track) = self.report.tracks.get_mut(u.id as usize) {
                track.push([u.position[0], u.position[1]]);
            }
            self.report.poses.push(crate::results::tracks::UavPose {
                step: truth.step,
                time_s: truth.time_s,
                uav: u.id,
                position: u.position,
                yaw: u.yaw,
            });
            if let Some(count) = self.report.geofence_overrides.get_mut(u.id as usize) {
                *count += u64::from(u.geofence_override());
            }
        }
        self.report.comms.count(
            ServiceKind::Frames,
            u64::from(live_agents),
            u64::from(live_agents) * std::mem::size_of::<CvsFrame>() as u64,
        );
        self.report.comms.count(
            ServiceKind::Commands,
            u64::from(live_agents),
            u64::from(live_agents) * std::mem::size_of::<UavCommand>() as u64,
        );
    }

    /// Shows the step with the shown UAV's sets and keeps the lowest id's as the final state.
    fn show_fused(
        &mut self,
        truth: &TruthState,
        all_fused: Vec<(u32, FusedSets)>,
        step: &StepMetrics,
    ) {
        let k = truth.step;
        // The shown UAV's sets are shown (the lowest id's when its estimate did not arrive);
        // the lowest id comes first, and its sets are the ones drawn in `sets.png`.
        let shown = all_fused
            .iter()
            .find(|(uav, _)| *uav == self.config.shown_uav)
            .or(all_fused.first())
            .map(|(uav, fused)| (*uav, fused));
        self.show(truth, shown, step);
        if let Some((uav, sets)) = all_fused.into_iter().next() {
            self.report.final_state = Some(FinalState {
                step: k,
                time_s: truth.time_s,
                uav,
                sets,
                targets: truth.targets().to_vec(),
            });
        }
    }

    /// Lets the orchestrator apply the faults due by this step's time before the step is
    /// acked; returns the mask of the agents it restarted.
    fn apply_faults(&mut self, truth: &TruthState) -> UavMask {
        let times = &self.config.fault_times;
        let mut due = false;
        // A tiny slack so that a time written as a multiple of T is reached at that step.
        while self.next_fault < times.len() && times[self.next_fault] <= truth.time_s + 1e-9 {
            self.next_fault += 1;
            due = true;
        }
        if !due {
            return 0;
        }
        let (done, applied) = std::sync::mpsc::channel();
        let event = ObserverEvent::FaultsDue {
            step: truth.step,
            time_s: truth.time_s,
            done,
        };
        if self.events.send(event).is_err() {
            return 0;
        }
        let deadline = Instant::now() + self.config.fault_wait;
        while !self.stopping() && Instant::now() < deadline {
            let before = self.clock.enter(phase::WAIT);
            let received = applied.recv_timeout(WAIT_SLICE);
            self.clock.enter(before);
            match received {
                Ok(restarted) => return restarted,
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return 0,
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
            }
        }
        tracing::warn!(step = truth.step, "faults were not applied in time");
        0
    }
}
