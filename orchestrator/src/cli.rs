//! The command line: the subcommands and where each one's raw clap arguments live. Each
//! command validates its own arguments into a config whose errors ([`UsageError`]) name the
//! flag or scenario key and the accepted range.
//!
//! [`UsageError`]: fleet_process::usage::UsageError

use clap::{Args, Parser, Subcommand};

/// The `fleet` command: runs, renders and benchmarks setfleet.
#[derive(Debug, Parser)]
#[command(name = "fleet", version, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: FleetCommand,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum FleetCommand {
    /// Run the fleet once: world-server and agents as processes; results into `--out`.
    Run(crate::run::config::RunArgs),
    /// Join a run of another machine with some of its agents (`fleet run --remote`).
    Host(crate::host::HostArgs),
    /// Make a fleet authority and a TLS certificate for each host.
    Certs(crate::host::CertsArgs),
    /// Run every variant on the seeds given and write the paper's Table I layout, with the
    /// variants' paired differences.
    Sweep(crate::sweep::SweepArgs),
    /// Render one UAV's camera frame at a given time as pictures.
    Render(crate::render::RenderArgs),
    /// Import a real city from an OpenStreetMap PBF file: its scene and a picture of it.
    City(crate::city::CityArgs),
    /// Measure a part of the system and write a JSON report.
    Bench(BenchArgs),
}

/// `fleet bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// What to measure.
    #[command(subcommand)]
    pub kind: BenchKind,
}

/// The benchmarks.
#[derive(Debug, Subcommand)]
pub enum BenchKind {
    /// CVS frame rendering (ray casts), per thread count.
    Render(fleet_bench::render::BenchRenderArgs),
    /// Moving frames, estimates and the token between processes (iceoryx2, Zenoh over TCP and
    /// TLS, and a Unix socket).
    Ipc(fleet_bench::ipc::BenchIpcArgs),
    /// One estimator step per frame, its phases, message sizes and fusion.
    Estimator(fleet_bench::estimator::BenchEstimatorArgs),
    /// One MPC guidance decision.
    Guidance(fleet_bench::guidance::BenchGuidanceArgs),
    /// Whole runs of 1 to 64 UAVs under both exchanges, the region scaled with the fleet:
    /// speed, CPU, traffic and memory per fleet size.
    Scale(crate::scale::BenchScaleArgs),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cli_parses_the_documented_commands() {
        let cli = Cli::try_parse_from([
            "fleet", "render", "--uav", "1", "--time", "3", "--out", "d", "--set", "seed=2",
        ])
        .unwrap();
        assert!(matches!(cli.command, FleetCommand::Render(ref r) if r.uav == 1));
        let cli = Cli::try_parse_from(["fleet", "bench", "render", "--out", "x.json"]).unwrap();
        assert!(matches!(cli.command, FleetCommand::Bench(_)));
        assert!(Cli::try_parse_from(["fleet", "render", "--frobnicate"]).is_err());
        let cli = Cli::try_parse_from(["fleet", "bench", "scale", "--uavs", "1,2"]).unwrap();
        assert!(matches!(
            cli.command,
            FleetCommand::Bench(BenchArgs { kind: BenchKind::Scale(ref s) }) if s.uavs == [1, 2]
        ));
    }
}
