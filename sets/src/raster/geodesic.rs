//! Lower bounds of how far a car must drive, around ground it cannot enter, from a set of
//! cells to each cell of a window: the geodesic counterpart of [`super::distance`].
//!
//! # The bound
//! Cars never enter the *blocked* cells (ground proven within `r_s` of an obstacle, `S^o`):
//! no car is ever in a blocked cell's closed square. Any car path therefore lies in
//! `Ω = window \ interior(∪ blocked squares)`, a closed domain bounded by grid lines, whose
//! shortest paths are polylines bending only at grid vertices (the domain's reflex corners).
//!
//! On the grid vertices of the window take the graph whose edges are
//! - the axis edge between two neighbouring vertices, weight [`AXIS`], unless both cells
//!   beside it are blocked;
//! - the diagonal edge across a cell, weight [`DIAGONAL`], unless the cell is blocked.
//!
//! Every straight segment of `Ω` between two vertices `(dx, dy)` apart (`|dx| ≥ |dy|`) has a
//! staircase of that graph (Bresenham's: one step per column, diagonal where the segment's row
//! changes) that only crosses cells the segment crosses and only runs along edges the segment
//! runs along or beside an unblocked cell it crosses, so all its edges exist. Its weight is
//! `AXIS |dx| + (DIAGONAL - AXIS) |dy| ≤ AXIS · κ · hypot(dx, dy)` with
//! `κ = hypot(1, (DIAGONAL - AXIS) / AXIS)` (Cauchy–Schwarz). Hence the graph distance `D`
//! between two vertices is at most `AXIS · κ` times their distance in `Ω`.
//!
//! A car in the closed square of a seed cell and a point of cell `c`'s square are each within
//! half a cell diagonal of a corner of their squares, and both squares lie in `Ω` (neither
//! cell is blocked), so the car's path to `c` is at least
//! `min over c's corners of D / (AXIS κ) - √2` cells long, the multi-source graph distance
//! taken from every corner of every seed cell. [`geodesic_gap_field`] returns that `D`;
//! [`gap_cells`] turns it into the bound.
//!
//! The distances are exact integers, found by forward and backward raster sweeps repeated
//! until nothing changes (a fixed point of the sweeps is the graph's shortest distances: every
//! value is a path's weight and no edge can shorten it). Sweeps that have not settled would
//! give values that are too large, so a window that does not settle within [`MAX_SWEEPS`]
//! gives no field at all.

use super::CellBox;

/// Weight of an axis edge (one cell side).
pub const AXIS: u32 = 5;
/// Weight of a diagonal edge (one cell diagonal, `7/5` of a side: any weight would do, the
/// bound divides by its own `κ`).
pub const DIAGONAL: u32 = 7;
/// Forward and backward sweep pairs tried before giving up.
pub const MAX_SWEEPS: usize = 12;

/// Graph distance of a vertex no seed reaches.
pub const UNREACHED: u32 = u32::MAX;

/// `κ`: the largest ratio of a staircase's weight, in [`AXIS`] units, to the straight length.
fn kappa() -> f64 {
    let slope = f64::from(DIAGONAL - AXIS) / f64::from(AXIS);
    1.0f64.hypot(slope)
}

/// The lower bound, in cells, of the path from a seed cell's square to the square of a cell
/// whose field value is `d`; `None` when no seed reaches the cell (no car can get there
/// without leaving the window through a seed).
pub fn gap_cells(d: u32) -> Option<f64> {
    if d == UNREACHED {
        return None;
    }
    // The relative margin covers the rounding of the division (far below a reach unit).
    let straight = f64::from(d) / (f64::from(AXIS) * kappa()) * (1.0 - 1e-12);
    Some((straight - std::f64::consts::SQRT_2).max(0.0))
}

/// For every cell of `window`, row-major, the least graph distance (see the module docs) from
/// a corner of a source cell to a corner of the cell; [`UNREACHED`] where no source reaches.
/// `sources` flags the seed cells a car may be in (never blocked ones), `blocked` the cells no
/// car enters, both row-major over the window. `None` when the sweeps did not settle.
///
/// # Panics
/// When `sources` or `blocked` does not hold one flag per cell of the window (a caller's bug).
pub fn geodesic_gap_field(
    window: &CellBox,
    sources: &[bool],
    blocked: &[bool],
) -> Option<Vec<u32>> {
    let w = (window.x1 - window.x0 + 1) as usize;
    let h = (window.y1 - window.y0 + 1) as usize;
    assert_eq!(
        sources.len(),
        w * h,
        "one source flag per cell of the window"
    );
    assert_eq!(
        blocked.len(),
        w * h,
        "one blocked flag per cell of the window"
    );
    let graph = Graph::new(w, h, blocked);
    let mut dist = vec![UNREACHED; graph.vw * (h + 1)];
    for (k, _) in sources.iter().enumerate().filter(|(_, s)| **s) {
        for v in graph.corners(k) {
            dist[v] = 0;
        }
    }
    let settled = (0..MAX_SWEEPS).any(|_| {
        let forward = graph.sweep_forward(&mut dist);
        let backward = graph.sweep_backward(&mut dist);
        !forward && !backward
    });
    if !settled {
        return None;
    }
    let mut field = vec![UNREACHED; w * h];
    for (k, out) in field.iter_mut().enumerate() {
        *out = graph
            .corners(k)
            .map(|v| dist[v])
            .into_iter()
            .min()
            .unwrap_or(UNREACHED);
    }
    Some(field)
}

