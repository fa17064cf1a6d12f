//! Every bounded wait of a run, derived from one place.
//!
//! Three waits are chosen; every other one follows from them, so a process started by hand
//! with the defaults agrees with the others:
//!
//! | wait | who waits | for what | value |
//! |---|---|---|---|
//! | [`Timeouts::peer_wait`] | an agent | its served peers' estimates of a step | chosen, 2 s |
//! | [`Timeouts::token_wait`] | an agent | one holder of the guidance token | chosen, 3 s |
//! | [`Timeouts::compute`] | everyone | an agent's own work on a step on a busy machine | chosen, 2 s |
//! | [`Timeouts::planner`] | an agent | an external planner's answer | the scenario's `timing.external_planner_ms` when a UAV asks one, else 0 |
//! | [`Timeouts::holder_wait`] | an agent | one holder of the token | token + planner |
//! | [`Timeouts::ack`] | the world (lockstep) | every served agent's ack of a step | peer + token + compute + planner |
//! | [`Timeouts::estimate_wait`] | the observer | the served agents' estimates of a step | peer + compute |
//! | [`Timeouts::world_lost`] | an agent | a frame, before it checks the world's node | 2 × ack |
//! | [`Timeouts::start`] | the world | hellos at start and from announced restarts | 30 s |
//! | [`Timeouts::rehello`] | an agent | a frame, before it says hello again | 1 s |
//! | [`Timeouts::first_step_extra`] | the world, the observer | added to their waits at step 0 | start |
//!
//! The three chosen waits hold for a machine running up to [`AGENTS_PER_WAIT`] agents (16 on
//! two cores, measured). A larger fleet shares the machine's cores between more agents, so
//! that every agent's step takes longer in wall time, and a 64-UAV fleet on two cores took up
//! to 10 s a step: [`Timeouts::for_scenario`] scales the three by `⌈n / AGENTS_PER_WAIT⌉`
//! for a fleet of `n`, which keeps such a run in lockstep (no healthy agent skipped, no peer
//! left out of a fusion for being late), and so reproducible. On hosts of their own the
//! agents would need less; the longer waits cost time only when a process is stalled, since a
//! dead one shows up at once.
//!
//! The ack wait covers one step of a healthy agent: a full peer wait, one silent holder's
//! token wait, and its own estimator and planner. An agent slower than that (stopped, swapped
//! out) is skipped, not lost: it rejoins with its next ack or hello. A dead process never
//! costs a wait: iceoryx2's node list shows it dead at once.

use std::time::Duration;

/// Agents one machine may run at once with the waits as chosen; larger fleets lengthen them
/// ([`Timeouts::for_scenario`]).
pub const AGENTS_PER_WAIT: u32 = 16;

/// The waits of a run. [`Timeouts::default`] is what every binary uses unless told otherwise.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Timeouts {
    /// Longest wait of an agent for its served peers' estimates of a step.
    pub peer_wait: Duration,
    /// Longest wait of an agent for one token holder before it takes the turn over.
    pub token_wait: Duration,
    /// Budget for an agent's own estimator and planner on one step, on a loaded machine.
    pub compute: Duration,
    /// Longest wait of an agent for an external planner's answer (docs/python.md): added to
    /// the waits for a token holder and for an agent's ack ([`Timeouts::for_scenario`]).
    pub planner: Duration,
}

impl Default for Timeouts {
    fn default() -> Self {
        Timeouts {
            peer_wait: Duration::from_secs(2),
            token_wait: Duration::from_secs(3),
            compute: Duration::from_secs(2),
            planner: Duration::ZERO,
        }
    }
}

impl Timeouts {
    /// The defaults with the two agent waits given in milliseconds (`None` keeps a default).
    pub fn with_waits_ms(peer_wait_ms: Option<u64>, token_wait_ms: Option<u64>) -> Timeouts {
        let d = Timeouts::default();
        Timeouts {
            peer_wait: peer_wait_ms.map_or(d.peer_wait, Duration::from_millis),
            token_wait: token_wait_ms.map_or(d.token_wait, Duration::from_millis),
            ..d
        }
    }

    /// These waits for `scenario`'s fleet: the three chosen ones scaled by
    /// `⌈uavs / AGENTS_PER_WAIT⌉` (see the [module](self) docs), and the budget of the
    /// external planner it may ask (`timing.external_planner_ms`, when any UAV asks one). The
    /// world, the observer and every agent derive them from the same scenario, so they agree.
    pub fn for_scenario(self, scenario: &crate::scenario::Scenario) -> Timeouts {
        let asks = (0..scenario.uavs.count).any(|uav| scenario.asks_external(uav));
        let load = scenario.uavs.count.div_ceil(AGENTS_PER_WAIT).max(1);
        Timeouts {
            peer_wait: self.peer_wait * load,
            token_wait: self.token_wait * load,
            compute: self.compute * load,
            planner: if asks {
                Duration::from_millis(u64::from(scenario.timing.external_planner_ms))
            } else {
                Duration::ZERO
            },
        }
    }

