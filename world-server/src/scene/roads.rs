//! The road grid: straight two-lane roads along x and y, crossing at every intersection, with
//! an outer ring road inside the RoI border so that a car never has to leave the RoI.

use protocol::scenario::Scenario;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use sets::math::{Point2, Real, Vector2};

use crate::error::WorldBuildError;

/// Typical distance between neighbouring parallel roads (a block of about 50 m plus a road).
const TYPICAL_ROAD_SPACING_M: Real = 58.0;
/// Largest random shift of an inner road from its regular position.
const ROAD_JITTER_M: Real = 4.0;
/// Gap kept between the ring road's edge and the RoI border.
pub const RING_BORDER_GAP_M: Real = 2.0;
/// Extra distance, beyond what the rules ask, between cars and between a car and a building.
pub const SAFETY_MARGIN_M: Real = 0.5;

/// Which way a road runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Axis {
    /// East-west: the road is the line `y = ys[k]`.
    X,
    /// North-south: the road is the line `x = xs[k]`.
    Y,
}

impl Axis {
    /// The other axis.
    pub fn other(self) -> Axis {
        match self {
            Axis::X => Axis::Y,
            Axis::Y => Axis::X,
        }
    }
}

/// One direction of travel on one road. Traffic keeps right: the lane's centreline is
/// offset from the road's centreline by [`RoadProfile::lane_offset`] to the right of the heading.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Lane {
    /// Which way the road runs.
    pub axis: Axis,
    /// Index of the road in [`RoadGrid::ys`] (axis X) or [`RoadGrid::xs`] (axis Y).
    pub road: usize,
    /// `+1` toward increasing coordinate along `axis`, `-1` the other way.
    pub dir: i8,
}

impl Lane {
    /// The lane of the same road in the opposite direction.
    pub fn opposite(self) -> Lane {
        Lane {
            dir: -self.dir,
            ..self
        }
    }

    /// Unit heading of travel.
    pub fn heading(self) -> Vector2 {
        let d = self.dir as Real;
        match self.axis {
            Axis::X => Vector2::new(d, 0.0),
            Axis::Y => Vector2::new(0.0, d),
        }
    }
}

/// Widths and clearances of the roads, derived from the cars and the safety distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoadProfile {
    /// Distance from a road's centreline to each lane's centreline.
    pub lane_offset: Real,
    /// Half the width of the paved road.
    pub half_width: Real,
    /// Smallest distance between a building and any lane centreline.
    pub building_clearance: Real,
    /// Smallest centre-to-centre distance between two cars.
    pub car_separation: Real,
}

impl RoadProfile {
    /// The profile a scenario needs.
    ///
    /// - cars keep `car_separation = max(r_s, car length) + margin` centre to centre, and the
    ///   two lanes of a road are more than that apart, so that cars passing each other in
    ///   opposite directions never come too close;
    /// - a building keeps `building_clearance = targets.building_clearance_m` (at least
    ///   `r_s`; by default `r_s + r_t + margin`) from every lane centreline, and a car's centre
    ///   is always on a lane centreline (see [`crate::traffic`]), so the car's centre stays
    ///   that far from every building (by default its whole target cylinder of radius `r_t`
    ///   stays clear too).
    pub fn for_scenario(scenario: &Scenario) -> RoadProfile {
        let t = &scenario.targets;
        let [length, width, _] = t.size_m;
        let car_separation = t.safety_distance_m.max(length) + SAFETY_MARGIN_M;
        let lane_offset = (car_separation / 2.0 + SAFETY_MARGIN_M / 2.0).max(2.0);
        let half_width = (lane_offset + width / 2.0 + SAFETY_MARGIN_M).max(4.0);
        RoadProfile {
            lane_offset,
            half_width,
            building_clearance: t.building_clearance_m,
            car_separation,
        }
    }

    /// Distance from a road's centreline to the nearest point a building may occupy.
    pub fn building_setback(&self) -> Real {
        (self.lane_offset + self.building_clearance).max(self.half_width)
    }
}

/// The road network: full-length roads along x at `ys` and along y at `xs`; the first and last
/// of each are the ring road.
#[derive(Clone, Debug, PartialEq)]
pub struct RoadGrid {
    /// `x` of the north-south roads, ascending.
    pub xs: Vec<Real>,
    /// `y` of the east-west roads, ascending.
    pub ys: Vec<Real>,
    /// Widths and clearances.
    pub profile: RoadProfile,
}

