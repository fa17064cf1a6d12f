//! The exchange with the peers ([`PeerExchange`]): what this agent sends them and what it
//! takes in from them, steps 2 and 3 of [`super`]'s loop.
//!
//! It owns everything that lives from one message to the next: the outboxes (the estimates'
//! and, under the measurement exchange, the observers' copy of the sets), this step's
//! measurement, the measurements it forwards (`comms.relay_hops`) and those it applied lately,
//! the peers it missed a message of, the inbox that rebuilds the peers' deltas, each peer's
//! queue and newest steps, the estimates the radio lost and the step from which the next
//! estimate carries the whole map. All of it is read and written only between an estimate
//! going out and the peers' coming in, so it is one part: split, each half would reach into
//! the other at every step.
//!
//! The radio's verdicts on the estimates are taken here ([`protocol::radio`]: functions of the
//! scenario's seed, the link and the step), and estimates are fused in ascending order of peer
//! once the step's wait is over, so what an agent fuses does not depend on timing.

use std::collections::{BTreeMap, BTreeSet};
use std::time::Instant;

use estimator::message::{self, EstimateInbox, EstimateOutbox, PeerMessage};
use estimator::{Estimator, EstimatorConfig, EstimatorStepError, Measurement, Relayed, StepReport};
use protocol::frame::CvsFrame;
use protocol::radio::{Endpoint, LinkKind, Radio};
use protocol::scenario::Exchange;
use protocol::wire::{DropReason, EstimateMsg, UavMask, WireKind, uav_bit};

use super::config::AgentConfig;
use super::error::AgentError;
use super::liveness::{LiveView, Presence};
use super::phase;
use super::process::{Process, WAIT_SLICE};
use super::report::AgentCounters;

/// What this agent knows of one peer's messages.
#[derive(Default)]
struct PeerInfo {
    /// Newest step fused from this peer.
    fused_step: Option<u64>,
    /// Newest step whose message from this peer was handled: queued, lost by the radio or
    /// dropped for want of its base. What [`PeerExchange::gather`] awaits.
    heard_step: Option<u64>,
    /// The peer's process, as its messages name it.
    incarnation: Option<u64>,
    /// The message counter of the last estimate read from this incarnation.
    last_seq: Option<u64>,
    /// Estimates received ahead of this agent's step.
    pending: Vec<Queued>,
}

/// A peer's estimate waiting for the fusion of its step.
enum Queued {
    /// Rebuilt when it came.
    Read(Box<PeerMessage>),
    /// Whole sets of the measurement exchange, kept as they came (encoded, runs of cells)
    /// and rebuilt only when fused, one peer's at a time. Rebuilt as they came, the whole
    /// sets that every peer sends at the same step (every `comms.whole_sets_every` messages
    /// on lossy links, to a peer that rejoined) were all held at once until the fusion: at
    /// 64 UAVs, 63 peers' sets and maps over a 2 km region, about 9 MB each, so 0.5 GB per
    /// agent, which ran a 64-UAV fleet out of memory.
    Unread(Box<EstimateMsg>),
}

impl Queued {
    /// Its sender, step, message counter and sender's incarnation.
    fn header(&self) -> (u32, u64, u64, u64) {
        match self {
            Queued::Read(p) => (p.uav, p.step, p.seq, p.incarnation),
            Queued::Unread(m) => (m.uav, m.step, m.seq, m.incarnation),
        }
    }

    fn step(&self) -> u64 {
        self.header().1
    }
}

/// The agent's side of the exchange with its peers.
pub(super) struct PeerExchange {
    /// This agent's UAV.
    me: u32,
    /// UAVs in the fleet.
    fleet: u32,
    /// What the estimates carry (`comms.exchange`).
    kind: Exchange,
    /// This agent's estimates.
    outbox: EstimateOutbox,
    /// This agent's measurement of the current step, under the measurement exchange.
    measurement: Option<Measurement>,
    /// How many times a peer measurement is forwarded (`comms.relay_hops`; 0 under the set
    /// exchange).
    relay_hops: u32,
    /// The peer measurements applied at the last gather that the next estimate forwards.
    relay_out: Vec<Relayed>,
    /// The peer measurements applied lately, as (step, UAV), when relaying: a measurement
    /// that comes again, from its sender or forwarded by another agent, is not applied twice.
    applied: BTreeSet<(u64, u32)>,
    /// Under the measurement exchange, the observers' copy of this agent's sets once it
    /// applied its peers' measurements ([`WireKind::State`]).
    state_outbox: Option<EstimateOutbox>,
    /// Peers this agent missed an estimate of since its last estimate: its next estimate asks
    /// them for whole sets.
    missed: UavMask,
    /// The peers' sets, the bases of their deltas.
    inbox: EstimateInbox,
    /// The simulated links ([`protocol::radio`]).
    radio: Radio,
    /// Estimates the radio lost, by step, not yet counted: they are counted once the agent
    /// has gathered their step, so the counters its estimates carry do not depend on when a
    /// peer's message of the next step came in.
    lost_by_step: BTreeMap<u64, u64>,
    /// The step from which the next estimate carries the whole map (a peer (re)joined).
    full_map_from: Option<u64>,
    /// What this agent knows of each peer's messages.
    peers: BTreeMap<u32, PeerInfo>,
}

