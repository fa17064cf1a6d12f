//! `fleet bench ipc`: what moving setfleet's messages between processes costs, side by side,
//! every role in its own process.
//!
//! Cases, each run in fresh child processes (`fleet bench-child`, see [`roles`]):
//! - `iox-1sub`, `iox-4sub`: the 864 KB [`CvsFrame`] over iceoryx2, zero-copy: the publisher
//!   loans a sample, writes the frame in place ([`CvsFrame::init_in_place`], depth, labels,
//!   checksum) and sends it; each subscriber takes it and verifies the checksum.
//! - `socket-1sub`: the same frame over a Unix domain socket, bincode-encoded
//!   ([`protocol::codec`]) and length-prefixed: the baseline a user would otherwise pick.
//! - `estimates`: a real estimate message (built by running the fleet in-process for a few
//!   steps) all-to-all among 4 processes, round after round.
//! - `token`: the guidance token ([`protocol::wire::GuidanceToken`], encoded as the agents
//!   encode it) passed around 4 processes over the run's guidance service, each process taking
//!   its turn with [`uav_agent::guidance::TokenRing`] and appending a plan; the latency is the
//!   whole round (the first holder's send to the completed token's return), the rate counts
//!   hops.
//!
//! A process killed with SIGKILL cannot clean up after itself: the next `fleet bench ipc`
//! removes the files of bench runs whose process is gone.
//!
//! Latency is from the publisher's send start (the frame is written, the send begins) to the
//! subscriber's receipt (it holds a usable frame: the iceoryx2 sample, or the decoded socket
//! message; the checksum is verified after). The send time travels in the message as
//! `CLOCK_MONOTONIC` nanoseconds, a clock every process on the machine shares (Rust's
//! `Instant` cannot cross processes). Frame latency is measured with one frame in flight; the
//! frame rate with up to [`WINDOW`] frames in flight, each acknowledged by every subscriber, so
//! it includes writing each frame in place and checking it. Every wake-up is an iceoryx2 event
//! waited for with a `WaitSet` (the socket baseline blocks in `read`), never a busy poll.
//!
//! The run has its own [`RunId`] (its own iceoryx2 prefix); its files are removed at the end.

mod children;
pub mod roles;
mod socket;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use iceoryx2::prelude::*;
use protocol::frame::{CvsFrame, FRAME_MAX_PIXELS};
use protocol::ipc::{self as pipc, Ipc, IpcOpenError, RunNode};
use protocol::scenario::Scenario;
use protocol::service::RunId;
use serde::{Deserialize, Serialize};

use super::estimator::FleetSim;
use super::{BenchCase, BenchReport, Metrics, Stats};
use crate::usage::{ScenarioArgs, UsageError};
use children::ChildSet;
use roles::Role;

pub use roles::BenchChildArgs;

/// Frames in flight while measuring the frame rate (the real frame service buffers 2).
pub const WINDOW: u64 = 2;
/// Rows of the benchmark frame (the default camera's).
const ROWS: u32 = 360;
/// Columns of the benchmark frame.
const COLS: u32 = 480;
const _: () = assert!((ROWS * COLS) as usize == FRAME_MAX_PIXELS);
/// Processes of the all-to-all and token cases (the default fleet).
const FLEET: u32 = 4;
/// Longest wait for a child to open its ports.
const READY_TIMEOUT: Duration = Duration::from_secs(30);
/// Iterations of `--quick`.
const QUICK_ITERATIONS: u64 = 50;
/// Fleet steps simulated to build the estimate message (`--quick`: fewer).
const ESTIMATE_STEPS: u64 = 30;
const QUICK_ESTIMATE_STEPS: u64 = 3;