impl RoadGrid {
    /// Lays out the grid over `[-half_extent, half_extent]^2`: the ring road sits inside the
    /// border, the inner roads are spaced about 58 m apart (blocks of about 50 m) with a random
    /// jitter.
    pub fn generate(
        half_extent: Real,
        profile: RoadProfile,
        rng: &mut ChaCha8Rng,
    ) -> Result<RoadGrid, WorldBuildError> {
        let ring = half_extent - profile.half_width - RING_BORDER_GAP_M;
        let needed = 2.0 * profile.lane_offset + profile.car_separation;
        if ring.is_nan() || ring < needed {
            return Err(WorldBuildError::Placement(format!(
                "region.half_extent_m = {half_extent} is too small for a ring road of half width \
                 {} m",
                profile.half_width
            )));
        }
        let xs = Self::lines(ring, rng);
        let ys = Self::lines(ring, rng);
        Ok(RoadGrid { xs, ys, profile })
    }

    fn lines(ring: Real, rng: &mut ChaCha8Rng) -> Vec<Real> {
        let span = 2.0 * ring;
        let n = (span / TYPICAL_ROAD_SPACING_M).round().max(1.0) as usize;
        let spacing = span / n as Real;
        let jitter = ROAD_JITTER_M.min(0.08 * spacing);
        (0..=n)
            .map(|i| {
                let base = -ring + i as Real * spacing;
                if i == 0 || i == n {
                    base
                } else {
                    base + rng.random_range(-jitter..=jitter)
                }
            })
            .collect()
    }

    /// Centreline coordinates of the roads running along `axis` (`ys` for X, `xs` for Y).
    pub fn roads(&self, axis: Axis) -> &[Real] {
        match axis {
            Axis::X => &self.ys,
            Axis::Y => &self.xs,
        }
    }

    /// Coordinates along `axis` where the roads running the other way cross.
    pub fn crossings(&self, axis: Axis) -> &[Real] {
        self.roads(axis.other())
    }

    /// Coordinate of a lane's centreline across its axis (its `y` for axis X, `x` for Y).
    pub fn lane_line(&self, lane: Lane) -> Real {
        let c = self.roads(lane.axis)[lane.road];
        let off = self.profile.lane_offset * lane.dir as Real;
        match lane.axis {
            Axis::X => c - off,
            Axis::Y => c + off,
        }
    }

    /// The point of a lane's centreline at coordinate `s` along its axis.
    pub fn point_on_lane(&self, lane: Lane, s: Real) -> Point2 {
        let l = self.lane_line(lane);
        match lane.axis {
            Axis::X => Point2::new(s, l),
            Axis::Y => Point2::new(l, s),
        }
    }

    /// Coordinate of `p` along `axis`.
    pub fn along(axis: Axis, p: &Point2) -> Real {
        match axis {
            Axis::X => p.x,
            Axis::Y => p.y,
        }
    }

    /// Whether a ground point lies on the paved roads.
    pub fn is_on_road(&self, p: &Point2) -> bool {
        let hw = self.profile.half_width;
        let (Some(&x0), Some(&x1), Some(&y0), Some(&y1)) = (
            self.xs.first(),
            self.xs.last(),
            self.ys.first(),
            self.ys.last(),
        ) else {
            return false;
        };
        let in_x = p.x >= x0 - hw && p.x <= x1 + hw;
        let in_y = p.y >= y0 - hw && p.y <= y1 + hw;
        (in_x && self.ys.iter().any(|y| (p.y - y).abs() <= hw))
            || (in_y && self.xs.iter().any(|x| (p.x - x).abs() <= hw))
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;

    use super::*;

    #[test]
    fn grid_has_ring_inside_region_and_blocks_of_about_fifty_metres() {
        let s = Scenario::default();
        let p = RoadProfile::for_scenario(&s);
        let g = RoadGrid::generate(250.0, p, &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
        for v in [&g.xs, &g.ys] {
            assert!(v.first().unwrap() - p.half_width > -250.0);
            assert!(v.last().unwrap() + p.half_width < 250.0);
            for w in v.windows(2) {
                let block = w[1] - w[0] - 2.0 * p.half_width;
                assert!((35.0..65.0).contains(&block), "{block}");
            }
        }
        // Opposite lanes are farther apart than the car separation.
        assert!(2.0 * p.lane_offset > p.car_separation);
    }

    #[test]
    fn lanes_keep_right() {
        let s = Scenario::default();
        let p = RoadProfile::for_scenario(&s);
        let g = RoadGrid::generate(250.0, p, &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
        let east = Lane {
            axis: Axis::X,
            road: 2,
            dir: 1,
        };
        assert!(g.lane_line(east) < g.ys[2]);
        let north = Lane {
            axis: Axis::Y,
            road: 2,
            dir: 1,
        };
        assert!(g.lane_line(north) > g.xs[2]);
        assert!(g.is_on_road(&g.point_on_lane(north, 13.0)));
    }

    #[test]
    fn tiny_region_is_refused() {
        let s = Scenario::default();
        let p = RoadProfile::for_scenario(&s);
        assert!(RoadGrid::generate(8.0, p, &mut ChaCha8Rng::seed_from_u64(3)).is_err());
    }
}
