//! What `fleet run` and `fleet host` share around their processes: the output directory
//! ([`RunDirs`]: the logs, the scenario every child reads, the iceoryx2 configurations, the
//! checkpoints emptied of an earlier run), the termination signals ([`Signals`]), and the
//! end ([`stop_agents_and_bridges`], [`clean_run_files`]): every agent and bridge stopped
//! within a bounded grace, then the run's iceoryx2 files removed.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context as _;
use protocol::ipc::{cleanup_stale, remove_run_files, run_files};
use protocol::scenario::Scenario;
use protocol::service::RunId;
use tokio::signal::unix::{Signal, SignalKind, signal};

use super::children::Children;
use super::hosts::HostLayout;
use super::iox2;

/// How long the children get to exit on their own at the end, and after SIGTERM.
pub const EXIT_GRACE: Duration = Duration::from_secs(10);

/// The run's directories and files under its output directory.
#[derive(Clone, Debug)]
pub struct RunDirs {
    /// Every process's log.
    pub logs: PathBuf,
    /// The resolved scenario, which every child reads.
    pub scenario_file: PathBuf,
    /// The agents' checkpoints.
    pub checkpoints: PathBuf,
}

impl RunDirs {
    /// Makes the output directory `out` of run `run` of `scenario` over `layout`: the logs
    /// directory, `scenario.toml`, the iceoryx2 configurations and an empty checkpoints
    /// directory (an agent must never resume from another run's checkpoint; it would refuse
    /// it anyway).
    pub fn prepare(
        out: &Path,
        scenario: &Scenario,
        layout: &HostLayout,
        run: &RunId,
    ) -> anyhow::Result<RunDirs> {
        let logs = out.join("logs");
        std::fs::create_dir_all(&logs)
            .with_context(|| format!("cannot create the output directory {}", logs.display()))?;
        let scenario_file = out.join("scenario.toml");
        std::fs::write(&scenario_file, scenario.to_toml_string())
            .with_context(|| format!("cannot write {}", scenario_file.display()))?;
        iox2::write_configs(out, layout, run)?;
        let checkpoints = out.join("checkpoints");
        fresh_dir(&checkpoints)?;
        Ok(RunDirs {
            logs,
            scenario_file,
            checkpoints,
        })
    }
}

/// Creates `dir`, emptied of what was in it.
fn fresh_dir(dir: &Path) -> anyhow::Result<()> {
    match std::fs::remove_dir_all(dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(e).with_context(|| format!("cannot empty {}", dir.display())),
    }
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))
}

/// SIGINT and SIGTERM, taken before any child starts so that an early Ctrl-C still cleans up.
pub struct Signals {
    interrupt: Signal,
    terminate: Signal,
}

impl Signals {
    /// Takes over SIGINT and SIGTERM (inside a tokio runtime).
    pub fn take() -> anyhow::Result<Signals> {
        Ok(Signals {
            interrupt: signal(SignalKind::interrupt()).context("cannot handle SIGINT")?,
            terminate: signal(SignalKind::terminate()).context("cannot handle SIGTERM")?,
        })
    }

    /// Waits for either; its name.
    pub async fn recv(&mut self) -> &'static str {
        tokio::select! {
            _ = self.interrupt.recv() => "SIGINT",
            _ = self.terminate.recv() => "SIGTERM",
        }
    }
}

/// Stops the agents and then the bridges, each within [`EXIT_GRACE`]: the agents first get
/// the grace to exit on their own when `let_agents_finish` (the run ended), then SIGTERM and
/// the grace again, then SIGKILL.
pub async fn stop_agents_and_bridges(children: &mut Children, let_agents_finish: bool) {
    if let_agents_finish {
        children.wait_agents(EXIT_GRACE).await;
    }
    children.terminate_agents();
    children.wait_agents(EXIT_GRACE).await;
    children.kill_agents().await;
    children.stop_bridges(EXIT_GRACE).await;
}

/// Removes the run's iceoryx2 files once every process of it is gone; returns how many
/// remain (0 unless the removal failed).
pub fn clean_run_files(run: &RunId) -> usize {
    if let Err(e) = cleanup_stale(run) {
        tracing::debug!(error = %e, "cannot scan the run's nodes");
    }
    if let Err(e) = remove_run_files(run) {
        tracing::warn!(error = %e, "cannot remove the run's iceoryx2 files");
    }
    run_files(run).map_or(0, |files| {
        for f in &files {
            tracing::warn!(file = %f.display(), "iceoryx2 file left behind");
        }
        files.len()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_checkpoints_of_an_earlier_run_are_emptied() {
        let dir = std::env::temp_dir().join(format!("setfleet-dirs-{}", std::process::id()));
        let scenario = Scenario::load(None, &["uavs.count=2".into()]).expect("scenario");
        let run = RunId::new("dirstest").expect("run id");
        let layout = HostLayout::single(scenario.uavs.count);
        let first = RunDirs::prepare(&dir, &scenario, &layout, &run).expect("first");
        std::fs::write(first.checkpoints.join("agent-0.ckpt"), b"old").expect("write");
        let second = RunDirs::prepare(&dir, &scenario, &layout, &run).expect("second");
        assert!(second.logs.is_dir());
        assert!(second.scenario_file.is_file());
        assert_eq!(
            std::fs::read_dir(&second.checkpoints).expect("dir").count(),
            0
        );
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }
}
