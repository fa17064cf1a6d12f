//! Reception: the observer receives the agents' estimates as an agent does, so that it can
//! rebuild the sets each agent holds after its own fusion of a step.
//!
//! [`Reception`] owns everything that takes: what decoding needs (the estimator's
//! configuration, what the agents' estimates carry, and the inbox of the agents' last sets
//! that their deltas are read against), the store of decoded estimates waiting for the truth
//! of their step, and the agents' radio with its latency queue (the estimates already
//! measured that the agents fuse `d` steps later). Kept together because each of them only
//! makes sense against the others: a delta needs the inbox, a fusion needs the radio and the
//! queue, the queue is fed by the store. What is received is counted in the run's
//! [`ObserverReport`] (traffic, drops, each agent's tally) and merged into its fleet map.

use std::collections::BTreeMap;

use estimator::message::{self, EstimateInbox, PeerMessage};
use estimator::occupancy::OccupancyMap;
use estimator::{EstimateReadError, EstimatorConfig};
use iceoryx2::sample::Sample;
use protocol::ipc::Ipc;
use protocol::radio::Radio;
use protocol::scenario::{Exchange, Scenario};
use protocol::wire::{DropReason, WireHeader, WireKind, unix_now_ns};
use sets::grid::GroundGrid;
use sets::raster::CellBox;

use super::ObserverReport;
use super::metrics::{EstimateObserveError, FusedSets, ObservedEstimate};
use super::tally::ServiceKind;

/// Steps of estimates kept per agent ahead of the truth being processed.
const MAX_STORED_STEPS: usize = 64;

/// One message received on an agent's estimate service.
pub(super) type EstimateSample = Sample<Ipc, [u8], WireHeader>;

/// The observer as a receiver of the agents' estimates (see the [module](self) docs).
pub(super) struct Reception {
    /// The agents' estimator configuration, for decoding and fusing.
    estimator: EstimatorConfig,
    /// What the agents' estimates carry (`comms.exchange`).
    exchange: Exchange,
    /// The agents' last sets, the bases of their deltas.
    inbox: EstimateInbox,
    /// Decoded estimates per agent, by step, not yet measured.
    store: BTreeMap<u32, BTreeMap<u64, ObservedEstimate>>,
    /// The agents' links.
    radio: Radio,
    /// With a latency of `d` steps, the estimates of the last `d` steps measured, by step:
    /// those the agents fuse in the next `d` steps.
    sent: BTreeMap<u64, Vec<ObservedEstimate>>,
}

impl Reception {
    /// Receives the estimates of `scenario`'s agents, as they do: by their estimator, their
    /// exchange and their radio.
    pub(super) fn new(scenario: &Scenario) -> Reception {
        Reception {
            estimator: EstimatorConfig::from_scenario(scenario),
            exchange: scenario.comms.exchange,
            inbox: EstimateInbox::new(),
            store: BTreeMap::new(),
            radio: Radio::from_scenario(scenario),
            sent: BTreeMap::new(),
        }
    }

    /// The ground grid the agents' sets live on.
    pub(super) fn grid(&self) -> GroundGrid {
        self.estimator.grid
    }

    /// The window over which the sender of `estimate` kept `X̄` at its step
    /// ([`EstimatorConfig::window_of`] of its pose); `None` without windows.
    pub(super) fn window_of(&self, estimate: &ObservedEstimate) -> Option<CellBox> {
        self.estimator.window_of(estimate.estimate.pose.as_ref()?)
    }

    /// The grid of the agents' occupancy maps.
    pub(super) fn oem_grid(&self) -> GroundGrid {
        self.estimator.oem_grid
    }

