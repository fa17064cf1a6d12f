//! `world-server`: publishes the world of one run over iceoryx2 (usually started by `fleet`).
//!
//! At exit it prints its report (steps, agents, the phases of its time, its own peak memory)
//! as one line of JSON on stdout.
//!
//! Exit codes: 0 the run ended (or was stopped by SIGTERM/SIGINT), 1 the run failed, 2 bad
//! arguments or scenario.

use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use clap::{Parser, ValueEnum};
use fleet_process::startup::{self, ChildArgs, Role};
use protocol::timeouts::Timeouts;
use world_server::server::{self, ServerConfig, StepMode};

/// Publishes every UAV's camera frames and the ground truth of one setfleet run.
#[derive(Debug, Parser)]
#[command(name = "world-server", version)]
struct Args {
    /// The run, its host's domain and the scenario.
    #[command(flatten)]
    child: ChildArgs,
    /// Stepping mode.
    #[arg(long, value_enum, default_value_t = Mode::Lockstep)]
    mode: Mode,
    /// Simulated seconds per wall second in realtime mode.
    #[arg(long, default_value_t = 1.0)]
    speedup: f64,
    /// UAV indices that have an agent, comma-separated (default: every UAV).
    #[arg(long, value_delimiter = ',')]
    agents: Option<Vec<u32>>,
    /// Wait for an observer's hello and acks (lockstep).
    #[arg(long)]
    wait_observer: bool,
    /// The agents' longest wait for their peers' estimates of a step, milliseconds (default:
    /// the agents' default). The ack wait is derived from it.
    #[arg(long)]
    peer_wait_ms: Option<u64>,
    /// The agents' longest wait for one token holder, milliseconds (default: the agents'
    /// default). The ack wait is derived from it.
    #[arg(long)]
    token_wait_ms: Option<u64>,
    /// Longest wait for the agents' hellos, milliseconds (default: 30 s).
    #[arg(long)]
    start_timeout_ms: Option<u64>,
    /// Longest wait for the acks of one step, milliseconds (default: derived from the
    /// agents' waits, so that a healthy agent is never timed out).
    #[arg(long)]
    ack_timeout_ms: Option<u64>,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Mode {
    Lockstep,
    Realtime,
}

fn main() -> ExitCode {
    let args: Args = match startup::start(Role::Child) {
        Ok(args) => args,
        Err(code) => return code,
    };
    let scenario = match args.child.load_scenario() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("world-server: bad scenario: {e}");
            return ExitCode::from(2);
        }
    };
    let mode = match args.mode {
        Mode::Lockstep => StepMode::Lockstep,
        Mode::Realtime => StepMode::Realtime {
            speedup: args.speedup,
        },
    };
    let timeouts = Timeouts::with_waits_ms(args.peer_wait_ms, args.token_wait_ms);
    let run_id = args.child.run();
    let mut config = ServerConfig::new(run_id, scenario, &timeouts);
    if let Some(agents) = args.agents {
        config.expected_agents = agents;
    }
    config.mode = mode;
    config.wait_for_observer = args.wait_observer;
    if let Some(ms) = args.start_timeout_ms {
        config.start_timeout = Duration::from_millis(ms);
    }
    if let Some(ms) = args.ack_timeout_ms {
        config.ack_timeout = Duration::from_millis(ms);
    }
    // SIGTERM/SIGINT are handled by iceoryx2's wait set; nothing else sets this flag.
    let shutdown = AtomicBool::new(false);
    match server::run(config, &shutdown) {
        Ok(report) => {
            for a in &report.agents {
                tracing::info!(
                    uav = a.uav,
                    acks = a.acks,
                    misses = a.misses,
                    rejoins = a.rejoins,
                    deaths = a.deaths,
                    "agent"
                );
            }
            // The report on stdout, as the agents print theirs: `fleet` reads the phases.
            match serde_json::to_string(&report) {
                Ok(json) => println!("{json}"),
                Err(e) => eprintln!("world-server: cannot print the report: {e}"),
            }
            ExitCode::SUCCESS
        }
        Err(e) if e.is_usage() => {
            eprintln!("world-server: {e}");
            ExitCode::from(2)
        }
        Err(e) => {
            eprintln!("world-server: run failed: {e}");
            ExitCode::from(1)
        }
    }
}
