//! The bench's own run: its id, its temp dir and its iceoryx2 files, removed however the bench
//! ends; and what earlier benches killed before their cleanup left behind.

use std::path::PathBuf;

use anyhow::Context;
use protocol::ipc as pipc;
use protocol::service::RunId;

/// Removes the run's iceoryx2 files and the bench's temp dir when the bench ends, however it
/// ends (declared before the children, so they are gone first).
pub(super) struct RunFiles {
    /// The run.
    pub(super) run: RunId,
    /// Its temp dir.
    pub(super) dir: PathBuf,
}

impl Drop for RunFiles {
    fn drop(&mut self) {
        if let Err(e) = pipc::remove_run_files(&self.run) {
            tracing::warn!(error = %e, run = %self.run, "cannot remove the run's files");
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

impl RunFiles {
    /// A new bench run, `bench-ipc-{pid}-{nanos}`, and its temp dir, created.
    pub(super) fn create() -> anyhow::Result<RunFiles> {
        let stamp = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let run = RunId::new(&format!("{RUN_ID_PREFIX}{}-{stamp}", std::process::id()))?;
        let dir = std::env::temp_dir().join(format!("fleet-{run}"));
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        Ok(RunFiles { run, dir })
    }
}

/// Start of every bench run id: `bench-ipc-{pid}-{nanos}`.
const RUN_ID_PREFIX: &str = "bench-ipc-";

/// Whether `run` is a bench run (`bench-ipc-{pid}-{nanos}`) whose process is gone (a bench
/// killed with SIGKILL cannot clean up; the next one does).
fn is_stale_bench_run(run: &RunId) -> bool {
    let Some((pid, nanos)) = run
        .as_str()
        .strip_prefix(RUN_ID_PREFIX)
        .and_then(|rest| rest.split_once('-'))
    else {
        return false;
    };
    let (Ok(pid), Ok(_)) = (pid.parse::<libc::pid_t>(), nanos.parse::<u32>()) else {
        return false;
    };
    // SAFETY: kill with signal 0 only checks whether the process exists.
    let failed = unsafe { libc::kill(pid, 0) } != 0;
    failed && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH)
}

/// Removes what earlier bench runs killed before their cleanup left behind.
pub(super) fn remove_stale_runs() {
    let runs = match pipc::runs_with_files() {
        Ok(runs) => runs,
        Err(e) => {
            tracing::debug!(error = %e, "cannot list the iceoryx2 files of earlier runs");
            return;
        }
    };
    for run in runs.into_iter().filter(is_stale_bench_run) {
        drop(RunFiles {
            dir: std::env::temp_dir().join(format!("fleet-{run}")),
            run,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_bench_runs_of_dead_processes_are_stale() {
        let run = |id: &str| RunId::new(id).unwrap();
        let me = std::process::id();
        assert!(!is_stale_bench_run(&run(&format!("bench-ipc-{me}-5"))));
        assert!(!is_stale_bench_run(&run("other-run")));
        assert!(!is_stale_bench_run(&run("bench-ipc-x-5")));
        assert!(!is_stale_bench_run(&run("bench-ipc-2147483632-4-2")));
        // Pid 0x7ffffff0 is above Linux's pid_max, so no process has it.
        assert!(is_stale_bench_run(&run("bench-ipc-2147483632-42")));
        let file = "iox2_sf_bench-ipc-2147483632-42_0354a209029e7d094a81.service";
        assert!(pipc::run_of_file(file).is_some_and(|r| is_stale_bench_run(&r)));
    }
}
