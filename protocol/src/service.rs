//! Run ids and every iceoryx2 service name, built here and nowhere else.
//!
//! | service | from -> to |
//! |---|---|
//! | [`cvs`] `{run}/uav/{i}/cvs` | world-server -> agent i and observers |
//! | [`cmd`] `{run}/uav/{i}/cmd` | agent i -> world-server |
//! | [`estimate`] `{run}/uav/{i}/estimate` | agent i -> peers and observers |
//! | [`guidance`] `{run}/guidance` | agent -> agents (the token) |
//! | [`truth`] `{run}/truth` | world-server -> observers |
//! | [`agent_wake`] `{run}/uav/{i}/wake` | anyone sending to agent i -> agent i (event) |
//! | [`world_wake`] `{run}/world/wake` | agents -> world-server (event) |
//! | [`observer_wake`] `{run}/observer/wake` | world and agents -> observers (event) |
//! | [`observer_ack`] `{run}/observer/ack` | observer -> world-server (lockstep ack) |
//! | [`plan`] `{run}/uav/{i}/plan` | agent i -> an external planner (request-response) |
//! | [`planner_wake`] `{run}/planner/wake` | agents -> external planners (event, id = UAV) |

use std::fmt;

use iceoryx2::prelude::ServiceName;

/// Start of every setfleet iceoryx2 file name, before the run id (iceoryx2's own files start
/// with `iox2_`).
pub const FILE_PREFIX: &str = "iox2_sf_";

/// Why a run id was refused.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum RunIdError {
    /// Empty or longer than [`RunId::MAX_LEN`].
    #[error("run id must be 1 to {max} characters, got {0}", max = RunId::MAX_LEN)]
    Length(usize),
    /// A character other than ASCII letters, digits, '-' and '_'.
    #[error("run id may hold only ASCII letters, digits, '-' and '_', got {0:?}")]
    Character(char),
}

/// The id of one run: prefixes every service and every shared-memory file of the run, so runs
/// and tests never see each other.
///
/// A run spread over several hosts has one iceoryx2 *domain* per host. On real machines the
/// domains are apart anyway; hosts simulated on one machine ([`RunId::in_domain`]) keep
/// theirs apart by the file prefix alone: host `k`'s files start with
/// `iox2_sf_{run}.h{k}_` (a run id never holds a `.`), so its processes share no service,
/// node or file with the other hosts' and meet them only through the bridge. Service names, the run tag and the text of
/// the id are the same on every host.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct RunId {
    id: String,
    domain: Option<u16>,
}

impl RunId {
    /// Longest accepted id.
    pub const MAX_LEN: usize = 40;

    /// Validates a run id.
    pub fn new(id: &str) -> Result<Self, RunIdError> {
        if id.is_empty() || id.len() > Self::MAX_LEN {
            return Err(RunIdError::Length(id.len()));
        }
        if let Some(c) = id
            .chars()
            .find(|c| !(c.is_ascii_alphanumeric() || *c == '-' || *c == '_'))
        {
            return Err(RunIdError::Character(c));
        }
        Ok(Self {
            id: id.to_owned(),
            domain: None,
        })
    }

    /// The same run in the iceoryx2 domain of simulated host `host` (see the type's docs).
    pub fn in_domain(&self, host: u16) -> RunId {
        RunId {
            id: self.id.clone(),
            domain: Some(host),
        }
    }

    /// The simulated host whose domain this is, if any.
    pub fn domain(&self) -> Option<u16> {
        self.domain
    }

    /// The id as text.
    pub fn as_str(&self) -> &str {
        &self.id
    }

    /// A 64-bit tag (FNV-1a of the id) stamped on every message, so a message of another run
    /// is recognised and dropped.
    pub fn tag(&self) -> u64 {
        self.id.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
            (h ^ b as u64).wrapping_mul(0x100_0000_01b3)
        })
    }

    /// Prefix of every iceoryx2 file of this run: [`FILE_PREFIX`], the id, `_`; in a
    /// simulated host's domain, `.h{host}` comes before the `_`.
    pub fn file_prefix(&self) -> String {
        format!("{FILE_PREFIX}{}_", self.domain_id())
    }

    /// The id followed by the domain, as file names carry it: `{id}` or `{id}.h{host}`.
    fn domain_id(&self) -> String {
        match self.domain {
            None => self.id.clone(),
            Some(host) => format!("{}.h{host}", self.id),
        }
    }

    /// Reads back the part of a file name between [`FILE_PREFIX`] and `_`: `{id}` or
    /// `{id}.h{host}`, as [`RunId::file_prefix`] writes it.
    pub fn from_domain_id(text: &str) -> Option<RunId> {
        match text.split_once(".h") {
            None => RunId::new(text).ok(),
            Some((id, host)) => {
                let host: u16 = host.parse().ok()?;
                (text.ends_with(&format!(".h{host}")))
                    .then(|| RunId::new(id).ok().map(|r| r.in_domain(host)))
                    .flatten()
            }
        }
    }
}

