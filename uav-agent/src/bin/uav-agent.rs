//! `uav-agent`: one UAV of a setfleet run (usually started by `fleet`).
//!
//! Exit codes: 0 the run ended (or SIGTERM/SIGINT stopped it), 1 the agent failed (the world
//! was lost, the id is already live), 2 bad arguments or scenario.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use clap::Parser;
use protocol::process::{self, Role};
use protocol::scenario::Scenario;
use protocol::service::RunId;
use protocol::timeouts::Timeouts;
use uav_agent::agent::{self, AgentConfig};

/// Environment variable (milliseconds) that makes the agent sit on the guidance token before
/// planning: a test hook to kill a holder mid-turn. Only in builds with the `test-hooks`
/// feature, which the `tests` crate enables; shipped builds ignore the variable.
#[cfg(feature = "test-hooks")]
const HOLD_TOKEN_ENV: &str = "SETFLEET_TEST_HOLD_TOKEN_MS";

/// Runs one UAV's estimator, guidance and peer exchange in a setfleet run.
#[derive(Debug, Parser)]
#[command(name = "uav-agent", version)]
struct Args {
    /// Run id of the run to join.
    #[arg(long)]
    run_id: RunId,
    /// Simulated host whose iceoryx2 domain to join (`fleet run --hosts`): its processes meet
    /// the other hosts' only through the Zenoh bridge (default: the run's one domain).
    #[arg(long)]
    domain: Option<u16>,
    /// This agent's UAV index (0-based).
    #[arg(long)]
    id: u32,
    /// Scenario TOML file (the same as the world-server's).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Overrides a scenario key, e.g. `--set guidance.kappa=0` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
    /// Longest wait for the peers' estimates of a step, milliseconds (default: 2000; give
    /// the world-server the same value).
    #[arg(long)]
    peer_wait_ms: Option<u64>,
    /// Longest wait for one token holder, milliseconds (default: 3000; give the world-server
    /// the same value).
    #[arg(long)]
    token_wait_ms: Option<u64>,
    /// Without frames for this long and without a live world node, exit, milliseconds
    /// (default: twice the world's ack wait).
    #[arg(long)]
    world_timeout_ms: Option<u64>,
    /// Directory of the run's checkpoints: the agent saves its state to `agent-<id>.ckpt`
    /// there after every step, and resumes from it when restarted (default: no checkpoint).
    #[arg(long)]
    checkpoint_dir: Option<PathBuf>,
}

fn main() -> ExitCode {
    let args: Args = match process::start(Role::Child) {
        Ok(args) => args,
        Err(code) => return code,
    };
    let scenario = match Scenario::load(args.scenario.as_deref(), &args.overrides) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("uav-agent: bad scenario: {e}");
            return ExitCode::from(2);
        }
    };
    let run_id = match args.domain {
        Some(host) => args.run_id.in_domain(host),
        None => args.run_id,
    };
    let mut config = AgentConfig::new(run_id, args.id, scenario);
    config.timeouts = Timeouts::with_waits_ms(args.peer_wait_ms, args.token_wait_ms);
    config.world_timeout = args
        .world_timeout_ms
        .map_or(config.timeouts.world_lost(), Duration::from_millis);
    config.checkpoint = args
        .checkpoint_dir
        .map(|dir| AgentConfig::checkpoint_in(&dir, args.id));
    #[cfg(feature = "test-hooks")]
    apply_test_hooks(&mut config);
    let shutdown = AtomicBool::new(false);
    match agent::run(config, &shutdown) {
        Ok(report) => {
            match serde_json::to_string(&report) {
                Ok(json) => println!("{json}"),
                Err(e) => eprintln!("uav-agent: cannot print the report: {e}"),
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("uav-agent: {e}");
            ExitCode::from(if e.is_usage() { 2 } else { 1 })
        }
    }
}

/// Fault-injection hooks for tests (inherited through `fleet run`): sit on the token.
#[cfg(feature = "test-hooks")]
fn apply_test_hooks(config: &mut AgentConfig) {
    if let Some(ms) = std::env::var(HOLD_TOKEN_ENV)
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
    {
        config.hold_token = std::time::Duration::from_millis(ms);
    }
}
