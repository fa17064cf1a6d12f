//! How a run's processes are spread over hosts (`fleet run --hosts N`, `fleet host`).
//!
//! Host 0 is the *world host*: the world-server, the observer (in `fleet` itself) and the
//! first agents. The agents are split in contiguous blocks over the hosts, agent `i` on host
//! `i * N / uavs`, so every host runs at least one agent. On one machine each host other than
//! host 0 is simulated by its own iceoryx2 domain ([`RunId::in_domain`]); host 0 keeps the
//! run's own, so the observer and every tool that opens the run need not know about hosts.
//! Each host has a bridge ([`bridge`]) and the hosts meet only through them.

use std::collections::BTreeSet;

use protocol::service::RunId;

/// Most hosts a run may have (each needs an agent).
pub const MAX_HOSTS: u16 = 16;

/// The hosts of a run and which agents each one runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HostLayout {
    /// Number of hosts, at least 1.
    pub hosts: u16,
    /// UAVs of the run.
    pub uavs: u32,
}

impl HostLayout {
    /// A layout of `hosts` hosts for `uavs` UAVs; an error when a host would have no agent.
    pub fn new(hosts: u16, uavs: u32) -> Result<HostLayout, String> {
        if hosts == 0 || hosts > MAX_HOSTS || u32::from(hosts) > uavs.max(1) {
            return Err(format!(
                "--hosts {hosts}: must be 1 to {} (every host runs at least one of the {uavs} \
                 agents, and at most {MAX_HOSTS} hosts)",
                uavs.clamp(1, u32::from(MAX_HOSTS))
            ));
        }
        Ok(HostLayout { hosts, uavs })
    }

    /// One host: everything in the run's one domain, no bridge.
    pub fn single(uavs: u32) -> HostLayout {
        HostLayout { hosts: 1, uavs }
    }

    /// Whether the run spans several hosts (and needs bridges).
    pub fn is_distributed(&self) -> bool {
        self.hosts > 1
    }

    /// The host of agent `uav`.
    pub fn host_of(&self, uav: u32) -> u16 {
        // uav < uavs and hosts <= uavs, so the quotient is below hosts.
        (u64::from(uav) * u64::from(self.hosts) / u64::from(self.uavs.max(1))) as u16
    }

    /// The agents of host `host`.
    pub fn agents_on(&self, host: u16) -> BTreeSet<u32> {
        (0..self.uavs).filter(|&u| self.host_of(u) == host).collect()
    }

    /// The run as seen on host `host`: the run itself on host 0, the host's own domain on
    /// the others.
    pub fn run_on(&self, run: &RunId, host: u16) -> RunId {
        if host == 0 {
            run.clone()
        } else {
            run.in_domain(host)
        }
    }

    /// The `--domain` a process of host `host` is started with (none on host 0).
    pub fn domain_arg(&self, host: u16) -> Option<u16> {
        (host != 0).then_some(host)
    }

    /// Host `host`'s name (its certificate's common name): `h{host}`.
    pub fn name(host: u16) -> String {
        format!("h{host}")
    }

    /// Every host's run, host 0 first.
    pub fn runs(&self, run: &RunId) -> Vec<RunId> {
        (0..self.hosts).map(|h| self.run_on(run, h)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agents_are_split_in_blocks_with_one_at_least_per_host() {
        let l = HostLayout::new(2, 4).unwrap();
        assert_eq!(l.agents_on(0), BTreeSet::from([0, 1]));
        assert_eq!(l.agents_on(1), BTreeSet::from([2, 3]));
        let l = HostLayout::new(3, 4).unwrap();
        let sizes: Vec<usize> = (0..3).map(|h| l.agents_on(h).len()).collect();
        assert_eq!(sizes.iter().sum::<usize>(), 4);
        assert!(sizes.iter().all(|&n| n >= 1), "{sizes:?}");
        for hosts in 1..=8 {
            for uavs in u32::from(hosts)..=20 {
                let l = HostLayout::new(hosts, uavs).unwrap();
                for h in 0..hosts {
                    assert!(!l.agents_on(h).is_empty(), "{hosts} hosts, {uavs} UAVs");
                }
            }
        }
        assert!(HostLayout::new(0, 4).is_err());
        assert!(HostLayout::new(5, 4).is_err());
    }

    #[test]
    fn host_zero_keeps_the_run_and_the_others_have_domains() {
        let run = RunId::new("r").unwrap();
        let l = HostLayout::new(3, 6).unwrap();
        assert_eq!(l.run_on(&run, 0), run);
        assert_eq!(l.run_on(&run, 2).domain(), Some(2));
        assert_eq!(l.domain_arg(0), None);
        assert_eq!(l.runs(&run).len(), 3);
    }
}
