//! The compact message form of a set: run lengths inside the bounding box.
//!
//! Runs alternate empty/full, start with an empty run (possibly of length 0) and read the box
//! row-major, continuing from one row's end to the next row's start. A run longer than
//! `u32::MAX` is written as `u32::MAX`, a zero-length run of the other value, and the rest, so
//! any grid size encodes.

use super::{CellBox, CellSet, EncodedSet, SetDecodeError};
use crate::grid::GroundGrid;

impl CellSet {
    /// The compact encoding for messages.
    pub fn encode(&self) -> EncodedSet {
        let bbox = self.bounding_box();
        let mut runs = Vec::new();
        if let Some(b) = bbox {
            let mut value = false;
            let mut len = 0u64;
            for iy in b.y0..=b.y1 {
                let row = self.row(iy);
                let end = b.x1 + 1;
                let mut x = b.x0;
                while x < end {
                    let next = next_with(row, x, end, !value);
                    len += u64::from(next - x);
                    x = next;
                    if x < end {
                        push_run(&mut runs, len);
                        value = !value;
                        len = 0;
                    }
                }
            }
            push_run(&mut runs, len);
        }
        EncodedSet {
            nx: self.nx,
            ny: self.ny,
            bbox,
            runs,
        }
    }

    /// The number of runs of [`CellSet::encode`], counted without writing them: the transitions
    /// between empty and full cells along the box, word by word.
    pub fn encoded_run_count(&self) -> usize {
        let Some(b) = self.bounding_box() else {
            return 0;
        };
        if b.cell_count() > u64::from(u32::MAX) {
            // Runs that long are split ([`CellSet::encode`]'s module docs): count them there.
            return self.encode().runs.len();
        }
        // Each cell against the one before it along the box. The row's bits outside the box
        // are made copies of their neighbours inside it, so they add no transition: those
        // before `lo` repeat the cell before the row (the last cell read, or empty before the
        // first run), those after `hi` repeat the cell at `hi`.
        let mut transitions = 0u64;
        let mut previous = 0u64;
        let (w0, w1) = (b.x0 as usize / 64, b.x1 as usize / 64);
        let (head, tail) = (u64::MAX << (b.x0 % 64), u64::MAX >> (63 - b.x1 % 64));
        let mut padded = Vec::with_capacity(w1 - w0 + 1);
        for iy in b.y0..=b.y1 {
            padded.clear();
            padded.extend_from_slice(&self.row(iy)[w0..=w1]);
            padded[0] = padded[0] & head | previous.wrapping_neg() & !head;
            let last = padded.len() - 1;
            let top = padded[last] >> (b.x1 % 64) & 1;
            padded[last] = padded[last] & tail | top.wrapping_neg() & !tail;
            let mut carry = previous;
            for &bits in &padded {
                transitions += u64::from((bits ^ (bits << 1 | carry)).count_ones());
                carry = bits >> 63;
            }
            previous = top;
        }
        transitions as usize + 1
    }

    /// Decodes a set received from a peer on `grid`; never panics on bad input. The grid size,
    /// the box and the run total are all checked before anything is allocated, and the only
    /// allocation is the set on the caller's own grid.
    pub fn decode(grid: &GroundGrid, encoded: &EncodedSet) -> Result<CellSet, SetDecodeError> {
        let mut set = CellSet::empty(grid);
        set.flip_encoded(grid, encoded)?;
        Ok(set)
    }

    /// `self ← self xor` the cells of `encoded` (on `grid`, the grid of `self`), after the
    /// same checks as [`CellSet::decode`]; `self` is untouched when they fail.
    pub(crate) fn flip_encoded(
        &mut self,
        grid: &GroundGrid,
        encoded: &EncodedSet,
    ) -> Result<(), SetDecodeError> {
        if (encoded.nx, encoded.ny) != (grid.nx, grid.ny) {
            return Err(SetDecodeError::GridMismatch {
                nx: grid.nx,
                ny: grid.ny,
                got_nx: encoded.nx,
                got_ny: encoded.ny,
            });
        }
        let total = encoded
            .runs
            .iter()
            .try_fold(0u64, |acc, &r| acc.checked_add(u64::from(r)));
        let got = total.unwrap_or(u64::MAX);
        let Some(b) = encoded.bbox else {
            if got != 0 {
                return Err(SetDecodeError::RunLength { expected: 0, got });
            }
            return Ok(());
        };
        let inside = b.x0 <= b.x1 && b.y0 <= b.y1 && b.x1 < grid.nx && b.y1 < grid.ny;
        if !inside {
            return Err(SetDecodeError::BadBox(b));
        }
        let expected = b.cell_count();
        if got != expected {
            return Err(SetDecodeError::RunLength { expected, got });
        }
        self.store_rows(b.y0, b.y1 + 1);
        let width = u64::from(b.x1 - b.x0) + 1;
        let mut pos = 0u64;
        for (i, &r) in encoded.runs.iter().enumerate() {
            let end = pos + u64::from(r);
            if i % 2 == 1 {
                self.flip_box_cells(&b, width, pos, end);
            }
            pos = end;
        }
        Ok(())
    }

