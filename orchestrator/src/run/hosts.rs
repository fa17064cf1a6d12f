//! How a run's processes are spread over hosts: `fleet run --hosts N` (hosts simulated on
//! this machine), `fleet run --remote NAME=UAVS` and `fleet host` (real machines).
//!
//! Host 0 is the *world host*: the world-server, the observer (in `fleet` itself) and the
//! agents no other host runs; its bridge is the Zenoh router the other hosts connect to.
//! Each host has a bridge ([`bridge`]), and the hosts meet only through them.
//!
//! - **Simulated hosts** (`--hosts N`): the agents are split in contiguous blocks, agent `i`
//!   on host `i * N / uavs`, so every host runs at least one. Each host other than host 0
//!   has its own iceoryx2 domain on this machine ([`RunId::in_domain`]); host 0 keeps the
//!   run's own, so the observer and every tool that opens the run need not know about hosts.
//! - **Remote hosts** (`--remote h1=2,3`): those agents run on another machine, started
//!   there by `fleet host`; this machine runs host 0 and nothing of the remote hosts.

use std::collections::BTreeSet;

use bridge::placement::HostShare;
use bridge::security::HostName;
use protocol::service::RunId;

/// Most hosts a run may have (each needs an agent, host 0 aside).
pub const MAX_HOSTS: u16 = 16;

/// One host of a run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Host {
    /// Its name: its certificate's common name.
    pub name: HostName,
    /// Whether this `fleet` process starts its processes.
    pub here: bool,
    /// Its iceoryx2 domain when several hosts are simulated on this machine.
    pub domain: Option<u16>,
}

/// The hosts of a run and which agents each one runs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HostLayout {
    hosts: Vec<Host>,
    /// The host of each agent, by UAV.
    host_of: Vec<u16>,
}

/// `--remote NAME=UAVS`: agents that run on another machine.
pub type RemoteHost = HostShare;

/// Host `host`'s default name: `h{host}`.
pub fn default_name(host: u16) -> HostName {
    HostName::new(&format!("h{host}")).unwrap_or_else(|e| unreachable!("h{host}: {e}"))
}

impl HostLayout {
    /// One host: everything in the run's one domain, no bridge.
    pub fn single(uavs: u32) -> HostLayout {
        HostLayout {
            hosts: vec![Host {
                name: default_name(0),
                here: true,
                domain: None,
            }],
            host_of: vec![0; uavs as usize],
        }
    }

    /// `hosts` hosts simulated on this machine, the agents split in blocks; an error when a
    /// host would have no agent.
    pub fn simulated(hosts: u16, uavs: u32) -> Result<HostLayout, String> {
        if hosts == 0 || hosts > MAX_HOSTS || u32::from(hosts) > uavs.max(1) {
            return Err(format!(
                "--hosts {hosts}: must be 1 to {} (every host runs at least one of the {uavs} \
                 agents, and at most {MAX_HOSTS} hosts)",
                uavs.clamp(1, u32::from(MAX_HOSTS))
            ));
        }
        Ok(HostLayout {
            hosts: (0..hosts)
                .map(|h| Host {
                    name: default_name(h),
                    here: true,
                    domain: (h != 0).then_some(h),
                })
                .collect(),
            host_of: (0..uavs)
                .map(|u| (u64::from(u) * u64::from(hosts) / u64::from(uavs)) as u16)
                .collect(),
        })
    }

    /// Host 0 here with every agent that no remote host runs; the remote hosts' agents run on
    /// other machines (`fleet host`).
    pub fn with_remotes(uavs: u32, remotes: &[RemoteHost]) -> Result<HostLayout, String> {
        if remotes.len() >= usize::from(MAX_HOSTS) {
            return Err(format!("--remote: at most {} remote hosts", MAX_HOSTS - 1));
        }
        let mut layout = HostLayout::single(uavs);
        for (i, remote) in remotes.iter().enumerate() {
            let host = i as u16 + 1;
            if remote.agents.is_empty() {
                return Err(format!("--remote {remote}: name the host's agents"));
            }
            if layout.hosts.iter().any(|h| h.name == remote.name) {
                return Err(format!(
                    "--remote {remote}: the host name {} is taken",
                    remote.name.as_str()
                ));
            }
            for &uav in &remote.agents {
                match layout.host_of.get_mut(uav as usize) {
                    None => {
                        return Err(format!(
                            "--remote {remote}: UAV {uav} is outside the fleet (UAVs 0..{uavs})"
                        ));
                    }
                    Some(h) if *h != 0 => {
                        return Err(format!(
                            "--remote {remote}: UAV {uav} is already on another host"
                        ));
                    }
                    Some(h) => *h = host,
                }
            }
            layout.hosts.push(Host {
                name: remote.name.clone(),
                here: false,
                domain: None,
            });
        }
        Ok(layout)
    }

    /// The layout `fleet host` sees: host 0 (the world host) elsewhere, and this machine as
    /// host 1, named `name`, running `agents` (in domain `domain` when simulated for a test).
    pub fn joining(
        uavs: u32,
        name: HostName,
        agents: &BTreeSet<u32>,
        domain: Option<u16>,
    ) -> Result<HostLayout, String> {
        if let Some(&u) = agents.iter().find(|&&u| u >= uavs) {
            return Err(format!(
                "--agents: UAV {u} is outside the fleet (UAVs 0..{uavs})"
            ));
        }
        if agents.is_empty() {
            return Err("--agents: name at least one UAV".to_owned());
        }
        let mut layout = HostLayout::single(uavs);
        layout.hosts[0].here = false;
        layout.hosts.push(Host {
            name,
            here: true,
            domain,
        });
        for &u in agents {
            layout.host_of[u as usize] = 1;
        }
        Ok(layout)
    }

