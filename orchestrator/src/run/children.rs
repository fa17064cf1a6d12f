//! The run's child processes: the world-server and one `uav-agent` per UAV, found next to the
//! `fleet` executable, and on a run over several hosts one `fleet-bridge` per host
//! ([`super::hosts`]). Their stdout and stderr are appended to `logs/world.log`,
//! `logs/agent-<i>.log` (a restarted agent appends to its predecessor's log) and
//! `logs/bridge-h<k>.log`. Every child is
//! killed when its handle is dropped, and dies with `fleet` (the children set
//! `PR_SET_PDEATHSIG`).
//!
//! An agent can be paused (SIGSTOP) and continued (SIGCONT). Each agent process is an
//! *incarnation* with its own number, so a SIGCONT meant for a process that was killed
//! meanwhile never reaches its restarted successor; and an agent is always continued before
//! it is asked to terminate, so that no process of a run is left stopped.
//!
//! Every child is reaped here and nowhere else, after the kernel's account of the exited
//! process was read ([`fleet_process::resources::exited_child_usage`]: exact CPU time and peak
//! resident memory, a SIGKILLed agent's too). [`Children::exited`] lists every process that
//! ended, with that account ([`super::resources`] joins it to the phases and the own peak
//! memory the process reported, which replaces the kernel's peak when there is one).

use std::collections::BTreeMap;
use std::ffi::OsString;
use std::fs::OpenOptions;
use std::path::{Path, PathBuf};
use std::process::{ExitStatus, Stdio};
use std::time::Duration;

use anyhow::Context as _;
use fleet_process::resources::{ProcessUsage, exited_child_usage};
use fleet_process::startup::ChildArgs;
use protocol::service::RunId;
use tokio::process::{Child, Command};
use world_server::server::StepMode;

use super::hosts::HostLayout;

/// Paths of the binaries `fleet` starts.
#[derive(Clone, Debug)]
pub struct Binaries {
    /// `world-server`.
    pub world: PathBuf,
    /// `uav-agent`.
    pub agent: PathBuf,
    /// `fleet-bridge`, if it was built (needed only by runs over several hosts).
    pub bridge: Option<PathBuf>,
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
            bridge: find("fleet-bridge").ok(),
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

/// A child process that ended, with the kernel's account of it.
#[derive(Clone, Debug, PartialEq)]
pub struct ExitedProcess {
    /// The UAV of an agent, `None` for the world-server and bridges.
    pub uav: Option<u32>,
    /// An agent's process number among its UAV's (1 for the first, 2 after a restart, ...).
    pub incarnation: Option<u32>,
    /// The host of a bridge (its name), `None` for the world-server and agents.
    pub bridge_host: Option<String>,
    /// Its pid.
    pub pid: Option<u32>,
    /// How it ended (`None` if it could not be reaped).
    pub status: Option<ExitStatus>,
    /// CPU time and peak memory (`None` if they could not be read).
    pub usage: Option<ProcessUsage>,
}

/// The world-server and agent processes of one run.
pub struct Children {
    run: RunId,
    binaries: Binaries,
    scenario: PathBuf,
    logs: PathBuf,
    checkpoints: PathBuf,
    mode: StepMode,
    layout: HostLayout,
    world: Option<Child>,
    agents: BTreeMap<u32, Agent>,
    /// The bridges by host, on a run over several hosts.
    bridges: BTreeMap<u16, Child>,
    incarnations: u64,
    /// Agent processes started per UAV.
    uav_incarnations: BTreeMap<u32, u32>,
    exited: Vec<ExitedProcess>,
}

/// One running agent process.
struct Agent {
    child: Child,
    /// Its number among the run's agent processes.
    incarnation: u64,
    /// Its number among its UAV's processes, from 1.
    uav_incarnation: u32,
    /// Whether it was sent SIGSTOP and not SIGCONT since.
    stopped: bool,
}

/// Reaps `child` if it has exited, reading the kernel's account of it first; `None` while
/// it runs.
fn try_reap(child: &mut Child) -> std::io::Result<Option<(ExitStatus, Option<ProcessUsage>)>> {
    let usage = match child.id().map(exited_child_usage) {
        Some(Ok(None)) => return Ok(None),
        Some(Ok(Some(usage))) => Some(usage),
        Some(Err(e)) => {
            tracing::debug!(error = %e, "cannot read the child's usage");
            None
        }
        // Already reaped.
        None => None,
    };
    Ok(child.try_wait()?.map(|status| (status, usage)))
}

/// Waits at most `timeout` for `child` to exit and reaps it ([`try_reap`]).
async fn reap(child: &mut Child, timeout: Duration) -> Option<(ExitStatus, Option<ProcessUsage>)> {
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        match try_reap(child) {
            Ok(Some(exit)) => return Some(exit),
            Ok(None) => {}
            Err(e) => {
                tracing::warn!(error = %e, "cannot poll a child");
                return None;
            }
        }
        if tokio::time::Instant::now() >= deadline {
            return None;
        }
        tokio::time::sleep(REAP_POLL).await;
    }
}

