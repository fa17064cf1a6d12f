//! Cleaning what killed runs left behind: iceoryx2 files of runs none of whose nodes is alive.
//!
//! A run's files carry its prefix `iox2_sf_<run>_` ([`RunId::file_prefix`]); the run id is
//! read back from a file name as the shortest prefix after which iceoryx2's own naming
//! follows (a long hex hash or node id, or `node`).

use std::collections::BTreeSet;
use std::path::Path;

use protocol::ipc::{remove_run_files, scan_nodes};
use protocol::service::RunId;

/// The prefix every setfleet file starts with, before the run id.
const SETFLEET_PREFIX: &str = "iox2_sf_";

/// The run a setfleet iceoryx2 file name belongs to.
pub fn run_of_file(name: &str) -> Option<RunId> {
    let rest = name.strip_prefix(SETFLEET_PREFIX)?;
    rest.match_indices('_').find_map(|(i, _)| {
        let after = &rest[i + 1..];
        let first = after.split(['_', '.']).next().unwrap_or_default();
        let iceoryx_name =
            first == "node" || (first.len() >= 20 && first.bytes().all(|b| b.is_ascii_hexdigit()));
        if iceoryx_name {
            RunId::new(&rest[..i]).ok()
        } else {
            None
        }
    })
}

/// Runs that have files in `/dev/shm` or under iceoryx2's root directory.
fn runs_with_files() -> BTreeSet<String> {
    let mut runs = BTreeSet::new();
    let root = iceoryx2::config::Config::default()
        .global
        .root_path()
        .to_string();
    collect(Path::new("/dev/shm"), false, &mut runs);
    collect(Path::new(&root), true, &mut runs);
    runs
}

fn collect(dir: &Path, recursive: bool, runs: &mut BTreeSet<String>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let Ok(kind) = entry.file_type() else {
            continue;
        };
        if kind.is_dir() {
            if recursive {
                collect(&entry.path(), true, runs);
            }
        } else if let Some(run) = run_of_file(&entry.file_name().to_string_lossy()) {
            runs.insert(run.as_str().to_owned());
        }
    }
}

/// Removes the files of every run none of whose nodes is alive (dead nodes' resources are
/// released first); returns (runs cleaned, files removed). `keep` is never touched.
pub fn remove_stale_runs(keep: &RunId) -> (usize, usize) {
    let (mut runs, mut files) = (0, 0);
    for id in runs_with_files() {
        let Ok(run) = RunId::new(&id) else {
            continue;
        };
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_ids_are_read_back_from_file_names() {
        let hash = "9204dd183d1c4d8e1ff592a30766ffa6765aa8b5";
        let run = |n: &str| run_of_file(n).map(|r| r.as_str().to_owned());
        assert_eq!(
            run(&format!("iox2_sf_def12034_{hash}_node.0_10_0.global_mgmt")),
            Some("def12034".into())
        );
        assert_eq!(
            run(&format!("iox2_sf_a_b-c_{hash}.service")),
            Some("a_b-c".into())
        );
        assert_eq!(
            run("iox2_sf_r17-3_372037203897852790578837.node_monitor"),
            Some("r17-3".into())
        );
        assert_eq!(run("iox2_sf_t1_node.details"), Some("t1".into()));
        assert_eq!(run("iox2_other_x.service"), None);
        assert_eq!(run("iox2_sf_nothing"), None);
    }
}
