//! `uav-agent`: one UAV of a setfleet run (usually started by `fleet`).
//!
//! Exit codes: 0 the run ended (or SIGTERM/SIGINT stopped it), 1 the agent failed (the world
//! was lost, the id is already live), 2 bad arguments or scenario.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;

use clap::Parser;
use protocol::scenario::Scenario;
use protocol::service::RunId;
use std::time::Duration;

use protocol::timeouts::Timeouts;
use uav_agent::agent::{self, AgentConfig};

/// Environment variable (milliseconds) that makes the agent sit on the guidance token before
/// planning: a test hook to kill a holder mid-turn.
const HOLD_TOKEN_ENV: &str = "SETFLEET_TEST_HOLD_TOKEN_MS";

/// Runs one UAV's estimator, guidance and peer exchange in a setfleet run.
#[derive(Debug, Parser)]
#[command(name = "uav-agent", version)]
struct Args {
    /// Run id of the run to join.
    #[arg(long)]
    run_id: RunId,
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
    die_with_parent();
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .init();
    let args = match Args::try_parse() {
        Ok(args) => args,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(e.exit_code().clamp(0, 255) as u8);
        }
    };
    let scenario = match Scenario::load(args.scenario.as_deref(), &args.overrides) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("uav-agent: bad scenario: {e}");
            return ExitCode::from(2);
        }
    };
    let mut config = AgentConfig::new(args.run_id, args.id, scenario);
    config.timeouts = Timeouts::with_waits_ms(args.peer_wait_ms, args.token_wait_ms);
    config.world_timeout = args
        .world_timeout_ms
        .map_or(config.timeouts.world_lost(), Duration::from_millis);
    config.checkpoint = args
        .checkpoint_dir
        .map(|dir| AgentConfig::checkpoint_in(&dir, args.id));
    // Fault-injection hook for tests (inherited through `fleet run`): sit on the token.
    if let Some(ms) = std::env::var(HOLD_TOKEN_ENV)
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
    {
        config.hold_token = Duration::from_millis(ms);
    }
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

/// Children of `fleet` die with it (Linux), so no agent outlives an interrupted run.
fn die_with_parent() {
    #[cfg(target_os = "linux")]
    // SAFETY: prctl(PR_SET_PDEATHSIG) only sets a process attribute; no memory is involved.
    unsafe {
        libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
    }
}
