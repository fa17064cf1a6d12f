//! The fleet's access policy: which host may publish which key expressions, turned into
//! Zenoh's `access_control` configuration.

use std::collections::{BTreeMap, BTreeSet};

use protocol::ipc::RunNode;
use protocol::service::RunId;
use protocol::wire::MAX_UAVS;
use serde_json::{Value, json};

use super::host::HostName;
use crate::keys;

/// Why a role could not be given to a host.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AccessPolicyError {
    /// The run has a world host already.
    #[error("{second} cannot be the world host: {first} already is")]
    SecondWorldHost {
        /// The world host already named.
        first: HostName,
        /// The host refused.
        second: HostName,
    },
    /// The UAV runs on another host already.
    #[error("UAV {uav} cannot run on {second}: it runs on {first}")]
    UavOnTwoHosts {
        /// The UAV.
        uav: u32,
        /// The host it was given to first.
        first: HostName,
        /// The host refused.
        second: HostName,
    },
    /// The UAV index is not below [`MAX_UAVS`].
    #[error("UAV {0} does not exist: a fleet has UAVs 0 to {max}", max = MAX_UAVS - 1)]
    UavIndex(u32),
}

/// What one host may publish.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
struct Rights {
    world: bool,
    relay: bool,
    uavs: BTreeSet<u32>,
}

/// `setfleet/{run}/{rest}`.
fn under(run: &RunId, rest: &str) -> String {
    format!("{}/{rest}", keys::run_root(run))
}

/// Who may publish what in one run, by host role; converted by [`AccessPolicy::to_json`] into
/// Zenoh's `access_control` section.
///
/// - the **world host** (world-server and observer) publishes frames and world events (the end
///   of the run), and announces the world-server and the observer alive;
/// - an **agent host** running UAVs `S` publishes, for each `i` in `S`, UAV `i`'s commands,
///   estimates and guidance token, and announces agent `i` alive;
/// - **every host** named here may subscribe to the whole run and watch everyone's liveliness;
///   it declares liveliness tokens only under its own name and only for its own processes, so
///   no host can make another host's process look alive;
/// - a **relay host**, the Zenoh router the other hosts connect to, forwards everyone's
///   messages and tokens: the others accept anything of the run from it. It is trusted with
///   the whole run (a relay can forge anything), and it is where the roles are enforced: it
///   refuses what a host sends outside its role, before relaying.
///
/// A host may hold several roles (the world host is usually the relay too; a machine may run
/// the world and some agents). Anything else is denied, and a host not named here (even with a
/// valid fleet certificate) may do nothing.
///
/// The same policy serves every host of the run: on the relay it filters what each host sends,
/// on the others it admits the relay's deliveries and nothing from anyone else.
///
/// ```
/// use bridge::security::{AccessPolicy, HostName};
/// use protocol::service::RunId;
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let run = RunId::new("demo")?;
/// let world = HostName::new("world")?;
/// let policy = AccessPolicy::new(&run)
///     .world_host(&world)?
///     .relay_host(&world)
///     .agent_host(&HostName::new("h1")?, &[0, 1])?
///     .agent_host(&HostName::new("h2")?, &[2, 3])?;
/// assert_eq!(policy.to_json()["default_permission"], "deny");
/// # Ok(())
/// # }
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AccessPolicy {
    run: RunId,
    hosts: BTreeMap<HostName, Rights>,
}

impl AccessPolicy {
    /// A policy for one run that allows nothing yet.
    pub fn new(run: &RunId) -> Self {
        Self {
            run: run.clone(),
            hosts: BTreeMap::new(),
        }
    }

    /// Makes `host` the world host (one per run).
    pub fn world_host(mut self, host: &HostName) -> Result<Self, AccessPolicyError> {
        if let Some((first, _)) = self.hosts.iter().find(|(h, r)| r.world && *h != host) {
            return Err(AccessPolicyError::SecondWorldHost {
                first: first.clone(),
                second: host.clone(),
            });
        }
        self.hosts.entry(host.clone()).or_default().world = true;
        Ok(self)
    }

    /// Makes `host` the relay: the Zenoh router that the other hosts connect to and that
    /// forwards their messages to each other. Others accept every publication and liveliness
    /// token of the run from it.
    pub fn relay_host(mut self, host: &HostName) -> Self {
        self.hosts.entry(host.clone()).or_default().relay = true;
        self
    }