impl PeerExchange {
    /// The exchange of agent `config.uav` in its `incarnation`, over `radio`, with estimates
    /// of `estimator`'s grids; `resumed` when the agent resumed from a checkpoint.
    pub(super) fn new(
        config: &AgentConfig,
        estimator: &EstimatorConfig,
        incarnation: u64,
        radio: Radio,
        resumed: bool,
    ) -> Self {
        let kind = config.scenario.comms.exchange;
        let outbox = match kind {
            Exchange::Sets => {
                let outbox = EstimateOutbox::new(config.uav, incarnation, estimator.oem_full_every);
                // A delta against a message the radio lost rebuilds nothing: whole sets under
                // loss.
                if radio.is_lossy() {
                    outbox
                } else {
                    outbox.with_set_deltas()
                }
            }
            // Whole sets now and then where the radio loses messages or limits the range (they
            // carry what was lost or is out of reach); on perfect links only when a peer
            // (re)joins or asks, and in the first message of an agent resumed from a checkpoint
            // (a fresh one's sets hold nothing its measurements do not carry).
            Exchange::Measurements => {
                let outbox = EstimateOutbox::new(
                    config.uav,
                    incarnation,
                    if radio.loses_or_limits() {
                        u64::from(config.scenario.comms.whole_sets_every)
                    } else {
                        u64::MAX
                    },
                );
                if resumed {
                    outbox
                } else {
                    outbox.starting_fresh()
                }
            }
        };
        PeerExchange {
            me: config.uav,
            fleet: config.scenario.uavs.count,
            kind,
            outbox,
            measurement: None,
            relay_hops: match kind {
                Exchange::Sets => 0,
                Exchange::Measurements => config.scenario.comms.relay_hops,
            },
            relay_out: Vec::new(),
            applied: BTreeSet::new(),
            // The observers' copy of this agent's sets, over the local IPC (no radio): deltas.
            state_outbox: (kind == Exchange::Measurements).then(|| {
                EstimateOutbox::new(config.uav, incarnation, estimator.oem_full_every)
                    .with_set_deltas()
                    .without_map()
            }),
            missed: 0,
            // Whole sets of the measurement exchange are never the base of a delta.
            inbox: match kind {
                Exchange::Sets => EstimateInbox::new(),
                Exchange::Measurements => EstimateInbox::without_bases(),
            },
            radio,
            lost_by_step: BTreeMap::new(),
            full_map_from: None,
            peers: BTreeMap::new(),
        }
    }

    /// One estimator step on `frame`; under the measurement exchange it keeps the frame's
    /// measurement for this step's estimate.
    pub(super) fn step_estimator(
        &mut self,
        estimator: &mut Estimator,
        frame: &CvsFrame,
    ) -> Result<StepReport, EstimatorStepError> {
        match self.kind {
            Exchange::Sets => estimator.step(frame),
            Exchange::Measurements => {
                let (report, measurement) = estimator.step_sharing(frame, self.me)?;
                self.measurement = Some(measurement);
                Ok(report)
            }
        }
    }

    /// Publishes this agent's estimate of step `k`: its sets, or its measurement with the
    /// peers' it forwards; with the counters as of now, and the peers it asks for whole sets.
    pub(super) fn publish_estimate(
        &mut self,
        k: u64,
        process: &mut Process<'_>,
        estimator: &mut Estimator,
    ) -> Result<(), AgentError> {
        if self.full_map_from.is_some_and(|from| k >= from) {
            self.outbox.request_full();
            self.full_map_from = None;
        }
        let relayed = std::mem::take(&mut self.relay_out);
        let counters = &mut process.counters;
        let mut msg = match (&self.measurement, self.kind) {
            (Some(m), Exchange::Measurements) => {
                counters.shared.relayed_sent += relayed.len() as u64;
                self.outbox
                    .compose_measurement(estimator.state_mut(), m, &relayed)
            }
            _ => self.outbox.compose(estimator.state_mut()),
        };
        msg.stats = counters.shared;
        msg.want_whole = self.inbox.wanted() | std::mem::take(&mut self.missed);
        let bytes = message::to_bytes(&msg)?;
        process.send(WireKind::Estimate, k, &bytes)?;
        process.counters.estimates_sent += 1;
        Ok(())
    }

