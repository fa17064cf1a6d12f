//! The run's child processes: the world-server and one `uav-agent` per UAV, found next to the
//! `fleet` executable. Their stdout and stderr are appended to `logs/world.log` and
//! `logs/agent-<i>.log` (a restarted agent appends to its predecessor's log). Every child is
//! killed when its handle is dropped, and dies with `fleet` (the children set
//! `PR_SET_PDEATHSIG`).
//!
//! An agent can be paused (SIGSTOP) and continued (SIGCONT). Each agent process is an
//! *incarnation* with its own number, so a SIGCONT meant for a process that was killed
//! meanwhile never reaches its restarted successor; and an agent is always continued before
//! it is asked to terminate, so that no process of a run is left stopped.

use std::collections::BTreeMap;
use std::ffi::OsString;
use std::fs::OpenOptions;
use std::path::{Path, PathBuf};
use std::process::{ExitStatus, Stdio};
use std::time::Duration;

use anyhow::Context as _;
use protocol::service::RunId;
use tokio::process::{Child, Command};
use world_server::server::StepMode;

/// Paths of the binaries `fleet` starts.
#[derive(Clone, Debug)]
pub struct Binaries {
    /// `world-server`.
    pub world: PathBuf,
    /// `uav-agent`.
    pub agent: PathBuf,
}

impl Binaries {
    /// The binaries next to the running executable.
    pub fn locate() -> anyhow::Result<Binaries> {
        let exe = std::env::current_exe().context("cannot locate the fleet executable")?;
        let dir = exe
            .parent()
            .context("the fleet executable has no parent directory")?;
        let find = |name: &str| {
            let path = dir.join(name);
            if path.is_file() {
                Ok(path)
            } else {
                anyhow::bail!(
                    "cannot find {name} next to fleet (looked for {}); build every binary with \
                     `cargo build --bins`",
                    path.display()
                )
            }
        };
        Ok(Binaries {
            world: find("world-server")?,
            agent: find("uav-agent")?,
        })
    }
}

/// How an agent left the run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AgentExit {
    /// The UAV.
    pub uav: u32,
    /// Its exit status.
    pub status: ExitStatus,
}

/// The world-server and agent processes of one run.
pub struct Children {
    run: RunId,
    binaries: Binaries,
    scenario: PathBuf,
    logs: PathBuf,
    checkpoints: PathBuf,
    mode: StepMode,
    agents: BTreeMap<u32, Agent>,
    incarnations: u64,
}

/// One running agent process.
struct Agent {
    child: Child,
    /// Its number among the run's agent processes.
    incarnation: u64,
    /// Whether it was sent SIGSTOP and not SIGCONT since.
    stopped: bool,
}

impl Children {
    /// No process yet; `scenario` is the file every child reads, `logs` the log directory,
    /// `checkpoints` the agents' checkpoint directory.
    pub fn new(
        run: RunId,
        binaries: Binaries,
        scenario: PathBuf,
        logs: PathBuf,
        checkpoints: PathBuf,
        mode: StepMode,
    ) -> Children {
        Children {
            run,
            binaries,
            scenario,
            logs,
            checkpoints,
            mode,
            agents: BTreeMap::new(),
            incarnations: 0,
        }
    }

    fn spawn(&self, program: &Path, args: Vec<OsString>, log: &str) -> anyhow::Result<Child> {
        let path = self.logs.join(log);
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .with_context(|| format!("cannot open the log {}", path.display()))?;
        let stdout = file
            .try_clone()
            .with_context(|| format!("cannot open the log {}", path.display()))?;
        Command::new(program)
            .args(args)
            .stdin(Stdio::null())
            .stdout(stdout)
            .stderr(file)
            // The logs are files: no terminal colours in them.
            .env("NO_COLOR", "1")
            .kill_on_drop(true)
            .spawn()
            .with_context(|| format!("cannot start {}", program.display()))
    }

    fn common_args(&self) -> Vec<OsString> {
        vec![
            "--run-id".into(),
            self.run.as_str().into(),
            "--scenario".into(),
            self.scenario.clone().into_os_string(),
        ]
    }

    /// Starts the world-server, which waits for the agents' and the observer's hellos.
    pub fn spawn_world(&self) -> anyhow::Result<Child> {
        let mut args = self.common_args();
        args.push("--wait-observer".into());
        match self.mode {
            StepMode::Lockstep => args.extend(["--mode".into(), "lockstep".into()]),
            StepMode::Realtime { speedup } => args.extend([
                "--mode".into(),
                "realtime".into(),
                "--speedup".into(),
                speedup.to_string().into(),
            ]),
        }
        self.spawn(&self.binaries.world, args, "world.log")
    }

    /// Starts (or restarts) agent `uav`.
    pub fn spawn_agent(&mut self, uav: u32) -> anyhow::Result<()> {
        let mut args = self.common_args();
        args.extend(["--id".into(), uav.to_string().into()]);
        args.extend([
            "--checkpoint-dir".into(),
            self.checkpoints.clone().into_os_string(),
        ]);
        let child = self.spawn(&self.binaries.agent, args, &format!("agent-{uav}.log"))?;
        self.incarnations += 1;
        let agent = Agent {
            child,
            incarnation: self.incarnations,
            stopped: false,
        };
        // A predecessor not reaped yet is killed as its handle drops.
        if self.agents.insert(uav, agent).is_some() {
            tracing::warn!(uav, "agent replaced while its predecessor was running");
        }
        Ok(())
    }

