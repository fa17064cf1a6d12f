//! `fleet sweep --cache DIR`: finished runs kept by what they depend on, so that a run asked
//! for again (by another sweep, another axis value equal to the default, another figure) is
//! taken from the store instead of being run again.
//!
//! **Why a run can be reused.** A lockstep run is deterministic: the same binaries, resolved
//! scenario (seed included), variant and faults give the same `summary.json` apart from its
//! wall-clock fields, the same `timeseries.csv` and `tracks.csv` (README, `fleet run`;
//! `tests/integration/sweep.rs` checks it across `--jobs` and shards). The store's key is the
//! SHA-256 of exactly those:
//!
//! - the build: the SHA-256 of the `fleet`, `world-server` and `uav-agent` executables
//!   ([`RunCache::open`] hashes them once per sweep), so a rebuilt binary never reuses an
//!   older build's runs, even when its source did not change;
//! - the resolved scenario as its `scenario.toml` is written, which holds every key and the
//!   seed;
//! - the variant, the step mode, the host layout and the faults;
//! - for an imported city, the SHA-256 of its scene file (`city.scene`) and of its trace file
//!   (`city.trace`), which the scenario names by path only, and for cars SUMO drives, SUMO's
//!   version (no SUMO found: no key).
//!
//! Runs with a pause fault (a process stopped for wall-clock seconds) or a restart (the new
//! process joins when it has started) depend on the wall clock, so they are never stored nor
//! taken ([`RunCache::key`] is `None`). Neither is a run that failed or was interrupted.
//!
//! **The store.** `DIR/<key>/` holds a finished run's whole directory (summary, time series,
//! tracks, pictures, logs, checkpoints), as hard links to the run's files where the file
//! system allows, else as copies. A run is stored under a temporary name and renamed into
//! place, so a store that a crash cut short is never taken and two sweeps storing the same
//! run at once both succeed. A taken run's files are linked or copied into the run's
//! directory; its `summary.json` is the original run's, wall-clock fields and run id
//! included, since that is the run the results are from. Runs never change their files
//! after they are written, so the links share nothing that changes.
//!
//! Storing is best effort: a store that cannot be written is reported and the sweep goes on.

use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::Context as _;
use sha2::{Digest as _, Sha256};

use crate::run::children::Binaries;
use crate::run::config::RunConfig;
use fleet_observe::faults::FaultKind;
use fleet_observe::results::summary::Summary;
use protocol::scenario::CityTraffic;
use world_server::traffic::sumo::SumoTools;

/// Bumped whenever what a key covers changes, so that old entries stop matching.
const FORMAT: &str = "setfleet run cache 1";

/// A store of finished runs.
#[derive(Debug, Clone)]
pub struct RunCache {
    dir: PathBuf,
    /// The hex SHA-256 of the binaries a run executes.
    build: String,
    /// SUMO's version, looked up for the first run SUMO drives (`None`: no SUMO found).
    sumo_version: OnceLock<Option<String>>,
}

impl RunCache {
    /// The store at `dir` (made if missing) for runs of the running `fleet` and the binaries
    /// beside it.
    pub fn open(dir: &Path) -> anyhow::Result<RunCache> {
        let binaries = Binaries::locate()?;
        let fleet = std::env::current_exe().context("cannot locate the fleet executable")?;
        Self::with_executables(dir, &[fleet, binaries.world, binaries.agent])
    }

    /// The store at `dir` for runs of these executables (their contents make the build id).
    pub fn with_executables(dir: &Path, executables: &[PathBuf]) -> anyhow::Result<RunCache> {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the run cache {}", dir.display()))?;
        let mut hash = Sha256::new();
        let mut buf = vec![0u8; 1 << 20];
        for exe in executables {
            let mut file = std::fs::File::open(exe)
                .with_context(|| format!("cannot read {} to hash it", exe.display()))?;
            let name = exe.file_name().map(|n| n.to_string_lossy().into_owned());
            hash.update(name.unwrap_or_default().as_bytes());
            hash.update([0]);
            loop {
                let n = file
                    .read(&mut buf)
                    .with_context(|| format!("cannot read {} to hash it", exe.display()))?;
                if n == 0 {
                    break;
                }
                hash.update(&buf[..n]);
            }
        }
        Ok(RunCache {
            dir: dir.to_owned(),
            build: hex(&hash.finalize()),
            sumo_version: OnceLock::new(),
        })
    }

