//! Estimates on the wire: [`EstimatorState`] -> [`EstimateMsg`] -> bytes, and back to a
//! validated [`PeerEstimate`].
//!
//! The map travels as the cells changed since the previous message, and as the whole known
//! map every `oem_full_every` messages or when asked ([`EstimateOutbox::request_full`], e.g.
//! after a peer restarted), so a peer that missed messages or restarted rebuilds it.
//!
//! Sets travel the same way when the outbox sends deltas ([`EstimateOutbox::with_set_deltas`],
//! as agents do): in a whole message (the first one, every `oem_full_every`-th, and the next
//! one after a request) every set is whole ([`SetCode::Whole`]); in the others each set is a
//! delta against the same set of the previous message ([`SetCode::Delta`], the cells that
//! changed) whenever that is smaller. An [`EstimateInbox`] keeps, per sender, the sets of the
//! last message it rebuilt, and applies a delta message only to exactly its base (same
//! incarnation, `base_seq`): a receiver that missed a message, joined late or restarted
//! rebuilds nothing from the deltas it cannot place ([`EstimateReadError::MissingBase`],
//! counted and dropped), asks for whole sets in its own estimates
//! ([`EstimateInbox::wanted`] -> [`EstimateMsg::want_whole`]) and is back in step with the
//! next whole message. Every rebuilt set is compared with the sender's digest, so a set
//! rebuilt from a wrong base is refused, never fused: the fused sets are exactly those a
//! receiver of whole sets fuses.
//!
//! On lossy links (`comms.loss > 0`, [`protocol::radio`]) agents send whole sets in every
//! message: a receiver whose radio lost a message could place none of the deltas after it
//! until whole sets came, so what it fused would depend on its history of losses, not only on
//! which messages reached it. The map keeps its scheme there: its cells merge by a join (ground
//! wins, else the taller obstacle), so a change carried by a lost message only comes later, with
//! the next whole map (every `oem_full_every` messages) or the cell's next change; it never makes
//! a receiver's map wrong, and the map feeds the guidance only, never the guaranteed sets.
//!
//! Besides its guaranteed sets, an estimate carries the sender's `H^CVS` and `P^g` of its step
//! (the ground its frame saw hidden and the ground it proved free) and its `H̄` as it stood
//! before the step's fusion: a receiver folds the first two into its own `H̄`, which is the
//! fleet's ([`super::Unseen`]), and the observer rebuilds every agent's `H̄` from the three.
//! `P^g` is one camera footprint: a few runs per row of its box, and as a delta the cells the
//! footprint gained and lost since the previous frame.
//!
//! Whatever a peer sends is validated: a set on another grid (any of them, `P^g` included), a
//! malformed set or delta, a map cell out of range, a duplicated target are typed errors, never
//! a panic. The layout is the protocol's ([`protocol::wire::PROTOCOL_VERSION`]): a peer of
//! another version is refused by its header before its payload is read.

use std::collections::BTreeMap;
use std::sync::Arc;

use protocol::camera::CameraPose;
use protocol::codec::{self, DecodeError, EncodeError};
use protocol::wire::{
    DropReason, EstimateMsg, MeasurementMsg, OemCellUpdate, RelayedMeasurementMsg, SetsMsg,
    TargetSetMsg, UavMask, uav_bit,
};
use sets::grid::GroundGrid;
use sets::math::Point3;
use sets::raster::CellSet;
use sets::raster::delta::{DeltaError, SetCode};

use super::fusion::{EstimateSets, SharedSet};
use super::{EstimatorConfig, EstimatorState, Measurement, PeerEstimate, Relayed};
use crate::occupancy::{OccupancyMap, OemUpdateError};

/// The sets of one message: the estimate's, and the sender's `H̄` (which only the observer
/// reads). What a sender keeps as the base of its next deltas and a receiver rebuilds
/// (sharing the estimate's with the [`PeerEstimate`] it hands on).
#[derive(Clone, Debug, PartialEq)]
struct MessageSets {
    /// The estimate's sets.
    estimate: EstimateSets,
    /// `H̄`.
    unseen: SharedSet,
}

impl MessageSets {
    /// The sets a state sends.
    fn of_state(state: &EstimatorState) -> Self {
        Self {
            estimate: EstimateSets::of_state(state),
            unseen: Arc::new(state.hidden_history.unseen().clone()),
        }
    }
}

/// Builds this agent's outgoing estimates and numbers them.
#[derive(Clone, Debug, PartialEq)]
pub struct EstimateOutbox {
    uav: u32,
    incarnation: u64,
    seq: u64,
    full_every: u64,
    full_requested: bool,
    /// Whether the first message is whole (not for a sender that starts from the prior under
    /// the measurement exchange: [`EstimateOutbox::starting_fresh`]).
    first_whole: bool,
    set_deltas: bool,
    /// Whether messages carry the map.
    map: bool,
    /// The sets of the last message, when sets go as deltas.
    last: Option<MessageSets>,
}

impl EstimateOutbox {
    /// The outbox of UAV `uav` in its `incarnation` (a value that changes at each start),
    /// sending the whole map every `full_every` messages (and in the first one). Sets go whole
    /// in every message unless [`EstimateOutbox::with_set_deltas`].
    pub fn new(uav: u32, incarnation: u64, full_every: u64) -> Self {
        Self {
            uav,
            incarnation,
            seq: 0,
            full_every: full_every.max(1),
            full_requested: true,
            first_whole: true,
            set_deltas: false,
            map: true,
            last: None,
        }
    }

    /// Messages carry no map (the observers' copy of an agent's sets under the measurement
    /// exchange: the map travels with the measurements), and leave the state's map alone.
    pub fn without_map(mut self) -> Self {
        self.map = false;
        self
    }

    /// For a sender that starts from the prior (no checkpoint) under the measurement
    /// exchange: its first message is not whole. Its sets and its map are then the prior
    /// corrected by its own frame, and its measurement carries that frame, so a receiver
    /// learns nothing more from them: at a fleet's start each receiver would decode and fuse
    /// every peer's whole sets of the region for nothing. Later whole messages come as
    /// before: asked for, or every `full_every`-th.
    pub fn starting_fresh(mut self) -> Self {
        self.full_requested = false;
        self.first_whole = false;
        self
    }

