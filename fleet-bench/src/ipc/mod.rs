//! `fleet bench ipc`: what moving setfleet's messages between processes costs, side by side,
//! every role in its own process.
//!
//! Cases, each run in fresh child processes (`fleet-bench-child`, see [`roles`]):
//! - `iox-1sub`, `iox-4sub`: the 864 KB [`CvsFrame`] over iceoryx2, zero-copy: the publisher
//!   loans a sample, writes the frame in place ([`CvsFrame::init_in_place`], depth, labels,
//!   checksum) and sends it; each subscriber takes it and verifies the checksum.
//! - `socket-1sub`: the same frame over a Unix domain socket, bincode-encoded
//!   ([`protocol::codec`]) and length-prefixed: the baseline a user would otherwise pick.
//! - `zenoh-frame-tcp`, `zenoh-frame-tls`, `zenoh-frame-quic`: the same frame from one host's
//!   bridge to another's
//!   over Zenoh on loopback, set up as `fleet-bridge` sets up its sessions (module `zenoh_link`): a
//!   router listening, a client connecting, the bridge's publisher QoS, the frame in the
//!   bridge's envelope ([`bridge::envelope::encode_frame`], decoded with `decode_frame_into`
//!   and its checksum verified). Over plain TCP, and over mutually authenticated TLS over TCP
//!   and QUIC (the bridge's default) with the run's access policy (certificates made for the
//!   bench, hosts `h0` and `h1`).
//! - `estimates`: a real estimate message (built by running the fleet in-process for a few
//!   steps) all-to-all among 4 processes, round after round.
//! - `zenoh-estimate-tcp`, `-tls`, `-quic`: that estimate message in the bridge's
//!   envelope ([`bridge::envelope::encode_wire`]) from the router to the client, as the frame.
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
//! The Zenoh cases measure one way, from the send start (the frame written, before encoding)
//! to the decoded message; their acks come back over iceoryx2, not over the Zenoh link,
//! because Zenoh 1.10.2's TLS link is unsound when both of its directions are busy (see
//! `zenoh_link`). A message Zenoh loses (a TLS link that dropped and reconnected) is sent
//! again after 100 ms without an ack and counted (`resent`); its latency counts the loss.
//!
//! The run has its own [`RunId`](protocol::service::RunId) (its own iceoryx2 prefix); its
//! files are removed at the end.

mod bench_run;
mod children;
mod config;
pub mod handshake;
mod measure;
mod message;
mod report;
pub mod roles;
mod services;
mod socket;
mod zenoh_link;

use protocol::frame::CvsFrame;

use super::{BenchReport, Stats};
use bench_run::{RunFiles, remove_stale_runs};
use handshake::{Role, ZenohTransport};
use measure::{CaseSpec, Shared, latency_us, rate, run_case, typical_estimate};
use report::{Headline, ZenohFigures, ZenohHeadline, case};
use zenoh_link::Payload;

pub use config::{BenchIpcArgs, BenchIpcConfig};
pub use handshake::BenchChildArgs;
pub use message::{
    Ack, ChildReport, PHASE_LATENCY, PHASE_RATE, Stamp, WINDOW, fill_frame, monotonic_ns,
};
pub use services::{AckService, BenchServices, FrameService, StampedService};

/// Processes of the all-to-all and token cases (the default fleet).
const FLEET: u32 = 4;

/// Runs every case and reports.
pub fn run(config: &BenchIpcConfig) -> anyhow::Result<BenchReport> {
    let mut report = BenchReport::new("ipc");
    remove_stale_runs();
    let files = RunFiles::create()?;
    let (run, dir) = (&files.run, &files.dir);
    let estimate = typical_estimate(&config.scenario, config.estimate_steps)?;
    let message = dir.join("estimate.bin");
    std::fs::write(&message, &estimate)?;
    let socket = dir.join("frame.sock");
    let certs = dir.join("certs");
    zenoh_link::write_certs(&certs)?;
    let shared = Shared {
        run,
        iterations: config.iterations,
        socket: &socket,
        message: &message,
        certs: &certs,
    };
    let frame_bytes = std::mem::size_of::<CvsFrame>();
    let n = config.iterations;

    let frame_cases = iceoryx_frame_cases(&shared, &mut report, frame_bytes)?;
    let (base_lat, base_fps) = socket_case(&shared, &mut report, frame_bytes)?;
    let mut zenoh = ZenohHeadline::default();
    zenoh_cases(&shared, &mut report, Payload::Frame, &mut zenoh)?;
    let (est_lat, est_mps) = estimates_case(&shared, &mut report, estimate.len())?;
    zenoh_cases(&shared, &mut report, Payload::Estimate, &mut zenoh)?;
    let token_lat = token_case(&shared, &mut report)?;

    let (frame_1sub, frame_4sub) = (frame_cases[0], frame_cases[1]);
    report.summary = Headline {
        frame_1sub,
        frame_4sub,
        baseline: (base_lat, base_fps),
        estimates: (est_lat, est_mps),
        estimate_bytes: estimate.len(),
        token_round: token_lat,
        zenoh,
        frame_bytes,
        iterations: n,
    }
    .summary();
    Ok(report)
}

