//! Who is there for an agent ([`Presence`]): whom it awaits at its step, and whom it knows
//! live.
//!
//! **Awaited** are the peers the world serves at the step (the frame's `served` mask, the same
//! for every agent) whose iceoryx2 node is alive (a SIGKILLed peer shows up dead at once and its
//! resources are cleaned). They say that a message will never be sent (a peer the world does
//! not serve sends no estimate, a dead holder no token), so they end the agent's waits.
//! Listing the nodes costs milliseconds of CPU, so it is done when the served mask names a peer
//! not known alive, and while waiting at most once per [`liveness_scan_period`], not at every
//! step and every wake-up (the world drops a peer that died before the step from the mask).
//! The same listing says whether the world-server's node is alive.
//!
//! **Known live** ([`LiveView`], `comms.liveness`) are the UAVs its token ring waits for and
//! skips, and the round's fleet ([`crate::guidance::TokenRing`]):
//!
//! - **Radio** (the default): the peers whose estimate the agent fuses at its step, by the
//!   radio's rule ([`Radio::fuses`]: delivered, arrived, sent from within range). A peer out
//!   of range, or whose estimate the radio lost, is not live to the agent at that step, however
//!   alive its process is: the agent has heard nothing from it.
//! - **World**: the awaited peers, the same for every agent.
//!
//! Under both readings the agent still awaits every served, alive peer's estimate of the step
//! before it fuses (bounded): a message comes over the IPC whatever the radio then decides,
//! and only the mask and the node list say that one will never be sent. They end waits; under
//! the radio's reading they never add a UAV to what the agent knows live. The two are one part
//! because the ring asks both at each hop: whom it knows live, and whether the holder it waits
//! for can still send.

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use fleet_process::resources::PhaseClock;
use protocol::ipc::{RunNode, scan_nodes};
use protocol::radio::{Endpoint, Radio};
use protocol::scenario::Liveness;
use protocol::service::RunId;
use protocol::wire::{UavMask, uav_bit};

use super::config::AgentConfig;
use super::phase;

/// How old the last listing of the run's nodes may grow while the agent waits for peers or the
/// token before it lists them again, for a fleet of up to [`UAVS_PER_SCAN_PERIOD`] UAVs: a peer
/// that died meanwhile stops being awaited within this time. A listing costs about a
/// millisecond of CPU; at every wait slice it was about 5 % of a run's CPU. The world lists
/// them before every step anyway and serves only the live agents.
const LIVENESS_SCAN_PERIOD: Duration = Duration::from_millis(250);

/// A listing reads every node of the run, so it costs more in a larger fleet, and every agent
/// of it lists: the period grows by [`LIVENESS_SCAN_PERIOD`] for every this many UAVs
/// ([`liveness_scan_period`]).
const UAVS_PER_SCAN_PERIOD: u32 = 4;

/// How old the last listing may grow in a fleet of `uavs` UAVs: [`LIVENESS_SCAN_PERIOD`] up to
/// [`UAVS_PER_SCAN_PERIOD`] UAVs, and as many times that as it has groups of them (1 s for 16
/// UAVs, 4 s for 64). With a period that stays, the listings of a 64-UAV fleet on one machine
/// took about 80 % of its agents' CPU. A dead peer still costs at most the peer wait of the
/// step it died in: the world's listing before the next step no longer serves it.
fn liveness_scan_period(uavs: u32) -> Duration {
    LIVENESS_SCAN_PERIOD * uavs.div_ceil(UAVS_PER_SCAN_PERIOD).max(1)
}

/// Whom an agent awaits at its step and whom it knows live.
pub(super) struct Presence {
    /// The run whose nodes are listed.
    run_id: RunId,
    /// This agent's UAV.
    me: u32,
    /// UAVs in the fleet.
    fleet: u32,
    /// How old the last listing may grow while waiting ([`liveness_scan_period`]).
    scan_period: Duration,
    /// The agents the world serves at the current step (the frame's mask).
    served: UavMask,
    /// Live peers (this agent excluded), from the run's node list.
    live: BTreeSet<u32>,
    /// Whether the world's node was alive at the last listing.
    world_live: bool,
    /// When the run's nodes were last listed.
    last_scan: Instant,
    /// Whom the agent knows live at its step, for the ring (`comms.liveness`).
    pub(super) view: LiveView,
}