    /// Sends sets as deltas against the previous message, except in whole messages (the
    /// first, every `full_every`-th and the one after [`EstimateOutbox::request_full`]); its
    /// receivers must read with an [`EstimateInbox`].
    pub fn with_set_deltas(mut self) -> Self {
        self.set_deltas = true;
        self
    }

    /// Makes the next message carry the whole known map and whole sets.
    pub fn request_full(&mut self) {
        self.full_requested = true;
    }

    /// Messages composed so far.
    pub fn sent(&self) -> u64 {
        self.seq
    }

    /// The message for the current state, with its sets (whole or as deltas). Drains the
    /// map's pending changes into it.
    pub fn compose(&mut self, state: &mut EstimatorState) -> EstimateMsg {
        let full = self.next_is_full();
        let oem = self.take_map(state, full);
        let sets = MessageSets::of_state(state);
        let base = if full { None } else { self.last.take() };
        let (sets_msg, any_delta) = sets_msg(&sets, base.as_ref());
        let msg = self.message(state, Some(sets_msg), None, any_delta, oem, full);
        if self.set_deltas {
            self.last = Some(sets);
        }
        msg
    }

    /// The measurement exchange's message of the current state: the frame's `measurement`,
    /// with the whole sets and the whole map in a whole message (the first, every
    /// `full_every`-th and the one after [`EstimateOutbox::request_full`]), else the map
    /// cells the frame changed, and the peers' measurements it forwards (`relayed`). Drains
    /// the map's pending changes.
    pub fn compose_measurement(
        &mut self,
        state: &mut EstimatorState,
        measurement: &Measurement,
        relayed: &[Relayed],
    ) -> EstimateMsg {
        let full = self.next_is_full();
        let pending = self.take_map(state, full);
        let oem = if full {
            pending
        } else {
            measurement.map_cells.clone()
        };
        let sets = full.then(|| sets_msg(&MessageSets::of_state(state), None).0);
        let relayed = relayed
            .iter()
            .map(|r| RelayedMeasurementMsg {
                uav: r.measurement.uav,
                step: r.measurement.step,
                hops: r.hops,
                pose: r.measurement.pose.unwrap_or(NO_POSE),
                measurement: measurement_msg(&r.measurement),
                oem: r.measurement.map_cells.clone(),
            })
            .collect();
        let measured = measurement_msg(measurement);
        EstimateMsg {
            relayed,
            ..self.message(state, sets, Some(measured), false, oem, full)
        }
    }

    /// Whether the next message is a whole one; clears a request.
    fn next_is_full(&mut self) -> bool {
        let periodic =
            self.seq.is_multiple_of(self.full_every) && (self.seq > 0 || self.first_whole);
        let full = self.full_requested || periodic;
        self.full_requested = false;
        full
    }

    /// The map of the next message: the whole known map or the pending changes (none when
    /// the outbox sends no map).
    fn take_map(&self, state: &mut EstimatorState, full: bool) -> Vec<OemCellUpdate> {
        match (self.map, full) {
            (false, _) => Vec::new(),
            (true, true) => state.oem.take_full(),
            (true, false) => state.oem.take_changes(),
        }
    }

    /// The next message, numbered.
    fn message(
        &mut self,
        state: &EstimatorState,
        sets: Option<SetsMsg>,
        measurement: Option<MeasurementMsg>,
        any_delta: bool,
        oem: Vec<OemCellUpdate>,
        full: bool,
    ) -> EstimateMsg {
        let msg = EstimateMsg {
            uav: self.uav,
            step: state.step,
            time_s: state.time_s,
            seq: self.seq,
            incarnation: self.incarnation,
            // The base is the previous message: `last` is only kept between consecutive ones.
            base_seq: any_delta.then(|| self.seq.saturating_sub(1)),
            want_whole: 0,
            pose: state.pose.unwrap_or(NO_POSE),
            sets,
            measurement,
            relayed: Vec::new(),
            stats: protocol::wire::AgentStats::default(),
            oem,
            oem_full: full && self.map,
        };
        self.seq += 1;
        msg
    }
}

/// The pose a message carries when its state has none (before the first frame).
const NO_POSE: CameraPose = CameraPose {
    position: Point3::new(0.0, 0.0, 0.0),
    yaw: 0.0,
};

/// A measurement's sets, whole (a camera window's sets are small, and a receiver holds no
/// base for them).
fn measurement_msg(m: &Measurement) -> MeasurementMsg {
    let whole = |set: &SharedSet| SetCode::Whole(set.encode());
    MeasurementMsg {
        free_ground: whole(&m.free_ground),
        hidden: whole(&m.hidden),
        obstacles: whole(&m.obstacles),
        targets: m
            .targets
            .iter()
            .map(|(&id, set)| TargetSetMsg {
                id,
                set: whole(set),
            })
            .collect(),
    }
}

/// The sets as a message, each a delta against `base` where that is smaller; whether any is.
fn sets_msg(sets: &MessageSets, base: Option<&MessageSets>) -> (SetsMsg, bool) {
    let code = |set: &SharedSet, base: Option<&SharedSet>| SetCode::choose(set, base.map(|b| &**b));
    let (ours, theirs) = (&sets.estimate, base.map(|b| &b.estimate));
    let msg = SetsMsg {
        undetected: code(&ours.undetected, theirs.map(|b| &b.undetected)),
        targets: ours
            .targets
            .iter()
            .map(|(&id, set)| TargetSetMsg {
                id,
                set: code(set, theirs.and_then(|b| b.targets.get(&id))),
            })
            .collect(),
        obstacle_neighbourhood: code(
            &ours.obstacle_neighbourhood,
            theirs.map(|b| &b.obstacle_neighbourhood),
        ),
        explored: code(&ours.explored, theirs.map(|b| &b.explored)),
        hidden: code(&ours.hidden, theirs.map(|b| &b.hidden)),
        free_ground: code(&ours.free_ground, theirs.map(|b| &b.free_ground)),
        unseen: code(&sets.unseen, base.map(|b| &b.unseen)),
    };
    let any_delta = [
        &msg.undetected,
        &msg.obstacle_neighbourhood,
        &msg.explored,
        &msg.hidden,
        &msg.free_ground,
        &msg.unseen,
    ]
    .into_iter()
    .chain(msg.targets.iter().map(|t| &t.set))
    .any(SetCode::is_delta);
    (msg, any_delta)
}

