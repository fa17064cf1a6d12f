//! Crash-safe checkpoints of an agent's estimator state.
//!
//! An agent with a checkpoint file saves its [`EstimatorState`] there after every few steps
//! it acked ([`super::AgentConfig::checkpoint_every`]). A restarted agent reads it back before its first frame and resumes from it: the
//! first frame's prediction grows every set by the motion since the checkpoint's step, so the
//! sets hold the targets as surely as if the agent had never stopped, and nothing the agent
//! had learned (explored ground, identified targets, the map) is lost even when no peer is
//! left to resend it.
//!
//! **Off the step's path.** The step loop encodes the state and replaces the file (a write
//! and a rename: a crash or a kill of the agent cannot undo it, so a restarted agent always
//! finds the last checkpoint it wrote); a [`CheckpointFlusher`] thread then flushes it to the
//! disk, so the loop never waits for the disk.
//!
//! **Atomic.** A checkpoint is written to `<file>.tmp` and renamed over `<file>`, then the
//! file and the directory are flushed (`fsync`): a crash of the agent at any point leaves
//! either the old checkpoint or the new one, never a mix. A crash of the machine before the
//! flush may leave a file whose checks fail: it is refused like a corrupt one
//! ([`CheckpointFile::write`] flushes before the rename, for callers that wait).
//!
//! **Checked.** The file is `MAGIC`, the body's length and CRC-32, then the body (through
//! [`protocol::codec`], size-limited). The body names the run (its tag), the UAV and a
//! fingerprint of the scenario. A file that is truncated, corrupt, of another format, run,
//! UAV or scenario, or whose sets do not fit the estimator's grids is refused with a
//! [`CheckpointError`]: the caller logs it and starts fresh.
//!
//! **The agent's part.** The agent's loop holds its checkpoints in one part (`Checkpoints`):
//! the file, the thread, when to save, and what they did ([`CheckpointFigures`], printed in
//! the agent's report). Nothing else of the agent reads or writes them, and the file's format
//! is theirs alone, so both live here.

use std::fs::{self, File};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

use protocol::codec::{self, DecodeError, EncodeError};
use protocol::scenario::Scenario;
use serde::{Deserialize, Serialize};

use estimator::{Estimator, EstimatorConfig, EstimatorState};
use fleet_process::resources::PhaseClock;

use super::config::AgentConfig;
use super::phase;

/// First bytes of every checkpoint file (format version included: 02 since the state keeps
/// its frame's `P^g` and the step's news of the fleet's `H̄`), so a checkpoint of an older
/// layout is refused, not misread.
const MAGIC: &[u8; 8] = b"SFCKPT02";
/// Magic, body length (u64 LE), body CRC-32 (u32 LE).
const HEADER_BYTES: usize = 8 + 8 + 4;

/// Whose checkpoint a file is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Owner {
    /// The run's tag ([`protocol::service::RunId::tag`]).
    pub run_tag: u64,
    /// The UAV.
    pub uav: u32,
    /// CRC-32 of the scenario's TOML: a checkpoint of another scenario is refused.
    pub scenario: u32,
}

impl Owner {
    /// The owner of UAV `uav`'s checkpoints in the run tagged `run_tag` of `scenario`.
    pub fn new(run_tag: u64, uav: u32, scenario: &Scenario) -> Owner {
        Owner {
            run_tag,
            uav,
            scenario: crc32fast::hash(scenario.to_toml_string().as_bytes()),
        }
    }
}

#[derive(Serialize, Deserialize)]
struct Body {
    owner: Owner,
    state: EstimatorState,
}

/// Why a checkpoint could not be written or was refused.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// Reading or writing the file failed.
    #[error("checkpoint {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The reason.
        source: std::io::Error,
    },
    /// The state could not be encoded.
    #[error("checkpoint: {0}")]
    Encode(#[from] EncodeError),
    /// The file is not a whole, intact checkpoint.
    #[error("checkpoint {path} is corrupt: {why}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// The file is intact but belongs to another run, UAV or scenario.
    #[error("checkpoint {path} is foreign: it is {found:?}, this agent is {expected:?}")]
    Foreign {
        /// The file.
        path: PathBuf,
        /// Whose it is.
        found: Owner,
        /// Whose it should be.
        expected: Owner,
    },
    /// The state's sets do not fit this agent's grids.
    #[error("checkpoint {path} holds sets of other grids")]
    Grids {
        /// The file.
        path: PathBuf,
    },
}

/// The error of an I/O operation on `path`.
fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> CheckpointError + use<> {
    let path = path.to_owned();
    move |source| CheckpointError::Io { path, source }
}

