//! Property tests of the row window of [`CellSet`]: a set stores only some rows, and that is
//! storage only. After any sequence of edits and algebra, the set reads exactly as a plain
//! bitmap over the whole grid (the model here): the same cells, counts, boxes and encoding,
//! and the same digests as the bitmap's words hashed row after row, whatever rows it stores.

use proptest::prelude::*;
use sets::grid::GroundGrid;
use sets::math::Point2;
use sets::raster::{CellBox, CellSet};

/// A plain bitmap over the whole grid: the model.
#[derive(Clone)]
struct Model {
    nx: u32,
    ny: u32,
    cells: Vec<bool>,
}

impl Model {
    fn new(grid: &GroundGrid) -> Self {
        Self {
            nx: grid.nx,
            ny: grid.ny,
            cells: vec![false; (grid.nx * grid.ny) as usize],
        }
    }

    fn at(&self, ix: u32, iy: u32) -> bool {
        self.cells[(iy * self.nx + ix) as usize]
    }

    fn put(&mut self, ix: u32, iy: u32, v: bool) {
        if ix < self.nx && iy < self.ny {
            self.cells[(iy * self.nx + ix) as usize] = v;
        }
    }

    /// The words of every row, as a dense bitmap stores them.
    fn words(&self) -> Vec<u64> {
        let wpr = (self.nx as usize).div_ceil(64);
        let mut out = vec![0u64; wpr * self.ny as usize];
        for iy in 0..self.ny {
            for ix in 0..self.nx {
                if self.at(ix, iy) {
                    out[iy as usize * wpr + ix as usize / 64] |= 1 << (ix % 64);
                }
            }
        }
        out
    }

    fn digest(&self) -> u64 {
        self.words()
            .iter()
            .fold(0xcbf2_9ce4_8422_2325_u64, |h, &w| {
                (h ^ w).wrapping_mul(0x100_0000_01b3)
            })
    }

    fn fingerprint(&self) -> u64 {
        const BASIS: u64 = 0xcbf2_9ce4_8422_2325;
        const PRIME: u64 = 0x100_0000_01b3;
        let words = self.words();
        let mut lanes = [BASIS, BASIS ^ 1, BASIS ^ 2, BASIS ^ 3];
        for (i, &w) in words.iter().enumerate() {
            lanes[i % 4] = (lanes[i % 4] ^ w).wrapping_mul(PRIME);
        }
        let folded = lanes
            .iter()
            .fold(BASIS, |h, &lane| (h ^ lane).wrapping_mul(PRIME));
        (folded ^ words.len() as u64).wrapping_mul(PRIME)
    }

    fn set(&self, grid: &GroundGrid) -> CellSet {
        let mut s = CellSet::empty(grid);
        // Rows from the bottom up, so the window grows at its front.
        for iy in (0..self.ny).rev() {
            for ix in 0..self.nx {
                if self.at(ix, iy) {
                    s.set((ix, iy), true);
                }
            }
        }
        s
    }
}

/// One edit of a set.
#[derive(Clone, Debug)]
enum Edit {
    Set(u32, u32, bool),
    Span(u32, u32, u32),
    Row(u32, u32, u32),
    Or(Vec<(u32, u32)>),
    And(Vec<(u32, u32)>),
    AndNot(Vec<(u32, u32)>),
    Crop(CellBox),
    Trim,
}

fn cells(n: u32) -> impl Strategy<Value = Vec<(u32, u32)>> {
    proptest::collection::vec((0..n, 0..n), 0..40)
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (0u32..140, 0u32..70, any::<bool>()).prop_map(|(x, y, v)| Edit::Set(x, y, v)),
        (0u32..70, 0u32..140, 0u32..140).prop_map(|(y, a, b)| Edit::Span(y, a.min(b), a.max(b))),
        (0u32..70, 1u32..30, 0u32..3).prop_map(|(y, n, k)| Edit::Row(y, n, k)),
        cells(140).prop_map(Edit::Or),
        cells(140).prop_map(Edit::And),
        cells(140).prop_map(Edit::AndNot),
        (0u32..140, 0u32..70, 0u32..140, 0u32..70)
            .prop_map(|(x0, y0, x1, y1)| Edit::Crop(CellBox { x0, y0, x1, y1 })),
        Just(Edit::Trim),
    ]
}

fn grid(nx: u32, ny: u32) -> GroundGrid {
    GroundGrid {
        origin: Point2::new(0.0, 0.0),
        cell_m: 0.5,
        nx,
        ny,
    }
}

/// The other operand of an algebra edit, on the set's grid and in the model.
fn operand(g: &GroundGrid, cells: &[(u32, u32)]) -> (CellSet, Model) {
    let mut m = Model::new(g);
    for &(x, y) in cells {
        m.put(x % g.nx, y % g.ny, true);
    }
    (m.set(g), m)
}