impl Presence {
    /// Nothing listed yet: every agent served, the world presumed alive.
    pub(super) fn new(config: &AgentConfig) -> Self {
        let fleet = config.scenario.uavs.count;
        Presence {
            run_id: config.run_id.clone(),
            me: config.uav,
            fleet,
            scan_period: liveness_scan_period(fleet),
            served: UavMask::MAX,
            live: BTreeSet::new(),
            world_live: true,
            last_scan: Instant::now(),
            view: LiveView::new(config.scenario.comms.liveness),
        }
    }

    /// A new step whose frame says the world serves `served` (0: a world that does not say
    /// whom it serves, and every live peer is awaited).
    pub(super) fn serve(&mut self, served: UavMask) {
        self.served = match served {
            0 => UavMask::MAX,
            mask => mask,
        };
    }

    /// Re-reads which peers and whether the world are alive (and cleans dead nodes), counting
    /// the time to [`phase::SCAN`].
    pub(super) fn refresh(&mut self, clock: &mut PhaseClock) {
        let before = clock.enter(phase::SCAN);
        let scanned = scan_nodes(&self.run_id, true);
        clock.enter(before);
        self.last_scan = Instant::now();
        match scanned {
            Ok(scan) => {
                self.world_live = scan.is_alive(RunNode::WORLD);
                self.live = (0..self.fleet)
                    .filter(|&j| j != self.me && scan.is_alive(&RunNode::agent_name(j)))
                    .collect();
                for dead in &scan.dead {
                    tracing::info!(node = %dead, "cleaned up a dead node");
                }
            }
            Err(e) => tracing::warn!(error = %e, "cannot list the run's nodes"),
        }
    }

    /// Lists the run's nodes if the last listing is [`liveness_scan_period`] old: while
    /// waiting, a peer that died is noticed within that time.
    pub(super) fn refresh_if_stale(&mut self, clock: &mut PhaseClock) {
        if self.last_scan.elapsed() >= self.scan_period {
            self.refresh(clock);
        }
    }

    /// Whether the world serves a peer not known alive (one that (re)joined): the world lists
    /// the nodes before every step, so a peer it serves is alive unless it died since, which
    /// the waits notice; only a newcomer needs a look.
    pub(super) fn has_newcomer(&self) -> bool {
        (0..self.fleet)
            .any(|j| j != self.me && self.served & uav_bit(j) != 0 && !self.live.contains(&j))
    }

    /// Whether peer `uav`'s node was alive at the last listing.
    pub(super) fn is_alive(&self, uav: u32) -> bool {
        self.live.contains(&uav)
    }

    /// Whether the world's node was alive at the last listing.
    pub(super) fn world_live(&self) -> bool {
        self.world_live
    }

    /// The peers awaited at the current step: served by the world and alive.
    pub(super) fn awaited(&self) -> BTreeSet<u32> {
        self.live
            .iter()
            .copied()
            .filter(|&j| self.served & uav_bit(j) != 0)
            .collect()
    }

    /// The UAVs this agent knows live at its step, itself included, as `comms.liveness` reads
    /// it: what the token ring waits for and the round's fleet.
    pub(super) fn ring_live(&self) -> BTreeSet<u32> {
        self.view.live(self.me, self.awaited())
    }
}

/// The peers an agent knows live at its current step.
#[derive(Clone, Debug)]
pub(super) struct LiveView {
    reading: Liveness,
    /// The peers whose estimate the agent fused at its current step.
    heard: BTreeSet<u32>,
}

impl LiveView {
    /// Nothing heard yet, read as `reading` says.
    pub(super) fn new(reading: Liveness) -> Self {
        Self {
            reading,
            heard: BTreeSet::new(),
        }
    }

    /// A new step: no peer heard in it yet.
    pub(super) fn start_step(&mut self) {
        self.heard.clear();
    }

    /// Whether the agent at `receiver` fuses the estimate of `sender` ([`Radio::fuses`]); if it
    /// does, `sender` is heard at this step.
    pub(super) fn fuses(&mut self, radio: &Radio, receiver: &Endpoint, sender: &Endpoint) -> bool {
        let fuses = radio.fuses(receiver, sender);
        if fuses {
            self.heard.insert(sender.uav);
        }
        fuses
    }

