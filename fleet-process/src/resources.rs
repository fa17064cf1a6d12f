//! Where a process's time and memory go: CPU clocks, the [`PhaseClock`] that splits one
//! thread's (or a whole process's) time into named phases, and the kernel's account of a
//! whole process ([`ProcessUsage`]: CPU time and peak resident memory).
//!
//! Phases are measured in CPU time and in wall time. The CPU time of a phase is the clock's
//! ([`CpuClock::Thread`] for work done on one thread, [`CpuClock::Process`] when the work of a
//! phase runs on a thread pool); its wall time is what a waiting phase is about. At every
//! moment the clock is in exactly one phase, so the phases' CPU times add up to the clock's
//! CPU time since the clock started: never more than the process's.
//!
//! ```
//! use fleet_process::resources::{CpuClock, PhaseClock};
//!
//! let mut clock = PhaseClock::new(CpuClock::Thread, "other");
//! let before = clock.enter("estimate");
//! let _work: u64 = (0..1000u64).sum();
//! clock.enter(before);
//! let phases = clock.times();
//! assert!(phases.contains_key("estimate") && phases.contains_key("other"));
//! ```
//!
//! A process's own account comes from `getrusage(RUSAGE_SELF)` ([`own_usage`]); a child's,
//! exactly and whatever ended it (a SIGKILL too), from `waitid(WNOWAIT)` on the exited child
//! before it is reaped ([`exited_child_usage`]), which leaves the reaping to its owner.
//!
//! The kernel's peak memory of a child (`ru_maxrss`) is not the child program's own: the
//! kernel carries the peak of the image a process replaces at `exec` over to the new program,
//! and a spawned child's image before its `exec` is the spawning process's. So a child of a
//! `fleet` that already ran a large fleet reports at least that `fleet`'s memory. A process
//! reads its own peak instead with [`own_peak_rss_kb`] (`VmHWM`, the high-water mark of the
//! program's own memory) and reports it; the kernel's figure is the fallback for a process
//! that could not report (a killed agent).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

/// Which CPU time a [`PhaseClock`] counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CpuClock {
    /// The calling thread's (`CLOCK_THREAD_CPUTIME_ID`): the clock must stay on one thread.
    Thread,
    /// The whole process's, every thread (`CLOCK_PROCESS_CPUTIME_ID`): for a process whose
    /// phases run on a pool of threads while one thread drives them.
    Process,
}

impl CpuClock {
    /// CPU time consumed so far (zero if the clock cannot be read, which Linux never does for
    /// these clocks).
    pub fn now(self) -> Duration {
        let id = match self {
            CpuClock::Thread => libc::CLOCK_THREAD_CPUTIME_ID,
            CpuClock::Process => libc::CLOCK_PROCESS_CPUTIME_ID,
        };
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: clock_gettime writes one timespec into memory this frame owns.
        let rc = unsafe { libc::clock_gettime(id, &mut ts) };
        if rc != 0 {
            return Duration::ZERO;
        }
        Duration::new(
            u64::try_from(ts.tv_sec).unwrap_or(0),
            u32::try_from(ts.tv_nsec).unwrap_or(0),
        )
    }
}

/// The time spent in one phase, seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PhaseTime {
    /// CPU time of the phase's clock.
    pub cpu_s: f64,
    /// Wall time.
    pub wall_s: f64,
}

/// Phases by name, as a process reports them.
pub type PhaseTimes = BTreeMap<String, PhaseTime>;

/// Accumulated time of one phase.
#[derive(Clone, Copy, Debug, Default)]
struct Spent {
    cpu: Duration,
    wall: Duration,
}

/// Splits a thread's (or process's) time into named phases: [`PhaseClock::enter`] closes the
/// current phase and opens another. Cheap: two clock reads per switch.
#[derive(Clone, Debug)]
pub struct PhaseClock {
    clock: CpuClock,
    current: &'static str,
    cpu_at: Duration,
    wall_at: Instant,
    spent: BTreeMap<&'static str, Spent>,
}

impl PhaseClock {
    /// A clock counting `clock`, in phase `phase` from now.
    pub fn new(clock: CpuClock, phase: &'static str) -> PhaseClock {
        PhaseClock {
            clock,
            current: phase,
            cpu_at: clock.now(),
            wall_at: Instant::now(),
            spent: BTreeMap::new(),
        }
    }