/// Which set of an estimate was bad.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SetRole {
    /// `X̄`.
    Undetected,
    /// `X_j` of this id.
    Target(u32),
    /// `S^o`.
    ObstacleNeighbourhood,
    /// The explored ground.
    Explored,
    /// `H^CVS`.
    Hidden,
    /// `P^g`.
    FreeGround,
    /// `H̄`.
    Unseen,
    /// The measurement's `P^g`.
    MeasuredFree,
    /// The measurement's `H^CVS`.
    MeasuredHidden,
    /// The measurement's new `S^o` cells.
    MeasuredObstacles,
    /// The measurement `X^m_j` of this id.
    Measured(u32),
}

/// Why a peer's estimate was refused.
#[derive(Debug, thiserror::Error)]
pub enum EstimateReadError {
    /// The bytes are not an estimate message (truncated, corrupted, too large, trailing bytes).
    #[error("undecodable estimate: {0}")]
    Bytes(#[from] DecodeError),
    /// A set is malformed, lives on another grid, or its delta does not rebuild the sender's
    /// set.
    #[error("bad {role:?} set: {source}")]
    Set {
        /// Which set.
        role: SetRole,
        /// What is wrong with it.
        source: DeltaError,
    },
    /// The sets are deltas against a message this receiver does not hold.
    #[error("deltas against message {base_seq} of UAV {uav}, which is not held here")]
    MissingBase {
        /// The sender.
        uav: u32,
        /// The message the deltas are against.
        base_seq: u64,
    },
    /// Two target sets share an id.
    #[error("target {0} appears twice")]
    DuplicateTarget(u32),
    /// A map update is out of range or malformed.
    #[error("bad OEM update: {0}")]
    Oem(#[from] OemUpdateError),
    /// The time stamp is not a finite number.
    #[error("time stamp {0} is not finite")]
    BadTime(f64),
    /// The message carries no sets where sets were expected (a measurement alone).
    #[error("the estimate of UAV {0} carries no sets")]
    NoSets(u32),
    /// A forwarded measurement is of the sender itself, of a step not before the message's,
    /// or claims a number of hops out of range.
    #[error("bad forwarded measurement of UAV {uav} at step {step}: {reason}")]
    BadRelay {
        /// The UAV whose measurement it claims to be.
        uav: u32,
        /// Its step.
        step: u64,
        /// What is wrong with it.
        reason: &'static str,
    },
}

impl EstimateReadError {
    /// The reason to count the message as dropped under: [`DropReason::NoBase`] when it could
    /// not be rebuilt for want of the right base (a resync mends it), else
    /// [`DropReason::Malformed`].
    pub fn drop_reason(&self) -> DropReason {
        match self {
            EstimateReadError::MissingBase { .. }
            | EstimateReadError::Set {
                source: DeltaError::NoBase | DeltaError::WrongBase { .. },
                ..
            } => DropReason::NoBase,
            _ => DropReason::Malformed,
        }
    }
}

/// Encodes a message to bytes.
pub fn to_bytes(msg: &EstimateMsg) -> Result<Vec<u8>, EncodeError> {
    codec::encode(msg)
}

/// Decodes a message from bytes, without validating its content.
pub fn from_bytes(bytes: &[u8]) -> Result<EstimateMsg, DecodeError> {
    codec::decode(bytes)
}

fn decode_set(
    grid: &GroundGrid,
    role: SetRole,
    code: &SetCode,
    base: Option<&SharedSet>,
) -> Result<SharedSet, EstimateReadError> {
    code.decode(grid, base.map(|b| &**b))
        .map(Arc::new)
        .map_err(|source| EstimateReadError::Set { role, source })
}

/// A peer's message as received and validated: its sets (an estimate), its frame's
/// measurement (the measurement exchange), or both.
#[derive(Clone, Debug, PartialEq)]
pub struct PeerMessage {
    /// Sender's UAV index.
    pub uav: u32,
    /// Step of the message.
    pub step: u64,
    /// Sender's message counter.
    pub seq: u64,
    /// Sender's incarnation.
    pub incarnation: u64,
    /// Sender's camera pose at that step (`None` when not finite).
    pub pose: Option<CameraPose>,
    /// Its sets, when it carries them (with the message's map).
    pub estimate: Option<PeerEstimate>,
    /// What its frame proved (with the message's map when it carries no sets).
    pub measurement: Option<Measurement>,
    /// Peers' measurements it forwards (`comms.relay_hops`).
    pub relayed: Vec<Relayed>,
}

impl PeerMessage {
    /// Validates a received message that holds no deltas (a message with delta sets needs an
    /// [`EstimateInbox`]: here it is [`EstimateReadError::MissingBase`]).
    pub fn from_msg(
        msg: &EstimateMsg,
        config: &EstimatorConfig,
    ) -> Result<Self, EstimateReadError> {
        rebuild(msg, config, None).map(|(message, _)| message)
    }

    /// Decodes and validates a received message that holds no deltas (a message with delta
    /// sets needs an [`EstimateInbox`]: here it is [`EstimateReadError::MissingBase`]).
    pub fn from_bytes(bytes: &[u8], config: &EstimatorConfig) -> Result<Self, EstimateReadError> {
        rebuild(&from_bytes(bytes)?, config, None).map(|(message, _)| message)
    }

    /// Its sender, its step and the sender's pose then ([`protocol::radio::Radio::fuses`]).
    pub fn endpoint(&self) -> protocol::radio::Endpoint {
        protocol::radio::Endpoint {
            uav: self.uav,
            step: self.step,
            pose: self.pose,
        }
    }
}

/// Validates a message and rebuilds its sets, its deltas against `base` (the sets of message
/// `msg.base_seq`, or `None` when the receiver holds no base), and its measurement.
fn rebuild(
    msg: &EstimateMsg,
    config: &EstimatorConfig,
    base: Option<&MessageSets>,
) -> Result<(PeerMessage, Option<MessageSets>), EstimateReadError> {
    if !msg.time_s.is_finite() {
        return Err(EstimateReadError::BadTime(msg.time_s));
    }
    let pose = finite(msg.pose);
    for u in &msg.oem {
        OccupancyMap::cell_of_update(&config.oem_grid, u)?;
    }
    let sets = match &msg.sets {
        Some(sets) => Some(rebuild_sets(msg, sets, config, base)?),
        None => None,
    };
    let estimate = match &sets {
        Some(sets) => Some(PeerEstimate {
            uav: msg.uav,
            step: msg.step,
            time_s: msg.time_s,
            seq: msg.seq,
            incarnation: msg.incarnation,
            pose,
            sets: sets.estimate.clone(),
            oem: OccupancyMap::from_updates(config.oem_grid, &msg.oem)?,
            oem_full: msg.oem_full,
        }),
        None => None,
    };
    // The map goes with the sets when the message carries both.
    let map_cells = if sets.is_some() {
        Vec::new()
    } else {
        msg.oem.clone()
    };
    let measurement = msg
        .measurement
        .as_ref()
        .map(|m| decode_measurement(config, msg.uav, msg.step, pose, m, map_cells))
        .transpose()?;
    let relayed = msg
        .relayed
        .iter()
        .map(|r| decode_relayed(config, msg, r))
        .collect::<Result<_, _>>()?;
    let message = PeerMessage {
        uav: msg.uav,
        step: msg.step,
        seq: msg.seq,
        incarnation: msg.incarnation,
        pose,
        estimate,
        measurement,
        relayed,
    };
    Ok((message, sets))
}

/// The pose, when every number of it is finite.
fn finite(pose: CameraPose) -> Option<CameraPose> {
    let ok = pose.position.iter().all(|v| v.is_finite()) && pose.yaw.is_finite();
    ok.then_some(pose)
}

/// Validates and decodes the measurement of UAV `uav` at `step`, its camera at `pose`.
fn decode_measurement(
    config: &EstimatorConfig,
    uav: u32,
    step: u64,
    pose: Option<CameraPose>,
    m: &MeasurementMsg,
    map_cells: Vec<OemCellUpdate>,
) -> Result<Measurement, EstimateReadError> {
    let grid = &config.grid;
    let mut targets = BTreeMap::new();
    for t in &m.targets {
        let set = decode_set(grid, SetRole::Measured(t.id), &t.set, None)?;
        if targets.insert(t.id, set).is_some() {
            return Err(EstimateReadError::DuplicateTarget(t.id));
        }
    }
    Ok(Measurement {
        uav,
        step,
        pose,
        free_ground: decode_set(grid, SetRole::MeasuredFree, &m.free_ground, None)?,
        hidden: decode_set(grid, SetRole::MeasuredHidden, &m.hidden, None)?,
        obstacles: decode_set(grid, SetRole::MeasuredObstacles, &m.obstacles, None)?,
        targets,
        map_cells,
    })
}

/// Validates and decodes a measurement that `msg`'s sender forwards: another UAV's, of an
/// earlier step, forwarded at most [`protocol::scenario::MAX_RELAY_HOPS`] times.
fn decode_relayed(
    config: &EstimatorConfig,
    msg: &EstimateMsg,
    r: &RelayedMeasurementMsg,
) -> Result<Relayed, EstimateReadError> {
    let bad = |reason| EstimateReadError::BadRelay {
        uav: r.uav,
        step: r.step,
        reason,
    };
    if r.uav == msg.uav {
        return Err(bad("the sender's own"));
    }
    if r.step >= msg.step {
        return Err(bad("not of an earlier step than its message"));
    }
    if !(1..=protocol::scenario::MAX_RELAY_HOPS).contains(&r.hops) {
        return Err(bad("hops out of range"));
    }
    for u in &r.oem {
        OccupancyMap::cell_of_update(&config.oem_grid, u)?;
    }
    let measurement = decode_measurement(
        config,
        r.uav,
        r.step,
        finite(r.pose),
        &r.measurement,
        r.oem.clone(),
    )?;
    Ok(Relayed {
        hops: r.hops,
        measurement,
    })
}

/// Rebuilds the sets of a message, its deltas against `base`.
fn rebuild_sets(
    msg: &EstimateMsg,
    sets: &SetsMsg,
    config: &EstimatorConfig,
    base: Option<&MessageSets>,
) -> Result<MessageSets, EstimateReadError> {
    let grid = &config.grid;
    if let (Some(base_seq), None) = (msg.base_seq, base) {
        return Err(EstimateReadError::MissingBase {
            uav: msg.uav,
            base_seq,
        });
    }
    let theirs = base.map(|b| &b.estimate);
    let mut targets = BTreeMap::new();
    for t in &sets.targets {
        let b = theirs.and_then(|b| b.targets.get(&t.id));
        let set = decode_set(grid, SetRole::Target(t.id), &t.set, b)?;
        if targets.insert(t.id, set).is_some() {
            return Err(EstimateReadError::DuplicateTarget(t.id));
        }
    }
    let estimate = EstimateSets {
        undetected: decode_set(
            grid,
            SetRole::Undetected,
            &sets.undetected,
            theirs.map(|b| &b.undetected),
        )?,
        targets,
        obstacle_neighbourhood: decode_set(
            grid,
            SetRole::ObstacleNeighbourhood,
            &sets.obstacle_neighbourhood,
            theirs.map(|b| &b.obstacle_neighbourhood),
        )?,
        explored: decode_set(
            grid,
            SetRole::Explored,
            &sets.explored,
            theirs.map(|b| &b.explored),
        )?,
        hidden: decode_set(
            grid,
            SetRole::Hidden,
            &sets.hidden,
            theirs.map(|b| &b.hidden),
        )?,
        free_ground: decode_set(
            grid,
            SetRole::FreeGround,
            &sets.free_ground,
            theirs.map(|b| &b.free_ground),
        )?,
    };
    Ok(MessageSets {
        estimate,
        unseen: decode_set(grid, SetRole::Unseen, &sets.unseen, base.map(|b| &b.unseen))?,
    })
}

/// What a receiver holds of one sender: the sets of its last rebuilt message.
#[derive(Clone, Debug, PartialEq)]
struct Held {
    incarnation: u64,
    seq: u64,
    /// The base of the sender's next delta (none in an inbox that keeps no bases).
    sets: Option<MessageSets>,
}

/// The receiving side of estimates whose sets may be deltas: per sender, the sets of the last
/// message rebuilt, the base of the next delta.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EstimateInbox {
    held: BTreeMap<u32, Held>,
    /// Whether the sets of each sender's last message are kept as the base of its deltas.
    no_bases: bool,
    wanted: UavMask,
}

impl EstimateInbox {
    /// An inbox that holds nothing (a newcomer: it needs a whole message from each sender).
    pub fn new() -> Self {
        Self::default()
    }

