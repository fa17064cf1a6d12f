//! The guarantee and the growth of [`ReachSet`], checked against continuous geometry.
//!
//! The reference is the exact set of possible target positions, sampled: 3 x 3 points per
//! cell, strictly inside it. Prediction keeps every sample within the step's motion of a
//! possible sample, a proven-free cell removes the samples in its square, a measurement keeps
//! the samples in its cells. Every sample the reference holds is a position some target can
//! really be at, so a sample outside the set's cells is a broken guarantee.

mod common;

use common::{box_set, cell_box};
use proptest::prelude::*;
use sets::grid::{CellIndex, GroundGrid};
use sets::math::Point2;
use sets::raster::{CellBox, CellSet, REACH_UNIT_M, ReachSet};

const SAMPLES: u32 = 3;

fn grid() -> GroundGrid {
    GroundGrid::new(6.0, 0.5) // 24 x 24 cells
}

/// Sample points, `n x n` a cell, row-major, with the cell holding each.
fn samples(g: &GroundGrid, n: u32) -> Vec<(Point2, CellIndex)> {
    let mut out = Vec::new();
    for iy in 0..g.ny {
        for ix in 0..g.nx {
            let r = g.cell_rect((ix, iy));
            for sy in 0..n {
                for sx in 0..n {
                    let fx = (f64::from(sx) + 0.5) / f64::from(n);
                    let fy = (f64::from(sy) + 0.5) / f64::from(n);
                    let p = Point2::new(
                        r.min.x + fx * (r.max.x - r.min.x),
                        r.min.y + fy * (r.max.y - r.min.y),
                    );
                    out.push((p, (ix, iy)));
                }
            }
        }
    }
    out
}

/// The sampled positions possible after the targets move at most `r` from the `possible`
/// ones (a possible position stays possible: it may stand still). Samples are looked up by
/// cell, so that each looks only at the cells within the motion.
fn moved(g: &GroundGrid, pts: &[(Point2, CellIndex)], possible: &[bool], r: f64) -> Vec<bool> {
    let mut by_cell: Vec<Vec<Point2>> = vec![Vec::new(); (g.nx * g.ny) as usize];
    for ((p, (ix, iy)), k) in pts.iter().zip(possible) {
        if *k {
            by_cell[(iy * g.nx + ix) as usize].push(*p);
        }
    }
    let span = (r / g.cell_m).ceil() as i64 + 1;
    pts.iter()
        .map(|(p, (ix, iy))| {
            (-span..=span).any(|dy| {
                (-span..=span).any(|dx| {
                    let (x, y) = (i64::from(*ix) + dx, i64::from(*iy) + dy);
                    if x < 0 || y < 0 || x >= i64::from(g.nx) || y >= i64::from(g.ny) {
                        return false;
                    }
                    by_cell[(y * i64::from(g.nx) + x) as usize]
                        .iter()
                        .any(|q| (p - q).norm() <= r)
                })
            })
        })
        .collect()
}

/// One event of the random histories.
#[derive(Clone, Debug)]
enum Event {
    /// The targets move at most this far.
    Move(f64),
    /// A rectangle of cells is proven free.
    Free(CellBox),
    /// The target is measured inside a rectangle of cells.
    Measure(CellBox),
    /// The set is saved as its cells and restored ([`ReachSet::from_cells_at`]).
    Restore,
    /// The target is measured inside a rectangle of cells, and the set is replaced by its
    /// copy met with the measurement ([`ReachSet::restricted_copy`], as a target's set is
    /// first made from `X̄`).
    Learn(CellBox),
    /// The reach is bounded by the set's box ([`ReachSet::bound_by_box`]).
    Bound,
    /// The set keeps its reach over this rectangle only, with a summary of lower bounds
    /// elsewhere ([`ReachSet::set_window`]; nothing for a set not kept over a window).
    Window(CellBox),
}

/// The grid of the test across words: 136 columns (two whole words and 8 cells), 12 rows.
const WIDE: (u32, u32) = (136, 12);

/// The grid of the window tests: 136 columns and 48 rows, six blocks of rows
/// ([`sets::raster::reach::SUMMARY_BLOCK`]), room for proven-free boxes that hold blocks
/// away from every block that is not free.
const ROOMY: (u32, u32) = (136, 48);

impl Event {
    /// The event for a wide grid of `ny` rows: its box's rows folded into them, its motion
    /// four times longer (so that a set crosses words within a history).
    fn within_rows(self, ny: u32) -> Self {
        let fold = |b: CellBox| {
            let y0 = b.y0 % ny;
            CellBox {
                y0,
                y1: (y0 + (b.y1 - b.y0)).min(ny - 1),
                ..b
            }
        };
        match self {
            Event::Free(b) => Event::Free(fold(b)),
            Event::Measure(b) => Event::Measure(fold(b)),
            Event::Learn(b) => Event::Learn(fold(b)),
            Event::Window(b) => Event::Window(fold(b)),
            Event::Move(r) => Event::Move(4.0 * r),
            other => other,
        }
    }
}

/// Cells around its box a learned set stores its reach over ([`Event::Learn`]).
const LEARN_MARGIN: u32 = 3;

