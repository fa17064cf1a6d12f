//! Weights that follow the scenario (`guidance.adapt_weights`, the `setfleet` planner).
//!
//! The `setfleet` weights were chosen on the default scenario (`docs/results/setfleet.md`).
//! Each of them has units, and the quantity it trades against changes with the scenario: the
//! camera's footprint (with the altitude the fleet flies at, which follows the buildings and
//! the number of UAVs), and the targets' speed. With
//! `guidance.adapt_weights = true` the weights given are read as the default scenario's, and
//! each is multiplied by the ratio of the quantity it stands for, this scenario's over the
//! default's. On the default scenario every ratio is 1, so the planner is exactly the tuned
//! one; elsewhere nothing is tuned, only scaled:
//!
//! | weight | stands for | scaled by |
//! |---|---|---|
//! | `lambda`, m² per m | the ground one metre of flight sweeps: the footprint's width | `W / W₀` |
//! | `spread_m`, m | two footprints overlapping: the footprint's width | `W / W₀` |
//! | `track_revisit_s`, s | the radius `v T` a car's set may reach before it is revisited: the localisation error allowed | `v₀ / v` |
//!
//! `growth_horizon_s` stays as given: it charges the growth a pocket left behind adds within
//! a couple of the planner's lookaheads, seconds of the UAV's own flight in every scenario.
//! Scaling it too, by the time the fleet takes to sweep the region once (`A / (n W V)`, 1.65
//! times the default's on `scenarios/suite/large-region.toml`), did not help there: seeds
//! 1-2 ended at 47.6 % UA and 25.3 m of error against 41.2 % and 10.9 m without it, a
//! difference two seeds cannot measure (`docs/results/setfleet.md`).
//!
//! `W` is the mean width (area over depth) of the footprint of the camera in level flight at
//! the fleet's nominal altitude ([`Scenario::nominal_altitude`]: the tallest building the
//! scenario allows, plus the clearance and steps), and `v` the targets' speed bound. The
//! dimensionless weights (`target_weight`, the beam, the lookahead) stay as given. Only
//! decisions change, so the guarantee does not depend on any of this.
//!
//! The scenario keeps the weights as given ([`protocol::scenario::SetfleetConfig`]); the
//! planner multiplies each by its factor ([`WeightFactors`]) where it uses it.

use protocol::camera::{Camera, CameraPose};
use protocol::scenario::{Planner, Scenario};
use sets::math::Point3;

/// The quantities the `setfleet` weights trade against, for one scenario.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scale {
    /// Mean width of the camera's footprint in level flight at the nominal altitude, m.
    pub footprint_width_m: f64,
    /// The targets' speed bound, m/s.
    pub target_speed_mps: f64,
}

impl Scale {
    /// The quantities of `scenario`, or `None` when its camera misses the ground in level
    /// flight (no footprint to scale by).
    pub fn of(scenario: &Scenario) -> Option<Scale> {
        let level = CameraPose {
            position: Point3::new(0.0, 0.0, scenario.nominal_altitude()),
            yaw: 0.0,
        };
        let camera = Camera::new(scenario.camera_model(), level);
        let footprint_width_m = camera.ground_footprint_width();
        if footprint_width_m <= 0.0 {
            return None;
        }
        Some(Scale {
            footprint_width_m,
            target_speed_mps: scenario.targets.max_speed_mps,
        })
    }

    /// The default scenario's, which the weights given are read against.
    pub fn reference() -> Option<Scale> {
        Scale::of(&Scenario::default())
    }

    /// The factors that scale the weights given for `reference` to `self` (the module's
    /// table). A ratio that is not finite and positive (a zero speed) leaves its weights as
    /// given.
    pub fn factors(&self, reference: &Scale) -> WeightFactors {
        let ratio = |num: f64, den: f64| {
            let r = num / den;
            if r.is_finite() && r > 0.0 { r } else { 1.0 }
        };
        WeightFactors {
            width: ratio(self.footprint_width_m, reference.footprint_width_m),
            speed: ratio(reference.target_speed_mps, self.target_speed_mps),
        }
    }
}

