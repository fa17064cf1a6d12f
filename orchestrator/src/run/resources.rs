//! Where a run's time and memory went, per process (`summary.json` `resources`).
//!
//! - **CPU time** of every child (the world-server, every agent process, restarted ones
//!   included) is the kernel's account of the exited process, read just before it is reaped
//!   ([`super::children`]): exact, user plus system time of every thread, and a SIGKILLed
//!   agent's too (what it used up to the kill). A child that could not be reaped has none.
//!   The orchestrator's own is `getrusage(RUSAGE_SELF)`: its CPU from the start of the run
//!   to its end (a sweep runs several runs in one process).
//! - **Peak resident memory** of a child is its own, `VmHWM` as it printed it in its report
//!   at exit ([`PeakSource::Vmhwm`]). The kernel's account of the exited child
//!   ([`PeakSource::Rusage`]) is only the fallback for a child that printed none (killed, or
//!   a bridge): it includes this process's memory at the spawn
//!   ([`fleet_process::resources`]), which grows with every fleet a bench or a sweep ran before.
//!   The orchestrator's own is its `getrusage` peak since the process started.
//! - **Phases** are what each process measured itself ([`fleet_process::resources::PhaseClock`])
//!   and printed in its report at exit (one line of JSON on stdout, which goes to its log):
//!   the world-server's process CPU per phase, each agent's thread CPU per phase, the
//!   observer thread's. A process that was killed prints no report, so it has no phases.
//!   The orchestrator's `other` phase is its CPU less the observer thread's phases.
//!
//! Every value here depends on the machine and its load: the whole section is left out when
//! two runs are compared for determinism.

use std::collections::BTreeMap;
use std::path::Path;

use fleet_observe::results::resources::{
    PeakSource, ProcessResources, ResourceTotals, Resources, RunSize,
};
use fleet_process::resources::{PhaseTimes, ProcessUsage, kib_to_mib};

use super::children::ExitedProcess;

/// What the orchestrator knows of its own process over a run.
#[derive(Clone, Debug, Default)]
pub struct OwnUsage {
    /// CPU over the run (the process's at the end less at the start).
    pub usage: Option<ProcessUsage>,
    /// The observer thread's phases.
    pub observer: PhaseTimes,
}

/// The resources of a run: the orchestrator's `own`, the children that `exited` (their
/// phases and own peak memory read from the reports in the logs in `logs`), over `uavs` UAVs,
/// `steps` steps of `sim_s` simulated seconds in `wall_s`.
pub fn gather(own: &OwnUsage, exited: &[ExitedProcess], logs: &Path, run: RunSize) -> Resources {
    let reports = reports(logs);
    let mut processes = vec![orchestrator(own)];
    let mut children: Vec<ProcessResources> = exited
        .iter()
        .map(|p| {
            let report = p.pid.and_then(|pid| reports.get(&pid));
            child(p, report)
        })
        .collect();
    // The world first, then the agents in order, then the bridges.
    children.sort_by_key(|p| (p.role == "bridge", p.uav.is_some(), p.uav, p.incarnation));
    processes.extend(children);
    let totals = ResourceTotals::of(&processes, run);
    Resources { processes, totals }
}

fn orchestrator(own: &OwnUsage) -> ProcessResources {
    let mut phases: BTreeMap<String, f64> = own
        .observer
        .iter()
        .map(|(name, t)| (name.clone(), t.cpu_s))
        .collect();
    let phases_wall_s = own
        .observer
        .iter()
        .map(|(name, t)| (name.clone(), t.wall_s))
        .collect();
    if let Some(usage) = own.usage {
        let observed: f64 = phases.values().sum();
        // The rest of the process: the event loop, faults, progress, the runtime.
        let rest = (usage.cpu_s() - observed).max(0.0);
        *phases.entry("other".to_owned()).or_insert(0.0) += rest;
    }
    ProcessResources {
        role: "orchestrator".to_owned(),
        end: "running".to_owned(),
        cpu_s: own.usage.map(|u| u.cpu_s()),
        user_s: own.usage.map(|u| u.user_s),
        system_s: own.usage.map(|u| u.system_s),
        peak_rss_mb: own.usage.map(|u| u.peak_rss_mb()),
        peak_rss_source: own.usage.map(|_| PeakSource::Rusage),
        phases,
        phases_wall_s,
        ..ProcessResources::default()
    }
}

