//! The simulated radio between agents: range, loss and latency (`[comms]` of the scenario,
//! docs/design.md §2 "Radio links").
//!
//! Links are simulated by the receiver. Every message still crosses the IPC (or the bridge to
//! another host) whole; the receiving agent then decides whether the radio carried it, from
//! nothing but the scenario and the message's identity, so that the observer, applying the
//! same [`Radio`], knows exactly what each agent fused. Nothing goes through a shared random
//! number generator: whether the message of `kind` sent by `sender` at `step` reaches
//! `receiver` is a pure function of those and of the scenario's seed ([`Radio::delivers`]),
//! the same on every host and in every run with that seed, whatever the order messages come
//! in.
//!
//! - **Range** (`comms.range_m`): an estimate is fused only when the sender's camera, as it
//!   sent, is within range of the receiver's, as it fuses ([`in_comms_range`]). A token
//!   reaches a receiver only from a sender within range of it at the token's step
//!   ([`Radio::carries_token`]; `comms.token_range = "unlimited"` lets every token through, as
//!   before the key). In lockstep a receiver reads a round's tokens at the round's step:
//!   the round's first decision waits for every estimate of that step, published once its
//!   sender has its pose, and the world's next frame waits for the round's last decision.
//! - **Loss** (`comms.loss`): each message on each link is lost with probability `loss`,
//!   independently of every other (message kind, sender, receiver and step are all mixed into
//!   the draw). The receiver knows at once (it decided), so a lost message is never waited
//!   for: a lost estimate is not read at all, a lost token (to loss or to range) counts as its
//!   sender passing the turn without the receiver learning its plan.
//! - **Latency** (`comms.latency_ms`): an estimate of step `k` is fused at the receiver's first
//!   step `k'` whose time reaches `t(k) + latency`, that is `k' = k + d` with
//!   `d = ceil(latency / cvs_period_s)` ([`latency_steps`]), dilated by the `d` steps it lags
//!   as every older estimate is. Tokens are not delayed: in lockstep the simulated time stands
//!   still while the fleet decides (the planners' computing takes none either), and a hop's
//!   latency would have to stretch the round over several frames, which is another guidance
//!   scheme, not a slower link.
//!
//! The three make one rule, written once: which estimates an agent fuses at its step
//! ([`Radio::fuses`] for one estimate, [`Radio::fused_peers`] for those of a lockstep step, in
//! the order the agent fuses them). The agent applies it to the estimates it holds, the
//! observer to the estimates it saw published, and so both fuse the same.
//!
//! ```
//! use protocol::scenario::Scenario;
//! use protocol::radio::{LinkKind, Radio};
//!
//! let scenario = Scenario::load(None, &["comms.loss=0.3".to_owned()])?;
//! let radio = Radio::from_scenario(&scenario);
//! // The same question always has the same answer: agents and observer agree.
//! let a = radio.delivers(LinkKind::Estimate, 1, 2, 40);
//! assert_eq!(a, Radio::from_scenario(&scenario).delivers(LinkKind::Estimate, 1, 2, 40));
//! // An agent always hears itself.
//! assert!(radio.delivers(LinkKind::Token, 3, 3, 40));
//! # Ok::<(), protocol::scenario::ScenarioError>(())
//! ```

use crate::camera::CameraPose;
use crate::scenario::{Scenario, TokenRange};

/// The kinds of message a link carries, each drawn on its own (a lost estimate says nothing
/// about the token of the same step).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LinkKind {
    /// An agent's estimate (`{run}/uav/{i}/estimate`).
    Estimate,
    /// The guidance token (`{run}/guidance`).
    Token,
}

impl LinkKind {
    /// The kind's lane in the draw.
    fn lane(self) -> u64 {
        match self {
            LinkKind::Estimate => 1,
            LinkKind::Token => 2,
        }
    }
}

/// The links between agents of one run: what reaches whom, and when.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Radio {
    seed: u64,
    loss: f64,
    latency_steps: u64,
    range_m: f64,
    token_range: TokenRange,
}

/// One end of a message's link, as the radio judges it: an agent, one of its steps and its
/// camera pose then (the sender's as it sent, the receiver's as it fuses an estimate or reads
/// a token; unknown before the agent's first frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Endpoint {
    /// The agent's UAV index.
    pub uav: u32,
    /// The sender's step (that of the message) or the receiver's (that it fuses at).
    pub step: u64,
    /// The agent's camera pose at that step.
    pub pose: Option<CameraPose>,
}