/// One agent's checkpoint file.
#[derive(Clone, Debug)]
pub struct CheckpointFile {
    path: PathBuf,
    owner: Owner,
}

impl CheckpointFile {
    /// The checkpoint of `owner` at `path` (nothing is read or written yet).
    pub fn new(path: PathBuf, owner: Owner) -> CheckpointFile {
        CheckpointFile { path, owner }
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The file's bytes for `state`: header, then the body.
    pub fn encode(&self, state: &EstimatorState) -> Result<Vec<u8>, CheckpointError> {
        let body = codec::encode(&BodyRef {
            owner: self.owner,
            state,
        })?;
        let mut bytes = Vec::with_capacity(HEADER_BYTES + body.len());
        bytes.extend_from_slice(MAGIC);
        bytes.extend_from_slice(&(body.len() as u64).to_le_bytes());
        bytes.extend_from_slice(&crc32fast::hash(&body).to_le_bytes());
        bytes.extend_from_slice(&body);
        Ok(bytes)
    }

    /// Replaces the checkpoint with `bytes` ([`CheckpointFile::encode`]), atomically and
    /// durably: the new file is flushed before it is renamed over the old one, so even a
    /// power loss leaves the old checkpoint or the new one.
    pub fn write(&self, bytes: &[u8]) -> Result<(), CheckpointError> {
        self.put(bytes, true)?;
        self.flush_directory()
    }

    /// Replaces the checkpoint with `bytes` atomically, without waiting for the disk: written
    /// to `<file>.tmp`, renamed over the file. Once this returns the new checkpoint survives
    /// the process (a crash, a kill); it survives the machine once [`CheckpointFile::flush`]
    /// returned (a power loss before may leave a file that [`CheckpointFile::load`] refuses).
    pub fn replace(&self, bytes: &[u8]) -> Result<(), CheckpointError> {
        self.put(bytes, false)
    }

    fn put(&self, bytes: &[u8], durable: bool) -> Result<(), CheckpointError> {
        let tmp = self.path.with_extension("tmp");
        let mut file = File::create(&tmp).map_err(io_error(&tmp))?;
        file.write_all(bytes).map_err(io_error(&tmp))?;
        if durable {
            file.sync_all().map_err(io_error(&tmp))?;
        }
        drop(file);
        fs::rename(&tmp, &self.path).map_err(io_error(&self.path))
    }

    /// Flushes the checkpoint and its directory entry to the disk.
    pub fn flush(&self) -> Result<(), CheckpointError> {
        File::open(&self.path)
            .and_then(|f| f.sync_all())
            .map_err(io_error(&self.path))?;
        self.flush_directory()
    }

    /// Flushes the directory, which makes the last rename durable.
    fn flush_directory(&self) -> Result<(), CheckpointError> {
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            File::open(dir)
                .and_then(|d| d.sync_all())
                .map_err(io_error(dir))?;
        }
        Ok(())
    }

    /// The estimator resumed from the saved state ([`Estimator::with_state`]), if there is a
    /// checkpoint (`Ok(None)` when there is no file), checked against this agent's owner and
    /// grids.
    pub fn load(&self, config: &EstimatorConfig) -> Result<Option<Estimator>, CheckpointError> {
        let bytes = match fs::read(&self.path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => {
                return Err(CheckpointError::Io {
                    path: self.path.clone(),
                    source,
                });
            }
        };
        let corrupt = |why: String| CheckpointError::Corrupt {
            path: self.path.clone(),
            why,
        };
        if bytes.len() < HEADER_BYTES || &bytes[..8] != MAGIC {
            return Err(corrupt("not a setfleet checkpoint".into()));
        }
        let len = u64::from_le_bytes(bytes[8..16].try_into().unwrap_or_default());
        let crc = u32::from_le_bytes(bytes[16..20].try_into().unwrap_or_default());
        let body = &bytes[HEADER_BYTES..];
        if len != body.len() as u64 {
            return Err(corrupt(format!(
                "{} body bytes, the header says {len}",
                body.len()
            )));
        }
        if crc32fast::hash(body) != crc {
            return Err(corrupt("checksum mismatch".into()));
        }
        let body: Body = codec::decode(body).map_err(|e: DecodeError| corrupt(e.to_string()))?;
        if body.owner != self.owner {
            return Err(CheckpointError::Foreign {
                path: self.path.clone(),
                found: body.owner,
                expected: self.owner,
            });
        }
        Estimator::with_state(config.clone(), body.state)
            .map(Some)
            .map_err(|_| CheckpointError::Grids {
                path: self.path.clone(),
            })
    }
}