/// Applies `e` to `set` as the estimator would: motion within the whole-cell dilation.
fn apply(g: &GroundGrid, set: &mut ReachSet, e: &Event, clock: &mut f64) {
    match e {
        Event::Move(r) => {
            *clock += r;
            set.advance_within(*clock, set.cells().word_dilation(g, *r));
        }
        Event::Free(b) => set.clear(g, &box_set(g, b), b),
        Event::Measure(b) => set.restrict(g, &box_set(g, b), 8),
        Event::Restore => *set = ReachSet::from_cells_at(g, set.cells().clone(), *clock),
        Event::Learn(b) => *set = set.restricted_copy(g, &box_set(g, b), LEARN_MARGIN),
        Event::Bound => set.bound_by_box(g),
        Event::Window(b) => set.set_window(b),
    }
}

fn event(n: u32) -> impl Strategy<Value = Event> {
    // Measurements are larger: a few metres around the target.
    let measured = move |b: CellBox| CellBox {
        x1: (b.x1 + 6).min(n - 1),
        y1: (b.y1 + 6).min(n - 1),
        ..b
    };
    prop_oneof![
        4 => (0.1f64..1.6).prop_map(Event::Move),
        4 => cell_box(n, 11).prop_map(Event::Free),
        1 => cell_box(n, 11).prop_map(move |b| Event::Measure(measured(b))),
        1 => Just(Event::Restore),
        1 => cell_box(n, 11).prop_map(move |b| Event::Learn(measured(b))),
        1 => Just(Event::Bound),
        2 => cell_box(n, n).prop_map(Event::Window),
    ]
}

/// Events on the [`ROOMY`] grid: proven-free boxes of up to 40 cells, windows anywhere.
fn roomy_event() -> impl Strategy<Value = Event> {
    let (nx, ny) = ROOMY;
    prop_oneof![
        6 => (0.1f64..2.0).prop_map(Event::Move),
        4 => cell_box(nx, 72).prop_map(Event::Free),
        1 => cell_box(nx, 14).prop_map(Event::Measure),
        1 => Just(Event::Restore),
        1 => cell_box(nx, 14).prop_map(Event::Learn),
        1 => Just(Event::Bound),
        3 => cell_box(nx, 48).prop_map(Event::Window),
    ]
    .prop_map(move |e| e.within_rows(ny))
}

