//! `fleet-bridge`: joins one host's share of a setfleet run to the other hosts over Zenoh
//! (started by `fleet run` on the world host and by `fleet host` on the others).
//!
//! Exit codes: 0 stopped by SIGTERM/SIGINT, 1 the bridge failed (no router, bad
//! certificates, ports that cannot be opened), 2 bad arguments or scenario.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;

use bridge::Bridge;
use bridge::placement::{self, HostPlan, HostShare};
use bridge::security::{HostName, HostTlsFiles, LinkMode, LinkPlan, zenoh_config};
use clap::Parser;
use fleet_process::startup::{self, ChildArgs, Role};

/// Forwards a run's iceoryx2 services between this host and the others over Zenoh, on
/// mutually authenticated, encrypted links (QUIC or TLS over TCP).
#[derive(Debug, Parser)]
#[command(name = "fleet-bridge", version)]
struct Args {
    /// The run, its host's domain and the scenario (the same as the other processes').
    #[command(flatten)]
    child: ChildArgs,
    /// This host's name: one of the `--member`s, and its certificate's common name.
    #[arg(long)]
    host: HostName,
    /// Every host of the run and its agents, the world host first (repeatable), e.g.
    /// `--member h0=0,1 --member h1=2,3`. The world host's bridge is the Zenoh router.
    #[arg(long, value_name = "NAME=UAVS", required = true)]
    member: Vec<HostShare>,
    /// Zenoh endpoint the world host listens on, e.g. `quic/0.0.0.0:7447` (QUIC) or
    /// `tls/0.0.0.0:7447` (TLS over TCP).
    #[arg(long, value_name = "ENDPOINT", conflicts_with = "connect")]
    listen: Vec<String>,
    /// Zenoh endpoint of the world host to connect to, e.g. `quic/10.0.0.1:7447`.
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// Directory of the fleet's certificates: `ca.pem`, `HOST.pem` and `HOST.key`.
    #[arg(long, value_name = "DIR", required_unless_present = "insecure")]
    tls: Option<PathBuf>,
    /// Plain TCP links without authentication nor access control (`tcp/` endpoints), for
    /// tests on one machine only.
    #[arg(long, conflicts_with = "tls")]
    insecure: bool,
}

fn main() -> ExitCode {
    let args: Args = match startup::start(Role::Child) {
        Ok(args) => args,
        Err(code) => return code,
    };
    let (plan, config) = match configure(&args) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("fleet-bridge: {e}");
            return ExitCode::from(2);
        }
    };
    let bridge = match Bridge::open(config) {
        Ok(bridge) => bridge,
        Err(e) => {
            eprintln!("fleet-bridge: {e}");
            return ExitCode::FAILURE;
        }
    };
    let shutdown = AtomicBool::new(false);
    let forwarded = bridge.forward(&plan, &shutdown);
    // The report goes out before the session closes, which may take a while.
    let code = match forwarded {
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
    };
    bridge.close();
    code
}

/// The host's plan and its Zenoh configuration, or what is wrong with the arguments.
fn configure(args: &Args) -> Result<(HostPlan, zenoh::Config), String> {
    let scenario = args
        .child
        .load_scenario()
        .map_err(|e| format!("bad scenario: {e}"))?;
    let run = args.child.run();
    let me = args
        .member
        .iter()
        .position(|m| m.name == args.host)
        .ok_or_else(|| format!("--host {}: not among the --members", args.host.as_str()))?;
    let world = me == 0;
    let plan = HostPlan {
        run,
        host: args.host.as_str().to_owned(),
        fleet: scenario.uavs.count,
        agents: args.member[me].agents.clone(),
        world,
    };
    let link = LinkPlan {
        mode: if world {
            LinkMode::Router
        } else {
            LinkMode::Client
        },
        listen: args.listen.clone(),
        connect: args.connect.clone(),
    };
    let tls = args
        .tls
        .as_ref()
        .map(|dir| HostTlsFiles::in_dir(dir, &args.host));
    let policy =
        placement::access_policy(&args.child.run_id, &args.member).map_err(|e| e.to_string())?;
    let policy = tls.as_ref().map(|_| &policy);
    let mut config = zenoh_config(&link, tls.as_ref(), policy).map_err(|e| e.to_string())?;
    if !world {
        // A host may start before the world host: keep trying to reach it.
        config
            .insert_json5("connect/timeout_ms", "-1")
            .and_then(|()| {
                config.insert_json5(
                    "connect/retry",
                    "{ period_init_ms: 50, period_max_ms: 1000, period_increase_factor: 2 }",
                )
            })
            .map_err(|e| format!("cannot configure the connection: {e}"))?;
    }
    Ok((plan, config))
}
