//! Exact distances between cells: how far the closed square of each cell of a window lies from
//! the closed squares of a set of cells.
//!
//! Two closed cell squares `dx` columns and `dy` rows apart are
//! `cell_m * hypot(max(|dx| - 1, 0), max(|dy| - 1, 0))` apart. For integers,
//! `max(|t| - 1, 0)² = min over s in {-1, 0, 1} of (t - s)²`, so that distance is the Euclidean
//! distance between cell *centres* to the set grown by its 8 neighbours. The transform is
//! therefore an exact squared Euclidean distance transform (Felzenszwalb and Huttenlocher's
//! lower envelope of parabolas, one pass per column then one per row) of the 3x3-grown set,
//! in integer arithmetic: no rounding can make a distance longer than it is.

use super::CellBox;

/// Squared distance, in cells², of a cell no seed reaches.
pub const UNREACHED: u64 = u64::MAX;

/// For every cell of `window`, the squared distance in cell units between its closed square
/// and the closed square of the nearest seed cell of the window; [`UNREACHED`] when the window
/// has no seed. `seeds` and the result are row-major over the window.
///
/// # Panics
/// When `seeds` does not hold one flag per cell of the window (a caller's bug).
pub fn square_gap_field(window: &CellBox, seeds: &[bool]) -> Vec<u64> {
    GapField::default().compute(window, seeds).to_vec()
}

/// [`square_gap_field`] with its buffers kept between calls: a caller that transforms a
/// window per frame allocates (and the kernel zeroes) nothing after the first.
#[derive(Debug, Default)]
pub struct GapField {
    /// The current row of seeds grown by their horizontal neighbours.
    across: Vec<bool>,
    /// Vertical distances, row-major over the window.
    vertical: Vec<u32>,
    /// The result, row-major over the window ([`GapField::compute`]).
    out: Vec<u64>,
    /// One row of the result ([`GapField::compute_rows`]).
    row: Vec<u64>,
    envelope: Envelope,
}

impl GapField {
    /// [`square_gap_field`] of `window` and `seeds`, in this scratch's buffer.
    ///
    /// # Panics
    /// When `seeds` does not hold one flag per cell of the window (a caller's bug).
    pub fn compute(&mut self, window: &CellBox, seeds: &[bool]) -> &[u64] {
        let mut out = std::mem::take(&mut self.out);
        out.clear();
        self.compute_rows(window, seeds, |_, row| out.extend_from_slice(row));
        self.out = out;
        &self.out
    }