/// [`Body`] by reference, so saving does not clone the state.
#[derive(Serialize)]
struct BodyRef<'a> {
    owner: Owner,
    state: &'a EstimatorState,
}

/// Flushes an agent's checkpoints to the disk on a thread of its own, so that the step loop
/// never waits for the disk (a flush took 12-16 ms per step here, as long as a step's
/// estimation).
///
/// The loop replaces the file ([`CheckpointFile::replace`]: a write and a rename, which a
/// crash or a kill of the agent cannot undo) and asks for a flush
/// ([`CheckpointFlusher::request`]); the thread flushes the file and its directory. Requests
/// made while a flush runs are served by one more flush. [`CheckpointFlusher::finish`]
/// serves the last request and reports.
#[derive(Debug)]
pub struct CheckpointFlusher {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

/// What the step loop and the flushing thread share.
#[derive(Debug, Default)]
struct Shared {
    queue: Mutex<Queue>,
    wake: Condvar,
}

#[derive(Debug, Default)]
struct Queue {
    /// A checkpoint was replaced since the last flush began.
    requested: bool,
    /// No more requests will come: serve the last one, then stop.
    closing: bool,
    stats: FlushStats,
}

/// What a [`CheckpointFlusher`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FlushStats {
    /// Flushes done.
    pub flushes: u64,
    /// Requests served by a flush asked for by a later one.
    pub merged: u64,
    /// Flushes that failed (each logged).
    pub failed: u64,
    /// Wall time the thread spent flushing, milliseconds.
    pub flush_ms: f64,
}

impl CheckpointFlusher {
    /// Starts the thread that flushes `file`.
    pub fn start(file: CheckpointFile) -> std::io::Result<CheckpointFlusher> {
        let shared = Arc::new(Shared::default());
        let theirs = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("checkpoint".into())
            .spawn(move || flush_loop(&file, &theirs))?;
        Ok(CheckpointFlusher {
            shared,
            thread: Some(thread),
        })
    }

    /// Asks for a flush of the checkpoint just replaced.
    pub fn request(&self) {
        let mut queue = lock(&self.shared.queue);
        if std::mem::replace(&mut queue.requested, true) {
            queue.stats.merged += 1;
        }
        self.shared.wake.notify_one();
    }

    /// Serves the last request, stops the thread and tells what it did.
    pub fn finish(mut self) -> FlushStats {
        self.close()
    }

    fn close(&mut self) -> FlushStats {
        lock(&self.shared.queue).closing = true;
        self.shared.wake.notify_one();
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            tracing::error!("the checkpoint thread panicked");
        }
        lock(&self.shared.queue).stats
    }
}

impl Drop for CheckpointFlusher {
    fn drop(&mut self) {
        if self.thread.is_some() {
            self.close();
        }
    }
}

/// The queue, also when a thread panicked while holding it (every update of it is a single
/// assignment, so it is consistent).
fn lock(queue: &Mutex<Queue>) -> std::sync::MutexGuard<'_, Queue> {
    queue
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn flush_loop(file: &CheckpointFile, shared: &Shared) {
    loop {
        {
            let mut queue = lock(&shared.queue);
            while !queue.requested {
                if queue.closing {
                    return;
                }
                queue = shared
                    .wake
                    .wait(queue)
                    .unwrap_or_else(|poisoned| poisoned.into_inner());
            }
            queue.requested = false;
        }
        let started = Instant::now();
        let result = file.flush();
        let mut queue = lock(&shared.queue);
        queue.stats.flush_ms += started.elapsed().as_secs_f64() * 1e3;
        match result {
            Ok(()) => queue.stats.flushes += 1,
            Err(e) => {
                queue.stats.failed += 1;
                tracing::warn!(error = %e, "cannot flush the checkpoint");
            }
        }
    }
}

/// What an agent's checkpoints did, printed flat in its report
/// ([`super::AgentReport::checkpoint`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CheckpointFigures {
    /// Step of the checkpoint this agent resumed from, if it did.
    pub resumed_from_step: Option<u64>,
    /// Why a checkpoint found at start was refused, if one was.
    pub checkpoint_refused: Option<String>,
    /// Checkpoints written.
    pub checkpoints: u64,
    /// Checkpoints that could not be written.
    pub checkpoint_failures: u64,
    /// Wall time the step loop spent on checkpoints (encoding and writing them, and flushing
    /// them when there is no checkpoint thread), milliseconds.
    pub checkpoint_ms: f64,
    /// Flushes to the disk done by the checkpoint thread (one may serve several checkpoints).
    pub checkpoint_flushes: u64,
    /// Flushes that failed.
    pub checkpoint_flush_failures: u64,
    /// Wall time the checkpoint thread spent flushing, milliseconds.
    pub checkpoint_flush_ms: f64,
}

