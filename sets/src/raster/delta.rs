//! Sets sent as changes: the cells that differ from a base set the receiver already holds.
//!
//! A [`SetDelta`] is the symmetric difference between the new set and its base, encoded like a
//! whole set ([`CellSet::encode`]: runs inside the bounding box, so a few changed cells cost a
//! few bytes), and the [`CellSet::fingerprint`] of the new set. Applying it flips those cells of the
//! base; the receiver then compares the result's digest with the one carried, so a delta
//! applied to another base than the sender's (a lost message, a restarted sender, a bug) is a
//! typed error instead of a wrong set. A [`SetCode`] is what a message carries for one set:
//! the whole set, or a delta when that is smaller.

use serde::{Deserialize, Serialize};

use super::{CellSet, EncodedSet, SetDecodeError};
use crate::grid::GroundGrid;

/// A set as the cells that changed since a base set, with the digest of the result.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetDelta {
    /// The cells in exactly one of the base and the new set.
    pub flips: EncodedSet,
    /// [`CellSet::fingerprint`] of the new set.
    pub digest: u64,
}

/// One set in a message: whole, or as a delta against the set of the same role in the base
/// message the receiver holds.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum SetCode {
    /// The whole set.
    Whole(EncodedSet),
    /// The changes since the base.
    Delta(SetDelta),
}

/// Why a [`SetDelta`] or a [`SetCode`] could not be turned back into a set.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum DeltaError {
    /// The encoded cells are malformed or on another grid.
    #[error(transparent)]
    Decode(#[from] SetDecodeError),
    /// A delta came and the receiver holds no base for it.
    #[error("a delta without a base set")]
    NoBase,
    /// The base lives on a grid of another size than the delta.
    #[error("base set on a {got_nx}x{got_ny} grid, the delta on {nx}x{ny}")]
    BaseShape {
        /// Width of the delta's grid.
        nx: u32,
        /// Height of the delta's grid.
        ny: u32,
        /// Width of the base's grid.
        got_nx: u32,
        /// Height of the base's grid.
        got_ny: u32,
    },
    /// The rebuilt set is not the sender's: the delta was applied to another base.
    #[error("rebuilt set has digest {got:#018x}, the sender's is {expected:#018x}")]
    WrongBase {
        /// The digest the sender carried.
        expected: u64,
        /// The digest of the set rebuilt here.
        got: u64,
    },
}

impl CellSet {
    /// The delta that turns `base` into `self`; `None` when the two live on grids of different
    /// sizes (then only the whole set can be sent).
    pub fn encode_delta(&self, base: &CellSet) -> Option<SetDelta> {
        self.flips_from(base).map(|flips| self.delta_of(&flips))
    }

    /// The cells in exactly one of `self` and `base` (`None` on grids of different sizes).
    fn flips_from(&self, base: &CellSet) -> Option<CellSet> {
        self.same_shape(base).then(|| {
            let mut flips = self.clone();
            flip_words(&mut flips, base);
            flips
        })
    }

    /// The delta of `flips` ([`CellSet::flips_from`] of some base) that rebuilds `self`.
    fn delta_of(&self, flips: &CellSet) -> SetDelta {
        SetDelta {
            flips: flips.encode(),
            digest: self.fingerprint(),
        }
    }

    /// The set a delta makes of `base` on `grid`; never panics on bad input. The result is
    /// checked against the delta's digest.
    pub fn apply_delta(
        base: &CellSet,
        grid: &GroundGrid,
        delta: &SetDelta,
    ) -> Result<CellSet, DeltaError> {
        let (nx, ny) = (delta.flips.nx, delta.flips.ny);
        if (nx, ny) == (grid.nx, grid.ny) && (base.nx, base.ny) != (nx, ny) {
            return Err(DeltaError::BaseShape {
                nx,
                ny,
                got_nx: base.nx,
                got_ny: base.ny,
            });
        }
        // The flips go straight into a copy of the base (checked like a whole set first).
        let mut set = base.clone();
        set.flip_encoded(grid, &delta.flips)?;
        let got = set.fingerprint();
        if got != delta.digest {
            return Err(DeltaError::WrongBase {
                expected: delta.digest,
                got,
            });
        }
        Ok(set)
    }
}

impl SetCode {
    /// How to send `set` to a receiver that holds `base` (`None`: holds nothing): as a delta
    /// when there is a base on the same grid and the delta has fewer runs than the whole set,
    /// else whole.
    pub fn choose(set: &CellSet, base: Option<&CellSet>) -> SetCode {
        // Runs are counted first (cheaper than writing them), and only the shorter written.
        match base.and_then(|b| set.flips_from(b)) {
            Some(flips) if flips.encoded_run_count() < set.encoded_run_count() => {
                SetCode::Delta(set.delta_of(&flips))
            }
            _ => SetCode::Whole(set.encode()),
        }
    }