    /// [`GapField::compute`] handed out a row at a time, from the window's first row to its
    /// last, as `(row index in the window, the row's squared gaps)`: a caller that uses each
    /// row once reads it while it is still in the cache, and no field of the whole window is
    /// written.
    ///
    /// # Panics
    /// When `seeds` does not hold one flag per cell of the window (a caller's bug).
    pub fn compute_rows(
        &mut self,
        window: &CellBox,
        seeds: &[bool],
        mut row: impl FnMut(usize, &[u64]),
    ) {
        let w = (window.x1 - window.x0 + 1) as usize;
        let h = (window.y1 - window.y0 + 1) as usize;
        assert_eq!(seeds.len(), w * h, "one seed flag per cell of the window");
        // Vertical distance to the nearest seed grown by its horizontal neighbours (inside the
        // window) in the same column, in cells: the distance `d` to the nearest grown cell,
        // down the window then up it, is `d - 1` (0 at most) to that cell grown by its
        // vertical neighbours, which lie between the two rows and so in the window. A column
        // without seeds keeps values of at least `far`.
        let far = u32::MAX / 4;
        self.across.clear();
        self.across.resize(w, false);
        self.vertical.clear();
        self.vertical.resize(w * h, far);
        for (y, src) in seeds.chunks_exact(w).enumerate() {
            // Each seed grown by its horizontal neighbours, in loops the compiler vectorises.
            let across = &mut self.across[..];
            across.copy_from_slice(src);
            for x in 1..w {
                across[x] |= src[x - 1];
            }
            for x in 0..w - 1 {
                across[x] |= src[x + 1];
            }
            let (done, rest) = self.vertical.split_at_mut(y * w);
            let row = &mut rest[..w];
            match y.checked_sub(1) {
                None => {
                    for (v, &a) in row.iter_mut().zip(across.iter()) {
                        *v = if a { 0 } else { far };
                    }
                }
                Some(up) => {
                    // Values stay below `far + h`, far from overflowing.
                    let above = &done[up * w..];
                    for ((v, &a), &u) in row.iter_mut().zip(across.iter()).zip(above) {
                        *v = if a { 0 } else { u + 1 };
                    }
                }
            }
        }
        for y in (0..h.saturating_sub(1)).rev() {
            let (head, below) = self.vertical.split_at_mut((y + 1) * w);
            let row = &mut head[y * w..];
            for (v, &b) in row.iter_mut().zip(&below[..w]) {
                *v = (*v).min(b + 1);
            }
        }
        for v in &mut self.vertical {
            *v -= u32::from(*v < far && *v > 0);
        }

        // Along each row, the lower envelope of the parabolas (x - x')² + vertical(x')², over
        // the span from the cell before the row's first cell that is not a seed to the one
        // after its last: the cells outside it are seeds (gap 0), and a seed at the span's
        // end has the parabola (x - x')², below that of every column beyond it at every cell
        // of the span, so those columns change nothing.
        self.row.clear();
        self.row.resize(w, UNREACHED);
        for (y, (g, src)) in self
            .vertical
            .chunks_exact(w)
            .zip(seeds.chunks_exact(w))
            .enumerate()
        {
            match (src.iter().position(|s| !s), src.iter().rposition(|s| !s)) {
                (Some(first), Some(last)) => {
                    let (lo, hi) = (first.saturating_sub(1), (last + 1).min(w - 1));
                    self.row[..lo].fill(0);
                    self.envelope
                        .lower(&g[lo..=hi], far, &mut self.row[lo..=hi]);
                    self.row[hi + 1..].fill(0);
                }
                _ => self.row.fill(0),
            }
            row(y, &self.row);
        }
    }
}

/// Scratch space of the one-dimensional transform.
#[derive(Debug, Default)]
struct Envelope {
    /// The parabolas of the envelope, left to right.
    parabolas: Vec<Parabola>,
}

/// One parabola `(x - apex)² + g(apex)²` of an envelope.
#[derive(Clone, Copy, Debug)]
struct Parabola {
    apex: i64,
    /// `g(apex)² + apex²`: the parabola is `x² - 2 apex x + level`.
    level: i64,
    /// Where it starts to be the lowest, as the fraction `num / den` (`den > 0`).
    from: (i64, i64),
}

