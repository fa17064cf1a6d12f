//! What the observer counts over a run: messages and bytes per service kind with their
//! latencies, and each agent's counters across its incarnations.

use std::collections::BTreeMap;

use protocol::wire::AgentStats;
use sets::raster::CellBox;

use super::metrics::{FusedSets, ObservedEstimate};

/// The kinds of service the observer accounts for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ServiceKind {
    /// CVS frames, world -> agent (counted from the truth: one per live agent and step).
    Frames,
    /// Commands and acks, agent -> world (one per live agent and step).
    Commands,
    /// Estimates, agent -> peers and observers (as received by the observer).
    Estimates,
    /// The guidance token (as received by the observer).
    Tokens,
    /// Truth, world -> observer.
    Truth,
    /// Under the measurement exchange, each agent's sets once it applied its peers'
    /// measurements, agent -> observers only (no radio link carries them).
    States,
}

impl ServiceKind {
    /// The kind's key in `summary.json`.
    pub fn key(self) -> &'static str {
        match self {
            ServiceKind::Frames => "frames",
            ServiceKind::Commands => "commands",
            ServiceKind::Estimates => "estimates",
            ServiceKind::Tokens => "tokens",
            ServiceKind::Truth => "truth",
            ServiceKind::States => "states",
        }
    }
}

/// Traffic of one service kind.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ServiceTally {
    /// Messages.
    pub messages: u64,
    /// Bytes: payload plus user header.
    pub bytes: u64,
    /// Send-to-receipt latencies, milliseconds (kinds that carry a send time only).
    pub latencies_ms: Vec<f64>,
}

/// Traffic per service kind.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Comms {
    /// By kind.
    pub by_kind: BTreeMap<ServiceKind, ServiceTally>,
}

impl Comms {
    /// Counts `messages` messages of `bytes` bytes in all.
    pub fn count(&mut self, kind: ServiceKind, messages: u64, bytes: u64) {
        let t = self.by_kind.entry(kind).or_default();
        t.messages += messages;
        t.bytes += bytes;
    }

    /// Counts one message with its send time (ns since the Unix epoch) against `now_ns`.
    pub fn count_timed(&mut self, kind: ServiceKind, bytes: u64, sent_ns: u64, now_ns: u64) {
        self.count(kind, 1, bytes);
        if sent_ns > 0 {
            let ms = now_ns.saturating_sub(sent_ns) as f64 / 1e6;
            self.by_kind.entry(kind).or_default().latencies_ms.push(ms);
        }
    }
}

/// One incarnation of an agent as seen through its estimates.
#[derive(Clone, Debug, PartialEq)]
struct Incarnation {
    id: u64,
    first_step: u64,
    last_seq: u64,
    stats: AgentStats,
}

/// One agent's counters over the run, summed over its incarnations (a restart resets the
/// agent's own counters; the latest estimate of each incarnation carries its totals).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AgentTally {
    /// Estimates the observer decoded.
    pub estimates_seen: u64,
    /// Messages on the agent's estimate service the observer could not use.
    pub estimates_dropped: u64,
    /// Step of the latest estimate seen.
    pub last_step: Option<u64>,
    incarnations: Vec<Incarnation>,
}

impl AgentTally {
    /// Folds in a decoded estimate.
    pub fn observe(&mut self, observed: &ObservedEstimate) {
        let e = &observed.estimate;
        self.observe_message(e.step, e.incarnation, e.seq, observed.stats);
    }

    /// Folds in a decoded estimate's header: its step, its sender's incarnation and message
    /// counter, and the counters it carries.
    pub fn observe_message(&mut self, step: u64, incarnation: u64, seq: u64, stats: AgentStats) {
        self.estimates_seen += 1;
        self.last_step = Some(self.last_step.map_or(step, |s| s.max(step)));
        match self.incarnations.iter_mut().find(|i| i.id == incarnation) {
            Some(i) if seq >= i.last_seq => {
                i.last_seq = seq;
                i.stats = stats;
            }
            Some(_) => {}
            None => self.incarnations.push(Incarnation {
                id: incarnation,
                first_step: step,
                last_seq: seq,
                stats,
            }),
        }
    }

