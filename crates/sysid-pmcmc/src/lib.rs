//! Bayesian identification of state-space models: particle marginal
//! Metropolis-Hastings ([`pmmh()`]) and particle Gibbs ([`particle_gibbs`]) with
//! backward simulation or ancestor sampling, with priors, several chains in parallel
//! and convergence diagnostics.
//!
//! # Model
//! A [`ModelFamily`] maps parameters `theta` to a state-space model of `sysid-smc`;
//! a [`Prior`] gives `p(theta)`. The target is `p(theta | y)` (PMMH) or
//! `p(theta, x | y)` (particle Gibbs).
//!
//! # Algorithm
//! See [`pmmh`](mod@pmmh) and [`gibbs`]. Chain `c` of a run seeded by `seed` draws from
//! the random stream `(seed, c)`: results are bit-identical whatever the number of
//! threads.
//!
//! # Complexity
//! One particle filter (PMMH) or one conditional SMC sweep (particle Gibbs) per
//! iteration: O(T M).
//!
//! # References
//! Andrieu, Doucet and Holenstein (2010), *Particle Markov chain Monte Carlo methods*;
//! Lindsten, Jordan and Schön (2014), *Particle Gibbs with ancestor sampling*;
//! Schön et al. (seed 001), Bayesian identification.

mod chain;
pub mod conjugate;
pub mod diagnostics;
mod error;
mod family;
pub mod gibbs;
mod observer;
pub mod pmmh;
pub mod prior;
mod report;
mod support;

pub use chain::Chain;
pub use diagnostics::{
    ParameterSummary, bulk_ess, effective_sample_size, rank_rhat, split_rhat, summarise, tail_ess,
};
pub use error::PmcmcError;
pub use family::ModelFamily;
pub use gibbs::{
    GibbsOptions, MetropolisWithinGibbs, ParameterStep, complete_data_log_likelihood,
    particle_gibbs, particle_gibbs_guided,
};
pub use observer::{ChainObserver, ChainRun};
pub use pmmh::{PmmhOptions, pmmh};
pub use prior::{IndependentPrior, Prior, ScalarPrior};
pub use report::{ACCEPTANCE_LIMIT, ChainReport, ChainWarning, ESS_LIMIT, RHAT_LIMIT};
pub use support::Support;
pub use sysid_smc::CsmcKernel;
