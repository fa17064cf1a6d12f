//! Where a run's time and memory went, per process (`summary.json` `resources`).
//!
//! - **CPU time and peak resident memory** of every child (the world-server, every agent
//!   process, restarted ones included) are the kernel's account of the exited process, read
//!   just before it is reaped ([`super::children`]): exact, user plus system time of every
//!   thread, and a SIGKILLed agent's too (what it used up to the kill). A child that could
//!   not be reaped has none. The orchestrator's own are `getrusage(RUSAGE_SELF)`: its CPU
//!   from the start of the run to its end (a sweep runs several runs in one process), its
//!   peak memory since the process started.
//! - **Phases** are what each process measured itself ([`protocol::resources::PhaseClock`])
//!   and printed in its report at exit (one line of JSON on stdout, which goes to its log):
//!   the world-server's process CPU per phase, each agent's thread CPU per phase, the
//!   observer thread's. A process that was killed prints no report, so it has no phases.
//!   The orchestrator's `other` phase is its CPU less the observer thread's phases.
//!
//! Every value here depends on the machine and its load: the whole section is left out when
//! two runs are compared for determinism.

use std::collections::BTreeMap;
use std::path::Path;

use fleet_observe::results::resources::{ProcessResources, ResourceTotals, Resources, RunSize};
use protocol::resources::{PhaseTimes, ProcessUsage};

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
/// phases read from the reports in the logs in `logs`), over `uavs` UAVs, `steps` steps
/// of `sim_s` simulated seconds in `wall_s`.
pub fn gather(own: &OwnUsage, exited: &[ExitedProcess], logs: &Path, run: RunSize) -> Resources {
    let reports = reported_phases(logs);
    let mut processes = vec![orchestrator(own)];
    let mut children: Vec<ProcessResources> = exited
        .iter()
        .map(|p| {
            let phases = p.pid.and_then(|pid| reports.get(&pid));
            child(p, phases)
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
        phases,
        phases_wall_s,
        ..ProcessResources::default()
    }
}

fn child(p: &ExitedProcess, phases: Option<&PhaseTimes>) -> ProcessResources {
    use std::os::unix::process::ExitStatusExt as _;
    let end = match p.status {
        Some(s) => match (s.code(), s.signal()) {
            (Some(code), _) => format!("exit {code}"),
            (None, Some(signal)) => format!("signal {signal}"),
            (None, None) => s.to_string(),
        },
        None => "not reaped".to_owned(),
    };
    let phases = phases.cloned().unwrap_or_default();
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
        peak_rss_mb: p.usage.map(|u| u.peak_rss_mb()),
        phases: phases.iter().map(|(n, t)| (n.clone(), t.cpu_s)).collect(),
        phases_wall_s: phases.iter().map(|(n, t)| (n.clone(), t.wall_s)).collect(),
    }
}

/// The phases every process printed in its report, by pid: the JSON lines of the logs in
/// `logs` that carry a `pid` and `phases` (a line that is not such a report is skipped).
fn reported_phases(logs: &Path) -> BTreeMap<u32, PhaseTimes> {
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
        out.extend(phases_in(&text));
    }
    out
}

/// The reports (`{"pid": .., "phases": {..}, ..}` lines) in a log's text, by pid.
fn phases_in(text: &str) -> impl Iterator<Item = (u32, PhaseTimes)> + '_ {
    #[derive(serde::Deserialize)]
    struct Report {
        pid: u32,
        phases: PhaseTimes,
    }
    text.lines()
        .filter(|line| line.starts_with('{'))
        .filter_map(|line| serde_json::from_str::<Report>(line).ok())
        .map(|r| (r.pid, r.phases))
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::resources::PhaseTime;

    #[test]
    fn reports_are_found_among_log_lines_by_pid() {
        let text = "2026-01-01T00:00:00Z  INFO agent started\n\
                    {\"frames\":3,\"pid\":42,\"phases\":{\"estimate\":{\"cpu_s\":1.5,\"wall_s\":2.0}}}\n\
                    {not json\n\
                    {\"pid\":7}\n\
                    {\"pid\":43,\"phases\":{}}\n";
        let found: BTreeMap<u32, PhaseTimes> = phases_in(text).collect();
        assert_eq!(found.len(), 2);
        assert_eq!(
            found[&42]["estimate"],
            PhaseTime {
                cpu_s: 1.5,
                wall_s: 2.0
            }
        );
        assert!(found[&43].is_empty());
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
        assert_eq!(r.totals.cpu_s, 10.0);
        assert_eq!(r.totals.world_and_agents_cpu_s, 8.0);
        assert_eq!(r.totals.cpu_ms_per_uav_step, Some(80.0));
        assert_eq!(r.totals.wall_s_per_sim_s, Some(0.5));
    }
}
