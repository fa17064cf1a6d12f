//! Messages other than frames: commands, truth, estimates and the guidance token.
//!
//! Fixed-size messages (commands, truth) are `#[repr(C)]` [`ZeroCopySend`] types whose
//! iceoryx2 type names carry the protocol version, so a process speaking another version cannot
//! open the service. Variable-size messages (estimates, token) travel as bincode in a `[u8]`
//! slice behind a versioned [`WireHeader`] user header, encoded by [`crate::codec`].

use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use crate::camera::CameraPose;
use sets::raster::delta::SetCode;

/// Version of every message layout in this module and in [`crate::frame`]. 11: the token
/// carries its sender's camera pose ([`GuidanceToken::pose`]), by which the simulated radio
/// judges its range. 9: an estimate
/// carries the peer measurements its sender forwards ([`RelayedMeasurementMsg`]). 8: UAV masks
/// ([`UavMask`]) are 64 bits wide, for fleets of up to 64 UAVs, and truth messages and frames
/// hold 128 cars. 7: an estimate's sets are optional ([`SetsMsg`]) and it may carry its
/// frame's measurement ([`MeasurementMsg`]); agents also send [`WireKind::State`] messages.
pub const PROTOCOL_VERSION: u32 = 11;
/// Targets a truth message can hold: the cars of the largest fleet's region (64 UAVs over
/// 2 x 2 km keep the default scenario's 8 cars per 4 UAVs).
pub const TRUTH_MAX_TARGETS: usize = 128;
/// UAVs a truth message can hold, and the largest fleet: one bit of a [`UavMask`] each.
pub const MAX_UAVS: usize = UavMask::BITS as usize;

/// A set of UAVs, bit `i` for UAV `i` ([`uav_bit`]): the frame's
/// [`crate::frame::FrameHeader::served`], [`ObserverAck::restarted`] and
/// [`EstimateMsg::want_whole`]. Its width is the largest fleet, [`MAX_UAVS`].
pub type UavMask = u64;

/// The `step` of a [`UavCommand`] that means "agent ready": an agent sends it once its
/// subscribers are open (and again every so often until its first frame arrives, since a
/// command sent before the world subscribed is lost). Also the `step` of an [`ObserverAck`]
/// that means "observer ready".
pub const HELLO_STEP: u64 = u64::MAX;

/// Bit `uav` of a [`UavMask`]: bit `i` stands for UAV `i`. 0 for a UAV beyond [`MAX_UAVS`].
pub fn uav_bit(uav: u32) -> UavMask {
    UavMask::from(1u8).checked_shl(uav).unwrap_or(0)
}

/// The UAVs of a mask, ascending.
pub fn uavs_in(mask: UavMask) -> impl Iterator<Item = u32> {
    (0..MAX_UAVS as u32).filter(move |&i| mask & uav_bit(i) != 0)
}

/// Agent -> world: the yaw reference for a UAV, and the lockstep ack of `step`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("setfleet.UavCommand.v2")]
pub struct UavCommand {
    /// [`crate::service::RunId::tag`] of the run.
    pub run_tag: u64,
    /// The frame step this command answers.
    pub step: u64,
    /// Sender's UAV index.
    pub uav: u32,
    /// 1 when `yaw_ref_rad` holds a new reference, 0 to keep the current one.
    pub has_yaw_ref: u32,
    /// Yaw reference, radians.
    pub yaw_ref_rad: f64,
    /// A number that differs at each start of the agent's process: a command of a new
    /// incarnation tells the world that the previous one is gone, whatever its node shows.
    pub incarnation: u64,
}

/// Observer -> world: the observer has processed the truth (and whatever else it needs) of
/// `step`, so a lockstep world that waits for its observer may advance. `step ==`
/// [`HELLO_STEP`] means "observer ready".
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("setfleet.ObserverAck.v3")]
pub struct ObserverAck {
    /// [`crate::service::RunId::tag`] of the run.
    pub run_tag: u64,
    /// The step acknowledged.
    pub step: u64,
    /// Agents restarted at this step: the world waits for their hellos (bounded) before it
    /// publishes the next step, so they are served from it.
    pub restarted: UavMask,
}

/// Ground truth of one target.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("setfleet.TargetTruth.v1")]
pub struct TargetTruth {
    /// Target id.
    pub id: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Ground point under the car's centre, world frame.
    pub ground: [f64; 2],
    /// Heading, radians.
    pub heading: f64,
    /// Speed, m/s.
    pub speed: f64,
}

