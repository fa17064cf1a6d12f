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
    /// The result, row-major over the window.
    out: Vec<u64>,
    envelope: Envelope,
}

impl GapField {
    /// [`square_gap_field`] of `window` and `seeds`, in this scratch's buffer.
    ///
    /// # Panics
    /// When `seeds` does not hold one flag per cell of the window (a caller's bug).
    pub fn compute(&mut self, window: &CellBox, seeds: &[bool]) -> &[u64] {
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
            for x in 0..w {
                self.across[x] = src[x] || (x > 0 && src[x - 1]) || (x + 1 < w && src[x + 1]);
            }
            let (done, rest) = self.vertical.split_at_mut(y * w);
            let row = &mut rest[..w];
            let above = done.get(done.len().saturating_sub(w)..).filter(|_| y > 0);
            for x in 0..w {
                row[x] = if self.across[x] {
                    0
                } else {
                    above.map_or(far, |a| a[x].saturating_add(1))
                };
            }
        }
        for y in (0..h.saturating_sub(1)).rev() {
            let (head, below) = self.vertical.split_at_mut((y + 1) * w);
            let row = &mut head[y * w..];
            for (v, b) in row.iter_mut().zip(&below[..w]) {
                *v = (*v).min(b.saturating_add(1));
            }
        }
        for v in &mut self.vertical {
            if *v < far {
                *v = v.saturating_sub(1);
            }
        }

        // Along each row, the lower envelope of the parabolas (x - x')² + vertical(x')².
        self.out.clear();
        self.out.resize(w * h, UNREACHED);
        for (g, out) in self
            .vertical
            .chunks_exact(w)
            .zip(self.out.chunks_exact_mut(w))
        {
            self.envelope.lower(g, far, out);
        }
        &self.out
    }
}

/// Scratch space of the one-dimensional transform.
#[derive(Debug, Default)]
struct Envelope {
    /// Apexes of the parabolas of the envelope.
    apex: Vec<usize>,
    /// Where each parabola starts to be the lowest, as the fraction `num / den` (`den > 0`).
    from: Vec<(i64, i64)>,
}

impl Envelope {
    /// `out[x] = min over x' with g[x'] < far of (x - x')² + g[x']²`; [`UNREACHED`] when every
    /// `g` is `far`. Windows are at most a few thousand cells wide, so every product below
    /// stays far inside `i64`.
    fn lower(&mut self, g: &[u32], far: u32, out: &mut [u64]) {
        self.apex.clear();
        self.from.clear();
        let value = |q: usize| i64::from(g[q]) * i64::from(g[q]);
        for (q, &gq) in g.iter().enumerate() {
            if gq >= far {
                continue;
            }
            // Where the parabola at q undercuts the one at p: s = (f(q) + q² - f(p) - p²) /
            // (2 (q - p)), kept as an exact fraction.
            let meets = |p: usize| {
                let (qi, pi) = (q as i64, p as i64);
                (value(q) + qi * qi - value(p) - pi * pi, 2 * (qi - pi))
            };
            while self.apex.len() > 1 {
                let s = meets(self.apex[self.apex.len() - 1]);
                let start = self.from[self.from.len() - 1];
                // s <= start, both with positive denominators.
                if s.0 * start.1 <= start.0 * s.1 {
                    self.apex.pop();
                    self.from.pop();
                } else {
                    break;
                }
            }
            // The first parabola starts at minus infinity; its fraction is never read.
            let start = self.apex.last().map_or((0, 1), |&p| meets(p));
            self.apex.push(q);
            self.from.push(start);
        }
        if self.apex.is_empty() {
            out.fill(UNREACHED);
            return;
        }
        let mut k = 0;
        for (x, o) in out.iter_mut().enumerate() {
            // Move to the last parabola that starts at or before x.
            while k + 1 < self.apex.len() && self.from[k + 1].0 <= x as i64 * self.from[k + 1].1 {
                k += 1;
            }
            let p = self.apex[k];
            let d = x.abs_diff(p) as u64;
            *o = d * d + u64::from(g[p]) * u64::from(g[p]);
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
    }
}