/// The vertex graph of a window: `(w + 1) x (h + 1)` vertices, vertex `(x, y)` the lower-left
/// corner of the window's cell `(x, y)`.
struct Graph {
    /// Vertices per row, `w + 1`.
    vw: usize,
    /// Vertex rows, `h + 1`.
    vh: usize,
    /// Per vertex: whether the diagonal edges towards the cells to its upper right and upper
    /// left exist, and whether the axis edges to its right and up exist.
    edges: Vec<u8>,
}

const UP_RIGHT: u8 = 1;
const UP_LEFT: u8 = 2;
const RIGHT: u8 = 4;
const UP: u8 = 8;

impl Graph {
    fn new(w: usize, h: usize, blocked: &[bool]) -> Self {
        let (vw, vh) = (w + 1, h + 1);
        // Cells outside the window count as not blocked: more edges only lower the bound.
        let cell = |x: isize, y: isize| {
            x >= 0
                && y >= 0
                && (x as usize) < w
                && (y as usize) < h
                && blocked[y as usize * w + x as usize]
        };
        let mut edges = vec![0u8; vw * vh];
        for y in 0..vh {
            for x in 0..vw {
                let (cx, cy) = (x as isize, y as isize);
                let mut e = 0;
                if x < w && y < h && !cell(cx, cy) {
                    e |= UP_RIGHT;
                }
                if x > 0 && y < h && !cell(cx - 1, cy) {
                    e |= UP_LEFT;
                }
                // The edge to the right runs between the cells below and above it.
                if x < w && !(cell(cx, cy - 1) && cell(cx, cy)) {
                    e |= RIGHT;
                }
                // The edge up runs between the cells to its left and right.
                if y < h && !(cell(cx - 1, cy) && cell(cx, cy)) {
                    e |= UP;
                }
                edges[y * vw + x] = e;
            }
        }
        Self { vw, vh, edges }
    }

    /// The vertices at the corners of the window's cell `k` (row-major).
    fn corners(&self, k: usize) -> [usize; 4] {
        let (x, y) = (k % (self.vw - 1), k / (self.vw - 1));
        let v = y * self.vw + x;
        [v, v + 1, v + self.vw, v + self.vw + 1]
    }

    /// Relaxes every vertex from its left, lower-left, lower and lower-right neighbours, in
    /// row-major order; whether anything changed.
    fn sweep_forward(&self, dist: &mut [u32]) -> bool {
        let vw = self.vw;
        let mut changed = false;
        for y in 0..self.vh {
            for x in 0..vw {
                let v = y * vw + x;
                let mut best = dist[v];
                if x > 0 && self.edges[v - 1] & RIGHT != 0 {
                    best = best.min(dist[v - 1].saturating_add(AXIS));
                }
                if y > 0 {
                    let below = v - vw;
                    if self.edges[below] & UP != 0 {
                        best = best.min(dist[below].saturating_add(AXIS));
                    }
                    if x > 0 && self.edges[below - 1] & UP_RIGHT != 0 {
                        best = best.min(dist[below - 1].saturating_add(DIAGONAL));
                    }
                    if x + 1 < vw && self.edges[below + 1] & UP_LEFT != 0 {
                        best = best.min(dist[below + 1].saturating_add(DIAGONAL));
                    }
                }
                if best < dist[v] {
                    dist[v] = best;
                    changed = true;
                }
            }
        }
        changed
    }

