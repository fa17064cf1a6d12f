//! `fleet run --chaos SEED`: a seeded random schedule of faults over a run.
//!
//! The schedule is a list of incidents, each one of:
//! - a **kill** of an agent and its **restart** 1 to 5 s of simulated time later (two faults);
//! - a **pause**: SIGSTOP, then SIGCONT 0.5 to 8 s of wall time later (one fault), from
//!   shorter than the observer's wait for an estimate to longer than the lockstep world's
//!   wait for an ack (`protocol::timeouts`: 4 s and 7 s), after which the world skips the
//!   agent until it answers again.
//!
//! Every third incident, the first included, lands on the **token holder**: at a guidance
//! step (a multiple of `timing.guidance_period_s`) on the UAV that holds the token first in
//! that round, the lowest UAV alive then (by the schedule's own kills and restarts). The
//! others fall on a random step and UAV, and so does a holder's incident when the holder is
//! busy at every guidance step tried.
//!
//! So that the run stays meaningful, faults start after the first guidance period, every
//! incident is over [`end_margin_s`] before the end of the run (each agent is back, and
//! measured back, before it), and incidents never overlap on one UAV: after a restart or a
//! pause its agent is left alone for [`SETTLE_STEPS`] steps. A pause is reckoned to last its
//! duration in simulated time (as in realtime at speedup 1; a lockstep world waits for the
//! stopped agent, so there it lasts less), and a pause longer than the world's ack wait
//! longer still: the world then goes on without the agent until its SIGCONT, up to
//! [`RUN_ON_RATE`] times faster than real time. Several UAVs may be down at once, the whole fleet included, but
//! rarely: every kill is short.
//!
//! The schedule depends only on the seed, the number of faults asked for, the scenario's
//! duration, periods and fleet size, and the explicit `--fault`s it is laid around.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use protocol::scenario::Scenario;
use protocol::timeouts::Timeouts;

use fleet_observe::faults::{Fault, FaultKind, FaultOrigin};

/// Faults per minute of simulated time when `--chaos-faults` is not given.
pub const FAULTS_PER_MINUTE: f64 = 6.0;
/// A killed agent is restarted this many seconds of simulated time later (least, most).
pub const RESTART_DELAY_S: (f64, f64) = (1.0, 5.0);
/// How long a pause lasts, seconds of wall time (least, most), in tenths of a second.
pub const PAUSE_S: (f64, f64) = (0.5, 8.0);
/// Steps a UAV is left alone after a restart or the end of a pause.
pub const SETTLE_STEPS: u64 = 10;
/// Simulated seconds per wall second a lockstep world may run at once it stopped waiting for
/// a stopped agent (small scenarios run at several times real time).
pub const RUN_ON_RATE: f64 = 10.0;
/// One incident in this many lands on the token holder at a guidance step.
const TOKEN_EVERY: usize = 3;
/// Placement attempts per incident before it is given up.
const ATTEMPTS: usize = 64;

/// The number of faults of `--chaos` without `--chaos-faults`: [`FAULTS_PER_MINUTE`] over
/// the run's simulated time, rounded.
pub fn default_count(scenario: &Scenario) -> u32 {
    (FAULTS_PER_MINUTE * scenario.duration_s / 60.0).round() as u32
}

/// How long before the end of the run the last fault comes, seconds: two guidance periods,
/// and at least [`SETTLE_STEPS`] steps.
pub fn end_margin_s(scenario: &Scenario) -> f64 {
    (2.0 * scenario.timing.guidance_period_s)
        .max(SETTLE_STEPS as f64 * scenario.timing.cvs_period_s)
}

