//! # tests
//!
//! The harness of setfleet's integration tests, which spawn the real binaries:
//!
//! - [`binary`] finds `world-server`, `uav-agent`, `fleet` next to the test executable
//!   (`target/<profile>/`), building all three once per test process (`$CARGO build --bins
//!   -p ...` with the test's profile): `cargo test --workspace` does not build other
//!   packages' binaries for this package's tests. All at once, so that a test never waits for
//!   a build (behind another test's, on cargo's lock) after it started a process that waits
//!   for it. The agent is built with its `test-hooks` feature (which this crate's
//!   dev-dependency on `uav-agent` also turns on), so fault injection such as
//!   `SETFLEET_TEST_HOLD_TOKEN_MS` works here and nowhere else.
//! - [`TestRun`] gives each test a unique [`RunId`] (so its own iceoryx2 prefix) and a temp
//!   dir; dropping it removes both, including the run's iceoryx2 files.
//! - [`ChildGuard`] kills (SIGKILL) and reaps its child when dropped, so a failing test never
//!   leaves a process behind. Declare it after the [`TestRun`]: locals drop in reverse order,
//!   so the child is gone before the run's files are removed.
//! - Every wait takes a timeout ([`ChildGuard::wait_timeout`]).

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU32, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use fleet_process::startup::ChildArgs;
use protocol::ipc;
use protocol::service::RunId;

/// The binaries the tests run, the packages that build them and the features the tests need
/// (the agent's fault-injection hooks, which shipped builds leave out).
const BINARIES: [(&str, &str, &str); 5] = [
    ("world-server", "world-server", ""),
    ("uav-agent", "uav-agent", "test-hooks"),
    ("fleet", "orchestrator", ""),
    ("fleet-bridge", "bridge", ""),
    ("fleet-bench-child", "fleet-bench", ""),
];

/// Most simulated hosts a test's run uses: their domains' files are checked and removed too.
pub const MAX_TEST_HOSTS: u16 = 4;

/// Longest wait for a process that should end on its own.
pub const EXIT_TIMEOUT: Duration = Duration::from_secs(120);

/// The directory holding the test executable's sibling binaries (`target/<profile>/`).
pub fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap_or_default();
    // target/<profile>/deps/integration-<hash>
    exe.parent()
        .and_then(Path::parent)
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

/// Path of binary `name` (`world-server`, `fleet`, ...). The first call in a test process
/// builds every binary with the test's profile and the features the tests need (always: a
/// file's age cannot tell which features it was built with; cargo rebuilds only what
/// changed). Panics, failing the test, if they cannot be built.
pub fn binary(name: &str) -> PathBuf {
    static BUILT: OnceLock<Result<(), String>> = OnceLock::new();
    if !BINARIES.iter().any(|(bin, _, _)| *bin == name) {
        panic!("unknown binary {name:?}");
    }
    let built = BUILT.get_or_init(build_packages);
    if let Err(e) = built {
        panic!("cannot build the binaries: {e}");
    }
    let path = target_dir().join(name);
    assert!(path.exists(), "binary {} not found", path.display());
    path
}

/// Builds every package's binaries with their features (the same features `cargo test`
/// unifies in, so the two builds do not undo each other).
fn build_packages() -> Result<(), String> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let dir = target_dir();
    let profile = match dir.file_name().and_then(|n| n.to_str()) {
        Some("debug") | None => "dev".to_owned(),
        Some(other) => other.to_owned(),
    };
    let mut cmd = Command::new(cargo);
    cmd.args(["build", "--bins", "--profile", &profile]);
    for (_, package, features) in BINARIES {
        cmd.args(["-p", package]);
        if !features.is_empty() {
            cmd.args(["--features", &format!("{package}/{features}")]);
        }
    }
    if let Some(target) = dir.parent() {
        cmd.arg("--target-dir").arg(target);
    }
    let out = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&out.stderr).into_owned())
    }
}

/// One test's run: a unique run id and a temp dir, both removed on drop.
pub struct TestRun {
    /// The run id (and so the iceoryx2 prefix) of this test.
    pub run: RunId,
    /// A fresh directory for this test's files.
    pub dir: PathBuf,
}

