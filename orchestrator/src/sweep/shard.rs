//! `--shard K/N`: which share of a sweep's runs one machine runs.
//!
//! A sweep's runs are listed in a fixed order: variant-major, in the order of `--variants`,
//! the seeds of `--seeds` in order within each variant. Run `i` of that list (counting from
//! 0) belongs to shard `i mod N`, and `K` counts from 0 too, so the indices a batch system
//! hands out (`$SLURM_ARRAY_TASK_ID` of `--array=0-15`, a Kubernetes indexed Job's
//! `$JOB_COMPLETION_INDEX`) are the shard numbers as they are. Every shard must be given the
//! same `--seeds`, `--variants` and scenario: the split is a function of the list alone, so
//! the shards are disjoint, together hold every run, and a run's shard never depends on the
//! machine, the time or the other shards. Each shard's directory is a `--merge` input.

use std::fmt;
use std::str::FromStr;

/// One share of a sweep: shard `index` of `count`, holding the runs `i` with
/// `i mod count == index`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    index: u32,
    count: u32,
}

/// Why a `--shard` value is not a shard.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ShardParseError {
    /// Not of the form `K/N` with two whole numbers.
    #[error("{0:?}: expected K/N, shard K (counted from 0) of N, e.g. 0/16")]
    Malformed(String),
    /// `N` is 0.
    #[error("{0:?}: the number of shards N must be at least 1")]
    NoShards(String),
    /// `K` is not below `N`.
    #[error("{text:?}: shard {index} does not exist; shards are counted from 0, so K must be 0 to {}", count - 1)]
    OutOfRange {
        /// The value as given.
        text: String,
        /// `K`.
        index: u32,
        /// `N`.
        count: u32,
    },
}

impl Shard {
    /// The whole sweep as one shard (`0/1`).
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// Shard `index` of `count`; `None` unless `index < count`.
    pub fn new(index: u32, count: u32) -> Option<Shard> {
        (index < count).then_some(Shard { index, count })
    }

    /// `K`, counted from 0.
    pub fn index(self) -> u32 {
        self.index
    }

    /// `N`, the number of shards.
    pub fn count(self) -> u32 {
        self.count
    }

    /// Whether run `run` (its place in the sweep's list, from 0) belongs to this shard.
    pub fn holds(self, run: usize) -> bool {
        run % self.count as usize == self.index as usize
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = ShardParseError;

    fn from_str(text: &str) -> Result<Shard, ShardParseError> {
        let malformed = || ShardParseError::Malformed(text.to_owned());
        let (k, n) = text.split_once('/').ok_or_else(malformed)?;
        // Digits only: no sign, no spaces, no `0x`.
        let number = |s: &str| {
            if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
                return Err(malformed());
            }
            s.parse::<u32>().map_err(|_| malformed())
        };
        let (index, count) = (number(k)?, number(n)?);
        if count == 0 {
            return Err(ShardParseError::NoShards(text.to_owned()));
        }
        Shard::new(index, count).ok_or(ShardParseError::OutOfRange {
            text: text.to_owned(),
            index,
            count,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_and_print_back() {
        for text in ["0/1", "0/16", "15/16", "3/4"] {
            let shard: Shard = text.parse().unwrap();
            assert_eq!(shard.to_string(), text);
        }
        let shard: Shard = "2/5".parse().unwrap();
        assert_eq!((shard.index(), shard.count()), (2, 5));
        assert_eq!(Shard::WHOLE, "0/1".parse().unwrap());
    }

    #[test]
    fn bad_shards_are_told_apart_with_their_reason() {
        for text in [
            "",
            "3",
            "/4",
            "3/",
            "a/4",
            "3/b",
            "-1/4",
            "+1/4",
            " 1/4",
            "1/4 ",
            "1/2/3",
            "1.0/4",
            "0x1/4",
            "99999999999/4",
        ] {
            assert_eq!(
                text.parse::<Shard>(),
                Err(ShardParseError::Malformed(text.into())),
                "{text:?}"
            );
        }
        assert_eq!(
            "0/0".parse::<Shard>(),
            Err(ShardParseError::NoShards("0/0".into()))
        );
        let err = "16/16".parse::<Shard>().unwrap_err();
        assert!(matches!(
            err,
            ShardParseError::OutOfRange {
                index: 16,
                count: 16,
                ..
            }
        ));
        assert!(err.to_string().contains("0 to 15"), "{err}");
        assert!(
            "1/4"
                .parse::<Shard>()
                .is_ok_and(|s| s == Shard::new(1, 4).unwrap())
        );
        assert_eq!(Shard::new(4, 4), None);
    }

    #[test]
    fn the_shards_split_the_runs_into_disjoint_round_robin_shares() {
        for count in 1..=7_u32 {
            for runs in [0_usize, 1, 5, 12, 40] {
                let mut owner = vec![None; runs];
                for index in 0..count {
                    let shard = Shard::new(index, count).unwrap();
                    let mine: Vec<usize> = (0..runs).filter(|&i| shard.holds(i)).collect();
                    // Round robin: the shares differ by at most one run.
                    let fair = runs / count as usize;
                    assert!(mine.len() == fair || mine.len() == fair + 1);
                    for i in mine {
                        assert_eq!(owner[i], None, "run {i} in two shards");
                        owner[i] = Some(index);
                    }
                }
                assert!(owner.iter().all(Option::is_some), "a run in no shard");
            }
        }
        // Run i goes to shard i mod N.
        let s = Shard::new(1, 3).unwrap();
        let held: Vec<usize> = (0..8).filter(|&i| s.holds(i)).collect();
        assert_eq!(held, vec![1, 4, 7]);
        assert!((0..10).all(|i| Shard::WHOLE.holds(i)));
    }
}
