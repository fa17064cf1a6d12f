//! How every setfleet binary starts: its log on stderr, its arguments, and, for a process that
//! `fleet` or a test started, dying with its parent.
//!
//! ```no_run
//! use std::process::ExitCode;
//! use clap::Parser;
//! use fleet_process::startup::{self, Role};
//!
//! #[derive(Parser)]
//! struct Args {
//!     #[arg(long)]
//!     id: u32,
//! }
//!
//! fn main() -> ExitCode {
//!     let args: Args = match startup::start(Role::Child) {
//!         Ok(args) => args,
//!         Err(code) => return code,
//!     };
//!     println!("agent {}", args.id);
//!     ExitCode::SUCCESS
//! }
//! ```

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use tracing_subscriber::EnvFilter;

use protocol::scenario::{Scenario, ScenarioError};
use protocol::service::RunId;

/// What every process of a run is told on its command line, whoever starts it (`fleet`, a
/// test, a user): the run, its host's domain and the scenario. The world-server, the agent
/// and the bridge flatten it into their arguments; [`ChildArgs::to_args`] writes it back as
/// the command line that parses to it.
#[derive(Clone, Debug, PartialEq, clap::Args)]
pub struct ChildArgs {
    /// Run id: prefixes every service and shared-memory file of the run.
    #[arg(long)]
    pub run_id: RunId,
    /// Simulated host whose iceoryx2 domain to join (`fleet run --hosts`): its processes meet
    /// the other hosts' only through the Zenoh bridge (default: the run's one domain).
    #[arg(long)]
    pub domain: Option<u16>,
    /// Scenario TOML file (default: the paper's scenario; `fleet` gives every process the
    /// run's resolved scenario).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Overrides a scenario key, e.g. `--set targets.count=4` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
}

impl ChildArgs {
    /// The arguments of run `run_id`, in `domain`, of the scenario file `scenario`.
    pub fn new(run_id: RunId, domain: Option<u16>, scenario: PathBuf) -> ChildArgs {
        ChildArgs {
            run_id,
            domain,
            scenario: Some(scenario),
            overrides: Vec::new(),
        }
    }

    /// The command line that parses back to these arguments.
    pub fn to_args(&self) -> Vec<OsString> {
        let mut args: Vec<OsString> = vec!["--run-id".into(), self.run_id.as_str().into()];
        if let Some(domain) = self.domain {
            args.extend(["--domain".into(), domain.to_string().into()]);
        }
        if let Some(file) = &self.scenario {
            args.extend(["--scenario".into(), file.clone().into_os_string()]);
        }
        for o in &self.overrides {
            args.extend(["--set".into(), o.into()]);
        }
        args
    }

    /// The run as this process sees it: in its host's domain, if it has one.
    pub fn run(&self) -> RunId {
        match self.domain {
            Some(host) => self.run_id.in_domain(host),
            None => self.run_id.clone(),
        }
    }

    /// Loads the scenario file with the overrides.
    pub fn load_scenario(&self) -> Result<Scenario, ScenarioError> {
        Scenario::load(self.scenario.as_deref(), &self.overrides)
    }
}

/// What kind of setfleet process is starting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// `fleet`, the command a user types: logs warnings and errors unless `RUST_LOG` says
    /// otherwise.
    Command,
    /// A process `fleet` or a test starts (world-server, agent): logs from `info` unless
    /// `RUST_LOG` says otherwise, and dies with its parent.
    Child,
}

impl Role {
    /// The log filter when `RUST_LOG` is unset or invalid.
    pub fn default_log_filter(self) -> &'static str {
        match self {
            Role::Command => "warn",
            Role::Child => "info",
        }
    }
}

/// Starts a binary: a [`Role::Child`] first asks to die with its parent ([`die_with_parent`]),
/// the allocator is told to reuse freed memory ([`keep_freed_memory`]), then the log goes to stderr ([`init_tracing`]) and the arguments are parsed
/// ([`parse_args`]). `Err` holds the code to exit with once help, the version or a usage error
/// was printed.
pub fn start<A: Parser>(role: Role) -> Result<A, ExitCode> {
    if role == Role::Child {
        die_with_parent();
    }
    keep_freed_memory();
    init_tracing(role.default_log_filter());
    parse_args()
}

/// Asks the kernel to send SIGTERM when the parent (`fleet`, a test) dies, so no child
/// outlives the run that started it (Linux; elsewhere nothing happens).
pub fn die_with_parent() {
    #[cfg(target_os = "linux")]
    // SAFETY: prctl(PR_SET_PDEATHSIG) only sets a process attribute; no memory is involved.
    unsafe {
        libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
    }
}

/// Largest allocation the C allocator serves from its heap rather than by mapping fresh pages
/// of its own, and the free memory at the top of the heap it keeps instead of returning it.
const HEAP_LIMIT_BYTES: i32 = 1 << 30;

/// Tells the C allocator (glibc) to serve large blocks from its heap and keep freed memory for
/// the next ones. Sets, reach arrays and frames are hundreds of KB to MB each and are made and
/// dropped every step; by default whether such a block is mapped fresh (zeroed by the kernel
/// page by page, unmapped at its drop) depends on the sizes freed before it, which made the
/// cost of a fusion vary threefold with unrelated changes and the page faults up to a fifth of
/// an agent's CPU. The process's peak memory is unchanged (it is what it holds at once); it is
/// kept until the process exits. Elsewhere than Linux with glibc nothing happens.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets two tuning parameters of the allocator; called before the
    // process makes threads, and glibc serialises it with its arenas anyway.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, HEAP_LIMIT_BYTES);
        libc::mallopt(libc::M_TRIM_THRESHOLD, HEAP_LIMIT_BYTES);
    }
}

/// Sends the `tracing` log to stderr (stdout is left to reports), filtered by `RUST_LOG`, or
/// by `default_filter` when it is unset or invalid.
pub fn init_tracing(default_filter: &str) {
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default_filter)),
        )
        .init();
}

/// Parses the process's arguments; on `--help`, `--version` or a usage error, prints what clap
/// says and returns the exit code (0 for help and version, 2 for a usage error).
pub fn parse_args<A: Parser>() -> Result<A, ExitCode> {
    A::try_parse().map_err(|e| {
        let _ = e.print();
        ExitCode::from(e.exit_code().clamp(0, 255) as u8)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Parser)]
    struct Child {
        #[command(flatten)]
        child: ChildArgs,
    }

    #[test]
    fn child_arguments_parse_back_from_their_command_line() {
        let run = RunId::new("argsrt").expect("run id");
        let mut args = ChildArgs::new(run.clone(), Some(2), PathBuf::from("/tmp/s c.toml"));
        args.overrides = vec!["targets.count=4".into(), "uavs.count=2".into()];
        for a in [
            args.clone(),
            ChildArgs::new(run, None, PathBuf::from("s.toml")),
        ] {
            let line = std::iter::once(OsString::from("child")).chain(a.to_args());
            let parsed = Child::try_parse_from(line).expect("parses");
            assert_eq!(parsed.child, a);
        }
        assert_eq!(args.run(), args.run_id.in_domain(2));
    }
}