    /// Receives one message of `sender`'s estimate service of the run tagged `run_tag`: counts
    /// it, checks it, decodes it (against the inbox when it carries deltas) and stores it for
    /// its step, merging its map cells into the report's fleet map. A message that cannot be
    /// used is counted as dropped. Returns whether the fleet map changed.
    pub(super) fn receive(
        &mut self,
        sender: u32,
        sample: EstimateSample,
        run_tag: u64,
        report: &mut ObserverReport,
    ) -> bool {
        let header = *sample.user_header();
        let len = sample.payload().len();
        // Under the measurement exchange the agents' sets come in state messages, for the
        // observers only; their estimates carry measurements, for the traffic and the map.
        let (kind, service) = match self.exchange {
            Exchange::Measurements if header.kind == WireKind::State as u32 => {
                (WireKind::State, ServiceKind::States)
            }
            _ => (WireKind::Estimate, ServiceKind::Estimates),
        };
        report.comms.count_timed(
            service,
            (len + std::mem::size_of::<WireHeader>()) as u64,
            header.sent_unix_ns,
            unix_now_ns(),
        );
        if let Err(reason) = header.check(len, kind, run_tag, Some(sender)) {
            drop(sample);
            report.drop_estimate(sender, reason);
            return false;
        }
        let changed = self.receive_payload(sender, kind, sample.payload(), report);
        drop(sample);
        changed
    }

    /// Receives the payload of one checked message of `sender`'s of `kind` (an estimate, or
    /// under the measurement exchange a state message): decodes it and stores it for its step,
    /// or counts it as dropped (see [`Reception::receive`]). Returns whether the fleet map
    /// changed.
    pub(super) fn receive_payload(
        &mut self,
        sender: u32,
        kind: WireKind,
        payload: &[u8],
        report: &mut ObserverReport,
    ) -> bool {
        let mut oem_changed = false;
        if self.exchange == Exchange::Measurements && kind == WireKind::Estimate {
            let read = message::from_bytes(payload)
                .map_err(EstimateReadError::from)
                .and_then(|msg| PeerMessage::from_msg(&msg, &self.estimator).map(|_| msg));
            match read {
                Ok(msg) if msg.uav == sender => {
                    let tally = report.agents.entry(sender).or_default();
                    tally.observe_message(msg.step, msg.incarnation, msg.seq, msg.stats);
                    for u in &msg.oem {
                        if let Ok((index, cell)) =
                            OccupancyMap::cell_of_update(&self.estimator.oem_grid, u)
                        {
                            oem_changed |= report.oem.merge_cell(index, cell);
                        }
                    }
                }
                Ok(_) => report.drop_estimate(sender, DropReason::Sender),
                Err(err) => {
                    tracing::warn!(uav = sender, error = %err, "unreadable estimate dropped");
                    report.drop_estimate(sender, err.drop_reason());
                }
            }
            return oem_changed;
        }
        let decoded = ObservedEstimate::read(&mut self.inbox, payload, &self.estimator);
        match decoded {
            Ok((e, _)) if e.uav() != sender => {
                report.drop_estimate(sender, DropReason::Sender);
                tracing::warn!(
                    uav = sender,
                    claims = e.uav(),
                    "estimate of another UAV dropped"
                );
            }
            Ok((e, map)) => {
                oem_changed |= report.oem.merge(&map);
                if self.exchange == Exchange::Sets {
                    report.agents.entry(sender).or_default().observe(&e);
                }
                let steps = self.store.entry(sender).or_default();
                steps.insert(e.step(), e);
                while steps.len() > MAX_STORED_STEPS {
                    steps.pop_first();
                }
            }
            Err(EstimateObserveError::Read(err)) => {
                tracing::warn!(uav = sender, error = %err, "unreadable estimate dropped");
                report.drop_estimate(sender, err.drop_reason());
            }
        }
        oem_changed
    }

    /// Whether `uav`'s estimate of step `k` is stored.
    pub(super) fn has(&self, uav: u32, k: u64) -> bool {
        self.store.get(&uav).is_some_and(|s| s.contains_key(&k))
    }

    /// Takes every agent's estimate of step `k` out of the store, dropping older ones.
    pub(super) fn take(&mut self, k: u64) -> Vec<ObservedEstimate> {
        self.store
            .values_mut()
            .filter_map(|steps| {
                let e = steps.remove(&k);
                // Older steps will never be measured now.
                steps.retain(|&s, _| s > k);
                e
            })
            .collect()
    }

