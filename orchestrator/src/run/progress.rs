//! Progress of a run on stderr: an `indicatif` bar over the steps with the simulated time,
//! the real-time factor, UA, identified targets and violations; when stderr is not a
//! terminal, a log line every ~10 % instead.

use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

use fleet_observe::observe::StepMetrics;

/// The progress display of one run.
pub struct Progress {
    bar: Option<ProgressBar>,
    label: String,
    total: u64,
    started: Instant,
    violations: u64,
    next_decile: u64,
}

impl Progress {
    /// A display over `total` steps, a bar if `bar` (a terminal), else log lines. `label`
    /// names the run (e.g. a sweep's variant and seed).
    pub fn new(total: u64, bar: bool, label: &str) -> Progress {
        let bar = bar.then(|| {
            let b = ProgressBar::new(total);
            let style = ProgressStyle::with_template(
                "{prefix}[{elapsed_precise}] {bar:30.cyan/blue} {pos}/{len} {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar());
            b.set_style(style);
            if !label.is_empty() {
                b.set_prefix(format!("{label} "));
            }
            b
        });
        Progress {
            bar,
            label: label.to_owned(),
            total: total.max(1),
            started: Instant::now(),
            violations: 0,
            next_decile: 1,
        }
    }

    /// Shows a measured step.
    pub fn step(&mut self, m: &StepMetrics) {
        self.violations += u64::from(m.violations);
        let done = m.step + 1;
        let rtf = m.time_s / self.started.elapsed().as_secs_f64().max(1e-9);
        // Means over agents.
        let ua = m.mean.map_or(f64::NAN, |s| s.ua);
        let identified = m.mean.map_or(0.0, |s| s.identified);
        let text = format!(
            "t={:.1}s rtf={rtf:.2} UA={ua:.3} identified={identified} violations={}",
            m.time_s, self.violations
        );
        match &self.bar {
            Some(bar) => {
                bar.set_position(done);
                bar.set_message(text);
            }
            None => {
                if done * 10 >= self.next_decile * self.total {
                    self.next_decile = done * 10 / self.total + 1;
                    let pct = done * 100 / self.total;
                    eprintln!(
                        "{}step {done}/{} ({pct}%) {text}",
                        self.prefix(),
                        self.total
                    );
                }
            }
        }
    }

    /// Notes an event (a fault, an agent exit) above the bar.
    pub fn note(&self, text: &str) {
        match &self.bar {
            Some(bar) => bar.println(format!("{}{text}", self.prefix())),
            None => eprintln!("{}{text}", self.prefix()),
        }
    }

    fn prefix(&self) -> String {
        if self.label.is_empty() {
            String::new()
        } else {
            format!("[{}] ", self.label)
        }
    }

    /// Removes the bar.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
