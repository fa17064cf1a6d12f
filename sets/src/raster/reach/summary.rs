//! The reach outside the window of an undetected set: one lower bound per block of
//! [`BLOCK`] x [`BLOCK`] cells over the whole grid (the module docs of [`super`], "A window
//! around the UAV", say why every operation here keeps the guarantee).

use super::{REACH_UNIT_M, UNIT_MARGIN};
use crate::grid::GroundGrid;
use crate::math::Real;
use crate::raster::CellBox;
use crate::raster::distance::GapField;

/// Cells per side of a block. A block of 8 columns is one byte of a row's word, so a window
/// stored in whole words of 64 columns and in rows rounded to blocks holds whole blocks.
pub const BLOCK: u32 = 8;

/// A lower bound of the reach of every cell of each block, for the cells outside the window.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct Summary {
    /// Blocks per row of blocks.
    nbx: u32,
    /// Rows of blocks.
    nby: u32,
    /// Per block, row-major: `τ` no cell of the block is below.
    tau: Vec<u32>,
    /// Per block: whether its cells outside the window hold every cell the clock reached by
    /// `tau` at the last advance. Cleared when the block's cells are removed, when its bound
    /// falls, and when it leaves the window; an advance fills the unsettled blocks.
    settled: Vec<bool>,
}

impl Summary {
    /// The bounds of a grid of `nx` x `ny` cells, all 0 (nothing known), none settled.
    pub(super) fn new(nx: u32, ny: u32) -> Self {
        let (nbx, nby) = (nx.div_ceil(BLOCK), ny.div_ceil(BLOCK));
        let n = nbx as usize * nby as usize;
        Self {
            nbx,
            nby,
            tau: vec![0; n],
            settled: vec![false; n],
        }
    }

    /// Blocks per row and rows of blocks.
    pub(super) fn blocks(&self) -> (u32, u32) {
        (self.nbx, self.nby)
    }

    fn at(&self, bx: u32, by: u32) -> usize {
        by as usize * self.nbx as usize + bx as usize
    }

    /// The bound of block `(bx, by)`.
    pub(super) fn tau(&self, bx: u32, by: u32) -> u32 {
        self.tau[self.at(bx, by)]
    }

    /// The bound of cell `(ix, iy)`.
    pub(super) fn tau_of_cell(&self, ix: u32, iy: u32) -> u32 {
        self.tau(ix / BLOCK, iy / BLOCK)
    }

    /// Writes the bound of cells `x0..x0 + span.len()` of row `iy` into `span`.
    pub(super) fn fill_span(&self, iy: u32, x0: u32, span: &mut [u32]) {
        let row = &self.tau[self.at(0, iy / BLOCK)..][..self.nbx as usize];
        for (ix, tau) in (x0..).zip(span.iter_mut()) {
            *tau = row[(ix / BLOCK) as usize];
        }
    }

    /// Raises the bound of block `(bx, by)` to `tau`, a lower bound of the reach of every one
    /// of its cells.
    pub(super) fn raise(&mut self, bx: u32, by: u32, tau: u32) {
        let at = self.at(bx, by);
        self.tau[at] = self.tau[at].max(tau);
    }

    /// Sets the bound of block `(bx, by)`, which leaves the window, to the larger of its own
    /// and `least`, the least reach of its cells (both are lower bounds of every cell's), and
    /// marks it unsettled: the clock may now reach cells the window's reach held out.
    pub(super) fn fold(&mut self, bx: u32, by: u32, least: u32) {
        let at = self.at(bx, by);
        self.tau[at] = self.tau[at].max(least);
        self.settled[at] = false;
    }

    /// Marks block `(bx, by)` unsettled: some of its cells left the set.
    pub(super) fn unsettle(&mut self, bx: u32, by: u32) {
        let at = self.at(bx, by);
        self.settled[at] = false;
    }

    /// Marks block `(bx, by)` settled or not after an advance filled it.
    pub(super) fn settle(&mut self, bx: u32, by: u32, settled: bool) {
        let at = self.at(bx, by);
        self.settled[at] = settled;
    }

    /// The blocks outside `inside` (whole blocks of the window) that are unsettled and
    /// whose bound the clock `reached` (reach units) has come to.
    pub(super) fn due(&self, reached: u32, inside: impl Fn(u32, u32) -> bool) -> Vec<(u32, u32)> {
        let mut due = Vec::new();
        for by in 0..self.nby {
            for bx in 0..self.nbx {
                let at = self.at(bx, by);
                if !self.settled[at] && self.tau[at] <= reached && !inside(bx, by) {
                    due.push((bx, by));
                }
            }
        }
        due
    }

    /// Raises the bounds from ground proven free at the clock `clock_m` (metres): `free_block`
    /// says, for each block of `blocks` (a box of blocks), whether every cell of the block is
    /// proven free, and `skip` names the blocks not to raise (the window's, whose cells the
    /// exact correction raised). A free block is at least the gap between its square and the
    /// nearest square of a block that is not free away from every target, and the gap
    /// between two blocks' squares is at most the gap between any cell of one and any cell of
    /// the other, so `τ ← max(τ, ⌊(gap + b) / unit⌋)` keeps (I1) for each of its cells. The
    /// blocks at the sides of `blocks` that are not at the grid's edge count as not free: they
    /// stand for every block beyond, which only lowers the bounds. Returns the blocks raised.
    pub(super) fn raise_free(
        &mut self,
        grid: &GroundGrid,
        blocks: &CellBox,
        clock_m: Real,
        free_block: impl Fn(u32, u32) -> bool,
        skip: impl Fn(u32, u32) -> bool,
        gaps: &mut GapField,
    ) -> Vec<(u32, u32)> {
        let width = (blocks.x1 - blocks.x0 + 1) as usize;
        let mut seeds = Vec::with_capacity(blocks.cell_count() as usize);
        for by in blocks.y0..=blocks.y1 {
            let edge_row = (by == blocks.y0 && by > 0) || (by == blocks.y1 && by + 1 < self.nby);
            for bx in blocks.x0..=blocks.x1 {
                let edge = edge_row
                    || (bx == blocks.x0 && bx > 0)
                    || (bx == blocks.x1 && bx + 1 < self.nbx);
                seeds.push(edge || !free_block(bx, by));
            }
        }
        let mut raised = Vec::new();
        if seeds.iter().all(|&s| s) {
            return raised;
        }
        let unit = Real::from(BLOCK) * grid.cell_m / REACH_UNIT_M;
        let clock = clock_m / REACH_UNIT_M;
        gaps.compute_rows(blocks, &seeds, |y, gap_row| {
            let by = blocks.y0 + y as u32;
            for (k, &gap2) in gap_row.iter().enumerate() {
                let bx = blocks.x0 + k as u32;
                if seeds[y * width + k] || skip(bx, by) {
                    continue;
                }
                // Truncation is the floor here (non-negative); `as` saturates, and a block no
                // seed reaches gets the largest reach.
                let tau = ((gap2 as Real).sqrt() * unit + clock - UNIT_MARGIN).max(0.0) as u32;
                self.raise(bx, by, tau.min(u32::MAX - 1));
                raised.push((bx, by));
            }
        });
        raised
    }
}
