//! Running a sweep's runs, up to `--jobs` of them at once.
//!
//! With `--cache`, a run found in the store ([`RunCache`]) is taken from it instead of run,
//! and a run that completes is stored.
//!
//! Every run is the whole of `fleet run` ([`execute`], then [`write_results`]) with its own
//! run id (so its own iceoryx2 prefix: runs never see each other's services or files), its
//! own output, log and checkpoint directories, and its own processes. The runs of a sweep
//! share one single-threaded tokio runtime: the work is in their child processes and
//! observer threads, and the pictures are drawn on the blocking pool, so a run finishing
//! never stalls the others' event loops.
//!
//! **Stopping.** SIGINT or SIGTERM stops the sweep: no run starts any more, and every running
//! run stops its children as `fleet run` does (each run listens for the signals itself). The
//! pool polls its runs inside the sweep's own task, and a run is started and first polled in
//! one poll of the pool, which registers its signal listeners before it starts any process.
//! Signals reach listeners only between polls, so a signal either finds a run listening or
//! finds the sweep's own listener first and stops the pool before the run exists: no run can
//! slip past a Ctrl-C.

use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll};

use anyhow::Context as _;
use tokio::signal::unix::{SignalKind, signal};

use super::{PlannedRun, RunCache};
use crate::outcome::Outcome;
use crate::run::{execute, outcome, write_results};
use fleet_observe::results::summary::Summary;

/// How one run ended.
pub(super) enum RunEnd {
    /// It ran and its results are written.
    Done {
        /// Its summary.
        summary: Box<Summary>,
        /// A signal cut it short.
        interrupted: bool,
        /// It did not complete (a process failed, or it was interrupted).
        failed: bool,
        /// It was taken from the run cache, not run.
        cached: bool,
    },
    /// It could not run, or its results could not be written.
    Error(anyhow::Error),
}

/// A run in progress: its place in the sweep's list and how it ends.
type Running<'a> = Pin<Box<dyn Future<Output = (usize, RunEnd)> + 'a>>;

/// The runs waiting to start and those running.
struct Pool<'a> {
    waiting: std::iter::Enumerate<std::slice::Iter<'a, PlannedRun>>,
    running: Vec<Running<'a>>,
    jobs: usize,
    cache: Option<&'a RunCache>,
    /// Whether runs may still start.
    open: bool,
}

impl<'a> Pool<'a> {
    /// Starts runs up to the limit, then polls every running one: the next to finish, or
    /// `None` once every run that was started has finished and none may start.
    fn poll_next(&mut self, cx: &mut Context<'_>) -> Poll<Option<(usize, RunEnd)>> {
        while self.open && self.running.len() < self.jobs {
            match self.waiting.next() {
                Some((index, run)) => {
                    self.running.push(Box::pin(one_run(index, run, self.cache)));
                }
                None => self.open = false,
            }
        }
        for i in 0..self.running.len() {
            if let Poll::Ready(done) = self.running[i].as_mut().poll(cx) {
                // The order of the others does not matter: each is polled every time.
                drop(self.running.swap_remove(i));
                return Poll::Ready(Some(done));
            }
        }
        if self.running.is_empty() && !self.open {
            Poll::Ready(None)
        } else {
            Poll::Pending
        }
    }
}

/// One run: takes it from the cache, or executes it, writes its results and stores it.
async fn one_run(index: usize, run: &PlannedRun, cache: Option<&RunCache>) -> (usize, RunEnd) {
    let key = cache.and_then(|c| c.key(&run.config));
    if let (Some(cache), Some(key)) = (cache, &key) {
        match cache.take(key, &run.config) {
            Ok(Some(summary)) => {
                let end = RunEnd::Done {
                    summary: Box::new(summary),
                    interrupted: false,
                    failed: false,
                    cached: true,
                };
                return (index, end);
            }
            Ok(None) => {}
            Err(e) => eprintln!("fleet: [{}] not taken from the cache: {e:#}", run.label),
        }
    }
    let end = match execute(&run.config, &run.label).await {
        Ok(record) => {
            let interrupted = record.interrupted;
            let failed = outcome(&record) != Outcome::Success;
            match tokio::task::spawn_blocking(move || write_results(&record)).await {
                Ok(Ok(summary)) => RunEnd::Done {
                    summary: Box::new(summary),
                    interrupted,
                    failed,
                    cached: false,
                },
                Ok(Err(e)) => RunEnd::Error(e),
                Err(e) => RunEnd::Error(anyhow::anyhow!("writing the results failed: {e}")),
            }
        }
        Err(e) => RunEnd::Error(e),
    };
    if let (
        Some(cache),
        Some(key),
        RunEnd::Done {
            failed: false,
            interrupted: false,
            ..
        },
    ) = (cache, &key, &end)
        && let Err(e) = cache.store(key, &run.config.out)
    {
        eprintln!("fleet: [{}] not stored in the cache: {e:#}", run.label);
    }
    (index, end)
}

/// Runs `runs`, at most `jobs` at once, in list order as places free up, each taken from
/// `cache` when it holds it; `done` is called with each run's place in `runs` and its end as
/// it finishes. Returns whether a signal stopped the sweep.
pub(super) async fn run_all(
    runs: &[PlannedRun],
    jobs: usize,
    cache: Option<&RunCache>,
    mut done: impl FnMut(usize, RunEnd),
) -> anyhow::Result<bool> {
    let mut sigint = signal(SignalKind::interrupt()).context("cannot handle SIGINT")?;
    let mut sigterm = signal(SignalKind::terminate()).context("cannot handle SIGTERM")?;
    let mut pool = Pool {
        waiting: runs.iter().enumerate(),
        running: Vec::new(),
        jobs: jobs.max(1),
        cache,
        open: true,
    };
    let mut interrupted = false;
    loop {
        let signal = tokio::select! {
            // Signals first: a run must not start once one arrived.
            biased;
            _ = sigint.recv() => "SIGINT",
            _ = sigterm.recv() => "SIGTERM",
            next = std::future::poll_fn(|cx| pool.poll_next(cx)) => match next {
                Some((index, end)) => {
                    done(index, end);
                    continue;
                }
                None => break,
            },
        };
        if !interrupted {
            interrupted = true;
            pool.open = false;
            eprintln!(
                "fleet: {signal} received: stopping the sweep ({} run(s) stopping)",
                pool.running.len()
            );
        }
    }
    Ok(interrupted)
}