/// Events on the 160 x 160 grid: larger boxes, moves of up to three metres.
fn wide_event() -> impl Strategy<Value = Event> {
    prop_oneof![
        4 => (0.1f64..3.0).prop_map(Event::Move),
        4 => cell_box(160, 60).prop_map(Event::Free),
        1 => cell_box(160, 30).prop_map(Event::Measure),
        1 => Just(Event::Restore),
        1 => cell_box(160, 30).prop_map(Event::Learn),
        1 => Just(Event::Bound),
        2 => cell_box(160, 160).prop_map(Event::Window),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// No position a target can really be at is ever outside the set, through any history of
    /// motion, proven-free ground and measurements; and the set is never larger than the
    /// whole-cell dilation it replaces.
    #[test]
    fn the_set_holds_every_possible_position(events in proptest::collection::vec(event(24), 1..24)) {
        holds_every_possible_position(&grid(), SAMPLES, &events, Storage::Every)?;
    }

    /// The same for a set that stores its reach over the rows near its cells only, with the
    /// far field of its box elsewhere ([`ReachSet::with_margin`]), for every margin.
    #[test]
    fn a_set_stored_over_its_rows_holds_every_possible_position(
        events in proptest::collection::vec(event(24), 1..24),
        margin in 0u32..6,
    ) {
        holds_every_possible_position(&grid(), SAMPLES, &events, Storage::Margin(margin))?;
    }

    /// The same on a grid three words wide, so that the window also cuts and widens by
    /// columns: a set stored over the cells near its box, moved, cleared, measured and cut
    /// across the words of its rows.
    #[test]
    fn a_set_stored_over_its_box_holds_every_possible_position_across_words(
        events in proptest::collection::vec(event(WIDE.0).prop_map(|e| e.within_rows(WIDE.1)), 1..24),
        margin in 0u32..10,
    ) {
        let g = GroundGrid { nx: WIDE.0, ny: WIDE.1, ..GroundGrid::new(1.0, 0.5) };
        holds_every_possible_position(&g, 2, &events, Storage::Margin(margin))?;
    }

    /// The same for an undetected set kept over a window that moves between the events
    /// ([`ReachSet::keep_window`]), with a summary of lower bounds per block outside it: on a
    /// grid three words wide and six blocks high, with proven-free boxes that raise the
    /// summary, on the same width two blocks high (the second one partial), and on the square
    /// grid. The window only loosens the set: until a measurement makes it a target's set, it
    /// holds every cell of the same set kept without a window.
    #[test]
    fn a_set_kept_over_a_moving_window_holds_every_possible_position(
        roomy in proptest::collection::vec(roomy_event(), 1..24),
        wide in proptest::collection::vec(event(WIDE.0).prop_map(|e| e.within_rows(WIDE.1)), 1..24),
        square in proptest::collection::vec(event(24), 1..24),
    ) {
        let at = |(nx, ny): (u32, u32)| GroundGrid { nx, ny, ..GroundGrid::new(1.0, 0.5) };
        holds_every_possible_position(&at(ROOMY), 2, &roomy, Storage::Window)?;
        holds_every_possible_position(&at(WIDE), 2, &wide, Storage::Window)?;
        holds_every_possible_position(&grid(), SAMPLES, &square, Storage::Window)?;
    }

    /// A set kept over a window that covers the grid is the set kept without one, cells and
    /// reach, through any history (the window is storage only until it leaves some cells out).
    #[test]
    fn a_window_over_the_whole_grid_changes_nothing(
        events in proptest::collection::vec(wide_event(), 1..24),
    ) {
        let g = GroundGrid::new(40.0, 0.5);
        let whole_grid = CellBox { x0: 0, y0: 0, x1: g.nx - 1, y1: g.ny - 1 };
        let mut plain = ReachSet::full(&g);
        let mut windowed = ReachSet::full(&g).keep_window();
        let (mut a, mut b) = (0.0, 0.0);
        for e in &events {
            let e = match e {
                Event::Window(_) => Event::Window(whole_grid),
                other => other.clone(),
            };
            apply(&g, &mut plain, &e, &mut a);
            apply(&g, &mut windowed, &e, &mut b);
            if matches!(e, Event::Restore) {
                windowed = windowed.keep_window();
            }
            prop_assert!(plain == windowed, "the sets differ after {:?}", e);
            prop_assert_eq!(plain.cells(), windowed.cells());
        }
    }

    /// A set that starts outside its window ([`ReachSet::full_outside_window`]) is, from its
    /// first window on, the whole grid kept over a window ([`ReachSet::keep_window`]): the
    /// same cells and reach through any history, on the grid of the window tests.
    #[test]
    fn a_set_started_outside_its_window_is_the_whole_grid_kept_over_it(
        first in cell_box(ROOMY.0, 48).prop_map(|b| Event::Window(b).within_rows(ROOMY.1)),
        events in proptest::collection::vec(roomy_event(), 1..24),
    ) {
        let g = GroundGrid { nx: ROOMY.0, ny: ROOMY.1, ..GroundGrid::new(1.0, 0.5) };
        let mut whole = ReachSet::full(&g).keep_window();
        let mut started = ReachSet::full_outside_window(&g);
        let (mut a, mut b) = (0.0, 0.0);
        for e in std::iter::once(&first).chain(&events) {
            apply(&g, &mut whole, e, &mut a);
            apply(&g, &mut started, e, &mut b);
            if matches!(e, Event::Restore) {
                whole = whole.keep_window();
                started = started.keep_window();
            }
            prop_assert!(whole == started, "the sets differ after {:?}", e);
            prop_assert_eq!(whole.cells(), started.cells());
        }
    }

    /// Advancing within a dilation read word by word ([`ReachSet::advance_within`] with a
    /// [`sets::raster::WordDilation`] of the set's rows, which skips the rows and words no
    /// cell is near) leaves the set, its reach and its clock exactly as advancing and then
    /// intersecting with the whole dilation does, and as a bound that reads every word does,
    /// through any history, on a grid several words wide; and advancing with the scans a set
    /// remembers gives what a set without them (rebuilt from its parts) gives. A set learned
    /// from a measurement stores the rows near its cells only; the one rebuilt from its parts
    /// stores every row, so the two growing alike also shows that the stored rows widen
    /// before the clock reaches a row outside them.
    #[test]
    fn advancing_within_a_dilation_read_word_by_word_is_the_whole_grid_way(
        events in proptest::collection::vec(wide_event(), 1..24),
    ) {
        let g = GroundGrid::new(40.0, 0.5); // 160 x 160 cells, 3 words a row
        let mut whole = ReachSet::full(&g);
        let mut local = ReachSet::full(&g);
        let mut unskipped = ReachSet::full(&g);
        let mut clock = 0.0;
        for e in &events {
            match e {
                Event::Move(r) => {
                    // A set rebuilt from its parts has no cached scans: it reads every word.
                    let (cells, base, relative) = whole.to_parts();
                    let mut uncached = ReachSet::from_parts(cells, base, &relative, clock)
                        .expect("parts of the same grid");
                    clock += r;
                    let previous = whole.cells().dilate(&g, *r);
                    whole.advance(clock);
                    whole.intersect(&previous);
                    uncached.advance(clock);
                    uncached.intersect(&previous);
                    prop_assert!(whole == uncached, "cached scans changed the set");
                    let near = local.cells().word_dilation_within(&g, *r, local.rows());
                    local.advance_within(clock, near);
                    let mut words = unskipped.cells().word_dilation(&g, *r);
                    unskipped.advance_within(clock, |old: &CellSet, iy, w| words.word(old, iy, w));
                }
                Event::Free(b) => {
                    let free = box_set(&g, b);
                    for set in [&mut whole, &mut local, &mut unskipped] {
                        set.clear(&g, &free, b);
                    }
                }
                Event::Measure(b) => {
                    let m = box_set(&g, b);
                    for set in [&mut whole, &mut local, &mut unskipped] {
                        set.restrict(&g, &m, 8);
                    }
                }
                Event::Restore => {
                    for set in [&mut whole, &mut local, &mut unskipped] {
                        *set = ReachSet::from_cells_at(&g, set.cells().clone(), clock);
                    }
                }
                Event::Learn(b) => {
                    let m = box_set(&g, b);
                    for set in [&mut whole, &mut local, &mut unskipped] {
                        *set = set.restricted_copy(&g, &m, LEARN_MARGIN);
                    }
                }
                Event::Bound => {
                    for set in [&mut whole, &mut local, &mut unskipped] {
                        set.bound_by_box(&g);
                    }
                }
                Event::Window(_) => {}
            }
            prop_assert!(whole == local, "the sets differ after {:?}", e);
            prop_assert!(whole == unskipped, "the sets differ after {:?}", e);
        }
    }

    /// The rows a set keeps ([`ReachSet::rows`]) hold every cell of it through any history of
    /// growth, proven-free ground, measurements, meets and joins, so the queries that read
    /// only those rows (emptiness, count, bounding box, sharing a cell) answer what the
    /// whole-grid ones do; and the rows whose reach it stores hold them.
    #[test]
    fn the_rows_a_set_keeps_hold_every_cell_it_has(
        events in proptest::collection::vec(
            (wide_event(), cell_box(160, 40), 0u8..4), 1..24,
        ),
    ) {
        let g = GroundGrid::new(40.0, 0.5);
        let mut set = ReachSet::full(&g);
        let mut clock = 0.0;
        for (e, other_box, op) in &events {
            let other = box_set(&g, other_box);
            apply(&g, &mut set, e, &mut clock);
            match op {
                0 => set.intersect(&other),
                1 => set.join(&other),
                2 => set.bound_by_box(&g),
                _ => set.advance(clock + 0.5),
            }
            let (rows, stored) = (set.rows(), set.stored_rows());
            prop_assert!(rows.is_empty() || (stored.start <= rows.start && rows.end <= stored.end));
            for (_, iy) in set.cells().iter() {
                prop_assert!(rows.contains(&iy), "row {} outside {:?} after {:?}", iy, rows, e);
            }
            prop_assert_eq!(set.is_empty(), set.cells().is_empty());
            prop_assert_eq!(set.count(), set.cells().count());
            prop_assert_eq!(set.bounding_box(), set.cells().bounding_box());
            prop_assert_eq!(set.intersects(&other), set.cells().intersects(&other));
        }
    }

    /// A copy of a set met with an outer raster of its targets ([`ReachSet::restricted_copy`])
    /// has the cells of cloning, meeting and bounding by the box, and the same reach over the
    /// rows it stores; elsewhere its reach (the far field of its box) is at most that one. (An
    /// empty copy holds no target, and any reach holds for it.)
    #[test]
    fn a_restricted_copy_is_the_bounded_meet_over_its_rows(
        events in proptest::collection::vec(wide_event(), 0..16),
        outer in cell_box(160, 40),
        margin in 0u32..24,
    ) {
        let g = GroundGrid::new(40.0, 0.5);
        let mut set = ReachSet::full(&g);
        let mut clock = 0.0;
        for e in &events {
            apply(&g, &mut set, e, &mut clock);
        }
        let outer = box_set(&g, &outer);
        let copy = set.restricted_copy(&g, &outer, margin);
        // The reference stores every row: the set's reach, wherever it was stored.
        let (cells, base, relative) = set.to_parts();
        let mut reference = ReachSet::from_parts(cells, base, &relative, set.clock_m())
            .expect("parts of the same grid");
        reference.intersect(&outer);
        reference.bound_by_box(&g);
        prop_assert_eq!(copy.cells(), reference.cells());
        if copy.is_empty() {
            return Ok(());
        }
        let (rows, columns, nx) = (copy.stored_rows(), copy.stored_columns(), g.nx as usize);
        let (mine, theirs) = (reach_of(&copy), reach_of(&reference));
        for (k, (a, b)) in mine.iter().zip(&theirs).enumerate() {
            let (ix, iy) = ((k % nx) as u32, (k / nx) as u32);
            if rows.contains(&iy) && columns.contains(&ix) {
                prop_assert_eq!(a, b, "cell {:?}", (ix, iy));
            } else {
                prop_assert!(a <= b, "cell {:?}: {} > {}", (ix, iy), a, b);
            }
        }
    }

    /// A pocket left unobserved for `n` steps of `R` grows to exactly the cells whose squares
    /// lie within `n R` of its squares: at most `n R` plus one cell diagonal from it.
    #[test]
    fn a_pocket_grows_by_the_motion_and_one_diagonal(
        pocket in proptest::collection::vec((20u32..40, 20u32..40), 1..6),
        steps in 1u32..12,
        r in 0.2f64..1.5,
    ) {
        pocket_growth(&pocket, steps, r)?;
    }
}

/// The reach of every cell of `set`, row-major, however the set stores it.
fn reach_of(set: &ReachSet) -> Vec<u32> {
    let (_, base, relative) = set.to_parts();
    relative.iter().map(|r| r + base).collect()
}

/// Where a set of the tests stores its reach.
#[derive(Clone, Copy, Debug)]
enum Storage {
    /// Every cell.
    Every,
    /// The rows within this margin of its cells ([`ReachSet::with_margin`]).
    Margin(u32),
    /// A window the events move, with a summary elsewhere ([`ReachSet::keep_window`]).
    Window,
}

impl Storage {
    fn apply(self, set: ReachSet) -> ReachSet {
        match self {
            Storage::Every => set,
            Storage::Margin(m) => set.with_margin(m),
            Storage::Window => set.keep_window(),
        }
    }

    /// The margin of a set stored near its cells.
    fn margin(self) -> Option<u32> {
        match self {
            Storage::Margin(m) => Some(m),
            _ => None,
        }
    }
}

/// The checks of `the_set_holds_every_possible_position` through `events`, for a set stored
/// as `storage` says. A set kept over a window is also checked against the same set kept
/// without one, which it must hold (until a measurement makes it a target's set).
fn holds_every_possible_position(
    g: &GroundGrid,
    per_side: u32,
    events: &[Event],
    storage: Storage,
) -> Result<(), TestCaseError> {
    let g = *g;
    let pts = samples(&g, per_side);
    let mut possible = vec![true; pts.len()];
    let mut set = storage.apply(ReachSet::full(&g));
    let mut plain = matches!(storage, Storage::Window).then(|| ReachSet::full(&g));
    let margin = storage.margin();
    let mut dilated = CellSet::full(&g);
    let mut clock = 0.0;
    for e in events {
        if let Some(plain) = &mut plain {
            let mut plain_clock = clock;
            apply(&g, plain, e, &mut plain_clock);
        }
        match e {
            Event::Move(r) => {
                possible = moved(&g, &pts, &possible, *r);
                clock += r;
                let previous = set.cells().dilate(&g, *r);
                set.advance(clock);
                set.intersect(&previous);
                dilated = dilated.dilate(&g, *r);
            }
            Event::Free(b) => {
                let free = box_set(&g, b);
                for ((_, c), k) in pts.iter().zip(possible.iter_mut()) {
                    *k &= !free.contains(*c);
                }
                set.clear(&g, &free, b);
                dilated.and_not_assign(&free);
            }
            Event::Measure(b) | Event::Learn(b) => {
                let m = box_set(&g, b);
                for ((_, c), k) in pts.iter().zip(possible.iter_mut()) {
                    *k &= m.contains(*c);
                }
                if matches!(e, Event::Learn(_)) {
                    set = set.restricted_copy(&g, &m, margin.unwrap_or(LEARN_MARGIN));
                } else {
                    set.restrict(&g, &m, 8);
                }
                dilated.and_assign(&m);
            }
            Event::Restore => {
                let restored = ReachSet::from_cells_at(&g, set.cells().clone(), clock);
                prop_assert_eq!(restored.cells(), set.cells());
                set = storage.apply(restored);
            }
            Event::Bound => set.bound_by_box(&g),
            Event::Window(b) => set.set_window(b),
        }
        if matches!(e, Event::Learn(_) | Event::Measure(_)) {
            plain = None;
        }
        if let Some(plain) = &plain {
            prop_assert!(
                plain.cells().is_subset_of(set.cells()),
                "the window dropped cells of the set without one after {:?}",
                e
            );
        }
        for ((p, c), k) in pts.iter().zip(&possible) {
            prop_assert!(
                !*k || set.contains(*c),
                "possible position {:?} outside the set (cell {:?}) after {:?}",
                p,
                c,
                e
            );
        }
        prop_assert!(set.cells().is_subset_of(&dilated));
    }
    Ok(())
}

/// The checks of `a_pocket_grows_by_the_motion_and_one_diagonal` for one case.
fn pocket_growth(pocket: &[(u32, u32)], steps: u32, r: f64) -> Result<(), TestCaseError> {
    let g = GroundGrid::new(15.0, 0.5); // 60 x 60 cells
    let mut free = CellSet::full(&g);
    for &c in pocket {
        free.set(c, false);
    }
    let mut set = ReachSet::full(&g);
    let all = CellBox {
        x0: 0,
        y0: 0,
        x1: g.nx - 1,
        y1: g.ny - 1,
    };
    set.clear(&g, &free, &all);
    let pocket_set = CellSet::from_cells(&g, pocket.iter().copied());
    prop_assert_eq!(set.cells(), &pocket_set);
    for k in 1..=steps {
        set.advance(f64::from(k) * r);
    }
    let reach = f64::from(steps) * r;
    let diagonal = g.cell_m * std::f64::consts::SQRT_2;
    for iy in 0..g.ny {
        for ix in 0..g.nx {
            let gap = pocket
                .iter()
                .map(|&(px, py)| {
                    let gx = f64::from(ix.abs_diff(px).saturating_sub(1));
                    let gy = f64::from(iy.abs_diff(py).saturating_sub(1));
                    g.cell_m * gx.hypot(gy)
                })
                .fold(f64::INFINITY, f64::min);
            // Exactly the squares within the motion, up to one reach unit that the rounding
            // may add and 1e-6 m of arithmetic.
            if gap <= reach - 1e-6 {
                prop_assert!(
                    set.contains((ix, iy)),
                    "cell {:?} gap {} reach {}",
                    (ix, iy),
                    gap,
                    reach
                );
            }
            if gap > reach + REACH_UNIT_M + 1e-6 {
                prop_assert!(
                    !set.contains((ix, iy)),
                    "cell {:?} gap {} reach {}",
                    (ix, iy),
                    gap,
                    reach
                );
            }
            // Hence every point of the set lies within n R plus a diagonal of the pocket:
            // checked on the cell's centre, measured to the pocket's squares in metres.
            if set.contains((ix, iy)) {
                let c = g.cell_centre((ix, iy));
                let to_pocket = pocket
                    .iter()
                    .map(|&p| {
                        let r = g.cell_rect(p);
                        let dx = (r.min.x - c.x).max(c.x - r.max.x).max(0.0);
                        let dy = (r.min.y - c.y).max(c.y - r.max.y).max(0.0);
                        dx.hypot(dy)
                    })
                    .fold(f64::INFINITY, f64::min);
                prop_assert!(to_pocket <= reach + diagonal / 2.0 + REACH_UNIT_M + 1e-6);
            }
        }
    }
    // The whole-cell dilation it replaces grows faster, up to the reach unit the rounding may
    // add (above): its first step takes that unit too. Dilating step by step holds every cell
    // within the summed radii, as each point on the way lies in some square of the previous set.
    let mut old = pocket_set.dilate(&g, r + REACH_UNIT_M + 1e-6);
    for _ in 1..steps {
        old = old.dilate(&g, r);
    }
    prop_assert!(set.cells().is_subset_of(&old));
    Ok(())
}

/// A step just short of three cells reaches the cells three cells away, by the one reach unit
/// the rounding adds; the dilation it is compared with must allow that unit (a case proptest
/// once found).
#[test]
fn a_step_a_hair_short_of_whole_cells_stays_within_one_unit() {
    pocket_growth(&[(20, 20)], 1, 1.4999630805469912).unwrap();
    pocket_growth(&[(20, 20)], 3, 1.4336523589877859).unwrap();
}

#[test]
fn a_lone_cell_grows_one_metre_per_step_not_one_and_a_half() {
    // 0.5 m cells, 1 m per step: after 10 steps the pocket's squares reach 10 m, 20 cells;
    // rounding out at every step would reach 30 cells.
    let g = GroundGrid::new(25.0, 0.5); // 100 x 100 cells
    let mut free = CellSet::full(&g);
    free.set((50, 50), false);
    let mut set = ReachSet::full(&g);
    set.clear(
        &g,
        &free,
        &CellBox {
            x0: 0,
            y0: 0,
            x1: 99,
            y1: 99,
        },
    );
    let mut old = CellSet::from_cells(&g, [(50, 50)]);
    for k in 1..=10 {
        set.advance(f64::from(k));
        old = old.dilate(&g, 1.0);
    }
    let row: Vec<u32> = (0..100).filter(|&x| set.contains((x, 50))).collect();
    assert_eq!(row.first(), Some(&29));
    assert_eq!(row.last(), Some(&71));
    let old_row: Vec<u32> = (0..100).filter(|&x| old.contains((x, 50))).collect();
    assert_eq!(old_row.first(), Some(&20));
    assert!(set.cells().count() * 2 < old.count());
}

#[test]
fn reach_survives_its_parts() {
    let g = grid();
    let mut set = ReachSet::full(&g);
    let b = CellBox {
        x0: 3,
        y0: 4,
        x1: 15,
        y1: 12,
    };
    set.clear(&g, &box_set(&g, &b), &b);
    set.advance(0.7);
    let (cells, base, relative) = set.to_parts();
    let back = ReachSet::from_parts(cells, base, &relative, set.clock_m()).expect("parts fit");
    assert_eq!(back.cells(), set.cells());
    let (mut a, mut b2) = (set.clone(), back);
    for k in 1..6 {
        a.advance(0.7 + f64::from(k) * 0.4);
        b2.advance(0.7 + f64::from(k) * 0.4);
        assert_eq!(a.cells(), b2.cells());
    }
    assert!(ReachSet::from_parts(CellSet::empty(&g), 0, &[1, 2, 3], 0.0).is_none());
}

/// A fact learned late: at the clock before the last `lag` moves.
#[derive(Clone, Debug)]
enum LateEvent {
    /// The targets move at most this far.
    Move(f64),
    /// A rectangle of cells is proven free `lag` moves ago ([`ReachSet::clear_since`]).
    Free(CellBox, usize),
    /// The target was measured inside a rectangle `lag` moves ago
    /// ([`ReachSet::restrict_since`]).
    Measure(CellBox, usize),
    /// As `Measure`, on a copy first met with the measurement grown by the motion since (a
    /// target first learned from a late measurement).
    Learn(CellBox, usize),
    /// The reach is bounded by the set's box.
    Bound,
    /// The set keeps its reach over this rectangle only ([`ReachSet::set_window`]).
    Window(CellBox),
}

/// Late events on a grid of `nx` x `ny` cells, proven-free boxes of up to `free_side` cells.
fn late_event(nx: u32, ny: u32, free_side: u32) -> impl Strategy<Value = LateEvent> {
    let fold = move |b: CellBox| CellBox {
        x0: b.x0,
        x1: b.x1,
        y0: b.y0 % ny,
        y1: (b.y0 % ny + (b.y1 - b.y0)).min(ny - 1),
    };
    let measured = move |b: CellBox| CellBox {
        x1: (b.x1 + 6).min(nx - 1),
        y1: (b.y1 + 6).min(ny - 1),
        ..fold(b)
    };
    prop_oneof![
        4 => (0.1f64..1.6).prop_map(LateEvent::Move),
        4 => (cell_box(nx, free_side), 0usize..4)
            .prop_map(move |(b, lag)| LateEvent::Free(fold(b), lag)),
        1 => (cell_box(nx, 11), 0usize..4)
            .prop_map(move |(b, lag)| LateEvent::Measure(measured(b), lag)),
        1 => (cell_box(nx, 11), 0usize..4)
            .prop_map(move |(b, lag)| LateEvent::Learn(measured(b), lag)),
        1 => Just(LateEvent::Bound),
        2 => cell_box(nx, 48).prop_map(move |b| LateEvent::Window(fold(b))),
    ]
}

/// What the reference knows, in the order of the targets' time.
#[derive(Clone, Debug)]
enum Fact {
    Move(f64),
    /// The targets were in none of these cells.
    Free(CellSet),
    /// The targets were in these cells.
    In(CellSet),
}

/// The sampled possible positions after `facts`, from every position.
fn possible_after(g: &GroundGrid, pts: &[(Point2, CellIndex)], facts: &[Fact]) -> Vec<bool> {
    let mut possible = vec![true; pts.len()];
    for f in facts {
        match f {
            Fact::Move(r) => possible = moved(g, pts, &possible, *r),
            Fact::Free(free) => {
                for ((_, c), k) in pts.iter().zip(possible.iter_mut()) {
                    *k &= !free.contains(*c);
                }
            }
            Fact::In(m) => {
                for ((_, c), k) in pts.iter().zip(possible.iter_mut()) {
                    *k &= m.contains(*c);
                }
            }
        }
    }
    possible
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Facts applied late, at the clock they were true at ([`ReachSet::clear_since`],
    /// [`ReachSet::restrict_since`]), never drop a position a target can really be at, for a
    /// set stored over every row or over its rows only: the reference applies each fact at
    /// its own time, among the moves. With no lag they are the current operations.
    #[test]
    fn late_facts_keep_every_possible_position(
        events in proptest::collection::vec(late_event(24, 24, 11), 1..20),
        margin in prop::option::of(0u32..6),
    ) {
        let storage = margin.map_or(Storage::Every, Storage::Margin);
        late_facts_hold(&grid(), SAMPLES, &events, storage)?;
    }

    /// The same for an undetected set kept over a window that moves between the facts, on a
    /// grid two words wide and six blocks high, with proven-free boxes large enough to hold
    /// blocks far from every block that is not free (so that late facts raise the summary
    /// above the clock).
    #[test]
    fn late_facts_keep_every_possible_position_in_a_moving_window(
        events in proptest::collection::vec(late_event(ROOMY.0, ROOMY.1, 40), 1..20),
    ) {
        let g = GroundGrid { nx: ROOMY.0, ny: ROOMY.1, ..GroundGrid::new(1.0, 0.5) };
        late_facts_hold(&g, 1, &events, Storage::Window)?;
    }
}

/// The checks of `late_facts_keep_every_possible_position` through `events`, for a set stored
/// as `storage` says, with `per_side` x `per_side` samples a cell.
fn late_facts_hold(
    g: &GroundGrid,
    per_side: u32,
    events: &[LateEvent],
    storage: Storage,
) -> Result<(), TestCaseError> {
    let g = *g;
    let pts = samples(&g, per_side);
    let mut set = storage.apply(ReachSet::full(&g));
    let margin = storage.margin();
    let mut facts: Vec<Fact> = Vec::new();
    // The clock after each move, with 0 first.
    let mut clocks = vec![0.0];
    for e in events {
        let clock = *clocks.last().expect("a clock");
        // Where a fact `lag` moves old goes among the facts, and its clock.
        let at = |lag: usize, facts: &[Fact]| {
            let lag = lag.min(clocks.len() - 1);
            let mut moves = 0;
            let mut k = facts.len();
            while moves < lag {
                k -= 1;
                if matches!(facts[k], Fact::Move(_)) {
                    moves += 1;
                }
            }
            (k, clocks[clocks.len() - 1 - lag])
        };
        match e {
            LateEvent::Move(r) => {
                let next = clock + r;
                let previous = set.cells().dilate(&g, *r);
                set.advance(next);
                set.intersect(&previous);
                clocks.push(next);
                facts.push(Fact::Move(*r));
            }
            LateEvent::Free(b, lag) => {
                let (k, then) = at(*lag, &facts);
                let free = box_set(&g, b);
                if *lag == 0 {
                    let mut current = set.clone();
                    current.clear(&g, &free, b);
                    set.clear_since(&g, &free, b, then);
                    prop_assert!(set == current, "no lag is the current clear");
                } else {
                    set.clear_since(&g, &free, b, then);
                }
                facts.insert(k, Fact::Free(free));
            }
            LateEvent::Measure(b, lag) | LateEvent::Learn(b, lag) => {
                let (k, then) = at(*lag, &facts);
                let m = box_set(&g, b);
                if matches!(e, LateEvent::Learn(..)) {
                    let grown = m.dilate(&g, clock - then);
                    set = set.restricted_copy(&g, &grown, margin.unwrap_or(LEARN_MARGIN));
                }
                if *lag == 0 {
                    let mut current = set.clone();
                    current.restrict(&g, &m, 8);
                    set.restrict_since(&g, &m, 8, then);
                    prop_assert!(set == current, "no lag is the current restriction");
                } else {
                    set.restrict_since(&g, &m, 8, then);
                }
                facts.insert(k, Fact::In(m));
            }
            LateEvent::Bound => set.bound_by_box(&g),
            LateEvent::Window(b) => set.set_window(b),
        }
        let possible = possible_after(&g, &pts, &facts);
        for ((p, c), k) in pts.iter().zip(&possible) {
            prop_assert!(
                !*k || set.contains(*c),
                "possible position {:?} outside the set (cell {:?}) after {:?}",
                p,
                c,
                e
            );
        }
    }
    Ok(())
}

/// A late clear removes the free cells deeper than the motion since, and keeps the others.
#[test]
fn a_late_clear_removes_what_its_clock_still_proves() {
    let g = GroundGrid::new(10.0, 0.5); // 40 x 40 cells
    let mut set = ReachSet::full(&g);
    set.advance(1.0);
    set.advance(3.0);
    let b = CellBox {
        x0: 10,
        y0: 10,
        x1: 29,
        y1: 29,
    };
    // Free at the clock 1 m, learned at 3 m: the targets may have driven 2 m (4 cells) in.
    set.clear_since(&g, &box_set(&g, &b), &b, 1.0);
    for iy in 0..40u32 {
        for ix in 0..40u32 {
            let (x, y) = (i64::from(ix), i64::from(iy));
            let depth = [x - 10, 29 - x, y - 10, 29 - y]
                .into_iter()
                .min()
                .unwrap_or(0);
            let inside = (10..=29).contains(&ix) && (10..=29).contains(&iy);
            // Cells 5 whole cells or more inside are beyond 2 m of every cell outside; at 4
            // the gap is exactly the motion.
            let expected = !(inside && depth >= 5);
            assert_eq!(set.contains((ix, iy)), expected, "{:?}", (ix, iy));
        }
    }
    // From now on they regrow at the motion's pace.
    set.advance(3.5);
    assert!(set.contains((15, 20)) && !set.contains((16, 20)));
}

/// Ground proven free outside the window raises the summary: the blocks deep in it stay out
/// of the set while the motion has not reached them, as they would without a window (to
/// within a block), and the ones near its sides rejoin first.
#[test]
fn free_ground_outside_the_window_stays_out_by_blocks() {
    let g = GroundGrid {
        nx: ROOMY.0,
        ny: ROOMY.1,
        ..GroundGrid::new(1.0, 0.5)
    };
    let mut set = ReachSet::full(&g).keep_window();
    // The window holds the first word of columns; the free box lies beyond it.
    set.set_window(&CellBox {
        x0: 0,
        y0: 0,
        x1: 63,
        y1: 47,
    });
    let free = CellBox {
        x0: 64,
        y0: 0,
        x1: 135,
        y1: 47,
    };
    set.clear(&g, &box_set(&g, &free), &free);
    set.advance(2.0);
    // The box's far side is the grid's edge, its near side the window's: cells 8 blocks
    // (32 m) from the near side stay out after 2 m, and so do cells 4.5 m from it (a block
    // of 4 m is the summary's rounding; the block next to the side rejoins).
    assert!(!set.contains((130, 20)));
    assert!(!set.contains((64 + 9, 20)));
    assert!(set.contains((64, 20)));
    // Without a window the same history keeps out every cell beyond 2 m of the side.
    let mut plain = ReachSet::full(&g);
    plain.clear(&g, &box_set(&g, &free), &free);
    plain.advance(2.0);
    assert!(!plain.contains((64 + 5, 20)));
    // As the motion grows, the set regrows no later than the one without a window (it holds
    // it), and no sooner than a block's diagonal allows: every cell it holds is within the
    // motion plus a block's diagonal of a cell the free box did not prove free.
    let block_diagonal = 8.0 * 0.5 * 2f64.sqrt();
    for step in 1..=80 {
        let clock = 2.0 + 0.5 * f64::from(step);
        set.advance(clock);
        plain.advance(clock);
        assert!(plain.cells().is_subset_of(set.cells()), "clock {clock}");
        let mut unproven = CellSet::full(&g);
        unproven.and_not_assign(&box_set(&g, &free));
        let regrown = unproven.dilate(&g, clock + block_diagonal);
        assert!(set.cells().is_subset_of(&regrown), "clock {clock}");
    }
}
