//! The static city: the roads and the buildings, generated from the scenario's seed
//! ([`City::generate`]: a road grid and boxes) or imported from a scene file ([`City::import`]:
//! `fleet city`'s road network and buildings cut into convex parts).
//!
//! Invariant the traffic relies on: every building footprint is at least
//! [`RoadProfile::building_clearance`] (`targets.building_clearance_m`, at least `r_s`; by
//! default `r_s + r_t + margin`) away from every point a car's centre can reach: the grid's
//! lane centrelines, or the imported network's lanes, which stay within the lane offset of
//! road centrelines that the importer keeps the lane offset plus the clearance from every
//! building part ([`City::import`] checks the scene against the scenario). So a car's centre
//! always keeps at least `r_s` from every building, as the paper assumes, and by default more
//! than `r_s + r_t`, with its whole target cylinder clear too. The ground is flat at `z = 0`.

pub mod buildings;
pub mod roads;

use std::sync::Arc;

use city::scene::CityScene;
use protocol::scenario::Scenario;
use rand_chacha::ChaCha8Rng;
use sets::math::{Point2, Real};

pub use buildings::Building;
pub use roads::{Axis, Lane, RING_BORDER_GAP_M, RoadGrid, RoadProfile};

use crate::error::WorldBuildError;
use crate::render::prism::segment_distance;
use crate::traffic::network::LaneNetwork;

/// Slack on the checks of an imported scene against the scenario, metres (rounding only).
const SCENE_SLACK_M: Real = 1e-9;

/// The roads of a city, as the cars drive them.
#[derive(Clone, Debug)]
pub enum Roads {
    /// The generated city's grid.
    Grid(Arc<RoadGrid>),
    /// An imported city's road network.
    Network(Arc<LaneNetwork>),
}

impl Roads {
    /// The roads' centrelines, for pictures: the grid's roads across the region
    /// `[-half_extent, half_extent]²`, or the network's edges.
    pub fn centrelines(&self, half_extent: Real) -> Vec<(Point2, Point2)> {
        let h = half_extent;
        match self {
            Roads::Grid(grid) => (grid.xs.iter())
                .map(|&x| (Point2::new(x, -h), Point2::new(x, h)))
                .chain((grid.ys.iter()).map(|&y| (Point2::new(-h, y), Point2::new(h, y))))
                .collect(),
            Roads::Network(net) => net.centrelines().collect(),
        }
    }
}

/// The roads and the buildings of a run.
#[derive(Clone, Debug)]
pub struct City {
    /// Half the side of the square RoI `[-h, h]^2`.
    pub half_extent: Real,
    /// Widths and clearances of the roads.
    pub profile: RoadProfile,
    /// The roads.
    pub roads: Roads,
    /// The buildings, standing on the ground.
    pub buildings: Vec<Building>,
}

impl City {
    /// Generates the city of a scenario, deterministically from `rng`.
    pub fn generate(scenario: &Scenario, rng: &mut ChaCha8Rng) -> Result<City, WorldBuildError> {
        let r = &scenario.region;
        let h = r.half_extent_m;
        let profile = RoadProfile::for_scenario(scenario);
        let roads = RoadGrid::generate(h, profile, rng)?;
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
            profile,
            roads: Roads::Grid(Arc::new(roads)),
            buildings,
        })
    }

    /// The city of an imported scene, for the scenario's cars: the buildings' heights come
    /// from `[city]`'s storey and default heights where the map has no `height`. Refused when
    /// the scene does not fit the scenario: another region, lanes closer to their centrelines
    /// than these cars need, or road centrelines too close to a building or to the border for
    /// `targets.building_clearance_m` (the scene keeps what it was imported for; import it
    /// again with this scenario).
    pub fn import(scene: &CityScene, scenario: &Scenario) -> Result<City, WorldBuildError> {
        let h = scenario.region.half_extent_m;
        let profile = RoadProfile::for_scenario(scenario);
        let mismatch = |what: String| {
            Err(WorldBuildError::Scene(format!(
                "{what}; import the city again with this scenario (fleet city --scenario ...)"
            )))
        };
        if (scene.half_extent_m - h).abs() > SCENE_SLACK_M {
            return mismatch(format!(
                "the scene covers a half extent of {} m, region.half_extent_m is {h} m",
                scene.half_extent_m
            ));
        }
        let net = &scene.roads;
        if net.lane_offset_m < profile.lane_offset - SCENE_SLACK_M {
            return mismatch(format!(
                "the scene's lanes run {} m from their road's centreline, these cars need {} m",
                net.lane_offset_m, profile.lane_offset
            ));
        }
        let clearance = net.centreline_clearance_m - net.lane_offset_m;
        if clearance < profile.building_clearance - SCENE_SLACK_M {
            return mismatch(format!(
                "the scene keeps lanes {clearance} m from buildings, \
                 targets.building_clearance_m is {} m",
                profile.building_clearance
            ));
        }
        let inner = h - net.lane_offset_m;
        if net
            .points
            .iter()
            .any(|p| p[0].abs() > inner + SCENE_SLACK_M || p[1].abs() > inner + SCENE_SLACK_M)
        {
            return mismatch(format!(
                "a road of the scene runs closer than its lane offset ({} m) to the border",
                net.lane_offset_m
            ));
        }
        let c = &scenario.city;
        let buildings = scene
            .buildings
            .iter()
            .filter_map(|b| {
                let (height, _) = b.height(c.storey_height_m, c.default_height_m);
                let parts = b
                    .parts
                    .iter()
                    .map(|part| part.iter().map(|q| Point2::new(q[0], q[1])).collect())
                    .collect();
                Building::from_parts(parts, height)
            })
            .collect();
        Ok(City {
            half_extent: h,
            profile,
            roads: Roads::Network(Arc::new(LaneNetwork::new(net, profile.car_separation))),
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

    /// Whether a ground point lies on the paved roads: the grid's, or within the half width
    /// of a network's centreline.
    pub fn is_on_road(&self, p: &Point2) -> bool {
        match &self.roads {
            Roads::Grid(grid) => grid.is_on_road(p),
            Roads::Network(net) => net
                .centrelines()
                .any(|(a, b)| segment_distance(p, &a, &b) <= self.profile.half_width),
        }
    }

    /// The generated city's road grid (none for an imported city).
    pub fn grid(&self) -> Option<&RoadGrid> {
        match &self.roads {
            Roads::Grid(grid) => Some(grid),
            Roads::Network(_) => None,
        }
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
        let roads = c.grid().unwrap();
        let p = roads.profile;
        for b in &c.buildings {
            assert!(b.height >= 10.0 && b.height <= 60.0);
            for &x in &roads.xs {
                let d = (b.min.x - x).max(x - b.max.x);
                assert!(d >= p.lane_offset + p.building_clearance - 1e-9);
            }
            for &y in &roads.ys {
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
        let (a, b, c) = (city(11, 0.05), city(11, 0.05), city(12, 0.05));
        assert_eq!(a.buildings, b.buildings);
        assert_eq!(a.grid(), b.grid());
        assert_ne!(a.buildings, c.buildings);
    }
}
