//! Watching chains as they run (progress bars, logging).

/// Called by the samplers after every iteration of every chain. Chains run in
/// parallel, so an observer must be `Sync`; every method has a default.
///
/// # Example
/// Counting iterations across parallel chains:
/// ```
/// use std::sync::atomic::{AtomicUsize, Ordering};
/// use sysid_pmcmc::ChainObserver;
/// struct Counter(AtomicUsize);
/// impl ChainObserver for Counter {
///     fn iteration(&self, _chain: usize, _iteration: usize) {
///         self.0.fetch_add(1, Ordering::Relaxed);
///     }
/// }
/// let counter = Counter(AtomicUsize::new(0));
/// counter.iteration(0, 0);
/// assert_eq!(counter.0.load(Ordering::Relaxed), 1);
/// ```
pub trait ChainObserver: Sync {
    /// Chain `chain` finished iteration `iteration` (0-based).
    fn iteration(&self, chain: usize, iteration: usize) {
        let _ = (chain, iteration);
    }

    /// Asked after every iteration of every chain: `true` ends the chains where they
    /// are (a user's Ctrl-C); each is returned with the draws made so far and marked
    /// [`Chain::interrupted`](crate::Chain::interrupted). Default: never.
    fn should_stop(&self) -> bool {
        false
    }
}

impl ChainObserver for () {}

/// How a set of chains runs: how many, from which seed, and who watches them. Chain
/// `c` draws from the random stream `(seed, c)`, so the draws do not depend on the
/// number of threads; the chains run in parallel on the current rayon pool.
///
/// # Example
/// ```
/// use sysid_pmcmc::ChainRun;
/// let run = ChainRun::new(4, 1);
/// assert_eq!((run.chains, run.seed), (4, 1));
/// ```
#[derive(Clone, Copy)]
pub struct ChainRun<'a> {
    /// Number of chains.
    pub chains: usize,
    /// The index of the first chain (default 0): this run's chains are
    /// `first .. first + chains`, so that chains split over machines
    /// (`starting_at(0)` with 2 chains, `starting_at(2)` with 2) are those of one run of 4.
    pub first: usize,
    /// The seed of the chains' random streams.
    pub seed: u64,
    /// Told of every iteration and asked whether to stop ([`ChainObserver`]).
    pub observer: &'a dyn ChainObserver,
}

impl ChainRun<'static> {
    /// `chains` chains from `seed`, watched by no one.
    pub fn new(chains: usize, seed: u64) -> Self {
        ChainRun {
            chains,
            first: 0,
            seed,
            observer: &(),
        }
    }
}

impl<'a> ChainRun<'a> {
    /// The same run, watched by `observer` (a progress bar, Ctrl-C).
    pub fn observed_by<'b>(self, observer: &'b dyn ChainObserver) -> ChainRun<'b> {
        ChainRun {
            chains: self.chains,
            first: self.first,
            seed: self.seed,
            observer,
        }
    }

    /// The same run's chains `first .. first + chains` (by default `0 .. chains`):
    /// chain `c` draws from the stream `(seed, c)` wherever it runs.
    ///
    /// # Example
    /// ```
    /// use sysid_pmcmc::ChainRun;
    /// let second_half = ChainRun::new(2, 1).starting_at(2);
    /// assert_eq!(second_half.chain_ids().collect::<Vec<_>>(), [2, 3]);
    /// ```
    pub fn starting_at(self, first: usize) -> ChainRun<'a> {
        ChainRun { first, ..self }
    }

    /// The indices of this run's chains.
    pub fn chain_ids(&self) -> std::ops::Range<usize> {
        self.first..self.first.saturating_add(self.chains)
    }
}

impl std::fmt::Debug for ChainRun<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ChainRun")
            .field("chains", &self.chains)
            .field("first", &self.first)
            .field("seed", &self.seed)
            .finish_non_exhaustive()
    }
}