    /// An inbox for senders that never send deltas (the measurement exchange's whole sets,
    /// [`EstimateOutbox::compose_measurement`]): it keeps no sets between messages, so its
    /// memory does not grow with the fleet times the region. A delta read by it finds no
    /// base, and its sender is wanted.
    pub fn without_bases() -> Self {
        Self {
            no_bases: true,
            ..Self::default()
        }
    }

    /// Validates a received message and rebuilds its sets, applying its deltas to the sets
    /// held from the same sender's message `base_seq` of the same incarnation. A message that
    /// cannot be rebuilt is an error (its sender is then in [`EstimateInbox::wanted`] until a
    /// message of it is rebuilt); the held sets change only with a rebuilt message that is not
    /// of an older incarnation than them.
    pub fn read(
        &mut self,
        msg: &EstimateMsg,
        config: &EstimatorConfig,
    ) -> Result<PeerEstimate, EstimateReadError> {
        self.read_message(msg, config)?
            .estimate
            .ok_or(EstimateReadError::NoSets(msg.uav))
    }

    /// As [`EstimateInbox::read`], for a message that may carry a measurement instead of
    /// sets, or both.
    pub fn read_message(
        &mut self,
        msg: &EstimateMsg,
        config: &EstimatorConfig,
    ) -> Result<PeerMessage, EstimateReadError> {
        let held = self.held.get(&msg.uav);
        let base = held
            .filter(|h| h.incarnation == msg.incarnation && Some(h.seq) == msg.base_seq)
            .and_then(|h| h.sets.as_ref());
        match rebuild(msg, config, base) {
            Ok((message, sets)) => {
                if let Some(sets) = sets
                    && held.is_none_or(|h| h.incarnation <= msg.incarnation)
                {
                    self.held.insert(
                        msg.uav,
                        Held {
                            incarnation: msg.incarnation,
                            seq: msg.seq,
                            sets: (!self.no_bases).then_some(sets),
                        },
                    );
                    self.wanted &= !uav_bit(msg.uav);
                }
                Ok(message)
            }
            Err(e) => {
                if e.drop_reason() == DropReason::NoBase {
                    self.wanted |= uav_bit(msg.uav);
                }
                Err(e)
            }
        }
    }