/// `fleet bench ipc`.
#[derive(Debug, Args)]
pub struct BenchIpcArgs {
    /// The scenario of the estimate message (default: the paper's).
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// Messages (frames, rounds) per case and phase.
    #[arg(long, default_value_t = 1000)]
    pub iterations: u64,
    /// A short run (50 iterations, a younger estimate message): checks that everything works,
    /// the figures are rough.
    #[arg(long)]
    pub quick: bool,
    /// JSON report file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// A validated `fleet bench ipc`.
#[derive(Debug, Clone)]
pub struct BenchIpcConfig {
    /// The scenario of the estimate message.
    pub scenario: Scenario,
    /// Messages per case and phase.
    pub iterations: u64,
    /// Fleet steps simulated before taking the estimate message.
    pub estimate_steps: u64,
    /// JSON report file.
    pub out: Option<PathBuf>,
}

impl BenchIpcArgs {
    /// Checks the counts.
    pub fn validate(&self) -> Result<BenchIpcConfig, UsageError> {
        let scenario = self.scenario.load()?;
        if !(1..=1_000_000).contains(&self.iterations) {
            return Err(UsageError(format!(
                "--iterations {} is out of range; accepted: 1 to 1000000",
                self.iterations
            )));
        }
        Ok(BenchIpcConfig {
            scenario,
            iterations: if self.quick {
                self.iterations.min(QUICK_ITERATIONS)
            } else {
                self.iterations
            },
            estimate_steps: if self.quick {
                QUICK_ESTIMATE_STEPS
            } else {
                ESTIMATE_STEPS
            },
            out: self.out.clone(),
        })
    }
}

/// The send time and sequence number every benchmark message carries (an iceoryx2 user
/// header).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("setfleet.bench.Stamp.v1")]
pub struct Stamp {
    /// Sequence number within the case.
    pub seq: u64,
    /// `CLOCK_MONOTONIC` at the send start, ns.
    pub sent_mono_ns: u64,
    /// Sending process's index.
    pub sender: u32,
    /// 0: latency (one message in flight); 1: rate.
    pub phase: u32,
}

/// A subscriber's acknowledgement of a frame.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("setfleet.bench.Ack.v1")]
pub struct Ack {
    /// The frame's sequence number.
    pub seq: u64,
    /// The subscriber.
    pub subscriber: u32,
    /// 1 if the checksum held.
    pub ok: u32,
}

/// The latency phase of a case.
pub const PHASE_LATENCY: u32 = 0;
/// The rate phase of a case.
pub const PHASE_RATE: u32 = 1;

/// What a child measured, printed as its last line.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ChildReport {
    /// Latencies of the messages it received in the latency phase, ns (for the token: round
    /// times measured by the round's first holder).
    pub latency_ns: Vec<u64>,
    /// Messages it sent (publishers) or received (others) in the rate phase.
    pub messages: u64,
    /// Bytes of those messages.
    pub bytes: u64,
    /// Duration of the rate phase, ns.
    pub elapsed_ns: u64,
    /// Messages whose content check failed.
    pub corrupt: u64,
}

/// `CLOCK_MONOTONIC`, ns: one clock for every process of the machine.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into the timespec we own; CLOCK_MONOTONIC always exists on
    // Linux.
    unsafe {
        libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts);
    }
    (ts.tv_sec as u64).saturating_mul(1_000_000_000) + ts.tv_nsec as u64
}

/// Writes frame `seq` into `frame` as a renderer would: header, every pixel's depth and label
/// (varying with `seq`, so a stale or torn frame fails its checksum), then the checksum.
pub fn fill_frame(frame: &mut CvsFrame, seq: u64) {
    let h = &mut frame.header;
    h.rows = ROWS;
    h.cols = COLS;
    h.step = seq;
    h.time_s = seq as f64 * 0.5;
    h.box_count = 0;
    let n = frame.pixel_count();
    let salt = (seq as u32).wrapping_mul(0x9E37_79B9);
    for (i, (d, l)) in frame.depth[..n]
        .iter_mut()
        .zip(&mut frame.labels[..n])
        .enumerate()
    {
        let v = i as u32 ^ salt;
        *d = 20.0 + (v & 0xFFFF) as f32 * 1e-3;
        *l = ((v >> 7) & 3) as u8;
    }
    frame.header.checksum = frame.checksum();
}

/// The benchmark's own services of a run, named here and nowhere else: `{run}/bench/{what}`.
pub struct BenchServices<'a> {
    node: &'a RunNode,
}

/// The frame service: the frame with a [`Stamp`].
pub type FrameService =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, CvsFrame, Stamp>;
/// The ack service.
pub type AckService = pipc::PubSubService<Ack>;
/// A variable-size message service with a [`Stamp`].
pub type StampedService =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, [u8], Stamp>;

impl<'a> BenchServices<'a> {
    /// The services of `node`'s run.
    pub fn new(node: &'a RunNode) -> Self {
        Self { node }
    }

