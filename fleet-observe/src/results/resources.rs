//! Where a run's time and memory went, per process: the `resources` section of
//! `summary.json` ([`Resources`]). The run measures them (`orchestrator::run::resources`);
//! every value depends on the machine and its load, so the whole section is left out when
//! two runs are compared for determinism.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// One process of the run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ProcessResources {
    /// `orchestrator`, `world`, `agent` or `bridge`.
    pub role: String,
    /// An agent's UAV.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uav: Option<u32>,
    /// An agent's process number among its UAV's (1, then 2 after a restart, ...).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub incarnation: Option<u32>,
    /// How it ended: `exit N`, `signal N` (an agent killed by a fault: `signal 9`), or
    /// `running` for the orchestrator.
    pub end: String,
    /// User plus system CPU time, seconds (`null` when it could not be read).
    pub cpu_s: Option<f64>,
    /// User CPU time, seconds.
    pub user_s: Option<f64>,
    /// System CPU time, seconds.
    pub system_s: Option<f64>,
    /// Peak resident memory, MiB.
    pub peak_rss_mb: Option<f64>,
    /// Where `peak_rss_mb` comes from (`null` when there is none).
    pub peak_rss_source: Option<PeakSource>,
    /// CPU seconds per phase, as the process measured it (empty if it reported none).
    pub phases: BTreeMap<String, f64>,
    /// Wall seconds per phase (the waits' length is here).
    pub phases_wall_s: BTreeMap<String, f64>,
    /// What an agent's external planner did, as the agent reported it at exit (decisions,
    /// fallbacks by reason, the time from request to answer and its overhead, ms;
    /// docs/python.md); absent for the other processes and an agent killed before its report.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub external: Option<serde_json::Value>,
}

/// Where a process's peak resident memory was read ([`ProcessResources::peak_rss_source`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PeakSource {
    /// `vmhwm`: the process's own high-water mark (`VmHWM`), which it reported at its end
    /// (the world-server and the agents).
    Vmhwm,
    /// `rusage`: the kernel's account (`ru_maxrss`): the orchestrator's own, and a child
    /// that reported none (a killed agent, a bridge), whose figure includes the memory of the
    /// `fleet` process that spawned it.
    Rusage,
}

/// Every process of the run and the totals.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Resources {
    /// The orchestrator, the world-server, then the agents by UAV and incarnation.
    pub processes: Vec<ProcessResources>,
    /// Sums over the processes.
    pub totals: ResourceTotals,
}

/// Sums over a run's processes.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ResourceTotals {
    /// CPU seconds of every process whose usage was read.
    pub cpu_s: f64,
    /// CPU seconds of the world-server and the agents.
    pub world_and_agents_cpu_s: f64,
    /// `world_and_agents_cpu_s` in milliseconds per UAV and step (`null` without steps).
    pub cpu_ms_per_uav_step: Option<f64>,
    /// Wall seconds per simulated second (`null` without steps).
    pub wall_s_per_sim_s: Option<f64>,
    /// The agents' CPU seconds per phase, summed over agents.
    pub agent_phases: BTreeMap<String, f64>,
    /// The agents' wall seconds per phase, summed over agents.
    pub agent_phases_wall_s: BTreeMap<String, f64>,
}

/// The size of a run, for the totals.
#[derive(Clone, Copy, Debug, Default)]
pub struct RunSize {
    /// UAVs in the fleet.
    pub uavs: u32,
    /// Steps measured.
    pub steps: u64,
    /// Simulated seconds.
    pub sim_s: f64,
    /// Wall seconds.
    pub wall_s: f64,
}

impl ResourceTotals {
    /// The totals of `processes`, a run of `run`'s size.
    pub fn of(processes: &[ProcessResources], run: RunSize) -> ResourceTotals {
        let cpu = |p: &&ProcessResources| p.cpu_s.unwrap_or(0.0);
        let cpu_s = processes.iter().map(|p| cpu(&p)).sum();
        let world_and_agents_cpu_s: f64 = processes
            .iter()
            .filter(|p| p.role != "orchestrator")
            .map(|p| cpu(&p))
            .sum();
        let uav_steps = f64::from(run.uavs) * run.steps as f64;
        let mut agent_phases = BTreeMap::new();
        let mut agent_phases_wall_s = BTreeMap::new();
        for p in processes.iter().filter(|p| p.role == "agent") {
            for (name, s) in &p.phases {
                *agent_phases.entry(name.clone()).or_insert(0.0) += s;
            }
            for (name, s) in &p.phases_wall_s {
                *agent_phases_wall_s.entry(name.clone()).or_insert(0.0) += s;
            }
        }
        ResourceTotals {
            cpu_s,
            world_and_agents_cpu_s,
            cpu_ms_per_uav_step: (uav_steps > 0.0)
                .then(|| world_and_agents_cpu_s * 1e3 / uav_steps),
            wall_s_per_sim_s: (run.sim_s > 0.0).then(|| run.wall_s / run.sim_s),
            agent_phases,
            agent_phases_wall_s,
        }
    }
}
