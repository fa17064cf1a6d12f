//! Cleaning what killed runs left behind: iceoryx2 files of runs none of whose nodes is alive.
//!
//! Which run a file belongs to is read from its name by [`protocol::ipc::run_of_file`]
//! ([`runs_with_files`] lists them).
//!
//! A run being started has files before iceoryx2 lists any node of it: a node writes its
//! details file before its monitor token, and a token still starting is not listed. So a run
//! without a live node counts as left over only if one of its nodes is listed dead (a killed
//! run: its processes died with it) or none of its files was touched for
//! [`STARTING_GRACE`]; otherwise a run started next to another (`fleet sweep --jobs`, two
//! sweeps side by side) could remove the other's files while its first node is created.
//! The global management segment, which iceoryx2 creates with a domain's first node and never
//! removes, does not count as touched: a run whose processes all ended (the last ones clean
//! the dead nodes of the others) leaves only that file, and a starting run lists its first
//! node milliseconds after creating it. `fleet run` creates its observer's node before it
//! starts any child, so a starting run is listed from then on.

use std::path::PathBuf;
use std::time::{Duration, SystemTime};

use protocol::ipc::{is_global_segment, remove_run_files, run_files, runs_with_files, scan_nodes};
use protocol::service::RunId;

/// How long a run's files may go untouched with no node listed before they are left over.
pub const STARTING_GRACE: Duration = Duration::from_secs(60);

/// Removes the files of every run none of whose nodes is alive (dead nodes' resources are
/// released first); returns (runs cleaned, files removed). `keep` is never touched.
pub fn remove_stale_runs(keep: &RunId) -> (usize, usize) {
    let (mut runs, mut files) = (0, 0);
    let found = match runs_with_files() {
        Ok(found) => found,
        Err(e) => {
            tracing::warn!(error = %e, "cannot list the iceoryx2 files of earlier runs");
            return (runs, files);
        }
    };
    for run in found {
        if &run == keep {
            continue;
        }
        match scan_nodes(&run, true) {
            Ok(scan) if scan.alive.is_empty() && (!scan.dead.is_empty() || !starting(&run)) => {
                match remove_run_files(&run) {
                    Ok(n) => {
                        runs += 1;
                        files += n;
                        tracing::debug!(run = %run, files = n, "removed a dead run's files");
                    }
                    Err(e) => {
                        tracing::warn!(run = %run, error = %e, "cannot remove a dead run's files")
                    }
                }
            }
            Ok(_) => {}
            Err(e) => tracing::debug!(run = %run, error = %e, "cannot list a run's nodes"),
        }
    }
    (runs, files)
}

/// Whether a file of `run` other than the global management segment was modified within
/// [`STARTING_GRACE`] (or cannot be read: then the run is left alone too).
fn starting(run: &RunId) -> bool {
    let Ok(files) = run_files(run) else {
        return true;
    };
    let now = SystemTime::now();
    let global = |f: &&PathBuf| {
        f.file_name()
            .is_some_and(|n| is_global_segment(&n.to_string_lossy()))
    };
    files.iter().filter(|f| !global(f)).any(|f| {
        std::fs::metadata(f)
            .and_then(|m| m.modified())
            .map_or(true, |t| {
                now.duration_since(t)
                    .map_or(true, |age| age < STARTING_GRACE)
            })
    })
}