    /// Decodes, validates and rebuilds a received message ([`EstimateInbox::read`]).
    pub fn read_bytes(
        &mut self,
        bytes: &[u8],
        config: &EstimatorConfig,
    ) -> Result<PeerEstimate, EstimateReadError> {
        self.read(&from_bytes(bytes)?, config)
    }

    /// The senders whose deltas could not be placed since their last rebuilt message: what
    /// to ask whole sets of ([`EstimateMsg::want_whole`]).
    pub fn wanted(&self) -> UavMask {
        self.wanted
    }

    /// `H̄` of the last message rebuilt from `uav`.
    pub fn unseen(&self, uav: u32) -> Option<&CellSet> {
        self.held
            .get(&uav)
            .and_then(|h| h.sets.as_ref())
            .map(|s| &*s.unseen)
    }
}

impl PeerEstimate {
    /// Validates a received message against this agent's configuration; a message whose sets
    /// are deltas needs an [`EstimateInbox`] (here it is [`EstimateReadError::MissingBase`]).
    pub fn from_msg(
        msg: &EstimateMsg,
        config: &EstimatorConfig,
    ) -> Result<Self, EstimateReadError> {
        rebuild(msg, config, None)?
            .0
            .estimate
            .ok_or(EstimateReadError::NoSets(msg.uav))
    }

