//! UAV dynamics, shared by the world (which flies the UAVs) and the guidance (which predicts
//! them), so that the two can never disagree about where a yaw reference takes a UAV.
//!
//! The model: a UAV flies at a constant ground speed and a constant altitude; its yaw moves
//! toward the yaw reference at a bounded rate, the shortest way round, and stops exactly on
//! the reference (no overshoot). The position follows the heading; while the yaw turns at a
//! constant rate, the path is an exact circular arc, so the result does not depend on how a
//! period is cut into calls (up to floating-point rounding).

use serde::{Deserialize, Serialize};

use sets::math::{Point3, Real, wrap_angle};

/// Where a UAV is and where it points.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct UavState {
    /// Position of the camera's optical centre, world frame (`z` is the altitude).
    pub position: Point3,
    /// Heading, radians counter-clockwise from east, in `(-pi, pi]`.
    pub yaw: Real,
}

/// The state of a UAV `dt` seconds after `state`, flying at `speed_mps` while its yaw follows
/// `yaw_ref` at no more than `max_yaw_rate_rps`.
///
/// - The yaw turns toward `yaw_ref` the shortest way round (a reference exactly opposite the
///   yaw turns counter-clockwise), by at most `max_yaw_rate_rps * dt`; once it reaches the
///   reference it stays there, exactly (`yaw == wrap_angle(yaw_ref)`), for the rest of `dt`.
/// - The position moves at `speed_mps` along the instantaneous heading: an exact circular arc
///   while the yaw turns, then a straight segment. The altitude never changes.
/// - The returned yaw is wrapped into `(-pi, pi]`.
///
/// Degenerate inputs keep the UAV safe and predictable rather than poisoning the state with
/// NaN: a non-finite `yaw_ref` keeps the current yaw as reference; a non-finite or
/// non-positive `dt` returns `state` unchanged; a non-finite or negative speed or rate counts
/// as zero.
///
/// ```
/// use protocol::flight::{UavState, advance};
/// use sets::math::Point3;
///
/// let s = UavState { position: Point3::new(0.0, 0.0, 80.0), yaw: 0.0 };
/// let next = advance(s, 0.0, 0.5, 10.0, 1.0);
/// assert!((next.position.x - 5.0).abs() < 1e-12);
/// ```
pub fn advance(
    state: UavState,
    yaw_ref: Real,
    dt: Real,
    speed_mps: Real,
    max_yaw_rate_rps: Real,
) -> UavState {
    if !(dt.is_finite() && dt > 0.0) {
        return state;
    }
    let speed = non_negative(speed_mps);
    let rate = non_negative(max_yaw_rate_rps);
    let yaw0 = wrap_angle(state.yaw);
    let target = if yaw_ref.is_finite() {
        wrap_angle(yaw_ref)
    } else {
        yaw0
    };
    let error = wrap_angle(target - yaw0);
    let turn_needed = error.abs();

    // Time spent turning, and the signed turn rate during it.
    let (turn_time, omega, final_yaw) = if turn_needed == 0.0 {
        (0.0, 0.0, yaw0)
    } else if rate * dt >= turn_needed {
        (turn_needed / rate, rate * error.signum(), target)
    } else {
        (
            dt,
            rate * error.signum(),
            wrap_angle(yaw0 + rate * dt * error.signum()),
        )
    };

    let mut p = state.position;
    if turn_time > 0.0 {
        let (dx, dy) = arc_displacement(yaw0, omega, turn_time, speed);
        p.x += dx;
        p.y += dy;
    }
    let straight = dt - turn_time;
    if straight > 0.0 {
        let (s, c) = final_yaw.sin_cos();
        p.x += speed * straight * c;
        p.y += speed * straight * s;
    }
    UavState {
        position: p,
        yaw: final_yaw,
    }
}

/// Ground displacement over `t` seconds at `speed` with the heading starting at `yaw0` and
/// turning at the constant rate `omega` (the exact integral of the velocity).
fn arc_displacement(yaw0: Real, omega: Real, t: Real, speed: Real) -> (Real, Real) {
    let turned = omega * t;
    if turned.abs() < 1e-9 {
        // The arc is indistinguishable from a chord along the mean heading; the closed form
        // below would lose its digits dividing by a tiny omega.
        let mid = yaw0 + turned / 2.0;
        return (speed * t * mid.cos(), speed * t * mid.sin());
    }
    let r = speed / omega;
    let yaw1 = yaw0 + turned;
    (
        r * (yaw1.sin() - yaw0.sin()),
        -r * (yaw1.cos() - yaw0.cos()),
    )
}

