//! The benchmark's child processes, seen from the parent: each is `fleet-bench-child`, which
//! dies with the parent (`fleet_process::startup::die_with_parent`), says
//! `ready` on stdout once its ports are open, starts on `go` from stdin and ends by printing
//! `result {json}`. Every wait is bounded; a child that fails or falls silent fails the bench
//! with its stderr, and every child still running is killed when the set is dropped.

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context, anyhow, bail};

use super::handshake::{GO, READY, RESULT};
use super::message::ChildReport;

/// The child binary: `fleet-bench-child` beside the running binary (`fleet`, or a test's
/// binary in `target/<profile>/deps`, whose parent directory holds the binaries).
fn child_binary() -> anyhow::Result<PathBuf> {
    const NAME: &str = "fleet-bench-child";
    let exe = std::env::current_exe().context("cannot locate the running binary")?;
    let dir = exe
        .parent()
        .context("the running binary has no directory")?;
    [dir.join(NAME), dir.join("..").join(NAME)]
        .into_iter()
        .find(|p| p.is_file())
        .with_context(|| format!("{NAME} not found beside {}", exe.display()))
}

/// How long a child may hold the end of its stderr in an error message.
const STDERR_TAIL: usize = 2000;

struct Member {
    name: String,
    process: Child,
    stdin: Option<ChildStdin>,
    stderr: Option<JoinHandle<String>>,
    lines: VecDeque<String>,
    closed: bool,
    /// Its result was read: ending its output is expected.
    done: bool,
}

/// Lines read from the children's stdout: (child index, line or end of output).
type LineEvent = (usize, Option<String>);

/// A set of running children.
pub struct ChildSet {
    members: Vec<Member>,
    events: mpsc::Receiver<LineEvent>,
    sender: mpsc::Sender<LineEvent>,
}

impl ChildSet {
    /// An empty set.
    pub fn new() -> ChildSet {
        let (sender, events) = mpsc::channel();
        ChildSet {
            members: Vec::new(),
            events,
            sender,
        }
    }

    /// Starts `fleet-bench-child ARGS` as `name` and waits (at most `timeout`) until it is
    /// ready.
    pub fn spawn_ready(
        &mut self,
        name: &str,
        args: &[String],
        timeout: Duration,
    ) -> anyhow::Result<()> {
        let mut cmd = Command::new(child_binary()?);
        cmd.args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut process = cmd
            .spawn()
            .with_context(|| format!("cannot start bench child {name}"))?;
        let index = self.members.len();
        let stdout = process.stdout.take();
        let stderr = process.stderr.take();
        let sender = self.sender.clone();
        if let Some(stdout) = stdout {
            std::thread::spawn(move || {
                for line in BufReader::new(stdout).lines() {
                    let Ok(line) = line else { break };
                    if sender.send((index, Some(line))).is_err() {
                        return;
                    }
                }
                let _ = sender.send((index, None));
            });
        }
        let stderr = stderr.map(|mut s| {
            std::thread::spawn(move || {
                let mut text = String::new();
                let _ = s.read_to_string(&mut text);
                text
            })
        });
        self.members.push(Member {
            name: name.to_owned(),
            stdin: process.stdin.take(),
            process,
            stderr,
            lines: VecDeque::new(),
            closed: false,
            done: false,
        });
        let line = self.next_line(index, Instant::now() + timeout, READY)?;
        if line != READY {
            bail!("bench child {name} said {line:?} instead of {READY:?}");
        }
        Ok(())
    }

    /// Starts every child.
    pub fn go(&mut self) -> anyhow::Result<()> {
        for m in &mut self.members {
            let stdin = m
                .stdin
                .as_mut()
                .ok_or_else(|| anyhow!("bench child {} has no stdin", m.name))?;
            writeln!(stdin, "{GO}")
                .and_then(|()| stdin.flush())
                .with_context(|| format!("cannot start bench child {}", m.name))?;
        }
        Ok(())
    }

    /// Waits (until `deadline` overall) for every child's report and exit.
    pub fn results(&mut self, deadline: Instant) -> anyhow::Result<Vec<ChildReport>> {
        let mut out = Vec::with_capacity(self.members.len());
        for i in 0..self.members.len() {
            let line = self.next_line(i, deadline, "its result")?;
            let name = &self.members[i].name;
            let json = line.strip_prefix(RESULT).ok_or_else(|| {
                anyhow!("bench child {name} printed {line:?} instead of a result")
            })?;
            let report: ChildReport = serde_json::from_str(json)
                .with_context(|| format!("bench child {name} printed a malformed result"))?;
            self.members[i].done = true;
            out.push(report);
        }
        for i in 0..self.members.len() {
            self.wait_exit(i, deadline)?;
        }
        Ok(out)
    }

    /// The next stdout line of child `i`; an error naming the child and quoting its stderr if
    /// it ends its output or the deadline passes first.
    fn next_line(&mut self, i: usize, deadline: Instant, what: &str) -> anyhow::Result<String> {
        loop {
            if let Some(line) = self.members[i].lines.pop_front() {
                return Ok(line);
            }
            if self.members[i].closed {
                return Err(self.failure(i, &format!("ended before {what}")));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(self.failure(i, &format!("sent no {what} in time")));
            }
            match self.events.recv_timeout(left) {
                Ok((j, Some(line))) => self.members[j].lines.push_back(line),
                Ok((j, None)) => {
                    self.members[j].closed = true;
                    // Another child that ends with nothing left to read died early: its peers
                    // would only time out waiting for it, so report it at once.
                    let m = &self.members[j];
                    if j != i && !m.done && m.lines.is_empty() {
                        return Err(self.failure(j, "ended early"));
                    }
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    return Err(self.failure(i, "lost its output"));
                }
            }
        }
    }

    fn wait_exit(&mut self, i: usize, deadline: Instant) -> anyhow::Result<()> {
        loop {
            match self.members[i].process.try_wait() {
                Ok(Some(status)) if status.success() => return Ok(()),
                Ok(Some(status)) => {
                    return Err(self.failure(i, &format!("exited with {status}")));
                }
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(2));
                }
                Ok(None) => return Err(self.failure(i, "did not exit in time")),
                Err(e) => return Err(self.failure(i, &format!("cannot be waited for: {e}"))),
            }
        }
    }

    /// Kills child `i` and describes its failure with the end of its stderr.
    fn failure(&mut self, i: usize, what: &str) -> anyhow::Error {
        let m = &mut self.members[i];
        let _ = m.process.kill();
        let status = m
            .process
            .wait()
            .map(|s| s.to_string())
            .unwrap_or_else(|e| e.to_string());
        let stderr = m
            .stderr
            .take()
            .and_then(|h| h.join().ok())
            .unwrap_or_default();
        let tail = stderr
            .char_indices()
            .rev()
            .nth(STDERR_TAIL)
            .map_or(stderr.as_str(), |(at, _)| &stderr[at..]);
        anyhow!(
            "bench child {} {what} ({status}); its stderr:\n{}",
            m.name,
            tail.trim_end()
        )
    }
}

impl Drop for ChildSet {
    fn drop(&mut self) {
        for m in &mut self.members {
            if matches!(m.process.try_wait(), Ok(None)) {
                let _ = m.process.kill();
            }
            let _ = m.process.wait();
        }
    }
}
