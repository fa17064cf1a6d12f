//! Estimates on the wire: [`EstimatorState`] -> [`EstimateMsg`] -> bytes, and back to a
//! validated [`PeerEstimate`].
//!
//! Sets travel as [`CellSet::encode`] encodings. The map travels as the cells changed since the
//! previous message, and as the whole known map every `oem_full_every` messages or when asked
//! ([`EstimateOutbox::request_full`], e.g. after a peer restarted), so a peer that missed
//! messages or restarted rebuilds it. Whatever a peer sends is validated: a set on another
//! grid, a malformed set, a map cell out of range, a duplicated target are typed errors, never
//! a panic.

use std::collections::BTreeMap;

use protocol::camera::CameraPose;
use protocol::codec::{self, DecodeError, EncodeError};
use protocol::grid::GroundGrid;
use protocol::math::Point3;
use protocol::raster::{CellSet, SetDecodeError};
use protocol::wire::{EstimateMsg, TargetSetMsg};

use super::{EstimatorConfig, EstimatorState, PeerEstimate};
use crate::occupancy::{OccupancyMap, OemUpdateError};

/// Builds this agent's outgoing estimates and numbers them.
#[derive(Clone, Debug, PartialEq)]
pub struct EstimateOutbox {
    uav: u32,
    incarnation: u64,
    seq: u64,
    full_every: u64,
    full_requested: bool,
}

impl EstimateOutbox {
    /// The outbox of UAV `uav` in its `incarnation` (a value that changes at each start),
    /// sending the whole map every `full_every` messages (and in the first one).
    pub fn new(uav: u32, incarnation: u64, full_every: u64) -> Self {
        Self {
            uav,
            incarnation,
            seq: 0,
            full_every: full_every.max(1),
            full_requested: true,
        }
    }

    /// Makes the next message carry the whole known map.
    pub fn request_full(&mut self) {
        self.full_requested = true;
    }

    /// Messages composed so far.
    pub fn sent(&self) -> u64 {
        self.seq
    }

    /// The message for the current state. Drains the map's pending changes into it.
    pub fn compose(&mut self, state: &mut EstimatorState) -> EstimateMsg {
        let full = self.full_requested || self.seq.is_multiple_of(self.full_every);
        self.full_requested = false;
        let oem = if full {
            state.oem.take_full()
        } else {
            state.oem.take_changes()
        };
        let msg = EstimateMsg {
            uav: self.uav,
            step: state.step,
            time_s: state.time_s,
            seq: self.seq,
            incarnation: self.incarnation,
            pose: state.pose.unwrap_or(CameraPose {
                position: Point3::origin(),
                yaw: 0.0,
            }),
            undetected: state.undetected.cells().encode(),
            targets: state
                .targets
                .iter()
                .map(|(&id, set)| TargetSetMsg {
                    id,
                    set: set.cells().encode(),
                })
                .collect(),
            obstacle_free: state.obstacle_free.encode(),
            explored: state.explored.encode(),
            hidden: state.hidden.encode(),
            unseen: state.hidden_history.unseen().encode(),
            stats: protocol::wire::AgentStats::default(),
            oem,
            oem_full: full,
        };
        self.seq += 1;
        msg
    }
}

/// Which set of an estimate was bad.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SetRole {
    /// `X̄`.
    Undetected,
    /// `X_j` of this id.
    Target(u32),
    /// `S^o`.
    ObstacleFree,
    /// The explored ground.
    Explored,
    /// `H^CVS`.
    Hidden,
}

