//! Every Zenoh key expression of a run, built and read here and nowhere else.
//!
//! | key | carries | published by |
//! |---|---|---|
//! | `setfleet/{run}/uav/{i}/cvs` | UAV `i`'s frames | the world host |
//! | `setfleet/{run}/uav/{i}/cmd` | agent `i`'s commands, acks, hellos | agent `i`'s host |
//! | `setfleet/{run}/uav/{i}/estimate` | agent `i`'s estimates, for its peers | agent `i`'s host |
//! | `setfleet/{run}/uav/{i}/state` | agent `i`'s state messages, for the observer | agent `i`'s host |
//! | `setfleet/{run}/guidance/{i}` | the token as agent `i` passes it | agent `i`'s host |
//! | `setfleet/{run}/world/end` | the end of the run | the world host |
//! | `setfleet/{run}/alive/{host}/{node}` | liveliness token of a process | its host |
//!
//! Keys name their sender, so the access policy ([`crate::security`]) can say which host may
//! publish what, and a receiver can check that a message's own sender field matches its key.

use protocol::service::RunId;

/// First segment of every key.
pub const ROOT: &str = "setfleet";

/// What a received key is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Topic {
    /// UAV `i`'s frame.
    Frame(u32),
    /// Agent `i`'s command.
    Command(u32),
    /// Agent `i`'s estimate.
    Estimate(u32),
    /// Agent `i`'s state message (sets for the observer, under the measurement exchange).
    State(u32),
    /// The token as agent `i` passed it.
    Token(u32),
    /// The end of the run.
    EndOfRun,
}

/// `setfleet/{run}`: everything of the run lies under it.
pub fn run_root(run: &RunId) -> String {
    format!("{ROOT}/{}", run.as_str())
}

/// `setfleet/{run}/uav/{i}/cvs`.
pub fn frame(run: &RunId, uav: u32) -> String {
    format!("{}/uav/{uav}/cvs", run_root(run))
}

/// `setfleet/{run}/uav/{i}/cmd`.
pub fn command(run: &RunId, uav: u32) -> String {
    format!("{}/uav/{uav}/cmd", run_root(run))
}

/// `setfleet/{run}/uav/{i}/estimate`.
pub fn estimate(run: &RunId, uav: u32) -> String {
    format!("{}/uav/{uav}/estimate", run_root(run))
}

/// `setfleet/{run}/uav/{i}/state`: only the world host, where the observer runs, subscribes
/// to it, so the other hosts never receive the sets meant for the observer.
pub fn state(run: &RunId, uav: u32) -> String {
    format!("{}/uav/{uav}/state", run_root(run))
}

/// `setfleet/{run}/guidance/{i}`.
pub fn token(run: &RunId, uav: u32) -> String {
    format!("{}/guidance/{uav}", run_root(run))
}

/// `setfleet/{run}/world/end`.
pub fn end_of_run(run: &RunId) -> String {
    format!("{}/world/end", run_root(run))
}

/// `setfleet/{run}/alive/{host}/{node}`: the liveliness token of `node` on `host`.
pub fn alive(run: &RunId, host: &str, node: &str) -> String {
    format!("{}/alive/{host}/{node}", run_root(run))
}

/// `setfleet/{run}/alive/**`: every liveliness token of the run.
pub fn all_alive(run: &RunId) -> String {
    format!("{}/alive/**", run_root(run))
}

/// Reads a data key of `run`; `None` for anything else.
pub fn topic(run: &RunId, key: &str) -> Option<Topic> {
    let rest = key.strip_prefix(&run_root(run))?.strip_prefix('/')?;
    let parts: Vec<&str> = rest.split('/').collect();
    match parts.as_slice() {
        ["uav", i, what] => {
            let uav = index(i)?;
            match *what {
                "cvs" => Some(Topic::Frame(uav)),
                "cmd" => Some(Topic::Command(uav)),
                "estimate" => Some(Topic::Estimate(uav)),
                "state" => Some(Topic::State(uav)),
                _ => None,
            }
        }
        ["guidance", i] => Some(Topic::Token(index(i)?)),
        ["world", "end"] => Some(Topic::EndOfRun),
        _ => None,
    }
}

/// Reads a liveliness key of `run`: the host and the node.
pub fn alive_of<'a>(run: &RunId, key: &'a str) -> Option<(&'a str, &'a str)> {
    let rest = key.strip_prefix(&run_root(run))?.strip_prefix("/alive/")?;
    let (host, node) = rest.split_once('/')?;
    (!host.is_empty() && !node.is_empty() && !node.contains('/')).then_some((host, node))
}

/// A UAV index written the way the keys write it (no sign, no leading zero).
fn index(s: &str) -> Option<u32> {
    let i: u32 = s.parse().ok()?;
    (i.to_string() == s).then_some(i)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_read_back() {
        let run = RunId::new("r-1").unwrap().in_domain(3);
        assert_eq!(frame(&run, 2), "setfleet/r-1/uav/2/cvs");
        assert_eq!(topic(&run, &frame(&run, 2)), Some(Topic::Frame(2)));
        assert_eq!(topic(&run, &command(&run, 0)), Some(Topic::Command(0)));
        assert_eq!(topic(&run, &estimate(&run, 9)), Some(Topic::Estimate(9)));
        assert_eq!(topic(&run, &state(&run, 9)), Some(Topic::State(9)));
        assert_eq!(topic(&run, &token(&run, 1)), Some(Topic::Token(1)));
        assert_eq!(topic(&run, &end_of_run(&run)), Some(Topic::EndOfRun));
        assert_eq!(topic(&run, "setfleet/r-1/uav/02/cvs"), None);
        assert_eq!(topic(&run, "setfleet/r-12/uav/2/cvs"), None);
        assert_eq!(topic(&run, "setfleet/r-1/uav/2/cvs/x"), None);
        let key = alive(&run, "h1", "agent-2");
        assert_eq!(alive_of(&run, &key), Some(("h1", "agent-2")));
        assert_eq!(alive_of(&run, "setfleet/r-1/alive/h1"), None);
    }
}