    /// The phase the clock is in.
    pub fn current(&self) -> &'static str {
        self.current
    }

    /// Closes the current phase and enters `phase`; returns the phase left, so that a nested
    /// phase can hand back to whatever called it (`let before = clock.enter("x"); ...;
    /// clock.enter(before);`).
    pub fn enter(&mut self, phase: &'static str) -> &'static str {
        if phase == self.current {
            return phase;
        }
        self.close();
        std::mem::replace(&mut self.current, phase)
    }

    /// Adds the time since the last switch to the current phase.
    fn close(&mut self) {
        let cpu = self.clock.now();
        let wall = Instant::now();
        let spent = self.spent.entry(self.current).or_default();
        spent.cpu += cpu.saturating_sub(self.cpu_at);
        spent.wall += wall.saturating_duration_since(self.wall_at);
        self.cpu_at = cpu;
        self.wall_at = wall;
    }

    /// The time of every phase so far, the current one up to now.
    pub fn times(&mut self) -> PhaseTimes {
        self.close();
        self.spent
            .iter()
            .map(|(name, s)| {
                let time = PhaseTime {
                    cpu_s: s.cpu.as_secs_f64(),
                    wall_s: s.wall.as_secs_f64(),
                };
                ((*name).to_owned(), time)
            })
            .collect()
    }
}

/// What the kernel accounted to a process: CPU time (every thread) and peak resident memory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ProcessUsage {
    /// CPU time in user mode, seconds.
    pub user_s: f64,
    /// CPU time in the kernel, seconds.
    pub system_s: f64,
    /// Peak resident set size, KiB (`ru_maxrss`).
    pub peak_rss_kb: u64,
}

impl ProcessUsage {
    /// User plus system CPU time, seconds.
    pub fn cpu_s(&self) -> f64 {
        self.user_s + self.system_s
    }

    /// Peak resident set size, MiB.
    pub fn peak_rss_mb(&self) -> f64 {
        kib_to_mib(self.peak_rss_kb)
    }

    fn from_rusage(ru: &libc::rusage) -> ProcessUsage {
        let secs = |tv: libc::timeval| tv.tv_sec as f64 + tv.tv_usec as f64 * 1e-6;
        ProcessUsage {
            user_s: secs(ru.ru_utime),
            system_s: secs(ru.ru_stime),
            peak_rss_kb: u64::try_from(ru.ru_maxrss).unwrap_or(0),
        }
    }
}

/// Why a process's usage could not be read.
#[derive(Debug, thiserror::Error)]
pub enum UsageReadError {
    /// `getrusage` failed.
    #[error("cannot read this process's resource usage: {0}")]
    Own(std::io::Error),
    /// `waitid` failed (the pid is not an unreaped child of this process, ...).
    #[error("cannot read the resource usage of child {pid}: {source}")]
    Child {
        /// The child's pid.
        pid: u32,
        /// What the system said.
        source: std::io::Error,
    },
    /// This system has no way to read a child's usage without reaping it.
    #[error("reading a child's resource usage is not supported on this system")]
    Unsupported,
}

/// KiB (the kernel's unit of memory) in MiB.
pub fn kib_to_mib(kib: u64) -> f64 {
    kib as f64 / 1024.0
}

/// This program's own peak resident memory so far, KiB: `VmHWM` of `/proc/self/status`, the
/// high-water mark of this process's memory since its `exec`, without the spawning process's
/// memory that the kernel's `ru_maxrss` of a child includes (see the module's docs). A child
/// process reads it at the end of its run and puts it in its report. `None` where `/proc` is
/// not there (off Linux) or has no such line.
pub fn own_peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    vm_hwm_kb(&status)
}

/// The `VmHWM` line of a `/proc/<pid>/status` text, KiB.
fn vm_hwm_kb(status: &str) -> Option<u64> {
    let value = status.lines().find_map(|l| l.strip_prefix("VmHWM:"))?;
    value.trim().strip_suffix("kB")?.trim().parse().ok()
}