/// Why a peer's estimate was refused.
#[derive(Debug, thiserror::Error)]
pub enum EstimateReadError {
    /// The bytes are not an estimate message (truncated, corrupted, too large, trailing bytes).
    #[error("undecodable estimate: {0}")]
    Bytes(#[from] DecodeError),
    /// A set is malformed or lives on another grid.
    #[error("bad {role:?} set: {source}")]
    Set {
        /// Which set.
        role: SetRole,
        /// What is wrong with it.
        source: SetDecodeError,
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
    e: &protocol::raster::EncodedSet,
) -> Result<CellSet, EstimateReadError> {
    CellSet::decode(grid, e).map_err(|source| EstimateReadError::Set { role, source })
}

impl PeerEstimate {
    /// Validates a received message against this agent's configuration.
    pub fn from_msg(
        msg: &EstimateMsg,
        config: &EstimatorConfig,
    ) -> Result<Self, EstimateReadError> {
        let grid = &config.grid;
        if !msg.time_s.is_finite() {
            return Err(EstimateReadError::BadTime(msg.time_s));
        }
        let mut targets = BTreeMap::new();
        for t in &msg.targets {
            let set = decode_set(grid, SetRole::Target(t.id), &t.set)?;
            if targets.insert(t.id, set).is_some() {
                return Err(EstimateReadError::DuplicateTarget(t.id));
            }
        }
        let pose_ok = msg.pose.position.iter().all(|v| v.is_finite()) && msg.pose.yaw.is_finite();
        Ok(Self {
            uav: msg.uav,
            step: msg.step,
            time_s: msg.time_s,
            seq: msg.seq,
            incarnation: msg.incarnation,
            pose: pose_ok.then_some(msg.pose),
            undetected: decode_set(grid, SetRole::Undetected, &msg.undetected)?,
            targets,
            obstacle_free: decode_set(grid, SetRole::ObstacleFree, &msg.obstacle_free)?,
            explored: decode_set(grid, SetRole::Explored, &msg.explored)?,
            hidden: decode_set(grid, SetRole::Hidden, &msg.hidden)?,
            oem: OccupancyMap::from_updates(config.oem_grid, &msg.oem)?,
            oem_full: msg.oem_full,
        })
    }

    /// Decodes and validates a received message.
    pub fn from_bytes(bytes: &[u8], config: &EstimatorConfig) -> Result<Self, EstimateReadError> {
        Self::from_msg(&from_bytes(bytes)?, config)
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use proptest::strategy::ValueTree;
    use protocol::raster::{EncodedSet, ReachSet};
    use protocol::wire::OemCellUpdate;

    use super::*;
    use crate::estimator::fusion::tests::{config, peer_strategy};

    fn state_from(p: &PeerEstimate) -> EstimatorState {
        let cfg = config();
        let mut s = EstimatorState::new(&cfg);
        s.step = p.step;
        s.time_s = p.time_s;
        s.undetected = ReachSet::with_cells(p.undetected.clone());
        s.targets = p
            .targets
            .iter()
            .map(|(id, set)| (*id, ReachSet::with_cells(set.clone())))
            .collect();
        s.obstacle_free = p.obstacle_free.clone();
        s.explored = p.explored.clone();
        s.hidden = p.hidden.clone();
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
            prop_assert_eq!(&back.undetected, &p.undetected);
            prop_assert_eq!(&back.targets, &p.targets);
            prop_assert_eq!(&back.obstacle_free, &p.obstacle_free);
            prop_assert_eq!(&back.explored, &p.explored);
            prop_assert_eq!(&back.hidden, &p.hidden);
            prop_assert_eq!(
                back.oem.known_cells().collect::<Vec<_>>(),
                p.oem.known_cells().collect::<Vec<_>>()
            );
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
                prop_assert!(p.undetected.same_shape(&CellSet::empty(&g)));
            }
        }
    }

    #[test]
    fn deltas_carry_only_changed_cells_and_full_maps_come_back() {
        let cfg = config();
        let mut s = EstimatorState::new(&cfg);
        let mut outbox = EstimateOutbox::new(0, 1, 3);
        s.oem
            .observe_obstacle(&protocol::math::Point2::new(1.0, 1.0), 20.0);
        assert_eq!(outbox.compose(&mut s).oem.len(), 1); // first message: full
        assert!(outbox.compose(&mut s).oem.is_empty()); // nothing changed
        s.oem
            .observe_obstacle(&protocol::math::Point2::new(-5.0, 1.0), 10.0);
        let m = outbox.compose(&mut s);
        assert!(!m.oem_full && m.oem.len() == 1);
        let m = outbox.compose(&mut s); // seq 3: periodic full map
        assert!(m.oem_full && m.oem.len() == 2);
        outbox.request_full();
        assert!(outbox.compose(&mut s).oem_full);
        assert_eq!(outbox.sent(), 5);
    }

    #[test]
    fn invalid_content_is_a_typed_error() {
        let cfg = config();
        let mut s = EstimatorState::new(&cfg);
        let good = EstimateOutbox::new(0, 1, 3).compose(&mut s);
        assert!(PeerEstimate::from_msg(&good, &cfg).is_ok());

        let mut m = good.clone();
        m.undetected = EncodedSet {
            nx: 7,
            ..m.undetected.clone()
        };
        assert!(matches!(
            PeerEstimate::from_msg(&m, &cfg),
            Err(EstimateReadError::Set {
                role: SetRole::Undetected,
                ..
            })
        ));

        let mut m = good.clone();
        let t = TargetSetMsg {
            id: 3,
            set: good.hidden.clone(),
        };
        m.targets = vec![t.clone(), t];
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