    /// Stops agent `uav` with SIGSTOP; the incarnation stopped, `None` if the agent is not
    /// running or already stopped.
    pub fn pause_agent(&mut self, uav: u32) -> Option<u64> {
        let agent = self.agents.get_mut(&uav)?;
        if agent.stopped || !matches!(agent.child.try_wait(), Ok(None)) {
            return None;
        }
        send_signal(agent.child.id()?, libc::SIGSTOP);
        agent.stopped = true;
        Some(agent.incarnation)
    }

    /// Continues incarnation `incarnation` of agent `uav` with SIGCONT; false if that process
    /// is no longer running (it died or was killed while stopped) or was not stopped.
    pub fn resume_agent(&mut self, uav: u32, incarnation: u64) -> bool {
        let Some(agent) = self.agents.get_mut(&uav) else {
            return false;
        };
        if agent.incarnation != incarnation || !agent.stopped {
            return false;
        }
        continue_agent(uav, agent)
    }

    /// Kills agent `uav` with SIGKILL and reaps it (bounded); false if it was not running.
    pub async fn kill_agent(&mut self, uav: u32) -> bool {
        let Some(Agent { mut child, .. }) = self.agents.remove(&uav) else {
            return false;
        };
        // SIGKILL ends a stopped process too.
        if let Err(e) = child.start_kill() {
            tracing::warn!(uav, error = %e, "cannot kill the agent");
        }
        let reaped = tokio::time::timeout(Duration::from_secs(5), child.wait()).await;
        if !matches!(reaped, Ok(Ok(_))) {
            tracing::warn!(uav, "the killed agent was not reaped in time");
        }
        true
    }

    /// Agents that exited since the last call (removed from the set).
    pub fn reap_agents(&mut self) -> Vec<AgentExit> {
        let mut exits = Vec::new();
        self.agents
            .retain(|&uav, agent| match agent.child.try_wait() {
                Ok(Some(status)) => {
                    exits.push(AgentExit { uav, status });
                    false
                }
                Ok(None) => true,
                Err(e) => {
                    tracing::warn!(uav, error = %e, "cannot poll the agent");
                    true
                }
            });
        exits
    }

    /// Waits at most `timeout` for every agent to exit; returns their exits.
    pub async fn wait_agents(&mut self, timeout: Duration) -> Vec<AgentExit> {
        let deadline = tokio::time::Instant::now() + timeout;
        let mut exits = Vec::new();
        loop {
            exits.extend(self.reap_agents());
            if self.agents.is_empty() || tokio::time::Instant::now() >= deadline {
                return exits;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    /// Sends SIGTERM to every running agent (and SIGCONT to a stopped one, which would
    /// otherwise hold the SIGTERM pending).
    pub fn terminate_agents(&mut self) {
        for (&uav, agent) in &mut self.agents {
            if let Some(pid) = agent.child.id() {
                send_signal(pid, libc::SIGTERM);
                tracing::debug!(uav, pid, "SIGTERM sent");
            }
            if agent.stopped {
                continue_agent(uav, agent);
            }
        }
    }

    /// Kills (SIGKILL) and reaps every agent still running; returns how many there were.
    pub async fn kill_agents(&mut self) -> usize {
        let uavs: Vec<u32> = self.agents.keys().copied().collect();
        for &uav in &uavs {
            tracing::warn!(uav, "agent still running: killed");
            self.kill_agent(uav).await;
        }
        uavs.len()
    }
}

/// Sends SIGCONT to a stopped agent; whether it was still running.
fn continue_agent(uav: u32, agent: &mut Agent) -> bool {
    agent.stopped = false;
    let running = matches!(agent.child.try_wait(), Ok(None));
    if let Some(pid) = agent.child.id().filter(|_| running) {
        send_signal(pid, libc::SIGCONT);
        tracing::debug!(uav, pid, "SIGCONT sent");
    }
    running
}

/// Sends `signal` to process `pid`.
pub fn send_signal(pid: u32, signal: i32) {
    if let Ok(pid) = i32::try_from(pid)
        && pid > 0
    {
        // SAFETY: kill(2) on the pid of a child this process started and has not reaped; no
        // memory is involved.
        unsafe {
            libc::kill(pid, signal);
        }
    }
}

/// Stops the world: SIGTERM, then SIGKILL after `grace`; returns its status if it exited.
pub async fn stop_world(world: &mut Child, grace: Duration) -> Option<ExitStatus> {
    if let Ok(Some(status)) = world.try_wait() {
        return Some(status);
    }
    if let Some(pid) = world.id() {
        send_signal(pid, libc::SIGTERM);
    }
    if let Ok(Ok(status)) = tokio::time::timeout(grace, world.wait()).await {
        return Some(status);
    }
    tracing::warn!("world-server did not stop on SIGTERM: killed");
    let _ = world.start_kill();
    tokio::time::timeout(Duration::from_secs(5), world.wait())
        .await
        .ok()
        .and_then(Result::ok)
}
