//! The token ring ([`uav_agent::guidance::ring`]) on lossy, range-limited links: every token
//! reaches every agent's queue when it is sent (as on the IPC), and each receiver decides with
//! the run's [`Radio`] whether the radio carried it ([`TokenRing::receive`]), as the agent loop
//! does. Agents poll in an order drawn from a seed of its own, draining their queue and asking
//! for their turn; nothing ever times out (no holder is declared silent by a wait), so a round
//! that needed a wait would deadlock the simulation and fail it.
//!
//! Properties, for 2 to 6 agents, any loss and several rounds, under both readings of who is
//! live (`comms.liveness`) and, for the radio's, random positions and ranges (the UAVs move
//! between rounds; tokens limited by the range as estimates are):
//! - every round ends: each agent decides exactly once, with no wait run out;
//! - under the world's reading, each decision is taken around exactly the plans carried by the
//!   tokens its radio delivered to it before (none that it lost, unless a later token carried
//!   them); under the radio's, around exactly the plans carried by the tokens it read from the
//!   UAVs before it that it heard (fused the estimate of) at the round's step;
//! - the plans each agent decides around do not depend on the order agents poll in: the same
//!   seed gives the same decisions (what makes lossy lockstep runs reproducible).

use std::collections::{BTreeMap, BTreeSet, VecDeque};

use proptest::prelude::*;
use protocol::camera::CameraPose;
use protocol::radio::{Endpoint, Radio};
use protocol::scenario::Liveness;
use protocol::wire::{GuidanceToken, PlannedView};
use sets::math::Point3;
use uav_agent::guidance::{TokenRing, Turn};

/// Steps per guidance period.
const STEPS: u64 = 6;

/// splitmix64, for the polling order and the positions.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }

    /// Uniform in `[-h, h)`.
    fn coordinate(&mut self, h: f64) -> f64 {
        ((self.next() >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) * h
    }
}

fn plan(uav: u32, round: u64) -> PlannedView {
    PlannedView {
        uav,
        poses: vec![CameraPose {
            position: Point3::new(f64::from(uav), 0.0, 80.0),
            yaw: round as f64,
        }],
    }
}

/// What happened in a run: per round and agent, the UAVs whose plans it decided around.
type Decisions = BTreeMap<(u64, u32), Vec<u32>>;

struct Outcome {
    decisions: Decisions,
    lost: u64,
}

/// How the agents of a run know each other: who is live, and where the UAVs are in each round
/// (drawn from `positions` in a square of `2 * half_extent_m` m; all at the origin when
/// `positions` is `None`).
#[derive(Clone, Copy)]
struct Links {
    radio: Radio,
    liveness: Liveness,
    positions: Option<u64>,
    half_extent_m: f64,
}

impl Links {
    fn world(radio: Radio) -> Self {
        Self {
            radio,
            liveness: Liveness::World,
            positions: None,
            half_extent_m: 0.0,
        }
    }

    /// Where each of `n` UAVs is at `step`: the camera poses of their messages.
    fn endpoints(&self, n: u32, step: u64) -> Vec<Endpoint> {
        let mut rng = Rng(self.positions.unwrap_or(0) ^ step.wrapping_mul(0x2545_f491));
        (0..n)
            .map(|uav| {
                let (x, y) = match self.positions {
                    Some(_) => (
                        rng.coordinate(self.half_extent_m),
                        rng.coordinate(self.half_extent_m),
                    ),
                    None => (0.0, 0.0),
                };
                Endpoint {
                    uav,
                    step,
                    pose: Some(CameraPose {
                        position: Point3::new(x, y, 60.0),
                        yaw: 0.0,
                    }),
                }
            })
            .collect()
    }

    /// Whom each agent knows live at `step`: everyone under the world's reading; under the
    /// radio's, itself and the peers whose estimate of the step it fuses.
    fn live(&self, at: &[Endpoint]) -> Vec<BTreeSet<u32>> {
        at.iter()
            .map(|me| match self.liveness {
                Liveness::World => at.iter().map(|e| e.uav).collect(),
                Liveness::Radio => at
                    .iter()
                    .filter(|e| e.uav == me.uav || self.radio.fuses(me, e))
                    .map(|e| e.uav)
                    .collect(),
            })
            .collect()
    }
}

