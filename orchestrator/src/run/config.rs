//! `fleet run`'s command line: raw clap arguments, and their validation into a [`RunConfig`]
//! whose errors name the flag or scenario key and the accepted range (exit code 2).

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use protocol::scenario::Scenario;
use protocol::service::RunId;
use world_server::server::StepMode;

use fleet_observe::faults::{Fault, FaultKind};

use super::chaos;
use super::hosts::{HostLayout, RemoteHost};
use fleet_observe::viewer::{LiveAddress, ViewConfig};
use fleet_process::usage::{ScenarioArgs, UsageError};
use protocol::variant::Variant;

/// The flags that make a run's scenario, shared by `fleet run` and `fleet host` so that the
/// same flags give every host the same scenario.
#[derive(Debug, Clone, Args)]
pub struct RunScenarioArgs {
    /// The scenario.
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// The guidance variant: a named set of scenario settings, applied after the scenario
    /// file and before `--set`.
    #[arg(long, value_enum, default_value_t = Variant::Paper)]
    pub variant: Variant,
    /// Overrides the scenario's `seed`.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Overrides the scenario's `duration_s`, seconds of simulated time.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Overrides the scenario's `uavs.count`.
    #[arg(long)]
    pub uavs: Option<u32>,
    /// UAVs that ask an external planner for their decisions (docs/python.md):
    /// `external:0,2` or `external:all`; the variant's planner decides when no answer comes
    /// in time (sets `guidance.external_uavs`).
    #[arg(long, value_name = "external:UAVS|external:all")]
    pub planner: Option<PlannerArg>,
}

/// `--planner`: which UAVs ask an external planner.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PlannerArg {
    /// These UAVs.
    External(Vec<u32>),
    /// Every UAV of the fleet.
    ExternalAll,
}

impl std::str::FromStr for PlannerArg {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let usage = || format!("{s:?}: expected external:UAVS (e.g. external:0,2) or external:all");
        let uavs = s.strip_prefix("external:").ok_or_else(usage)?;
        if uavs == "all" {
            return Ok(PlannerArg::ExternalAll);
        }
        uavs.split(',')
            .map(|u| u.trim().parse::<u32>().map_err(|_| usage()))
            .collect::<Result<Vec<_>, _>>()
            .map(PlannerArg::External)
    }
}

impl RunScenarioArgs {
    /// The scenario: the file, then the variant's settings, the `--set`s, and the `--seed`,
    /// `--duration`, `--uavs` and `--planner` flags, which are overrides like any other, so
    /// the scenario's checks name the key and its range.
    pub fn resolve(&self) -> Result<Scenario, UsageError> {
        let mut overrides = self.variant.with_user_overrides(&self.scenario.overrides);
        if let Some(seed) = self.seed {
            overrides.push(format!("seed={seed}"));
        }
        if let Some(d) = self.duration {
            overrides.push(format!("duration_s={d:?}"));
        }
        if let Some(n) = self.uavs {
            overrides.push(format!("uavs.count={n}"));
        }
        let load = |overrides: &[String]| {
            Scenario::load(self.scenario.scenario.as_deref(), overrides)
                .map_err(|e| UsageError(format!("bad scenario: {e}")))
        };
        let uavs = match &self.planner {
            None => return load(&overrides),
            Some(PlannerArg::External(uavs)) => uavs.clone(),
            // The fleet's size is the scenario's: known once it is loaded.
            Some(PlannerArg::ExternalAll) => (0..load(&overrides)?.uavs.count).collect(),
        };
        let list: Vec<String> = uavs.iter().map(u32::to_string).collect();
        overrides.push(format!("guidance.external_uavs=[{}]", list.join(",")));
        load(&overrides)
    }
}