    fn name(&self, what: &str) -> anyhow::Result<ServiceName> {
        let s = format!("{}/bench/{what}", self.node.run());
        ServiceName::new(&s).map_err(|e| anyhow::anyhow!("invalid service name {s:?}: {e:?}"))
    }

    /// `{run}/bench/frame`: one publisher, up to `FLEET` subscribers.
    pub fn frames(&self) -> anyhow::Result<FrameService> {
        let name = self.name("frame")?;
        Ok(self
            .node
            .node()
            .service_builder(&name)
            .publish_subscribe::<CvsFrame>()
            .user_header::<Stamp>()
            .max_publishers(1)
            .max_subscribers(FLEET as usize)
            .max_nodes(pipc::MAX_NODES)
            .subscriber_max_buffer_size(2 * WINDOW as usize)
            .subscriber_max_borrowed_samples(pipc::MAX_BORROWED)
            .history_size(0)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|source| IpcOpenError::PubSub {
                service: name.as_str().to_owned(),
                source,
            })?)
    }

    /// `{run}/bench/frame-ack`: every subscriber's acks to the frame publisher.
    pub fn acks(&self) -> anyhow::Result<AckService> {
        let name = self.name("frame-ack")?;
        Ok(self
            .node
            .node()
            .service_builder(&name)
            .publish_subscribe::<Ack>()
            .max_publishers(FLEET as usize)
            .max_subscribers(1)
            .max_nodes(pipc::MAX_NODES)
            // Every subscriber may have a window of acks outstanding.
            .subscriber_max_buffer_size(4 * FLEET as usize * WINDOW as usize)
            .subscriber_max_borrowed_samples(pipc::MAX_BORROWED)
            .history_size(0)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|source| IpcOpenError::PubSub {
                service: name.as_str().to_owned(),
                source,
            })?)
    }

    /// `{run}/bench/estimate/{i}`: process `i`'s estimates, with the QoS of the run's estimate
    /// services.
    pub fn estimates(&self, i: u32) -> anyhow::Result<StampedService> {
        let name = self.name(&format!("estimate/{i}"))?;
        Ok(self
            .node
            .node()
            .service_builder(&name)
            .publish_subscribe::<[u8]>()
            .user_header::<Stamp>()
            .max_publishers(1)
            .max_subscribers(FLEET as usize)
            .max_nodes(pipc::MAX_NODES)
            .subscriber_max_buffer_size(pipc::MESSAGE_BUFFER)
            .subscriber_max_borrowed_samples(pipc::MAX_BORROWED)
            .history_size(0)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|source| IpcOpenError::PubSub {
                service: name.as_str().to_owned(),
                source,
            })?)
    }

    /// `{run}/bench/{what}`: an event service (`frame-wake`, `ack-wake`).
    pub fn event(&self, what: &str) -> anyhow::Result<pipc::EventService> {
        let name = self.name(what)?;
        Ok(self
            .node
            .node()
            .service_builder(&name)
            .event()
            .max_notifiers(FLEET as usize)
            .max_listeners(FLEET as usize)
            .max_nodes(pipc::MAX_NODES)
            .open_or_create()
            .map_err(|source| IpcOpenError::Event {
                service: name.as_str().to_owned(),
                source,
            })?)
    }
}

/// Removes the run's iceoryx2 files and the bench's temp dir when the bench ends, however it
/// ends (declared before the children, so they are gone first).
struct RunFiles {
    run: RunId,
    dir: PathBuf,
}