fn non_negative(v: Real) -> Real {
    if v.is_finite() && v > 0.0 { v } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use std::f64::consts::{FRAC_PI_2, PI};

    use super::*;

    fn at(yaw: Real) -> UavState {
        UavState {
            position: Point3::new(1.0, 2.0, 80.0),
            yaw,
        }
    }

    #[test]
    fn straight_flight_keeps_yaw_and_altitude() {
        let s = advance(at(FRAC_PI_2), FRAC_PI_2, 0.5, 10.0, 1.0);
        assert!((s.position.x - 1.0).abs() < 1e-12);
        assert!((s.position.y - 7.0).abs() < 1e-12);
        assert_eq!(s.position.z, 80.0);
        assert_eq!(s.yaw, FRAC_PI_2);
    }

    #[test]
    fn yaw_change_is_bounded_by_rate() {
        for &(y0, yr) in &[
            (0.0, 2.0),
            (0.0, -2.0),
            (3.0, -3.0),
            (-3.0, 3.0),
            (0.1, 0.3),
        ] {
            let s = advance(at(y0), yr, 0.5, 10.0, 1.0);
            let moved = wrap_angle(s.yaw - y0).abs();
            assert!(moved <= 0.5 + 1e-12, "{y0} -> {yr}: {moved}");
        }
    }

    #[test]
    fn turns_the_short_way_across_the_wrap() {
        // From 3.0 to -3.0 is 0.283 rad counter-clockwise through pi, not 6 rad clockwise.
        let s = advance(at(3.0), -3.0, 0.1, 10.0, 1.0);
        assert!((s.yaw - 3.1).abs() < 1e-12);
        let s = advance(at(3.0), -3.0, 1.0, 10.0, 1.0);
        assert_eq!(s.yaw, -3.0);
    }

    #[test]
    fn arrives_exactly_without_overshoot() {
        let s = advance(at(0.0), 0.3, 0.5, 10.0, 1.0);
        assert_eq!(s.yaw, 0.3);
        let mut s = at(0.0);
        for _ in 0..10 {
            s = advance(s, 1.2, 0.5, 10.0, 1.0);
            assert!(s.yaw <= 1.2);
        }
        assert_eq!(s.yaw, 1.2);
    }

    #[test]
    fn opposite_reference_turns_counter_clockwise() {
        let s = advance(at(0.0), PI, 0.5, 10.0, 1.0);
        assert!((s.yaw - 0.5).abs() < 1e-12);
    }

    #[test]
    fn distance_travelled_is_speed_times_dt_along_the_arc() {
        // A full-rate quarter turn traces a quarter circle of radius v / rate.
        let s = advance(at(0.0), FRAC_PI_2, FRAC_PI_2, 10.0, 1.0);
        assert!((s.position.x - 11.0).abs() < 1e-9);
        assert!((s.position.y - 12.0).abs() < 1e-9);
    }

    #[test]
    fn splitting_the_period_gives_the_same_state() {
        let whole = advance(at(0.2), -1.0, 0.5, 10.0, 1.0);
        let mut s = at(0.2);
        for _ in 0..50 {
            s = advance(s, -1.0, 0.01, 10.0, 1.0);
        }
        assert!((whole.position - s.position).norm() < 1e-9);
        assert!((whole.yaw - s.yaw).abs() < 1e-12);
    }

    #[test]
    fn degenerate_inputs_stay_finite() {
        let s = advance(at(0.4), Real::NAN, 0.5, 10.0, 1.0);
        assert_eq!(s.yaw, 0.4);
        assert!(s.position.x.is_finite());
        assert_eq!(advance(at(0.4), 1.0, -1.0, 10.0, 1.0), at(0.4));
        let s = advance(at(0.4), 1.0, 0.5, Real::INFINITY, Real::NAN);
        assert_eq!(s.yaw, 0.4);
        assert_eq!(s.position, at(0.4).position);
    }
}
