//! What `fleet bench ipc` reports: one [`BenchCase`] per case, and the headline figures
//! docs/design.md names.

use std::collections::BTreeMap;

use super::handshake::ZenohTransport;
use crate::{BenchCase, Metrics, Stats};

/// A case's row: its parameters, latency percentiles, rates and message size.
pub(super) fn case(
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

/// What a Zenoh case measured.
pub(super) struct ZenohFigures {
    /// Latency, us.
    pub(super) latency: Stats,
    /// Messages per second of the rate phase.
    pub(super) rate: f64,
    /// Messages sent again because Zenoh lost them.
    pub(super) resent: u64,
}

/// The Zenoh cases: what was sent (`frame`, `estimate`), over which link, and its figures.
#[derive(Default)]
pub(super) struct ZenohHeadline {
    /// Each case, in the bench's order.
    pub(super) cases: Vec<(&'static str, ZenohTransport, ZenohFigures)>,
}

/// Median latency of a frame over Zenoh on loopback the bridge aims at, us.
const GOAL_ZENOH_FRAME_P50_US: f64 = 2000.0;
/// Median latency of an estimate over Zenoh on loopback the bridge aims at, us.
const GOAL_ZENOH_ESTIMATE_P50_US: f64 = 300.0;

impl ZenohHeadline {
    /// `zenoh_{frame,estimate}_{tcp,tls,quic}_{p50_us,p99_us,resent}`,
    /// `zenoh_frames_per_s_{tcp,tls,quic}`, `zenoh_estimate_msgs_per_s_{tcp,tls,quic}` and
    /// the goals.
    fn insert_into(&self, sum: &mut BTreeMap<String, serde_json::Value>) {
        for (what, transport, figures) in &self.cases {
            let link = transport.as_arg();
            let prefix = format!("zenoh_{what}_{link}");
            let rate_key = match *what {
                "frame" => format!("zenoh_frames_per_s_{link}"),
                _ => format!("zenoh_{what}_msgs_per_s_{link}"),
            };
            sum.insert(format!("{prefix}_p50_us"), figures.latency.median.into());
            sum.insert(format!("{prefix}_p99_us"), figures.latency.p99.into());
            sum.insert(format!("{prefix}_resent"), figures.resent.into());
            sum.insert(rate_key, figures.rate.into());
        }
        sum.insert(
            "goal_zenoh_frame_p50_us".into(),
            GOAL_ZENOH_FRAME_P50_US.into(),
        );
        sum.insert(
            "goal_zenoh_estimate_p50_us".into(),
            GOAL_ZENOH_ESTIMATE_P50_US.into(),
        );
    }
}

/// The headline figures of a bench: each case's latency and rate.
pub(super) struct Headline {
    /// The frame to one subscriber: latency, frames per second.
    pub(super) frame_1sub: (Stats, f64),
    /// The frame to four subscribers: latency, frames per second.
    pub(super) frame_4sub: (Stats, f64),
    /// The socket baseline: latency, frames per second.
    pub(super) baseline: (Stats, f64),
    /// Estimates all-to-all: latency, messages per second.
    pub(super) estimates: (Stats, f64),
    /// Size of the estimate message, bytes.
    pub(super) estimate_bytes: usize,
    /// Latency of a whole token round.
    pub(super) token_round: Stats,
    /// The Zenoh cases.
    pub(super) zenoh: ZenohHeadline,
    /// Size of a frame, bytes.
    pub(super) frame_bytes: usize,
    /// Messages per case and phase.
    pub(super) iterations: u64,
}

impl Headline {
    /// The report's summary: docs/design.md's keys.
    pub(super) fn summary(&self) -> BTreeMap<String, serde_json::Value> {
        let (lat1, fps1) = &self.frame_1sub;
        let (lat4, fps4) = &self.frame_4sub;
        let (base_lat, base_fps) = &self.baseline;
        let (est_lat, est_mps) = &self.estimates;
        let token_lat = &self.token_round;
        let mut sum = BTreeMap::new();
        sum.insert("frame_p50_us".into(), lat1.median.into());
        sum.insert("frame_p99_us".into(), lat1.p99.into());
        sum.insert("frame_4sub_p50_us".into(), lat4.median.into());
        sum.insert("frame_4sub_p99_us".into(), lat4.p99.into());
        sum.insert("frames_per_s_1sub".into(), (*fps1).into());
        sum.insert("frames_per_s_4sub".into(), (*fps4).into());
        sum.insert("baseline_frame_p50_us".into(), base_lat.median.into());
        sum.insert("baseline_frame_p99_us".into(), base_lat.p99.into());
        sum.insert("baseline_frames_per_s".into(), (*base_fps).into());
        sum.insert("speedup".into(), (base_lat.median / lat1.median).into());
        sum.insert("estimate_msgs_per_s".into(), (*est_mps).into());
        sum.insert("estimate_p50_us".into(), est_lat.median.into());
        sum.insert("estimate_p99_us".into(), est_lat.p99.into());
        sum.insert("estimate_bytes".into(), self.estimate_bytes.into());
        sum.insert("token_round_us".into(), token_lat.median.into());
        sum.insert("token_round_p99_us".into(), token_lat.p99.into());
        sum.insert("frame_bytes".into(), self.frame_bytes.into());
        sum.insert("iterations".into(), self.iterations.into());
        sum.insert("goal_frame_p50_us".into(), 100.0.into());
        sum.insert("goal_speedup".into(), 15.0.into());
        self.zenoh.insert_into(&mut sum);
        sum
    }
}
