//! `fleet host`: this machine joins a run of another machine with some of its agents, and
//! `fleet certs`: the fleet's certificates.
//!
//! On the world host, `fleet run --remote h1=2,3 --listen quic/0.0.0.0:7447 --tls certs
//! --run-id demo` runs the world-server, the observer and agents 0 and 1, and waits for the
//! others' hellos. On machine `h1`, `fleet host --run-id demo --host h1 --agents 2,3
//! --connect quic/WORLD_ADDR:7447 --tls certs` starts this machine's bridge, waits until it
//! reaches the world host, then starts agents 2 and 3; it ends when they do (at the end of
//! the run). The scenario must be the world host's: the same scenario flags resolve to it.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context as _;
use bridge::security::{HostName, write_fleet_certs};
use clap::Args;
use protocol::ipc::{RunNode, scan_nodes};
use protocol::service::RunId;
use world_server::server::StepMode;

use crate::outcome::Outcome;
use crate::run::children::{Binaries, Children};
use crate::run::config::{RunScenarioArgs, default_out_dir};
use crate::run::hosts::HostLayout;
use crate::run::lifecycle::{RunDirs, Signals, clean_run_files, stop_agents_and_bridges};
use fleet_process::usage::UsageError;

/// `fleet host`.
#[derive(Debug, Args)]
pub struct HostArgs {
    /// The run to join: the world host's `--run-id`.
    #[arg(long)]
    pub run_id: RunId,
    /// This machine's host name: its certificate's common name (`HOST.pem`, `HOST.key`).
    #[arg(long)]
    pub host: HostName,
    /// The UAVs whose agents run on this machine, comma-separated (the world host's
    /// `--remote HOST=UAVS`).
    #[arg(long, value_delimiter = ',', required = true)]
    pub agents: Vec<u32>,
    /// The world host's bridge, e.g. `quic/10.0.0.1:7447` (its address must be one of the
    /// names in its certificate: `fleet certs --san`).
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: String,
    /// Directory of the fleet's certificates: `ca.pem`, `HOST.pem`, `HOST.key`.
    #[arg(long, value_name = "DIR")]
    pub tls: PathBuf,
    /// The world host's name (its certificate's common name).
    #[arg(long, default_value = "h0")]
    pub world_host: HostName,
    /// The run's scenario: the same `--scenario`, `--set`, `--variant`, `--seed`,
    /// `--duration` and `--uavs` as the world host's `fleet run`.
    #[command(flatten)]
    pub choice: RunScenarioArgs,
    /// Output directory for the logs and checkpoints (default: `runs/host-<UTC timestamp>`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The iceoryx2 domain to use (1 or more) when the world host is this same machine, to
    /// try several hosts on one machine; without it, this host's processes would share the
    /// world host's domain and its bridge could not open its ports.
    #[arg(long, value_name = "N")]
    pub domain: Option<u16>,
}

/// A validated `fleet host`.
#[derive(Clone, Debug)]
pub struct HostConfig {
    run: RunId,
    scenario: protocol::scenario::Scenario,
    layout: HostLayout,
    connect: String,
    tls: PathBuf,
    out: PathBuf,
}

impl HostArgs {
    /// Checks the arguments against the scenario.
    pub fn validate(&self) -> Result<HostConfig, UsageError> {
        let scenario = self.choice.resolve()?;
        let agents: BTreeSet<u32> = self.agents.iter().copied().collect();
        if self.host == self.world_host {
            return Err(UsageError(format!(
                "--host {}: that is the world host's name",
                self.host
            )));
        }
        let mut layout =
            HostLayout::joining(scenario.uavs.count, self.host.clone(), &agents, self.domain)
                .map_err(UsageError)?;
        layout.rename_world_host(self.world_host.clone());
        Ok(HostConfig {
            run: self.run_id.clone(),
            scenario,
            layout,
            connect: self.connect.clone(),
            tls: self.tls.clone(),
            out: self.out.clone().unwrap_or_else(|| default_out_dir("host-")),
        })
    }
}

/// How often `fleet host` looks for the world host (its proxy) and for exited agents.
const POLL: Duration = Duration::from_millis(100);

/// Runs `fleet host`: the bridge, then the agents once the world host is reached, until the
/// agents end or a signal stops them.
pub fn command(config: &HostConfig) -> anyhow::Result<Outcome> {
    crate::run::runtime()?.block_on(serve(config))
}