    /// Under the measurement exchange, sends the observers this agent's sets once it applied
    /// its peers' measurements of step `k` (the guarantee is checked on them).
    pub(super) fn publish_state(
        &mut self,
        k: u64,
        process: &mut Process<'_>,
        estimator: &mut Estimator,
    ) -> Result<(), AgentError> {
        let Some(outbox) = &mut self.state_outbox else {
            return Ok(());
        };
        let mut msg = outbox.compose(estimator.state_mut());
        msg.stats = process.counters.shared;
        let bytes = message::to_bytes(&msg)?;
        process.send(WireKind::State, k, &bytes)?;
        Ok(())
    }

    /// Fuses the awaited peers' estimates of step `k`, waiting for them (bounded). Sets are
    /// fused as they come (intersection does not depend on the order, so the work overlaps
    /// the wait); measurements are applied once the wait is over, all together in the order
    /// of the peers, not in whatever order they happened to come.
    pub(super) fn gather(
        &mut self,
        k: u64,
        process: &mut Process<'_>,
        presence: &mut Presence,
        estimator: &mut Estimator,
    ) {
        if presence.has_newcomer() {
            presence.refresh(&mut process.clock);
        }
        presence.view.start_step();
        let deadline = Instant::now() + process.config.timeouts.peer_wait;
        loop {
            let before = process.clock.enter(phase::FUSE);
            self.drain(process, estimator.config());
            if self.kind == Exchange::Sets {
                self.fuse_pending(k, estimator, &mut presence.view, &mut process.counters);
            }
            process.clock.enter(before);
            let missing = self.awaits_any(&presence.awaited(), k);
            if !missing || process.leaving() {
                break;
            }
            if Instant::now() >= deadline {
                process.counters.peer_timeouts += 1;
                tracing::debug!(step = k, "some peers' estimates did not arrive in time");
                break;
            }
            process.wait(deadline.min(Instant::now() + WAIT_SLICE), phase::WAIT_PEERS);
            // A peer that died meanwhile is no longer awaited.
            presence.refresh_if_stale(&mut process.clock);
        }
        let before = process.clock.enter(phase::FUSE);
        self.fuse_pending(k, estimator, &mut presence.view, &mut process.counters);
        process.clock.enter(before);
    }

    /// Whether a message of step `k` from one of the `awaited` peers has not been handled yet.
    fn awaits_any(&self, awaited: &BTreeSet<u32>, k: u64) -> bool {
        awaited.iter().any(|j| {
            self.peers
                .get(j)
                .and_then(|p| p.heard_step)
                .is_none_or(|s| s < k)
        })
    }

    /// Reads every pending peer estimate into the peers' queues, rebuilding them against
    /// estimates of `config`'s grids.
    pub(super) fn drain(&mut self, process: &mut Process<'_>, config: &EstimatorConfig) {
        let links = process.links;
        for (sender, sub) in &links.estimates_in {
            let sender = *sender;
            loop {
                let sample = match sub.receive() {
                    Ok(Some(s)) => s,
                    Ok(None) => break,
                    Err(e) => {
                        tracing::warn!(error = ?e, peer = sender, "receive failed");
                        break;
                    }
                };
                let header = *sample.user_header();
                if header.kind == WireKind::State as u32 {
                    // The peer's sets for the observers: nothing for an agent.
                    continue;
                }
                let checked = header.check(
                    sample.payload().len(),
                    WireKind::Estimate,
                    process.run_tag,
                    Some(sender),
                );
                let counters = &mut process.counters;
                if let Err(reason) = checked {
                    drop(sample);
                    counters.drop_message(reason, "estimate", &format!("from UAV {sender}"));
                    continue;
                }
                let parsed = message::from_bytes(sample.payload());
                drop(sample);
                match parsed {
                    Ok(m) if m.uav == sender => {
                        if self
                            .radio
                            .delivers(LinkKind::Estimate, sender, self.me, m.step)
                        {
                            self.read_peer(m, config, counters);
                        } else {
                            self.lose_estimate(&m);
                        }
                    }
                    Ok(m) => counters.drop_message(
                        DropReason::Sender,
                        "estimate",
                        &format!("claims UAV {} on UAV {sender}'s service", m.uav),
                    ),
                    Err(e) => {
                        counters.drop_message(DropReason::Malformed, "estimate", &e.to_string())
                    }
                }
            }
        }
    }