    /// Decodes and validates a received message ([`PeerEstimate::from_msg`]).
    pub fn from_bytes(bytes: &[u8], config: &EstimatorConfig) -> Result<Self, EstimateReadError> {
        Self::from_msg(&from_bytes(bytes)?, config)
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use proptest::strategy::ValueTree;
    use protocol::wire::OemCellUpdate;
    use sets::raster::{EncodedSet, ReachSet};

    use super::*;
    use crate::fusion::tests::{config, peer_strategy};

    fn state_from(p: &PeerEstimate) -> EstimatorState {
        let cfg = config();
        let mut s = EstimatorState::new(&cfg);
        s.step = p.step;
        s.time_s = p.time_s;
        s.undetected = ReachSet::with_cells((*p.sets.undetected).clone());
        s.targets = p
            .sets
            .targets
            .iter()
            .map(|(id, set)| (*id, ReachSet::with_cells((**set).clone())))
            .collect();
        s.obstacle_neighbourhood = (*p.sets.obstacle_neighbourhood).clone();
        s.explored = (*p.sets.explored).clone();
        s.hidden = (*p.sets.hidden).clone();
        s.free_ground = (*p.sets.free_ground).clone();
        s.oem = p.oem.clone();
        s
    }

    fn sample_bytes() -> Vec<u8> {
        let mut runner = proptest::test_runner::TestRunner::deterministic();
        let p = peer_strategy(5)
            .new_tree(&mut runner)
            .expect("tree")
            .current();
        let mut s = state_from(&p);
        let msg = EstimateOutbox::new(2, 9, 4).compose(&mut s);
        to_bytes(&msg).expect("encode")
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        #[test]
        fn estimates_round_trip_through_bytes(p in peer_strategy(5)) {
            let cfg = config();
            let mut s = state_from(&p);
            let mut outbox = EstimateOutbox::new(2, 9, 4);
            let msg = outbox.compose(&mut s);
            prop_assert!(msg.oem_full);
            let bytes = to_bytes(&msg).unwrap();
            prop_assert_eq!(&from_bytes(&bytes).unwrap(), &msg);
            let back = PeerEstimate::from_bytes(&bytes, &cfg).unwrap();
            prop_assert_eq!((back.uav, back.step, back.incarnation), (2, 5, 9));
            prop_assert_eq!(&back.sets, &p.sets);
            prop_assert_eq!(
                back.oem.known_cells().collect::<Vec<_>>(),
                p.oem.known_cells().collect::<Vec<_>>()
            );
        }

        #[test]
        fn deltas_rebuild_every_message_exactly(
            a in peer_strategy(5), b in peer_strategy(6), c in peer_strategy(7)
        ) {
            let cfg = config();
            let mut outbox = EstimateOutbox::new(2, 9, 10).with_set_deltas();
            let mut inbox = EstimateInbox::new();
            for (i, p) in [&a, &b, &c, &a].into_iter().enumerate() {
                let mut s = state_from(p);
                let msg = outbox.compose(&mut s);
                prop_assert_eq!(msg.base_seq.is_some(), i > 0 && msg.base_seq == Some(i as u64 - 1));
                let bytes = to_bytes(&msg).unwrap();
                let back = inbox.read_bytes(&bytes, &cfg).unwrap();
                prop_assert_eq!(&back.sets, &p.sets);
                prop_assert_eq!(inbox.unseen(2), Some(s.hidden_history.unseen()));
                prop_assert_eq!(inbox.wanted(), 0);
            }
        }

        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let _ = PeerEstimate::from_bytes(&bytes, &config());
        }

        #[test]
        fn truncations_are_refused(cut in 0.0f64..1.0) {
            let bytes = sample_bytes();
            let n = ((bytes.len() as f64) * cut) as usize;
            prop_assert!(PeerEstimate::from_bytes(&bytes[..n], &config()).is_err());
        }

        #[test]
        fn bit_flips_are_refused_or_read_as_valid_estimates(pos in any::<usize>(), bit in 0u8..8) {
            let mut bytes = sample_bytes();
            let i = pos % bytes.len();
            bytes[i] ^= 1 << bit;
            // Either an error, or an estimate that passed every validation.
            if let Ok(p) = PeerEstimate::from_bytes(&bytes, &config()) {
                let g = config().grid;
                prop_assert!(p.sets.undetected.same_shape(&CellSet::empty(&g)));
            }
        }
    }

    #[test]
    fn deltas_carry_only_changed_cells_and_full_maps_come_back() {
        let cfg = config();
        let mut s = EstimatorState::new(&cfg);
        let mut outbox = EstimateOutbox::new(0, 1, 3);
        s.oem
            .observe_obstacle(&sets::math::Point2::new(1.0, 1.0), 20.0);
        assert_eq!(outbox.compose(&mut s).oem.len(), 1); // first message: full
        assert!(outbox.compose(&mut s).oem.is_empty()); // nothing changed
        s.oem
            .observe_obstacle(&sets::math::Point2::new(-5.0, 1.0), 10.0);
        let m = outbox.compose(&mut s);
        assert!(!m.oem_full && m.oem.len() == 1);
        let m = outbox.compose(&mut s); // seq 3: periodic full map
        assert!(m.oem_full && m.oem.len() == 2);
        outbox.request_full();
        assert!(outbox.compose(&mut s).oem_full);
        assert_eq!(outbox.sent(), 5);
    }

    #[test]
    fn a_fresh_sender_sends_whole_sets_only_when_asked_or_periodically() {
        let cfg = config();
        let mut s = EstimatorState::new(&cfg);
        s.oem
            .observe_obstacle(&sets::math::Point2::new(1.0, 1.0), 20.0);
        let nothing = Arc::new(CellSet::empty(&cfg.grid));
        let m = Measurement {
            uav: 0,
            step: 0,
            pose: None,
            free_ground: nothing.clone(),
            hidden: nothing.clone(),
            obstacles: nothing,
            targets: BTreeMap::new(),
            map_cells: Vec::new(),
        };
        let whole = |msg: EstimateMsg| {
            assert_eq!(msg.sets.is_some(), msg.oem_full);
            msg.oem_full
        };
        // Resumed (or under the set exchange): the first message is whole.
        let mut resumed = EstimateOutbox::new(0, 1, 3);
        assert!(whole(resumed.compose_measurement(&mut s, &m, &[])));
        // Fresh: its first message is its measurement alone, and its map's changes.
        let mut fresh = EstimateOutbox::new(0, 1, 3).starting_fresh();
        s.oem
            .observe_obstacle(&sets::math::Point2::new(-5.0, 1.0), 10.0);
        let first = fresh.compose_measurement(&mut s, &m, &[]);
        assert!(first.measurement.is_some() && first.oem.is_empty());
        assert!(!whole(first));
        assert!(!whole(fresh.compose_measurement(&mut s, &m, &[])));
        assert!(!whole(fresh.compose_measurement(&mut s, &m, &[])));
        assert!(whole(fresh.compose_measurement(&mut s, &m, &[]))); // seq 3: periodic
        fresh.request_full();
        assert!(whole(fresh.compose_measurement(&mut s, &m, &[])));
        assert!(!whole(fresh.compose_measurement(&mut s, &m, &[])));
    }

