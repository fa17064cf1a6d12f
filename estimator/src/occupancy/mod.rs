//! The occupancy elevation map (OEM): a coarse map of the city built while searching.
//!
//! Each cell of a coarse grid (5 m by default) is [`OemStatus::Unknown`], [`OemStatus::Obstacle`]
//! with the highest obstacle point seen in it, or [`OemStatus::Ground`] (seen open ground).
//! The map is approximate and only steers the guidance; no guaranteed set depends on it.
//!
//! Observations and merges follow one rule, so that fusing maps is idempotent, commutative and
//! associative: ground from anyone wins; otherwise obstacle with the largest height; unknown is
//! the identity.

mod visibility;

use std::collections::BTreeSet;

use protocol::wire::OemCellUpdate;
use serde::{Deserialize, Serialize};
use sets::grid::{CellIndex, GroundGrid};
use sets::math::Point2;

/// What is known about one OEM cell.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum OemStatus {
    /// Never observed.
    #[default]
    Unknown,
    /// An obstacle point was seen above the cell.
    Obstacle,
    /// Open ground was seen at the cell's centre.
    Ground,
}

impl OemStatus {
    /// The wire code of [`OemCellUpdate::status`].
    pub fn code(self) -> u8 {
        match self {
            OemStatus::Unknown => 0,
            OemStatus::Obstacle => 1,
            OemStatus::Ground => 2,
        }
    }

    /// Reads a wire code; `None` for an undefined one.
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(OemStatus::Unknown),
            1 => Some(OemStatus::Obstacle),
            2 => Some(OemStatus::Ground),
            _ => None,
        }
    }
}

/// One OEM cell: status and obstacle height (0 unless [`OemStatus::Obstacle`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OemCell {
    /// What the cell holds.
    pub status: OemStatus,
    /// Highest obstacle point seen above the cell, metres.
    pub height_m: f32,
}

impl OemCell {
    /// The merge of two cells: ground wins, else obstacle with the larger height, else unknown.
    pub fn merged(self, other: OemCell) -> OemCell {
        use OemStatus::*;
        match (self.status, other.status) {
            (Ground, _) | (_, Ground) => OemCell {
                status: Ground,
                height_m: 0.0,
            },
            (Obstacle, Obstacle) => OemCell {
                status: Obstacle,
                height_m: self.height_m.max(other.height_m),
            },
            (Obstacle, Unknown) => self,
            (Unknown, _) => other,
        }
    }
}

/// Why OEM cell updates from a peer were refused.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum OemUpdateError {
    /// The cell index lies outside the map.
    #[error("OEM cell ({ix}, {iy}) is outside the {nx}x{ny} map")]
    OutOfRange {
        /// Column in the update.
        ix: u16,
        /// Row in the update.
        iy: u16,
        /// Map width.
        nx: u32,
        /// Map height.
        ny: u32,
    },
    /// The status code is not 0, 1 or 2.
    #[error("OEM status code {0} is undefined")]
    BadStatus(u8),
    /// The height is not finite or negative.
    #[error("OEM height {0} is not a finite non-negative number")]
    BadHeight(f32),
}

/// The occupancy elevation map on its own coarse grid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OccupancyMap {
    grid: GroundGrid,
    cells: Vec<OemCell>,
    /// Cells changed since the last [`OccupancyMap::take_changes`], as flat indices.
    changed: BTreeSet<u32>,
}

impl OccupancyMap {
    /// An all-unknown map on `grid`.
    pub fn new(grid: GroundGrid) -> Self {
        Self {
            grid,
            cells: vec![OemCell::default(); grid.cell_count()],
            changed: BTreeSet::new(),
        }
    }

    /// The map's grid.
    pub fn grid(&self) -> &GroundGrid {
        &self.grid
    }

    /// The cell `(ix, iy)`, `None` outside the map.
    pub fn cell(&self, (ix, iy): CellIndex) -> Option<OemCell> {
        self.flat((ix, iy)).map(|i| self.cells[i])
    }

    /// The cell under a ground point, `None` outside the map.
    pub fn cell_at(&self, p: &Point2) -> Option<OemCell> {
        self.grid.cell_of(p).and_then(|c| self.cell(c))
    }

