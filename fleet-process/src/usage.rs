//! What every command's arguments share: where the scenario comes from ([`ScenarioArgs`]) and
//! the error of bad input ([`UsageError`], exit code 2). The `fleet` command line and the
//! commands' libraries both import it.

use std::path::PathBuf;

use clap::Args;
use protocol::scenario::Scenario;

/// Where the scenario comes from: a file and `KEY=VALUE` overrides.
#[derive(Debug, Clone, Default, Args)]
pub struct ScenarioArgs {
    /// Scenario TOML file (default: the paper's scenario).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Overrides a scenario key, e.g. `--set guidance.kappa=0` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
}

impl ScenarioArgs {
    /// Loads and checks the scenario.
    pub fn load(&self) -> Result<Scenario, UsageError> {
        Scenario::load(self.scenario.as_deref(), &self.overrides)
            .map_err(|e| UsageError(format!("bad scenario: {e}")))
    }
}

/// Bad arguments or scenario: `fleet` exits with code 2 and this message.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("{0}")]
pub struct UsageError(pub String);
