//! The token ring ([`uav_agent::guidance::ring`]) on lossy links: every token reaches every
//! agent's queue when it is sent (as on the IPC), and each receiver decides with the run's
//! [`Radio`] whether the radio carried it ([`TokenRing::receive`]), as the agent loop does.
//! Agents poll in an order drawn from a seed of its own, draining their queue and asking for
//! their turn; nothing ever times out (no holder is declared silent by a wait), so a round
//! that needed a wait would deadlock the simulation and fail it.
//!
//! Properties, for 2 to 6 agents, any loss and several rounds:
//! - every round ends: each agent decides exactly once, with no wait run out;
//! - each decision is taken around exactly the plans carried by the tokens its radio
//!   delivered to it before (none that it lost, unless a later token carried them);
//! - the plans each agent decides around do not depend on the order agents poll in: the same
//!   seed gives the same decisions (what makes lossy lockstep runs reproducible).

use std::collections::{BTreeMap, BTreeSet, VecDeque};

use proptest::prelude::*;
use protocol::camera::CameraPose;
use protocol::radio::{LinkKind, Radio};
use protocol::wire::{GuidanceToken, PlannedView};
use sets::math::Point3;
use uav_agent::guidance::{TokenRing, Turn};

/// Steps per guidance period.
const STEPS: u64 = 6;

/// splitmix64, for the polling order.
struct Rng(u64);

impl Rng {
    fn below(&mut self, n: usize) -> usize {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) % n as u64) as usize
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

/// Runs `rounds` rounds of `n` agents over `radio`, agents polling in the order drawn from
/// `order_seed`.
fn run(n: u32, rounds: u64, radio: Radio, order_seed: u64) -> Result<Outcome, TestCaseError> {
    let live: BTreeSet<u32> = (0..n).collect();
    let mut rings: Vec<TokenRing> = (0..n).map(TokenRing::new).collect();
    // Tokens in each agent's queue, with their sender and step (the wire header's).
    let mut queues: Vec<VecDeque<(GuidanceToken, u32, u64)>> = vec![VecDeque::new(); n as usize];
    // Per agent, the plans delivered to it in the current round.
    let mut delivered: Vec<BTreeSet<u32>> = vec![BTreeSet::new(); n as usize];
    let mut order = Rng(order_seed);
    let mut outcome = Outcome {
        decisions: Decisions::new(),
        lost: 0,
    };
    for round in 0..rounds {
        let step = round * STEPS;
        delivered.iter_mut().for_each(BTreeSet::clear);
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
            while let Some((token, sender, sent_at)) = queues[i].pop_front() {
                let ok = radio.delivers(LinkKind::Token, sender, me, sent_at);
                if !ok {
                    outcome.lost += 1;
                } else if token.round == round {
                    delivered[i].extend(token.plans.iter().map(|p| p.uav));
                }
                rings[i].receive(token, sender, ok);
            }
            match rings[i].turn(round, &live) {
                Turn::Decide { others } => {
                    idle_polls = 0;
                    let uavs: Vec<u32> = others.iter().map(|p| p.uav).collect();
                    let known: BTreeSet<u32> = uavs.iter().copied().collect();
                    prop_assert_eq!(
                        &known,
                        &delivered[i],
                        "agent {} in round {} decides around the delivered plans",
                        me,
                        round
                    );
                    prop_assert!(
                        outcome.decisions.insert((round, me), uavs).is_none(),
                        "agent {} decided twice in round {}",
                        me,
                        round
                    );
                    let token = rings[i].pass(round, step, &live, plan(me, round));
                    for q in &mut queues {
                        q.push_back((token.clone(), me, step));
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
    // The last tokens, still queued where their receivers had decided already.
    for (me, queue) in queues.iter().enumerate() {
        for (_, sender, sent_at) in queue {
            let ok = radio.delivers(LinkKind::Token, *sender, me as u32, *sent_at);
            outcome.lost += u64::from(!ok);
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
        let radio = Radio::perfect().with_loss(seed, loss);
        let a = run(n, rounds, radio, order_a)?;
        let b = run(n, rounds, radio, order_b)?;
        prop_assert_eq!(&a.decisions, &b.decisions, "the polling order changed a decision");
        prop_assert_eq!(a.lost, b.lost);
    }
}

#[test]
fn perfect_links_decide_in_order_around_every_earlier_plan() {
    let out = run(4, 2, Radio::perfect(), 1).unwrap();
    assert_eq!(out.lost, 0);
    for round in 0..2 {
        for uav in 0..4u32 {
            assert_eq!(out.decisions[&(round, uav)], (0..uav).collect::<Vec<_>>());
        }
    }
}

#[test]
fn a_holder_that_lost_every_token_decides_around_no_plans_without_waiting() {
    let out = run(5, 3, Radio::perfect().with_loss(1, 1.0), 7).unwrap();
    assert!(out.decisions.values().all(Vec::is_empty));
    assert_eq!(
        out.lost,
        3 * 5 * 4,
        "every token on every link of every round"
    );
    // At 50 % some tokens come and some do not.
    let half = run(5, 3, Radio::perfect().with_loss(2, 0.5), 7).unwrap();
    assert!(half.lost > 0 && half.lost < 60, "{}", half.lost);
    assert!(half.decisions.values().any(|d| !d.is_empty()));
}
