//! # fleet-bench
//!
//! `fleet bench`'s measurements, each written as a [`BenchReport`] (JSON) and printed as a
//! table: [`render`] (frames), [`ipc`] (moving messages between processes, with its own child
//! binary, `fleet-bench-child`), [`estimator`] (an estimator step) and [`guidance`] (one MPC
//! decision). `fleet bench scale`, which times whole runs of the fleet, lives with the run in
//! the `fleet` command and writes the same report. The report type is shared by every kind: a headline `summary` (the keys docs/design.md names, flattened at
//! the top level of the JSON), one [`BenchCase`] per configuration measured, the machine, the
//! command line and the date.

pub mod estimator;
pub mod guidance;
pub mod ipc;
pub mod render;

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

use serde::Serialize;
use serde::ser::SerializeMap;

pub use fleet_process::stats::Stats;

/// The machine a benchmark ran on.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MachineInfo {
    /// CPU model name from `/proc/cpuinfo` ("unknown" elsewhere).
    pub cpu_model: String,
    /// Logical CPUs this process may use.
    pub cores: usize,
    /// Operating system and architecture.
    pub os: String,
}

impl MachineInfo {
    /// Reads the machine's description.
    pub fn detect() -> MachineInfo {
        let cpu_model = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|text| {
                text.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, v)| v.trim().to_owned())
            })
            .unwrap_or_else(|| "unknown".to_owned());
        MachineInfo {
            cpu_model,
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            os: format!("{} {}", std::env::consts::OS, std::env::consts::ARCH),
        }
    }
}

/// Named measures in the order they were added (printed in that order; JSON as an object).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Metrics(pub Vec<(String, f64)>);

impl Metrics {
    /// Adds a measure.
    pub fn push(&mut self, name: &str, value: f64) {
        self.0.push((name.to_owned(), value));
    }

    /// The order statistics of `s` (median, p10, p90, p99, max, each followed by `suffix`,
    /// e.g. `_ms`), and the sample size `n`.
    pub fn of_stats(s: &Stats, suffix: &str) -> Metrics {
        let mut m = Metrics::default();
        for (name, value) in [
            ("median", s.median),
            ("p10", s.p10),
            ("p90", s.p90),
            ("p99", s.p99),
            ("max", s.max),
        ] {
            m.push(&format!("{name}{suffix}"), value);
        }
        m.push("n", s.n as f64);
        m
    }

    /// A measure by name.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.0.iter().find(|(n, _)| n == name).map(|(_, v)| *v)
    }
}

impl Serialize for Metrics {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in &self.0 {
            map.serialize_entry(k, v)?;
        }
        map.end()
    }
}

/// One configuration measured (e.g. one thread count).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BenchCase {
    /// Short name, e.g. `threads=2`.
    pub name: String,
    /// Parameters of the configuration.
    pub params: BTreeMap<String, serde_json::Value>,
    /// What was measured.
    pub metrics: Metrics,
}

/// A benchmark's report: what `fleet bench KIND --out FILE.json` writes.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BenchReport {
    /// `render`, `ipc`, `estimator`, `guidance`, `scale`.
    pub kind: String,
    /// The command line that produced it.
    pub command: String,
    /// UTC date and time, RFC 3339.
    pub date: String,
    /// The machine.
    pub machine: MachineInfo,
    /// Headline figures (docs/design.md's keys), at the top level of the JSON.
    #[serde(flatten)]
    pub summary: BTreeMap<String, serde_json::Value>,
    /// Per configuration.
    pub cases: Vec<BenchCase>,
}

impl BenchReport {
    /// An empty report of `kind`, stamped with this process's command line, the date and the
    /// machine.
    pub fn new(kind: &str) -> BenchReport {
        BenchReport {
            kind: kind.to_owned(),
            command: std::env::args().collect::<Vec<_>>().join(" "),
            date: fleet_process::clock::utc_now_rfc3339(),
            machine: MachineInfo::detect(),
            summary: BTreeMap::new(),
            cases: Vec::new(),
        }
    }

    /// Prints the machine and a table of the cases.
    pub fn print_table(&self, out: &mut impl Write) -> std::io::Result<()> {
        writeln!(
            out,
            "bench {} on {} ({} cores)",
            self.kind, self.machine.cpu_model, self.machine.cores
        )?;
        let Some(first) = self.cases.first() else {
            return Ok(());
        };
        let names: Vec<&str> = first.metrics.0.iter().map(|(n, _)| n.as_str()).collect();
        let width = names.iter().map(|n| n.len()).max().unwrap_or(8).max(12);
        let case_width = self
            .cases
            .iter()
            .map(|c| c.name.len())
            .max()
            .unwrap_or(4)
            .max(12);
        write!(out, "{:<case_width$}", "case")?;
        for n in &names {
            write!(out, " {n:>width$}")?;
        }
        writeln!(out)?;
        for case in &self.cases {
            write!(out, "{:<case_width$}", case.name)?;
            for n in &names {
                match case.metrics.get(n) {
                    Some(v) => write!(out, " {:>width$}", format_value(v))?,
                    None => write!(out, " {:>width$}", "-")?,
                }
            }
            writeln!(out)?;
        }
        for (k, v) in &self.summary {
            writeln!(out, "{k}: {v}")?;
        }
        Ok(())
    }

    /// Prints the table to stdout and, with `out`, writes the JSON there.
    pub fn publish(&self, out: Option<&Path>) -> anyhow::Result<()> {
        self.print_table(&mut std::io::stdout().lock())?;
        if let Some(path) = out {
            self.write_json(path)?;
            println!("report written to {}", path.display());
        }
        Ok(())
    }

    /// Writes the report as pretty JSON.
    pub fn write_json(&self, path: &Path) -> anyhow::Result<()> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)?;
        }
        std::fs::write(path, serde_json::to_string_pretty(self)? + "\n")?;
        Ok(())
    }
}

fn format_value(v: f64) -> String {
    if v.abs() >= 1e6 {
        format!("{v:.3e}")
    } else if v.abs() >= 100.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.3}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_json_has_the_headline_keys_at_the_top() {
        let mut r = BenchReport::new("render");
        r.summary.insert("frames_per_s".into(), 12.5.into());
        let mut m = Metrics::default();
        m.push("median_ms", 3.0);
        r.cases.push(BenchCase {
            name: "threads=1".into(),
            params: BTreeMap::new(),
            metrics: m,
        });
        let v = serde_json::to_value(&r).unwrap();
        assert_eq!(v["frames_per_s"], 12.5);
        assert_eq!(v["cases"][0]["metrics"]["median_ms"], 3.0);
        assert!(v["machine"]["cores"].as_u64().unwrap() >= 1);
    }
}
