//! `fleet-bench-child`: one process of `fleet bench ipc`, started by it (see
//! `fleet_bench::ipc::roles`). It dies with its parent, says `ready`, waits for `go` and prints
//! its `result`.

use std::process::ExitCode;

use fleet_bench::ipc::BenchChildArgs;
use fleet_process::startup::{self, Role};

fn main() -> ExitCode {
    let args: BenchChildArgs = match startup::start(Role::Child) {
        Ok(args) => args,
        Err(code) => return code,
    };
    match fleet_bench::ipc::roles::run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("fleet-bench-child: {e:#}");
            ExitCode::FAILURE
        }
    }
}