/// Ground truth of one UAV.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("setfleet.UavTruth.v2")]
pub struct UavTruth {
    /// UAV index.
    pub id: u32,
    /// 1 while the world considers the UAV's agent live.
    pub agent_live: u32,
    /// Position of the camera's optical centre.
    pub position: [f64; 3],
    /// Yaw, radians.
    pub yaw: f64,
    /// The yaw reference followed in the step that led here, radians: the commanded one, or
    /// the world's turn back to the centre when its geofence overrode the command.
    pub yaw_ref: f64,
    /// The yaw reference last commanded by the agent, radians (wrapped into `(-pi, pi]`).
    pub commanded_yaw_ref: f64,
}

impl UavTruth {
    /// Whether the world's geofence overrode the agent's command in the step that led here.
    pub fn geofence_override(&self) -> bool {
        self.yaw_ref != self.commanded_yaw_ref
    }
}

/// World -> observers: the true state at a step (agents never subscribe).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("setfleet.TruthState.v3")]
pub struct TruthState {
    /// [`crate::service::RunId::tag`] of the run.
    pub run_tag: u64,
    /// Step index.
    pub step: u64,
    /// Simulated time, seconds.
    pub time_s: f64,
    /// Targets in use.
    pub target_count: u32,
    /// UAVs in use.
    pub uav_count: u32,
    /// Target states.
    pub targets: [TargetTruth; TRUTH_MAX_TARGETS],
    /// UAV states.
    pub uavs: [UavTruth; MAX_UAVS],
}

impl Default for TruthState {
    fn default() -> Self {
        Self {
            run_tag: 0,
            step: 0,
            time_s: 0.0,
            target_count: 0,
            uav_count: 0,
            targets: [TargetTruth::default(); TRUTH_MAX_TARGETS],
            uavs: [UavTruth::default(); MAX_UAVS],
        }
    }
}

impl TruthState {
    /// The targets in use.
    pub fn targets(&self) -> &[TargetTruth] {
        &self.targets[..(self.target_count as usize).min(TRUTH_MAX_TARGETS)]
    }

    /// The UAVs in use.
    pub fn uavs(&self) -> &[UavTruth] {
        &self.uavs[..(self.uav_count as usize).min(MAX_UAVS)]
    }
}

/// What kind of payload follows a [`WireHeader`].
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WireKind {
    /// An [`EstimateMsg`].
    Estimate = 1,
    /// A [`GuidanceToken`].
    Token = 2,
    /// An [`EstimateMsg`] for observers only, on the sender's estimate service: under the
    /// measurement exchange, the sets the agent holds once it applied the step's measurements
    /// (peers skip it unread).
    State = 3,
}

/// User header of every variable-size message: who sent what, for which run, in which version.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("setfleet.WireHeader.v1")]
pub struct WireHeader {
    /// [`PROTOCOL_VERSION`] of the sender.
    pub version: u32,
    /// [`WireKind`] as a number.
    pub kind: u32,
    /// [`crate::service::RunId::tag`] of the run.
    pub run_tag: u64,
    /// Sender's UAV index.
    pub sender: u32,
    /// Payload length in bytes.
    pub len: u32,
    /// Step the payload belongs to.
    pub step: u64,
    /// Wall-clock send time, nanoseconds since the Unix epoch (for latency measurements).
    pub sent_unix_ns: u64,
}

impl WireHeader {
    /// The header of a `len`-byte payload of `kind` that UAV `sender` sends at `step` of the
    /// run tagged `run_tag`, in this [`PROTOCOL_VERSION`]; `sent_unix_ns` is usually
    /// [`unix_now_ns`].
    pub fn new(
        kind: WireKind,
        run_tag: u64,
        sender: u32,
        step: u64,
        len: u32,
        sent_unix_ns: u64,
    ) -> Self {
        Self {
            version: PROTOCOL_VERSION,
            kind: kind as u32,
            run_tag,
            sender,
            len,
            step,
            sent_unix_ns,
        }
    }

    /// Checks a received header against what the service carries: this version, the run
    /// `run_tag`, payloads of `kind`, from `sender` (`None` when any UAV may send, as on the
    /// guidance service), and a length that matches the `payload_len` bytes received. The
    /// first field that does not match is the reason to drop the message.
    pub fn check(
        &self,
        payload_len: usize,
        kind: WireKind,
        run_tag: u64,
        sender: Option<u32>,
    ) -> Result<(), DropReason> {
        if self.version != PROTOCOL_VERSION {
            Err(DropReason::Version)
        } else if self.run_tag != run_tag {
            Err(DropReason::OtherRun)
        } else if self.kind != kind as u32 {
            Err(DropReason::Kind)
        } else if sender.is_some_and(|s| s != self.sender) {
            Err(DropReason::Sender)
        } else if self.len as usize != payload_len {
            Err(DropReason::Length)
        } else {
            Ok(())
        }
    }
}

