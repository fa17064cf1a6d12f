//! # orchestrator
//!
//! The `fleet` command, the one a user types. Its library holds every subcommand so tests
//! and other tools can drive them in-process:
//!
//! - [`cli`]: the subcommands; each command's raw clap arguments live with the command and
//!   validate into its config (errors name the flag or the scenario key and the accepted
//!   range: exit code 2).
//! - [`run`]: `fleet run`, one run of the fleet as processes; the `fleet-observe`
//!   crate measures it, writes its results and shows it.
//! - [`host`]: `fleet host`, this machine's share of a run over several hosts, and
//!   `fleet certs`.
//! - [`sweep`]: `fleet sweep`, every variant on several seeds, the paper's Table I.
//! - [`render`]: `fleet render`, one frame as pictures.
//! - [`city`]: `fleet city`, a real city imported from OpenStreetMap.
//! - [`outcome`]: how a command ended ([`Outcome`]), its exit code; every command module
//!   returns one, so none depends on this crate's root.
//! - [`scale`]: `fleet bench scale`, whole runs per fleet size; the other benchmarks are the
//!   `fleet-bench` crate's.
//!
//! The library uses `anyhow` for a command's failures (exit code 1): it is the body of the
//! `fleet` binary, and [`UsageError`] is the one error a caller must tell apart.
//!
//! ```no_run
//! use clap::Parser;
//! use orchestrator::cli::Cli;
//! let cli = Cli::parse_from(["fleet", "render", "--uav", "0", "--time", "10", "--out", "frame"]);
//! let code = orchestrator::dispatch(cli);
//! assert_eq!(code, orchestrator::Outcome::Success);
//! ```

pub mod city;
pub mod cli;
pub mod host;
pub mod outcome;
pub mod render;
pub mod run;
pub mod scale;
pub mod sweep;

use cli::{BenchKind, Cli, FleetCommand};
use fleet_process::usage::UsageError;
pub use outcome::Outcome;

/// Runs a parsed command line, printing errors to stderr.
pub fn dispatch(cli: Cli) -> Outcome {
    if let Err(e) = fleet_observe::pictures::register_fonts() {
        eprintln!("fleet: {e}");
        return Outcome::Failed;
    }
    let result = match cli.command {
        FleetCommand::Run(args) => match args.validate() {
            Ok(config) => return finish(run::command(&config)),
            Err(e) => return bad_input(e),
        },
        FleetCommand::Host(args) => match args.validate() {
            Ok(config) => return finish(host::command(&config)),
            Err(e) => return bad_input(e),
        },
        FleetCommand::Certs(args) => host::certs(&args),
        FleetCommand::Sweep(args) => match args.merge_config() {
            Some(merge) => return finish(sweep::merge(&merge)),
            None => match args.validate() {
                Ok(config) => return finish(sweep::command(&config)),
                Err(e) => return bad_input(e),
            },
        },
        FleetCommand::City(args) => match args.validate() {
            Ok(config) => return finish(city::command(&config)),
            Err(e) => return bad_input(e),
        },
        FleetCommand::Render(args) => match args.validate() {
            Ok(config) => render::command(&config),
            Err(e) => return bad_input(e),
        },
        FleetCommand::Bench(args) => match args.kind {
            BenchKind::Render(args) => match args.validate() {
                Ok(config) => bench_render(&config),
                Err(e) => return bad_input(e),
            },
            BenchKind::Ipc(args) => match args.validate() {
                Ok(c) => fleet_bench::ipc::run(&c).and_then(|r| r.publish(c.out.as_deref())),
                Err(e) => return bad_input(e),
            },
            BenchKind::Estimator(args) => match args.validate() {
                Ok(c) => fleet_bench::estimator::run(&c).and_then(|r| r.publish(c.out.as_deref())),
                Err(e) => return bad_input(e),
            },
            BenchKind::Guidance(args) => match args.validate() {
                Ok(c) => fleet_bench::guidance::run(&c).and_then(|r| r.publish(c.out.as_deref())),
                Err(e) => return bad_input(e),
            },
            BenchKind::Scale(args) => match args.validate() {
                Ok(config) => return finish(scale::command(&config)),
                Err(e) => return bad_input(e),
            },
        },
    };
    match result {
        Ok(()) => Outcome::Success,
        Err(e) => {
            eprintln!("fleet: {e:#}");
            Outcome::Failed
        }
    }
}

/// The outcome of a command that decides its own exit code.
fn finish(result: anyhow::Result<Outcome>) -> Outcome {
    result.unwrap_or_else(|e| {
        eprintln!("fleet: {e:#}");
        Outcome::Failed
    })
}

fn bad_input(e: UsageError) -> Outcome {
    eprintln!("fleet: {e}");
    Outcome::BadInput
}

fn bench_render(config: &fleet_bench::render::BenchRenderConfig) -> anyhow::Result<()> {
    let report = fleet_bench::render::run(config)?;
    report.print_table(&mut std::io::stdout().lock())?;
    if let Some(path) = &config.out {
        report.write_json(path)?;
        println!("report written to {}", path.display());
    }
    Ok(())
}
