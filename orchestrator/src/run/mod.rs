//! `fleet run`: one run of the fleet as separate processes.
//!
//! [`execute`] is the whole run on a tokio runtime: it cleans what killed runs left, writes
//! the resolved scenario into the output directory (every child reads that file), starts the
//! observer thread ([`fleet_observe::observe`]), the world-server and one `uav-agent` per UAV
//! ([`children`]), then reacts to what happens until the world ends the run:
//!
//! - each measured step moves the progress display ([`progress`]);
//! - faults due at a step ([`faults`]: `--fault`s and the [`chaos`] schedule) are applied
//!   before the observer acknowledges that step, so a kill or restart is as reproducible as
//!   any lockstep run; a pause (SIGSTOP) is continued (SIGCONT) by a timer after its wall-clock
//!   duration, while the loop goes on serving events, and the continued agent is announced
//!   in the observer's next ack like a restart (the world waits for it);
//! - an agent that exits on its own is noted (the world and its peers go on without it);
//! - the world-server exiting early fails the run; Ctrl-C or SIGTERM interrupts it.
//!
//! Whatever the ending, every paused agent is continued, every child is stopped (SIGTERM,
//! then SIGKILL after a bounded grace), the run's iceoryx2 files are removed, and the
//! [`RunRecord`] holds what was measured, with each restarted or resumed agent's resync and
//! where every process's time went ([`resources`]).
//! [`command`] is `fleet run`: it executes, then writes `summary.json`, `timeseries.csv` and the
//! pictures (with `run.gif`), and prints the summary table. While the run goes on, its
//! directory holds the run's iceoryx2 configuration for iceoryx2's own tools ([`iox2`]);
//! with `--record` or `--live` the observer shows the run in Foxglove ([`fleet_observe::viewer`]).

pub mod chaos;
pub mod children;
pub mod config;
pub mod faults;
pub mod hosts;
pub mod iox2;
pub mod lifecycle;
pub mod progress;
pub mod resources;
pub mod stale;

use std::path::PathBuf;
use std::process::ExitStatus;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use bridge::endpoint::{Transport, free_loopback_port};
use protocol::ipc::cleanup_stale;
use protocol::timeouts::Timeouts;
use tokio::sync::mpsc;

use fleet_observe::faults::FaultKind;
use fleet_observe::observe::{self, ObserverConfig, ObserverEvent, ObserverReport, StepMetrics};
use fleet_observe::results::maps::AnimationSink;
use fleet_observe::results::resources::{Resources, RunSize};
use fleet_observe::results::summary::{RunFacts, Summary};
use fleet_observe::results::{curves, maps, timeseries, tracks};
use fleet_observe::viewer::Viewer;

use crate::outcome::Outcome;
use children::{Binaries, Children};
use config::RunConfig;
use faults::{DueFault, FaultPlan, PendingResume, Resumes};
use lifecycle::{EXIT_GRACE, RunDirs, Signals, clean_run_files, stop_agents_and_bridges};
use progress::Progress;
use resources::OwnUsage;

/// Longest wait for a fault to be applied before the observer acknowledges its step.
const FAULT_WAIT: Duration = Duration::from_secs(10);
/// How long the observer may go on after the world exited (it drains the last steps).
const OBSERVER_DRAIN: Duration = Duration::from_secs(5);
/// Interval of the housekeeping tick (agent exits, deadlines).
const TICK: Duration = Duration::from_millis(100);

/// Everything one run produced, for the results.
pub struct RunRecord {
    /// The run's configuration.
    pub config: RunConfig,
    /// The metrics of every measured step, in order.
    pub series: Vec<StepMetrics>,
    /// What the observer gathered (`None` if its thread failed).
    pub observer: Option<ObserverReport>,
    /// The faults and what became of them.
    pub faults: FaultPlan,
    /// Wall time of the whole run, seconds.
    pub wall_s: f64,
    /// Whether a signal interrupted the run.
    pub interrupted: bool,
    /// Why the run failed, if it did (a process could not start, the world died, ...).
    pub failure: Option<String>,
    /// Start of the run, UTC.
    pub started_utc: String,
    /// The run's iceoryx2 files still present after cleanup (0 unless something is wrong).
    pub leftover_files: usize,
    /// CPU time, peak memory and phases per process.
    pub resources: Resources,
}