/// Keeps the radio's draws apart from every other use of the scenario's seed.
const RADIO_DOMAIN: u64 = 0x7261_6469_6f6c_6f73; // "radiolos"

impl Radio {
    /// Perfect links: unlimited range, no loss, no latency (a range set later limits tokens
    /// too).
    pub fn perfect() -> Radio {
        Radio {
            seed: 0,
            loss: 0.0,
            latency_steps: 0,
            range_m: f64::INFINITY,
            token_range: TokenRange::Radio,
        }
    }

    /// The links of a (validated) scenario: its seed, `comms.range_m`, `comms.loss`,
    /// `comms.latency_ms` in whole CVS periods and `comms.token_range`.
    pub fn from_scenario(scenario: &Scenario) -> Radio {
        Radio {
            seed: scenario.seed,
            loss: scenario.comms.loss,
            latency_steps: latency_steps(scenario.comms.latency_ms, scenario.timing.cvs_period_s),
            range_m: scenario.comms.range_m,
            token_range: scenario.comms.token_range,
        }
    }

    /// These links with another drop probability (`loss` is a probability: outside `[0, 1]`
    /// it acts as the nearest bound, NaN as 0).
    pub fn with_loss(self, seed: u64, loss: f64) -> Radio {
        Radio { seed, loss, ..self }
    }

    /// These links with another latency, in steps.
    pub fn with_latency_steps(self, latency_steps: u64) -> Radio {
        Radio {
            latency_steps,
            ..self
        }
    }

    /// These links with another range, metres.
    pub fn with_range(self, range_m: f64) -> Radio {
        Radio { range_m, ..self }
    }

    /// These links with tokens limited by the range or not.
    pub fn with_token_range(self, token_range: TokenRange) -> Radio {
        Radio {
            token_range,
            ..self
        }
    }

    /// The probability that a message is lost on one link.
    pub fn loss(&self) -> f64 {
        self.loss
    }

    /// Whether some message may be lost: then estimates must carry whole sets, since a delta
    /// against a lost message rebuilds nothing (see `estimator::message`).
    pub fn is_lossy(&self) -> bool {
        self.loss > 0.0
    }

    /// Whether a message can fail to reach a peer in time: some loss, or a finite range.
    pub fn loses_or_limits(&self) -> bool {
        self.is_lossy() || self.range_m().is_finite()
    }

    /// Whether the range can keep a token from a receiver: a finite range that limits tokens
    /// (`comms.token_range = "radio"`). Only then does the radio read the poses of a token's
    /// ends.
    pub fn limits_tokens(&self) -> bool {
        self.token_range == TokenRange::Radio && self.range_m.is_finite()
    }

    /// Steps between an estimate's step and the step it is fused at.
    pub fn latency_steps(&self) -> u64 {
        self.latency_steps
    }

    /// Link range, metres.
    pub fn range_m(&self) -> f64 {
        self.range_m
    }

    /// Whether the message of `kind` that `sender` sent at `step` reaches `receiver`: always
    /// for an agent's own messages and on lossless links; else iff its draw
    /// ([`link_draw`]) is at least `loss`, so a fraction `loss` of the messages is lost.
    pub fn delivers(&self, kind: LinkKind, sender: u32, receiver: u32, step: u64) -> bool {
        sender == receiver
            || !self.is_lossy()
            || link_draw(self.seed, kind, sender, receiver, step) >= self.loss
    }

    /// Whether an estimate of `sent_step` has arrived by the receiver's `step`
    /// (`sent_step + latency_steps <= step`).
    pub fn arrived(&self, sent_step: u64, step: u64) -> bool {
        sent_step.saturating_add(self.latency_steps) <= step
    }

    /// Whether an estimate sent from `sender`'s pose is in range of a receiver at `receiver`
    /// ([`in_comms_range`] with this radio's range).
    pub fn in_range(&self, receiver: Option<CameraPose>, sender: Option<CameraPose>) -> bool {
        in_comms_range(self.range_m, receiver, sender)
    }

    /// Whether `receiver` fuses, at its step, the estimate `sender` sent at its own: an
    /// estimate of another agent that the radio delivered to it ([`Radio::delivers`]), that
    /// has arrived by its step ([`Radio::arrived`]) and whose sender was in range of it
    /// ([`Radio::in_range`]: the sender's pose as it sent, the receiver's as it fuses). An
    /// agent fuses an estimate once, at the first step this holds, and never one older than
    /// an estimate of the same sender it already fused.
    pub fn fuses(&self, receiver: &Endpoint, sender: &Endpoint) -> bool {
        sender.uav != receiver.uav
            && self.delivers(LinkKind::Estimate, sender.uav, receiver.uav, sender.step)
            && self.arrived(sender.step, receiver.step)
            && self.in_range(receiver.pose, sender.pose)
    }

