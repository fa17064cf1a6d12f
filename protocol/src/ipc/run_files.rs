//! A run's iceoryx2 files: telling a file's run from its name, listing them, removing them.
//!
//! iceoryx2 names each file `{global.prefix}{its own name}` and keeps them in `/dev/shm` and,
//! in subdirectories, under its root directory. setfleet's prefix is
//! [`RunId::file_prefix`], `iox2_sf_{run}_`, and iceoryx2's own name starts with a long hex
//! hash, a long decimal node id or `node`. A run id may hold `_`, so run `a_b`'s files also
//! start with run `a`'s prefix: what follows the prefix tells them apart (`b_...` is not
//! iceoryx2's naming). This module is the only place that reads those names.

use std::collections::BTreeSet;
use std::io;
use std::path::{Path, PathBuf};

use iceoryx2::prelude::*;

use crate::service::{FILE_PREFIX, RunId};

/// Shortest hash or node id iceoryx2 puts after the prefix (its hashes are 40 hex digits,
/// its node ids some 24 decimal digits; a run id's own segments are shorter or not hex).
const MIN_ICEORYX_ID_LEN: usize = 20;

/// Whether `rest`, what follows a prefix in a file name, starts with iceoryx2's own naming.
fn iceoryx_name_follows(rest: &str) -> bool {
    let first = rest.split(['_', '.']).next().unwrap_or_default();
    first == "node"
        || (first.len() >= MIN_ICEORYX_ID_LEN && first.bytes().all(|b| b.is_ascii_hexdigit()))
}

/// Whether `file_name` is one of `run`'s files (and not a longer run id's).
pub fn belongs_to_run(file_name: &str, run: &RunId) -> bool {
    file_name
        .strip_prefix(&run.file_prefix())
        .is_some_and(iceoryx_name_follows)
}

/// Whether `file_name` is iceoryx2's global management segment of a domain (created with a
/// domain's first node and never removed by iceoryx2 itself; it holds a node counter that
/// node ids combine with the process id and the time, so removing it is harmless: the next
/// node creates it again).
pub fn is_global_segment(file_name: &str) -> bool {
    let suffix = Config::default().global.node.global_mgmt_suffix.to_string();
    file_name.ends_with(&suffix)
}

/// The run a setfleet iceoryx2 file belongs to, in its domain if it has one
/// ([`RunId::in_domain`]): the shortest run id after whose prefix iceoryx2's own naming
/// follows. `None` for a file that is not setfleet's.
pub fn run_of_file(file_name: &str) -> Option<RunId> {
    let rest = file_name.strip_prefix(FILE_PREFIX)?;
    rest.match_indices('_').find_map(|(i, _)| {
        if iceoryx_name_follows(&rest[i + 1..]) {
            RunId::from_domain_id(&rest[..i])
        } else {
            None
        }
    })
}

/// Calls `visit` with the path and name of every file in `/dev/shm` and under iceoryx2's root
/// directory (a directory that does not exist holds nothing).
fn visit_iceoryx_files(mut visit: impl FnMut(PathBuf, &str)) -> io::Result<()> {
    visit_dir(Path::new("/dev/shm"), false, &mut visit)?;
    let root = PathBuf::from(Config::default().global.root_path().to_string());
    visit_dir(&root, true, &mut visit)
}

fn visit_dir(dir: &Path, recursive: bool, visit: &mut impl FnMut(PathBuf, &str)) -> io::Result<()> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        // Not there (yet), or removed by another cleaner meanwhile.
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e),
    };
    for entry in entries {
        let entry = entry?;
        if entry.file_type()?.is_dir() {
            if recursive {
                visit_dir(&entry.path(), true, visit)?;
            }
        } else {
            visit(entry.path(), &entry.file_name().to_string_lossy());
        }
    }
    Ok(())
}

/// The files of `run` in `/dev/shm` and under iceoryx2's root directory.
pub fn run_files(run: &RunId) -> io::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    visit_iceoryx_files(|path, name| {
        if belongs_to_run(name, run) {
            out.push(path);
        }
    })?;
    Ok(out)
}

/// Every run (each simulated host's domain apart) that has files in `/dev/shm` or under
/// iceoryx2's root directory, by id.
pub fn runs_with_files() -> io::Result<Vec<RunId>> {
    let mut ids = BTreeSet::new();
    visit_iceoryx_files(|_, name| {
        if let Some(run) = run_of_file(name) {
            ids.insert((run.as_str().to_owned(), run.domain()));
        }
    })?;
    Ok(ids
        .into_iter()
        .filter_map(|(id, domain)| {
            let run = RunId::new(&id).ok()?;
            Some(domain.map_or_else(|| run.clone(), |d| run.in_domain(d)))
        })
        .collect())
}

