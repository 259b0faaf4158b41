//! The settings every fit run shares: its seed and its stop.

/// How a fit runs: the seed of its random streams, and when to end it early (a
/// user's Ctrl-C, a time budget). The fits that take it ([`crate::affine::fit_affine`],
/// [`crate::affine::fit_robust_until`], a model file's fit) give the same result for
/// the same seed on any number of threads.
///
/// # Example
/// ```
/// use std::sync::atomic::{AtomicBool, Ordering};
/// use sysid_em::FitRun;
/// let interrupted = AtomicBool::new(false);
/// let stop = || interrupted.load(Ordering::Relaxed);
/// let run = FitRun::new(7).stopped_by(&stop);
/// assert_eq!(run.seed, 7);
/// assert!(!(run.stop)());
/// ```
#[derive(Clone, Copy)]
pub struct FitRun<'a> {
    /// The seed of every random stream of the run.
    pub seed: u64,
    /// Asked after every EM iteration: `true` ends the run with what it has.
    pub stop: &'a (dyn Fn() -> bool + Sync),
}

/// The stop that never comes.
fn never() -> bool {
    false
}

impl FitRun<'static> {
    /// A run from `seed` that is never stopped early.
    pub fn new(seed: u64) -> Self {
        FitRun { seed, stop: &never }
    }
}

impl FitRun<'_> {
    /// The same run, ended early when `stop()` turns true.
    pub fn stopped_by(self, stop: &(dyn Fn() -> bool + Sync)) -> FitRun<'_> {
        FitRun {
            seed: self.seed,
            stop,
        }
    }
}

impl std::fmt::Debug for FitRun<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FitRun")
            .field("seed", &self.seed)
            .finish_non_exhaustive()
    }
}