/// An agent's checkpoints as its loop uses them: the file it resumed from and saves to, the
/// thread that flushes it, when to save, and what they did.
pub(super) struct Checkpoints {
    /// The checkpoint file (none: no checkpoints).
    file: Option<CheckpointFile>,
    /// The thread that flushes the checkpoints to the disk (none: flushed in the loop).
    flusher: Option<CheckpointFlusher>,
    /// Save after the steps that are multiples of this.
    every: u64,
    /// What they did.
    figures: CheckpointFigures,
}

impl Checkpoints {
    /// The checkpoints of the agent `config` describes, and the estimator of `estimator`'s
    /// grids it starts from: the checkpoint's when there is one that it accepts, else a fresh
    /// one (a resumption or a refused checkpoint is noted).
    pub(super) fn open(config: &AgentConfig, estimator: &EstimatorConfig) -> (Self, Estimator) {
        let file = config.checkpoint.clone().map(|path| {
            CheckpointFile::new(
                path,
                Owner::new(config.run_id.tag(), config.uav, &config.scenario),
            )
        });
        let mut figures = CheckpointFigures::default();
        let restored = restore(file.as_ref(), estimator, &mut figures);
        let flusher = file.clone().and_then(|file| {
            CheckpointFlusher::start(file)
                .inspect_err(
                    |e| tracing::warn!(error = %e, "no checkpoint thread: flushing in the loop"),
                )
                .ok()
        });
        let checkpoints = Checkpoints {
            file,
            flusher,
            every: config.checkpoint_every.max(1),
            figures,
        };
        (checkpoints, restored)
    }

    /// The step of the checkpoint the agent resumed from, if it did.
    pub(super) fn resumed_from(&self) -> Option<u64> {
        self.figures.resumed_from_step
    }

    /// The agent dropped the state it resumed from and starts fresh (a checkpoint of a run
    /// that was started over).
    pub(super) fn start_fresh(&mut self) {
        self.figures.resumed_from_step = None;
    }

    /// Whether the agent saves after folding step `k` in.
    pub(super) fn due(&self, k: u64) -> bool {
        k.is_multiple_of(self.every)
    }

    /// Saves `state` to the checkpoint file, if there is one (a failure is logged and
    /// counted: the run goes on without it), counting the time to [`phase::CHECKPOINT`].
    /// Encodes the state and replaces the checkpoint with it; the checkpoint thread flushes it
    /// to the disk (without a thread, it is flushed here).
    pub(super) fn save(&mut self, state: &EstimatorState, clock: &mut PhaseClock) {
        let Some(file) = &self.file else {
            return;
        };
        let started = Instant::now();
        let before = clock.enter(phase::CHECKPOINT);
        let saved = file.encode(state).and_then(|bytes| match &self.flusher {
            Some(flusher) => {
                file.replace(&bytes)?;
                flusher.request();
                Ok(())
            }
            None => file.write(&bytes),
        });
        clock.enter(before);
        self.figures.checkpoint_ms += started.elapsed().as_secs_f64() * 1e3;
        match saved {
            Ok(()) => self.figures.checkpoints += 1,
            Err(e) => {
                self.figures.checkpoint_failures += 1;
                tracing::warn!(error = %e, "cannot write the checkpoint");
            }
        }
    }

    /// What the checkpoints did, once the checkpoint thread served the last request.
    pub(super) fn finish(mut self) -> CheckpointFigures {
        if let Some(flusher) = self.flusher.take() {
            let stats = flusher.finish();
            self.figures.checkpoint_flushes = stats.flushes;
            self.figures.checkpoint_flush_failures = stats.failed;
            self.figures.checkpoint_flush_ms = stats.flush_ms;
        }
        self.figures
    }
}