/// Why a received variable-size message was dropped: [`WireHeader::check`]'s verdict, or a
/// payload that does not decode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, thiserror::Error)]
pub enum DropReason {
    /// Another protocol version.
    #[error("another protocol version")]
    Version,
    /// Another run.
    #[error("another run")]
    OtherRun,
    /// Another kind of message than the service carries.
    #[error("another kind of message than the service carries")]
    Kind,
    /// The sender field does not match the service it came on.
    #[error("a sender that does not match the service")]
    Sender,
    /// The header's length does not match the payload.
    #[error("a length that does not match the payload")]
    Length,
    /// The payload does not decode or does not validate.
    #[error("a payload that does not decode")]
    Malformed,
    /// The sender's process was replaced by a newer one (a restart) since.
    #[error("a sender whose process was replaced since")]
    Superseded,
    /// Sets sent as changes against a message the receiver does not hold (it missed one, or
    /// joined late): the receiver asks for whole sets ([`EstimateMsg::want_whole`]).
    #[error("changes against a message the receiver does not hold")]
    NoBase,
}

impl DropReason {
    /// A short name for counters: `version`, `other-run`, `kind`, `sender`, `length`,
    /// `malformed`, `superseded`, `no-base`.
    pub fn label(self) -> &'static str {
        match self {
            DropReason::Version => "version",
            DropReason::OtherRun => "other-run",
            DropReason::Kind => "kind",
            DropReason::Sender => "sender",
            DropReason::Length => "length",
            DropReason::Superseded => "superseded",
            DropReason::Malformed => "malformed",
            DropReason::NoBase => "no-base",
        }
    }
}

/// Wall-clock time, nanoseconds since the Unix epoch (0 if the clock is before it): the clock
/// of [`WireHeader::sent_unix_ns`], which every process on the machine shares.
pub fn unix_now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// One target's set in an estimate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TargetSetMsg {
    /// Target id.
    pub id: u32,
    /// Outer set `X_j` (a delta against the base message's `X_j` of this id).
    pub set: SetCode,
}

/// One occupancy elevation map cell that changed.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct OemCellUpdate {
    /// Cell column on the OEM grid.
    pub ix: u16,
    /// Cell row on the OEM grid.
    pub iy: u16,
    /// 0 unknown, 1 obstacle, 2 ground.
    pub status: u8,
    /// Height of the obstacle, metres (0 for ground).
    pub height_m: f32,
}

/// An agent's running counters, carried by every estimate.
///
/// The one record of them: the agent counts into it and sends it as it is, its report at exit
/// prints it (`uav_agent::agent::AgentCounters`), and the observer sums it over the agent's
/// incarnations (`+=`) into summary.json. A counter is defined here only: the report and the
/// summary name every field, so the build points at the places that give it its key.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct AgentStats {
    /// Frames folded into the estimator.
    pub frames: u64,
    /// Frames refused (malformed, other run).
    pub frames_refused: u64,
    /// Peer estimates fused.
    pub estimates_received: u64,
    /// Peer messages dropped (bad header, malformed, other run or version).
    pub messages_dropped: u64,
    /// Guidance decisions taken.
    pub decisions: u64,
    /// Decisions taken after waiting out a silent token holder.
    pub token_timeouts: u64,
    /// Peer estimates the simulated radio lost on the way to this agent (`comms.loss`), of
    /// the steps up to this estimate's.
    pub estimates_lost: u64,
    /// Tokens the simulated radio lost on the way to this agent.
    pub tokens_lost: u64,
    /// Peer measurements applied from a copy another agent forwarded (`comms.relay_hops`).
    pub relayed_applied: u64,
    /// Peer measurements this agent forwarded.
    pub relayed_sent: u64,
    /// Decisions taken from an external planner's answer (docs/python.md).
    pub external_decisions: u64,
    /// Decisions of an agent that asks an external planner taken by its fallback planner
    /// instead (the answer was late, malformed or absent).
    pub external_fallbacks: u64,
}