    /// The counters its estimates carry, as of each incarnation's latest estimate, summed over
    /// the incarnations.
    pub fn counters(&self) -> AgentStats {
        self.incarnations.iter().map(|i| i.stats).sum()
    }

    /// Estimates sent (each incarnation's latest message counter, plus one).
    pub fn estimates_sent(&self) -> u64 {
        self.incarnations.iter().map(|i| i.last_seq + 1).sum()
    }

    /// Incarnations seen (1 + restarts that published).
    pub fn incarnations(&self) -> usize {
        self.incarnations.len()
    }

    /// First step of each incarnation, in the order they appeared.
    pub fn incarnation_starts(&self) -> Vec<u64> {
        self.incarnations.iter().map(|i| i.first_step).collect()
    }
}

/// The cars' sets the agents held under windows (`estimator.window_m` smaller than the
/// region), summed over the agent-steps measured, and how many of them meet the holder's
/// window: what an agent that kept only the cars whose sets meet its window would hold and
/// predict (docs/design.md §3, "X̄ over a window").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WindowTally {
    /// Agent-steps measured under windows.
    pub agent_steps: u64,
    /// Cars' sets held, summed over those agent-steps.
    pub targets: u64,
    /// Of them, the sets with a cell in the holder's window.
    pub targets_meeting: u64,
    /// Cells of the cars' sets held.
    pub target_cells: u64,
    /// Cells of the sets that meet the window (all of each such set's cells).
    pub target_cells_meeting: u64,
}

impl WindowTally {
    /// Counts one agent-step: the cars' sets of `fused`, against the agent's `window`.
    pub fn count(&mut self, fused: &FusedSets, window: &CellBox) {
        self.agent_steps += 1;
        for set in fused.targets.values() {
            let cells = set.count();
            self.targets += 1;
            self.target_cells += cells;
            if set.count_in_box(window) > 0 {
                self.targets_meeting += 1;
                self.target_cells_meeting += cells;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use sets::grid::GroundGrid;

    use super::*;

    fn estimate(incarnation: u64, seq: u64, frames: u64) -> ObservedEstimate {
        let mut e = crate::observe::metrics::tests::blank(&GroundGrid::new(2.0, 1.0), 0, seq);
        e.estimate.incarnation = incarnation;
        e.estimate.seq = seq;
        e.stats = AgentStats {
            frames,
            estimates_received: 2 * frames,
            estimates_lost: frames / 2,
            tokens_lost: frames / 4,
            ..AgentStats::default()
        };
        e
    }

    #[test]
    fn counters_add_up_over_incarnations_and_ignore_late_messages() {
        let mut t = AgentTally::default();
        t.observe(&estimate(7, 0, 1));
        t.observe(&estimate(7, 4, 5));
        t.observe(&estimate(7, 3, 4)); // late: older than what was seen
        t.observe(&estimate(9, 0, 1)); // restarted
        t.observe(&estimate(9, 1, 2));
        assert_eq!(t.estimates_seen, 5);
        let counters = t.counters();
        assert_eq!(counters.frames, 7);
        assert_eq!(t.estimates_sent(), 7);
        assert_eq!(counters.estimates_received, 14);
        assert_eq!((counters.estimates_lost, counters.tokens_lost), (2 + 1, 1));
        assert_eq!(t.incarnations(), 2);
        assert_eq!(t.incarnation_starts(), vec![0, 0]);
        assert_eq!(t.last_step, Some(4));
    }

    #[test]
    fn latencies_are_kept_only_for_stamped_messages() {
        let mut c = Comms::default();
        c.count_timed(ServiceKind::Estimates, 100, 1_000_000, 3_000_000);
        c.count_timed(ServiceKind::Estimates, 50, 0, 3_000_000);
        c.count(ServiceKind::Frames, 4, 400);
        let e = &c.by_kind[&ServiceKind::Estimates];
        assert_eq!(
            (e.messages, e.bytes, e.latencies_ms.clone()),
            (2, 150, vec![2.0])
        );
        assert_eq!(c.by_kind[&ServiceKind::Frames].messages, 4);
    }
}