/// `fleet run`.
#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// The scenario and the flags that change it.
    #[command(flatten)]
    pub choice: RunScenarioArgs,
    /// How the world steps: lockstep (deterministic) or realtime.
    #[arg(long, value_enum, default_value_t = ModeArg::Lockstep)]
    pub mode: ModeArg,
    /// Simulated seconds per wall second in realtime mode.
    #[arg(long, default_value_t = 1.0)]
    pub speedup: f64,
    /// A fault to inject (repeatable): `kill:UAV@S` (SIGKILL at S seconds of simulated
    /// time), `restart:UAV@S` (start it again), `pause:UAV@S+D` (SIGSTOP at S, SIGCONT D
    /// seconds of wall time later).
    #[arg(long = "fault", value_name = "KIND:UAV@S[+D]")]
    pub faults: Vec<Fault>,
    /// Injects a random schedule of kills (each restarted 1 to 5 s later), restarts and
    /// pauses drawn from this seed, some of them on the token holder at guidance steps; on
    /// top of any `--fault`.
    #[arg(long, value_name = "SEED")]
    pub chaos: Option<u64>,
    /// How many faults `--chaos` injects (a kill and its restart are two; default: 6 per
    /// minute of simulated time).
    #[arg(long, value_name = "N", requires = "chaos")]
    pub chaos_faults: Option<u32>,
    /// Spreads the processes over this many simulated hosts: host 0 runs the world-server,
    /// the observer and the first agents, the others the rest of the agents, each in its own
    /// iceoryx2 domain; a Zenoh bridge per host joins them over loopback QUIC (TLS 1.3).
    #[arg(long, default_value_t = 1, conflicts_with = "remote")]
    pub hosts: u16,
    /// Agents that run on another machine (repeatable), e.g. `h1=2,3`: this machine runs the
    /// world-server, the observer and the other agents, and `fleet host --host h1 --agents
    /// 2,3` on that machine runs these. Needs `--listen`, `--tls` and `--run-id`.
    #[arg(long, value_name = "NAME=UAVS", requires_all = ["listen", "tls", "run_id"])]
    pub remote: Vec<RemoteHost>,
    /// Where this machine's bridge listens for the other hosts, e.g. `quic/0.0.0.0:7447`
    /// (`tls/...` for TLS over TCP; default with `--hosts`: a free loopback UDP port).
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Option<String>,
    /// Directory of the fleet's certificates (`fleet certs`): `ca.pem` and this host's
    /// `h0.pem` and `h0.key` (default with `--hosts`: made for the run in `OUT/certs`).
    #[arg(long, value_name = "DIR")]
    pub tls: Option<PathBuf>,
    /// Simulated hosts talk over plain loopback TCP, without TLS nor access control (the
    /// issue's "Zenoh over loopback TCP"; tests compare it with the secure default).
    #[arg(long, hide = true, conflicts_with_all = ["tls", "remote"])]
    pub insecure_links: bool,
    /// Output directory (default: `runs/<UTC timestamp>`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Exit with code 1 when a guarantee violation was seen.
    #[arg(long)]
    pub strict: bool,
    /// Run id, prefix of every service and shared-memory file (default: generated). A run
    /// with `--remote` hosts needs one: `fleet host` joins the run by it.
    #[arg(long)]
    pub run_id: Option<RunId>,
    /// Records the run for Foxglove into this MCAP file (the city, the UAVs, the sets, the
    /// map, the plans, the metrics, the true cars and the shown UAV's camera).
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,
    /// Serves the run live to Foxglove over WebSocket, on 127.0.0.1:8765 unless given
    /// (`0`: any free port; the address is printed); connect Foxglove to `ws://HOST:PORT`.
    #[arg(long, value_name = "[HOST:]PORT", num_args = 0..=1, default_missing_value = "8765")]
    pub live: Option<LiveAddress>,
    /// The UAV whose sets and camera `--record` and `--live` show (the lowest one measured
    /// stands in at a step without its estimate).
    #[arg(long, value_name = "UAV", default_value_t = 0)]
    pub show_uav: u32,
}

/// `--mode`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// The world waits for every live agent and the observer at each step.
    Lockstep,
    /// The world advances every `T / speedup` of wall time.
    Realtime,
}

/// A validated `fleet run`.
#[derive(Clone, Debug)]
pub struct RunConfig {
    /// The resolved scenario (file, `--set`, then `--seed/--duration/--uavs`).
    pub scenario: Scenario,
    /// How the world steps.
    pub mode: StepMode,
    /// Faults in the order they apply (by time; at the same time a kill, then a restart,
    /// then a pause): the `--fault`s and the `--chaos` schedule.
    pub faults: Vec<Fault>,
    /// Output directory.
    pub out: PathBuf,
    /// Exit 1 on a violation.
    pub strict: bool,
    /// The run id (generated when not given).
    pub run_id: RunId,
    /// Whether to draw a progress bar (else a log line every ~10 %).
    pub progress_bar: bool,
    /// The guidance variant the scenario was built with.
    pub variant: Variant,
    /// The `--chaos` seed, if the faults include a chaos schedule.
    pub chaos_seed: Option<u64>,
    /// Where the processes run.
    pub layout: HostLayout,
    /// Where host 0's bridge listens (`None`: a free loopback port, on simulated hosts).
    pub listen: Option<String>,
    /// The fleet's certificates (`None`: made for the run, on simulated hosts).
    pub tls: Option<PathBuf>,
    /// Plain TCP between simulated hosts (tests).
    pub insecure_links: bool,
    /// What the run is shown to (Foxglove).
    pub view: ViewConfig,
}

