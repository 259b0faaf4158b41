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
            seed: self.seed,
            observer,
        }
    }
}

impl std::fmt::Debug for ChainRun<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ChainRun")
            .field("chains", &self.chains)
            .field("seed", &self.seed)
            .finish_non_exhaustive()
    }
}
