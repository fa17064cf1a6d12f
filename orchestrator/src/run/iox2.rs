//! The run's iceoryx2 configuration, written where iceoryx2's own tools find it.
//!
//! Every run has its own file prefix ([`RunId::file_prefix`]), so iceoryx2's `iox2` command
//! (crate `iceoryx2-cli`) sees a run's services and nodes only with a configuration that
//! carries that prefix. `iox2` reads `config/iceoryx2.toml` under the directory it is started
//! in before any user or system configuration, so the run writes one there:
//!
//! - `OUT/config/iceoryx2.toml`: the world's host, where the world-server, the observer and
//!   its agents are (`cd OUT && iox2 service list`);
//! - `OUT/hosts/NAME/config/iceoryx2.toml`: each other simulated host started here, in its
//!   own domain (`--hosts N`).

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use protocol::ipc::run_config;
use protocol::service::RunId;

use super::hosts::HostLayout;

/// The directory under `out` whose `config/iceoryx2.toml` is host `host`'s.
pub fn config_home(out: &Path, layout: &HostLayout, host: u16) -> PathBuf {
    if host == 0 {
        out.to_path_buf()
    } else {
        out.join("hosts")
            .join(layout.hosts()[usize::from(host)].name.as_str())
    }
}

/// Writes the configuration of every host of `layout` started here; returns the files.
pub fn write_configs(out: &Path, layout: &HostLayout, run: &RunId) -> anyhow::Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    for (h, host) in layout.hosts().iter().enumerate() {
        let h = h as u16;
        if !host.here {
            continue;
        }
        let config = run_config(&layout.run_on(run, h))?;
        let text = toml::to_string(&config).context("cannot write the iceoryx2 configuration")?;
        let dir = config_home(out, layout, h).join("config");
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
            // Everything else is iceoryx2's default, as every process of the run uses it.
            assert_eq!(read, run_config(&layout.run_on(&run, h as u16)).unwrap());
        }
        std::fs::remove_dir_all(&out).unwrap();
    }
}
