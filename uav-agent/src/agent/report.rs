//! What an agent counts as it runs ([`AgentCounters`]) and the report it prints at exit
//! ([`AgentReport`]).
//!
//! The counters an estimate carries are one record, [`AgentStats`] (in [`protocol::wire`]): the
//! agent counts into it directly ([`AgentCounters::shared`]), each estimate carries a copy, and
//! the observer sums the copies into summary.json. The report adds what only the agent's own
//! account needs (drops by reason, estimates out of range, the checkpoints, where the time
//! went), and prints everything flat, in the key order it has always had: the counters' order
//! in the report differs from the record's, which the wire fixes, so [`AgentCounters`]' JSON
//! names every field of the record, and a counter added to the record does not compile until it
//! is given its place there and in the summary.

use std::collections::BTreeMap;

use fleet_process::resources::PhaseTimes;
use protocol::wire::{AgentStats, DropReason};
use serde::{Serialize, Serializer};

use super::checkpoint::CheckpointFigures;
use crate::guidance::external::ExternalReport;

/// How the agent's loop ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum EndReason {
    /// The world announced the end of the run.
    EndOfRun,
    /// SIGTERM/SIGINT or the shutdown flag.
    Interrupted,
}

/// What an agent counted: the counters its estimates carry, and those only its report gives.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AgentCounters {
    /// The counters every estimate carries, as of now (`messages_dropped` is the total of
    /// [`AgentCounters::dropped`]).
    pub shared: AgentStats,
    /// Estimates published.
    pub estimates_sent: u64,
    /// Peer estimates out of comms range, not fused.
    pub estimates_out_of_range: u64,
    /// Messages dropped, by reason (`{what}:{reason}`).
    pub dropped: BTreeMap<String, u64>,
    /// Steps whose peers' estimates did not all arrive in time.
    pub peer_timeouts: u64,
}

impl AgentCounters {
    /// Logs and counts a message dropped for `reason`: `what` it was (`"estimate"`,
    /// `"token"`) and a `detail` for the log.
    pub fn drop_message(&mut self, reason: DropReason, what: &str, detail: &str) {
        tracing::warn!(?reason, what, detail, "message dropped");
        *self
            .dropped
            .entry(format!("{what}:{reason:?}"))
            .or_default() += 1;
        self.shared.messages_dropped += 1;
    }
}

/// [`AgentCounters`] as the report prints them: its keys, in their order.
#[derive(Serialize)]
struct PrintedCounters<'a> {
    frames: u64,
    frames_refused: u64,
    estimates_sent: u64,
    estimates_received: u64,
    estimates_out_of_range: u64,
    estimates_lost: u64,
    tokens_lost: u64,
    relayed_applied: u64,
    relayed_sent: u64,
    external_decisions: u64,
    external_fallbacks: u64,
    dropped: &'a BTreeMap<String, u64>,
    decisions: u64,
    token_timeouts: u64,
    peer_timeouts: u64,
}

impl Serialize for AgentCounters {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        // Every field by name: a counter added to the record stops the build here until the
        // report prints it (or says why not).
        let AgentStats {
            frames,
            frames_refused,
            estimates_received,
            // Printed by reason, as `dropped`.
            messages_dropped: _,
            decisions,
            token_timeouts,
            estimates_lost,
            tokens_lost,
            relayed_applied,
            relayed_sent,
            external_decisions,
            external_fallbacks,
        } = self.shared;
        PrintedCounters {
            frames,
            frames_refused,
            estimates_sent: self.estimates_sent,
            estimates_received,
            estimates_out_of_range: self.estimates_out_of_range,
            estimates_lost,
            tokens_lost,
            relayed_applied,
            relayed_sent,
            external_decisions,
            external_fallbacks,
            dropped: &self.dropped,
            decisions,
            token_timeouts,
            peer_timeouts: self.peer_timeouts,
        }
        .serialize(serializer)
    }
}

/// What an agent did, printed at exit (one JSON object, its parts flat).
#[derive(Clone, Debug, Default, Serialize)]
pub struct AgentReport {
    /// What it counted: frames, estimates, tokens, drops, decisions, timeouts.
    #[serde(flatten)]
    pub counters: AgentCounters,
    /// Cells of `X̄` after the last fusion.
    pub final_undetected_cells: u64,
    /// Fingerprint of `X̄` after the last fusion ([`sets::raster::CellSet::digest`]):
    /// agents that fused the same estimates hold the same set.
    pub final_undetected_digest: u64,
    /// Step of the last frame.
    pub final_step: u64,
    /// Its checkpoints: the one it resumed from or refused, those it wrote and flushed.
    #[serde(flatten)]
    pub checkpoint: CheckpointFigures,
    /// How the loop ended.
    pub end: Option<EndReason>,
    /// This process's id, so that whoever started it can join this report to the kernel's
    /// account of the process.
    pub pid: u32,
    /// Where the agent's thread spent its time ([`super::phase`]): CPU time of the thread and
    /// wall time per phase, from the start of the loop to its end.
    pub phases: PhaseTimes,
    /// The process's own peak resident memory at the end of its loop, KiB
    /// ([`fleet_process::resources::own_peak_rss_kb`]: without the memory of whoever spawned it);
    /// `None` if it could not be read.
    pub peak_rss_kb: Option<u64>,
    /// What the external planner did, for an agent that asks one: decisions, fallbacks by
    /// reason, the time from request to answer and its overhead beyond the planner's own.
    pub external: Option<ExternalReport>,
}

