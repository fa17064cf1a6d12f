//! `fleet-bridge`: joins one host's share of a setfleet run to the other hosts over Zenoh
//! (usually started by `fleet run --hosts` or `fleet host`).
//!
//! Exit codes: 0 stopped by SIGTERM/SIGINT, 1 the bridge failed (no router, bad
//! certificates, ports that cannot be opened), 2 bad arguments or scenario.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;

use bridge::plan::HostPlan;
use clap::Parser;
use protocol::process::{self, Role};
use protocol::scenario::Scenario;
use protocol::service::RunId;

/// Forwards a run's iceoryx2 services between this host and the others over Zenoh.
#[derive(Debug, Parser)]
#[command(name = "fleet-bridge", version)]
struct Args {
    /// Run id of the run to join.
    #[arg(long)]
    run_id: RunId,
    /// Simulated host whose iceoryx2 domain to join (default: the run's one domain).
    #[arg(long)]
    domain: Option<u16>,
    /// This host's name (its certificate's common name).
    #[arg(long)]
    host: String,
    /// Scenario TOML file (the same as the other processes').
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Overrides a scenario key (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
    /// UAVs whose agents run on this host, comma-separated.
    #[arg(long, value_delimiter = ',')]
    agents: Vec<u32>,
    /// The world-server and the observer run on this host: the bridge is the Zenoh router
    /// that the other hosts connect to.
    #[arg(long)]
    world: bool,
    /// Zenoh endpoint to listen on, e.g. `tcp/0.0.0.0:7447` (the world host).
    #[arg(long)]
    listen: Vec<String>,
    /// Zenoh endpoint of the world host to connect to, e.g. `tcp/10.0.0.1:7447`.
    #[arg(long)]
    connect: Vec<String>,
}

fn main() -> ExitCode {
    let args: Args = match process::start(Role::Child) {
        Ok(args) => args,
        Err(code) => return code,
    };
    let scenario = match Scenario::load(args.scenario.as_deref(), &args.overrides) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("fleet-bridge: bad scenario: {e}");
            return ExitCode::from(2);
        }
    };
    let run = match args.domain {
        Some(host) => args.run_id.in_domain(host),
        None => args.run_id,
    };
    let plan = HostPlan {
        run,
        host: args.host,
        fleet: scenario.uavs.count,
        agents: args.agents.iter().copied().collect::<BTreeSet<u32>>(),
        world: args.world,
    };
    let config = match bridge::session::plain_config(plan.world, &args.listen, &args.connect) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("fleet-bridge: {e}");
            return ExitCode::from(2);
        }
    };
    let shutdown = AtomicBool::new(false);
    match bridge::run(&plan, config, &shutdown) {
        Ok(report) => {
            match serde_json::to_string(&report) {
                Ok(json) => println!("{json}"),
                Err(e) => eprintln!("fleet-bridge: cannot print the report: {e}"),
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("fleet-bridge: {e}");
            ExitCode::FAILURE
        }
    }
}
