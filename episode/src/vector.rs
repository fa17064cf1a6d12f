//! Several episodes stepped at once, over threads.

use crate::{Episode, EpisodeError};

/// Several episodes, each with its own seed, whose [`Episode::run`]s go at once over up to
/// [`Episodes::threads`] threads: a vector of environments stepped in one call. The episodes
/// share nothing, so each one runs exactly as it would alone.
pub struct Episodes {
    episodes: Vec<Episode>,
    threads: usize,
}

impl Episodes {
    /// `episodes` run over up to `threads` threads (at least 1).
    pub fn new(episodes: Vec<Episode>, threads: usize) -> Episodes {
        Episodes {
            episodes,
            threads: threads.max(1),
        }
    }

    /// The threads a [`Episodes::run`] uses at most.
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// How many episodes.
    pub fn len(&self) -> usize {
        self.episodes.len()
    }

    /// Whether there is none.
    pub fn is_empty(&self) -> bool {
        self.episodes.is_empty()
    }

    /// The episodes.
    pub fn episodes(&self) -> &[Episode] {
        &self.episodes
    }

    /// The episodes back, in order.
    pub fn into_episodes(self) -> Vec<Episode> {
        self.episodes
    }

    /// The episodes, to answer their requests or replace one that finished.
    pub fn episodes_mut(&mut self) -> &mut [Episode] {
        &mut self.episodes
    }

    /// [`Episode::run`] of each episode of `which` (indices), at once over the threads; the
    /// results in `which`'s order. Episodes are dealt to the threads in turn, so each thread
    /// runs about as many.
    ///
    /// # Panics
    /// If an index is out of range or repeated (a caller's bug).
    pub fn run(&mut self, which: &[usize]) -> Vec<Result<bool, EpisodeError>> {
        let mut chosen: Vec<Option<&mut Episode>> = self.episodes.iter_mut().map(Some).collect();
        let mut work: Vec<(usize, &mut Episode)> = which
            .iter()
            .enumerate()
            .map(|(slot, &i)| {
                let episode = chosen[i].take().expect("each episode named once");
                (slot, episode)
            })
            .collect();
        let threads = self.threads.min(work.len()).max(1);
        let mut shares: Vec<Vec<(usize, &mut Episode)>> =
            (0..threads).map(|_| Vec::new()).collect();
        for (n, item) in work.drain(..).enumerate() {
            shares[n % threads].push(item);
        }
        let mut results: Vec<Option<Result<bool, EpisodeError>>> =
            (0..which.len()).map(|_| None).collect();
        let done: Vec<Vec<(usize, Result<bool, EpisodeError>)>> = std::thread::scope(|scope| {
            let mut handles = Vec::new();
            let mut shares = shares.into_iter();
            // The caller's thread runs the first share itself.
            let first = shares.next().unwrap_or_default();
            for share in shares {
                handles.push(scope.spawn(move || run_share(share)));
            }
            let mut done = vec![run_share(first)];
            for handle in handles {
                // A panicking episode is a bug: let it show.
                done.push(
                    handle
                        .join()
                        .unwrap_or_else(|p| std::panic::resume_unwind(p)),
                );
            }
            done
        });
        for (slot, result) in done.into_iter().flatten() {
            results[slot] = Some(result);
        }
        results
            .into_iter()
            .map(|r| r.expect("every episode ran"))
            .collect()
    }
}

fn run_share(share: Vec<(usize, &mut Episode)>) -> Vec<(usize, Result<bool, EpisodeError>)> {
    share
        .into_iter()
        .map(|(slot, episode)| (slot, episode.run()))
        .collect()
}