/// Interval of polls for a child's exit while waiting for it.
const REAP_POLL: Duration = Duration::from_millis(10);

impl Children {
    /// No process yet; `scenario` is the file every child reads, `logs` the log directory,
    /// `checkpoints` the agents' checkpoint directory, `layout` where the agents run.
    pub fn new(
        run: RunId,
        binaries: Binaries,
        scenario: PathBuf,
        logs: PathBuf,
        checkpoints: PathBuf,
        mode: StepMode,
        layout: HostLayout,
    ) -> Children {
        Children {
            run,
            binaries,
            scenario,
            logs,
            checkpoints,
            mode,
            layout,
            world: None,
            agents: BTreeMap::new(),
            bridges: BTreeMap::new(),
            incarnations: 0,
            uav_incarnations: BTreeMap::new(),
            exited: Vec::new(),
        }
    }

    /// Every child process that ended so far, in the order they were reaped.
    pub fn exited(&self) -> &[ExitedProcess] {
        &self.exited
    }

    fn note_world_exit(
        &mut self,
        pid: Option<u32>,
        exit: Option<(ExitStatus, Option<ProcessUsage>)>,
    ) {
        self.exited.push(ExitedProcess {
            uav: None,
            incarnation: None,
            bridge_host: None,
            pid,
            status: exit.map(|(s, _)| s),
            usage: exit.and_then(|(_, u)| u),
        });
    }

