//! `fleet`: runs, renders and benchmarks setfleet. See the `orchestrator` library.

use std::process::ExitCode;

use fleet_process::startup::{self, Role};
use orchestrator::cli::Cli;

fn main() -> ExitCode {
    let cli: Cli = match startup::start(Role::Command) {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    ExitCode::from(orchestrator::dispatch(cli).code())
}