impl RunArgs {
    /// Loads the scenario, applies the overrides, checks that the world builds from it, and
    /// checks the faults against the fleet and the run's duration.
    pub fn validate(&self) -> Result<RunConfig, UsageError> {
        let scenario = self.choice.resolve()?;
        // A city its blocks cannot hold, or an imported scene that is missing or does not fit
        // the scenario, is the user's to fix: said here, before any process starts.
        world_server::World::new(&scenario).map_err(|e| UsageError(e.to_string()))?;
        let mode = match self.mode {
            ModeArg::Lockstep => StepMode::Lockstep,
            ModeArg::Realtime => {
                if !(self.speedup.is_finite() && self.speedup > 0.0) {
                    return Err(UsageError(format!(
                        "--speedup {}: must be a positive finite number",
                        self.speedup
                    )));
                }
                StepMode::Realtime {
                    speedup: self.speedup,
                }
            }
        };
        let mut faults = check_faults(&self.faults, &scenario)?;
        if let Some(seed) = self.chaos {
            let asked = self.chaos_faults;
            let count = asked.unwrap_or_else(|| chaos::default_count(&scenario));
            let drawn = chaos::schedule(seed, count, &scenario, &faults);
            if let Some(asked) = asked
                && (drawn.len() as u32) < asked
            {
                return Err(UsageError(format!(
                    "--chaos-faults {asked}: only {} fit in this run (seed {seed}, duration_s = \
                     {}, {} UAVs; faults start after the first guidance period, end {} s before \
                     the end and do not overlap on a UAV)",
                    drawn.len(),
                    scenario.duration_s,
                    scenario.uavs.count,
                    chaos::end_margin_s(&scenario)
                )));
            }
            faults.extend(drawn);
            // The schedule is built around the explicit faults; this checks it is consistent.
            faults = check_faults(&faults, &scenario)?;
        }
        let layout = if self.remote.is_empty() {
            HostLayout::simulated(self.hosts, scenario.uavs.count)
        } else {
            HostLayout::with_remotes(scenario.uavs.count, &self.remote)
        }
        .map_err(UsageError)?;
        if self.show_uav >= scenario.uavs.count {
            return Err(UsageError(format!(
                "--show-uav {}: UAV outside the fleet (UAVs 0..={})",
                self.show_uav,
                scenario.uavs.count.saturating_sub(1)
            )));
        }
        if let Some(record) = &self.record
            && record.is_dir()
        {
            return Err(UsageError(format!(
                "--record {}: a directory; give the recording's file name",
                record.display()
            )));
        }
        if let Some(f) = faults.iter().find(|f| !layout.is_here(f.uav)) {
            return Err(UsageError(format!(
                "--fault {f}: UAV {} runs on another machine; faults apply to this machine's \
                 agents",
                f.uav
            )));
        }
        Ok(RunConfig {
            scenario,
            mode,
            faults,
            out: self.out.clone().unwrap_or_else(|| default_out_dir("")),
            strict: self.strict,
            run_id: self.run_id.clone().unwrap_or_else(|| new_run_id(0)),
            progress_bar: std::io::IsTerminal::is_terminal(&std::io::stderr()),
            variant: self.choice.variant,
            chaos_seed: self.chaos,
            layout,
            listen: self.listen.clone(),
            tls: self.tls.clone(),
            insecure_links: self.insecure_links,
            view: ViewConfig {
                record: self.record.clone(),
                live: self.live.clone(),
                uav: self.show_uav,
            },
        })
    }
}

/// Checks every fault against the fleet and the run, that a restart follows a kill of the
/// same UAV and that a paused UAV is running; returns them in the order they apply (by time;
/// at the same time a kill, then a restart, then a pause).
pub fn check_faults(faults: &[Fault], scenario: &Scenario) -> Result<Vec<Fault>, UsageError> {
    let count = scenario.uavs.count;
    let duration = scenario.duration_s;
    for f in faults {
        if f.uav >= count {
            return Err(UsageError(format!(
                "--fault {f}: UAV {} is outside the fleet (UAVs 0..={})",
                f.uav,
                count.saturating_sub(1)
            )));
        }
        if !(f.at_s >= 0.0 && f.at_s < duration) {
            return Err(UsageError(format!(
                "--fault {f}: time {} s is outside the run (0 <= time < duration_s = {duration})",
                f.at_s
            )));
        }
    }
    let mut ordered = faults.to_vec();
    ordered.sort_by(|a, b| a.at_s.total_cmp(&b.at_s).then(a.kind.cmp(&b.kind)));
    let mut alive = vec![true; count as usize];
    for f in &ordered {
        let slot = &mut alive[f.uav as usize];
        match (f.kind, *slot) {
            (FaultKind::Kill, true) => *slot = false,
            (FaultKind::Restart, false) => *slot = true,
            (FaultKind::Kill, false) => {
                return Err(UsageError(format!(
                    "--fault {f}: UAV {} is already killed then; restart it first",
                    f.uav
                )));
            }
            (FaultKind::Restart, true) => {
                return Err(UsageError(format!(
                    "--fault {f}: UAV {} is running then; a restart must follow a kill",
                    f.uav
                )));
            }
            (FaultKind::Pause, true) => {}
            (FaultKind::Pause, false) => {
                return Err(UsageError(format!(
                    "--fault {f}: UAV {} is killed then; only a running agent can be paused",
                    f.uav
                )));
            }
        }
    }
    Ok(ordered)
}