    /// The UAVs agent `me` knows live, itself included: under the radio's reading the peers
    /// it heard at its step; under the world's, `served` (the peers the world serves whose
    /// process is alive).
    pub(super) fn live(&self, me: u32, served: BTreeSet<u32>) -> BTreeSet<u32> {
        let mut live = match self.reading {
            Liveness::Radio => self.heard.clone(),
            Liveness::World => served,
        };
        live.insert(me);
        live
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use protocol::camera::CameraPose;
    use protocol::radio::LinkKind;
    use sets::math::Point3;

    use super::*;

    #[test]
    fn the_liveness_listing_slows_down_with_the_fleet() {
        let ms = |uavs| liveness_scan_period(uavs).as_millis();
        assert_eq!([ms(0), ms(1), ms(4)], [250, 250, 250]);
        assert_eq!([ms(5), ms(8), ms(16), ms(64)], [500, 500, 1000, 4000]);
    }

    fn at(uav: u32, step: u64, (x, y): (f64, f64)) -> Endpoint {
        Endpoint {
            uav,
            step,
            pose: Some(CameraPose {
                position: Point3::new(x, y, 60.0 + 10.0 * f64::from(uav)),
                yaw: 0.0,
            }),
        }
    }

    /// The live set of each of `positions`' agents at `step` when each fuses every other's
    /// estimate of `step - latency`, sent from the same positions.
    fn live_sets(radio: &Radio, positions: &[(f64, f64)], step: u64) -> Vec<BTreeSet<u32>> {
        let sent = step - radio.latency_steps();
        (0..positions.len() as u32)
            .map(|me| {
                let receiver = at(me, step, positions[me as usize]);
                let mut view = LiveView::new(Liveness::Radio);
                view.start_step();
                for (j, &p) in positions.iter().enumerate() {
                    view.fuses(radio, &receiver, &at(j as u32, sent, p));
                }
                view.live(me, (0..positions.len() as u32).collect())
            })
            .collect()
    }

    /// By hand, 100 m of range: 0 at (0, 0), 1 at (60, 80) (100 m from 0), 2 at (0, 101)
    /// (101 m from 0, 63.6 m from 1), 3 at (-70, 0) (70 m from 0, 152.6 m from 1, 122.9 m
    /// from 2).
    #[test]
    fn under_the_radio_an_agent_knows_live_the_peers_it_heard() {
        let positions = [(0.0, 0.0), (60.0, 80.0), (0.0, 101.0), (-70.0, 0.0)];
        let radio = Radio::perfect().with_range(100.0);
        let expected: Vec<BTreeSet<u32>> = [&[0, 1, 3][..], &[0, 1, 2], &[1, 2], &[0, 3]]
            .iter()
            .map(|s| s.iter().copied().collect())
            .collect();
        assert_eq!(live_sets(&radio, &positions, 6), expected);
        // Unlimited range: everyone; the world's reading: whom the world serves.
        let all: BTreeSet<u32> = (0..4).collect();
        assert!(
            live_sets(&Radio::perfect(), &positions, 6)
                .iter()
                .all(|l| *l == all)
        );
        let world = LiveView::new(Liveness::World);
        assert_eq!(world.live(2, [0, 3].into()), [0, 2, 3].into());
        // A new step forgets what was heard.
        let mut view = LiveView::new(Liveness::Radio);
        assert!(view.fuses(&radio, &at(0, 6, positions[0]), &at(1, 6, positions[1])));
        view.start_step();
        assert_eq!(view.live(0, all), [0].into());
    }

    proptest! {
        /// Under the radio's reading an agent never knows live a peer that was out of range
        /// (its camera as it sent, the receiver's as it fuses) or whose estimate the radio
        /// lost, and knows live every other peer it fused: whatever the world serves.
        #[test]
        fn radio_liveness_never_includes_a_peer_out_of_range_or_lost(
            positions in proptest::collection::vec((-300.0f64..300.0, -300.0f64..300.0), 2..8),
            range in 1.0f64..400.0, seed in any::<u64>(), loss in 0.0f64..=0.5,
            latency in 0u64..3, step in 3u64..100,
        ) {
            let radio = Radio::perfect()
                .with_range(range)
                .with_loss(seed, loss)
                .with_latency_steps(latency);
            let sent = step - latency;
            for (me, live) in live_sets(&radio, &positions, step).iter().enumerate() {
                let me = me as u32;
                let mine = positions[me as usize];
                for (j, &p) in positions.iter().enumerate() {
                    let j = j as u32;
                    if j == me {
                        prop_assert!(live.contains(&j));
                        continue;
                    }
                    let distance = ((p.0 - mine.0).powi(2) + (p.1 - mine.1).powi(2)).sqrt();
                    let heard = distance <= range
                        && radio.delivers(LinkKind::Estimate, j, me, sent);
                    prop_assert_eq!(
                        live.contains(&j), heard,
                        "agent {} and peer {} {} m apart, range {}", me, j, distance, range
                    );
                }
            }
        }
    }
}