/// This process's usage so far (`getrusage(RUSAGE_SELF)`: every thread, peak RSS since start).
pub fn own_usage() -> Result<ProcessUsage, UsageReadError> {
    // SAFETY: an all-zero rusage is a valid value of this plain C struct.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage writes one rusage into memory this frame owns.
    let rc = unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut ru) };
    if rc != 0 {
        return Err(UsageReadError::Own(std::io::Error::last_os_error()));
    }
    Ok(ProcessUsage::from_rusage(&ru))
}

/// The final usage of child `pid` if it has exited (`None` while it runs or is stopped),
/// without reaping it: `waitid(P_PID, pid, WEXITED | WNOHANG | WNOWAIT)` with the kernel's
/// rusage of the zombie, so the caller's `wait` still gets its status. Exact whatever ended
/// the child (an exit, SIGKILL), as long as it is called before the child is reaped.
#[cfg(target_os = "linux")]
pub fn exited_child_usage(pid: u32) -> Result<Option<ProcessUsage>, UsageReadError> {
    let child = |source| UsageReadError::Child { pid, source };
    let id = libc::id_t::from(pid);
    // SAFETY: all-zero siginfo_t and rusage are valid values of these plain C structs.
    let mut info: libc::siginfo_t = unsafe { std::mem::zeroed() };
    // SAFETY: as above.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    // The raw system call: its fifth argument (the rusage) is not in the libc wrapper.
    // SAFETY: waitid writes one siginfo_t and one rusage into memory this frame owns; WNOWAIT
    // leaves the child to its owner, WNOHANG never blocks.
    let rc = unsafe {
        libc::syscall(
            libc::SYS_waitid,
            libc::P_PID,
            id,
            &mut info as *mut libc::siginfo_t,
            libc::WEXITED | libc::WNOHANG | libc::WNOWAIT,
            &mut ru as *mut libc::rusage,
        )
    };
    if rc != 0 {
        return Err(child(std::io::Error::last_os_error()));
    }
    // SAFETY: waitid filled `info` (or left it zeroed when no child changed state).
    let exited = unsafe { info.si_pid() } != 0;
    Ok(exited.then(|| ProcessUsage::from_rusage(&ru)))
}