fn apply(g: &GroundGrid, s: &mut CellSet, m: &mut Model, e: &Edit) {
    match e {
        Edit::Set(x, y, v) => {
            s.set((*x, *y), *v);
            m.put(*x, *y, *v);
        }
        Edit::Span(y, a, b) => {
            let y = y % g.ny;
            s.fill_row_span(y, *a, *b);
            for x in *a..=*b {
                m.put(x, y, true);
            }
        }
        Edit::Row(y, n, k) => {
            // Many rows one at a time, going up, down or every other row.
            for i in 0..*n {
                let y = match k {
                    0 => y + i,
                    1 => y.saturating_sub(i),
                    _ => y + 2 * i,
                } % g.ny;
                s.row_mut(y)[0] |= 1;
                m.put(0, y, true);
            }
        }
        Edit::Or(c) | Edit::And(c) | Edit::AndNot(c) => {
            let (o, om) = operand(g, c);
            for (v, &w) in m.cells.iter_mut().zip(&om.cells) {
                *v = match e {
                    Edit::Or(_) => *v || w,
                    Edit::And(_) => *v && w,
                    _ => *v && !w,
                };
            }
            match e {
                Edit::Or(_) => s.or_assign(&o),
                Edit::And(_) => s.and_assign(&o),
                _ => s.and_not_assign(&o),
            }
        }
        Edit::Crop(b) => {
            s.crop(b);
            for iy in 0..g.ny {
                for ix in 0..g.nx {
                    if !b.contains((ix, iy)) {
                        m.put(ix, iy, false);
                    }
                }
            }
        }
        Edit::Trim => s.trim_rows(),
    }
}

/// Everything a set says of itself, against the model.
fn check(g: &GroundGrid, s: &CellSet, m: &Model) -> Result<(), TestCaseError> {
    let mut count = 0;
    for iy in 0..g.ny {
        for ix in 0..g.nx {
            prop_assert_eq!(s.contains((ix, iy)), m.at(ix, iy), "cell ({}, {})", ix, iy);
            count += u64::from(m.at(ix, iy));
        }
    }
    prop_assert_eq!(s.count(), count);
    prop_assert_eq!(s.is_empty(), count == 0);
    prop_assert_eq!(s.iter().count() as u64, count);
    prop_assert_eq!(s.digest(), m.digest());
    prop_assert_eq!(s.fingerprint(), m.fingerprint());
    // The same cells stored over other rows: equal, with the same encoding.
    let dense = m.set(g);
    prop_assert_eq!(s, &dense);
    prop_assert_eq!(s.encode(), dense.encode());
    prop_assert_eq!(
        &CellSet::decode(g, &s.encode()).expect("its own encoding"),
        s
    );
    prop_assert_eq!(s.bounding_box(), dense.bounding_box());
    for iy in 0..g.ny {
        if !s.stored_rows().contains(&iy) {
            prop_assert!(s.row(iy).iter().all(|&w| w == 0));
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// Any sequence of edits leaves a set that reads as the model's bitmap.
    #[test]
    fn a_set_reads_as_its_bitmap_whatever_rows_it_stores(
        nx in 1u32..140,
        ny in 1u32..70,
        edits in proptest::collection::vec(edit(), 1..24),
    ) {
        let g = grid(nx, ny);
        let mut s = CellSet::empty(&g);
        let mut m = Model::new(&g);
        for e in &edits {
            apply(&g, &mut s, &mut m, e);
            check(&g, &s, &m)?;
        }
    }

    /// The queries between two sets agree with the model, whatever rows each stores.
    #[test]
    fn queries_between_sets_agree_with_the_bitmaps(
        nx in 1u32..140,
        ny in 1u32..70,
        a in cells(140),
        b in cells(140),
    ) {
        let g = grid(nx, ny);
        let ((sa, ma), (sb, mb)) = (operand(&g, &a), operand(&g, &b));
        let both = ma.cells.iter().zip(&mb.cells).filter(|(x, y)| **x && **y).count() as u64;
        let only_a = ma.cells.iter().zip(&mb.cells).filter(|(x, y)| **x && !**y).count() as u64;
        prop_assert_eq!(sa.intersection_count(&sb), both);
        prop_assert_eq!(sa.intersects(&sb), both > 0);
        prop_assert_eq!(sa.difference_count(&sb), only_a);
        prop_assert_eq!(sa.is_subset_of(&sb), only_a == 0);
        let full = CellSet::full(&g);
        prop_assert!(sa.is_subset_of(&full));
        prop_assert_eq!(full.difference_count(&sa), u64::from(nx * ny) - sa.count());
    }
}

/// Rows too wide for the shared zero row: the set stores every row, and reads the same.
#[test]
fn a_grid_of_very_wide_rows_stores_every_row() {
    let g = grid(66_000, 3);
    let mut s = CellSet::empty(&g);
    assert_eq!(s.stored_rows(), 0..3);
    s.set((65_999, 2), true);
    s.trim_rows();
    assert_eq!(s.stored_rows(), 0..3);
    assert_eq!(s.count(), 1);
    let mut m = Model::new(&g);
    m.put(65_999, 2, true);
    assert_eq!(s.digest(), m.digest());
    assert_eq!(s.fingerprint(), m.fingerprint());
}

/// A set of a few rows stores a few rows, and forgets the rows it no longer needs.
#[test]
fn a_small_set_on_a_large_grid_stores_its_rows() {
    let g = grid(2000, 2000);
    let mut s = CellSet::empty(&g);
    assert!(s.stored_rows().is_empty());
    s.fill_row_span(1000, 10, 20);
    s.fill_row_span(1010, 10, 20);
    assert!(s.stored_rows().len() <= 20, "{:?}", s.stored_rows());
    let mut far = CellSet::empty(&g);
    far.fill_row_span(1900, 0, 5);
    s.or_assign(&far);
    s.and_not_assign(&CellSet::from_cells(&g, (0..2000).map(|x| (x, 1000))));
    s.and_not_assign(&CellSet::from_cells(&g, (0..2000).map(|x| (x, 1010))));
    assert!(s.stored_rows().contains(&1900) && s.stored_rows().len() <= 9);
    s.and_assign(&CellSet::empty(&g));
    assert!(s.stored_rows().is_empty() && s.is_empty());
}
