//! Measuring a case: its children started, set going and collected, their latencies and rates
//! summed up; and the estimate message the estimates case sends.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context;
use protocol::scenario::Scenario;
use protocol::service::RunId;

use super::children::ChildSet;
use super::handshake::{Role, ZenohTransport};
use super::message::ChildReport;
use super::zenoh_link;
use crate::Stats;
use crate::estimator::fleet;

/// Longest wait for a child to open its ports.
const READY_TIMEOUT: Duration = Duration::from_secs(30);

/// One case: its children, as (name, role, index), started in order.
pub(super) struct CaseSpec<'a> {
    /// The case's name.
    pub(super) name: &'a str,
    /// Its children, as (name, role, index).
    pub(super) children: Vec<(String, Role, u32)>,
    /// `--peers` of every child.
    pub(super) peers: u32,
    /// The Zenoh link of a Zenoh case (its router gets a free loopback port).
    pub(super) zenoh: Option<ZenohTransport>,
}

/// Arguments shared by every child of the bench.
pub(super) struct Shared<'a> {
    /// The bench's run.
    pub(super) run: &'a RunId,
    /// Messages per case and phase.
    pub(super) iterations: u64,
    /// The socket baseline's socket.
    pub(super) socket: &'a Path,
    /// The file holding the estimate message.
    pub(super) message: &'a Path,
    /// The fleet's certificates of the Zenoh cases over QUIC and TLS.
    pub(super) certs: &'a Path,
}

/// Runs one case in fresh children; fails if any message failed its content check.
pub(super) fn run_case(
    shared: &Shared<'_>,
    spec: &CaseSpec<'_>,
) -> anyhow::Result<Vec<ChildReport>> {
    let mut set = ChildSet::new();
    let zenoh = match spec.zenoh {
        Some(transport) => vec![
            "--transport".to_owned(),
            transport.as_arg().to_owned(),
            "--port".to_owned(),
            zenoh_link::free_port(transport)?.to_string(),
        ],
        None => Vec::new(),
    };
    for (name, role, index) in &spec.children {
        let mut args = vec![
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
            "--certs".to_owned(),
            shared.certs.display().to_string(),
        ];
        args.extend(zenoh.iter().cloned());
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
pub(super) fn latency_us(reports: &[ChildReport]) -> anyhow::Result<Stats> {
    let v: Vec<f64> = reports
        .iter()
        .flat_map(|r| r.latency_ns.iter().map(|&ns| ns as f64 / 1e3))
        .collect();
    Stats::from_samples(&v).ok_or_else(|| anyhow::anyhow!("no latency was measured"))
}

/// Messages per second of the rate phase: every child's messages over the longest duration.
pub(super) fn rate(reports: &[ChildReport]) -> (f64, f64) {
    let elapsed = reports.iter().map(|r| r.elapsed_ns).max().unwrap_or(0) as f64 / 1e9;
    let messages: u64 = reports.iter().map(|r| r.messages).sum();
    let bytes: u64 = reports.iter().map(|r| r.bytes).sum();
    if elapsed > 0.0 {
        (messages as f64 / elapsed, bytes as f64 / elapsed)
    } else {
        (0.0, 0.0)
    }
}

/// The message a fleet agent typically sends: the fleet runs `steps` steps in-process and the
/// median-sized of the last step's estimates is taken.
pub(super) fn typical_estimate(scenario: &Scenario, steps: u64) -> anyhow::Result<Vec<u8>> {
    let mut sim = fleet(scenario)?;
    for _ in 0..steps.max(1) {
        sim.step()?;
    }
    let mut messages: Vec<&Vec<u8>> = sim.messages().iter().collect();
    messages.sort_by_key(|m| m.len());
    messages
        .get(messages.len() / 2)
        .map(|m| (*m).clone())
        .ok_or_else(|| anyhow::anyhow!("the scenario has no UAV"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_use_the_slowest_child_and_latencies_every_child() {
        let r = |lat: Vec<u64>, messages, elapsed_ns| ChildReport {
            latency_ns: lat,
            messages,
            bytes: messages * 10,
            elapsed_ns,
            corrupt: 0,
            resent: 0,
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
}
