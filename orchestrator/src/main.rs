//! `fleet`: runs, renders and benchmarks setfleet. See the `orchestrator` library.

use std::process::ExitCode;

use orchestrator::cli::Cli;
use protocol::process::{self, Role};

fn main() -> ExitCode {
    let cli: Cli = match process::start(Role::Command) {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    ExitCode::from(orchestrator::dispatch(cli).code())
}