/// A child's peak memory, MiB, and where it comes from: its own report's, else the kernel's.
fn child_peak(p: &ExitedProcess, report: Option<&Report>) -> (Option<f64>, Option<PeakSource>) {
    match (report.and_then(|r| r.peak_rss_kb), p.usage) {
        (Some(kb), _) => (Some(kib_to_mib(kb)), Some(PeakSource::Vmhwm)),
        (None, Some(usage)) => (Some(usage.peak_rss_mb()), Some(PeakSource::Rusage)),
        (None, None) => (None, None),
    }
}

fn child(p: &ExitedProcess, report: Option<&Report>) -> ProcessResources {
    use std::os::unix::process::ExitStatusExt as _;
    let end = match p.status {
        Some(s) => match (s.code(), s.signal()) {
            (Some(code), _) => format!("exit {code}"),
            (None, Some(signal)) => format!("signal {signal}"),
            (None, None) => s.to_string(),
        },
        None => "not reaped".to_owned(),
    };
    let (peak_rss_mb, peak_rss_source) = child_peak(p, report);
    let phases = report.map(|r| r.phases.clone()).unwrap_or_default();
    ProcessResources {
        role: match (p.uav, &p.bridge_host) {
            (Some(_), _) => "agent",
            (None, Some(_)) => "bridge",
            (None, None) => "world",
        }
        .to_owned(),
        uav: p.uav,
        incarnation: p.incarnation,
        end,
        cpu_s: p.usage.map(|u| u.cpu_s()),
        user_s: p.usage.map(|u| u.user_s),
        system_s: p.usage.map(|u| u.system_s),
        peak_rss_mb,
        peak_rss_source,
        phases: phases.iter().map(|(n, t)| (n.clone(), t.cpu_s)).collect(),
        phases_wall_s: phases.iter().map(|(n, t)| (n.clone(), t.wall_s)).collect(),
        external: report
            .and_then(|r| r.external.clone())
            .filter(|e| !e.is_null()),
    }
}

/// What a child says of itself in the report it prints at exit (one line of JSON among its
/// log's lines; the rest of the report is the child's own business).
#[derive(Debug, serde::Deserialize)]
struct Report {
    pid: u32,
    phases: PhaseTimes,
    /// Its own peak resident memory, KiB (`VmHWM`); absent from an older child's report.
    #[serde(default)]
    peak_rss_kb: Option<u64>,
    /// An agent's external planner's figures, passed on as they are.
    #[serde(default)]
    external: Option<serde_json::Value>,
}

/// The report every process printed, by pid: the JSON lines of the logs in `logs` that carry
/// a `pid` and `phases` (a line that is not such a report is skipped).
fn reports(logs: &Path) -> BTreeMap<u32, Report> {
    let mut out = BTreeMap::new();
    let Ok(dir) = std::fs::read_dir(logs) else {
        return out;
    };
    for entry in dir.flatten() {
        let path = entry.path();
        if path.extension().and_then(|e| e.to_str()) != Some("log") {
            continue;
        }
        let Ok(text) = std::fs::read_to_string(&path) else {
            tracing::debug!(log = %path.display(), "cannot read a log");
            continue;
        };
        out.extend(reports_in(&text));
    }
    out
}

/// The reports (`{"pid": .., "phases": {..}, ..}` lines) in a log's text, by pid.
fn reports_in(text: &str) -> impl Iterator<Item = (u32, Report)> + '_ {
    text.lines()
        .filter(|line| line.starts_with('{'))
        .filter_map(|line| serde_json::from_str::<Report>(line).ok())
        .map(|r| (r.pid, r))
}

#[cfg(test)]
mod tests {
    use super::*;
    use fleet_process::resources::PhaseTime;