/// The chaos faults of a run: `count` faults drawn from `seed` around the (checked)
/// `explicit` faults, in the order they apply. Fewer when the run has no room for them all
/// (see the module docs).
pub fn schedule(seed: u64, count: u32, scenario: &Scenario, explicit: &[Fault]) -> Vec<Fault> {
    let mut chaos = Chaos::new(scenario, explicit);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut budget = count;
    let mut incident = 0;
    while budget > 0 {
        let kill = budget >= 2 && rng.random_bool(0.5);
        budget -= if kill { 2 } else { 1 };
        let on_holder = incident % TOKEN_EVERY == 0;
        incident += 1;
        let placed = (0..ATTEMPTS).any(|_| chaos.try_place(&mut rng, kill, on_holder));
        // A holder busy at every guidance step leaves the incident to a random UAV.
        if !placed && on_holder {
            (0..ATTEMPTS).any(|_| chaos.try_place(&mut rng, kill, false));
        }
    }
    let mut faults = chaos.faults;
    faults.sort_by(|a, b| a.at_s.total_cmp(&b.at_s).then(a.kind.cmp(&b.kind)));
    faults
}

/// Steps `[from, to]` during which a UAV takes no new fault.
#[derive(Clone, Copy, Debug)]
struct Busy {
    from: u64,
    to: u64,
}

/// The schedule being drawn.
struct Chaos {
    period_s: f64,
    /// The lockstep world's wait for an agent's ack, seconds.
    ack_wait_s: f64,
    guidance_steps: u64,
    uavs: u32,
    /// First and last step a fault may fall on (`first > last`: none).
    first: u64,
    last: u64,
    /// Per UAV, when it takes no new fault.
    busy: Vec<Vec<Busy>>,
    /// Per UAV, the steps `[kill, restart)` it is down (`u64::MAX`: never restarted).
    down: Vec<Vec<(u64, u64)>>,
    faults: Vec<Fault>,
}

impl Chaos {
    fn new(scenario: &Scenario, explicit: &[Fault]) -> Chaos {
        let period_s = scenario.timing.cvs_period_s;
        let guidance_steps = scenario.steps_per_guidance();
        let margin = (end_margin_s(scenario) / period_s).ceil() as u64;
        let uavs = scenario.uavs.count;
        let mut chaos = Chaos {
            period_s,
            ack_wait_s: Timeouts::default()
                .for_scenario(scenario)
                .ack()
                .as_secs_f64(),
            guidance_steps,
            uavs,
            first: guidance_steps.max(1),
            last: scenario.steps().saturating_sub(margin),
            busy: vec![Vec::new(); uavs as usize],
            down: vec![Vec::new(); uavs as usize],
            faults: Vec::new(),
        };
        // The explicit faults, in application order: a kill is down until its restart.
        let mut killed: Vec<Option<u64>> = vec![None; uavs as usize];
        for f in explicit {
            let Some(slot) = killed.get_mut(f.uav as usize) else {
                continue;
            };
            let step = chaos.step_of(f.at_s);
            match f.kind {
                FaultKind::Kill => *slot = Some(step),
                FaultKind::Restart => {
                    let from = slot.take().unwrap_or(step);
                    chaos.block(f.uav, from, step + SETTLE_STEPS);
                    chaos.down[f.uav as usize].push((from, step));
                }
                FaultKind::Pause => {
                    let to = step + chaos.pause_span(f.pause_s.unwrap_or(0.0)) + SETTLE_STEPS;
                    chaos.block(f.uav, step, to);
                }
            }
        }
        for (uav, slot) in killed.iter().enumerate() {
            if let Some(from) = *slot {
                chaos.block(uav as u32, from, u64::MAX);
                chaos.down[uav].push((from, u64::MAX));
            }
        }
        chaos
    }

    /// The step at which a fault due at `at_s` applies (the first whose time reaches it).
    fn step_of(&self, at_s: f64) -> u64 {
        (at_s / self.period_s - 1e-9).ceil().max(0.0) as u64
    }

    /// Steps of simulated time a pause of `pause_s` wall seconds is reckoned to last (see
    /// the module docs).
    fn pause_span(&self, pause_s: f64) -> u64 {
        let run_on = (pause_s - self.ack_wait_s).max(0.0) * RUN_ON_RATE;
        ((pause_s + run_on) / self.period_s).ceil() as u64
    }

    fn block(&mut self, uav: u32, from: u64, to: u64) {
        if let Some(busy) = self.busy.get_mut(uav as usize) {
            busy.push(Busy { from, to });
        }
    }