/// Last resort once every process of `run` ended: deletes the run's files in `/dev/shm` and
/// under iceoryx2's root directory. Returns how many files were removed. Never call it while
/// a process of the run is alive.
pub fn remove_run_files(run: &RunId) -> io::Result<usize> {
    let files = run_files(run)?;
    let mut removed = 0;
    for f in &files {
        match std::fs::remove_file(f) {
            Ok(()) => removed += 1,
            // Another cleaner got there first.
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
    }
    // iceoryx2 keeps a node's files in a directory named by the node id (no prefix): remove
    // the ones this left empty, never /dev/shm or the root itself.
    let root = PathBuf::from(Config::default().global.root_path().to_string());
    for f in &files {
        if let Some(parent) = f
            .parent()
            .filter(|p| *p != Path::new("/dev/shm") && *p != root)
        {
            let _ = std::fs::remove_dir(parent);
        }
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    const HASH: &str = "0354a209029e7d094a819e2d4030ea331e6caaf0";

    #[test]
    fn run_files_are_told_apart_from_a_longer_run_id() {
        let a = RunId::new("a").unwrap();
        assert!(belongs_to_run(
            &format!("iox2_sf_a_{HASH}_6338__0.data"),
            &a
        ));
        assert!(belongs_to_run(
            "iox2_sf_a_372037203897852790578837.node_monitor",
            &a
        ));
        assert!(belongs_to_run("iox2_sf_a_node.details", &a));
        let global = format!("iox2_sf_a_{HASH}_node.0_10_0.global_mgmt");
        assert!(belongs_to_run(&global, &a));
        assert!(is_global_segment(&global));
        assert!(!is_global_segment(&format!("iox2_sf_a_{HASH}.service")));
        assert!(!belongs_to_run(&format!("iox2_sf_a_b_{HASH}.service"), &a));
        assert!(!belongs_to_run("iox2_other.service", &a));
        assert!(belongs_to_run(
            &format!("iox2_sf_a_b_{HASH}.service"),
            &RunId::new("a_b").unwrap()
        ));
    }

    #[test]
    fn run_ids_are_read_back_from_file_names() {
        let run = |n: &str| run_of_file(n).map(|r| r.as_str().to_owned());
        assert_eq!(
            run(&format!("iox2_sf_def12034_{HASH}_node.0_10_0.global_mgmt")),
            Some("def12034".into())
        );
        assert_eq!(
            run(&format!("iox2_sf_a_b-c_{HASH}.service")),
            Some("a_b-c".into())
        );
        assert_eq!(
            run("iox2_sf_r17-3_372037203897852790578837.node_monitor"),
            Some("r17-3".into())
        );
        assert_eq!(run("iox2_sf_t1_node.details"), Some("t1".into()));
        assert_eq!(run("iox2_other_x.service"), None);
        assert_eq!(run("iox2_sf_nothing"), None);
        assert_eq!(run("iox2_sf_bench-ipc-7-5_abc.service"), None);
        let host = run_of_file(&format!("iox2_sf_a_b.h3_{HASH}.service")).unwrap();
        assert_eq!(host, RunId::new("a_b").unwrap().in_domain(3));
    }

    #[test]
    fn a_host_domain_has_files_of_its_own() {
        let a = RunId::new("a").unwrap();
        let name = format!("iox2_sf_a.h1_{HASH}.service");
        assert!(!belongs_to_run(&name, &a));
        assert!(belongs_to_run(&name, &a.in_domain(1)));
        assert!(!belongs_to_run(&name, &a.in_domain(11)));
        assert!(!belongs_to_run(
            &format!("iox2_sf_a_{HASH}.service"),
            &a.in_domain(1)
        ));
    }

    #[test]
    fn a_file_read_back_to_its_run_belongs_to_that_run() {
        for name in [
            format!("iox2_sf_a_b-c_{HASH}.service"),
            format!("iox2_sf_def12034_{HASH}_node.0_10_0.global_mgmt"),
            "iox2_sf_t1_node.details".to_owned(),
        ] {
            let run = run_of_file(&name).unwrap();
            assert!(belongs_to_run(&name, &run), "{name}");
        }
    }

    #[test]
    fn a_live_run_is_listed_with_its_files_and_leaves_none_behind() {
        let run = RunId::new(&format!("ipc-files-{}", std::process::id())).unwrap();
        {
            let node =
                super::super::RunNode::new(&run, "lister", SignalHandlingMode::Disabled).unwrap();
            node.open_guidance().unwrap();
            assert!(runs_with_files().unwrap().contains(&run));
            let files = run_files(&run).unwrap();
            assert!(!files.is_empty());
            assert!(files.iter().all(|f| {
                let name = f.file_name().unwrap().to_string_lossy();
                run_of_file(&name).as_ref() == Some(&run)
            }));
        }
        remove_run_files(&run).unwrap();
        assert_eq!(run_files(&run).unwrap(), Vec::<PathBuf>::new());
        assert!(!runs_with_files().unwrap().contains(&run));
    }
}
