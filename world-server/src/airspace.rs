//! The UAVs: constant speed and altitude, yaw following a reference through
//! [`protocol::flight::advance`], and a geofence that keeps them inside the RoI.

use std::f64::consts::{FRAC_PI_4, PI, TAU};

use protocol::flight::{UavState, advance};
use protocol::scenario::Scenario;
use sets::math::{Point3, Real};

use crate::error::WorldBuildError;

/// One UAV.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Uav {
    /// Position of the optical centre and yaw.
    pub state: UavState,
    /// The yaw reference last commanded.
    pub commanded_yaw_ref: Real,
    /// The yaw reference followed in the last step: the commanded one, or the geofence's.
    pub yaw_ref: Real,
}

/// The UAVs in the air and their flight parameters.
#[derive(Clone, Debug)]
pub struct Airspace {
    uavs: Vec<Uav>,
    speed: Real,
    max_yaw_rate: Real,
    fence: Real,
}

impl Airspace {
    /// The UAVs at their start: UAV `i` evenly spaced on a circle inside the geofence, heading
    /// to the centre of the RoI, at [`Scenario::uav_altitude`] (`altitudes_m[i]` or, when the
    /// scenario gives none, `tallest + 20 + 10 i` m).
    pub fn launch(
        scenario: &Scenario,
        tallest_building: Real,
    ) -> Result<Airspace, WorldBuildError> {
        let u = &scenario.uavs;
        let n = u.count as usize;
        if !u.altitudes_m.is_empty() && u.altitudes_m.len() < n {
            return Err(WorldBuildError::Placement(format!(
                "uavs.altitudes_m has {} values for uavs.count = {n}",
                u.altitudes_m.len()
            )));
        }
        let fence = scenario.geofence_half_extent();
        let radius = 0.9 * fence;
        let uavs = (0..n)
            .map(|i| {
                let z = scenario.uav_altitude(i, tallest_building);
                let bearing = FRAC_PI_4 + TAU * i as Real / n as Real;
                let yaw = sets::math::wrap_angle(bearing + PI);
                Uav {
                    state: UavState {
                        position: Point3::new(radius * bearing.cos(), radius * bearing.sin(), z),
                        yaw,
                    },
                    commanded_yaw_ref: yaw,
                    yaw_ref: yaw,
                }
            })
            .collect();
        Ok(Airspace {
            uavs,
            speed: u.speed_mps,
            max_yaw_rate: u.max_yaw_rate_rps,
            fence,
        })
    }

    /// The UAVs, by index.
    pub fn uavs(&self) -> &[Uav] {
        &self.uavs
    }

    /// Sets UAV `i`'s commanded yaw reference (ignored for an unknown index or a non-finite
    /// value).
    pub fn command(&mut self, i: usize, yaw_ref: Real) {
        if let Some(u) = self.uavs.get_mut(i)
            && yaw_ref.is_finite()
        {
            u.commanded_yaw_ref = sets::math::wrap_angle(yaw_ref);
        }
    }

    /// Moves UAV `i` to `state` (for tools and tests that need a given viewpoint).
    pub fn teleport(&mut self, i: usize, state: UavState) {
        if let Some(u) = self.uavs.get_mut(i) {
            u.state = state;
            u.yaw_ref = state.yaw;
            u.commanded_yaw_ref = state.yaw;
        }
    }

    /// Advances every UAV by `dt`. Geofence: when the commanded reference would take a UAV
    /// outside the fence square `[-f, f]^2` within this step, the UAV follows the bearing to
    /// the RoI's centre instead. The fence lies far enough inside the RoI (two turn radii and
    /// a step) that a UAV turning back at its largest rate never leaves the RoI.
    pub fn step(&mut self, dt: Real) {
        for (i, u) in self.uavs.iter_mut().enumerate() {
            let ahead = advance(
                u.state,
                u.commanded_yaw_ref,
                dt,
                self.speed,
                self.max_yaw_rate,
            );
            let p = ahead.position;
            u.yaw_ref = if p.x.abs() > self.fence || p.y.abs() > self.fence {
                let home = (-u.state.position.y).atan2(-u.state.position.x);
                tracing::debug!(
                    uav = i,
                    commanded = u.commanded_yaw_ref,
                    home,
                    "geofence: UAV turned back toward the centre"
                );
                home
            } else {
                u.commanded_yaw_ref
            };
            u.state = advance(u.state, u.yaw_ref, dt, self.speed, self.max_yaw_rate);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uavs_stay_inside_the_region_whatever_they_are_told() {
        let s = Scenario::default();
        let mut f = Airspace::launch(&s, 60.0).unwrap();
        // Always steer straight out of the RoI.
        for _ in 0..2000 {
            for i in 0..f.uavs().len() {
                let p = f.uavs()[i].state.position;
                f.command(i, p.y.atan2(p.x));
            }
            f.step(0.5);
            for u in f.uavs() {
                let p = u.state.position;
                assert!(p.x.abs() < 250.0 && p.y.abs() < 250.0, "{p:?}");
            }
        }
    }

    /// A command that keeps a UAV inside the geofence (the square the MPC plans in with
    /// `guidance.border = "geofence"`) is flown as given; one that would cross it is
    /// overridden, and the override is what the truth reports
    /// ([`protocol::wire::UavTruth::geofence_override`]).
    #[test]
    fn only_commands_crossing_the_geofence_are_overridden() {
        let s = Scenario::default();
        let fence = s.geofence_half_extent();
        let mut f = Airspace::launch(&s, 60.0).unwrap();
        let at = |x: Real| UavState {
            position: Point3::new(x, 0.0, 80.0),
            yaw: 0.0,
        };
        // Heading east, 10 m inside the fence: a 5 m step stays inside.
        f.teleport(0, at(fence - 10.0));
        f.command(0, 0.0);
        f.step(0.5);
        let u = f.uavs()[0];
        assert_eq!(u.yaw_ref, u.commanded_yaw_ref);
        assert!(u.state.position.x <= fence);
        // 2 m inside: the step would cross the fence, and the world turns it back instead.
        f.teleport(0, at(fence - 2.0));
        f.command(0, 0.0);
        f.step(0.5);
        let u = f.uavs()[0];
        assert_ne!(u.yaw_ref, u.commanded_yaw_ref);
    }

    #[test]
    fn default_altitudes_are_distinct_and_above_buildings() {
        let s = Scenario::default();
        let f = Airspace::launch(&s, 57.0).unwrap();
        let z: Vec<Real> = f.uavs().iter().map(|u| u.state.position.z).collect();
        assert_eq!(z, vec![77.0, 87.0, 97.0, 107.0]);
    }
}