    /// Whether `receiver`, at the token's step, reads the token `sender` sent at its step: its
    /// own always; another's when the radio delivered it ([`Radio::delivers`]) and, if the
    /// range limits tokens ([`Radio::limits_tokens`]), the sender's camera as it sent was in
    /// range of the receiver's ([`Radio::in_range`]). A token the receiver does not read is its
    /// sender's turn passed with a plan the receiver will not see.
    pub fn carries_token(&self, receiver: &Endpoint, sender: &Endpoint) -> bool {
        sender.uav == receiver.uav
            || (self.delivers(LinkKind::Token, sender.uav, receiver.uav, sender.step)
                && (!self.limits_tokens() || self.in_range(receiver.pose, sender.pose)))
    }

    /// The estimates among `sent` that `receiver` fuses at its step `k` when every estimate
    /// comes in time (in lockstep): those of step `k - d` (`d` the latency in steps) that it
    /// [fuses](Radio::fuses), in the order it fuses them, by ascending sender. None before
    /// step `d`. `endpoint` gives each estimate's sender, step and pose.
    pub fn fused_peers<'a, T>(
        &self,
        receiver: &Endpoint,
        sent: &'a [T],
        endpoint: impl Fn(&T) -> Endpoint,
    ) -> Vec<&'a T> {
        let due = receiver.step.checked_sub(self.latency_steps);
        let mut peers: Vec<&T> = sent
            .iter()
            .filter(|estimate| {
                let sender = endpoint(estimate);
                Some(sender.step) == due && self.fuses(receiver, &sender)
            })
            .collect();
        peers.sort_by_key(|estimate| endpoint(estimate).uav);
        peers
    }
}

/// `ceil(latency_ms / 1000 / period_s)` whole periods, 0 for no latency (or a period that is
/// not positive). A latency that is a whole number of periods up to rounding (250 ms at 0.5 s
/// is half a period: 1; 1000 ms is 2, not 3 from a rounding error) is that number.
pub fn latency_steps(latency_ms: f64, period_s: f64) -> u64 {
    if !(latency_ms > 0.0 && period_s > 0.0) {
        return 0;
    }
    let periods = latency_ms / 1000.0 / period_s;
    let whole = periods.round();
    let steps = if (periods - whole).abs() <= 1e-9 * whole.max(1.0) {
        whole
    } else {
        periods.ceil()
    };
    // Validated latencies are at most tens of steps; `as` saturates anything else.
    steps as u64
}

