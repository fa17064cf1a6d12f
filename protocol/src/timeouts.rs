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
//! | [`Timeouts::ack`] | the world (lockstep) | every served agent's ack of a step | peer + token + compute |
//! | [`Timeouts::estimate_wait`] | the observer | the served agents' estimates of a step | peer + compute |
//! | [`Timeouts::world_lost`] | an agent | a frame, before it checks the world's node | 2 × ack |
//! | [`Timeouts::start`] | the world | hellos at start and from announced restarts | 30 s |
//! | [`Timeouts::rehello`] | an agent | a frame, before it says hello again | 1 s |
//!
//! The ack wait covers one step of a healthy agent: a full peer wait, one silent holder's
//! token wait, and its own estimator and planner. An agent slower than that (stopped, swapped
//! out) is skipped, not lost: it rejoins with its next ack or hello. A dead process never
//! costs a wait: iceoryx2's node list shows it dead at once.

use std::time::Duration;

/// The waits of a run. [`Timeouts::default`] is what every binary uses unless told otherwise.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Timeouts {
    /// Longest wait of an agent for its served peers' estimates of a step.
    pub peer_wait: Duration,
    /// Longest wait of an agent for one token holder before it takes the turn over.
    pub token_wait: Duration,
    /// Budget for an agent's own estimator and planner on one step, on a loaded machine.
    pub compute: Duration,
}

impl Default for Timeouts {
    fn default() -> Self {
        Timeouts {
            peer_wait: Duration::from_secs(2),
            token_wait: Duration::from_secs(3),
            compute: Duration::from_secs(2),
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

    /// Longest wait of the lockstep world for the acks of one step: a healthy agent's worst
    /// step (peer wait, one token wait, its own work).
    pub fn ack(&self) -> Duration {
        self.peer_wait + self.token_wait + self.compute
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
}
