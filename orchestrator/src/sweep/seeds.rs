//! `--seeds N` or `--seeds A..B`: the seeds a sweep runs every variant on.
//!
//! A count `N` means seeds `1..=N`; a range `A..B` (or `A..=B`, the same) means the seeds `A`
//! to `B`, both included, so `--seeds 101..130` is thirty seeds that no sweep of `--seeds 100`
//! ran. Either way a sweep holds 1 to [`MAX_SEEDS`] seeds, and each is a scenario seed (0 to
//! `i64::MAX`, what a TOML integer holds).

use std::fmt;
use std::ops::RangeInclusive;
use std::str::FromStr;

/// Most seeds a sweep runs.
pub const MAX_SEEDS: u64 = 1000;

/// The largest seed: a scenario's seed is written into its TOML, whose integers are `i64`.
const MAX_SEED: u64 = i64::MAX as u64;

/// The seeds of a sweep: `first..=last`, never empty.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SeedSet {
    first: u64,
    last: u64,
}

/// Why a `--seeds` value is not a set of seeds.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum SeedsParseError {
    /// Neither a whole number nor `A..B` / `A..=B` of two.
    #[error(
        "--seeds {0:?}: expected a number of seeds N (seeds 1..=N) or a range A..B of seeds, \
         both included (also written A..=B), e.g. 30 or 101..130"
    )]
    Malformed(String),
    /// The count is 0 or a range ends before it starts.
    #[error("--seeds {0:?}: no seed in it (a range A..B needs A <= B)")]
    Empty(String),
    /// More than [`MAX_SEEDS`] seeds.
    #[error("--seeds {text:?}: {count} seeds, must be 1 to {MAX_SEEDS}")]
    TooMany {
        /// The value as given.
        text: String,
        /// How many seeds it holds.
        count: u128,
    },
    /// A seed above `i64::MAX`.
    #[error("--seeds {0:?}: a seed must be 0 to {MAX_SEED}")]
    SeedTooLarge(String),
}

impl SeedSet {
    /// Seeds `1..=count`; `None` unless `count` is 1 to [`MAX_SEEDS`].
    pub fn count(count: u64) -> Option<SeedSet> {
        (1..=MAX_SEEDS).contains(&count).then_some(SeedSet {
            first: 1,
            last: count,
        })
    }

    /// Seeds `first..=last`; `None` when that is empty, holds more than [`MAX_SEEDS`] seeds
    /// or a seed above `i64::MAX`.
    pub fn range(first: u64, last: u64) -> Option<SeedSet> {
        (first <= last && last <= MAX_SEED && last - first < MAX_SEEDS)
            .then_some(SeedSet { first, last })
    }

    /// The first seed.
    pub fn first(self) -> u64 {
        self.first
    }

    /// The last seed, included.
    pub fn last(self) -> u64 {
        self.last
    }

    /// How many seeds: 1 to [`MAX_SEEDS`].
    pub fn len(self) -> usize {
        // At most MAX_SEEDS, so it fits.
        (self.last - self.first + 1) as usize
    }

    /// Never: a set holds at least one seed.
    pub fn is_empty(self) -> bool {
        false
    }

    /// The seeds in order.
    pub fn iter(self) -> RangeInclusive<u64> {
        self.first..=self.last
    }
}

impl fmt::Display for SeedSet {
    /// `A..=B`, which parses back to the same set.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}..={}", self.first, self.last)
    }
}

impl FromStr for SeedSet {
    type Err = SeedsParseError;

    fn from_str(text: &str) -> Result<SeedSet, SeedsParseError> {
        let malformed = || SeedsParseError::Malformed(text.to_owned());
        // Digits only: no sign, no spaces, no `0x`; too many digits is a seed too large.
        let number = |s: &str| {
            if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
                return Err(malformed());
            }
            s.parse::<u64>()
                .ok()
                .filter(|&n| n <= MAX_SEED)
                .ok_or_else(|| SeedsParseError::SeedTooLarge(text.to_owned()))
        };
        let (first, last) = match text.split_once("..") {
            None => {
                let count = number(text)?;
                if count == 0 {
                    return Err(SeedsParseError::Empty(text.to_owned()));
                }
                (1, count)
            }
            Some((a, b)) => {
                let b = b.strip_prefix('=').unwrap_or(b);
                (number(a)?, number(b)?)
            }
        };
        if first > last {
            return Err(SeedsParseError::Empty(text.to_owned()));
        }
        SeedSet::range(first, last).ok_or_else(|| SeedsParseError::TooMany {
            text: text.to_owned(),
            count: u128::from(last - first) + 1,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_are_a_count_or_an_inclusive_range() {
        let thirty: SeedSet = "30".parse().unwrap();
        assert_eq!((thirty.first(), thirty.last(), thirty.len()), (1, 30, 30));
        assert_eq!(Some(thirty), SeedSet::count(30));
        let later: SeedSet = "101..130".parse().unwrap();
        assert_eq!((later.first(), later.last(), later.len()), (101, 130, 30));
        assert_eq!("101..=130".parse::<SeedSet>(), Ok(later));
        assert_eq!(
            later.iter().collect::<Vec<_>>(),
            (101..=130).collect::<Vec<_>>()
        );
        assert_eq!(later.to_string().parse::<SeedSet>(), Ok(later));
        assert_eq!("7..7".parse::<SeedSet>().map(SeedSet::len), Ok(1));
        assert_eq!("0..=2".parse::<SeedSet>().map(SeedSet::first), Ok(0));
        assert_eq!("1000".parse::<SeedSet>().map(SeedSet::len), Ok(1000));
        assert_eq!("5..1004".parse::<SeedSet>().map(SeedSet::len), Ok(1000));
        let top = format!("{MAX_SEED}..={MAX_SEED}");
        assert_eq!(top.parse::<SeedSet>().map(SeedSet::len), Ok(1));
    }

    #[test]
    fn bad_seeds_are_refused_naming_the_flag_and_the_reason() {
        for text in [
            "", "a", "a..b", "1..b", "..5", "5..", "..", "-1", "+3", " 3", "3 ", "1...3", "1..=",
            "1..==3", "1.5", "0x10", "1..2..3", "1-3",
        ] {
            assert_eq!(
                text.parse::<SeedSet>(),
                Err(SeedsParseError::Malformed(text.into())),
                "{text:?}"
            );
        }
        for text in ["0", "5..2", "5..=4"] {
            assert_eq!(
                text.parse::<SeedSet>(),
                Err(SeedsParseError::Empty(text.into())),
                "{text:?}"
            );
        }
        for (text, count) in [("1001", 1001), ("1..1001", 1001), ("0..1000", 1001)] {
            assert_eq!(
                text.parse::<SeedSet>(),
                Err(SeedsParseError::TooMany {
                    text: text.into(),
                    count
                }),
                "{text:?}"
            );
        }
        for text in ["99999999999999999999", "1..99999999999999999999"] {
            assert_eq!(
                text.parse::<SeedSet>(),
                Err(SeedsParseError::SeedTooLarge(text.into())),
                "{text:?}"
            );
        }
        let big = format!("{}", MAX_SEED + 1);
        assert!(matches!(
            big.parse::<SeedSet>(),
            Err(SeedsParseError::SeedTooLarge(_))
        ));
        for text in ["0", "5..2", "a..b", "2000"] {
            let e = text.parse::<SeedSet>().unwrap_err().to_string();
            assert!(e.starts_with("--seeds "), "{e}");
        }
        assert_eq!(SeedSet::count(0), None);
        assert_eq!(SeedSet::range(3, 2), None);
    }
}
