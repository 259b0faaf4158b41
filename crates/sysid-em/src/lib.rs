//! Expectation-maximisation for state-space models.
//!
//! * [`runner`]: the one EM loop (stopping rule, trace, monotonicity check, observers)
//!   that every variant uses;
//! * [`linear`]: exact EM for linear Gaussian models with a closed-form M-step;
//! * [`affine`]: particle EM for nonlinear models affine in the parameters, and PSAEM;
//! * [`gradient`]: particle EM with a BFGS M-step for any model with log-densities.

pub mod affine;
pub mod gradient;
pub mod linear;
mod regression;
pub mod runner;

pub use runner::{
    EmAlgorithm, EmObserver, EmOptions, EmResult, IterationInfo, OptionsError, Termination,
    relative_change, run_em,
};

/// A seed for piece `k` of the work seeded by `seed` (the particle E-steps' filter and
/// smoother streams).
pub(crate) fn sub_seed(seed: u64, k: u64) -> u64 {
    use rand::RngExt;
    sysid_smc::stream(seed, k).random()
}
