//! Whom an agent knows live at its step (`comms.liveness`): the UAVs its token ring waits for
//! and skips, and the round's fleet ([`crate::guidance::TokenRing`]).
//!
//! - **Radio** (the default): the peers whose estimate the agent fuses at its step, by the
//!   radio's rule ([`Radio::fuses`]: delivered, arrived, sent from within range). A peer out
//!   of range, or whose estimate the radio lost, is not live to the agent at that step, however
//!   alive its process is: the agent has heard nothing from it.
//! - **World**: the peers the world serves at the step (the frame's mask) whose process the
//!   run's node list shows alive, the same for every agent.
//!
//! Under both readings the agent still awaits every served, alive peer's estimate of the step
//! before it fuses (bounded): a message comes over the IPC whatever the radio then decides,
//! and only the mask and the node list say that one will never be sent. They end waits; under
//! the radio's reading they never add a UAV to what the agent knows live.

use std::collections::BTreeSet;

use protocol::radio::{Endpoint, Radio};
use protocol::scenario::Liveness;

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