    #[test]
    fn reports_are_found_among_log_lines_by_pid() {
        let text = "2026-01-01T00:00:00Z  INFO agent started\n\
                    {\"frames\":3,\"pid\":42,\"phases\":{\"estimate\":{\"cpu_s\":1.5,\"wall_s\":2.0}}}\n\
                    {not json\n\
                    {\"pid\":7}\n\
                    {\"pid\":43,\"phases\":{}}\n";
        let found: BTreeMap<u32, Report> = reports_in(text).collect();
        assert_eq!(found.len(), 2);
        assert_eq!(
            found[&42].phases["estimate"],
            PhaseTime {
                cpu_s: 1.5,
                wall_s: 2.0
            }
        );
        assert!(found[&43].phases.is_empty());
        assert_eq!(found[&42].peak_rss_kb, None);
    }

    #[test]
    fn a_childs_own_peak_wins_over_the_kernels_which_is_the_fallback() {
        // The kernel's figure of a child counts the parent's memory at the spawn: 600 MiB
        // here, against the 40 MiB the child's own high-water mark says.
        let text = "{\"pid\":10,\"phases\":{},\"peak_rss_kb\":40960}\n";
        let found: BTreeMap<u32, Report> = reports_in(text).collect();
        let process = |pid| ExitedProcess {
            uav: Some(0),
            incarnation: Some(1),
            bridge_host: None,
            pid: Some(pid),
            status: None,
            usage: Some(ProcessUsage {
                user_s: 1.0,
                system_s: 0.0,
                peak_rss_kb: 600 << 10,
            }),
        };
        let reported = child(&process(10), found.get(&10));
        assert_eq!(reported.peak_rss_mb, Some(40.0));
        assert_eq!(reported.peak_rss_source, Some(PeakSource::Vmhwm));
        // A killed agent printed no report: the kernel's figure, said to be so.
        let killed = child(&process(11), found.get(&11));
        assert_eq!(killed.peak_rss_mb, Some(600.0));
        assert_eq!(killed.peak_rss_source, Some(PeakSource::Rusage));
        let unreaped = ExitedProcess {
            usage: None,
            ..process(12)
        };
        let none = child(&unreaped, None);
        assert_eq!((none.peak_rss_mb, none.peak_rss_source), (None, None));
        // In summary.json: a new key beside the old ones.
        let json = serde_json::to_value(&reported).unwrap();
        assert_eq!(json["peak_rss_mb"], 40.0);
        assert_eq!(json["peak_rss_source"], "vmhwm");
    }

    #[test]
    fn totals_add_the_processes_and_the_orchestrator_keeps_the_rest_as_other() {
        let usage = |cpu: f64| ProcessUsage {
            user_s: cpu,
            system_s: 0.0,
            peak_rss_kb: 2048,
        };
        let mut observer = PhaseTimes::new();
        observer.insert(
            "observe".into(),
            PhaseTime {
                cpu_s: 0.5,
                wall_s: 0.6,
            },
        );
        let own = OwnUsage {
            usage: Some(usage(2.0)),
            observer,
        };
        let exited = [
            ExitedProcess {
                uav: Some(0),
                incarnation: Some(1),
                bridge_host: None,
                pid: Some(10),
                status: None,
                usage: Some(usage(3.0)),
            },
            ExitedProcess {
                uav: None,
                incarnation: None,
                bridge_host: None,
                pid: Some(11),
                status: None,
                usage: Some(usage(5.0)),
            },
        ];
        let run = RunSize {
            uavs: 1,
            steps: 100,
            sim_s: 50.0,
            wall_s: 25.0,
        };
        let r = gather(&own, &exited, Path::new("/nonexistent"), run);
        let roles: Vec<&str> = r.processes.iter().map(|p| p.role.as_str()).collect();
        assert_eq!(roles, ["orchestrator", "world", "agent"]);
        let orchestrator = &r.processes[0];
        assert_eq!(orchestrator.phases["other"], 1.5);
        assert_eq!(orchestrator.peak_rss_mb, Some(2.0));
        assert_eq!(orchestrator.peak_rss_source, Some(PeakSource::Rusage));
        assert_eq!(r.totals.cpu_s, 10.0);
        assert_eq!(r.totals.world_and_agents_cpu_s, 8.0);
        assert_eq!(r.totals.cpu_ms_per_uav_step, Some(80.0));
        assert_eq!(r.totals.wall_s_per_sim_s, Some(0.5));
    }
}
