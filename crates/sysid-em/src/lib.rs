//! Expectation-maximisation for state-space models.
//!
//! * [`runner`]: the one EM loop (stopping rule, trace, monotonicity check, observers)
//!   that every variant uses;
//! * [`linear`]: exact EM for linear Gaussian models with a closed-form M-step;
//! * [`affine`]: particle EM for nonlinear models affine in the parameters, and PSAEM;
//! * [`gradient`]: particle EM with a BFGS M-step for any model with log-densities, and
//!   the multi-start direct maximum-likelihood fit of models that are not affine;
//! * [`likelihood_search`]: Nelder–Mead on a particle log-likelihood with common random
//!   numbers (the polish and the direct fit).

pub mod affine;
mod box_qp;
mod fit_run;
pub mod gradient;
pub mod likelihood_search;
pub mod linear;
mod particle_pass;
mod regression;
pub mod runner;
mod settings;

pub use fit_run::FitRun;
pub use runner::{
    CheckedEmOptions, EmAlgorithm, EmObserver, EmOptions, EmResult, IterationInfo, OptionsError,
    Termination, relative_change, remaining_gain, run_em,
};
pub use settings::{FitSettings, SettingError};