/// Not available off Linux: always [`UsageReadError::Unsupported`].
#[cfg(not(target_os = "linux"))]
pub fn exited_child_usage(_pid: u32) -> Result<Option<ProcessUsage>, UsageReadError> {
    Err(UsageReadError::Unsupported)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Burns some CPU on this thread.
    fn spin(for_at_least: Duration) -> u64 {
        let start = CpuClock::Thread.now();
        let mut x = 1u64;
        while CpuClock::Thread.now().saturating_sub(start) < for_at_least {
            for i in 0..1000u64 {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(i);
            }
        }
        std::hint::black_box(x)
    }

    #[test]
    fn cpu_clocks_advance_with_work() {
        for clock in [CpuClock::Thread, CpuClock::Process] {
            let before = clock.now();
            spin(Duration::from_millis(5));
            assert!(
                clock.now() >= before + Duration::from_millis(5),
                "{clock:?}"
            );
        }
    }

    #[test]
    fn phases_split_the_time_and_add_up_to_the_clock() {
        let start = CpuClock::Thread.now();
        let mut clock = PhaseClock::new(CpuClock::Thread, "other");
        assert_eq!(clock.current(), "other");
        let left = clock.enter("work");
        assert_eq!(left, "other");
        spin(Duration::from_millis(20));
        assert_eq!(clock.enter("wait"), "work");
        std::thread::sleep(Duration::from_millis(20));
        // Entering the current phase changes nothing.
        assert_eq!(clock.enter("wait"), "wait");
        clock.enter("work");
        spin(Duration::from_millis(5));
        let times = clock.times();
        let total_cpu = CpuClock::Thread.now().saturating_sub(start).as_secs_f64();
        let names: Vec<&str> = times.keys().map(String::as_str).collect();
        assert_eq!(names, ["other", "wait", "work"]);
        let work = times["work"];
        let wait = times["wait"];
        assert!(work.cpu_s >= 0.025, "{work:?}");
        assert!(work.wall_s >= work.cpu_s * 0.5, "{work:?}");
        // Sleeping costs wall time, (almost) no CPU.
        assert!(wait.wall_s >= 0.02, "{wait:?}");
        assert!(wait.cpu_s < 0.01, "{wait:?}");
        let sum: f64 = times.values().map(|t| t.cpu_s).sum();
        assert!(sum <= total_cpu + 1e-9, "{sum} > {total_cpu}");
    }

    #[test]
    fn times_include_the_open_phase_and_keep_counting() {
        let mut clock = PhaseClock::new(CpuClock::Thread, "busy");
        spin(Duration::from_millis(3));
        let first = clock.times()["busy"].cpu_s;
        assert!(first >= 0.003);
        spin(Duration::from_millis(3));
        let second = clock.times()["busy"].cpu_s;
        assert!(second >= first + 0.003, "{first} then {second}");
    }

    #[test]
    fn phase_times_round_trip_through_json() {
        let mut clock = PhaseClock::new(CpuClock::Process, "a");
        clock.enter("b");
        let times = clock.times();
        let text = serde_json::to_string(&times).expect("encode");
        let back: PhaseTimes = serde_json::from_str(&text).expect("decode");
        assert_eq!(back, times);
    }

    #[test]
    fn own_usage_counts_this_process() {
        spin(Duration::from_millis(5));
        let usage = own_usage().expect("getrusage");
        assert!(usage.cpu_s() >= 0.005, "{usage:?}");
        assert!(usage.peak_rss_kb > 0);
        assert!(usage.peak_rss_mb() > 0.0);
    }

    #[test]
    fn the_peak_is_read_from_the_vm_hwm_line() {
        let status = "Name:\tuav-agent\nVmPeak:\t  912344 kB\nVmSize:\t  900000 kB\n\
                      VmHWM:\t   40960 kB\nVmRSS:\t   30000 kB\n";
        assert_eq!(vm_hwm_kb(status), Some(40960));
        assert_eq!(vm_hwm_kb("Name:\tx\nVmRSS:\t 1 kB\n"), None);
        assert_eq!(vm_hwm_kb("VmHWM:\t lots kB\n"), None);
        assert_eq!(kib_to_mib(40960), 40.0);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn the_own_peak_follows_this_programs_memory() {
        let before = own_peak_rss_kb().expect("VmHWM");
        assert!(before > 0);
        // 64 MiB touched page by page: the high-water mark rises by about as much.
        let mut block = vec![0u8; 64 << 20];
        for i in (0..block.len()).step_by(4096) {
            block[i] = 1;
        }
        std::hint::black_box(&block);
        let after = own_peak_rss_kb().expect("VmHWM");
        assert!(after >= before.max(60 << 10), "{before} then {after} KiB");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn an_exited_childs_usage_is_read_and_the_child_is_left_to_reap() {
        let mut child = std::process::Command::new("sh")
            .args(["-c", "i=0; while [ $i -lt 20000 ]; do i=$((i+1)); done"])
            .spawn()
            .expect("sh");
        let pid = child.id();
        let deadline = Instant::now() + Duration::from_secs(60);
        let usage = loop {
            if let Some(usage) = exited_child_usage(pid).expect("waitid") {
                break usage;
            }
            assert!(Instant::now() < deadline, "the child did not exit");
            std::thread::sleep(Duration::from_millis(5));
        };
        assert!(usage.cpu_s() > 0.0, "{usage:?}");
        assert!(usage.peak_rss_kb > 0, "{usage:?}");
        // Still there to reap, with its status.
        assert!(child.wait().expect("wait").success());
        // Once reaped it is no child of ours any more.
        assert!(exited_child_usage(pid).is_err());
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_killed_child_still_has_its_usage() {
        let mut child = std::process::Command::new("sh")
            .args(["-c", "while :; do :; done"])
            .spawn()
            .expect("sh");
        let pid = child.id();
        assert_eq!(exited_child_usage(pid).expect("waitid"), None, "running");
        std::thread::sleep(Duration::from_millis(100));
        child.kill().expect("kill");
        let deadline = Instant::now() + Duration::from_secs(60);
        let usage = loop {
            if let Some(usage) = exited_child_usage(pid).expect("waitid") {
                break usage;
            }
            assert!(Instant::now() < deadline, "the child did not die");
            std::thread::sleep(Duration::from_millis(5));
        };
        assert!(usage.cpu_s() > 0.0, "{usage:?}");
        assert!(!child.wait().expect("wait").success());
    }
}