    /// Longest wait of an agent for one token holder: the token wait, and the holder's wait
    /// for its external planner.
    pub fn holder_wait(&self) -> Duration {
        self.token_wait + self.planner
    }

    /// Longest wait of the lockstep world for the acks of one step: a healthy agent's worst
    /// step (peer wait, one token wait, its own work, its wait for an external planner).
    pub fn ack(&self) -> Duration {
        self.peer_wait + self.token_wait + self.compute + self.planner
    }

    /// Longest wait of the observer for the served agents' estimates of a step. An agent
    /// publishes its estimate before it waits for its peers or the token, so its own work
    /// bounds the wait; the peer wait is margin. Shorter than [`Timeouts::ack`], so an
    /// observer waiting out a stalled agent never misses the world's deadline itself.
    pub fn estimate_wait(&self) -> Duration {
        self.peer_wait + self.compute
    }

    /// How long an agent goes without a frame before it checks whether the world's node is
    /// still alive (and exits if it is not). Longer than any step the world waits out.
    pub fn world_lost(&self) -> Duration {
        self.ack() * 2
    }

    /// Longest wait of the world for the hellos of the expected agents at start, and of an
    /// agent whose restart it was told about.
    pub fn start(&self) -> Duration {
        Duration::from_secs(30)
    }

    /// What the world's ack wait and the observer's estimate wait add at step 0: the start
    /// wait. The first step is every agent's first frame, the token's first pass round the
    /// whole ring and, over hosts, the first messages through bridges still connecting: 64
    /// UAVs over 4 hosts of one 2-core machine took up to 42 s over it, against at most 28 s
    /// over any later step.
    pub fn first_step_extra(&self) -> Duration {
        self.start()
    }

    /// How long an agent goes without a frame before it says hello again (the world may have
    /// stopped serving it while it was stalled). Repeated at this interval.
    pub fn rehello(&self) -> Duration {
        Duration::from_secs(1)
    }

    /// Interval of an agent's hellos before its first frame.
    pub fn hello_interval(&self) -> Duration {
        Duration::from_millis(200)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_world_waits_out_a_healthy_agents_slowest_step() {
        let t = Timeouts::with_waits_ms(Some(4_000), None);
        assert_eq!(t.peer_wait, Duration::from_secs(4));
        assert!(t.ack() > t.peer_wait + t.token_wait);
        assert!(t.world_lost() > t.ack());
        assert!(t.estimate_wait() < t.ack());
        assert!(t.rehello() < t.ack());
        assert_eq!(Timeouts::with_waits_ms(None, None), Timeouts::default());
    }

    #[test]
    fn an_external_planner_lengthens_the_holder_and_ack_waits_only_when_asked() {
        use crate::scenario::Scenario;
        let mut s = Scenario::default();
        let plain = Timeouts::default().for_scenario(&s);
        assert_eq!(plain, Timeouts::default());
        s.guidance.external_uavs = vec![1];
        s.timing.external_planner_ms = 1500;
        let t = Timeouts::default().for_scenario(&s);
        assert_eq!(
            t.holder_wait(),
            plain.token_wait + Duration::from_millis(1500)
        );
        assert_eq!(t.ack(), plain.ack() + Duration::from_millis(1500));
        assert_eq!(t.estimate_wait(), plain.estimate_wait());
    }

    #[test]
    fn fleets_larger_than_a_machine_runs_lengthen_the_chosen_waits() {
        use crate::scenario::Scenario;
        let mut s = Scenario::default();
        let chosen = Timeouts::with_waits_ms(Some(500), None);
        for (uavs, load) in [(1, 1), (16, 1), (17, 2), (32, 2), (64, 4)] {
            s.uavs.count = uavs;
            let t = chosen.for_scenario(&s);
            assert_eq!(t.peer_wait, chosen.peer_wait * load, "{uavs} UAVs");
            assert_eq!(t.token_wait, chosen.token_wait * load, "{uavs} UAVs");
            assert_eq!(t.ack(), chosen.ack() * load, "{uavs} UAVs");
            assert!(t.estimate_wait() < t.ack());
            // The first step's extra is the start wait, whatever the fleet.
            assert_eq!(t.first_step_extra(), chosen.start(), "{uavs} UAVs");
        }
    }
}
