//! The run's iceoryx2 configuration, written where iceoryx2's own tools find it.
//!
//! Every run has its own file prefix ([`RunId::file_prefix`]), so iceoryx2's `iox2` command
//! (crate `iceoryx2-cli`) sees a run's services and nodes only with a configuration that
//! carries that prefix. `iox2` reads `config/iceoryx2.toml` under the directory it is started
//! in before any user or system configuration, so the run writes one there:
//!
//! - `OUT/config/iceoryx2.toml`: the first host started here: with `fleet run` the world's
//!   host, where the world-server, the observer and its agents are (`cd OUT && iox2 service
//!   list`), with `fleet host` that host;
//! - `OUT/hosts/NAME/config/iceoryx2.toml`: each other simulated host started here, in its
//!   own domain (`fleet run --hosts N`).

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use protocol::ipc::run_config;
use protocol::service::RunId;

use super::hosts::HostLayout;

/// Writes the configuration of every host of `layout` started here; returns the files.
pub fn write_configs(out: &Path, layout: &HostLayout, run: &RunId) -> anyhow::Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    let here = layout.hosts().iter().enumerate().filter(|(_, h)| h.here);
    for (n, (h, host)) in here.enumerate() {
        let config = run_config(&layout.run_on(run, h as u16))?;
        let text = toml::to_string(&config).context("cannot write the iceoryx2 configuration")?;
        let home = match n {
            0 => out.to_path_buf(),
            _ => out.join("hosts").join(host.name.as_str()),
        };
        let dir = home.join("config");
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        let file = dir.join("iceoryx2.toml");
        std::fs::write(&file, text).with_context(|| format!("cannot write {}", file.display()))?;
        written.push(file);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use iceoryx2::config::Config;
    use iceoryx2::prelude::*;

    use super::*;

    #[test]
    fn every_host_gets_a_config_with_its_prefix_that_iceoryx2_reads_back() {
        let out = std::env::temp_dir().join(format!("setfleet-iox2-{}", std::process::id()));
        let layout = HostLayout::simulated(2, 4).unwrap();
        let run: RunId = "iox2-test".parse().unwrap();
        let files = write_configs(&out, &layout, &run).unwrap();
        assert_eq!(files.len(), 2);
        assert_eq!(files[0], out.join("config/iceoryx2.toml"));
        for (h, file) in files.iter().enumerate() {
            let path = FilePath::new(file.to_str().unwrap().as_bytes()).unwrap();
            let read = Config::from_file(&path).unwrap();
            let expected = layout.run_on(&run, h as u16).file_prefix();
            assert_eq!(read.global.prefix.to_string(), expected);
            // Everything else is the run's configuration, as every process of the run uses it.
            assert_eq!(read, run_config(&layout.run_on(&run, h as u16)).unwrap());
        }
        std::fs::remove_dir_all(&out).unwrap();
    }

    #[test]
    fn a_joining_host_writes_its_own_config_at_the_top() {
        let out = std::env::temp_dir().join(format!("setfleet-iox2-host-{}", std::process::id()));
        let name = bridge::security::HostName::new("h1").unwrap();
        let agents = [2, 3].into_iter().collect();
        let layout = HostLayout::joining(4, name, &agents, Some(5)).unwrap();
        let run: RunId = "iox2-host".parse().unwrap();
        let files = write_configs(&out, &layout, &run).unwrap();
        assert_eq!(files, [out.join("config/iceoryx2.toml")]);
        let text = std::fs::read_to_string(&files[0]).unwrap();
        assert!(
            text.contains(&layout.run_on(&run, 1).file_prefix()),
            "{text}"
        );
        std::fs::remove_dir_all(&out).unwrap();
    }
}
