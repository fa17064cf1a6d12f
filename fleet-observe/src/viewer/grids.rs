//! The sets and the map as `foxglove.Grid`s on the ground plane of the `world` frame.
//!
//! A set grid has one `uint8` field, `value`: 1 on a cell that meets the set, 0 elsewhere.
//! The large layers (`X̄`, `S^o`, `H̄`, explored) are coarsened to at most [`MAX_SIDE`] cells
//! a side, a coarse cell holding 1 when any of its fine cells is in the set, so a set never
//! looks smaller than it is; a target set `X_j` is sent at the estimator's own resolution
//! over its bounding box (coarsened too only if that box is wider than [`MAX_SIDE`] cells).

use estimator::occupancy::OccupancyMap;
use foxglove::messages::{
    Grid, PackedElementField, Pose, Quaternion, Timestamp, Vector2, Vector3,
    packed_element_field::NumericType,
};
use sets::grid::GroundGrid;
use sets::math::Point2;
use sets::raster::{CellBox, CellSet};

use super::topics::WORLD_FRAME;

/// Most cells along a side of a grid sent.
pub const MAX_SIDE: u32 = 200;
/// Height of the set layers above the ground, metres, so they do not flicker with it.
const LAYER_Z: f64 = 0.05;

/// Fine cells per coarse cell along a side, for a box `side` fine cells wide.
pub fn coarsening(side: u32) -> u32 {
    side.div_ceil(MAX_SIDE).max(1)
}

/// `set` over the whole grid, coarsened to at most [`MAX_SIDE`] cells a side.
pub fn whole_set(set: &CellSet, grid: &GroundGrid, stamp: Timestamp) -> Grid {
    let all = CellBox {
        x0: 0,
        y0: 0,
        x1: grid.nx - 1,
        y1: grid.ny - 1,
    };
    set_grid(set, grid, all, coarsening(grid.nx.max(grid.ny)), stamp)
}

/// `set` over its own bounding box, at the grid's resolution unless the box is wider than
/// [`MAX_SIDE`]; `None` for an empty set.
pub fn set_extent(set: &CellSet, grid: &GroundGrid, stamp: Timestamp) -> Option<Grid> {
    let bbox = set.bounding_box()?;
    let side = (bbox.x1 - bbox.x0 + 1).max(bbox.y1 - bbox.y0 + 1);
    Some(set_grid(set, grid, bbox, coarsening(side), stamp))
}

/// The cells of `area` as a grid whose cell is `factor` fine cells a side; 1 where any fine
/// cell under it is in `set`.
fn set_grid(
    set: &CellSet,
    grid: &GroundGrid,
    area: CellBox,
    factor: u32,
    stamp: Timestamp,
) -> Grid {
    let columns = (area.x1 - area.x0 + 1).div_ceil(factor);
    let rows = (area.y1 - area.y0 + 1).div_ceil(factor);
    let cell = grid.cell_m * f64::from(factor);
    let corner = [
        grid.origin.x + f64::from(area.x0) * grid.cell_m,
        grid.origin.y + f64::from(area.y0) * grid.cell_m,
    ];
    let blocks = GroundGrid {
        origin: Point2::new(corner[0], corner[1]),
        cell_m: cell,
        nx: columns,
        ny: rows,
    };
    let mut data = vec![0u8; columns as usize * rows as usize];
    for (c, r) in set.coarsen_any(&area, factor, &blocks).iter() {
        data[r as usize * columns as usize + c as usize] = 1;
    }
    Grid {
        timestamp: Some(stamp),
        frame_id: WORLD_FRAME.into(),
        pose: Some(ground_pose(corner, LAYER_Z)),
        column_count: columns,
        cell_size: Some(Vector2 { x: cell, y: cell }),
        row_stride: columns,
        cell_stride: 1,
        fields: vec![field("value", 0, NumericType::Uint8)],
        data: data.into(),
    }
}