impl std::ops::AddAssign for AgentStats {
    /// Adds `other`'s counts to these (an agent's totals over its incarnations).
    fn add_assign(&mut self, other: AgentStats) {
        // Every field by name: a counter added to the record does not compile until it is
        // summed too.
        let AgentStats {
            frames,
            frames_refused,
            estimates_received,
            messages_dropped,
            decisions,
            token_timeouts,
            estimates_lost,
            tokens_lost,
            relayed_applied,
            relayed_sent,
            external_decisions,
            external_fallbacks,
        } = other;
        self.frames += frames;
        self.frames_refused += frames_refused;
        self.estimates_received += estimates_received;
        self.messages_dropped += messages_dropped;
        self.decisions += decisions;
        self.token_timeouts += token_timeouts;
        self.estimates_lost += estimates_lost;
        self.tokens_lost += tokens_lost;
        self.relayed_applied += relayed_applied;
        self.relayed_sent += relayed_sent;
        self.external_decisions += external_decisions;
        self.external_fallbacks += external_fallbacks;
    }
}

impl std::iter::Sum for AgentStats {
    fn sum<I: Iterator<Item = AgentStats>>(iter: I) -> AgentStats {
        iter.fold(AgentStats::default(), |mut total, stats| {
            total += stats;
            total
        })
    }
}

/// Agent -> peers and observers: the agent's estimate at a step.
///
/// Under the set exchange (`comms.exchange = "sets"`) it carries the agent's sets after
/// correction ([`SetsMsg`]) in every message. Under the measurement exchange it carries what
/// the agent's frame of the step proved ([`MeasurementMsg`]), and whole sets only now and
/// then and when a peer (re)joins.
///
/// Each set is whole or a delta ([`SetCode`]) against the set of the same role in the
/// sender's message `base_seq` of the same incarnation; a receiver that does not hold that
/// message rebuilds nothing from this one and asks for whole sets in its own estimates
/// (`want_whole`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimateMsg {
    /// Sender's UAV index.
    pub uav: u32,
    /// Step the sets belong to.
    pub step: u64,
    /// Simulated time, seconds.
    pub time_s: f64,
    /// Counts every message this agent process sent (a heartbeat).
    pub seq: u64,
    /// Changes each time the agent (re)starts, so peers can tell a restart.
    pub incarnation: u64,
    /// The `seq` of the message (same sender and incarnation) the deltas are against; `None`
    /// when every set is whole.
    pub base_seq: Option<u64>,
    /// Peers whose sets the sender could not rebuild ([`uav_bit`]): each of them sends whole
    /// sets in its next estimate.
    pub want_whole: UavMask,
    /// The camera pose of the frame.
    pub pose: CameraPose,
    /// The sender's sets, if the message carries them.
    pub sets: Option<SetsMsg>,
    /// What the sender's frame of `step` proved, under the measurement exchange.
    pub measurement: Option<MeasurementMsg>,
    /// Peers' measurements the sender applied and forwards (`comms.relay_hops`).
    pub relayed: Vec<RelayedMeasurementMsg>,
    /// The sender's counters, so observers see them even if the agent is killed.
    pub stats: AgentStats,
    /// OEM cells changed since the last message, or the whole known map when `oem_full`.
    pub oem: Vec<OemCellUpdate>,
    /// Whether `oem` holds every known cell rather than a delta.
    pub oem_full: bool,
}

/// The sets of an estimate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SetsMsg {
    /// Outer set `X̄` of targets not yet identified.
    pub undetected: SetCode,
    /// Outer sets `X_j` of identified targets.
    pub targets: Vec<TargetSetMsg>,
    /// Inner set `S^o` of ground near obstacles, accumulated.
    pub obstacle_neighbourhood: SetCode,
    /// Ground proven free at some frame so far (union of `P^g`), for the explored metric.
    pub explored: SetCode,
    /// Ground hidden in this frame, `H^CVS`.
    pub hidden: SetCode,
    /// Ground this frame proved free, `P^g`: receivers remove it from their `H̄`, which is the
    /// fleet's (ground hidden from any UAV and seen by none since).
    pub free_ground: SetCode,
    /// `H̄`: ground hidden at some earlier frame and not proven free since, as the sender held
    /// it before fusing the step's estimates (for the OA metric).
    pub unseen: SetCode,
}

/// What one frame proved (the measurement exchange): sets of one camera window, whole.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeasurementMsg {
    /// `P^g`: ground the frame proved free at its step.
    pub free_ground: SetCode,
    /// `H^CVS`: ground the frame's view held but did not show.
    pub hidden: SetCode,
    /// The cells of `S^o` the frame added.
    pub obstacles: SetCode,
    /// `X^m_j` of each car the frame measured.
    pub targets: Vec<TargetSetMsg>,
}