impl Drop for RunFiles {
    fn drop(&mut self) {
        if let Err(e) = pipc::remove_run_files(&self.run) {
            tracing::warn!(error = %e, run = %self.run, "cannot remove the run's files");
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// One case: its children, as (name, role, index), started in order.
struct CaseSpec<'a> {
    name: &'a str,
    children: Vec<(String, Role, u32)>,
    /// `--peers` of every child.
    peers: u32,
}

/// Arguments shared by every child of the bench.
struct Shared<'a> {
    run: &'a RunId,
    iterations: u64,
    socket: &'a Path,
    message: &'a Path,
}

fn run_case(shared: &Shared<'_>, spec: &CaseSpec<'_>) -> anyhow::Result<Vec<ChildReport>> {
    let mut set = ChildSet::new();
    for (name, role, index) in &spec.children {
        let args = vec![
            "--run".to_owned(),
            shared.run.to_string(),
            "--role".to_owned(),
            role.as_arg().to_owned(),
            "--index".to_owned(),
            index.to_string(),
            "--peers".to_owned(),
            spec.peers.to_string(),
            "--iterations".to_owned(),
            shared.iterations.to_string(),
            "--socket".to_owned(),
            shared.socket.display().to_string(),
            "--message".to_owned(),
            shared.message.display().to_string(),
        ];
        set.spawn_ready(name, &args, READY_TIMEOUT)
            .with_context(|| format!("case {}", spec.name))?;
    }
    set.go()?;
    // Generous: even a debug build on a busy machine moves a frame in well under 50 ms.
    let budget = Duration::from_secs(60) + Duration::from_millis(50) * shared.iterations as u32;
    let reports = set
        .results(Instant::now() + budget)
        .with_context(|| format!("case {}", spec.name))?;
    let corrupt: u64 = reports.iter().map(|r| r.corrupt).sum();
    if corrupt > 0 {
        anyhow::bail!(
            "case {}: {corrupt} messages failed their content check",
            spec.name
        );
    }
    Ok(reports)
}

/// Latency statistics of every child's samples, in microseconds.
fn latency_us(reports: &[ChildReport]) -> anyhow::Result<Stats> {
    let v: Vec<f64> = reports
        .iter()
        .flat_map(|r| r.latency_ns.iter().map(|&ns| ns as f64 / 1e3))
        .collect();
    Stats::from_samples(&v).ok_or_else(|| anyhow::anyhow!("no latency was measured"))
}

/// Messages per second of the rate phase: every child's messages over the longest duration.
fn rate(reports: &[ChildReport]) -> (f64, f64) {
    let elapsed = reports.iter().map(|r| r.elapsed_ns).max().unwrap_or(0) as f64 / 1e9;
    let messages: u64 = reports.iter().map(|r| r.messages).sum();
    let bytes: u64 = reports.iter().map(|r| r.bytes).sum();
    if elapsed > 0.0 {
        (messages as f64 / elapsed, bytes as f64 / elapsed)
    } else {
        (0.0, 0.0)
    }
}

fn case(
    name: &str,
    params: &[(&str, serde_json::Value)],
    lat: &Stats,
    msgs: f64,
    bytes: f64,
    size: usize,
) -> BenchCase {
    let mut metrics = Metrics::default();
    metrics.push("p50_us", lat.median);
    metrics.push("p99_us", lat.p99);
    metrics.push("max_us", lat.max);
    metrics.push("msgs_per_s", msgs);
    metrics.push("MB_per_s", bytes / 1e6);
    metrics.push("msg_bytes", size as f64);
    BenchCase {
        name: name.to_owned(),
        params: params
            .iter()
            .map(|(k, v)| ((*k).to_owned(), v.clone()))
            .collect::<BTreeMap<_, _>>(),
        metrics,
    }
}

/// The message a fleet agent typically sends: the fleet runs `steps` steps in-process and the
/// median-sized of the last step's estimates is taken.
fn typical_estimate(scenario: &Scenario, steps: u64) -> anyhow::Result<Vec<u8>> {
    let mut sim = FleetSim::new(scenario)?;
    for _ in 0..steps.max(1) {
        sim.step()?;
    }
    let mut messages: Vec<&Vec<u8>> = sim.last_messages().iter().collect();
    messages.sort_by_key(|m| m.len());
    messages
        .get(messages.len() / 2)
        .map(|m| (*m).clone())
        .ok_or_else(|| anyhow::anyhow!("the scenario has no UAV"))
}

/// Start of every bench run id: `bench-ipc-{pid}-{nanos}`.
const RUN_ID_PREFIX: &str = "bench-ipc-";

/// Whether `run` is a bench run (`bench-ipc-{pid}-{nanos}`) whose process is gone (a bench
/// killed with SIGKILL cannot clean up; the next one does).
fn is_stale_bench_run(run: &RunId) -> bool {
    let Some((pid, nanos)) = run
        .as_str()
        .strip_prefix(RUN_ID_PREFIX)
        .and_then(|rest| rest.split_once('-'))
    else {
        return false;
    };
    let (Ok(pid), Ok(_)) = (pid.parse::<libc::pid_t>(), nanos.parse::<u32>()) else {
        return false;
    };
    // SAFETY: kill with signal 0 only checks whether the process exists.
    let failed = unsafe { libc::kill(pid, 0) } != 0;
    failed && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH)
}

