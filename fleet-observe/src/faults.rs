//! The faults a run injects into its agents, as the command line writes them ([`Fault`],
//! `--fault kill:1@30`) and as `summary.json` reports what became of them ([`FaultRecord`]).
//! The run schedules and applies them (`orchestrator::run::faults`); the summary counts
//! restarts and resyncs from the records.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// What a fault does.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FaultKind {
    /// SIGKILL the agent's process.
    Kill,
    /// Start the agent again (same id).
    Restart,
    /// SIGSTOP the agent's process, and SIGCONT it after a wall-clock delay.
    Pause,
}

impl FaultKind {
    /// The name on the command line and in `summary.json`.
    pub fn name(self) -> &'static str {
        match self {
            FaultKind::Kill => "kill",
            FaultKind::Restart => "restart",
            FaultKind::Pause => "pause",
        }
    }
}

/// Where a fault comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FaultOrigin {
    /// A `--fault` of the command line.
    Explicit,
    /// The `--chaos` schedule.
    Chaos,
}

/// A fault to inject: `kind` on UAV `uav` once simulated time reaches `at_s`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fault {
    /// What to do.
    pub kind: FaultKind,
    /// The UAV.
    pub uav: u32,
    /// Simulated time, seconds.
    pub at_s: f64,
    /// How long a pause lasts, seconds of wall time (`Some` exactly for a pause): the world
    /// is simulated, but a stopped process is stopped in real time.
    pub pause_s: Option<f64>,
    /// A `--fault` or the `--chaos` schedule.
    pub origin: FaultOrigin,
}

/// Why a `--fault` value could not be read.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error(
    "{0:?}: expected kill:UAV@S, restart:UAV@S or pause:UAV@S+D (S seconds of simulated time, \
     D seconds of wall time), e.g. kill:1@30 or pause:1@30+8"
)]
pub struct FaultParseError(String);

impl FromStr for Fault {
    type Err = FaultParseError;

    fn from_str(text: &str) -> Result<Fault, FaultParseError> {
        let bad = || FaultParseError(text.to_owned());
        let (kind, rest) = text.split_once(':').ok_or_else(bad)?;
        let kind = match kind.trim() {
            "kill" => FaultKind::Kill,
            "restart" => FaultKind::Restart,
            "pause" => FaultKind::Pause,
            _ => return Err(bad()),
        };
        let (uav, when) = rest.split_once('@').ok_or_else(bad)?;
        let uav = uav.trim().parse().map_err(|_| bad())?;
        let (at, pause) = match kind {
            FaultKind::Pause => {
                let (at, pause) = when.split_once('+').ok_or_else(bad)?;
                (at, Some(pause))
            }
            FaultKind::Kill | FaultKind::Restart => (when, None),
        };
        let at_s: f64 = at.trim().parse().map_err(|_| bad())?;
        if !at_s.is_finite() {
            return Err(bad());
        }
        let pause_s = match pause {
            Some(p) => {
                let p: f64 = p.trim().parse().map_err(|_| bad())?;
                if !(p.is_finite() && p > 0.0) {
                    return Err(bad());
                }
                Some(p)
            }
            None => None,
        };
        Ok(Fault {
            kind,
            uav,
            at_s,
            pause_s,
            origin: FaultOrigin::Explicit,
        })
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}@{}", self.kind.name(), self.uav, self.at_s)?;
        if let Some(p) = self.pause_s {
            write!(f, "+{p}")?;
        }
        Ok(())
    }
}

/// One fault as injected.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FaultRecord {
    /// `kill`, `restart` or `pause`.
    pub kind: FaultKind,
    /// The UAV.
    pub uav: u32,
    /// The time asked for, seconds of simulated time.
    pub at_s: f64,
    /// How long a pause was asked to last, seconds of wall time (`null` for other kinds).
    pub pause_s: Option<f64>,
    /// `explicit` (a `--fault`) or `chaos` (the `--chaos` schedule).
    pub origin: FaultOrigin,
    /// The step at which it was applied (`null` if the run ended first).
    pub applied_at_step: Option<u64>,
    /// The simulated time of that step, seconds.
    pub applied_at_s: Option<f64>,
    /// Whether it took effect (a kill found a running agent, a restart started one, a pause
    /// stopped a running agent that was not stopped already).
    pub effective: bool,
    /// A pause: the step at which SIGCONT was sent (the last step the observer had
    /// acknowledged then); `null` if the agent died or was killed while stopped.
    pub resumed_at_step: Option<u64>,
    /// A restart or pause: steps until the agent's estimates were back (see the module
    /// docs); `null` if they never were, or for a kill.
    pub resync_steps: Option<u64>,
}

/// Effective restarts of `uav` among `records`.
pub fn restarts(records: &[FaultRecord], uav: u32) -> u64 {
    records
        .iter()
        .filter(|r| r.uav == uav && r.kind == FaultKind::Restart && r.effective)
        .count() as u64
}

/// The worst and the mean resync over the `records` that have one (`None` when none has).
pub fn resync_max_mean(records: &[FaultRecord]) -> (Option<u64>, Option<f64>) {
    let all: Vec<u64> = records.iter().filter_map(|r| r.resync_steps).collect();
    let max = all.iter().copied().max();
    let mean = (!all.is_empty()).then(|| all.iter().sum::<u64>() as f64 / all.len() as f64);
    (max, mean)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_parse_and_print_back() {
        let f: Fault = "kill:1@30".parse().unwrap();
        assert_eq!(
            f,
            Fault {
                kind: FaultKind::Kill,
                uav: 1,
                at_s: 30.0,
                pause_s: None,
                origin: FaultOrigin::Explicit,
            }
        );
        assert_eq!(f.to_string(), "kill:1@30");
        assert_eq!("restart:0@2.5".parse::<Fault>().unwrap().at_s, 2.5);
        let p: Fault = "pause:2@12.5+8".parse().unwrap();
        assert_eq!(
            (p.kind, p.uav, p.at_s, p.pause_s),
            (FaultKind::Pause, 2, 12.5, Some(8.0))
        );
        assert_eq!(p.to_string(), "pause:2@12.5+8");
        assert_eq!(
            " pause : 0 @ 1 + 0.5 ".parse::<Fault>().unwrap().pause_s,
            Some(0.5)
        );
        for bad in [
            "kill",
            "kill:1",
            "stop:1@3",
            "kill:x@3",
            "kill:1@nan",
            "kill:-1@3",
            "kill:1@3+2",
            "restart:1@3+2",
            "pause:1@3",
            "pause:1@3+",
            "pause:1@+2",
            "pause:1@3+0",
            "pause:1@3+-1",
            "pause:1@3+inf",
            "pause:1@3+2+1",
        ] {
            let e = bad.parse::<Fault>().unwrap_err().to_string();
            for form in ["kill:UAV@S", "restart:UAV@S", "pause:UAV@S+D"] {
                assert!(e.contains(form), "{bad}: {e}");
            }
        }
    }
}