#[cfg(test)]
mod tests {
    use protocol::wire::DropReason;

    use super::*;
    use crate::guidance::external::ExternalReport;

    /// A report with a distinct value in every field, as it was printed before its counters
    /// became one record with the estimates': every key, in its order.
    const PRINTED: &str = concat!(
        r#"{"frames":1,"frames_refused":2,"estimates_sent":3,"estimates_received":4,"#,
        r#""estimates_out_of_range":5,"estimates_lost":6,"tokens_lost":7,"#,
        r#""relayed_applied":8,"relayed_sent":9,"external_decisions":10,"#,
        r#""external_fallbacks":11,"dropped":{"estimate:NoBase":3,"token:Malformed":4},"#,
        r#""decisions":12,"token_timeouts":13,"peer_timeouts":14,"#,
        r#""final_undetected_cells":15,"final_undetected_digest":16,"final_step":17,"#,
        r#""resumed_from_step":18,"checkpoint_refused":"no","checkpoints":19,"#,
        r#""checkpoint_failures":20,"checkpoint_ms":21.5,"checkpoint_flushes":22,"#,
        r#""checkpoint_flush_failures":23,"checkpoint_flush_ms":24.25,"end":"EndOfRun","#,
        r#""pid":25,"phases":{},"peak_rss_kb":26,"external":{"asked":27,"answered":0,"#,
        r#""deferred":0,"late":0,"malformed":0,"absent":0,"round_trip_ms":null,"overhead_ms":null}}"#,
    );

    /// A default report as it was printed then.
    const PRINTED_DEFAULT: &str = concat!(
        r#"{"frames":0,"frames_refused":0,"estimates_sent":0,"estimates_received":0,"#,
        r#""estimates_out_of_range":0,"estimates_lost":0,"tokens_lost":0,"#,
        r#""relayed_applied":0,"relayed_sent":0,"external_decisions":0,"#,
        r#""external_fallbacks":0,"dropped":{},"decisions":0,"token_timeouts":0,"#,
        r#""peer_timeouts":0,"final_undetected_cells":0,"final_undetected_digest":0,"#,
        r#""final_step":0,"resumed_from_step":null,"checkpoint_refused":null,"#,
        r#""checkpoints":0,"checkpoint_failures":0,"checkpoint_ms":0.0,"#,
        r#""checkpoint_flushes":0,"checkpoint_flush_failures":0,"checkpoint_flush_ms":0.0,"#,
        r#""end":null,"pid":0,"phases":{},"peak_rss_kb":null,"external":null}"#,
    );

    #[test]
    fn the_printed_report_keeps_its_keys_and_their_order() {
        let mut counters = AgentCounters::default();
        for _ in 0..3 {
            counters.drop_message(DropReason::NoBase, "estimate", "test");
        }
        for _ in 0..4 {
            counters.drop_message(DropReason::Malformed, "token", "test");
        }
        assert_eq!(counters.shared.messages_dropped, 7);
        counters.shared = AgentStats {
            frames: 1,
            frames_refused: 2,
            estimates_received: 4,
            decisions: 12,
            token_timeouts: 13,
            estimates_lost: 6,
            tokens_lost: 7,
            relayed_applied: 8,
            relayed_sent: 9,
            external_decisions: 10,
            external_fallbacks: 11,
            ..counters.shared
        };
        counters.estimates_sent = 3;
        counters.estimates_out_of_range = 5;
        counters.peer_timeouts = 14;
        let report = AgentReport {
            counters,
            final_undetected_cells: 15,
            final_undetected_digest: 16,
            final_step: 17,
            checkpoint: CheckpointFigures {
                resumed_from_step: Some(18),
                checkpoint_refused: Some("no".into()),
                checkpoints: 19,
                checkpoint_failures: 20,
                checkpoint_ms: 21.5,
                checkpoint_flushes: 22,
                checkpoint_flush_failures: 23,
                checkpoint_flush_ms: 24.25,
            },
            end: Some(EndReason::EndOfRun),
            pid: 25,
            phases: PhaseTimes::default(),
            peak_rss_kb: Some(26),
            external: Some(ExternalReport {
                asked: 27,
                ..ExternalReport::default()
            }),
        };
        let json = |r: &AgentReport| serde_json::to_string(r).expect("a report prints");
        assert_eq!(json(&report), PRINTED);
        assert_eq!(json(&AgentReport::default()), PRINTED_DEFAULT);
    }
}
