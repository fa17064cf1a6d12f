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
//! The observer's thread is a loop ([`spawn`]) over a few parts, each in its own module:
//! its ports on the run's services (`ports`), the reception of the agents' estimates as an
//! agent receives them (`reception`), the measurement of a step (`measure`, which
//! [`Measurer`] offers without ports to a fleet that runs in the caller's process), what the
//! sinks are shown (`showing`) and the record it hands back ([`ObserverReport`], `report`). The loop owns the order of everything: what is
//! read when, when a step is acknowledged, measured and shown.
//!
//! Signals are left to the tokio side ([`SignalHandlingMode::Disabled`]).

mod measure;
pub mod metrics;
mod ports;
mod reception;
mod report;
mod showing;
pub mod sink;
pub mod tally;

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use fleet_process::resources::{CpuClock, PhaseClock};
use iceoryx2::prelude::{SignalHandlingMode, WaitSet};
use protocol::ipc::{Ipc, RunNode, scan_nodes, wait_for_wake};
use protocol::scenario::Scenario;
use protocol::service::RunId;
use protocol::wire::{
    DropReason, HELLO_STEP, TruthState, UavMask, WireHeader, WireKind, unix_now_ns,
};
use tokio::sync::mpsc::UnboundedSender;

pub use measure::Measurer;
use metrics::SetMetrics;
use ports::Ports;
use reception::Reception;
pub use report::{FinalState, ObserverEnd, ObserverReport};
use showing::Showing;
use sink::SinkMaker;
use tally::ServiceKind;

/// What the observer needs to know about the run.
pub struct ObserverConfig {
    /// The run.
    pub run: RunId,
    /// The run's scenario (the grids, the fleet).
    pub scenario: Scenario,
    /// Longest wait for the agents' estimates of a step.
    pub estimate_wait: Duration,
    /// What the wait adds at step 0, as the world's ack wait does
    /// ([`Timeouts::first_step_extra`](protocol::timeouts::Timeouts::first_step_extra)).
    pub first_step_extra: Duration,
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
    /// Mean over [`StepMetrics::agents`], `None` when no estimate of the step arrived. Under
    /// windows its UA and OA are the fleet's ([`metrics::fleet_areas`]).
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

/// The observer thread: builds its sinks and ports, runs the loop, ends the sinks.
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
    let showing = Showing::new(sinks, config.shown_uav);
    let ports =
        Ports::open(&node, uavs, showing.camera()).context("cannot open the observer's ports")?;
    let waitset = node.waitset()?;
    let _guard = waitset
        .attach_notification(&ports.wake)
        .context("cannot wait on the observer's wake-up event")?;
    let reception = Reception::new(&config.scenario);
    let mut observer = Observer {
        config,
        run_tag: config.run.tag(),
        ports: &ports,
        waitset: &waitset,
        stop,
        events,
        report: ObserverReport::new(uavs, reception.oem_grid()),
        truths: VecDeque::new(),
        next_fault: 0,
        end_of_run: false,
        first_truth: None,
        clock,
        reception,
        showing,
    };
    let ended = observer.main_loop();
    observer.showing.finish(&mut observer.report);
    ended?;
    observer.report.phases = observer.clock.times();
    Ok(observer.report)
}

/// The observer's loop and its state: the run's ports, the truths not yet processed, the
/// faults, the clock of its time, and the parts it hands each message to.
struct Observer<'a> {
    /// The run.
    config: &'a ObserverConfig,
    /// The tag of the run's messages ([`RunId::tag`]).
    run_tag: u64,
    /// The observer's ports.
    ports: &'a Ports,
    /// Waits on [`Ports::wake`].
    waitset: &'a WaitSet<Ipc>,
    /// Raised by the orchestrator to end the loop.
    stop: &'a AtomicBool,
    /// To the tokio side.
    events: &'a UnboundedSender<ObserverEvent>,
    /// What the observer gathered so far.
    report: ObserverReport,
    /// Truths received, not yet processed, in order.
    truths: VecDeque<TruthState>,
    /// The next of [`ObserverConfig::fault_times`] not yet due.
    next_fault: usize,
    /// Whether the world announced the end of the run.
    end_of_run: bool,
    /// When the first truth of the run arrived.
    first_truth: Option<Instant>,
    /// Where the thread's time goes ([`phase`]).
    clock: PhaseClock,
    /// The agents' estimates, received as an agent receives them.
    reception: Reception,
    /// What the run is shown to.
    showing: Showing,
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
        self.ports.send_ack(self.run_tag, step, restarted)
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
                        self.report.drop_message("truth", DropReason::OtherRun);
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
                        self.showing.frame(frame, &mut self.clock);
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

    /// Hands every pending message of agent `idx`'s estimate service to the reception.
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
            let changed = self
                .reception
                .receive(sender, sample, self.run_tag, &mut self.report);
            self.showing.note_map(changed);
        }
    }

    /// Counts the guidance tokens and hands them to the showing, which reads their plans if a
    /// sink shows them.
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
                self.report.drop_message("token", reason);
                continue;
            }
            self.showing.token(sample.payload(), &mut self.report);
            drop(sample);
            self.report.comms.count_timed(
                ServiceKind::Tokens,
                (len + std::mem::size_of::<WireHeader>()) as u64,
                header.sent_unix_ns,
                unix_now_ns(),
            );
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
        let wait = match k {
            0 => self.config.estimate_wait + self.config.first_step_extra,
            _ => self.config.estimate_wait,
        };
        let deadline = Instant::now() + wait;
        let mut last_scan = Instant::now();
        loop {
            self.drain();
            awaited.retain(|&uav| !self.reception.has(uav, k));
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
        if let Some(t) = self.first_truth {
            self.report.stepping = Some(t.elapsed());
        }
        // The receiver is gone only when the tokio side gave up on the run.
        let _ = self.events.send(ObserverEvent::Step(step));
        Ok(())
    }

    /// Measures step `truth.step` ([`measure::measure_step`]), shows it to the sinks and
    /// returns its metrics.
    fn measure(&mut self, truth: &TruthState, live_agents: u32) -> StepMetrics {
        let (step, all_fused) =
            measure::measure_step(&mut self.reception, truth, live_agents, &mut self.report);
        self.showing
            .show_fused(truth, &all_fused, &step, &mut self.clock, &mut self.report);
        measure::keep_final_state(&mut self.report, truth, all_fused);
        step
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