/// Runs the frame over iceoryx2 to one subscriber, then to [`FLEET`], adds their rows to
/// `report` and returns their latency and frame rate, in that order.
fn iceoryx_frame_cases(
    shared: &Shared<'_>,
    report: &mut BenchReport,
    frame_bytes: usize,
) -> anyhow::Result<Vec<(Stats, f64)>> {
    let mut frame_cases = Vec::new();
    for subs in [1u32, FLEET] {
        let mut children: Vec<(String, Role, u32)> = (0..subs)
            .map(|i| (format!("frame-sub-{i}"), Role::FrameSubscriber, i))
            .collect();
        children.push(("frame-pub".to_owned(), Role::FramePublisher, 0));
        let name = format!("iox-{subs}sub");
        let reports = run_case(
            shared,
            &CaseSpec {
                name: &name,
                children,
                peers: subs,
                zenoh: None,
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
    Ok(frame_cases)
}

/// Runs the socket baseline, adds its row to `report` and returns its latency and frame rate.
fn socket_case(
    shared: &Shared<'_>,
    report: &mut BenchReport,
    frame_bytes: usize,
) -> anyhow::Result<(Stats, f64)> {
    let reports = run_case(
        shared,
        &CaseSpec {
            name: "socket-1sub",
            children: vec![
                ("socket-pub".to_owned(), Role::SocketPublisher, 0),
                ("socket-sub".to_owned(), Role::SocketSubscriber, 0),
            ],
            peers: 1,
            zenoh: None,
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
    Ok((base_lat, base_fps))
}

/// Runs the Zenoh cases of `payload` over every transport and adds their figures to `zenoh`.
fn zenoh_cases(
    shared: &Shared<'_>,
    report: &mut BenchReport,
    payload: Payload,
    zenoh: &mut ZenohHeadline,
) -> anyhow::Result<()> {
    let what = payload_name(payload);
    for transport in ZenohTransport::ALL {
        let figures = zenoh_case(shared, report, payload, transport)?;
        zenoh.cases.push((what, transport, figures));
    }
    Ok(())
}

/// The children of a [`FLEET`]-process case: `{prefix}-{i}` in `role`.
fn fleet_children(prefix: &str, role: Role) -> Vec<(String, Role, u32)> {
    (0..FLEET)
        .map(|i| (format!("{prefix}-{i}"), role, i))
        .collect()
}

/// Runs the estimates all-to-all, adds its row to `report` and returns its latency and
/// message rate.
fn estimates_case(
    shared: &Shared<'_>,
    report: &mut BenchReport,
    estimate_bytes: usize,
) -> anyhow::Result<(Stats, f64)> {
    let reports = run_case(
        shared,
        &CaseSpec {
            name: "estimates",
            children: fleet_children("estimates", Role::Estimates),
            peers: FLEET,
            zenoh: None,
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
        estimate_bytes,
    ));
    Ok((est_lat, est_mps))
}

/// Runs the token around the fleet, adds its row to `report` and returns the latency of a
/// whole round.
fn token_case(shared: &Shared<'_>, report: &mut BenchReport) -> anyhow::Result<Stats> {
    let reports = run_case(
        shared,
        &CaseSpec {
            name: "token",
            children: fleet_children("token", Role::Token),
            peers: FLEET,
            zenoh: None,
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
    Ok(token_lat)
}

/// Runs the Zenoh case of `payload` over `transport` (a router publishing to a client), adds
/// its row to `report` and returns its figures.
fn zenoh_case(
    shared: &Shared<'_>,
    report: &mut BenchReport,
    payload: Payload,
    transport: ZenohTransport,
) -> anyhow::Result<ZenohFigures> {
    let (publisher, subscriber) = match payload {
        Payload::Frame => (Role::ZenohFramePublisher, Role::ZenohFrameSubscriber),
        Payload::Estimate => (Role::ZenohEstimatePublisher, Role::ZenohEstimateSubscriber),
    };
    let name = format!("zenoh-{}-{}", payload_name(payload), transport.as_arg());
    let reports = run_case(
        shared,
        &CaseSpec {
            name: &name,
            // The router listens before the client connects.
            children: vec![
                (format!("{name}-pub"), publisher, 0),
                (format!("{name}-sub"), subscriber, 0),
            ],
            peers: 1,
            zenoh: Some(transport),
        },
    )?;
    let (pub_report, sub_reports) = reports.split_at(1);
    let lat = latency_us(sub_reports)?;
    let (mps, bps) = rate(pub_report);
    let size = pub_report
        .first()
        .map_or(0, |r| r.bytes / r.messages.max(1));
    let resent: u64 = pub_report.iter().map(|r| r.resent).sum();
    let mut row = case(
        &name,
        &[
            (
                "transport",
                format!("zenoh {}", transport.description()).into(),
            ),
            ("topology", "router -> client, loopback".into()),
            ("acks", "iceoryx2".into()),
        ],
        &lat,
        mps,
        bps,
        size as usize,
    );
    row.metrics.push("resent", resent as f64);
    report.cases.push(row);
    Ok(ZenohFigures {
        latency: lat,
        rate: mps,
        resent,
    })
}

/// The name of `payload` in the Zenoh cases' names and figures.
fn payload_name(payload: Payload) -> &'static str {
    match payload {
        Payload::Frame => "frame",
        Payload::Estimate => "estimate",
    }
}
