//! How a `fleet` command ended: [`Outcome`] and its exit code (0, 1 or 2, as the README's
//! "The command line" gives them). Each command module returns one; [`crate::dispatch`] turns
//! it into the process's exit code.

/// How a `fleet` command ended, and its exit code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Exit 0.
    Success,
    /// Exit 1: the command failed.
    Failed,
    /// Exit 2: bad arguments or scenario.
    BadInput,
}

impl Outcome {
    /// The process exit code.
    pub fn code(self) -> u8 {
        match self {
            Outcome::Success => 0,
            Outcome::Failed => 1,
            Outcome::BadInput => 2,
        }
    }
}
