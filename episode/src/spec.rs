//! What an episode is told, as `fleet run` is told it.

use std::path::PathBuf;

use clap::ValueEnum as _;
use protocol::scenario::Scenario;
use protocol::variant::Variant;

use crate::EpisodeError;

/// An episode's run, in `fleet run`'s terms: its flags `--scenario`, `--variant`, `--set`,
/// `--seed`, `--duration`, `--uavs` and `--planner external:...`.
#[derive(Clone, Debug)]
pub struct EpisodeSpec {
    /// The scenario file (`None`: the built-in default, the paper's scenario).
    pub scenario: Option<PathBuf>,
    /// The guidance variant (its name, as `--variant` takes it).
    pub variant: String,
    /// `KEY=VALUE` overrides, applied after the variant's.
    pub overrides: Vec<String>,
    /// The run's seed.
    pub seed: u64,
    /// Simulated seconds (`None`: the scenario's).
    pub duration_s: Option<f64>,
    /// `uavs.count` (`None`: the scenario's).
    pub uavs: Option<u32>,
    /// The UAVs whose decisions the caller takes (`guidance.external_uavs`).
    pub learners: Vec<u32>,
}

impl Default for EpisodeSpec {
    /// The default scenario under the paper's variant, seed 1, no learner.
    fn default() -> Self {
        EpisodeSpec {
            scenario: None,
            variant: Variant::Paper.name().to_owned(),
            overrides: Vec::new(),
            seed: 1,
            duration_s: None,
            uavs: None,
            learners: Vec::new(),
        }
    }
}

impl EpisodeSpec {
    /// The scenario of the run, resolved as `fleet run` resolves its flags: the file, the
    /// variant's settings, the overrides, then the seed, the duration, the fleet's size and the
    /// learners as overrides, so the scenario's checks name the key at fault.
    pub fn scenario(&self) -> Result<Scenario, EpisodeError> {
        let variant = Variant::from_str(&self.variant, true)
            .map_err(|_| EpisodeError::Variant(self.variant.clone()))?;
        let mut overrides = variant.with_user_overrides(&self.overrides);
        overrides.push(format!("seed={}", self.seed));
        if let Some(d) = self.duration_s {
            overrides.push(format!("duration_s={d:?}"));
        }
        if let Some(n) = self.uavs {
            overrides.push(format!("uavs.count={n}"));
        }
        if !self.learners.is_empty() {
            let list: Vec<String> = self.learners.iter().map(u32::to_string).collect();
            overrides.push(format!("guidance.external_uavs=[{}]", list.join(",")));
        }
        Scenario::load(self.scenario.as_deref(), &overrides)
            .map_err(|e| EpisodeError::Scenario(e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flags_become_the_scenarios_keys_and_bad_ones_are_named() {
        let spec = EpisodeSpec {
            variant: "setfleet".to_owned(),
            overrides: vec!["region.half_extent_m=150".to_owned()],
            seed: 9,
            duration_s: Some(12.5),
            uavs: Some(3),
            learners: vec![0, 2],
            ..EpisodeSpec::default()
        };
        let s = spec.scenario().expect("a scenario");
        assert_eq!(s.seed, 9);
        assert_eq!(s.uavs.count, 3);
        assert_eq!(s.duration_s, 12.5);
        assert_eq!(s.region.half_extent_m, 150.0);
        assert!(s.asks_external(0) && !s.asks_external(1) && s.asks_external(2));
        let bad = EpisodeSpec {
            variant: "fastest".to_owned(),
            ..EpisodeSpec::default()
        };
        assert!(matches!(bad.scenario(), Err(EpisodeError::Variant(v)) if v == "fastest"));
        let bad = EpisodeSpec {
            overrides: vec!["region.half_extent_m=-1".to_owned()],
            ..EpisodeSpec::default()
        };
        let err = bad.scenario().expect_err("a bad value").to_string();
        assert!(err.contains("half_extent_m"), "{err}");
    }
}
