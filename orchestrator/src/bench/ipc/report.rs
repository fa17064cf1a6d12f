//! What `fleet bench ipc` reports: one [`BenchCase`] per case, and the headline figures
//! docs/design.md names.

use std::collections::BTreeMap;

use super::super::{BenchCase, Metrics, Stats};

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
        sum
    }
}