/// The radio's draw for one message on one link, uniform in `[0, 1)`: a splitmix64 chain over
/// the seed, the kind, the sender, the receiver and the step, so each input changes every bit
/// of the result and neighbouring links, steps and seeds draw independently.
pub fn link_draw(seed: u64, kind: LinkKind, sender: u32, receiver: u32, step: u64) -> f64 {
    let mut h = mix(seed ^ RADIO_DOMAIN);
    for word in [kind.lane(), u64::from(sender), u64::from(receiver), step] {
        h = mix(h ^ word);
    }
    // The top 53 bits as a fraction: every double of [0, 1) on a 2^-53 grid.
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// splitmix64's finaliser (with its increment), a bijection of `u64` that mixes every bit.
fn mix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Whether an agent whose camera is at `receiver` fuses an estimate sent from `sender` over
/// links of range `range_m`: always with an infinite range, else when the cameras are within
/// `range_m` of each other horizontally. An unknown pose is out of every finite range. The
/// observer applies the same rule to reproduce what each agent fused.
pub fn in_comms_range(
    range_m: f64,
    receiver: Option<CameraPose>,
    sender: Option<CameraPose>,
) -> bool {
    range_m.is_infinite()
        || match (receiver, sender) {
            (Some(a), Some(b)) => (a.position - b.position).xy().norm() <= range_m,
            _ => false,
        }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;
    use sets::math::Point3;

    fn lossy(seed: u64, loss: f64) -> Radio {
        Radio::perfect().with_loss(seed, loss)
    }

    #[test]
    fn perfect_links_deliver_everything_and_full_loss_nothing() {
        let perfect = Radio::perfect();
        let all = lossy(9, 1.0);
        for (s, r, k) in [(0, 1, 0), (3, 2, 17), (31, 0, u64::MAX)] {
            for kind in [LinkKind::Estimate, LinkKind::Token] {
                assert!(perfect.delivers(kind, s, r, k));
                assert!(!all.delivers(kind, s, r, k));
                assert!(all.delivers(kind, s, s, k), "an agent hears itself");
            }
        }
        assert!(!perfect.is_lossy() && all.is_lossy());
        assert!(!lossy(1, f64::NAN).is_lossy(), "NaN loses nothing");
        assert!(lossy(1, -0.5).delivers(LinkKind::Token, 0, 1, 0));
    }

    #[test]
    fn latency_is_rounded_up_to_whole_periods() {
        assert_eq!(latency_steps(0.0, 0.5), 0);
        assert_eq!(latency_steps(1.0, 0.5), 1);
        assert_eq!(latency_steps(250.0, 0.5), 1);
        assert_eq!(latency_steps(500.0, 0.5), 1);
        assert_eq!(latency_steps(501.0, 0.5), 2);
        assert_eq!(latency_steps(1000.0, 0.5), 2);
        // 0.3 s periods: 900 ms is 3 periods although 0.9 / 0.3 is 3.0000000000000004.
        assert_eq!(latency_steps(900.0, 0.3), 3);
        assert_eq!(latency_steps(10_000.0, 0.5), 20);
        assert_eq!(latency_steps(f64::NAN, 0.5), 0);
        assert_eq!(latency_steps(100.0, 0.0), 0);
        let r = Radio::perfect().with_latency_steps(2);
        assert!(!r.arrived(10, 11) && r.arrived(10, 12) && r.arrived(10, 13));
        assert!(Radio::perfect().arrived(10, 10));
    }

    #[test]
    fn the_radio_of_a_scenario_reads_every_comms_key() {
        let s = Scenario::load(
            None,
            &[
                "seed=5".to_owned(),
                "comms.loss=0.25".to_owned(),
                "comms.latency_ms=1200".to_owned(),
                "comms.range_m=90".to_owned(),
                "comms.token_range=unlimited".to_owned(),
            ],
        )
        .unwrap();
        let r = Radio::from_scenario(&s);
        assert_eq!((r.loss(), r.latency_steps(), r.range_m()), (0.25, 3, 90.0));
        let expected = lossy(5, 0.25)
            .with_latency_steps(3)
            .with_range(90.0)
            .with_token_range(TokenRange::Unlimited);
        assert_eq!(r, expected);
        assert!(!r.limits_tokens());
        let default = Radio::from_scenario(&Scenario::default());
        assert_eq!(default.loss(), 0.0);
        assert!(!default.limits_tokens(), "an infinite range limits nothing");
        assert!(default.with_range(90.0).limits_tokens());
    }

    /// An agent at `(x, y)` (camera `z` m up: the range is horizontal), at `step`.
    fn at_xy(uav: u32, step: u64, x: f64, y: f64, z: f64) -> Endpoint {
        Endpoint {
            uav,
            step,
            pose: Some(CameraPose {
                position: Point3::new(x, y, z),
                yaw: 0.0,
            }),
        }
    }

    /// Who reads whose token, by hand: four UAVs at different altitudes, 100 m of range.
    /// 0 at (0, 0), 1 at (60, 80) (100 m from 0: in range, the bound included), 2 at (0, 101)
    /// (101 m from 0; 63.6 m from 1), 3 at (-70, 0) (70 m from 0; 152.6 m from 1; 122.9 m from
    /// 2). Unlimited tokens reach everyone; a sender whose pose is unknown reaches no one
    /// under a finite range.
    #[test]
    fn a_token_reaches_the_receivers_in_range_of_its_sender() {
        let radio = Radio::perfect().with_range(100.0);
        let step = 12;
        let uavs = [
            at_xy(0, step, 0.0, 0.0, 60.0),
            at_xy(1, step, 60.0, 80.0, 70.0),
            at_xy(2, step, 0.0, 101.0, 80.0),
            at_xy(3, step, -70.0, 0.0, 90.0),
        ];
        let readers = |radio: &Radio, sender: &Endpoint| -> Vec<u32> {
            uavs.iter()
                .filter(|r| radio.carries_token(r, sender))
                .map(|r| r.uav)
                .collect()
        };
        let expected: [&[u32]; 4] = [&[0, 1, 3], &[0, 1, 2], &[1, 2], &[0, 3]];
        for (sender, expected) in uavs.iter().zip(expected) {
            assert_eq!(readers(&radio, sender), expected, "token of {}", sender.uav);
        }
        let unlimited = radio.with_token_range(TokenRange::Unlimited);
        for sender in &uavs {
            assert_eq!(readers(&unlimited, sender), [0, 1, 2, 3]);
        }
        let nowhere = Endpoint {
            pose: None,
            ..at_xy(1, step, 0.0, 0.0, 0.0)
        };
        assert_eq!(readers(&radio, &nowhere), [1], "only itself");
        assert_eq!(readers(&Radio::perfect(), &nowhere), [0, 1, 2, 3]);
        // Loss on top of range: a token read is one delivered and in range.
        let lossy = radio.with_loss(4, 0.5);
        for sender in &uavs {
            for receiver in &uavs {
                let delivered = lossy.delivers(LinkKind::Token, sender.uav, receiver.uav, step);
                assert_eq!(
                    lossy.carries_token(receiver, sender),
                    delivered && radio.carries_token(receiver, sender),
                    "{} -> {}",
                    sender.uav,
                    receiver.uav
                );
            }
        }
    }

    /// An agent at `x` metres along the x axis, at `step`.
    fn at(uav: u32, step: u64, x: f64) -> Endpoint {
        Endpoint {
            uav,
            step,
            pose: Some(CameraPose {
                position: Point3::new(x, 0.0, 50.0),
                yaw: 0.0,
            }),
        }
    }

    /// The rule the agents and the observer share: at its step `k`, an agent fuses the other
    /// agents' estimates of step `k - d` that the radio delivered to it from a sender in
    /// range, by ascending sender, whatever order they are listed in; never its own, never
    /// one of another step, nothing before step `d`, and an estimate with no pose only on
    /// links of unlimited range.
    #[test]
    fn an_agent_fuses_the_delivered_due_estimates_in_range_by_ascending_sender() {
        let radio = Radio::perfect()
            .with_loss(11, 0.4)
            .with_latency_steps(2)
            .with_range(100.0);
        // Senders 0..8 shuffled, 30 m apart, at steps 5 (due at 7), 6 and 7.
        let mut sent: Vec<Endpoint> = [5, 2, 7, 0, 3, 6, 1, 4]
            .into_iter()
            .flat_map(|uav| [5, 6, 7].map(|step| at(uav, step, 30.0 * f64::from(uav))))
            .collect();
        sent.push(Endpoint {
            pose: None,
            ..at(8, 5, 0.0)
        });
        let mut heard_any = false;
        for me in 0..9 {
            let receiver = at(me, 7, 30.0 * f64::from(me.min(7)));
            let fused: Vec<u32> = radio
                .fused_peers(&receiver, &sent, |e| *e)
                .into_iter()
                .map(|e| e.uav)
                .collect();
            let expected: Vec<u32> = (0..8)
                .filter(|&j| j != me)
                .filter(|&j| radio.delivers(LinkKind::Estimate, j, me, 5))
                .filter(|&j| (f64::from(j) - f64::from(me.min(7))).abs() * 30.0 <= 100.0)
                .collect();
            assert_eq!(fused, expected, "agent {me}");
            heard_any |= !fused.is_empty();
            // What one estimate's fate is, whatever the others'.
            for e in &sent {
                let fuses = radio.fuses(&receiver, e);
                assert_eq!(
                    fuses && e.step == 5,
                    fused.contains(&e.uav) && e.step == 5,
                    "agent {me}, {e:?}"
                );
                assert!(!fuses || e.step <= 5, "not arrived: {e:?}");
            }
        }
        assert!(heard_any);
        // Each delivered estimate of step 5 is fused by the agent's step 7 or later, not
        // before; the estimate without a pose is out of every finite range.
        let early = at(1, 6, 30.0);
        assert!(radio.fused_peers(&early, &sent, |e| *e).is_empty());
        let nowhere = Endpoint {
            pose: None,
            ..at(8, 5, 0.0)
        };
        assert!(!radio.fuses(&at(0, 9, 0.0), &nowhere));
        assert!(Radio::perfect().fuses(&at(0, 5, 0.0), &nowhere));
        assert!(
            !Radio::perfect().fuses(&at(8, 5, 0.0), &nowhere),
            "never its own"
        );
        assert!(radio.fused_peers(&at(0, 1, 0.0), &sent, |e| *e).is_empty());
    }

    /// Over 40,000 messages of a fixed seed the share lost is within 1.5 % of `loss` (the
    /// standard deviation of the share is at most 0.25 %: 6 of them). Deterministic: it
    /// cannot fail by luck, only if the draw is biased.
    #[test]
    fn the_share_of_messages_lost_is_the_loss() {
        for loss in [0.1, 0.3, 0.5, 0.9] {
            let r = lossy(1, loss);
            let mut lost = 0;
            let mut total = 0;
            for step in 0..1000 {
                for sender in 0..4 {
                    for receiver in (0..4).filter(|&x| x != sender) {
                        for kind in [LinkKind::Estimate, LinkKind::Token] {
                            total += 1;
                            lost += u32::from(!r.delivers(kind, sender, receiver, step));
                        }
                    }
                }
            }
            let share = f64::from(lost) / f64::from(total);
            assert!((share - loss).abs() < 0.015, "loss {loss}: {share}");
        }
    }

    /// Each input moves the draw: the draws of neighbouring links, steps, kinds and seeds are
    /// uncorrelated (their correlation over 20,000 pairs is below 0.05, about 7 standard
    /// deviations of the estimate for independent draws).
    #[test]
    fn neighbouring_links_draw_independently() {
        let n = 20_000u64;
        /// Two draws that differ in one input, for each `i`.
        type Pair = fn(u64) -> (f64, f64);
        let pairs: [(&str, Pair); 5] = [
            ("step", |i| {
                (
                    link_draw(1, LinkKind::Estimate, 0, 1, i),
                    link_draw(1, LinkKind::Estimate, 0, 1, i + 1),
                )
            }),
            ("kind", |i| {
                (
                    link_draw(1, LinkKind::Estimate, 0, 1, i),
                    link_draw(1, LinkKind::Token, 0, 1, i),
                )
            }),
            ("direction", |i| {
                (
                    link_draw(1, LinkKind::Estimate, 0, 1, i),
                    link_draw(1, LinkKind::Estimate, 1, 0, i),
                )
            }),
            ("receiver", |i| {
                (
                    link_draw(1, LinkKind::Estimate, 0, 1, i),
                    link_draw(1, LinkKind::Estimate, 0, 2, i),
                )
            }),
            ("seed", |i| {
                (
                    link_draw(i, LinkKind::Estimate, 0, 1, 7),
                    link_draw(i + 1, LinkKind::Estimate, 0, 1, 7),
                )
            }),
        ];
        for (what, pair) in pairs {
            let (mut sx, mut sy, mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for i in 0..n {
                let (x, y) = pair(i);
                sx += x;
                sy += y;
                sxy += x * y;
                sxx += x * x;
                syy += y * y;
            }
            let nf = n as f64;
            let cov = sxy / nf - sx / nf * sy / nf;
            let corr =
                cov / ((sxx / nf - (sx / nf).powi(2)) * (syy / nf - (sy / nf).powi(2))).sqrt();
            assert!(corr.abs() < 0.05, "{what}: correlation {corr}");
        }
    }

    proptest! {
        #[test]
        fn draws_are_fractions_and_a_pure_function_of_the_link(
            seed in any::<u64>(), sender in 0u32..32, receiver in 0u32..32, step in any::<u64>(),
            token in any::<bool>(), loss in 0.0f64..=1.0,
        ) {
            let kind = if token { LinkKind::Token } else { LinkKind::Estimate };
            let d = link_draw(seed, kind, sender, receiver, step);
            prop_assert!((0.0..1.0).contains(&d));
            prop_assert_eq!(d.to_bits(), link_draw(seed, kind, sender, receiver, step).to_bits());
            let r = lossy(seed, loss);
            let delivered = r.delivers(kind, sender, receiver, step);
            prop_assert_eq!(delivered, r.delivers(kind, sender, receiver, step));
            prop_assert_eq!(delivered, sender == receiver || loss == 0.0 || d >= loss);
        }

        /// A message lost at some loss is lost at every larger loss: raising `comms.loss` only
        /// adds losses (so the sweep over loss levels compares nested sets of lost messages).
        #[test]
        fn losses_are_nested_in_the_loss(
            seed in any::<u64>(), sender in 0u32..8, receiver in 0u32..8, step in 0u64..10_000,
            a in 0.0f64..=1.0, b in 0.0f64..=1.0,
        ) {
            let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
            let kind = LinkKind::Estimate;
            if !lossy(seed, lo).delivers(kind, sender, receiver, step) {
                prop_assert!(!lossy(seed, hi).delivers(kind, sender, receiver, step));
            }
        }
    }
}
