//! Serde adapters that store a [`CellSet`] as its compact [`EncodedSet`] and a [`ReachSet`]
//! as its cells and clock (its reach is rebuilt when the state is restored), so an
//! [`super::EstimatorState`] serialises to a compact snapshot and a corrupt snapshot is
//! refused with an error instead of a malformed set.

use std::collections::BTreeMap;

use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use sets::grid::GroundGrid;
use sets::math::Point2;
use sets::raster::{CellSet, EncodedSet, ReachSet};

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

/// A map stored as `(key, stored value)` pairs, each value through `store`.
fn serialize_map<K, V, W, S>(
    map: &BTreeMap<K, V>,
    store: impl Fn(&V) -> W,
    s: S,
) -> Result<S::Ok, S::Error>
where
    K: Serialize + Ord,
    W: Serialize,
    S: Serializer,
{
    let stored: Vec<(&K, W)> = map.iter().map(|(k, v)| (k, store(v))).collect();
    stored.serialize(s)
}

/// The map [`serialize_map`] stored, each value through `load`; the first failure refuses it.
fn deserialize_map<'de, K, V, W, D>(
    d: D,
    load: impl Fn(&W) -> Result<V, String>,
) -> Result<BTreeMap<K, V>, D::Error>
where
    K: Deserialize<'de> + Ord,
    W: Deserialize<'de>,
    D: Deserializer<'de>,
{
    Vec::<(K, W)>::deserialize(d)?
        .into_iter()
        .map(|(k, w)| load(&w).map(|v| (k, v)))
        .collect::<Result<_, _>>()
        .map_err(D::Error::custom)
}

/// `#[serde(with = "cell_set_map")]` for a `BTreeMap<K, CellSet>` field.
pub(crate) mod cell_set_map {
    use super::*;

    pub(crate) fn serialize<K, S>(map: &BTreeMap<K, CellSet>, s: S) -> Result<S::Ok, S::Error>
    where
        K: Serialize + Ord,
        S: Serializer,
    {
        serialize_map(map, CellSet::encode, s)
    }

    pub(crate) fn deserialize<'de, K, D>(d: D) -> Result<BTreeMap<K, CellSet>, D::Error>
    where
        K: Deserialize<'de> + Ord,
        D: Deserializer<'de>,
    {
        deserialize_map(d, decode_self_sized)
    }
}

/// A [`ReachSet`] as stored: its cells and its clock. The reach is not stored (a distance
/// field as large as the grid, hard to compress). A loaded set has reach 0 everywhere, which
/// keeps the guarantee but lets every cell join at the next advance;
/// [`super::Estimator::with_state`] rebuilds the reach from the cells' gaps on the
/// estimator's grid ([`ReachSet::from_cells_at`]), after which the set grows from its cells
/// by the motion since, without the sub-cell reach it had.
#[derive(Serialize, Deserialize)]
struct StoredReach {
    cells: EncodedSet,
    clock_m: f64,
}

fn store_reach(set: &ReachSet) -> StoredReach {
    StoredReach {
        cells: set.cells().encode(),
        clock_m: set.clock_m(),
    }
}

fn load_reach(stored: &StoredReach) -> Result<ReachSet, String> {
    let cells = decode_self_sized(&stored.cells)?;
    let zeros = vec![0; stored.cells.nx as usize * stored.cells.ny as usize];
    ReachSet::from_parts(cells, 0, &zeros, stored.clock_m)
        .ok_or_else(|| "reach does not fit its cells".to_owned())
}

/// `#[serde(with = "reach_set")]` for a [`ReachSet`] field.
pub(crate) mod reach_set {
    use super::*;

    pub(crate) fn serialize<S: Serializer>(set: &ReachSet, s: S) -> Result<S::Ok, S::Error> {
        store_reach(set).serialize(s)
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<ReachSet, D::Error> {
        load_reach(&StoredReach::deserialize(d)?).map_err(D::Error::custom)
    }
}

/// `#[serde(with = "reach_set_map")]` for a `BTreeMap<K, ReachSet>` field.
pub(crate) mod reach_set_map {
    use super::*;

    pub(crate) fn serialize<K, S>(map: &BTreeMap<K, ReachSet>, s: S) -> Result<S::Ok, S::Error>
    where
        K: Serialize + Ord,
        S: Serializer,
    {
        serialize_map(map, store_reach, s)
    }

    pub(crate) fn deserialize<'de, K, D>(d: D) -> Result<BTreeMap<K, ReachSet>, D::Error>
    where
        K: Deserialize<'de> + Ord,
        D: Deserializer<'de>,
    {
        deserialize_map(d, load_reach)
    }
}