    /// Every cell that is not unknown, with its index.
    pub fn known_cells(&self) -> impl Iterator<Item = (CellIndex, OemCell)> + '_ {
        self.cells
            .iter()
            .enumerate()
            .filter(|(_, c)| c.status != OemStatus::Unknown)
            .map(|(i, c)| (self.index_of(i), *c))
    }

    /// Number of cells of each status: `(unknown, obstacle, ground)`.
    pub fn census(&self) -> (usize, usize, usize) {
        self.cells
            .iter()
            .fold((0, 0, 0), |(u, o, g), c| match c.status {
                OemStatus::Unknown => (u + 1, o, g),
                OemStatus::Obstacle => (u, o + 1, g),
                OemStatus::Ground => (u, o, g + 1),
            })
    }

    fn flat(&self, (ix, iy): CellIndex) -> Option<usize> {
        (ix < self.grid.nx && iy < self.grid.ny)
            .then(|| iy as usize * self.grid.nx as usize + ix as usize)
    }

    fn index_of(&self, flat: usize) -> CellIndex {
        let nx = self.grid.nx as usize;
        ((flat % nx) as u32, (flat / nx) as u32)
    }

    /// Merges `cell` into cell `(ix, iy)`; returns whether it changed. Ignored outside the map.
    pub fn merge_cell(&mut self, index: CellIndex, cell: OemCell) -> bool {
        let Some(i) = self.flat(index) else {
            return false;
        };
        let merged = self.cells[i].merged(cell);
        if merged != self.cells[i] {
            self.cells[i] = merged;
            self.changed.insert(i as u32);
            true
        } else {
            false
        }
    }

    /// Records an obstacle point: the cell under it becomes an obstacle at least as tall as
    /// `z_m`, unless it is known ground. Returns whether the map changed.
    pub fn observe_obstacle(&mut self, ground: &Point2, z_m: f64) -> bool {
        let Some(index) = self.grid.cell_of(ground) else {
            return false;
        };
        let height_m = z_m.max(0.0) as f32;
        if !height_m.is_finite() {
            return false;
        }
        self.merge_cell(
            index,
            OemCell {
                status: OemStatus::Obstacle,
                height_m,
            },
        )
    }

    /// Records that cell `index` was seen as open ground. Returns whether the map changed.
    pub fn observe_ground(&mut self, index: CellIndex) -> bool {
        self.merge_cell(
            index,
            OemCell {
                status: OemStatus::Ground,
                height_m: 0.0,
            },
        )
    }

    /// Merges another map on the same grid into this one (a map on another grid is ignored and
    /// `false` returned). Returns whether this map changed.
    pub fn merge(&mut self, other: &OccupancyMap) -> bool {
        if other.grid != self.grid {
            return false;
        }
        let mut changed = false;
        for (i, c) in other.cells.iter().enumerate() {
            if c.status != OemStatus::Unknown {
                changed |= self.merge_cell(self.index_of(i), *c);
            }
        }
        changed
    }

    /// The wire updates of the cells changed since the last call, and forgets them.
    pub fn take_changes(&mut self) -> Vec<OemCellUpdate> {
        let changed = std::mem::take(&mut self.changed);
        changed
            .into_iter()
            .map(|i| self.update_of(i as usize))
            .collect()
    }

    /// Whether cells changed since the last [`OccupancyMap::take_changes`].
    pub fn has_changes(&self) -> bool {
        !self.changed.is_empty()
    }

    /// The wire updates of every known cell (for a peer that rebuilds its map), and forgets
    /// the pending changes, which they include.
    pub fn take_full(&mut self) -> Vec<OemCellUpdate> {
        self.changed.clear();
        (0..self.cells.len())
            .filter(|&i| self.cells[i].status != OemStatus::Unknown)
            .map(|i| self.update_of(i))
            .collect()
    }

    fn update_of(&self, i: usize) -> OemCellUpdate {
        let (ix, iy) = self.index_of(i);
        let c = self.cells[i];
        OemCellUpdate {
            // The map grid is checked to fit u16 indices where maps are built from a config.
            ix: ix.min(u16::MAX as u32) as u16,
            iy: iy.min(u16::MAX as u32) as u16,
            status: c.status.code(),
            height_m: c.height_m,
        }
    }

    /// A map on `grid` holding exactly the given peer updates (cells not mentioned are
    /// unknown, the identity of the merge). Every update is validated.
    pub fn from_updates(
        grid: GroundGrid,
        updates: &[OemCellUpdate],
    ) -> Result<OccupancyMap, OemUpdateError> {
        let mut map = OccupancyMap::new(grid);
        for u in updates {
            let (index, cell) = Self::cell_of_update(&grid, u)?;
            map.merge_cell(index, cell);
        }
        map.changed.clear();
        Ok(map)
    }

    /// The cell a peer's update names on `grid`, validated: inside the grid, a defined status
    /// and a finite non-negative height (0 unless an obstacle).
    pub fn cell_of_update(
        grid: &GroundGrid,
        u: &OemCellUpdate,
    ) -> Result<(CellIndex, OemCell), OemUpdateError> {
        if u.ix as u32 >= grid.nx || u.iy as u32 >= grid.ny {
            return Err(OemUpdateError::OutOfRange {
                ix: u.ix,
                iy: u.iy,
                nx: grid.nx,
                ny: grid.ny,
            });
        }
        let status = OemStatus::from_code(u.status).ok_or(OemUpdateError::BadStatus(u.status))?;
        if !(u.height_m.is_finite() && u.height_m >= 0.0) {
            return Err(OemUpdateError::BadHeight(u.height_m));
        }
        let height_m = if status == OemStatus::Obstacle {
            u.height_m
        } else {
            0.0
        };
        Ok(((u.ix as u32, u.iy as u32), OemCell { status, height_m }))
    }

    /// Runs `f` on the map and returns, with its result, the updates of the cells it changed;
    /// the changes pending before stay pending, with these.
    pub fn tracked<R>(&mut self, f: impl FnOnce(&mut Self) -> R) -> (R, Vec<OemCellUpdate>) {
        let pending = std::mem::take(&mut self.changed);
        let result = f(self);
        let mine = std::mem::replace(&mut self.changed, pending);
        let updates = mine.iter().map(|&i| self.update_of(i as usize)).collect();
        self.changed.extend(mine);
        (result, updates)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cell_strategy() -> impl Strategy<Value = OemCell> {
        (0u8..3, 0.0f32..80.0).prop_map(|(s, h)| {
            let status = OemStatus::from_code(s).unwrap_or_default();
            OemCell {
                status,
                height_m: if status == OemStatus::Obstacle {
                    h
                } else {
                    0.0
                },
            }
        })
    }

    fn map_strategy() -> impl Strategy<Value = OccupancyMap> {
        let grid = GroundGrid::new(20.0, 5.0);
        proptest::collection::vec(cell_strategy(), grid.cell_count()).prop_map(move |cells| {
            let mut m = OccupancyMap::new(grid);
            for (i, c) in cells.into_iter().enumerate() {
                let idx = m.index_of(i);
                m.merge_cell(idx, c);
            }
            m.changed.clear();
            m
        })
    }

    fn merged(a: &OccupancyMap, b: &OccupancyMap) -> Vec<OemCell> {
        let mut m = a.clone();
        m.merge(b);
        m.cells
    }

    proptest! {
        #[test]
        fn merge_is_idempotent_commutative_associative(
            a in map_strategy(), b in map_strategy(), c in map_strategy()
        ) {
            prop_assert_eq!(merged(&a, &a), a.cells.clone());
            prop_assert_eq!(merged(&a, &b), merged(&b, &a));
            let mut ab = a.clone();
            ab.merge(&b);
            let mut bc = b.clone();
            bc.merge(&c);
            prop_assert_eq!(merged(&ab, &c), merged(&a, &bc));
        }

        #[test]
        fn updates_round_trip(a in map_strategy()) {
            let mut src = a.clone();
            let full = src.take_full();
            let rebuilt = OccupancyMap::from_updates(*a.grid(), &full).unwrap();
            prop_assert_eq!(rebuilt.cells, a.cells);
        }
    }

    #[test]
    fn ground_wins_and_heights_grow() {
        let mut m = OccupancyMap::new(GroundGrid::new(20.0, 5.0));
        let p = Point2::new(1.0, 1.0);
        assert!(m.observe_obstacle(&p, 12.0));
        assert!(m.observe_obstacle(&p, 20.0));
        assert!(!m.observe_obstacle(&p, 15.0));
        assert_eq!(m.cell_at(&p).unwrap().height_m, 20.0);
        let idx = m.grid().cell_of(&p).unwrap();
        assert!(m.observe_ground(idx));
        assert!(!m.observe_obstacle(&p, 30.0));
        assert_eq!(m.cell_at(&p).unwrap().status, OemStatus::Ground);
        assert_eq!(m.take_changes().len(), 1);
        assert!(m.take_changes().is_empty());
    }

    #[test]
    fn bad_updates_are_refused() {
        let grid = GroundGrid::new(20.0, 5.0);
        let ok = OemCellUpdate {
            ix: 1,
            iy: 2,
            status: 1,
            height_m: 3.0,
        };
        assert!(OccupancyMap::from_updates(grid, &[ok]).is_ok());
        let out = OemCellUpdate { ix: 8, ..ok };
        assert!(matches!(
            OccupancyMap::from_updates(grid, &[out]),
            Err(OemUpdateError::OutOfRange { .. })
        ));
        let bad = OemCellUpdate { status: 7, ..ok };
        assert_eq!(
            OccupancyMap::from_updates(grid, &[bad]),
            Err(OemUpdateError::BadStatus(7))
        );
        let nan = OemCellUpdate {
            height_m: f32::NAN,
            ..ok
        };
        assert!(matches!(
            OccupancyMap::from_updates(grid, &[nan]),
            Err(OemUpdateError::BadHeight(_))
        ));
    }
}