/// A peer's measurement as another agent forwards it (`comms.relay_hops`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RelayedMeasurementMsg {
    /// The UAV whose frame it is.
    pub uav: u32,
    /// The frame's step.
    pub step: u64,
    /// How many agents forwarded it, this message's sender included (at least 1).
    pub hops: u32,
    /// The camera pose of the frame.
    pub pose: CameraPose,
    /// What the frame proved.
    pub measurement: MeasurementMsg,
    /// The map cells the frame changed.
    pub oem: Vec<OemCellUpdate>,
}

/// One UAV's plan for the horizon, as the next UAVs in the token need it: its predicted camera
/// poses at every CVS step of the horizon (the receiver derives the fields of view and what
/// its own map says buildings hide, with the same functions the sender used).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlannedView {
    /// UAV index.
    pub uav: u32,
    /// Predicted camera pose after each CVS step of the horizon, in order.
    pub poses: Vec<CameraPose>,
}

/// The round-robin guidance token.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GuidanceToken {
    /// Round number, one per guidance period.
    pub round: u64,
    /// Step at which the round started.
    pub step: u64,
    /// The order of live UAVs this round.
    pub order: Vec<u32>,
    /// The UAV that must plan next.
    pub holder: u32,
    /// The UAV that issued (or reissued) the token.
    pub issued_by: u32,
    /// Plans of the UAVs that already decided this round.
    pub plans: Vec<PlannedView>,
    /// The sending UAV's camera pose as it sent this token, which the simulated radio judges
    /// the token's range by, as it judges an estimate's (`crate::radio::Radio::carries_token`;
    /// `None`, unknown, is out of every finite range).
    pub pose: Option<CameraPose>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agent_stats_sum_field_by_field() {
        let one = AgentStats {
            frames: 3,
            frames_refused: 1,
            estimates_received: 5,
            messages_dropped: 2,
            decisions: 1,
            token_timeouts: 0,
            estimates_lost: 4,
            tokens_lost: 1,
            relayed_applied: 6,
            relayed_sent: 7,
            external_decisions: 1,
            external_fallbacks: 2,
        };
        let total: AgentStats = [one, one, AgentStats::default()].into_iter().sum();
        assert_eq!(
            total,
            AgentStats {
                frames: 6,
                frames_refused: 2,
                estimates_received: 10,
                messages_dropped: 4,
                decisions: 2,
                token_timeouts: 0,
                estimates_lost: 8,
                tokens_lost: 2,
                relayed_applied: 12,
                relayed_sent: 14,
                external_decisions: 2,
                external_fallbacks: 4,
            }
        );
    }

    fn header() -> WireHeader {
        WireHeader::new(WireKind::Estimate, 5, 2, 7, 10, 0)
    }

    #[test]
    fn a_new_header_carries_the_version_and_passes_its_own_check() {
        let h = header();
        assert_eq!(h.version, PROTOCOL_VERSION);
        assert_eq!(h.kind, WireKind::Estimate as u32);
        assert_eq!((h.run_tag, h.sender, h.step, h.len), (5, 2, 7, 10));
        assert_eq!(h.check(10, WireKind::Estimate, 5, Some(2)), Ok(()));
        assert_eq!(h.check(10, WireKind::Estimate, 5, None), Ok(()));
    }

    #[test]
    fn headers_are_checked_field_by_field() {
        let h = header();
        let cases = [
            (
                WireHeader { version: 0, ..h },
                10,
                WireKind::Estimate,
                5,
                DropReason::Version,
            ),
            (h, 10, WireKind::Estimate, 6, DropReason::OtherRun),
            (h, 10, WireKind::Token, 5, DropReason::Kind),
            (
                WireHeader { sender: 1, ..h },
                10,
                WireKind::Estimate,
                5,
                DropReason::Sender,
            ),
            (h, 9, WireKind::Estimate, 5, DropReason::Length),
        ];
        for (header, len, kind, run, reason) in cases {
            assert_eq!(
                header.check(len, kind, run, Some(2)),
                Err(reason),
                "{reason:?}"
            );
        }
    }

    #[test]
    fn the_first_field_that_differs_is_the_reason() {
        // Everything wrong: the version is checked first, then the run, the kind, the sender
        // and the length last.
        let bad = WireHeader {
            version: PROTOCOL_VERSION + 1,
            kind: WireKind::Token as u32,
            run_tag: 9,
            sender: 3,
            len: 1,
            ..header()
        };
        let reasons = [
            DropReason::Version,
            DropReason::OtherRun,
            DropReason::Kind,
            DropReason::Sender,
            DropReason::Length,
        ];
        let mut h = bad;
        for (i, reason) in reasons.into_iter().enumerate() {
            assert_eq!(
                h.check(10, WireKind::Estimate, 5, Some(2)),
                Err(reason),
                "{i}"
            );
            match reason {
                DropReason::Version => h.version = PROTOCOL_VERSION,
                DropReason::OtherRun => h.run_tag = 5,
                DropReason::Kind => h.kind = WireKind::Estimate as u32,
                DropReason::Sender => h.sender = 2,
                _ => h.len = 10,
            }
        }
        assert_eq!(h.check(10, WireKind::Estimate, 5, Some(2)), Ok(()));
    }

    #[test]
    fn drop_reasons_have_distinct_labels() {
        let all = [
            DropReason::Version,
            DropReason::OtherRun,
            DropReason::Kind,
            DropReason::Sender,
            DropReason::Length,
            DropReason::Malformed,
            DropReason::Superseded,
            DropReason::NoBase,
        ];
        let labels: std::collections::BTreeSet<_> = all.iter().map(|r| r.label()).collect();
        assert_eq!(labels.len(), all.len());
        assert_eq!(DropReason::OtherRun.label(), "other-run");
    }

    #[test]
    fn masks_hold_every_uav_of_the_largest_fleet_and_nothing_beyond() {
        assert_eq!(MAX_UAVS, 64);
        let all: Vec<u32> = (0..MAX_UAVS as u32).collect();
        let mask = all.iter().fold(0, |m, &u| m | uav_bit(u));
        assert_eq!(mask, UavMask::MAX);
        assert_eq!(uavs_in(mask).collect::<Vec<_>>(), all);
        assert_eq!(uav_bit(MAX_UAVS as u32), 0);
        assert_eq!(uav_bit(u32::MAX), 0);
        assert_eq!(
            uavs_in(uav_bit(3) | uav_bit(31) | uav_bit(32) | uav_bit(63)).collect::<Vec<_>>(),
            [3, 31, 32, 63]
        );
        // The last UAV's bit is the top one, and alone it names that UAV only.
        assert_eq!(uav_bit(63), 1 << 63);
        assert_eq!(uavs_in(uav_bit(63)).collect::<Vec<_>>(), [63]);
    }

    #[test]
    fn the_last_uavs_bit_survives_the_wire() {
        let ack = ObserverAck {
            run_tag: 1,
            step: 2,
            restarted: uav_bit(63) | uav_bit(0),
        };
        assert_eq!(uavs_in(ack.restarted).collect::<Vec<_>>(), [0, 63]);
        let msg = EstimateMsg {
            uav: 62,
            step: 3,
            time_s: 1.5,
            seq: 4,
            incarnation: 5,
            base_seq: None,
            want_whole: uav_bit(63) | uav_bit(40),
            pose: CameraPose {
                position: sets::math::Point3::new(1.0, 2.0, 80.0),
                yaw: 0.5,
            },
            sets: None,
            measurement: None,
            relayed: Vec::new(),
            stats: AgentStats::default(),
            oem: Vec::new(),
            oem_full: false,
        };
        let bytes = crate::codec::encode(&msg).expect("encode");
        let back: EstimateMsg = crate::codec::decode(&bytes).expect("decode");
        assert_eq!(back, msg);
        assert_eq!(uavs_in(back.want_whole).collect::<Vec<_>>(), [40, 63]);
    }

    #[test]
    fn fixed_size_messages_have_no_padding_and_aligned_masks() {
        use std::mem::{align_of, offset_of, size_of};
        // Three 8-byte fields: no hole for a sender's stale bytes to fill.
        assert_eq!(size_of::<ObserverAck>(), 24);
        assert_eq!(offset_of!(ObserverAck, restarted), 16);
        assert_eq!(align_of::<UavMask>(), 8);
        let truth = size_of::<TargetTruth>() * TRUTH_MAX_TARGETS + size_of::<UavTruth>() * MAX_UAVS;
        assert_eq!(size_of::<TruthState>(), 32 + truth);
        assert_eq!(
            offset_of!(TruthState, targets) % align_of::<TargetTruth>(),
            0
        );
    }
}
