//! The static city: the road grid and the buildings, generated from the scenario's seed.
//!
//! Invariant the traffic relies on: every building footprint is at least
//! [`RoadProfile::building_clearance`] (`targets.building_clearance_m`, at least `r_s`; by
//! default `r_s + r_t + margin`) away from every lane centreline, and a car's centre is always
//! on the road network's lane lines (see [`crate::traffic`]), so a car's centre always keeps
//! that clearance from every building: at least `r_s`, as the paper assumes, and by default
//! more than `r_s + r_t`, with its whole target cylinder clear too. The ground is flat at
//! `z = 0`.

pub mod buildings;
pub mod roads;

use protocol::scenario::Scenario;
use rand_chacha::ChaCha8Rng;
use sets::math::Real;

pub use buildings::Building;
pub use roads::{Axis, Lane, RING_BORDER_GAP_M, RoadGrid, RoadProfile};

use crate::error::WorldBuildError;

/// The road grid and the buildings of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct City {
    /// Half the side of the square RoI `[-h, h]^2`.
    pub half_extent: Real,
    /// The roads.
    pub roads: RoadGrid,
    /// The buildings (axis-aligned, standing on the ground).
    pub buildings: Vec<Building>,
}

impl City {
    /// Generates the city of a scenario, deterministically from `rng`.
    pub fn generate(scenario: &Scenario, rng: &mut ChaCha8Rng) -> Result<City, WorldBuildError> {
        let r = &scenario.region;
        let h = r.half_extent_m;
        let roads = RoadGrid::generate(h, RoadProfile::for_scenario(scenario), rng)?;
        let ground_area = 4.0 * h * h;
        let buildings = buildings::generate(
            &roads,
            ground_area,
            r.building_fraction,
            r.building_height_m,
            r.lot_size_m,
            rng,
        )?;
        Ok(City {
            half_extent: h,
            roads,
            buildings,
        })
    }

    /// Height of the tallest building (0 without buildings).
    pub fn tallest(&self) -> Real {
        self.buildings.iter().map(|b| b.height).fold(0.0, Real::max)
    }

    /// Share of the RoI's ground under buildings.
    pub fn building_fraction(&self) -> Real {
        let area: Real = self.buildings.iter().map(Building::area).sum();
        area / (4.0 * self.half_extent * self.half_extent)
    }

    /// Whether a ground point lies inside the RoI.
    pub fn contains(&self, x: Real, y: Real) -> bool {
        x.abs() <= self.half_extent && y.abs() <= self.half_extent
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;

    use super::*;

    fn city(seed: u64, fraction: Real) -> City {
        let mut s = Scenario::default();
        s.region.building_fraction = fraction;
        City::generate(&s, &mut ChaCha8Rng::seed_from_u64(seed)).unwrap()
    }

    #[test]
    fn buildings_cover_the_requested_fraction() {
        for (seed, f) in [(1, 0.05), (2, 0.0), (3, 0.2), (4, 0.4)] {
            let c = city(seed, f);
            assert!(
                (c.building_fraction() - f).abs() < 1e-6,
                "{f}: {}",
                c.building_fraction()
            );
            if f == 0.0 {
                assert!(c.buildings.is_empty());
            }
        }
    }

    #[test]
    fn buildings_keep_clear_of_every_lane_and_each_other() {
        let c = city(7, 0.1);
        let p = c.roads.profile;
        for b in &c.buildings {
            assert!(b.height >= 10.0 && b.height <= 60.0);
            for &x in &c.roads.xs {
                let d = (b.min.x - x).max(x - b.max.x);
                assert!(d >= p.lane_offset + p.building_clearance - 1e-9);
            }
            for &y in &c.roads.ys {
                let d = (b.min.y - y).max(y - b.max.y);
                assert!(d >= p.lane_offset + p.building_clearance - 1e-9);
            }
        }
        for (i, a) in c.buildings.iter().enumerate() {
            for b in &c.buildings[i + 1..] {
                let overlap = a.min.x < b.max.x
                    && b.min.x < a.max.x
                    && a.min.y < b.max.y
                    && b.min.y < a.max.y;
                assert!(!overlap);
            }
        }
    }

    #[test]
    fn too_many_buildings_are_refused() {
        let mut s = Scenario::default();
        s.region.building_fraction = 0.9;
        let e = City::generate(&s, &mut ChaCha8Rng::seed_from_u64(1));
        assert!(matches!(e, Err(WorldBuildError::Placement(_))));
    }

    #[test]
    fn same_seed_same_city() {
        assert_eq!(city(11, 0.05), city(11, 0.05));
        assert_ne!(city(11, 0.05), city(12, 0.05));
    }
}