    /// Names host 0 (the world host, of a joining host's layout).
    pub fn rename_world_host(&mut self, name: HostName) {
        self.hosts[0].name = name;
    }

    /// The hosts, host 0 first.
    pub fn hosts(&self) -> &[Host] {
        &self.hosts
    }

    /// Whether the run spans several hosts (and needs bridges).
    pub fn is_distributed(&self) -> bool {
        self.hosts.len() > 1
    }

    /// The host of agent `uav`.
    pub fn host_of(&self, uav: u32) -> u16 {
        self.host_of.get(uav as usize).copied().unwrap_or(0)
    }

    /// Whether agent `uav` is started by this `fleet` process.
    pub fn is_here(&self, uav: u32) -> bool {
        self.hosts[usize::from(self.host_of(uav))].here
    }

    /// The agents of host `host`.
    pub fn agents_on(&self, host: u16) -> BTreeSet<u32> {
        (0..self.host_of.len() as u32)
            .filter(|&u| self.host_of(u) == host)
            .collect()
    }

    /// The run as seen on host `host`: in the host's domain, if it has one.
    pub fn run_on(&self, run: &RunId, host: u16) -> RunId {
        match self.hosts[usize::from(host)].domain {
            Some(d) => run.in_domain(d),
            None => run.clone(),
        }
    }

    /// The `--domain` a process of host `host` is started with.
    pub fn domain_arg(&self, host: u16) -> Option<u16> {
        self.hosts[usize::from(host)].domain
    }

    /// The run in the domain of every host started here, once each.
    pub fn runs(&self, run: &RunId) -> Vec<RunId> {
        let mut runs: Vec<RunId> = Vec::new();
        for (h, host) in self.hosts.iter().enumerate() {
            let r = self.run_on(run, h as u16);
            if host.here && !runs.contains(&r) {
                runs.push(r);
            }
        }
        runs
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agents_are_split_in_blocks_with_one_at_least_per_host() {
        let l = HostLayout::simulated(2, 4).unwrap();
        assert_eq!(l.agents_on(0), BTreeSet::from([0, 1]));
        assert_eq!(l.agents_on(1), BTreeSet::from([2, 3]));
        for hosts in 1..=8 {
            for uavs in u32::from(hosts)..=20 {
                let l = HostLayout::simulated(hosts, uavs).unwrap();
                for h in 0..hosts {
                    assert!(!l.agents_on(h).is_empty(), "{hosts} hosts, {uavs} UAVs");
                }
            }
        }
        assert!(HostLayout::simulated(0, 4).is_err());
        assert!(HostLayout::simulated(5, 4).is_err());
    }

    #[test]
    fn host_zero_keeps_the_run_and_simulated_hosts_have_domains() {
        let run = RunId::new("r").unwrap();
        let l = HostLayout::simulated(3, 6).unwrap();
        assert_eq!(l.run_on(&run, 0), run);
        assert_eq!(l.run_on(&run, 2).domain(), Some(2));
        assert_eq!(l.domain_arg(0), None);
        assert_eq!(l.runs(&run).len(), 3);
        assert!(!HostLayout::single(4).is_distributed());
    }

    #[test]
    fn remote_hosts_take_their_agents_and_are_not_started_here() {
        let remote: RemoteHost = "uav-box=2,3".parse().unwrap();
        assert_eq!(remote.to_string(), "uav-box=2,3");
        let l = HostLayout::with_remotes(4, &[remote]).unwrap();
        assert_eq!(l.agents_on(0), BTreeSet::from([0, 1]));
        assert_eq!(l.agents_on(1), BTreeSet::from([2, 3]));
        assert!(l.is_here(1) && !l.is_here(2));
        let run = RunId::new("r").unwrap();
        assert_eq!(l.runs(&run), vec![run]);
        for bad in ["h1", "h1=", "h1=x", "h/1=2", "h1=9", "h0=1"] {
            let parsed = bad.parse::<RemoteHost>();
            let layout = parsed.and_then(|r| HostLayout::with_remotes(4, &[r]));
            assert!(layout.is_err(), "{bad}");
        }
        let twice = ["a=1".parse().unwrap(), "b=1".parse().unwrap()];
        assert!(HostLayout::with_remotes(4, &twice).is_err());
        let same = ["a=1".parse().unwrap(), "a=2".parse().unwrap()];
        assert!(HostLayout::with_remotes(4, &same).is_err());
    }

    #[test]
    fn a_joining_host_runs_only_its_agents() {
        let name = HostName::new("h7").unwrap();
        let l = HostLayout::joining(4, name, &BTreeSet::from([1, 2]), Some(7)).unwrap();
        assert!(!l.is_here(0) && l.is_here(1) && l.is_here(2) && !l.is_here(3));
        let run = RunId::new("r").unwrap();
        assert_eq!(l.runs(&run), vec![run.in_domain(7)]);
        assert!(HostLayout::joining(4, default_name(1), &BTreeSet::from([4]), None).is_err());
        assert!(HostLayout::joining(4, default_name(1), &BTreeSet::new(), None).is_err());
    }
}