/// The estimator the agent starts from: the checkpoint's when there is one that it accepts,
/// else a fresh one; `figures` note a resumption or a refused checkpoint.
fn restore(
    checkpoint: Option<&CheckpointFile>,
    config: &EstimatorConfig,
    figures: &mut CheckpointFigures,
) -> Estimator {
    match checkpoint.map(|c| c.load(config)) {
        Some(Ok(Some(estimator))) => {
            let step = estimator.state().step;
            tracing::info!(step, "resuming from the checkpoint");
            figures.resumed_from_step = Some(step);
            estimator
        }
        Some(Err(e)) => {
            tracing::warn!(error = %e, "checkpoint refused: starting fresh");
            figures.checkpoint_refused = Some(e.to_string());
            Estimator::new(config.clone())
        }
        Some(Ok(None)) | None => Estimator::new(config.clone()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> Scenario {
        let mut s = Scenario::default();
        s.region.half_extent_m = 60.0;
        s
    }

    fn state(config: &EstimatorConfig) -> EstimatorState {
        let mut state = Estimator::new(config.clone()).into_state();
        state.step = 42;
        state.frames = 7;
        state.explored.set((3, 2), true);
        state
    }

    fn dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("setfleet-ckpt-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn a_saved_state_comes_back_whole_and_no_temporary_file_is_left() {
        let scenario = small();
        let config = EstimatorConfig::from_scenario(&scenario);
        let dir = dir("roundtrip");
        let file = CheckpointFile::new(dir.join("agent-1.ckpt"), Owner::new(9, 1, &scenario));
        assert!(file.load(&config).unwrap().is_none());
        let saved = state(&config);
        file.write(&file.encode(&saved).unwrap()).unwrap();
        file.write(&file.encode(&saved).unwrap()).unwrap();
        let back = file.load(&config).unwrap().expect("a checkpoint");
        let back = back.state();
        assert_eq!((back.step, back.frames), (42, 7));
        assert_eq!(back.explored, saved.explored);
        assert_eq!(back.undetected.cells(), saved.undetected.cells());
        let names: Vec<_> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["agent-1.ckpt"]);
        fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn replaced_checkpoints_are_flushed_by_the_thread_and_every_request_counted() {
        let scenario = small();
        let config = EstimatorConfig::from_scenario(&scenario);
        let dir = dir("flusher");
        let file = CheckpointFile::new(dir.join("agent-2.ckpt"), Owner::new(9, 2, &scenario));
        let flusher = CheckpointFlusher::start(file.clone()).unwrap();
        let mut saved = state(&config);
        for step in 1..=25 {
            saved.step = step;
            saved.explored.set((step as u32, 5), true);
            file.replace(&file.encode(&saved).unwrap()).unwrap();
            flusher.request();
            // What a killed agent leaves: the last state replaced, whether flushed or not.
            let back = file.load(&config).unwrap().expect("a checkpoint");
            assert_eq!(back.state().step, step);
        }
        let stats = flusher.finish();
        assert_eq!(stats.failed, 0);
        assert_eq!(stats.flushes + stats.merged, 25);
        assert!(stats.flushes >= 1);
        assert_eq!(
            file.load(&config).unwrap().unwrap().state().explored,
            saved.explored
        );

        // A file that cannot be flushed is counted and the thread still stops.
        let gone = CheckpointFile::new(dir.join("gone/agent-2.ckpt"), Owner::new(9, 2, &scenario));
        let flusher = CheckpointFlusher::start(gone).unwrap();
        flusher.request();
        let stats = flusher.finish();
        assert_eq!((stats.flushes, stats.failed), (0, 1));
        fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn corrupt_truncated_and_foreign_checkpoints_are_refused() {
        let scenario = small();
        let config = EstimatorConfig::from_scenario(&scenario);
        let dir = dir("refused");
        let path = dir.join("agent-0.ckpt");
        let mine = CheckpointFile::new(path.clone(), Owner::new(9, 0, &scenario));
        mine.write(&mine.encode(&state(&config)).unwrap()).unwrap();
        let good = fs::read(&path).unwrap();

        let mut flipped = good.clone();
        let last = flipped.len() - 1;
        flipped[last] ^= 0x40;
        fs::write(&path, &flipped).unwrap();
        assert!(matches!(
            mine.load(&config),
            Err(CheckpointError::Corrupt { .. })
        ));
        fs::write(&path, &good[..good.len() / 2]).unwrap();
        assert!(matches!(
            mine.load(&config),
            Err(CheckpointError::Corrupt { .. })
        ));
        fs::write(&path, b"not a checkpoint at all").unwrap();
        assert!(matches!(
            mine.load(&config),
            Err(CheckpointError::Corrupt { .. })
        ));

        fs::write(&path, &good).unwrap();
        for other in [
            Owner::new(10, 0, &scenario),
            Owner::new(9, 1, &scenario),
            Owner::new(9, 0, &Scenario::default()),
        ] {
            let theirs = CheckpointFile::new(path.clone(), other);
            assert!(matches!(
                theirs.load(&config),
                Err(CheckpointError::Foreign { .. })
            ));
        }
        let other_grids = EstimatorConfig::from_scenario(&Scenario::default());
        assert!(matches!(
            mine.load(&other_grids),
            Err(CheckpointError::Grids { .. })
        ));
        assert!(mine.load(&config).unwrap().is_some());
        fs::remove_dir_all(dir).unwrap();
    }
}
