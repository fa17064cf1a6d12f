//! Where a run's processes are placed: which of them live on this host, and what the bridge
//! therefore forwards.

use std::collections::BTreeSet;
use std::fmt;
use std::str::FromStr;

use protocol::ipc::RunNode;
use protocol::service::RunId;

use crate::security::{AccessPolicy, AccessPolicyError, HostName};

/// A host and its agents, written `NAME=UAVS` (e.g. `h1=2,3`; `h0=` for a host without
/// agents): how the command line names the hosts of a run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HostShare {
    /// The host's name (its certificate's common name).
    pub name: HostName,
    /// Its agents.
    pub agents: BTreeSet<u32>,
}

impl FromStr for HostShare {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (name, uavs) = s
            .split_once('=')
            .ok_or_else(|| format!("{s:?}: expected NAME=UAVS, e.g. h1=2,3"))?;
        let name = HostName::new(name).map_err(|e| format!("{s:?}: {e}"))?;
        let agents = uavs
            .split(',')
            .filter(|u| !u.is_empty())
            .map(|u| {
                u.trim()
                    .parse::<u32>()
                    .map_err(|_| format!("{s:?}: {u:?} is not a UAV index"))
            })
            .collect::<Result<BTreeSet<u32>, String>>()?;
        Ok(HostShare { name, agents })
    }
}

impl fmt::Display for HostShare {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let uavs: Vec<String> = self.agents.iter().map(u32::to_string).collect();
        write!(f, "{}={}", self.name.as_str(), uavs.join(","))
    }
}

/// The access policy of a run whose hosts are `members`, the world host first: it is the
/// relay (the router) and publishes the world's topics; each host publishes its agents'.
pub fn access_policy(
    run: &RunId,
    members: &[HostShare],
) -> Result<AccessPolicy, AccessPolicyError> {
    let mut policy = AccessPolicy::new(run);
    if let Some(world) = members.first() {
        policy = policy.world_host(&world.name)?.relay_host(&world.name);
    }
    for m in members {
        let uavs: Vec<u32> = m.agents.iter().copied().collect();
        policy = policy.agent_host(&m.name, &uavs)?;
    }
    Ok(policy)
}

/// One host's share of a run.
///
/// The world-server and the observer share a host (the *world host*); agents may be anywhere.
/// Every service has one origin, so the bridge of each host knows, without asking, what to
/// send and what to receive:
///
/// | service | sent by the bridge of | received by the bridges of |
/// |---|---|---|
/// | `uav/{i}/cvs` (frames) | the world host | agent `i`'s host |
/// | `uav/{i}/cmd` (commands, acks, hellos) | agent `i`'s host | the world host |
/// | `uav/{i}/estimate`, estimates | agent `i`'s host | every other host |
/// | `uav/{i}/estimate`, state messages (for the observer) | agent `i`'s host, when not the world host | the world host |
/// | `guidance` (token passed by `i`) | agent `i`'s host | every other host |
/// | end of run (an event) | the world host | every other host |
/// | liveliness of each process | its host | every other host |
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HostPlan {
    /// The run, in this host's iceoryx2 domain.
    pub run: RunId,
    /// This host's name: its certificate's common name and its liveliness keys' segment.
    pub host: String,
    /// UAVs of the run.
    pub fleet: u32,
    /// The UAVs whose agents run on this host.
    pub agents: BTreeSet<u32>,
    /// Whether the world-server and the observer run on this host.
    pub world: bool,
}

impl HostPlan {
    /// Whether agent `uav` runs on this host.
    pub fn is_local(&self, uav: u32) -> bool {
        self.agents.contains(&uav)
    }

    /// The UAVs whose agents run on other hosts.
    pub fn remote_agents(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.fleet).filter(|u| !self.is_local(*u))
    }

    /// Names of the iceoryx2 nodes of this host's processes, whose liveliness the bridge
    /// announces to the other hosts.
    pub fn local_nodes(&self) -> Vec<String> {
        let mut nodes: Vec<String> = self
            .agents
            .iter()
            .map(|&u| RunNode::agent_name(u))
            .collect();
        if self.world {
            nodes.extend([RunNode::WORLD.to_owned(), RunNode::OBSERVER.to_owned()]);
        }
        nodes
    }

    /// Whether `node` is the name of a process another host may run: a proxy of it is kept
    /// here while that host announces it alive.
    pub fn is_remote_node(&self, node: &str) -> bool {
        if node == RunNode::WORLD || node == RunNode::OBSERVER {
            return !self.world;
        }
        node.strip_prefix("agent-")
            .and_then(|u| u.parse::<u32>().ok())
            .is_some_and(|u| u < self.fleet && !self.is_local(u) && RunNode::agent_name(u) == node)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn host_shares_read_and_print() {
        let share: HostShare = "uav-box=2,3".parse().unwrap();
        assert_eq!(share.agents, BTreeSet::from([2, 3]));
        assert_eq!(share.to_string(), "uav-box=2,3");
        let empty: HostShare = "h0=".parse().unwrap();
        assert!(empty.agents.is_empty());
        for bad in ["h1", "h1=x", "h/1=2", "=2", "ca=1"] {
            assert!(bad.parse::<HostShare>().is_err(), "{bad}");
        }
    }

    #[test]
    fn a_host_knows_its_nodes_and_the_others() {
        let plan = HostPlan {
            run: RunId::new("p").unwrap(),
            host: "h1".into(),
            fleet: 4,
            agents: [2, 3].into(),
            world: false,
        };
        assert_eq!(plan.remote_agents().collect::<Vec<_>>(), [0, 1]);
        assert_eq!(plan.local_nodes(), ["agent-2", "agent-3"]);
        assert!(plan.is_remote_node("world"));
        assert!(plan.is_remote_node("agent-1"));
        assert!(!plan.is_remote_node("agent-2"));
        assert!(!plan.is_remote_node("agent-4"));
        assert!(!plan.is_remote_node("agent-01"));
        assert!(!plan.is_remote_node("intruder"));
    }
}