    /// Forwarded measurements travel with the sender's own and come back as they went; one
    /// of the sender itself, of a step not before its message's or with hops out of range is
    /// refused as a whole message.
    #[test]
    fn forwarded_measurements_round_trip_and_bad_ones_are_refused() {
        let cfg = config();
        let pose = CameraPose {
            position: Point3::new(1.0, 2.0, 80.0),
            yaw: 0.25,
        };
        let mut s = EstimatorState::new(&cfg);
        s.step = 5;
        s.pose = Some(pose);
        let cells = |c: &[(u32, u32)]| Arc::new(CellSet::from_cells(&cfg.grid, c.iter().copied()));
        let of = |uav, step| Measurement {
            uav,
            step,
            pose: Some(pose),
            free_ground: cells(&[(1, 1), (2, 1)]),
            hidden: cells(&[(3, 3)]),
            obstacles: cells(&[]),
            targets: BTreeMap::from([(7, cells(&[(4, 4)]))]),
            map_cells: Vec::new(),
        };
        let relayed = vec![
            Relayed {
                hops: 1,
                measurement: of(2, 4),
            },
            Relayed {
                hops: 2,
                measurement: of(3, 3),
            },
        ];
        let mut outbox = EstimateOutbox::new(1, 1, 1000).starting_fresh();
        let msg = outbox.compose_measurement(&mut s, &of(1, 5), &relayed);
        let back = PeerMessage::from_bytes(&to_bytes(&msg).unwrap(), &cfg).unwrap();
        assert_eq!(back.relayed, relayed);
        assert_eq!(back.measurement, Some(of(1, 5)));
        let refused = |edit: fn(&mut RelayedMeasurementMsg)| {
            let mut bad = msg.clone();
            edit(&mut bad.relayed[0]);
            matches!(
                PeerMessage::from_msg(&bad, &cfg),
                Err(EstimateReadError::BadRelay { .. })
            )
        };
        assert!(refused(|r| r.uav = 1), "the sender's own");
        assert!(refused(|r| r.step = 5), "of the message's step");
        assert!(refused(|r| r.hops = 0));
        assert!(refused(|r| r.hops = protocol::scenario::MAX_RELAY_HOPS + 1));
    }

    /// A state whose sets change a little at each step, as a real one's do (the seen ground
    /// grows by a column).
    fn moving_state(step: u64) -> EstimatorState {
        let cfg = config();
        let mut s = EstimatorState::new(&cfg);
        s.step = step;
        s.time_s = step as f64 * 0.5;
        let g = cfg.grid;
        let mut seen = CellSet::empty(&g);
        for iy in 2..10 {
            seen.fill_row_span(iy, 0, step as u32 + 5);
        }
        let mut undetected = CellSet::full(&g);
        undetected.and_not_assign(&seen);
        s.undetected = ReachSet::with_cells(undetected);
        s.explored = seen.clone();
        s.hidden = CellSet::from_cells(&g, [(1, step as u32 % 30)]);
        s
    }

    #[test]
    fn a_receiver_that_missed_a_message_asks_for_whole_sets_and_resyncs() {
        let cfg = config();
        let mut outbox = EstimateOutbox::new(3, 7, 100).with_set_deltas();
        let mut inbox = EstimateInbox::new();
        let first = outbox.compose(&mut moving_state(0));
        assert_eq!(first.base_seq, None);
        inbox.read(&first, &cfg).unwrap();
        let second = outbox.compose(&mut moving_state(1));
        assert_eq!(second.base_seq, Some(0));
        assert!(second.sets.as_ref().unwrap().undetected.is_delta());
        // The second message is lost: the third one's base is not held.
        let third = outbox.compose(&mut moving_state(2));
        let e = inbox.read(&third, &cfg).unwrap_err();
        assert!(matches!(
            e,
            EstimateReadError::MissingBase {
                uav: 3,
                base_seq: 1
            }
        ));
        assert_eq!(e.drop_reason(), DropReason::NoBase);
        assert_eq!(inbox.wanted(), uav_bit(3));
        // Deltas keep failing until the sender, asked, sends whole sets.
        assert!(
            inbox
                .read(&outbox.compose(&mut moving_state(3)), &cfg)
                .is_err()
        );
        outbox.request_full();
        let whole = outbox.compose(&mut moving_state(4));
        assert_eq!(whole.base_seq, None);
        let back = inbox.read(&whole, &cfg).unwrap();
        assert_eq!(*back.sets.undetected, *moving_state(4).undetected.cells());
        assert_eq!(inbox.wanted(), 0);
        let next = outbox.compose(&mut moving_state(5));
        assert_eq!(next.base_seq, Some(4));
        let back = inbox.read(&next, &cfg).unwrap();
        assert_eq!(*back.sets.explored, moving_state(5).explored);
        // A stateless reader (or a newcomer) cannot use a delta message.
        assert!(matches!(
            PeerEstimate::from_msg(&next, &cfg),
            Err(EstimateReadError::MissingBase { .. })
        ));
        assert!(EstimateInbox::new().read(&next, &cfg).is_err());
    }

    #[test]
    fn the_last_uav_of_the_largest_fleet_is_asked_for_whole_sets_and_resyncs() {
        let cfg = config();
        let last = protocol::wire::MAX_UAVS as u32 - 1;
        let mut outbox = EstimateOutbox::new(last, 7, 100).with_set_deltas();
        let mut other = EstimateOutbox::new(0, 7, 100).with_set_deltas();
        let mut inbox = EstimateInbox::new();
        inbox
            .read(&outbox.compose(&mut moving_state(0)), &cfg)
            .unwrap();
        inbox
            .read(&other.compose(&mut moving_state(0)), &cfg)
            .unwrap();
        // One message of each lost: both are wanted, UAV 63 in the mask's top bit.
        outbox.compose(&mut moving_state(1));
        other.compose(&mut moving_state(1));
        assert!(
            inbox
                .read(&outbox.compose(&mut moving_state(2)), &cfg)
                .is_err()
        );
        assert!(
            inbox
                .read(&other.compose(&mut moving_state(2)), &cfg)
                .is_err()
        );
        assert_eq!(inbox.wanted(), 1 << 63 | 1);
        // The ask crosses the wire whole.
        let mut ask = other.compose(&mut moving_state(3));
        ask.want_whole = inbox.wanted();
        let back = from_bytes(&to_bytes(&ask).unwrap()).unwrap();
        assert_eq!(back.want_whole & uav_bit(last), uav_bit(last));
        outbox.request_full();
        inbox
            .read(&outbox.compose(&mut moving_state(4)), &cfg)
            .unwrap();
        assert_eq!(inbox.wanted(), uav_bit(0));
    }