    /// The key of `run`, `None` when the run depends on the wall clock (a pause or a restart)
    /// and so is never stored nor taken.
    pub fn key(&self, run: &RunConfig) -> Option<String> {
        if run.chaos_seed.is_some()
            || run
                .faults
                .iter()
                .any(|f| matches!(f.kind, FaultKind::Pause | FaultKind::Restart))
        {
            return None;
        }
        let mut hash = Sha256::new();
        let faults: Vec<String> = run.faults.iter().map(ToString::to_string).collect();
        let head = format!(
            "{FORMAT}\nbuild {}\nvariant {}\nmode {:?}\nlayout {:?}\nfaults {}\nscenario\n",
            self.build,
            run.variant.name(),
            run.mode,
            run.layout,
            faults.join(" "),
        );
        hash.update(head.as_bytes());
        hash.update(run.scenario.to_toml_string().as_bytes());
        let city = &run.scenario.city;
        for (name, file) in [("scene", &city.scene), ("trace", &city.trace)] {
            if !file.is_empty() {
                // A file that cannot be read makes the run fail; it is not stored either way.
                let bytes = std::fs::read(file).ok()?;
                hash.update(format!("\n{name} ").as_bytes());
                hash.update(hex(&Sha256::digest(&bytes)).as_bytes());
            }
        }
        if run.scenario.city.traffic == CityTraffic::Sumo {
            // SUMO drives the cars: another SUMO, other drives.
            let version = self
                .sumo_version
                .get_or_init(|| SumoTools::locate().and_then(|tools| tools.version()).ok());
            hash.update(format!("\nsumo {}", version.as_deref()?).as_bytes());
        }
        Some(hex(&hash.finalize()))
    }