/// What the weights given are multiplied by where the planner uses them (the module's
/// table): 1 each unless the `setfleet` planner adapts its weights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WeightFactors {
    /// `W / W₀`, of `lambda` and `spread_m`.
    pub width: f64,
    /// `v₀ / v`, of `track_revisit_s`.
    pub speed: f64,
}

impl WeightFactors {
    /// The weights as given.
    pub const GIVEN: WeightFactors = WeightFactors {
        width: 1.0,
        speed: 1.0,
    };

    /// The factors of `scenario`: scaled to it when its planner is `setfleet` with
    /// `guidance.adapt_weights` (and its camera sees the ground in level flight), else
    /// [`WeightFactors::GIVEN`]. The paper's MPC never adapts its `lambda`.
    pub fn of(scenario: &Scenario) -> WeightFactors {
        let guidance = &scenario.guidance;
        if guidance.setfleet.adapt_weights
            && guidance.planner == Planner::Setfleet
            && let (Some(scale), Some(reference)) = (Scale::of(scenario), Scale::reference())
        {
            scale.factors(&reference)
        } else {
            WeightFactors::GIVEN
        }
    }

    /// `lambda` as the planner uses it.
    pub fn lambda(&self, given: f64) -> f64 {
        given * self.width
    }

    /// `spread_m` as the planner uses it.
    pub fn spread_m(&self, given: f64) -> f64 {
        given * self.width
    }

    /// `track_revisit_s` as the planner uses it.
    pub fn track_revisit_s(&self, given: f64) -> f64 {
        given * self.speed
    }
}

#[cfg(test)]
mod tests {
    use protocol::scenario::SetfleetConfig;

    use super::*;

    fn load(overrides: &[&str]) -> Scenario {
        let o: Vec<String> = overrides.iter().map(|s| (*s).to_owned()).collect();
        Scenario::load(None, &o).unwrap()
    }

    /// `lambda = 10`, `track_revisit_s = 10` and the default `spread_m` and
    /// `growth_horizon_s`, as the planner uses them on `s`.
    fn adapted(s: &Scenario) -> (f64, SetfleetConfig) {
        let f = Scale::of(s).unwrap().factors(&Scale::reference().unwrap());
        let given = SetfleetConfig::default();
        let w = SetfleetConfig {
            spread_m: f.spread_m(given.spread_m),
            track_revisit_s: f.track_revisit_s(10.0),
            ..given
        };
        (f.lambda(10.0), w)
    }

    #[test]
    fn the_default_scenario_keeps_the_weights_given() {
        let (lambda, w) = adapted(&Scenario::default());
        let given = SetfleetConfig::default();
        assert_eq!(lambda, 10.0);
        assert_eq!(w.spread_m, given.spread_m);
        assert_eq!(w.growth_horizon_s, given.growth_horizon_s);
        assert_eq!(w.track_revisit_s, 10.0);
    }

    #[test]
    fn the_default_footprint_is_the_documented_trapezoid() {
        // docs/design.md: about 14,000 m², 85-160 m wide, at 80-110 m.
        let s = Scale::reference().unwrap();
        assert!((85.0..160.0).contains(&s.footprint_width_m), "{s:?}");
    }

    #[test]
    fn weights_follow_the_footprint_the_fleet_and_the_targets() {
        let reference = adapted(&Scenario::default());
        // A steeper camera sees a narrower footprint: less ground per metre, closer spread.
        let (lambda, w) = adapted(&load(&["camera.tilt_rad=1.0471975511965976"]));
        assert!(lambda < reference.0 && w.spread_m < reference.1.spread_m);
        // Twice the UAVs fly higher on average, so with a wider footprint.
        let (lambda, w) = adapted(&load(&["uavs.count=8"]));
        assert!(lambda > reference.0 && w.spread_m > reference.1.spread_m);
        assert_eq!(w.growth_horizon_s, reference.1.growth_horizon_s);
        // Cars 1.5 times faster: revisited 1.5 times sooner, the same radius allowed.
        let (_, w) = adapted(&load(&["targets.max_speed_mps=3"]));
        assert!((w.track_revisit_s - 10.0 / 1.5).abs() < 1e-9);
    }
}