    /// Relaxes every vertex from its right, upper-right, upper and upper-left neighbours, in
    /// reverse row-major order; whether anything changed.
    fn sweep_backward(&self, dist: &mut [u32]) -> bool {
        let vw = self.vw;
        let mut changed = false;
        for y in (0..self.vh).rev() {
            for x in (0..vw).rev() {
                let v = y * vw + x;
                let e = self.edges[v];
                let mut best = dist[v];
                if x + 1 < vw && e & RIGHT != 0 {
                    best = best.min(dist[v + 1].saturating_add(AXIS));
                }
                if y + 1 < self.vh {
                    let above = v + vw;
                    if e & UP != 0 {
                        best = best.min(dist[above].saturating_add(AXIS));
                    }
                    if e & UP_RIGHT != 0 {
                        best = best.min(dist[above + 1].saturating_add(DIAGONAL));
                    }
                    if e & UP_LEFT != 0 {
                        best = best.min(dist[above - 1].saturating_add(DIAGONAL));
                    }
                }
                if best < dist[v] {
                    dist[v] = best;
                    changed = true;
                }
            }
        }
        changed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn window(w: u32, h: u32) -> CellBox {
        CellBox {
            x0: 0,
            y0: 0,
            x1: w - 1,
            y1: h - 1,
        }
    }

    /// Dijkstra on the same graph, the reference for the sweeps.
    fn dijkstra(w: usize, h: usize, sources: &[bool], blocked: &[bool]) -> Vec<u32> {
        use std::cmp::Reverse;
        use std::collections::BinaryHeap;
        let g = Graph::new(w, h, blocked);
        let mut dist = vec![UNREACHED; g.vw * g.vh];
        let mut heap = BinaryHeap::new();
        for (k, _) in sources.iter().enumerate().filter(|(_, s)| **s) {
            for v in g.corners(k) {
                dist[v] = 0;
                heap.push(Reverse((0, v)));
            }
        }
        while let Some(Reverse((d, v))) = heap.pop() {
            if d > dist[v] {
                continue;
            }
            let (x, y) = (v % g.vw, v / g.vw);
            let mut next = Vec::new();
            let e = g.edges[v];
            if e & RIGHT != 0 {
                next.push((v + 1, AXIS));
            }
            if e & UP != 0 {
                next.push((v + g.vw, AXIS));
            }
            if e & UP_RIGHT != 0 {
                next.push((v + g.vw + 1, DIAGONAL));
            }
            if e & UP_LEFT != 0 {
                next.push((v + g.vw - 1, DIAGONAL));
            }
            if x > 0 && g.edges[v - 1] & RIGHT != 0 {
                next.push((v - 1, AXIS));
            }
            if y > 0 {
                let b = v - g.vw;
                if g.edges[b] & UP != 0 {
                    next.push((b, AXIS));
                }
                if x > 0 && g.edges[b - 1] & UP_RIGHT != 0 {
                    next.push((b - 1, DIAGONAL));
                }
                if x + 1 < g.vw && g.edges[b + 1] & UP_LEFT != 0 {
                    next.push((b + 1, DIAGONAL));
                }
            }
            for (u, wgt) in next {
                let nd = d + wgt;
                if nd < dist[u] {
                    dist[u] = nd;
                    heap.push(Reverse((nd, u)));
                }
            }
        }
        dist
    }

    proptest::proptest! {
        #[test]
        fn the_sweeps_find_the_shortest_distances(
            w in 1usize..14,
            h in 1usize..14,
            bits in proptest::collection::vec(0u8..8, 196),
        ) {
            let n = w * h;
            let sources: Vec<bool> = bits[..n].iter().map(|b| *b == 0).collect();
            let blocked: Vec<bool> = bits[..n].iter().map(|b| *b >= 5).collect();
            let field = geodesic_gap_field(&window(w as u32, h as u32), &sources, &blocked)
                .expect("small windows settle");
            let dist = dijkstra(w, h, &sources, &blocked);
            for (k, d) in field.iter().enumerate() {
                let v = (k / w) * (w + 1) + k % w;
                let want = dist[v].min(dist[v + 1]).min(dist[v + w + 1]).min(dist[v + w + 2]);
                proptest::prop_assert_eq!(*d, want, "cell {}", k);
            }
        }
    }

    #[test]
    fn a_wall_makes_the_way_round_longer_than_the_straight_line() {
        // 20 x 20 cells, a source at (10, 1), a wall across rows 5..=6 from x = 2 to x = 17.
        let (w, h) = (20usize, 20usize);
        let mut sources = vec![false; w * h];
        sources[w + 10] = true;
        let mut blocked = vec![false; w * h];
        for y in 5..=6 {
            for x in 2..=17 {
                blocked[y * w + x] = true;
            }
        }
        let field = geodesic_gap_field(&window(20, 20), &sources, &blocked).unwrap();
        // Straight through the wall the gap from (10, 1) to (10, 10) is 8 cells; around it at
        // least 8 cells sideways to x = 18, then up and back.
        let behind = gap_cells(field[10 * w + 10]).unwrap();
        assert!(behind > 15.0, "{behind}");
        // The same cell with no wall: the bound stays below the straight gap.
        let open = geodesic_gap_field(&window(20, 20), &sources, &vec![false; w * h]).unwrap();
        let straight = gap_cells(open[10 * w + 10]).unwrap();
        assert!(straight <= 8.0 && straight > 5.0, "{straight}");
        // A cell walled in on every side is reached by nothing.
        let mut boxed = vec![false; w * h];
        for y in 12..=16 {
            for x in 12..=16 {
                boxed[y * w + x] = !(y == 14 && x == 14);
            }
        }
        let field = geodesic_gap_field(&window(20, 20), &sources, &boxed).unwrap();
        assert_eq!(field[14 * w + 14], UNREACHED);
        assert_eq!(gap_cells(UNREACHED), None);
    }
}