impl fmt::Display for RunId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.id)
    }
}

impl std::str::FromStr for RunId {
    type Err = RunIdError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::new(s)
    }
}

fn name(s: String) -> ServiceName {
    // Names built from a validated run id and numbers are always valid service names.
    ServiceName::new(&s).unwrap_or_else(|e| unreachable!("invalid service name {s:?}: {e:?}"))
}

/// `{run}/uav/{i}/cvs`: frames for UAV `i`.
pub fn cvs(run: &RunId, uav: u32) -> ServiceName {
    name(format!("{run}/uav/{uav}/cvs"))
}

/// `{run}/uav/{i}/cmd`: commands and lockstep acks from agent `i`.
pub fn cmd(run: &RunId, uav: u32) -> ServiceName {
    name(format!("{run}/uav/{uav}/cmd"))
}

/// `{run}/uav/{i}/estimate`: agent `i`'s estimates.
pub fn estimate(run: &RunId, uav: u32) -> ServiceName {
    name(format!("{run}/uav/{uav}/estimate"))
}

/// `{run}/guidance`: the round-robin token.
pub fn guidance(run: &RunId) -> ServiceName {
    name(format!("{run}/guidance"))
}

/// `{run}/truth`: ground truth for observers.
pub fn truth(run: &RunId) -> ServiceName {
    name(format!("{run}/truth"))
}

/// `{run}/uav/{i}/wake`: event that wakes agent `i` (frame, peer estimate or token arrived).
pub fn agent_wake(run: &RunId, uav: u32) -> ServiceName {
    name(format!("{run}/uav/{uav}/wake"))
}

/// `{run}/world/wake`: event that wakes the world-server (a command arrived).
pub fn world_wake(run: &RunId) -> ServiceName {
    name(format!("{run}/world/wake"))
}

/// `{run}/observer/wake`: event that wakes observers (truth or an estimate was published).
pub fn observer_wake(run: &RunId) -> ServiceName {
    name(format!("{run}/observer/wake"))
}

/// `{run}/observer/ack`: an observer's lockstep acks, for a world that waits for it.
pub fn observer_ack(run: &RunId) -> ServiceName {
    name(format!("{run}/observer/ack"))
}

/// `{run}/uav/{i}/plan`: agent `i` asks an external planner for its decisions
/// ([`crate::plan`]).
pub fn plan(run: &RunId, uav: u32) -> ServiceName {
    name(format!("{run}/uav/{uav}/plan"))
}

/// `{run}/planner/wake`: wakes external planners; the event id is the asking UAV.
pub fn planner_wake(run: &RunId) -> ServiceName {
    name(format!("{run}/planner/wake"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_prefixed_by_the_run() {
        let run = RunId::new("t-1").unwrap();
        assert_eq!(cvs(&run, 3).as_str(), "t-1/uav/3/cvs");
        assert_eq!(guidance(&run).as_str(), "t-1/guidance");
        assert!(RunId::new("a/b").is_err());
        assert!(RunId::new("").is_err());
        assert_ne!(
            RunId::new("a").unwrap().tag(),
            RunId::new("b").unwrap().tag()
        );
    }

    #[test]
    fn a_domain_changes_the_files_only() {
        let run = RunId::new("t-1").unwrap();
        let host = run.in_domain(2);
        assert_eq!(host.domain(), Some(2));
        assert_eq!(host.tag(), run.tag());
        assert_eq!(host.to_string(), "t-1");
        assert_eq!(estimate(&host, 1).as_str(), estimate(&run, 1).as_str());
        assert_eq!(host.file_prefix(), "iox2_sf_t-1.h2_");
        assert_ne!(host, run);
        assert_eq!(RunId::from_domain_id("t-1.h2"), Some(host));
        assert_eq!(RunId::from_domain_id("t-1"), Some(run));
        for bad in ["t-1.h", "t-1.h02", "t-1.hx", "t.1", "t-1.h2.h3", ""] {
            assert_eq!(RunId::from_domain_id(bad), None, "{bad}");
        }
    }
}