    fn note_agent_exit(
        &mut self,
        uav: u32,
        agent: &Agent,
        pid: Option<u32>,
        exit: Option<(ExitStatus, Option<ProcessUsage>)>,
    ) {
        self.exited.push(ExitedProcess {
            uav: Some(uav),
            incarnation: Some(agent.uav_incarnation),
            bridge_host: None,
            pid,
            status: exit.map(|(s, _)| s),
            usage: exit.and_then(|(_, u)| u),
        });
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

    /// The arguments every child of host `host` is started with.
    fn common_args(&self, host: u16) -> Vec<OsString> {
        ChildArgs::new(
            self.run.clone(),
            self.layout.domain_arg(host),
            self.scenario.clone(),
        )
        .to_args()
    }

    /// Starts the world-server, which waits for the agents' and the observer's hellos.
    pub fn spawn_world(&mut self) -> anyhow::Result<()> {
        let mut args = self.common_args(0);
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
        self.world = Some(self.spawn(&self.binaries.world, args, "world.log")?);
        Ok(())
    }

    /// The world-server's exit status once it exited (reaped, with its usage), `None` while
    /// it runs or when it was already reaped.
    pub fn poll_world(&mut self) -> Option<ExitStatus> {
        let world = self.world.as_mut()?;
        let pid = world.id();
        match try_reap(world) {
            Ok(Some(exit)) => {
                self.world = None;
                self.note_world_exit(pid, Some(exit));
                Some(exit.0)
            }
            Ok(None) => None,
            Err(e) => {
                tracing::warn!(error = %e, "cannot poll the world-server");
                None
            }
        }
    }

    /// Waits at most `timeout` for the world-server to exit; its status if it did (`None`
    /// also when it was already reaped).
    pub async fn wait_world(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let world = self.world.as_mut()?;
        let pid = world.id();
        let exit = reap(world, timeout).await?;
        self.world = None;
        self.note_world_exit(pid, Some(exit));
        Some(exit.0)
    }

    /// Stops the world: SIGTERM, then SIGKILL after `grace`; returns its status if it exited.
    pub async fn stop_world(&mut self, grace: Duration) -> Option<ExitStatus> {
        if let Some(status) = self.poll_world() {
            return Some(status);
        }
        let pid = self.world.as_ref()?.id();
        if let Some(pid) = pid {
            send_signal(pid, libc::SIGTERM);
        }
        if let Some(status) = self.wait_world(grace).await {
            return Some(status);
        }
        tracing::warn!("world-server did not stop on SIGTERM: killed");
        let mut world = self.world.take()?;
        let _ = world.start_kill();
        let exit = reap(&mut world, Duration::from_secs(5)).await;
        self.note_world_exit(pid, exit);
        exit.map(|(s, _)| s)
    }

    /// Starts (or restarts) agent `uav`.
    pub fn spawn_agent(&mut self, uav: u32) -> anyhow::Result<()> {
        let mut args = self.common_args(self.layout.host_of(uav));
        args.extend(["--id".into(), uav.to_string().into()]);
        args.extend([
            "--checkpoint-dir".into(),
            self.checkpoints.clone().into_os_string(),
        ]);
        let child = self.spawn(&self.binaries.agent, args, &format!("agent-{uav}.log"))?;
        self.incarnations += 1;
        let uav_incarnation = self.uav_incarnations.entry(uav).or_default();
        *uav_incarnation += 1;
        let agent = Agent {
            child,
            incarnation: self.incarnations,
            uav_incarnation: *uav_incarnation,
            stopped: false,
        };
        // A predecessor not reaped yet is killed as its handle drops (its usage is lost).
        if let Some(old) = self.agents.insert(uav, agent) {
            tracing::warn!(uav, "agent replaced while its predecessor was running");
            let pid = old.child.id();
            self.note_agent_exit(uav, &old, pid, None);
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
        let Some(mut agent) = self.agents.remove(&uav) else {
            return false;
        };
        let pid = agent.child.id();
        // SIGKILL ends a stopped process too.
        if let Err(e) = agent.child.start_kill() {
            tracing::warn!(uav, error = %e, "cannot kill the agent");
        }
        let exit = reap(&mut agent.child, Duration::from_secs(5)).await;
        if exit.is_none() {
            tracing::warn!(uav, "the killed agent was not reaped in time");
        }
        self.note_agent_exit(uav, &agent, pid, exit);
        true
    }

    /// Agents that exited since the last call (removed from the set).
    pub fn reap_agents(&mut self) -> Vec<AgentExit> {
        let mut reaped = Vec::new();
        for (&uav, agent) in &mut self.agents {
            let pid = agent.child.id();
            match try_reap(&mut agent.child) {
                Ok(Some(exit)) => reaped.push((uav, pid, exit)),
                Ok(None) => {}
                Err(e) => tracing::warn!(uav, error = %e, "cannot poll the agent"),
            }
        }
        let mut exits = Vec::new();
        for (uav, pid, exit) in reaped {
            if let Some(agent) = self.agents.remove(&uav) {
                self.note_agent_exit(uav, &agent, pid, Some(exit));
            }
            exits.push(AgentExit {
                uav,
                status: exit.0,
            });
        }
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

    /// Starts the bridge of every host started here: host 0's (the Zenoh router, listening
    /// on `endpoint`) or the other hosts' (clients connecting to `endpoint`), with the
    /// fleet's certificates in `tls` (none: plain TCP, for tests). Nothing on a run of one
    /// host.
    pub fn spawn_bridges(&mut self, endpoint: &str, tls: Option<&Path>) -> anyhow::Result<()> {
        if !self.layout.is_distributed() {
            return Ok(());
        }
        let program = self.binaries.bridge.clone().context(
            "cannot find fleet-bridge next to fleet; build every binary with `cargo build --bins`",
        )?;
        // Every bridge knows every host's role, for the access control; the world host first.
        let members: Vec<OsString> = (0..self.layout.hosts().len() as u16)
            .map(|h| {
                let agents: Vec<String> = self
                    .layout
                    .agents_on(h)
                    .iter()
                    .map(u32::to_string)
                    .collect();
                let name = self.layout.hosts()[usize::from(h)].name.as_str();
                format!("{name}={}", agents.join(",")).into()
            })
            .collect();
        for (h, host) in self.layout.hosts().iter().enumerate() {
            if !host.here {
                continue;
            }
            let h = h as u16;
            let mut args = self.common_args(h);
            let name = host.name.as_str();
            args.extend(["--host".into(), name.into()]);
            match tls {
                Some(dir) => args.extend(["--tls".into(), dir.into()]),
                None => args.push("--insecure".into()),
            }
            for m in &members {
                args.extend(["--member".into(), m.clone()]);
            }
            let side = if h == 0 { "--listen" } else { "--connect" };
            args.extend([side.into(), endpoint.into()]);
            let child = self.spawn(&program, args, &format!("bridge-{name}.log"))?;
            self.bridges.insert(h, child);
        }
        Ok(())
    }

    /// Whether every bridge started is still running.
    pub fn bridges_running(&mut self) -> bool {
        self.bridges
            .values_mut()
            .all(|child| matches!(child.try_wait(), Ok(None)))
    }

    /// Stops the bridges (SIGTERM, then SIGKILL after `grace`), once every other process of
    /// the run is gone.
    pub async fn stop_bridges(&mut self, grace: Duration) {
        for child in self.bridges.values() {
            if let Some(pid) = child.id() {
                send_signal(pid, libc::SIGTERM);
            }
        }
        for (host, mut child) in std::mem::take(&mut self.bridges) {
            let host = self.layout.hosts()[usize::from(host)]
                .name
                .as_str()
                .to_owned();
            let pid = child.id();
            let mut exit = reap(&mut child, grace).await;
            if exit.is_none() {
                tracing::warn!(%host, "bridge did not stop on SIGTERM: killed");
                let _ = child.start_kill();
                exit = reap(&mut child, Duration::from_secs(5)).await;
            }
            if let Some((status, _)) = exit
                && !status.success()
            {
                tracing::warn!(%host, %status, "bridge exited with an error");
            }
            self.exited.push(ExitedProcess {
                uav: None,
                incarnation: None,
                bridge_host: Some(host.clone()),
                pid,
                status: exit.map(|(s, _)| s),
                usage: exit.and_then(|(_, u)| u),
            });
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
