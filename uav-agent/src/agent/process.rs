//! The agent process's hold on its run ([`Process`]): who it is (its config, the run's tag,
//! its incarnation), its ports and how it waits on them, where its time goes and what it
//! counted.
//!
//! The peer exchange and the guidance turn send, wait and count through this one, and
//! liveness and the checkpoints count their time on its clock; it is passed to their steps
//! explicitly. What the parts own stays theirs, and what they share (the ports, the clock,
//! the counters, the stop flags that end every wait) is in one place.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use fleet_process::resources::{CpuClock, PhaseClock};
use iceoryx2::prelude::WaitSet;
use protocol::ipc::{Ipc, wait_for_wake};
use protocol::wire::{UavCommand, WireKind};

use super::config::AgentConfig;
use super::links::{LinkError, Links};
use super::phase;
use super::report::{AgentCounters, EndReason};

/// Longest single wait, so the shutdown flag and dead processes are noticed promptly.
pub(super) const WAIT_SLICE: Duration = Duration::from_millis(50);

/// The agent process: its identity, ports, waits, clock and counters.
pub(super) struct Process<'a> {
    /// How the agent runs.
    pub(super) config: &'a AgentConfig,
    /// The run's tag, which every message carries.
    pub(super) run_tag: u64,
    /// This process's incarnation (see [`super::run`]).
    incarnation: u64,
    /// Its ports.
    pub(super) links: &'a Links,
    waitset: &'a WaitSet<Ipc>,
    shutdown: &'a AtomicBool,
    /// The world announced the end of the run.
    end_of_run: bool,
    /// A termination request came.
    interrupted: bool,
    /// Where the time goes ([`phase`]).
    pub(super) clock: PhaseClock,
    /// What the agent counted.
    pub(super) counters: AgentCounters,
}

impl<'a> Process<'a> {
    /// The process of agent `config.uav` in its `incarnation`, over `links`, waking on
    /// `waitset`, stopped by `shutdown`; its clock starts now.
    pub(super) fn new(
        config: &'a AgentConfig,
        incarnation: u64,
        links: &'a Links,
        waitset: &'a WaitSet<Ipc>,
        shutdown: &'a AtomicBool,
    ) -> Self {
        Process {
            config,
            run_tag: config.run_id.tag(),
            incarnation,
            links,
            waitset,
            shutdown,
            end_of_run: false,
            interrupted: false,
            clock: PhaseClock::new(CpuClock::Thread, phase::OTHER),
            counters: AgentCounters::default(),
        }
    }

    /// This agent's UAV.
    pub(super) fn uav(&self) -> u32 {
        self.config.uav
    }

    /// Waits for a wake-up until `deadline` at most, counting the time to `phase`; notes
    /// end-of-run and interrupts.
    pub(super) fn wait(&mut self, deadline: Instant, phase: &'static str) {
        let timeout = deadline.saturating_duration_since(Instant::now());
        if timeout.is_zero() {
            return;
        }
        let before = self.clock.enter(phase);
        let woken = wait_for_wake(self.waitset, &self.links.wake, timeout);
        self.clock.enter(before);
        match woken {
            Ok(wake) => {
                self.end_of_run |= wake.end_of_run;
                self.interrupted |= wake.interrupted;
            }
            Err(e) => {
                tracing::warn!(error = ?e, "wait failed");
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    }

    /// Whether a termination request came or the shutdown flag is set.
    pub(super) fn stopping(&self) -> bool {
        self.interrupted || self.shutdown.load(Ordering::Relaxed)
    }

    /// Whether the agent is stopping or the run ended: no wait is worth finishing.
    pub(super) fn leaving(&self) -> bool {
        self.stopping() || self.end_of_run
    }

    /// Why the loop should end now, if it should.
    pub(super) fn ended(&self) -> Option<EndReason> {
        if self.end_of_run {
            return Some(EndReason::EndOfRun);
        }
        self.stopping().then_some(EndReason::Interrupted)
    }

    /// Sends the world the command answering step `step` (or a hello), with a new yaw
    /// reference if any.
    pub(super) fn send_command(&self, step: u64, yaw_ref: Option<f64>) -> Result<(), LinkError> {
        self.links.send_command(UavCommand {
            run_tag: self.run_tag,
            step,
            uav: self.config.uav,
            has_yaw_ref: u32::from(yaw_ref.is_some()),
            yaw_ref_rad: yaw_ref.unwrap_or(0.0),
            incarnation: self.incarnation,
        })
    }

    /// Publishes this agent's message of step `step` (an estimate, its sets for the
    /// observers, a token).
    pub(super) fn send(&self, kind: WireKind, step: u64, bytes: &[u8]) -> Result<(), LinkError> {
        self.links
            .send_wire(kind, self.run_tag, self.config.uav, step, bytes)
    }
}
