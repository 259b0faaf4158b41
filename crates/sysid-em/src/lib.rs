//! Expectation-maximisation for state-space models.
//!
//! * [`runner`]: the one EM loop (stopping rule, trace, monotonicity check, observers)
//!   that every variant uses;
//! * [`linear`]: exact EM for linear Gaussian models with a closed-form M-step.

pub mod linear;
pub mod runner;

pub use runner::{
    EmAlgorithm, EmObserver, EmOptions, EmResult, IterationInfo, OptionsError, Termination,
    relative_change, run_em,
};
