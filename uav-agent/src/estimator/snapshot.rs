//! Serde adapters that store a [`CellSet`] as its compact [`EncodedSet`], so an
//! [`super::EstimatorState`] serialises to a snapshot of a few tens of kilobytes and a corrupt
//! snapshot is refused with an error instead of a malformed set.

use std::collections::BTreeMap;

use protocol::grid::GroundGrid;
use protocol::math::Point2;
use protocol::raster::{CellSet, EncodedSet};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Decodes an encoded set on a grid of the size it declares: the set type only needs the
/// dimensions, which the caller checks against its configuration.
pub(crate) fn decode_self_sized(encoded: &EncodedSet) -> Result<CellSet, String> {
    let grid = GroundGrid {
        origin: Point2::origin(),
        cell_m: 1.0,
        nx: encoded.nx,
        ny: encoded.ny,
    };
    CellSet::decode(&grid, encoded).map_err(|e| e.to_string())
}

/// `#[serde(with = "cell_set")]` for a [`CellSet`] field.
pub(crate) mod cell_set {
    use super::*;

    pub(crate) fn serialize<S: Serializer>(set: &CellSet, s: S) -> Result<S::Ok, S::Error> {
        set.encode().serialize(s)
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<CellSet, D::Error> {
        let encoded = EncodedSet::deserialize(d)?;
        decode_self_sized(&encoded).map_err(D::Error::custom)
    }
}

/// `#[serde(with = "cell_set_map")]` for a `BTreeMap<K, CellSet>` field.
pub(crate) mod cell_set_map {
    use super::*;

    pub(crate) fn serialize<K, S>(map: &BTreeMap<K, CellSet>, s: S) -> Result<S::Ok, S::Error>
    where
        K: Serialize + Ord,
        S: Serializer,
    {
        let encoded: Vec<(&K, EncodedSet)> = map.iter().map(|(k, v)| (k, v.encode())).collect();
        encoded.serialize(s)
    }

    pub(crate) fn deserialize<'de, K, D>(d: D) -> Result<BTreeMap<K, CellSet>, D::Error>
    where
        K: Deserialize<'de> + Ord,
        D: Deserializer<'de>,
    {
        let encoded = Vec::<(K, EncodedSet)>::deserialize(d)?;
        encoded
            .into_iter()
            .map(|(k, e)| decode_self_sized(&e).map(|s| (k, s)))
            .collect::<Result<_, _>>()
            .map_err(D::Error::custom)
    }
}