impl TestRun {
    /// A new run for the test `topic` (a short name, letters, digits and '-').
    pub fn new(topic: &str) -> TestRun {
        static COUNTER: AtomicU32 = AtomicU32::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let topic: String = topic
            .chars()
            .filter(|c| c.is_ascii_alphanumeric() || *c == '-')
            .take(20)
            .collect();
        let id = format!("t{}-{n}-{topic}", std::process::id());
        let run = RunId::new(&id).unwrap_or_else(|e| panic!("bad test run id {id:?}: {e}"));
        let dir = std::env::temp_dir().join(format!("setfleet-{id}"));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir)
            .unwrap_or_else(|e| panic!("cannot create {}: {e}", dir.display()));
        TestRun { run, dir }
    }

    /// Writes a file into the test's dir and returns its path.
    pub fn write(&self, name: &str, text: &str) -> PathBuf {
        let path = self.dir.join(name);
        std::fs::write(&path, text)
            .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
        path
    }

    /// The run and its simulated hosts' domains (`fleet run --hosts`).
    pub fn domains(&self) -> Vec<RunId> {
        std::iter::once(self.run.clone())
            .chain((1..MAX_TEST_HOSTS).map(|h| self.run.in_domain(h)))
            .collect()
    }

    /// The run's files (in every domain) still in `/dev/shm` and under iceoryx2's root.
    pub fn ipc_files(&self) -> Vec<PathBuf> {
        self.domains()
            .iter()
            .flat_map(|run| ipc::run_files(run).unwrap_or_default())
            .collect()
    }
}

