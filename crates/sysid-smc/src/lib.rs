//! Sequential Monte Carlo for nonlinear state-space models: the bootstrap particle
//! filter with four resampling schemes and ESS-adaptive resampling, and the particle
//! smoothers of the source papers (Tanizaki, FFBSi, rejection FFBSi, genealogy).
//!
//! # Model
//! ```text
//! x_0 ~ mu,   x_{t+1} ~ f(. | x_t, u_t, t),   y_t ~ g(. | x_t, u_t, t)
//! ```
//! A model implements the capabilities an algorithm needs ([`InitialSampler`],
//! [`TransitionSampler`], [`ObservationDensity`], [`TransitionDensity`],
//! [`TransitionBound`]).
//!
//! # Algorithm
//! [`ParticleFilter`] runs the bootstrap filter and keeps (optionally) a [`History`];
//! the smoothers of [`smoother`] draw backward trajectories from it or accumulate
//! additive functionals. Weights live in the log domain; random streams are derived
//! from `(seed, piece)` so results are bit-identical for any number of threads.
//!
//! # Complexity
//! Filter O(T M); smoothers between O(T K) and O(T K M), see [`smoother`].
//!
//! # References
//! Schön, Wills and Ninness (2006); Lindsten and Schön (2013), *Backward simulation
//! methods for Monte Carlo statistical inference*; Chopin and Papaspiliopoulos (2020).

mod busy;
pub mod conditional;
mod diagnostics;
mod error;
pub mod filter;
mod guided;
mod history;
mod lanes;
mod model;
pub mod normals;
pub mod resample;
mod series;
use sysid_linalg::simd;
pub mod smoother;
mod streams;
mod systematic;
mod team;
mod trial_numbers;
mod variance;
mod vexp;
pub mod weights;

pub use conditional::{ConditionalSmc, CsmcKernel, CsmcSummary};
pub use diagnostics::{
    FilterDiagnostics, FilterWarning, LOST_FRACTION, LOST_STEPS, LoglikSdMethod, SD_LIMIT,
};
pub use error::{ModelError, SmcError};
pub use filter::{FilterOptions, FilterSummary, ParticleFilter};
pub use guided::GuidedFilter;
pub use history::History;
pub use model::{
    FilterModel, GuidedProposal, InitialDensity, InitialSampler, ObservationDensity,
    ScalarGaussianKernel, StateSpace, TransitionBound, TransitionDensity, TransitionSampler,
};
pub use normals::{add_scaled_normals, fill_standard_normals};
pub use resample::Resampling;
pub use series::Series;
pub use smoother::{
    AdditiveFunctional, Ffbsi, FfbsiReject, Genealogy, PathSmoother, Smoother, SmootherStats,
    Tanizaki, Trajectories,
};
pub use streams::{DEFAULT_SEED, Rng, stream};
pub use variance::VARIANCE_SPAN;
pub use vexp::{exp_shifted_sum, exp_shifted_sum_portable};
pub use weights::normalise_log_weights;