/// Runs `rounds` rounds of `n` agents over `links`, agents polling in the order drawn from
/// `order_seed`.
fn run(n: u32, rounds: u64, links: Links, order_seed: u64) -> Result<Outcome, TestCaseError> {
    let radio = links.radio;
    let mut rings: Vec<TokenRing> = (0..n).map(|i| TokenRing::new(i, links.liveness)).collect();
    // Tokens in each agent's queue, with their sender (the wire header's).
    let mut queues: Vec<VecDeque<(GuidanceToken, u32)>> = vec![VecDeque::new(); n as usize];
    // Per agent, the tokens read in the current round: sender -> the UAVs of its plans.
    let mut read: Vec<BTreeMap<u32, BTreeSet<u32>>> = vec![BTreeMap::new(); n as usize];
    let mut order = Rng(order_seed);
    let mut outcome = Outcome {
        decisions: Decisions::new(),
        lost: 0,
    };
    let reads = |at: &[Endpoint], token: &GuidanceToken, sender: u32, me: u32| {
        let from = Endpoint {
            pose: token.pose,
            ..at[sender as usize]
        };
        radio.carries_token(&at[me as usize], &from)
    };
    let mut at = Vec::new();
    for round in 0..rounds {
        let step = round * STEPS;
        // The last tokens of the previous round, still queued where their receivers had
        // decided already: read at that round's step.
        for (me, queue) in queues.iter_mut().enumerate() {
            for (token, sender) in queue.drain(..) {
                outcome.lost += u64::from(!reads(&at, &token, sender, me as u32));
            }
        }
        at = links.endpoints(n, step);
        let live = links.live(&at);
        read.iter_mut().for_each(BTreeMap::clear);
        let mut done: BTreeSet<u32> = BTreeSet::new();
        let mut idle_polls = 0;
        while done.len() < n as usize {
            // Every agent waits and no token is on its way: the round could only end by a
            // wait running out, which lossy links must never need.
            let in_flight = queues.iter().any(|q| !q.is_empty());
            prop_assert!(
                in_flight || idle_polls < 20 * n,
                "round {round} stalled: done {done:?}"
            );
            let me = order.below(n as usize) as u32;
            let i = me as usize;
            while let Some((token, sender)) = queues[i].pop_front() {
                let ok = reads(&at, &token, sender, me);
                if !ok {
                    outcome.lost += 1;
                } else if token.round == round {
                    let carried = token.plans.iter().map(|p| p.uav).collect();
                    read[i].entry(sender).or_insert(carried);
                }
                rings[i].receive(token, sender, ok);
            }
            match rings[i].turn(round, &live[i]) {
                Turn::Decide { others } => {
                    idle_polls = 0;
                    let uavs: Vec<u32> = others.iter().map(|p| p.uav).collect();
                    let known: BTreeSet<u32> = uavs.iter().copied().collect();
                    let expected: BTreeSet<u32> = read[i]
                        .iter()
                        .filter(|(sender, _)| match links.liveness {
                            Liveness::World => true,
                            Liveness::Radio => **sender < me && live[i].contains(sender),
                        })
                        .flat_map(|(_, carried)| carried.iter().copied())
                        .filter(|&u| u != me)
                        .collect();
                    prop_assert_eq!(
                        &known,
                        &expected,
                        "agent {} in round {} decides around the plans it may use",
                        me,
                        round
                    );
                    prop_assert!(
                        outcome.decisions.insert((round, me), uavs).is_none(),
                        "agent {} decided twice in round {}",
                        me,
                        round
                    );
                    let mut token = rings[i].pass(round, step, &live[i], plan(me, round));
                    token.pose = at[i].pose;
                    for q in &mut queues {
                        q.push_back((token.clone(), me));
                    }
                    done.insert(me);
                }
                Turn::Done => {
                    done.insert(me);
                    idle_polls += 1;
                }
                Turn::Wait { .. } => idle_polls += 1,
            }
        }
        for uav in 0..n {
            prop_assert!(outcome.decisions.contains_key(&(round, uav)));
        }
    }
    for (me, queue) in queues.iter().enumerate() {
        for (token, sender) in queue {
            outcome.lost += u64::from(!reads(&at, token, *sender, me as u32));
        }
    }
    Ok(outcome)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn every_round_ends_with_one_decision_each_around_the_delivered_plans(
        n in 2u32..=6, rounds in 1u64..=4, seed in any::<u64>(), loss in 0.0f64..=1.0,
        order_a in any::<u64>(), order_b in any::<u64>(),
    ) {
        let links = Links::world(Radio::perfect().with_loss(seed, loss));
        let a = run(n, rounds, links, order_a)?;
        let b = run(n, rounds, links, order_b)?;
        prop_assert_eq!(&a.decisions, &b.decisions, "the polling order changed a decision");
        prop_assert_eq!(a.lost, b.lost);
    }

    /// Within a limited range (tokens limited too), the UAVs moving between rounds: under
    /// either reading of who is live every round ends without a wait run out, and the same
    /// seed gives the same decisions.
    #[test]
    fn within_a_range_every_round_ends_and_the_decisions_are_the_seeds(
        n in 2u32..=6, rounds in 1u64..=4, seed in any::<u64>(), loss in 0.0f64..=0.5,
        range in 20.0f64..300.0, positions in any::<u64>(), radio_liveness in any::<bool>(),
        order_a in any::<u64>(), order_b in any::<u64>(),
    ) {
        let links = Links {
            radio: Radio::perfect().with_loss(seed, loss).with_range(range),
            liveness: if radio_liveness { Liveness::Radio } else { Liveness::World },
            positions: Some(positions),
            half_extent_m: 150.0,
        };
        let a = run(n, rounds, links, order_a)?;
        let b = run(n, rounds, links, order_b)?;
        prop_assert_eq!(&a.decisions, &b.decisions, "the polling order changed a decision");
        prop_assert_eq!(a.lost, b.lost);
    }
}

