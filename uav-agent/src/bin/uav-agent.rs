//! `uav-agent`: one UAV of a setfleet run (usually started by `fleet`).
//!
//! Exit codes: 0 the run ended (or SIGTERM/SIGINT stopped it), 1 the agent failed (the world
//! was lost, the id is already live), 2 bad arguments or scenario.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use clap::Parser;
use fleet_process::startup::{self, ChildArgs, Role};
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
    /// The run, its host's domain and the scenario (the same as the world-server's).
    #[command(flatten)]
    child: ChildArgs,
    /// This agent's UAV index (0-based).
    #[arg(long)]
    id: u32,
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
    /// there after every `--checkpoint-every`-th step, and resumes from it when restarted
    /// (default: no checkpoint).
    #[arg(long)]
    checkpoint_dir: Option<PathBuf>,
    /// Checkpoint after the steps that are multiples of this.
    #[arg(long, default_value_t = agent::DEFAULT_CHECKPOINT_EVERY,
          value_parser = clap::value_parser!(u64).range(1..))]
    checkpoint_every: u64,
}

fn main() -> ExitCode {
    let args: Args = match startup::start(Role::Child) {
        Ok(args) => args,
        Err(code) => return code,
    };
    let scenario = match args.child.load_scenario() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("uav-agent: bad scenario: {e}");
            return ExitCode::from(2);
        }
    };
    let run_id = args.child.run();
    let mut config = AgentConfig::new(run_id, args.id, scenario);
    config.timeouts = Timeouts::with_waits_ms(args.peer_wait_ms, args.token_wait_ms)
        .for_scenario(&config.scenario);
    config.world_timeout = args
        .world_timeout_ms
        .map_or(config.timeouts.world_lost(), Duration::from_millis);
    config.checkpoint = args
        .checkpoint_dir
        .map(|dir| AgentConfig::checkpoint_in(&dir, args.id));
    config.checkpoint_every = args.checkpoint_every;
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