/// Removes what earlier bench runs killed before their cleanup left behind.
fn remove_stale_runs() {
    let runs = match pipc::runs_with_files() {
        Ok(runs) => runs,
        Err(e) => {
            tracing::debug!(error = %e, "cannot list the iceoryx2 files of earlier runs");
            return;
        }
    };
    for run in runs.into_iter().filter(is_stale_bench_run) {
        drop(RunFiles {
            dir: std::env::temp_dir().join(format!("fleet-{run}")),
            run,
        });
    }
}

/// Runs every case and reports.
pub fn run(config: &BenchIpcConfig) -> anyhow::Result<BenchReport> {
    let mut report = BenchReport::new("ipc");
    remove_stale_runs();
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let run = RunId::new(&format!("{RUN_ID_PREFIX}{}-{stamp}", std::process::id()))?;
    let dir = std::env::temp_dir().join(format!("fleet-{run}"));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let _files = RunFiles {
        run: run.clone(),
        dir: dir.clone(),
    };
    let estimate = typical_estimate(&config.scenario, config.estimate_steps)?;
    let message = dir.join("estimate.bin");
    std::fs::write(&message, &estimate)?;
    let socket = dir.join("frame.sock");
    let shared = Shared {
        run: &run,
        iterations: config.iterations,
        socket: &socket,
        message: &message,
    };
    let frame_bytes = std::mem::size_of::<CvsFrame>();
    let n = config.iterations;

    let mut frame_cases = Vec::new();
    for subs in [1u32, FLEET] {
        let mut children: Vec<(String, Role, u32)> = (0..subs)
            .map(|i| (format!("frame-sub-{i}"), Role::FrameSubscriber, i))
            .collect();
        children.push(("frame-pub".to_owned(), Role::FramePublisher, 0));
        let name = format!("iox-{subs}sub");
        let reports = run_case(
            &shared,
            &CaseSpec {
                name: &name,
                children,
                peers: subs,
            },
        )?;
        let (subs_reports, pub_report) = reports.split_at(subs as usize);
        let lat = latency_us(subs_reports)?;
        let (fps, bps) = rate(pub_report);
        report.cases.push(case(
            &name,
            &[
                ("subscribers", subs.into()),
                ("transport", "iceoryx2".into()),
            ],
            &lat,
            fps,
            bps,
            frame_bytes,
        ));
        frame_cases.push((lat, fps));
    }

    let reports = run_case(
        &shared,
        &CaseSpec {
            name: "socket-1sub",
            children: vec![
                ("socket-pub".to_owned(), Role::SocketPublisher, 0),
                ("socket-sub".to_owned(), Role::SocketSubscriber, 0),
            ],
            peers: 1,
        },
    )?;
    let base_lat = latency_us(&reports[1..])?;
    let (base_fps, base_bps) = rate(&reports[..1]);
    report.cases.push(case(
        "socket-1sub",
        &[
            ("subscribers", 1.into()),
            ("transport", "unix socket + bincode".into()),
        ],
        &base_lat,
        base_fps,
        base_bps,
        frame_bytes,
    ));

    let fleet_children = |prefix: &str, role: Role| -> Vec<(String, Role, u32)> {
        (0..FLEET)
            .map(|i| (format!("{prefix}-{i}"), role, i))
            .collect()
    };
    let reports = run_case(
        &shared,
        &CaseSpec {
            name: "estimates",
            children: fleet_children("estimates", Role::Estimates),
            peers: FLEET,
        },
    )?;
    let est_lat = latency_us(&reports)?;
    let (est_mps, est_bps) = rate(&reports);
    report.cases.push(case(
        "estimates",
        &[
            ("processes", FLEET.into()),
            ("pattern", "all-to-all".into()),
        ],
        &est_lat,
        est_mps,
        est_bps,
        estimate.len(),
    ));

    let reports = run_case(
        &shared,
        &CaseSpec {
            name: "token",
            children: fleet_children("token", Role::Token),
            peers: FLEET,
        },
    )?;
    let token_lat = latency_us(&reports)?;
    let (token_mps, token_bps) = rate(&reports);
    let token_bytes = reports.iter().map(|r| r.bytes).sum::<u64>() as f64
        / reports.iter().map(|r| r.messages).sum::<u64>().max(1) as f64;
    report.cases.push(case(
        "token-round",
        &[
            ("processes", FLEET.into()),
            ("latency", "whole round".into()),
        ],
        &token_lat,
        token_mps,
        token_bps,
        token_bytes as usize,
    ));

    let (lat1, fps1) = &frame_cases[0];
    let (lat4, fps4) = &frame_cases[1];
    let sum = &mut report.summary;
    sum.insert("frame_p50_us".into(), lat1.median.into());
    sum.insert("frame_p99_us".into(), lat1.p99.into());
    sum.insert("frame_4sub_p50_us".into(), lat4.median.into());
    sum.insert("frame_4sub_p99_us".into(), lat4.p99.into());
    sum.insert("frames_per_s_1sub".into(), (*fps1).into());
    sum.insert("frames_per_s_4sub".into(), (*fps4).into());
    sum.insert("baseline_frame_p50_us".into(), base_lat.median.into());
    sum.insert("baseline_frame_p99_us".into(), base_lat.p99.into());
    sum.insert("baseline_frames_per_s".into(), base_fps.into());
    sum.insert("speedup".into(), (base_lat.median / lat1.median).into());
    sum.insert("estimate_msgs_per_s".into(), est_mps.into());
    sum.insert("estimate_p50_us".into(), est_lat.median.into());
    sum.insert("estimate_p99_us".into(), est_lat.p99.into());
    sum.insert("estimate_bytes".into(), estimate.len().into());
    sum.insert("token_round_us".into(), token_lat.median.into());
    sum.insert("token_round_p99_us".into(), token_lat.p99.into());
    sum.insert("frame_bytes".into(), frame_bytes.into());
    sum.insert("iterations".into(), n.into());
    sum.insert("goal_frame_p50_us".into(), 100.0.into());
    sum.insert("goal_speedup".into(), 15.0.into());
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filled_frames_differ_by_sequence_and_carry_their_checksum() {
        let mut a = CvsFrame::new_boxed();
        let mut b = CvsFrame::new_boxed();
        fill_frame(&mut a, 1);
        fill_frame(&mut b, 2);
        assert_eq!(a.pixel_count(), FRAME_MAX_PIXELS);
        assert_eq!(a.checksum(), a.header.checksum);
        assert_ne!(a.header.checksum, b.header.checksum);
    }

    #[test]
    fn rates_use_the_slowest_child_and_latencies_every_child() {
        let r = |lat: Vec<u64>, messages, elapsed_ns| ChildReport {
            latency_ns: lat,
            messages,
            bytes: messages * 10,
            elapsed_ns,
            corrupt: 0,
        };
        let reports = [
            r(vec![1000, 3000], 100, 1_000_000_000),
            r(vec![2000], 100, 2_000_000_000),
        ];
        assert_eq!(rate(&reports), (100.0, 1000.0));
        let s = latency_us(&reports).unwrap();
        assert_eq!((s.n, s.median, s.max), (3, 2.0, 3.0));
        assert!(latency_us(&[]).is_err());
    }

    #[test]
    fn only_bench_runs_of_dead_processes_are_stale() {
        let run = |id: &str| RunId::new(id).unwrap();
        let me = std::process::id();
        assert!(!is_stale_bench_run(&run(&format!("bench-ipc-{me}-5"))));
        assert!(!is_stale_bench_run(&run("other-run")));
        assert!(!is_stale_bench_run(&run("bench-ipc-x-5")));
        assert!(!is_stale_bench_run(&run("bench-ipc-2147483632-4-2")));
        // Pid 0x7ffffff0 is above Linux's pid_max, so no process has it.
        assert!(is_stale_bench_run(&run("bench-ipc-2147483632-42")));
        let file = "iox2_sf_bench-ipc-2147483632-42_0354a209029e7d094a81.service";
        assert!(pipc::run_of_file(file).is_some_and(|r| is_stale_bench_run(&r)));
    }

    #[test]
    fn monotonic_clock_advances() {
        let a = monotonic_ns();
        let b = monotonic_ns();
        assert!(a > 0 && b >= a);
    }
}
