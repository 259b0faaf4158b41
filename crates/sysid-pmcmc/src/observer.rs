//! Watching chains as they run (progress bars, logging).

/// Called by the samplers after every iteration of every chain. Chains run in
/// parallel, so an observer must be `Sync`; every method has a default.
pub trait ChainObserver: Sync {
    /// Chain `chain` finished iteration `iteration` (0-based).
    fn iteration(&self, chain: usize, iteration: usize) {
        let _ = (chain, iteration);
    }
}

impl ChainObserver for () {}