    /// Makes `host` an agent host running `uavs` (each UAV on one host only). An empty list
    /// names a host that only listens.
    pub fn agent_host(mut self, host: &HostName, uavs: &[u32]) -> Result<Self, AccessPolicyError> {
        for &uav in uavs {
            if uav as usize >= MAX_UAVS {
                return Err(AccessPolicyError::UavIndex(uav));
            }
            if let Some((first, _)) = self
                .hosts
                .iter()
                .find(|(h, r)| *h != host && r.uavs.contains(&uav))
            {
                return Err(AccessPolicyError::UavOnTwoHosts {
                    uav,
                    first: first.clone(),
                    second: host.clone(),
                });
            }
        }
        self.hosts
            .entry(host.clone())
            .or_default()
            .uavs
            .extend(uavs.iter().copied());
        Ok(self)
    }

    /// The run this policy is for.
    pub fn run(&self) -> &RunId {
        &self.run
    }

    /// The hosts named, in name order.
    pub fn hosts(&self) -> impl Iterator<Item = &HostName> {
        self.hosts.keys()
    }

    /// The key expressions `host` may publish (empty for a host not named; the whole run for
    /// the relay).
    pub fn publications(&self, host: &HostName) -> Vec<String> {
        let Some(rights) = self.hosts.get(host) else {
            return Vec::new();
        };
        let run = &self.run;
        if rights.relay {
            return vec![under(run, "**")];
        }
        let mut keys = Vec::new();
        if rights.world {
            keys.extend([under(run, "uav/*/cvs"), under(run, "world/**")]);
        }
        for &uav in &rights.uavs {
            keys.extend([
                keys::command(run, uav),
                keys::estimate(run, uav),
                keys::state(run, uav),
                keys::token(run, uav),
            ]);
        }
        keys
    }

    /// The liveliness tokens `host` may declare: its own processes' under its own name
    /// (every host's for the relay).
    pub fn tokens(&self, host: &HostName) -> Vec<String> {
        let run = &self.run;
        let name = host.as_str();
        match self.hosts.get(host) {
            None => Vec::new(),
            Some(rights) if rights.relay => vec![keys::all_alive(run)],
            Some(rights) => {
                let mut tokens = Vec::new();
                if rights.world {
                    tokens.extend([
                        keys::alive(run, name, RunNode::WORLD),
                        keys::alive(run, name, RunNode::OBSERVER),
                    ]);
                }
                tokens.extend(
                    rights
                        .uavs
                        .iter()
                        .map(|&u| keys::alive(run, name, &RunNode::agent_name(u))),
                );
                tokens
            }
        }
    }