impl Drop for TestRun {
    fn drop(&mut self) {
        for run in self.domains() {
            let _ = ipc::remove_run_files(&run);
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A spawned child that is killed (SIGKILL) and reaped when dropped.
pub struct ChildGuard {
    child: Option<Child>,
    /// The threads draining the child's stdout and stderr into buffers.
    stdout: Option<JoinHandle<Vec<u8>>>,
    stderr: Option<JoinHandle<Vec<u8>>>,
}

impl ChildGuard {
    /// Spawns `cmd` with stdout and stderr captured. A thread per pipe reads it as the child
    /// writes, so a child that writes more than a pipe holds (64 KiB) never blocks on it.
    pub fn spawn(cmd: &mut Command) -> ChildGuard {
        let mut child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot spawn {cmd:?}: {e}"));
        ChildGuard {
            stdout: child.stdout.take().map(drain),
            stderr: child.stderr.take().map(drain),
            child: Some(child),
        }
    }

    /// The process id.
    pub fn id(&self) -> u32 {
        self.child.as_ref().map(Child::id).unwrap_or_default()
    }

    /// Sends a signal (e.g. `libc::SIGTERM`).
    pub fn signal(&self, signal: i32) {
        if let Ok(pid) = i32::try_from(self.id())
            && pid > 0
        {
            // SAFETY: kill(2) on our own child's pid; no memory is involved.
            unsafe {
                libc::kill(pid, signal);
            }
        }
    }

    /// Whether the child is still running.
    pub fn is_running(&mut self) -> bool {
        self.child
            .as_mut()
            .is_some_and(|c| matches!(c.try_wait(), Ok(None)))
    }

    /// Waits at most `timeout` for the child to exit; returns its status and everything it
    /// wrote, or `None` if it is still running (it is then killed when the guard drops).
    pub fn wait_timeout(&mut self, timeout: Duration) -> Option<Output> {
        let deadline = Instant::now() + timeout;
        let status = loop {
            let child = self.child.as_mut()?;
            match child.try_wait() {
                Ok(Some(status)) => break status,
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(20))
                }
                _ => return None,
            }
        };
        self.child = None;
        // The pipes end when the child and whatever inherited them have exited.
        let collect = |reader: Option<JoinHandle<Vec<u8>>>| {
            reader.and_then(|r| r.join().ok()).unwrap_or_default()
        };
        Some(Output {
            status,
            stdout: collect(self.stdout.take()),
            stderr: collect(self.stderr.take()),
        })
    }
}

/// Reads `pipe` to its end on a thread of its own; the thread returns what it read.
fn drain(mut pipe: impl Read + Send + 'static) -> JoinHandle<Vec<u8>> {
    std::thread::spawn(move || {
        let mut buffer = Vec::new();
        // A read error ends the capture; what was read so far is kept.
        let _ = pipe.read_to_end(&mut buffer);
        buffer
    })
}

impl Drop for ChildGuard {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Runs a command to completion (bounded by [`EXIT_TIMEOUT`]) and returns its output.
pub fn run_to_end(cmd: &mut Command) -> Output {
    let mut guard = ChildGuard::spawn(cmd);
    guard
        .wait_timeout(EXIT_TIMEOUT)
        .unwrap_or_else(|| panic!("{cmd:?} did not end within {EXIT_TIMEOUT:?}"))
}

/// A small, fast scenario: few UAVs and cars, a small camera, a short run.
pub fn small_scenario_toml(duration_s: f64) -> String {
    format!(
        "seed = 7\nduration_s = {duration_s}\n\n[region]\nhalf_extent_m = 100.0\n\n\
         [targets]\ncount = 3\n\n[uavs]\ncount = 2\n\n[camera]\nrows = 36\ncols = 48\n"
    )
}

/// Processes whose command line mentions `needle` (e.g. a run id): (pid, command line).
pub fn processes_mentioning(needle: &str) -> Vec<(u32, String)> {
    let own = std::process::id();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    entries
        .flatten()
        .filter_map(|e| {
            let pid: u32 = e.file_name().to_str()?.parse().ok()?;
            let raw = std::fs::read(e.path().join("cmdline")).ok()?;
            let cmdline = String::from_utf8_lossy(&raw).replace('\0', " ");
            (pid != own && cmdline.contains(needle)).then(|| (pid, cmdline.trim().to_owned()))
        })
        .collect()
}

/// Waits until `done` holds, polling every 20 ms; panics with `what` after `timeout`.
pub fn wait_until(what: &str, timeout: Duration, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + timeout;
    while !done() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// `fleet run` of `scenario` into `out` with `t`'s run id, and `extra` arguments.
pub fn fleet_run(t: &TestRun, scenario: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut cmd = Command::new(binary("fleet"));
    cmd.args(["run", "--run-id", t.run.as_str(), "--scenario"])
        .arg(scenario)
        .arg("--out")
        .arg(out)
        .args(extra);
    cmd
}

/// The command of one of `t`'s run's processes (`world-server`, `uav-agent`): the binary
/// `name` with the run's id and `scenario`; the caller adds the rest.
pub fn run_process(name: &str, t: &TestRun, scenario: &Path) -> Command {
    let mut cmd = Command::new(binary(name));
    cmd.args(ChildArgs::new(t.run.clone(), None, scenario.to_owned()).to_args());
    cmd
}

/// Starts a `world-server` of `t`'s run on `scenario`, serving the agents `agents` (a
/// comma-separated list), with long start and ack waits and `extra` arguments.
pub fn world_server(t: &TestRun, scenario: &Path, agents: &str, extra: &[&str]) -> ChildGuard {
    ChildGuard::spawn(
        run_process("world-server", t, scenario)
            .args(["--agents", agents, "--start-timeout-ms", "60000"])
            .args(["--ack-timeout-ms", "30000"])
            .args(extra),
    )
}

/// Plays one of the run's processes in the test: calls `hello` every 200 ms until the first
/// sample of `samples` arrives, hands every sample to `handle`, and returns at the run's end
/// (the `EndOfRun` event on `wake`), when `world` exits, or after [`EXIT_TIMEOUT`].
pub fn follow<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend>(
    waitset: &iceoryx2::prelude::WaitSet<ipc::Ipc>,
    wake: &iceoryx2::port::listener::Listener<ipc::Ipc>,
    samples: &iceoryx2::port::subscriber::Subscriber<ipc::Ipc, T, ()>,
    world: &mut ChildGuard,
    hello: impl Fn(),
    mut handle: impl FnMut(&T),
) {
    let _guard = waitset
        .attach_notification(wake)
        .expect("a listener attaches to the waitset");
    let deadline = Instant::now() + EXIT_TIMEOUT;
    let (mut ended, mut seen) = (false, false);
    let mut last_hello = None::<Instant>;
    while !ended && Instant::now() < deadline && world.is_running() {
        if !seen && last_hello.is_none_or(|h| h.elapsed() > Duration::from_millis(200)) {
            hello();
            last_hello = Some(Instant::now());
        }
        waitset
            .wait_and_process_once_with_timeout(
                |_| {
                    let _ = wake.try_wait(|e| {
                        ended |= ipc::WakeEvent::from_id(e.id) == Some(ipc::WakeEvent::EndOfRun)
                    });
                    iceoryx2::prelude::CallbackProgression::Continue
                },
                Duration::from_millis(100),
            )
            .expect("the waitset waits");
        while let Some(sample) = samples.receive().expect("a sample is received") {
            seen = true;
            handle(sample.payload());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_child_that_fills_its_pipes_is_reaped_with_all_its_output() {
        const MIB: usize = 1 << 20;
        // More than a pipe holds on each stream, stdout first: a harness that reads nothing
        // until the child exits leaves it blocked on its first write.
        let script = format!("head -c {MIB} /dev/zero; head -c {MIB} /dev/zero | tr '\\0' e >&2");
        let mut child = ChildGuard::spawn(Command::new("sh").args(["-c", &script]));
        let out = child
            .wait_timeout(EXIT_TIMEOUT)
            .expect("the child exited and was reaped");
        assert!(out.status.success(), "{:?}", out.status);
        assert_eq!(out.stdout.len(), MIB);
        assert!(out.stdout.iter().all(|&b| b == 0));
        assert_eq!(out.stderr.len(), MIB);
        assert!(out.stderr.iter().all(|&b| b == b'e'));
    }

    #[test]
    fn a_child_still_running_at_the_timeout_is_reported_and_killed() {
        let mut child = ChildGuard::spawn(Command::new("sleep").arg("60"));
        assert!(child.wait_timeout(Duration::from_millis(50)).is_none());
        assert!(child.is_running());
        drop(child);
    }
}