    /// Takes note of an estimate the radio lost: it is not read (nor its request for whole
    /// sets, nor its incarnation), and not awaited any longer.
    fn lose_estimate(&mut self, m: &EstimateMsg) {
        let info = self.peers.entry(m.uav).or_default();
        if info.incarnation.is_none_or(|i| m.incarnation >= i) {
            info.heard_step = info.heard_step.max(Some(m.step));
        }
        *self.lost_by_step.entry(m.step).or_default() += 1;
    }

    /// Rebuilds a peer's estimate and queues it. One that cannot be rebuilt for want of its
    /// base is not awaited any longer (this agent keeps its own sets for that step) and makes
    /// this agent ask for whole sets; a peer that asks them of this agent gets them next.
    /// Whole sets of the measurement exchange are queued as they came, and rebuilt when fused
    /// ([`Queued::Unread`]): whole, they need no base, and the inbox keeps none. One that
    /// cannot be rebuilt is counted as dropped then, and its step is not fused from it.
    fn read_peer(
        &mut self,
        m: EstimateMsg,
        config: &EstimatorConfig,
        counters: &mut AgentCounters,
    ) {
        if m.want_whole & uav_bit(self.me) != 0 {
            self.outbox.request_full();
        }
        if self.kind == Exchange::Measurements && m.sets.is_some() && m.base_seq.is_none() {
            self.queue_peer(Queued::Unread(Box::new(m)), counters);
            return;
        }
        match self.inbox.read_message(&m, config) {
            Ok(p) => self.queue_peer(Queued::Read(Box::new(p)), counters),
            Err(e) => {
                let reason = e.drop_reason();
                if reason == DropReason::NoBase {
                    let info = self.peers.entry(m.uav).or_default();
                    if info.incarnation.is_none_or(|i| i == m.incarnation) {
                        info.fused_step = Some(info.fused_step.map_or(m.step, |s| s.max(m.step)));
                        info.heard_step = info.heard_step.max(Some(m.step));
                    }
                }
                counters.drop_message(reason, "estimate", &e.to_string());
            }
        }
    }

    /// Queues a peer's rebuilt estimate, unless it comes from a process its peer replaced;
    /// notes a newcomer or a restart (it gets the whole map) and a missed message (its sender
    /// is asked for whole sets).
    fn queue_peer(&mut self, p: Queued, counters: &mut AgentCounters) {
        let (uav, step, seq, incarnation) = p.header();
        let info = self.peers.entry(uav).or_default();
        if info.incarnation.is_some_and(|i| incarnation < i) {
            let detail = format!("from UAV {uav}'s replaced process");
            counters.drop_message(DropReason::Superseded, "estimate", &detail);
            return;
        }
        if info.incarnation != Some(incarnation) {
            if info.incarnation.is_some() {
                tracing::info!(peer = uav, "peer restarted: sending it the whole map");
            }
            // A newcomer or a restarted peer needs the whole map to rebuild its own. It goes
            // with the estimate of the step after the peer's, whenever this message arrived:
            // in lockstep that keeps the traffic, like everything else, reproducible. Under
            // the measurement exchange a peer that starts with the run (its first estimate is
            // of step 0) has missed nothing: the measurements bring it everything.
            let started_with_run = step == 0 && info.incarnation.is_none();
            if !(started_with_run && self.kind == Exchange::Measurements) {
                let from = step + 1;
                self.full_map_from = Some(self.full_map_from.map_or(from, |f| f.min(from)));
            }
            info.incarnation = Some(incarnation);
            info.fused_step = None;
            info.last_seq = None;
        }
        // Under the measurement exchange on links that lose nothing, a message missed (this
        // agent was stalled, its buffer overflowed) is a measurement never applied: ask the
        // peer for its whole sets. Lossy and limited links have them periodically instead.
        let missed = info.last_seq.is_some_and(|last| seq > last + 1);
        info.last_seq = Some(seq);
        if missed && self.kind == Exchange::Measurements && !self.radio.loses_or_limits() {
            tracing::info!(
                peer = uav,
                seq = seq,
                "estimates missed: asking for whole sets"
            );
            self.missed |= uav_bit(uav);
        }
        info.heard_step = info.heard_step.max(Some(step));
        info.pending.push(p);
    }