async fn serve(config: &HostConfig) -> anyhow::Result<Outcome> {
    let dirs = RunDirs::prepare(&config.out, &config.scenario, &config.layout, &config.run)?;
    let mut signals = Signals::take()?;
    let mut children = Children::new(
        config.run.clone(),
        Binaries::locate()?,
        dirs.scenario_file.clone(),
        dirs.logs.clone(),
        dirs.checkpoints.clone(),
        StepMode::Lockstep,
        config.layout.clone(),
    );
    children.spawn_bridges(&config.connect, Some(&config.tls))?;
    let local = config.layout.run_on(&config.run, 1);
    eprintln!(
        "fleet host: waiting for the world host at {} (logs in {})",
        config.connect,
        dirs.logs.display()
    );
    let reached = tokio::select! {
        reached = world_reached(&local, &mut children) => Some(reached),
        _ = signals.recv() => None,
    };
    let outcome = match reached {
        Some(true) => {
            eprintln!("fleet host: the world host is reached; starting the agents");
            serve_agents(config, &mut children, &mut signals).await?
        }
        Some(false) => {
            eprintln!(
                "fleet host: the bridge ended before it reached the world host; see {}",
                dirs.logs
                    .join(format!("bridge-{}.log", config.layout.hosts()[1].name))
                    .display()
            );
            Outcome::Failed
        }
        None => Outcome::Success,
    };
    stop_agents_and_bridges(&mut children, false).await;
    clean_run_files(&local);
    Ok(outcome)
}

/// Runs this host's agents until they all end or a signal arrives; failed if one failed.
async fn serve_agents(
    config: &HostConfig,
    children: &mut Children,
    signals: &mut Signals,
) -> anyhow::Result<Outcome> {
    for uav in config.layout.agents_on(1) {
        children.spawn_agent(uav)?;
    }
    let mut failed = false;
    let mut running = config.layout.agents_on(1).len();
    while running > 0 {
        tokio::select! {
            _ = tokio::time::sleep(POLL) => {
                for exit in children.reap_agents() {
                    running -= 1;
                    eprintln!("fleet host: agent {} exited with {}", exit.uav, exit.status);
                    failed |= !exit.status.success();
                }
            }
            _ = signals.recv() => break,
        }
    }
    Ok(if failed {
        Outcome::Failed
    } else {
        Outcome::Success
    })
}

/// Waits until the world-server shows up in this host's domain (the bridge made its proxy:
/// the link to the world host is up); false if the bridge ended first.
async fn world_reached(local: &RunId, children: &mut Children) -> bool {
    loop {
        if scan_nodes(local, false).is_ok_and(|s| s.is_alive(RunNode::WORLD)) {
            return true;
        }
        if !children.bridges_running() {
            return false;
        }
        tokio::time::sleep(POLL).await;
    }
}

/// `fleet certs`.
#[derive(Debug, Args)]
pub struct CertsArgs {
    /// Directory to write the certificates into (created with mode 0700).
    #[arg(long)]
    pub out: PathBuf,
    /// The fleet's host names, comma-separated, the world host first (e.g. `h0,h1,h2`).
    #[arg(long, value_delimiter = ',', required = true)]
    pub hosts: Vec<String>,
    /// An address or DNS name the hosts dial each other by (repeatable), e.g. the world
    /// host's `10.0.0.1`: every certificate carries it, with `localhost` and `127.0.0.1`.
    #[arg(long, value_name = "ADDR")]
    pub san: Vec<String>,
    /// Replace the files of an existing fleet (its old certificates stop working).
    #[arg(long)]
    pub force: bool,
}

/// Runs `fleet certs`: a new fleet authority and a certificate per host.
pub fn certs(args: &CertsArgs) -> anyhow::Result<()> {
    let files = write_fleet_certs(&args.out, &args.hosts, &args.san, args.force)
        .with_context(|| format!("cannot write the certificates into {}", args.out.display()))?;
    println!("fleet authority: {}", files.ca_cert.display());
    println!(
        "  its key {} is secret: keep it where certificates are made",
        files.ca_key.display()
    );
    for (host, f) in &files.hosts {
        println!(
            "host {host}: copy {}, {} and {} (secret) to it",
            files.ca_cert.display(),
            f.cert.display(),
            f.key.display()
        );
    }
    Ok(())
}