    /// Whether this is a delta.
    pub fn is_delta(&self) -> bool {
        matches!(self, SetCode::Delta(_))
    }

    /// The set on `grid`, given the `base` the receiver holds for it (used by a delta only).
    pub fn decode(&self, grid: &GroundGrid, base: Option<&CellSet>) -> Result<CellSet, DeltaError> {
        match self {
            SetCode::Whole(e) => Ok(CellSet::decode(grid, e)?),
            SetCode::Delta(d) => CellSet::apply_delta(base.ok_or(DeltaError::NoBase)?, grid, d),
        }
    }
}

/// `set ← set xor other`, word by word over the rows `other` has cells in (both on grids of
/// the same size; bits past `nx` stay clear since they are clear in both).
fn flip_words(set: &mut CellSet, other: &CellSet) {
    let Some((lo, hi)) = other.row_range() else {
        return;
    };
    for iy in lo..=hi {
        for (a, b) in set.row_mut(iy).iter_mut().zip(other.row(iy)) {
            *a ^= b;
        }
    }
    set.trim_rows();
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    fn grid() -> GroundGrid {
        GroundGrid::new(20.0, 1.0)
    }

    fn set_strategy(density: f64) -> impl Strategy<Value = CellSet> {
        let g = grid();
        // Blocks of cells, so sets have runs as the real ones do, plus scattered cells.
        (
            proptest::collection::vec((0u32..g.nx, 0u32..g.ny, 1u32..12, 1u32..12), 0..6),
            proptest::collection::vec(proptest::bool::weighted(density), g.cell_count()),
        )
            .prop_map(move |(blocks, bits)| {
                let mut s = CellSet::empty(&g);
                for (x, y, w, h) in blocks {
                    for iy in y..(y + h).min(g.ny) {
                        s.fill_row_span(iy, x, x + w - 1);
                    }
                }
                for (i, b) in bits.into_iter().enumerate() {
                    if b {
                        s.set(((i as u32) % g.nx, (i as u32) / g.nx), true);
                    }
                }
                s
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        #[test]
        fn a_delta_rebuilds_the_set_from_its_base(
            a in set_strategy(0.05), b in set_strategy(0.05)
        ) {
            let g = grid();
            let d = b.encode_delta(&a).unwrap();
            prop_assert_eq!(CellSet::apply_delta(&a, &g, &d), Ok(b.clone()));
            // Whatever the codec chooses, the receiver holding the base rebuilds the set.
            let code = SetCode::choose(&b, Some(&a));
            prop_assert_eq!(code.decode(&g, Some(&a)), Ok(b.clone()));
            prop_assert_eq!(SetCode::choose(&b, None).decode(&g, None), Ok(b));
        }

        #[test]
        fn a_delta_applied_to_another_base_is_refused(
            a in set_strategy(0.05), b in set_strategy(0.05), c in set_strategy(0.05)
        ) {
            let g = grid();
            let d = b.encode_delta(&a).unwrap();
            if c != a {
                // b xor a xor c differs from b whenever c differs from a.
                let refused = matches!(
                    CellSet::apply_delta(&c, &g, &d),
                    Err(DeltaError::WrongBase { .. })
                );
                prop_assert!(refused);
            }
        }

        #[test]
        fn a_small_change_costs_a_small_delta(a in set_strategy(0.3), x in 0u32..40, y in 0u32..40) {
            let mut b = a.clone();
            b.set((x, y), !a.contains((x, y)));
            let d = b.encode_delta(&a).unwrap();
            prop_assert!(d.flips.runs.len() <= 2);
            // One cell is enough to tell the two apart.
            prop_assert_ne!(a.fingerprint(), b.fingerprint());
        }
    }

    #[test]
    fn an_unchanged_set_is_an_empty_delta() {
        let g = grid();
        let a = CellSet::from_cells(&g, [(1, 1), (5, 7)]);
        let d = a.encode_delta(&a).unwrap();
        assert_eq!(d.flips.bbox, None);
        assert!(SetCode::choose(&a, Some(&a)).is_delta());
        assert!(!SetCode::choose(&a, None).is_delta());
    }

    #[test]
    fn deltas_need_a_base_on_the_same_grid() {
        let g = grid();
        let other = GroundGrid::new(10.0, 1.0);
        let a = CellSet::from_cells(&g, [(1, 1)]);
        let small = CellSet::from_cells(&other, [(1, 1)]);
        assert_eq!(a.encode_delta(&small), None);
        let d = a.encode_delta(&CellSet::empty(&g)).unwrap();
        assert!(matches!(
            CellSet::apply_delta(&small, &g, &d),
            Err(DeltaError::BaseShape { .. })
        ));
        assert!(matches!(
            CellSet::apply_delta(&a, &other, &d),
            Err(DeltaError::Decode(SetDecodeError::GridMismatch { .. }))
        ));
        assert_eq!(SetCode::Delta(d).decode(&g, None), Err(DeltaError::NoBase));
    }
}