    /// Each agent's sets after its fusion of step `k`, in the order of `estimates` (the
    /// estimates of step `k`): fused as the agent did, with the estimates its links
    /// delivered.
    pub(super) fn fuse(&self, k: u64, estimates: &[ObservedEstimate]) -> Vec<(u32, FusedSets)> {
        let d = self.radio.latency_steps();
        let sent: &[ObservedEstimate] = if d == 0 {
            estimates
        } else {
            k.checked_sub(d)
                .and_then(|from| self.sent.get(&from))
                .map_or(&[], Vec::as_slice)
        };
        let all_fused = match self.exchange {
            Exchange::Sets => FusedSets::of_agents(estimates, sent, &self.estimator, &self.radio),
            // The agents' state messages hold their sets once they applied their peers'.
            Exchange::Measurements => estimates.iter().map(FusedSets::held).collect(),
        };
        estimates
            .iter()
            .map(ObservedEstimate::uav)
            .zip(all_fused)
            .collect()
    }

    /// With a link latency, keeps step `k`'s estimates for the steps that fuse them.
    pub(super) fn keep_sent(&mut self, k: u64, estimates: Vec<ObservedEstimate>) {
        let d = self.radio.latency_steps();
        // Under the measurement exchange the agents' own state messages are measured: nothing
        // is fused later.
        if d > 0 && self.exchange == Exchange::Sets {
            // Kept for the steps `k + 1 ..= k + d`, which fuse them.
            self.sent.insert(k, estimates);
            self.sent = self.sent.split_off(&k.saturating_add(1).saturating_sub(d));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::metrics::tests::blank;
    use super::*;

    /// The reception of the default scenario's agents exchanging sets, with a link latency of
    /// `d` steps.
    fn reception(d: u64) -> Reception {
        let mut scenario = Scenario::default();
        scenario.comms.exchange = Exchange::Sets;
        scenario.comms.latency_ms = d as f64 * scenario.timing.cvs_period_s * 1000.0;
        let reception = Reception::new(&scenario);
        assert_eq!(reception.radio.latency_steps(), d);
        reception
    }

    fn store(reception: &mut Reception, uav: u32, step: u64) {
        let e = blank(&reception.grid(), uav, step);
        reception.store.entry(uav).or_default().insert(step, e);
    }

    #[test]
    fn taking_a_step_takes_every_agents_estimate_of_it_and_drops_the_older() {
        let mut r = reception(0);
        for step in 1..=3 {
            store(&mut r, 0, step);
        }
        store(&mut r, 1, 2);
        store(&mut r, 2, 1);
        assert!(r.has(0, 2) && r.has(1, 2) && !r.has(2, 2));
        let taken = r.take(2);
        let taken: Vec<(u32, u64)> = taken.iter().map(|e| (e.uav(), e.step())).collect();
        assert_eq!(taken, [(0, 2), (1, 2)]);
        assert!(r.has(0, 3));
        assert!(!r.has(0, 1) && !r.has(2, 1) && !r.has(0, 2));
    }

    #[test]
    fn with_a_latency_of_d_steps_the_estimates_of_the_last_d_steps_are_kept() {
        let mut r = reception(2);
        for k in 0..5 {
            let estimates = vec![blank(&r.grid(), 0, k)];
            r.keep_sent(k, estimates);
            let kept: Vec<u64> = r.sent.keys().copied().collect();
            assert_eq!(kept, (k.saturating_sub(1)..=k).collect::<Vec<_>>());
        }
    }

    #[test]
    fn without_latency_or_under_the_measurement_exchange_nothing_is_kept_for_later() {
        let mut r = reception(0);
        let estimates = vec![blank(&r.grid(), 0, 4)];
        r.keep_sent(4, estimates);
        assert!(r.sent.is_empty());
        let mut r = reception(2);
        r.exchange = Exchange::Measurements;
        let estimates = vec![blank(&r.grid(), 0, 4)];
        r.keep_sent(4, estimates);
        assert!(r.sent.is_empty());
    }

    #[test]
    fn fused_sets_come_in_the_order_of_the_estimates() {
        let r = reception(0);
        let estimates = vec![blank(&r.grid(), 1, 4), blank(&r.grid(), 3, 4)];
        let fused = r.fuse(4, &estimates);
        let uavs: Vec<u32> = fused.iter().map(|(uav, _)| *uav).collect();
        assert_eq!(uavs, [1, 3]);
    }
}