/// The occupancy elevation map: per cell `height_m` (float32, at byte 0) and `status`
/// (uint8 at byte 4: 0 unknown, 1 obstacle, 2 ground), 8 bytes a cell.
pub fn oem(map: &OccupancyMap, stamp: Timestamp) -> Grid {
    const STRIDE: usize = 8;
    let grid = map.grid();
    let mut data = vec![0u8; grid.cell_count() * STRIDE];
    for ((ix, iy), cell) in map.known_cells() {
        let at = (iy as usize * grid.nx as usize + ix as usize) * STRIDE;
        data[at..at + 4].copy_from_slice(&cell.height_m.to_le_bytes());
        data[at + 4] = cell.status.code();
    }
    Grid {
        timestamp: Some(stamp),
        frame_id: WORLD_FRAME.into(),
        pose: Some(ground_pose([grid.origin.x, grid.origin.y], 0.0)),
        column_count: grid.nx,
        cell_size: Some(Vector2 {
            x: grid.cell_m,
            y: grid.cell_m,
        }),
        row_stride: grid.nx * STRIDE as u32,
        cell_stride: STRIDE as u32,
        fields: vec![
            field("height_m", 0, NumericType::Float32),
            field("status", 4, NumericType::Uint8),
        ],
        data: data.into(),
    }
}

fn field(name: &str, offset: u32, kind: NumericType) -> PackedElementField {
    PackedElementField {
        name: name.into(),
        offset,
        r#type: kind as i32,
    }
}

/// A pose on the ground plane at `corner`, height `z`, unrotated.
fn ground_pose(corner: [f64; 2], z: f64) -> Pose {
    Pose {
        position: Some(Vector3 {
            x: corner[0],
            y: corner[1],
            z,
        }),
        orientation: Some(Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> GroundGrid {
        GroundGrid::new(50.0, 0.5)
    }

    fn value_at(g: &Grid, column: u32, row: u32) -> u8 {
        g.data[(row * g.row_stride + column * g.cell_stride) as usize]
    }

    #[test]
    fn a_coarse_cell_holds_any_fine_cell_of_the_set() {
        let grid = grid();
        // 200 fine cells a side fit MAX_SIDE: no coarsening; 1000 would be 5 to 1.
        assert_eq!(coarsening(grid.nx), 1);
        assert_eq!(coarsening(1000), 5);
        assert_eq!(coarsening(1001), 6);
        let set = CellSet::from_cells(&grid, [(7, 3), (130, 199)]);
        let g = whole_set(&set, &grid, Timestamp::new(0, 0));
        assert_eq!(g.column_count, 200);
        assert_eq!(g.data.len(), 200 * 200);
        assert_eq!(value_at(&g, 7, 3), 1);
        assert_eq!(value_at(&g, 130, 199), 1);
        assert_eq!(g.data.iter().filter(|&&v| v == 1).count(), 2);
    }

    #[test]
    fn a_target_set_is_sent_over_its_box_at_full_resolution() {
        let grid = grid();
        let set = CellSet::from_cells(&grid, [(10, 20), (12, 21), (64, 20)]);
        let g = set_extent(&set, &grid, Timestamp::new(1, 0)).expect("not empty");
        assert_eq!(g.column_count, 55);
        assert_eq!(g.data.len(), 55 * 2);
        assert_eq!(g.cell_size.map(|c| c.x), Some(0.5));
        let corner = g.pose.and_then(|p| p.position).expect("pose");
        assert_eq!((corner.x, corner.y), (-50.0 + 5.0, -50.0 + 10.0));
        assert_eq!(value_at(&g, 0, 0), 1);
        assert_eq!(value_at(&g, 2, 1), 1);
        assert_eq!(value_at(&g, 54, 0), 1);
        assert_eq!(value_at(&g, 1, 0), 0);
        assert!(set_extent(&CellSet::empty(&grid), &grid, Timestamp::new(0, 0)).is_none());
    }

    #[test]
    fn a_coarse_set_keeps_every_cell_of_a_large_one() {
        // 1000 fine cells a side, coarsened 5 to 1: every fine cell lands in its coarse cell.
        let grid = GroundGrid::new(250.0, 0.5);
        let cells: Vec<_> = (0..1000)
            .step_by(37)
            .flat_map(|x| [(x, 999 - x), (x, x)])
            .collect();
        let set = CellSet::from_cells(&grid, cells.iter().copied());
        let g = whole_set(&set, &grid, Timestamp::new(0, 0));
        assert_eq!(g.column_count, 200);
        for &(x, y) in &cells {
            assert_eq!(value_at(&g, x / 5, y / 5), 1, "cell ({x}, {y})");
        }
    }
}