    #[test]
    fn an_inbox_without_bases_keeps_no_sets_and_wants_the_sender_of_a_delta() {
        let cfg = config();
        let mut outbox = EstimateOutbox::new(3, 7, 100).with_set_deltas();
        let mut inbox = EstimateInbox::without_bases();
        let whole = inbox
            .read(&outbox.compose(&mut moving_state(0)), &cfg)
            .unwrap();
        assert_eq!(whole.step, 0);
        assert_eq!(inbox.unseen(3), None, "no sets kept");
        let e = inbox
            .read(&outbox.compose(&mut moving_state(1)), &cfg)
            .unwrap_err();
        assert_eq!(e.drop_reason(), DropReason::NoBase);
        assert_eq!(inbox.wanted(), uav_bit(3));
        outbox.request_full();
        inbox
            .read(&outbox.compose(&mut moving_state(2)), &cfg)
            .unwrap();
        assert_eq!(inbox.wanted(), 0);
    }

    #[test]
    fn a_restarted_sender_is_read_from_its_first_message_and_a_wrong_base_is_refused() {
        let cfg = config();
        let mut old = EstimateOutbox::new(1, 5, 100).with_set_deltas();
        let mut inbox = EstimateInbox::new();
        inbox
            .read(&old.compose(&mut moving_state(0)), &cfg)
            .unwrap();
        inbox
            .read(&old.compose(&mut moving_state(1)), &cfg)
            .unwrap();
        // Restarted: a new incarnation whose seq starts over. Its deltas are not against
        // what is held of the old process.
        let mut new = EstimateOutbox::new(1, 6, 100).with_set_deltas();
        let mut first = new.compose(&mut moving_state(8));
        inbox.read(&first, &cfg).unwrap();
        let mut d = new.compose(&mut moving_state(9));
        d.incarnation = 5; // claims the old process: base seq 0 of it is not held
        assert!(inbox.read(&d, &cfg).is_err());
        // A delta whose base_seq names the held message but whose flips were made against
        // another set: the digest refuses it.
        first.seq = 1;
        inbox.read(&first, &cfg).unwrap();
        let mut forged = new.compose(&mut moving_state(10));
        forged.base_seq = Some(1);
        let e = inbox.read(&forged, &cfg).unwrap_err();
        assert!(
            matches!(
                e,
                EstimateReadError::Set {
                    source: DeltaError::WrongBase { .. },
                    ..
                }
            ),
            "{e}"
        );
        assert_eq!(inbox.wanted(), uav_bit(1));
    }

    #[test]
    fn invalid_content_is_a_typed_error() {
        let cfg = config();
        let mut s = EstimatorState::new(&cfg);
        let good = EstimateOutbox::new(0, 1, 3).compose(&mut s);
        assert!(PeerEstimate::from_msg(&good, &cfg).is_ok());

        let mut m = good.clone();
        let SetCode::Whole(e) = &good.sets.as_ref().unwrap().undetected else {
            panic!("a first message is whole")
        };
        m.sets.as_mut().unwrap().undetected = SetCode::Whole(EncodedSet { nx: 7, ..e.clone() });
        assert!(matches!(
            PeerEstimate::from_msg(&m, &cfg),
            Err(EstimateReadError::Set {
                role: SetRole::Undetected,
                ..
            })
        ));

        // P^g, which clears the receivers' H̄: on another grid, as a delta without a base, with
        // runs that overflow its box.
        let mut m = good.clone();
        let SetCode::Whole(e) = &good.sets.as_ref().unwrap().free_ground else {
            panic!("a first message is whole")
        };
        m.sets.as_mut().unwrap().free_ground = SetCode::Whole(EncodedSet { ny: 3, ..e.clone() });
        let refused = PeerEstimate::from_msg(&m, &cfg);
        assert!(
            matches!(
                refused,
                Err(EstimateReadError::Set {
                    role: SetRole::FreeGround,
                    ..
                })
            ),
            "{refused:?}"
        );
        m.sets.as_mut().unwrap().free_ground = SetCode::Delta(sets::raster::delta::SetDelta {
            flips: e.clone(),
            digest: 1,
        });
        let refused = PeerEstimate::from_msg(&m, &cfg);
        assert!(matches!(
            refused,
            Err(EstimateReadError::Set {
                role: SetRole::FreeGround,
                source: DeltaError::NoBase,
            })
        ));
        assert_eq!(refused.unwrap_err().drop_reason(), DropReason::NoBase);
        let mut runs = e.clone();
        runs.runs = vec![u32::MAX, 5];
        m.sets.as_mut().unwrap().free_ground = SetCode::Whole(runs);
        assert!(matches!(
            PeerEstimate::from_msg(&m, &cfg),
            Err(EstimateReadError::Set {
                role: SetRole::FreeGround,
                source: DeltaError::Decode(_),
            })
        ));

        let mut m = good.clone();
        let t = TargetSetMsg {
            id: 3,
            set: good.sets.as_ref().unwrap().hidden.clone(),
        };
        m.sets.as_mut().unwrap().targets = vec![t.clone(), t];
        assert!(matches!(
            PeerEstimate::from_msg(&m, &cfg),
            Err(EstimateReadError::DuplicateTarget(3))
        ));

        let mut m = good.clone();
        m.oem = vec![OemCellUpdate {
            ix: 999,
            iy: 0,
            status: 1,
            height_m: 1.0,
        }];
        assert!(matches!(
            PeerEstimate::from_msg(&m, &cfg),
            Err(EstimateReadError::Oem(_))
        ));

        let mut m = good;
        m.time_s = f64::NAN;
        assert!(matches!(
            PeerEstimate::from_msg(&m, &cfg),
            Err(EstimateReadError::BadTime(_))
        ));
    }
}
