//! Prediction: every target moves at most `v_max`, so after `dt` it is within `v_max * dt` of
//! where it could be (docs/design.md §3, estimator step 1).
//!
//! The estimator's own sets are [`ReachSet`]s, which grow by exactly that motion
//! ([`advance`]); sets received from peers are plain rasters, dilated whole-cell by [`grow`].

use std::borrow::Cow;

use sets::grid::GroundGrid;
use sets::math::Real;
use sets::raster::{CellSet, ReachSet};

/// Moves `set` to the motion clock `clock_m` (`v_max` times the time of the frame) and keeps
/// it inside the whole-cell dilation of its previous cells by `radius_m`, the motion since
/// then. Both hold the targets, so their intersection does: the reach brings the exact growth
/// of what this UAV observed, the dilation keeps what fusion with peers removed from growing
/// back faster than the targets can move.
///
/// The dilation is read only in the words the clock adds cells to ([`ReachSet::advance_within`]
/// with a [`sets::raster::WordDilation`]): the same sets as dilating the whole grid, at the
/// cost of the few words where the set grows; words no cell of the set is near are not read.
pub fn advance(set: &mut ReachSet, grid: &GroundGrid, clock_m: Real, radius_m: Real) {
    // The cases of `grow`: its result, word by word.
    if radius_m.is_nan() || radius_m <= 0.0 || set.is_empty() {
        set.advance_within(clock_m, |old: &CellSet, iy, w| old.row(iy)[w]);
        return;
    }
    let diagonal = grid.cell_m * (grid.nx as Real).hypot(grid.ny as Real);
    if radius_m >= diagonal {
        set.advance(clock_m);
        return;
    }
    let dilation = set.cells().word_dilation_within(grid, radius_m, set.rows());
    set.advance_within(clock_m, dilation);
}

/// Outer set grown by the motion over `radius_m` metres: every point within `radius_m` of the
/// set is in the result. A radius past the grid's diagonal gives the whole grid (the dilation
/// would anyway) without the work; a zero or invalid radius changes nothing.
pub fn grow<'a>(set: &'a CellSet, grid: &GroundGrid, radius_m: Real) -> Cow<'a, CellSet> {
    if radius_m.is_nan() || radius_m <= 0.0 || set.is_empty() {
        return Cow::Borrowed(set);
    }
    let diagonal = grid.cell_m * (grid.nx as Real).hypot(grid.ny as Real);
    if radius_m >= diagonal {
        return Cow::Owned(CellSet::full(grid));
    }
    Cow::Owned(set.dilate(grid, radius_m))
}

/// The radius targets may cover in `steps` frames of `period_s` at `max_speed_mps`.
pub fn motion_radius(steps: u64, period_s: Real, max_speed_mps: Real) -> Real {
    steps as Real * period_s * max_speed_mps
}