impl Envelope {
    /// `out[x] = min over x' with g[x'] < far of (x - x')² + g[x']²`; [`UNREACHED`] when every
    /// `g` is `far`. Windows are at most a few thousand cells wide, so every product below
    /// stays far inside `i64`.
    fn lower(&mut self, g: &[u32], far: u32, out: &mut [u64]) {
        let envelope = &mut self.parabolas;
        envelope.clear();
        for (q, &gq) in g.iter().enumerate() {
            if gq >= far {
                continue;
            }
            let qi = q as i64;
            let level = i64::from(gq) * i64::from(gq) + qi * qi;
            // Where the parabola at q undercuts the one at p: s = (level(q) - level(p)) /
            // (2 (q - p)), kept as an exact fraction.
            let meets = |p: &Parabola| (level - p.level, 2 * (qi - p.apex));
            while let [.., _, last] = envelope.as_slice() {
                let s = meets(last);
                // s <= start, both with positive denominators.
                if s.0 * last.from.1 <= last.from.0 * s.1 {
                    envelope.pop();
                } else {
                    break;
                }
            }
            // The first parabola starts at minus infinity; its fraction is never read.
            let from = envelope.last().map_or((0, 1), meets);
            envelope.push(Parabola {
                apex: qi,
                level,
                from,
            });
        }
        if envelope.is_empty() {
            out.fill(UNREACHED);
            return;
        }
        // Each parabola is the lowest (or tied) from its start on, up to the next one's start;
        // at a whole `x` that is from the ceiling of its start. A parabola whose span holds no
        // whole `x` is skipped: the next one is at or below it there.
        let len = out.len() as i64;
        let mut x = 0;
        for (k, p) in envelope.iter().enumerate() {
            let end = envelope.get(k + 1).map_or(len, |next| {
                let (num, den) = next.from;
                (-(-num).div_euclid(den)).clamp(0, len)
            });
            let g2 = (p.level - p.apex * p.apex) as u64;
            while x < end {
                let d = x.abs_diff(p.apex);
                out[x as usize] = d * d + g2;
                x += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    fn mask(window: &CellBox, seeds: &[(u32, u32)]) -> Vec<bool> {
        let mut out = Vec::new();
        for y in window.y0..=window.y1 {
            for x in window.x0..=window.x1 {
                out.push(seeds.contains(&(x, y)));
            }
        }
        out
    }

    /// The definition: the least squared gap between closed squares over every seed.
    fn brute(window: &CellBox, seeds: &[(u32, u32)]) -> Vec<u64> {
        let mut out = Vec::new();
        for y in window.y0..=window.y1 {
            for x in window.x0..=window.x1 {
                let best = seeds
                    .iter()
                    .map(|&(sx, sy)| {
                        let gx = u64::from(x.abs_diff(sx).saturating_sub(1));
                        let gy = u64::from(y.abs_diff(sy).saturating_sub(1));
                        gx * gx + gy * gy
                    })
                    .min()
                    .unwrap_or(UNREACHED);
                out.push(best);
            }
        }
        out
    }

    #[test]
    fn gaps_between_squares() {
        let window = CellBox {
            x0: 10,
            y0: 20,
            x1: 19,
            y1: 27,
        };
        let f = square_gap_field(&window, &mask(&window, &[(12, 21)]));
        let at = |x: u32, y: u32| f[((y - 20) * 10 + (x - 10)) as usize];
        assert_eq!(at(12, 21), 0);
        assert_eq!(at(13, 22), 0, "touching diagonally");
        assert_eq!(at(14, 21), 1, "one cell between");
        assert_eq!(at(15, 23), 2 * 2 + 1);
        assert_eq!(f, brute(&window, &[(12, 21)]));
        assert!(
            square_gap_field(&window, &mask(&window, &[]))
                .iter()
                .all(|&v| v == UNREACHED)
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(96))]

        #[test]
        fn matches_the_definition(
            x0 in 0u32..50, y0 in 0u32..50, w in 1u32..40, h in 1u32..40,
            seeds in proptest::collection::vec((0u32..40, 0u32..40), 0..12),
        ) {
            let window = CellBox { x0, y0, x1: x0 + w - 1, y1: y0 + h - 1 };
            let seeds: Vec<(u32, u32)> = seeds
                .into_iter()
                .filter(|&(x, y)| x < w && y < h)
                .map(|(x, y)| (x0 + x, y0 + y))
                .collect();
            let f = square_gap_field(&window, &mask(&window, &seeds));
            prop_assert_eq!(f, brute(&window, &seeds));
        }

        /// Dense and sparse seeds on wide windows: many parabolas per row, ties between them,
        /// rows of seeds only, with one seed or none, and one scratch reused across windows of
        /// every shape.
        #[test]
        fn matches_the_definition_with_many_seeds(
            windows in proptest::collection::vec(
                (1u32..90, 1u32..24, 0.0f64..1.0, proptest::collection::vec(0.0f64..1.0, 90 * 24)),
                1..4,
            ),
        ) {
            let mut field = GapField::default();
            for (w, h, density, draws) in windows {
                let window = CellBox { x0: 3, y0: 5, x1: 3 + w - 1, y1: 5 + h - 1 };
                let seeds: Vec<(u32, u32)> = (0..w * h)
                    .filter(|&i| draws[i as usize] < density)
                    .map(|i| (3 + i % w, 5 + i / w))
                    .collect();
                let flags = mask(&window, &seeds);
                let expected = brute(&window, &seeds);
                prop_assert_eq!(field.compute(&window, &flags), expected.as_slice());
            }
        }
    }
}