    /// Fuses every queued estimate that has arrived by step `k` (of step `k - d` and older
    /// with a latency of `d` steps; older ones than `k` are dilated by the fusion), in
    /// ascending order of peer, as the radio's rule says ([`Radio::fuses`]: the queue holds
    /// only delivered estimates, so what is left out is out of range), and counts the lost
    /// estimates of the steps up to `k`. The peers fused are heard at the step (`view`).
    fn fuse_pending(
        &mut self,
        k: u64,
        estimator: &mut Estimator,
        view: &mut LiveView,
        counters: &mut AgentCounters,
    ) {
        let me = Endpoint {
            uav: self.me,
            step: k,
            pose: estimator.state().pose,
        };
        let radio = self.radio;
        let later = self.lost_by_step.split_off(&k.saturating_add(1));
        let lost = std::mem::replace(&mut self.lost_by_step, later);
        counters.shared.estimates_lost += lost.values().sum::<u64>();
        // Measurements other agents forward, by (step, UAV), each with its fewest hops:
        // applied after the senders' own, in that order, so runs stay reproducible.
        let mut forwarded: BTreeMap<(u64, u32), Relayed> = BTreeMap::new();
        let fleet = self.fleet;
        let mut relay = Relaying {
            hops: self.relay_hops,
            applied: &mut self.applied,
            out: &mut self.relay_out,
        };
        let inbox = &mut self.inbox;
        for info in self.peers.values_mut() {
            let (ready, later): (Vec<_>, Vec<_>) = info
                .pending
                .drain(..)
                .partition(|p| radio.arrived(p.step(), k));
            info.pending = later;
            for p in ready {
                if info.fused_step.is_some_and(|s| s >= p.step()) {
                    continue;
                }
                info.fused_step = Some(p.step());
                let p = match p {
                    Queued::Read(p) => *p,
                    Queued::Unread(m) => match inbox.read_message(&m, estimator.config()) {
                        Ok(p) => p,
                        Err(e) => {
                            counters.drop_message(e.drop_reason(), "estimate", &e.to_string());
                            continue;
                        }
                    },
                };
                if view.fuses(&radio, &me, &p.endpoint()) {
                    if let Some(m) = &p.measurement {
                        relay.apply(estimator, m, 0);
                    }
                    if let Some(e) = &p.estimate {
                        estimator.fuse(e);
                    }
                    for r in p.relayed {
                        let m = &r.measurement;
                        if m.uav == me.uav || m.uav >= fleet {
                            continue;
                        }
                        let key = (m.step, m.uav);
                        if forwarded.get(&key).is_none_or(|kept| r.hops < kept.hops) {
                            forwarded.insert(key, r);
                        }
                    }
                    counters.shared.estimates_received += 1;
                } else {
                    counters.estimates_out_of_range += 1;
                }
            }
        }
        for r in forwarded.into_values() {
            if relay.apply(estimator, &r.measurement, r.hops) {
                counters.shared.relayed_applied += 1;
            }
        }
        // A copy comes at most a step and the radio's delay per hop after the measurement's
        // own step: older ones need no memory (one that came later still would be applied
        // again, which keeps the guarantee like any measurement).
        let keep = (u64::from(self.relay_hops) + 1) * (radio.latency_steps() + 1) + 1;
        let oldest = k.saturating_sub(keep);
        self.applied = self.applied.split_off(&(oldest, 0));
    }
}

/// How an agent applies its peers' measurements when it forwards them (`comms.relay_hops`).
struct Relaying<'a> {
    /// How many times a measurement is forwarded (0: never, and nothing is remembered).
    hops: u32,
    /// The measurements applied lately, as (step, UAV).
    applied: &'a mut BTreeSet<(u64, u32)>,
    /// What the next estimate forwards.
    out: &'a mut Vec<Relayed>,
}

impl Relaying<'_> {
    /// Applies `m`, which reached this agent after `hops` forwardings (0: from its sender),
    /// unless it was applied already; keeps it to forward when it has hops left. Whether it
    /// was applied now.
    fn apply(&mut self, estimator: &mut Estimator, m: &Measurement, hops: u32) -> bool {
        if self.hops == 0 {
            estimator.apply(m);
            return true;
        }
        if !self.applied.insert((m.step, m.uav)) {
            return false;
        }
        estimator.apply(m);
        if hops < self.hops {
            self.out.push(Relayed {
                hops: hops + 1,
                measurement: m.clone(),
            });
        }
        true
    }
}
