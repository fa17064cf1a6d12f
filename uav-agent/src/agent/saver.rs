//! Writes an agent's checkpoints on a thread of their own, so that the disk's flushes (tens of
//! milliseconds on a busy machine) are never on the step's critical path.
//!
//! The agent hands over a copy of its state after each step ([`CheckpointSaver::save`]); the
//! thread writes the newest state it was handed with [`CheckpointFile::save`] (atomic and
//! durable, as ever). A state handed over while the previous one is still being written
//! waits; a newer one replaces it (it is *superseded*: the file skips that step). So the file
//! always holds a whole checkpoint of a step the agent acked, at most the write in flight
//! behind. [`CheckpointSaver::finish`] writes what is pending and returns the counts.

use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::Instant;

use protocol::resources::{CpuClock, PhaseTime};

use super::checkpoint::CheckpointFile;
use crate::estimator::EstimatorState;

/// What the saver did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SaverStats {
    /// Checkpoints written.
    pub saved: u64,
    /// Checkpoints that could not be written.
    pub failed: u64,
    /// States replaced by a newer one before they were written.
    pub superseded: u64,
    /// The writing thread's CPU and wall time spent writing.
    pub writing: PhaseTime,
}

/// The state waiting to be written, and whether the agent is done.
#[derive(Default)]
struct Slot {
    pending: Option<EstimatorState>,
    superseded: u64,
    closed: bool,
}

type Shared = Arc<(Mutex<Slot>, Condvar)>;

/// A thread that writes the newest state it was handed to a checkpoint file.
pub struct CheckpointSaver {
    shared: Shared,
    thread: Option<JoinHandle<SaverStats>>,
}

impl CheckpointSaver {
    /// Starts the thread writing to `file`.
    pub fn start(file: CheckpointFile) -> std::io::Result<CheckpointSaver> {
        let shared: Shared = Arc::default();
        let theirs = shared.clone();
        let thread = std::thread::Builder::new()
            .name("checkpoint".into())
            .spawn(move || write_loop(&file, &theirs))?;
        Ok(CheckpointSaver {
            shared,
            thread: Some(thread),
        })
    }

    /// Hands `state` over to be written (replacing a state still waiting).
    pub fn save(&self, state: EstimatorState) {
        let (slot, wake) = &*self.shared;
        let mut slot = slot.lock().unwrap_or_else(PoisonError::into_inner);
        if slot.pending.replace(state).is_some() {
            slot.superseded += 1;
        }
        wake.notify_one();
    }

    /// Writes what is pending, stops the thread and returns what it did.
    pub fn finish(mut self) -> SaverStats {
        self.stop()
    }

    fn stop(&mut self) -> SaverStats {
        {
            let (slot, wake) = &*self.shared;
            slot.lock().unwrap_or_else(PoisonError::into_inner).closed = true;
            wake.notify_one();
        }
        let stats = self.thread.take().map(|t| t.join());
        let superseded = self
            .shared
            .0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .superseded;
        match stats {
            Some(Ok(stats)) => SaverStats {
                superseded,
                ..stats
            },
            Some(Err(_)) => {
                tracing::error!("the checkpoint thread panicked");
                SaverStats::default()
            }
            None => SaverStats::default(),
        }
    }
}

impl Drop for CheckpointSaver {
    fn drop(&mut self) {
        if self.thread.is_some() {
            self.stop();
        }
    }
}

fn write_loop(file: &CheckpointFile, shared: &Shared) -> SaverStats {
    let (slot, wake) = &**shared;
    let mut stats = SaverStats::default();
    loop {
        let state = {
            let mut slot = slot.lock().unwrap_or_else(PoisonError::into_inner);
            loop {
                if let Some(state) = slot.pending.take() {
                    break state;
                }
                if slot.closed {
                    return stats;
                }
                slot = wake.wait(slot).unwrap_or_else(PoisonError::into_inner);
            }
        };
        let (cpu, wall) = (CpuClock::Thread.now(), Instant::now());
        match file.save(&state) {
            Ok(()) => stats.saved += 1,
            Err(e) => {
                stats.failed += 1;
                tracing::warn!(error = %e, "cannot write the checkpoint");
            }
        }
        stats.writing.cpu_s += CpuClock::Thread.now().saturating_sub(cpu).as_secs_f64();
        stats.writing.wall_s += wall.elapsed().as_secs_f64();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::checkpoint::Owner;
    use crate::estimator::EstimatorConfig;
    use protocol::scenario::Scenario;

    #[test]
    fn the_newest_state_handed_over_is_the_one_on_disk() {
        let dir = std::env::temp_dir().join(format!("saver-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let mut scenario = Scenario::default();
        scenario.region.half_extent_m = 50.0;
        let config = EstimatorConfig::from_scenario(&scenario);
        let file = CheckpointFile::new(dir.join("agent-0.ckpt"), Owner::new(7, 0, &scenario));
        let saver = CheckpointSaver::start(file.clone()).expect("thread");
        let mut state = EstimatorState::new(&config);
        for step in 1..=5 {
            state.step = step;
            saver.save(state.clone());
        }
        let stats = saver.finish();
        assert_eq!(stats.saved + stats.superseded, 5, "{stats:?}");
        assert!(stats.saved >= 1 && stats.failed == 0, "{stats:?}");
        let back = file.load(&config).expect("load").expect("a checkpoint");
        assert_eq!(back.state().step, 5);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
