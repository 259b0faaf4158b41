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