    /// Flips the cells at row-major positions `from..to` of box `b` (of `width` columns).
    fn flip_box_cells(&mut self, b: &CellBox, width: u64, from: u64, to: u64) {
        let mut p = from;
        while p < to {
            let (row, col) = (p / width, p % width);
            let span = (width - col).min(to - p);
            // Positions are inside the checked box, so these fit in u32.
            let iy = b.y0 + row as u32;
            let x0 = b.x0 + col as u32;
            self.flip_row_span(iy, x0, x0 + (span - 1) as u32);
            p += span;
        }
    }
}

/// The first column in `from..end` whose bit equals `value`, or `end`.
fn next_with(row: &[u64], from: u32, end: u32, value: bool) -> u32 {
    let mut x = from;
    while x < end {
        let w = x as usize / 64;
        let word = if value { row[w] } else { !row[w] };
        let ahead = word & (u64::MAX << (x % 64));
        if ahead != 0 {
            return (w as u32 * 64 + ahead.trailing_zeros()).min(end);
        }
        x = (w as u32 + 1) * 64;
    }
    end
}

fn push_run(runs: &mut Vec<u32>, mut len: u64) {
    while len > u64::from(u32::MAX) {
        runs.push(u32::MAX);
        runs.push(0);
        len -= u64::from(u32::MAX);
    }
    // The loop leaves at most u32::MAX.
    runs.push(len as u32);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> GroundGrid {
        GroundGrid::new(50.0, 1.0)
    }

    #[test]
    fn runs_start_empty_and_cross_rows() {
        let g = grid();
        let s = CellSet::from_cells(&g, [(10, 5), (12, 5), (10, 6), (11, 6)]);
        let e = s.encode();
        assert_eq!(
            e.bbox,
            Some(CellBox {
                x0: 10,
                y0: 5,
                x1: 12,
                y1: 6
            })
        );
        // Row 5: F E F, row 6: F F E -> empty 0, full 1, empty 1, full 3 (wraps), empty 1.
        assert_eq!(e.runs, vec![0, 1, 1, 3, 1]);
        assert_eq!(CellSet::decode(&g, &e), Ok(s));
    }

    #[test]
    fn empty_and_full_sets_round_trip() {
        let g = grid();
        for s in [CellSet::empty(&g), CellSet::full(&g)] {
            assert_eq!(CellSet::decode(&g, &s.encode()).as_ref(), Ok(&s));
        }
        assert_eq!(CellSet::full(&g).encode().runs, vec![0, 10_000]);
    }

    #[test]
    fn hostile_encodings_are_refused() {
        let g = grid();
        let b = CellBox {
            x0: 0,
            y0: 0,
            x1: 1,
            y1: 1,
        };
        let e = |nx, bbox, runs: Vec<u32>| EncodedSet {
            nx,
            ny: 100,
            bbox,
            runs,
        };
        assert!(matches!(
            CellSet::decode(&g, &e(99, Some(b), vec![0, 4])),
            Err(SetDecodeError::GridMismatch { .. })
        ));
        let outside = CellBox {
            x0: 0,
            y0: 0,
            x1: 100,
            y1: 1,
        };
        assert_eq!(
            CellSet::decode(&g, &e(100, Some(outside), vec![0, 202])),
            Err(SetDecodeError::BadBox(outside))
        );
        let inverted = CellBox {
            x0: 5,
            y0: 0,
            x1: 4,
            y1: 1,
        };
        assert!(CellSet::decode(&g, &e(100, Some(inverted), vec![])).is_err());
        assert_eq!(
            CellSet::decode(&g, &e(100, Some(b), vec![u32::MAX, u32::MAX, 2])),
            Err(SetDecodeError::RunLength {
                expected: 4,
                got: 2 * u64::from(u32::MAX) + 2
            })
        );
        assert_eq!(
            CellSet::decode(&g, &e(100, None, vec![0, 1])),
            Err(SetDecodeError::RunLength {
                expected: 0,
                got: 1
            })
        );
        assert!(CellSet::decode(&g, &e(100, None, vec![0, 0])).is_ok());
    }

    #[test]
    fn long_runs_split_into_u32_pieces() {
        let mut runs = Vec::new();
        push_run(&mut runs, u64::from(u32::MAX) * 2 + 5);
        assert_eq!(runs, vec![u32::MAX, 0, u32::MAX, 0, 5]);
    }
}
