//! Expectation-maximisation for state-space models.
//!
//! * [`runner`]: the one EM loop (stopping rule, trace, monotonicity check, observers)
//!   that every variant uses;
//! * [`linear`]: exact EM for linear Gaussian models with a closed-form M-step;
//! * [`affine`]: particle EM for nonlinear models affine in the parameters.

pub mod affine;
pub mod linear;
mod regression;
pub mod runner;

pub use runner::{
    EmAlgorithm, EmObserver, EmOptions, EmResult, IterationInfo, OptionsError, Termination,
    relative_change, run_em,
};