    /// Puts the stored run `key` into `out` and returns its summary, `None` when the store
    /// has no such run. A stored run that is not `run`'s variant and seed is an error.
    pub fn take(&self, key: &str, run: &RunConfig) -> anyhow::Result<Option<Summary>> {
        let stored = self.dir.join(key);
        let file = stored.join("summary.json");
        if !file.is_file() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&file)
            .with_context(|| format!("cannot read {}", file.display()))?;
        let summary: Summary = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a run's summary", file.display()))?;
        anyhow::ensure!(
            summary.variant == run.variant.name() && summary.seed == run.scenario.seed,
            "the run cache's {} is of variant {} seed {}, not {} seed {}",
            stored.display(),
            summary.variant,
            summary.seed,
            run.variant.name(),
            run.scenario.seed
        );
        // The sweep reads the run back from `out` as it reads every run (its time series too).
        link_tree(&stored, &run.out)?;
        Ok(Some(summary))
    }

    /// Stores the finished run in `out` under `key` (kept as it is if already stored).
    pub fn store(&self, key: &str, out: &Path) -> anyhow::Result<()> {
        let target = self.dir.join(key);
        if target.is_dir() {
            return Ok(());
        }
        let temp = self
            .dir
            .join(format!(".partial-{key}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&temp);
        link_tree(out, &temp)?;
        match std::fs::rename(&temp, &target) {
            Ok(()) => Ok(()),
            // Another sweep stored the same run first: the same files.
            Err(_) if target.is_dir() => {
                let _ = std::fs::remove_dir_all(&temp);
                Ok(())
            }
            Err(e) => {
                let _ = std::fs::remove_dir_all(&temp);
                Err(e).with_context(|| format!("cannot store a run as {}", target.display()))
            }
        }
    }
}

/// Makes `to` hold the files of `from` (recursively): hard links where possible, else copies;
/// a file already in `to` is replaced.
fn link_tree(from: &Path, to: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("cannot create {}", to.display()))?;
    let entries =
        std::fs::read_dir(from).with_context(|| format!("cannot list {}", from.display()))?;
    for entry in entries {
        let entry = entry.with_context(|| format!("cannot list {}", from.display()))?;
        let (src, dst) = (entry.path(), to.join(entry.file_name()));
        let kind = entry
            .file_type()
            .with_context(|| format!("cannot read {}", src.display()))?;
        if kind.is_dir() {
            link_tree(&src, &dst)?;
            continue;
        }
        match std::fs::remove_file(&dst) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e).with_context(|| format!("cannot replace {}", dst.display())),
        }
        if std::fs::hard_link(&src, &dst).is_err() {
            std::fs::copy(&src, &dst)
                .with_context(|| format!("cannot copy {} to {}", src.display(), dst.display()))?;
        }
    }
    Ok(())
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::Variant;
    use crate::sweep::collect::tests::fake_run;
    use fleet_observe::faults::Fault;

    /// A store in a fresh directory under the test's temporary directory, for a "build" of
    /// one fake executable holding `build`.
    fn store(name: &str, build: &str) -> (PathBuf, RunCache) {
        let dir =
            std::env::temp_dir().join(format!("setfleet-cache-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("dir");
        let exe = dir.join("fleet");
        std::fs::write(&exe, build).expect("exe");
        let cache = RunCache::with_executables(&dir.join("cache"), &[exe]).expect("cache");
        (dir, cache)
    }

    /// The configuration `fleet sweep` plans for `variant` on `seed` with `overrides`.
    fn planned(variant: Variant, seed: u64, extra: &[&str], faults: &[&str]) -> RunConfig {
        let mut args = vec!["--seeds", "1", "--variants", variant.name()];
        for s in extra {
            args.extend(["--set", s]);
        }
        for f in faults {
            args.extend(["--fault", f]);
        }
        let mut config = crate::sweep::tests::parse(&args).runs.remove(0).config;
        config.scenario.seed = seed;
        config
    }

    #[test]
    fn the_key_changes_with_everything_a_run_depends_on_and_nothing_else() {
        let (dir, cache) = store("key", "build a");
        let base = planned(Variant::Paper, 1, &[], &[]);
        let key = cache.key(&base).expect("a plain run has a key");
        assert_eq!(key.len(), 64);

        // Where it is written and its run id do not matter.
        let mut elsewhere = base.clone();
        elsewhere.out = dir.join("somewhere-else");
        elsewhere.run_id = crate::run::config::new_run_id(7);
        assert_eq!(cache.key(&elsewhere).as_deref(), Some(key.as_str()));

        // The seed, the variant, a scenario key, a kill and the build all do.
        let others = [
            planned(Variant::Paper, 2, &[], &[]),
            planned(Variant::Setfleet, 1, &[], &[]),
            planned(Variant::Paper, 1, &["comms.loss=0.1"], &[]),
            planned(Variant::Paper, 1, &[], &["kill:1@60"]),
        ];
        for other in &others {
            let k = cache.key(other).expect("a key");
            assert_ne!(k, key, "{other:?}");
        }
        let (_, rebuilt) = store("key-rebuilt", "build b");
        assert_ne!(rebuilt.key(&base).expect("a key"), key);

        // Runs that depend on the wall clock have none.
        for faults in [["pause:1@30+5"].as_slice(), &["kill:1@20", "restart:1@60"]] {
            let run = planned(Variant::Paper, 1, &[], faults);
            assert_eq!(cache.key(&run), None, "{faults:?}");
        }
        let mut chaos = base.clone();
        chaos.chaos_seed = Some(3);
        chaos.faults.push(Fault {
            kind: FaultKind::Kill,
            uav: 1,
            at_s: 10.0,
            pause_s: None,
            origin: fleet_observe::faults::FaultOrigin::Chaos,
        });
        assert_eq!(cache.key(&chaos), None);

        // An imported city's scene file is part of the key by its contents, not its path.
        let scene = dir.join("city.json");
        let with_scene = |bytes: &str| {
            std::fs::write(&scene, bytes).expect("scene");
            let mut run = base.clone();
            run.scenario.city.scene = scene.to_string_lossy().into_owned();
            cache.key(&run)
        };
        let (a, a_again, b) = (with_scene("one"), with_scene("one"), with_scene("two"));
        assert!(a.is_some() && a != Some(key.clone()) && a != b);
        assert_eq!(a, a_again);
        std::fs::remove_file(&scene).expect("remove the scene");
        let mut missing = base.clone();
        missing.scenario.city.scene = scene.to_string_lossy().into_owned();
        assert_eq!(cache.key(&missing), None, "a scene that cannot be read");
        // So is a trace file.
        let trace = dir.join("drive.csv");
        let with_trace = |bytes: &str| {
            std::fs::write(&trace, bytes).expect("trace");
            let mut run = base.clone();
            run.scenario.city.trace = trace.to_string_lossy().into_owned();
            cache.key(&run)
        };
        let (a, a_again, b) = (with_trace("one"), with_trace("one"), with_trace("two"));
        assert!(a.is_some() && a != Some(key.clone()) && a != b);
        assert_eq!(a, a_again);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn a_stored_run_is_taken_back_whole_into_another_directory() {
        let (dir, cache) = store("roundtrip", "build");
        let mut run = planned(Variant::Paper, 4, &[], &[]);
        run.out = dir.join("first");
        fake_run(&dir.join("first-sweep"), Variant::Paper, 4, 0.25);
        let made = dir.join("first-sweep").join("paper").join("seed-4");
        std::fs::create_dir_all(made.join("logs")).expect("logs");
        std::fs::write(made.join("logs").join("agent-0.log"), "hello").expect("log");
        let key = cache.key(&run).expect("key");

        assert!(
            cache.take(&key, &run).expect("take").is_none(),
            "nothing stored yet"
        );
        cache.store(&key, &made).expect("store");
        cache
            .store(&key, &made)
            .expect("storing again keeps the first");

        let mut again = run.clone();
        again.out = dir.join("second");
        let summary = cache.take(&key, &again).expect("take").expect("stored");
        assert_eq!((summary.variant.as_str(), summary.seed), ("paper", 4));
        for file in ["summary.json", "timeseries.csv", "logs/agent-0.log"] {
            let a = std::fs::read(made.join(file)).expect("made");
            let b = std::fs::read(again.out.join(file)).expect("taken");
            assert_eq!(a, b, "{file}");
        }
        let leftovers: Vec<_> = std::fs::read_dir(dir.join("cache"))
            .expect("cache")
            .filter_map(Result::ok)
            .filter(|e| e.file_name().to_string_lossy().starts_with(".partial"))
            .collect();
        assert!(leftovers.is_empty(), "{leftovers:?}");

        // A stored run of another seed under the key is refused, not shown as this one.
        let mut seed5 = run.clone();
        seed5.scenario.seed = 5;
        let err = cache.take(&key, &seed5).expect_err("another seed's run");
        assert!(format!("{err:#}").contains("seed 4"), "{err:#}");
        let _ = std::fs::remove_dir_all(dir);
    }
}