impl RunRecord {
    /// Guarantee violations over the run.
    pub fn violations(&self) -> u64 {
        self.series.iter().map(|m| u64::from(m.violations)).sum()
    }

    /// What the summary reads of the run.
    pub fn facts(&self) -> RunFacts<'_> {
        let config = &self.config;
        RunFacts {
            scenario: &config.scenario,
            variant: config.variant.name(),
            mode: match config.mode {
                world_server::server::StepMode::Lockstep => "lockstep",
                world_server::server::StepMode::Realtime { .. } => "realtime",
            },
            chaos_seed: config.chaos_seed,
            hosts: config.layout.hosts().len() as u16,
            run_id: config.run_id.as_str(),
            series: &self.series,
            observer: self.observer.as_ref(),
            faults: self.faults.records(),
            wall_s: self.wall_s,
            interrupted: self.interrupted || self.failure.is_some(),
            started_utc: &self.started_utc,
            leftover_files: self.leftover_files,
            resources: &self.resources,
        }
    }

    /// The run's summary.
    pub fn summary(&self) -> Summary {
        Summary::build(&self.facts())
    }
}

/// `fleet run`: executes the run, writes its results into `config.out` and prints the
/// summary table.
pub fn command(config: &RunConfig) -> anyhow::Result<Outcome> {
    let record = runtime()?.block_on(execute(config, ""))?;
    let summary = write_results(&record)?;
    let mut out = std::io::stdout().lock();
    summary.print_table(&mut out)?;
    use std::io::Write as _;
    writeln!(out, "\nresults in {}", config.out.display())?;
    Ok(outcome(&record))
}

/// The runtime of `fleet run` and `fleet sweep`: one thread is plenty (the work is in the
/// children and the observer thread).
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("cannot start the tokio runtime")
}

/// The exit code a run deserves: failed if it did not complete, or if it saw a violation
/// under `--strict`.
pub fn outcome(record: &RunRecord) -> Outcome {
    if let Some(why) = &record.failure {
        eprintln!("fleet: the run failed: {why}");
        return Outcome::Failed;
    }
    if record.interrupted {
        eprintln!("fleet: the run was interrupted");
        return Outcome::Failed;
    }
    let violations = record.violations();
    if violations > 0 {
        eprintln!("fleet: {violations} guarantee violation(s): see the logs and summary.json");
        if record.config.strict {
            return Outcome::Failed;
        }
    }
    Outcome::Success
}