    fn is_free(&self, uav: u32, from: u64, to: u64) -> bool {
        self.busy[uav as usize]
            .iter()
            .all(|b| to < b.from || from > b.to)
    }

    fn is_alive(&self, uav: u32, step: u64) -> bool {
        self.down[uav as usize]
            .iter()
            .all(|&(from, to)| step < from || step >= to)
    }

    /// The UAV that holds the token first in the round of `step`: the lowest one alive.
    fn holder(&self, step: u64) -> Option<u32> {
        (0..self.uavs).find(|&u| self.is_alive(u, step))
    }

    /// Draws one incident and adds it if it fits; whether it did.
    fn try_place(&mut self, rng: &mut ChaCha8Rng, kill: bool, on_holder: bool) -> bool {
        if self.first > self.last || self.uavs == 0 {
            return false;
        }
        // The incident's steps: to the restart, or the pause's reckoned span.
        let (span, pause_s) = if kill {
            let least = (RESTART_DELAY_S.0 / self.period_s).ceil().max(1.0) as u64;
            let most = ((RESTART_DELAY_S.1 / self.period_s).floor() as u64).max(least);
            (rng.random_range(least..=most), 0.0)
        } else {
            let tenths = rng.random_range((PAUSE_S.0 * 10.0) as u32..=(PAUSE_S.1 * 10.0) as u32);
            let pause_s = f64::from(tenths) / 10.0;
            (self.pause_span(pause_s), pause_s)
        };
        // The incident is over inside the window.
        let Some(latest) = self.last.checked_sub(span) else {
            return false;
        };
        if latest < self.first {
            return false;
        }
        let step = if on_holder {
            let g = self.guidance_steps;
            let (lo, hi) = (self.first.div_ceil(g), latest / g);
            if lo > hi {
                return false;
            }
            rng.random_range(lo..=hi) * g
        } else {
            rng.random_range(self.first..=latest)
        };
        let end = step + span + SETTLE_STEPS;
        let uav = if on_holder {
            match self.holder(step) {
                Some(u) if self.is_free(u, step, end) => u,
                _ => return false,
            }
        } else {
            let free: Vec<u32> = (0..self.uavs)
                .filter(|&u| self.is_free(u, step, end))
                .collect();
            if free.is_empty() {
                return false;
            }
            free[rng.random_range(0..free.len())]
        };
        self.block(uav, step, end);
        let at = |s: u64| s as f64 * self.period_s;
        let fault = |kind, at_s, pause_s| Fault {
            kind,
            uav,
            at_s,
            pause_s,
            origin: FaultOrigin::Chaos,
        };
        if kill {
            let restart = step + span;
            self.down[uav as usize].push((step, restart));
            self.faults.push(fault(FaultKind::Kill, at(step), None));
            self.faults
                .push(fault(FaultKind::Restart, at(restart), None));
        } else {
            self.faults
                .push(fault(FaultKind::Pause, at(step), Some(pause_s)));
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::config::check_faults;

    fn scenario(duration_s: f64, uavs: u32) -> Scenario {
        Scenario::load(
            None,
            &[
                format!("duration_s={duration_s}"),
                format!("uavs.count={uavs}"),
            ],
        )
        .unwrap()
    }

    /// Whether `uav` is down at `step` by the kills and restarts of `faults`.
    fn down_at(faults: &[Fault], uav: u32, time_s: f64) -> bool {
        let mut down = false;
        for f in faults.iter().filter(|f| f.uav == uav && f.at_s <= time_s) {
            match f.kind {
                FaultKind::Kill => down = true,
                FaultKind::Restart => down = false,
                FaultKind::Pause => {}
            }
        }
        down
    }

    #[test]
    fn the_same_seed_draws_the_same_schedule_and_another_seed_another() {
        let s = scenario(300.0, 4);
        let a = schedule(7, 30, &s, &[]);
        assert_eq!(a, schedule(7, 30, &s, &[]));
        assert_ne!(a, schedule(8, 30, &s, &[]));
        assert_ne!(a, schedule(7, 30, &scenario(300.0, 3), &[]));
    }

    #[test]
    fn the_schedule_holds_what_it_promises() {
        for seed in 0..20 {
            let s = scenario(120.0, 3);
            let faults = schedule(seed, default_count(&s), &s, &[]);
            assert_eq!(faults.len(), 12, "6 per minute: {faults:?}");
            // A valid plan: restarts follow kills, pauses hit running agents.
            assert_eq!(check_faults(&faults, &s).unwrap(), faults);
            let (first, last) = (s.timing.guidance_period_s, s.duration_s - end_margin_s(&s));
            let mut on_holder = 0;
            for (i, f) in faults.iter().enumerate() {
                assert_eq!(f.origin, FaultOrigin::Chaos);
                assert!(f.at_s >= first && f.at_s <= last, "{f} outside the window");
                let step = f.at_s / s.timing.cvs_period_s;
                assert_eq!(step, step.round(), "{f} not at a step");
                match f.kind {
                    FaultKind::Kill => {
                        let restart = faults[i + 1..]
                            .iter()
                            .find(|r| r.uav == f.uav)
                            .expect("a restart");
                        assert_eq!(restart.kind, FaultKind::Restart, "{faults:?}");
                        let delay = restart.at_s - f.at_s;
                        assert!((1.0..=5.0).contains(&delay), "{f} then {restart}");
                        assert!(f.pause_s.is_none());
                    }
                    FaultKind::Restart => assert!(f.pause_s.is_none()),
                    FaultKind::Pause => {
                        let p = f.pause_s.expect("a pause duration");
                        assert!((0.5..=8.0).contains(&p), "{f}");
                        // Over before the end, even when the world runs on without the agent.
                        let run_on =
                            (p - Timeouts::default().for_scenario(&s).ack().as_secs_f64()).max(0.0);
                        assert!(f.at_s + p + run_on * RUN_ON_RATE <= last + 1e-9, "{f}");
                    }
                }
                let guidance_step = (f.at_s / s.timing.guidance_period_s).fract() == 0.0;
                let lowest_live = (0..3).find(|&u| !down_at(&faults, u, f.at_s - 1e-6));
                if f.kind != FaultKind::Restart && guidance_step && lowest_live == Some(f.uav) {
                    on_holder += 1;
                }
            }
            assert!(on_holder >= 2, "seed {seed}: {on_holder} on the holder");
            // No two faults of a UAV closer than its settling time, apart from a kill and its
            // restart.
            for u in 0..3 {
                let mine: Vec<&Fault> = faults.iter().filter(|f| f.uav == u).collect();
                for w in mine.windows(2) {
                    let gap = w[1].at_s - w[0].at_s;
                    if w[1].kind != FaultKind::Restart {
                        assert!(gap > 5.0, "seed {seed}: {} then {}", w[0], w[1]);
                    }
                }
            }
        }
    }

    #[test]
    fn the_schedule_goes_around_explicit_faults() {
        let s = scenario(60.0, 2);
        let explicit = check_faults(
            &[
                "kill:0@10".parse().unwrap(),
                "restart:0@20".parse().unwrap(),
                "pause:1@30+2".parse().unwrap(),
            ],
            &s,
        )
        .unwrap();
        for seed in 0..20 {
            let chaos = schedule(seed, 6, &s, &explicit);
            assert!(!chaos.is_empty());
            for f in &chaos {
                let clear_of =
                    |uav: u32, from: f64, to: f64| f.uav != uav || f.at_s < from || f.at_s > to;
                assert!(clear_of(0, 10.0, 25.0), "seed {seed}: {f}");
                assert!(clear_of(1, 30.0, 37.0), "seed {seed}: {f}");
            }
            let mut all = explicit.clone();
            all.extend(chaos);
            check_faults(&all, &s).unwrap();
        }
    }

    #[test]
    fn a_run_without_room_gets_fewer_faults_or_none() {
        // 10 s: the window is 3 s to 4 s.
        let s = scenario(10.0, 1);
        assert!(schedule(1, 20, &s, &[]).len() < 20);
        assert!(schedule(1, 5, &scenario(5.0, 2), &[]).is_empty());
        assert_eq!(default_count(&scenario(30.0, 2)), 3);
    }
}