/// `runs/<prefix><UTC timestamp>`, e.g. `runs/20250101T120000Z` or
/// `runs/sweep-20250101T120000Z`.
pub fn default_out_dir(prefix: &str) -> PathBuf {
    let stamp: String = fleet_process::clock::utc_now_rfc3339()
        .chars()
        .filter(|c| !matches!(c, '-' | ':'))
        .collect();
    PathBuf::from("runs").join(format!("{prefix}{stamp}"))
}

/// A short run id unique on this machine: `r`, the Unix time in seconds, the process id and
/// a sequence number (a sweep starts several runs in one process).
pub fn new_run_id(sequence: u32) -> RunId {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let id = format!("r{secs}-{}-{sequence}", std::process::id());
    // Digits, 'r' and '-' within 40 characters always make a valid id.
    RunId::new(&id).unwrap_or_else(|e| unreachable!("generated run id {id:?} is invalid: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser as _;
    use fleet_observe::faults::FaultOrigin;

    fn scenario() -> Scenario {
        Scenario::load(None, &["duration_s=60".into(), "uavs.count=2".into()]).unwrap()
    }

    #[test]
    fn planner_flags_name_the_asking_uavs() {
        assert_eq!("external:0,2".parse(), Ok(PlannerArg::External(vec![0, 2])));
        assert_eq!("external:all".parse(), Ok(PlannerArg::ExternalAll));
        for bad in ["paper", "external:", "external:a", "external:1,,2"] {
            assert!(bad.parse::<PlannerArg>().is_err(), "{bad}");
        }
        let args = |planner: &str| {
            crate::cli::Cli::try_parse_from(["fleet", "run", "--uavs", "3", "--planner", planner])
                .map(|cli| match cli.command {
                    crate::cli::FleetCommand::Run(run) => run.choice.resolve(),
                    _ => unreachable!("a run"),
                })
                .unwrap()
        };
        let all = args("external:all").unwrap();
        assert_eq!(all.guidance.external_uavs, [0, 1, 2]);
        assert_eq!(args("external:1").unwrap().guidance.external_uavs, [1]);
        let e = args("external:3").unwrap_err();
        assert!(e.0.contains("guidance.external_uavs"), "{e}");
    }

    #[test]
    fn faults_are_checked_against_the_fleet_the_run_and_each_other() {
        let s = scenario();
        let f = |t: &str| t.parse::<Fault>().unwrap();
        let e = check_faults(&[f("kill:2@10")], &s).unwrap_err();
        assert!(e.0.contains("UAV 2 is outside the fleet"), "{e}");
        let e = check_faults(&[f("kill:1@60")], &s).unwrap_err();
        assert!(e.0.contains("outside the run"), "{e}");
        let e = check_faults(&[f("restart:1@10")], &s).unwrap_err();
        assert!(e.0.contains("must follow a kill"), "{e}");
        let ok = check_faults(&[f("restart:1@20"), f("kill:1@20"), f("kill:0@5")], &s).unwrap();
        assert_eq!(ok, vec![f("kill:0@5"), f("kill:1@20"), f("restart:1@20")]);
        let e = check_faults(&[f("kill:1@10"), f("pause:1@12+3")], &s).unwrap_err();
        assert!(
            e.0.contains("--fault pause:1@12+3: UAV 1 is killed then"),
            "{e}"
        );
        let e = check_faults(&[f("pause:0@60+1")], &s).unwrap_err();
        assert!(e.0.contains("outside the run"), "{e}");
        let ok = check_faults(
            &[
                f("pause:1@20+2"),
                f("restart:1@20"),
                f("kill:1@10"),
                f("pause:0@3+30"),
            ],
            &s,
        )
        .unwrap();
        assert_eq!(
            ok,
            vec![
                f("pause:0@3+30"),
                f("kill:1@10"),
                f("restart:1@20"),
                f("pause:1@20+2")
            ]
        );
    }

    #[test]
    fn dedicated_flags_override_the_scenario_and_are_range_checked() {
        let args = |extra: &[&str]| {
            use clap::Parser;
            #[derive(Parser)]
            struct Wrap {
                #[command(flatten)]
                run: RunArgs,
            }
            let mut argv = vec!["fleet"];
            argv.extend_from_slice(extra);
            Wrap::try_parse_from(argv).unwrap().run
        };
        let c = args(&["--seed", "9", "--duration", "12", "--uavs", "3"])
            .validate()
            .unwrap();
        assert_eq!(
            (
                c.scenario.seed,
                c.scenario.duration_s,
                c.scenario.uavs.count
            ),
            (9, 12.0, 3)
        );
        assert_eq!(c.mode, StepMode::Lockstep);
        assert_eq!(c.variant, Variant::Paper);
        assert_eq!(c.scenario.guidance, Scenario::default().guidance);
        let c = args(&["--variant", "setfleet", "--set", "guidance.beam_width=3"])
            .validate()
            .unwrap();
        assert_eq!(c.variant, Variant::Setfleet);
        assert_eq!(
            c.scenario.guidance.planner,
            protocol::scenario::Planner::Setfleet
        );
        assert_eq!(
            c.scenario.guidance.setfleet.beam_width, 3,
            "--set applies after the variant"
        );
        let e = args(&["--uavs", "0"]).validate().unwrap_err();
        assert!(e.0.contains("uavs.count"), "{e}");
        // The largest fleet the protocol carries, and one more.
        let c = args(&["--uavs", "64", "--show-uav", "63"])
            .validate()
            .unwrap();
        assert_eq!(c.scenario.uavs.count, 64);
        let e = args(&["--uavs", "65"]).validate().unwrap_err();
        assert!(e.0.contains("uavs.count") && e.0.contains("<= 64"), "{e}");
        let e = args(&["--uavs", "2", "--fault", "kill:3@1"])
            .validate()
            .unwrap_err();
        assert!(e.0.contains("--fault kill:3@1"), "{e}");
    }

    #[test]
    fn chaos_adds_its_schedule_to_the_explicit_faults() {
        use clap::Parser;
        #[derive(Parser)]
        struct Wrap {
            #[command(flatten)]
            run: RunArgs,
        }
        let args = |extra: &[&str]| {
            let mut argv = vec!["fleet", "--duration", "60", "--uavs", "3"];
            argv.extend_from_slice(extra);
            Wrap::try_parse_from(argv).map(|w| w.run)
        };
        let plain = args(&["--fault", "pause:1@10+2"])
            .unwrap()
            .validate()
            .unwrap();
        assert_eq!(plain.faults.len(), 1);
        assert_eq!(plain.chaos_seed, None);
        let c = args(&["--fault", "pause:1@10+2", "--chaos", "4"])
            .unwrap()
            .validate()
            .unwrap();
        assert_eq!(c.chaos_seed, Some(4));
        // 6 per minute by default, besides the explicit one.
        assert_eq!(c.faults.len(), 7, "{:?}", c.faults);
        let chaos: Vec<&Fault> = c
            .faults
            .iter()
            .filter(|f| f.origin == FaultOrigin::Chaos)
            .collect();
        assert_eq!(chaos.len(), 6);
        assert!(c.faults.windows(2).all(|w| w[0].at_s <= w[1].at_s));
        let again = args(&["--fault", "pause:1@10+2", "--chaos", "4"])
            .unwrap()
            .validate()
            .unwrap();
        assert_eq!(c.faults, again.faults, "the same seed, the same schedule");
        let n = args(&["--chaos", "4", "--chaos-faults", "11"])
            .unwrap()
            .validate()
            .unwrap();
        assert_eq!(n.faults.len(), 11);
        let e = args(&["--chaos", "4", "--chaos-faults", "500"])
            .unwrap()
            .validate()
            .unwrap_err();
        assert!(e.0.contains("--chaos-faults 500: only"), "{e}");
        assert!(
            args(&["--chaos-faults", "3"]).is_err(),
            "--chaos-faults needs --chaos"
        );
    }

    #[test]
    fn generated_run_ids_are_valid_and_distinct() {
        assert_ne!(new_run_id(0), new_run_id(1));
        assert!(new_run_id(u32::MAX).as_str().len() <= RunId::MAX_LEN);
    }
}