/// Writes `summary.json`, `timeseries.csv`, `tracks.csv`, `metrics.png`, `map.png`,
/// `sets.png` and `run.gif` into the run's output directory; returns the summary.
pub fn write_results(record: &RunRecord) -> anyhow::Result<Summary> {
    let out = &record.config.out;
    let scenario = &record.config.scenario;
    let summary = record.summary();
    summary.write_json(&out.join("summary.json"))?;
    timeseries::write(&record.series, &out.join("timeseries.csv"))?;
    let title = format!(
        "seed {}, {} UAVs, {} targets: mean over agents",
        scenario.seed, scenario.uavs.count, scenario.targets.count
    );
    curves::draw_run(&record.series, &title, &out.join("metrics.png"))?;
    if let Some(observer) = &record.observer {
        tracks::write(&observer.poses, &out.join("tracks.csv"))?;
        maps::draw_map(&observer.oem, scenario, &out.join("map.png"))?;
        if let Some(state) = &observer.final_state {
            maps::draw_sets(state, &observer.tracks, scenario, &out.join("sets.png"))?;
        }
        for file in &observer.files {
            let path = out.join(file.name);
            std::fs::write(&path, &file.bytes)
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
    }
    Ok(summary)
}

/// How the event loop ended.
enum Ending {
    /// The observer finished (end of run, or stopped after the world left).
    ObserverDone,
    /// SIGINT or SIGTERM.
    Signal(&'static str),
}

/// Runs the fleet once; `label` prefixes the progress lines (a sweep's variant and seed).
pub async fn execute(config: &RunConfig, label: &str) -> anyhow::Result<RunRecord> {
    let clock = RunClock::start();
    let dirs = RunDirs::prepare(
        &config.out,
        &config.scenario,
        &config.layout,
        &config.run_id,
    )?;
    let (stale_runs, stale_files) = stale::remove_stale_runs(&config.run_id);
    if stale_runs > 0 {
        tracing::info!(
            runs = stale_runs,
            files = stale_files,
            "cleaned killed runs' files"
        );
    }
    let binaries = Binaries::locate()?;
    let mut signals = Signals::take()?;
    let mut running = Running::start(config, &dirs, binaries, label)?;
    let ending = running.drive(&mut signals).await;
    Ok(running.stop(ending, clock).await)
}

/// When a run started, by the wall clock and by this process's CPU.
struct RunClock {
    started: Instant,
    started_utc: String,
    own_at_start: Option<fleet_process::resources::ProcessUsage>,
}

impl RunClock {
    fn start() -> RunClock {
        RunClock {
            started: Instant::now(),
            started_utc: fleet_process::clock::utc_now_rfc3339(),
            own_at_start: fleet_process::resources::own_usage().ok(),
        }
    }
}

/// A run under way: its processes, its faults and what the observer handed over so far.
struct Running<'a> {
    config: &'a RunConfig,
    logs: PathBuf,
    children: Children,
    plan: FaultPlan,
    resumes: Resumes,
    /// Agents continued since the observer's last ack, for the observer to announce.
    resumed: Arc<AtomicU64>,
    /// Raised to stop the observer.
    stop: Arc<AtomicBool>,
    events: mpsc::UnboundedReceiver<ObserverEvent>,
    observer: std::thread::JoinHandle<anyhow::Result<ObserverReport>>,
    progress: Progress,
    series: Vec<StepMetrics>,
    world_exit: Option<(ExitStatus, Instant)>,
    failure: Option<String>,
    /// The newest step the observer handed over (faults due, or measured), and its time.
    latest: (u64, f64),
}

impl<'a> Running<'a> {
    /// Starts the observer, the bridges of a distributed run, the world and this host's
    /// agents.
    fn start(
        config: &'a RunConfig,
        dirs: &RunDirs,
        binaries: Binaries,
        label: &str,
    ) -> anyhow::Result<Running<'a>> {
        let run = &config.run_id;
        let plan = FaultPlan::new(&config.faults);
        let resumed = Arc::new(AtomicU64::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let (events_tx, events) = mpsc::unbounded_channel();
        let timeouts = Timeouts::default().for_scenario(&config.scenario);
        let (observer, observer_started) = observe::spawn(
            ObserverConfig {
                run: run.clone(),
                scenario: config.scenario.clone(),
                // An agent killed mid-step is noticed sooner, by the node scan.
                estimate_wait: timeouts.estimate_wait(),
                first_step_extra: timeouts.first_step_extra(),
                fault_times: plan.times(),
                fault_wait: FAULT_WAIT,
                resumed: resumed.clone(),
                sinks: vec![Viewer::maker(config.view.clone()), AnimationSink::maker()],
                shown_uav: config.view.uav,
            },
            stop.clone(),
            events_tx,
        )?;
        let mut children = Children::new(
            run.clone(),
            binaries,
            dirs.scenario_file.clone(),
            dirs.logs.clone(),
            dirs.checkpoints.clone(),
            config.mode,
            config.layout.clone(),
        );
        if config.layout.is_distributed() {
            spawn_bridges(config, &mut children)?;
        }
        children.spawn_world()?;
        let mut failure = None;
        for uav in (0..config.scenario.uavs.count).filter(|&u| config.layout.is_here(u)) {
            if let Err(e) = children.spawn_agent(uav) {
                failure = Some(format!("{e:#}"));
                break;
            }
        }
        let total =
            (config.scenario.duration_s / config.scenario.timing.cvs_period_s).round() as u64;
        let progress = Progress::new(total, config.progress_bar, label);
        if let Some(url) = &observer_started.live_url {
            progress.note(&format!(
                "live view on {url}: in Foxglove, open a connection to this address"
            ));
        }
        if let Some(file) = &config.view.record {
            progress.note(&format!("recording into {}", file.display()));
        }
        if failure.is_some() {
            stop.store(true, Ordering::Relaxed);
        }
        Ok(Running {
            config,
            logs: dirs.logs.clone(),
            children,
            plan,
            resumes: Resumes::default(),
            resumed,
            stop,
            events,
            observer,
            progress,
            series: Vec::with_capacity(total as usize + 1),
            world_exit: None,
            failure,
            latest: (0, 0.0),
        })
    }

    /// Reacts to the observer, the pauses' timers, the signals and the children until the
    /// observer is done or a signal arrives.
    async fn drive(&mut self, signals: &mut Signals) -> Ending {
        let mut tick = tokio::time::interval(TICK);
        loop {
            let next_resume = self.resumes.next_due();
            // Evaluated even when disabled: any instant will do then.
            let resume_at = next_resume.unwrap_or_else(|| tokio::time::Instant::now() + TICK);
            tokio::select! {
                event = self.events.recv() => match event {
                    Some(event) => self.on_event(event).await,
                    None => return Ending::ObserverDone,
                },
                _ = tokio::time::sleep_until(resume_at), if next_resume.is_some() => {
                    self.resume_due();
                }
                name = signals.recv() => return Ending::Signal(name),
                _ = tick.tick() => self.on_tick(),
            }
        }
    }

    /// A measured step moves the progress; faults due at a step are applied before the
    /// observer acknowledges it.
    async fn on_event(&mut self, event: ObserverEvent) {
        match event {
            ObserverEvent::Step(m) => {
                if m.step >= self.latest.0 {
                    self.latest = (m.step, m.time_s);
                }
                self.progress.step(&m);
                self.series.push(m);
            }
            ObserverEvent::FaultsDue { step, time_s, done } => {
                if step >= self.latest.0 {
                    self.latest = (step, time_s);
                }
                let layout = &self.config.layout;
                let mut restarted = 0;
                for due in self.plan.due(time_s) {
                    let host_run = layout.run_on(&self.config.run_id, layout.host_of(due.uav));
                    let effective =
                        apply_fault(&mut self.children, &host_run, due, &mut self.resumes).await;
                    self.plan.applied(due.index, step, time_s, effective);
                    if effective && due.kind == FaultKind::Restart {
                        restarted |= protocol::wire::uav_bit(due.uav);
                    }
                    self.progress.note(&fault_note(time_s, due, effective));
                }
                // The observer may have given up waiting; then nobody listens.
                let _ = done.send(restarted);
            }
        }
    }

    /// Continues the paused agents whose pause is over.
    fn resume_due(&mut self) {
        for due in self.resumes.take_due(tokio::time::Instant::now()) {
            if self.resume(due) {
                // Announced in the observer's next ack, so the world waits for it.
                self.resumed
                    .fetch_or(protocol::wire::uav_bit(due.uav), Ordering::AcqRel);
            }
        }
    }

    /// Sends a pause's SIGCONT and notes it in the plan, with the newest step the observer
    /// handed over; whether the agent was still there to continue.
    fn resume(&mut self, due: PendingResume) -> bool {
        let (step, time_s) = self.latest;
        if self.children.resume_agent(due.uav, due.incarnation) {
            self.plan.resumed(due.index, step);
            self.progress
                .note(&format!("t={time_s:.1}s: agent {} continued", due.uav));
            true
        } else {
            tracing::warn!(uav = due.uav, "the paused agent ended before its SIGCONT");
            self.progress.note(&format!(
                "t={time_s:.1}s: agent {} ended while paused",
                due.uav
            ));
            false
        }
    }

    /// Housekeeping: the world's exit, agents that exited, the observer's drain after the
    /// world left.
    fn on_tick(&mut self) {
        if self.world_exit.is_none()
            && let Some(status) = self.children.poll_world()
        {
            if !status.success() {
                self.failure.get_or_insert_with(|| {
                    format!(
                        "the world-server exited with {status}; see {}",
                        self.logs.join("world.log").display()
                    )
                });
            }
            self.world_exit = Some((status, Instant::now()));
        }
        for exit in self.children.reap_agents() {
            // An agent exits 0 at the end of the run (or on SIGTERM), often before the world
            // is seen gone: that is no news. A killed or failed agent is.
            if exit.status.success() {
                tracing::debug!(uav = exit.uav, "agent ended");
                continue;
            }
            self.progress
                .note(&format!("agent {} exited with {}", exit.uav, exit.status));
            tracing::warn!(uav = exit.uav, status = %exit.status, "agent exited");
        }
        if let Some((_, at)) = self.world_exit
            && at.elapsed() > OBSERVER_DRAIN
        {
            self.stop.store(true, Ordering::Relaxed);
        }
    }

    /// Stops everything, the observer first (it must not wait on anyone), then the world
    /// and the agents; what the run measured.
    async fn stop(mut self, ending: Ending, clock: RunClock) -> RunRecord {
        // No process is left stopped: a pause still running ends with the run.
        for due in self.resumes.take_all() {
            self.resume(due);
        }
        self.progress.finish();
        let interrupted = matches!(ending, Ending::Signal(_));
        if let Ending::Signal(name) = ending {
            eprintln!("fleet: {name} received: stopping the run");
        }
        self.stop.store(true, Ordering::Relaxed);
        let observer = match join_observer(self.observer).await {
            Ok(report) => {
                if let Some(why) = &report.sink_failure {
                    self.failure.get_or_insert_with(|| why.clone());
                }
                Some(report)
            }
            Err(e) => {
                self.failure.get_or_insert_with(|| {
                    format!(
                        "the observer failed: {e:#}; see the logs in {}",
                        self.logs.display()
                    )
                });
                None
            }
        };
        if interrupted {
            self.children.terminate_agents();
        }
        if self.world_exit.is_none() {
            let grace = if interrupted || self.failure.is_some() {
                Duration::ZERO
            } else {
                EXIT_GRACE
            };
            match self.children.wait_world(grace).await {
                Some(status) if !status.success() && !interrupted => {
                    self.failure
                        .get_or_insert_with(|| format!("the world-server exited with {status}"));
                }
                Some(_) => {}
                None => {
                    self.children.stop_world(EXIT_GRACE).await;
                }
            }
        }
        stop_agents_and_bridges(&mut self.children, true).await;
        let run = &self.config.run_id;
        let leftover_files = self
            .config
            .layout
            .runs(run)
            .iter()
            .map(clean_run_files)
            .sum();
        if let Some(report) = &observer
            && report.end != observe::ObserverEnd::EndOfRun
            && !interrupted
        {
            self.failure.get_or_insert_with(|| {
                format!(
                    "the run ended before the world announced its end; see the logs in {}",
                    self.logs.display()
                )
            });
        }
        self.plan.measure_resync(&self.series);
        let wall_s = clock.started.elapsed().as_secs_f64();
        let own = OwnUsage {
            usage: own_usage_since(clock.own_at_start),
            observer: observer
                .as_ref()
                .map(|o| o.phases.clone())
                .unwrap_or_default(),
        };
        let steps = self.series.len() as u64;
        let scenario = &self.config.scenario;
        let size = RunSize {
            uavs: scenario.uavs.count,
            steps,
            sim_s: steps as f64 * scenario.timing.cvs_period_s,
            wall_s,
        };
        let resources = resources::gather(&own, self.children.exited(), &self.logs, size);
        RunRecord {
            config: self.config.clone(),
            series: self.series,
            observer,
            faults: self.plan,
            wall_s,
            interrupted,
            failure: self.failure,
            started_utc: clock.started_utc,
            leftover_files,
            resources,
        }
    }
}

/// Starts the bridges of a distributed run: listening on `--listen`, or on a free loopback
/// port (QUIC, or plain TCP with `--insecure-links`), with `--tls` or the run's own
/// certificates.
fn spawn_bridges(config: &RunConfig, children: &mut Children) -> anyhow::Result<()> {
    let free_port = |transport| {
        free_loopback_port(transport).context("cannot find a free loopback port for the bridges")
    };
    let endpoint = match &config.listen {
        Some(e) => e.clone(),
        None if config.insecure_links => format!("tcp/127.0.0.1:{}", free_port(Transport::Tcp)?),
        None => format!("quic/127.0.0.1:{}", free_port(Transport::Udp)?),
    };
    let tls = match &config.tls {
        _ if config.insecure_links => None,
        Some(dir) => Some(dir.clone()),
        None => Some(run_certificates(&config.layout, &config.out)?),
    };
    children.spawn_bridges(&endpoint, tls.as_deref())
}

/// A fleet authority and a certificate for every simulated host, made for this run in
/// `OUT/certs` (nothing of it outlives its use but the files, which a new run replaces).
fn run_certificates(layout: &hosts::HostLayout, out: &std::path::Path) -> anyhow::Result<PathBuf> {
    let dir = out.join("certs");
    let names: Vec<String> = layout
        .hosts()
        .iter()
        .map(|h| h.name.as_str().to_owned())
        .collect();
    bridge::security::write_fleet_certs(&dir, &names, &[], true)
        .with_context(|| format!("cannot make the run's certificates in {}", dir.display()))?;
    Ok(dir)
}

/// This process's CPU since `start` (its usage then), with its peak memory so far.
fn own_usage_since(
    start: Option<fleet_process::resources::ProcessUsage>,
) -> Option<fleet_process::resources::ProcessUsage> {
    let now = fleet_process::resources::own_usage().ok()?;
    let start = start?;
    Some(fleet_process::resources::ProcessUsage {
        user_s: (now.user_s - start.user_s).max(0.0),
        system_s: (now.system_s - start.system_s).max(0.0),
        peak_rss_kb: now.peak_rss_kb,
    })
}

/// Applies one fault to an agent of `run` (the run in its host's domain); whether it took
/// effect. A pause's SIGCONT joins `resumes`.
async fn apply_fault(
    children: &mut Children,
    run: &protocol::service::RunId,
    due: DueFault,
    resumes: &mut Resumes,
) -> bool {
    let uav = due.uav;
    match due.kind {
        FaultKind::Kill => {
            let killed = children.kill_agent(uav).await;
            // The dead node's resources go at once, not at the next scan of a peer.
            if let Err(e) = cleanup_stale(run) {
                tracing::debug!(error = %e, "cannot clean the killed agent's resources");
            }
            killed
        }
        FaultKind::Restart => match children.spawn_agent(uav) {
            Ok(()) => true,
            Err(e) => {
                tracing::error!(uav, error = %format!("{e:#}"), "cannot restart the agent");
                false
            }
        },
        FaultKind::Pause => {
            let Some(incarnation) = children.pause_agent(uav) else {
                return false;
            };
            let wall = Duration::try_from_secs_f64(due.pause_s.unwrap_or(0.0)).unwrap_or_default();
            resumes.push(PendingResume {
                index: due.index,
                uav,
                incarnation,
                due: tokio::time::Instant::now() + wall,
            });
            true
        }
    }
}

/// The progress line of an applied fault.
fn fault_note(time_s: f64, due: DueFault, effective: bool) -> String {
    let uav = due.uav;
    match (due.kind, effective) {
        (FaultKind::Kill, true) => format!("t={time_s:.1}s: agent {uav} killed"),
        (FaultKind::Restart, true) => format!("t={time_s:.1}s: agent {uav} restarted"),
        (FaultKind::Pause, true) => format!(
            "t={time_s:.1}s: agent {uav} paused for {} s",
            due.pause_s.unwrap_or(0.0)
        ),
        (kind, false) => format!(
            "t={time_s:.1}s: {} of agent {uav} not applied (no running agent)",
            kind.name()
        ),
    }
}

/// Joins the observer thread without blocking the runtime.
async fn join_observer(
    handle: std::thread::JoinHandle<anyhow::Result<ObserverReport>>,
) -> anyhow::Result<ObserverReport> {
    tokio::task::spawn_blocking(move || handle.join())
        .await
        .context("cannot join the observer thread")?
        .map_err(|_| anyhow::anyhow!("the observer thread panicked"))?
}
