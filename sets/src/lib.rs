//! # sets
//!
//! The sets of setfleet and the mathematics that keeps their guarantee: a target is never
//! outside its set.
//!
//! - [`math`]: geometry aliases over nalgebra (`Point2`, `Point3`, `Vector3`, `Isometry3`;
//!   `f64`).
//! - [`grid`]: the ground grid ([`grid::GroundGrid`]): cells of the region, their centres and
//!   the cells a point or a box falls in.
//! - [`raster`]: the bit-raster [`raster::CellSet`] with the algebra of the sets (union,
//!   intersection, inner and outer coverage of shapes, dilation by the motion, run-length
//!   encoding and deltas), and the sets that grow by exactly the motion ([`raster::reach`],
//!   [`raster::geodesic`]).
//!
//! Each module argues its invariant in its docs; the proptests in `sets/tests/` check them
//! against continuous geometry.
//!
//! ```
//! use sets::grid::GroundGrid;
//! use sets::math::Point2;
//! use sets::raster::{CellSet, Coverage};
//!
//! // A region of 20 m x 20 m in cells of 0.5 m.
//! let grid = GroundGrid::new(10.0, 0.5);
//! let mut seen = CellSet::empty(&grid);
//! seen.fill_disc(&grid, Point2::new(0.0, 0.0), 3.0, Coverage::Outer);
//! // Every cell of the disc's edge is in the set (outer coverage).
//! let cell = grid.cell_of(&Point2::new(2.9, 0.0)).expect("inside the region");
//! assert!(seen.contains(cell));
//! // A set grown by a target's motion holds the set it grew from.
//! assert!(seen.is_subset_of(&seen.dilate(&grid, 1.0)));
//! ```

pub mod grid;
pub mod math;
pub mod raster;
