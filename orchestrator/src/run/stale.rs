//! Cleaning what killed runs left behind: iceoryx2 files of runs none of whose nodes is alive.
//!
//! Which run a file belongs to is read from its name by [`protocol::ipc::run_of_file`]
//! ([`runs_with_files`] lists them).

use protocol::ipc::{remove_run_files, runs_with_files, scan_nodes};
use protocol::service::RunId;

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
            Ok(scan) if scan.alive.is_empty() => match remove_run_files(&run) {
                Ok(n) => {
                    runs += 1;
                    files += n;
                    tracing::debug!(run = %run, files = n, "removed a dead run's files");
                }
                Err(e) => {
                    tracing::warn!(run = %run, error = %e, "cannot remove a dead run's files")
                }
            },
            Ok(_) => {}
            Err(e) => tracing::debug!(run = %run, error = %e, "cannot list a run's nodes"),
        }
    }
    (runs, files)
}
