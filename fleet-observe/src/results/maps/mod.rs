//! `map.png` and `sets.png`: what the fleet knows at the end of a run, seen from above.
//!
//! - [`draw_map`]: the fused occupancy elevation map (the paper's Fig. 7 from above), unknown
//!   cells grey, ground pale green, obstacles coloured by height, with the true building
//!   outlines over it for comparison.
//! - [`draw_sets`]: one agent's final fused sets over the city (the lowest id measured at the
//!   last step; with perfect links every agent holds the same sets but `H̄`): explored
//!   ground, `S^o`, `H̄`, `X̄`, each `X_j`, the true targets and the UAV tracks.
//!
//! Both share one layout (`chart`): a title line, a square chart of the region in metres and
//! a legend panel on the right (`legend`). The cell layers are composed per pixel into one
//! bitmap (`raster`; the set grid has up to a million cells, far more than the chart has
//! pixels) blitted under the vector overlays. A set is drawn at a pixel when any cell the
//! pixel touches belongs to it, so sets smaller than a pixel still show; the coarse map is
//! sampled at pixel centres.

mod animation;
mod chart;
#[cfg(test)]
mod fixtures;
mod legend;
mod map;
mod raster;
mod sets;

pub use animation::{Animation, AnimationError, AnimationSink, FRAME_PERIOD_S};
pub use map::draw_map;
pub use sets::draw_sets;