#[test]
fn perfect_links_decide_in_order_around_every_earlier_plan() {
    for liveness in [Liveness::World, Liveness::Radio] {
        let links = Links {
            liveness,
            ..Links::world(Radio::perfect())
        };
        let out = run(4, 2, links, 1).unwrap();
        assert_eq!(out.lost, 0);
        for round in 0..2 {
            for uav in 0..4u32 {
                assert_eq!(out.decisions[&(round, uav)], (0..uav).collect::<Vec<_>>());
            }
        }
    }
}

#[test]
fn a_holder_that_lost_every_token_decides_around_no_plans_without_waiting() {
    let out = run(5, 3, Links::world(Radio::perfect().with_loss(1, 1.0)), 7).unwrap();
    assert!(out.decisions.values().all(Vec::is_empty));
    assert_eq!(
        out.lost,
        3 * 5 * 4,
        "every token on every link of every round"
    );
    // At 50 % some tokens come and some do not.
    let half = run(5, 3, Links::world(Radio::perfect().with_loss(2, 0.5)), 7).unwrap();
    assert!(half.lost > 0 && half.lost < 60, "{}", half.lost);
    assert!(half.decisions.values().any(|d| !d.is_empty()));
}

/// Out of range, under the radio's reading, a UAV hears nobody and nobody waits for it: with
/// every UAV out of every other's range, each decides at once around no plans.
#[test]
fn out_of_everyones_range_every_uav_decides_alone() {
    let links = Links {
        radio: Radio::perfect().with_range(1e-3),
        liveness: Liveness::Radio,
        positions: Some(3),
        half_extent_m: 150.0,
    };
    let out = run(5, 3, links, 7).unwrap();
    assert!(out.decisions.values().all(Vec::is_empty));
    assert_eq!(out.lost, 3 * 5 * 4, "every token out of range");
}