    /// The `access_control` section of a Zenoh configuration enforcing this policy.
    ///
    /// Default permission deny. Subjects are hosts, matched by their certificate's Common Name
    /// (`cert_common_names`), so the policy needs TLS links. Zenoh checks every message twice,
    /// on the sender's *egress* and the receiver's *ingress*, each against the subject at the
    /// other end of the link:
    ///
    /// - **ingress** carries the policy: a receiver accepts a `put` from a host only on that
    ///   host's [`publications`](Self::publications), and a `liveliness_token` only among its
    ///   [`tokens`](Self::tokens). A host that does not follow the rules controls its own egress,
    ///   so only the receiver's check counts.
    /// - **egress** is open within the run for every fleet host (`put` on `setfleet/{run}/**`,
    ///   tokens under `alive/**`) — with a default of deny, a host would otherwise send nothing
    ///   at all.
    /// - both flows allow `declare_subscriber` on `setfleet/{run}/**` and
    ///   `declare_liveliness_subscriber` and `liveliness_query` on `setfleet/{run}/alive/**`.
    ///
    /// `delete`, queries, replies and queryables are denied: the bridge does not use them.
    pub fn to_json(&self) -> Value {
        let run = &self.run;
        let everything = under(run, "**");
        let all_alive = keys::all_alive(run);
        let mut rules = vec![
            json!({
                "id": "fleet-send",
                "messages": ["put"],
                "flows": ["egress"],
                "permission": "allow",
                "key_exprs": [everything],
            }),
            json!({
                "id": "fleet-send-alive",
                "messages": ["liveliness_token"],
                "flows": ["egress"],
                "permission": "allow",
                "key_exprs": [all_alive],
            }),
            json!({
                "id": "fleet-subscribe",
                "messages": ["declare_subscriber"],
                "flows": ["ingress", "egress"],
                "permission": "allow",
                "key_exprs": [everything],
            }),
            json!({
                "id": "fleet-watch-alive",
                "messages": ["declare_liveliness_subscriber", "liveliness_query"],
                "flows": ["ingress", "egress"],
                "permission": "allow",
                "key_exprs": [all_alive],
            }),
        ];
        let mut subjects = Vec::new();
        let mut policies = Vec::new();
        for host in self.hosts.keys() {
            let mut host_rules = vec![
                "fleet-send".to_owned(),
                "fleet-send-alive".to_owned(),
                "fleet-subscribe".to_owned(),
                "fleet-watch-alive".to_owned(),
            ];
            let publications = self.publications(host);
            if !publications.is_empty() {
                let id = format!("publish-{host}");
                rules.push(json!({
                    "id": id,
                    "messages": ["put"],
                    "flows": ["ingress"],
                    "permission": "allow",
                    "key_exprs": publications,
                }));
                host_rules.push(id);
            }
            let id = format!("alive-{host}");
            rules.push(json!({
                "id": id,
                "messages": ["liveliness_token"],
                "flows": ["ingress"],
                "permission": "allow",
                "key_exprs": self.tokens(host),
            }));
            host_rules.push(id);
            subjects.push(json!({
                "id": format!("host-{host}"),
                "cert_common_names": [host.as_str()],
            }));
            policies.push(json!({
                "id": format!("policy-{host}"),
                "rules": host_rules,
                "subjects": [format!("host-{host}")],
            }));
        }
        json!({
            "enabled": true,
            "default_permission": "deny",
            "rules": rules,
            "subjects": subjects,
            "policies": policies,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn host(name: &str) -> HostName {
        HostName::new(name).unwrap()
    }

    fn policy() -> AccessPolicy {
        AccessPolicy::new(&RunId::new("r").unwrap())
            .world_host(&host("world"))
            .unwrap()
            .relay_host(&host("relay"))
            .agent_host(&host("h1"), &[1, 0])
            .unwrap()
            .agent_host(&host("h2"), &[2])
            .unwrap()
    }

    #[test]
    fn roles_publish_their_keys_only() {
        let p = policy();
        assert_eq!(
            p.publications(&host("world")),
            ["setfleet/r/uav/*/cvs", "setfleet/r/world/**"]
        );
        assert_eq!(
            p.publications(&host("h1")),
            [
                "setfleet/r/uav/0/cmd",
                "setfleet/r/uav/0/estimate",
                "setfleet/r/uav/0/state",
                "setfleet/r/guidance/0",
                "setfleet/r/uav/1/cmd",
                "setfleet/r/uav/1/estimate",
                "setfleet/r/uav/1/state",
                "setfleet/r/guidance/1"
            ]
        );
        assert_eq!(p.publications(&host("relay")), ["setfleet/r/**"]);
        assert!(p.publications(&host("stranger")).is_empty());
        assert_eq!(
            p.tokens(&host("h1")),
            ["setfleet/r/alive/h1/agent-0", "setfleet/r/alive/h1/agent-1"]
        );
        assert_eq!(
            p.tokens(&host("world")),
            [
                "setfleet/r/alive/world/world",
                "setfleet/r/alive/world/observer"
            ]
        );
        assert_eq!(p.tokens(&host("relay")), ["setfleet/r/alive/**"]);
        assert!(p.tokens(&host("stranger")).is_empty());
    }

    #[test]
    fn one_world_and_one_host_per_uav() {
        let p = policy();
        assert_eq!(
            p.clone().world_host(&host("h1")),
            Err(AccessPolicyError::SecondWorldHost {
                first: host("world"),
                second: host("h1")
            })
        );
        assert_eq!(
            p.clone().agent_host(&host("h3"), &[2]),
            Err(AccessPolicyError::UavOnTwoHosts {
                uav: 2,
                first: host("h2"),
                second: host("h3")
            })
        );
        assert_eq!(
            p.clone().agent_host(&host("h3"), &[MAX_UAVS as u32]),
            Err(AccessPolicyError::UavIndex(MAX_UAVS as u32))
        );
        // Repeating a role, or a host holding both, is fine.
        let both = p
            .world_host(&host("world"))
            .unwrap()
            .agent_host(&host("world"), &[5])
            .unwrap()
            .agent_host(&host("h1"), &[1])
            .unwrap();
        // Four keys per UAV: commands, estimates, state messages, tokens.
        assert_eq!(both.publications(&host("world")).len(), 2 + 4);
        assert_eq!(both.publications(&host("h1")).len(), 2 * 4);
    }

    #[test]
    fn json_is_what_zenoh_accepts() {
        let json = policy().to_json();
        let mut config = zenoh::Config::default();
        config
            .insert_json5("access_control", &json.to_string())
            .unwrap();
        assert_eq!(json["default_permission"], "deny");
        assert_eq!(json["subjects"].as_array().unwrap().len(), 4);
        let h1 = json["subjects"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["id"] == "host-h1")
            .unwrap();
        assert_eq!(h1["cert_common_names"], json!(["h1"]));
        let publish_h1 = json["rules"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["id"] == "publish-h1")
            .unwrap();
        assert_eq!(publish_h1["flows"], json!(["ingress"]));
        // Every rule says its flows: left out, zenoh would apply it both ways.
        for rule in json["rules"].as_array().unwrap() {
            assert!(rule["flows"].is_array(), "{rule}");
        }
    }
}
