//! `sysid`: identification of dynamic systems from data.
//!
//! This facade re-exports the layers:
//!
//! * [`linalg`]: small dense kernels (Cholesky with typed errors, QR triangularisation);
//! * [`kalman`]: linear Gaussian state-space models: simulation, square-root Kalman
//!   filter, RTS smoother with lag-one covariances, exact log-likelihood with missing
//!   data, EM sufficient statistics;
//! * [`subspace`]: N4SID subspace identification (the start of EM);
//! * [`smc`]: particle filter (four resampling schemes, ESS-adaptive) and particle
//!   smoothers (Tanizaki, FFBSi, rejection FFBSi, genealogy);
//! * [`em`]: the EM runner and exact EM for linear Gaussian models;
//! * [`pmcmc`]: Bayesian identification: PMMH and particle Gibbs (ancestor sampling,
//!   backward simulation), priors, parallel chains and diagnostics;
//! * [`models`]: the canonical systems of the source papers;
//! * [`modelfile`]: your own nonlinear model from a model file (equations as
//!   expressions), for every particle method.
//!
//! # Example
//! ```
//! use sysid::prelude::*;
//! let sim = System::Lgss.simulate(500, 42).unwrap();
//! let model = System::Lgss.model();
//! let mut ws = KalmanWorkspace::new();
//! let loglik = ws.loglik(&model, &sim.record).unwrap();
//! assert!(loglik.is_finite());
//! ```

pub use sysid_em as em;
pub use sysid_kalman as kalman;
pub use sysid_linalg as linalg;
pub use sysid_modelfile as modelfile;
pub use sysid_models as models;
pub use sysid_pmcmc as pmcmc;
pub use sysid_smc as smc;
pub use sysid_subspace as subspace;

/// The names most programs need.
pub mod prelude {
    pub use crate::em::affine::{AffineFit, AffineFitOptions, AffineMethod, fit_affine};
    pub use crate::em::linear::{
        LinearFit, LinearFitOptions, LinearFitWarning, OrderChoice, Selection, Signals, Start,
    };
    pub use crate::em::{EmObserver, EmOptions, FitRun, Termination, run_em};
    pub use crate::kalman::{
        Comparison, Horizon, KalmanError, KalmanWorkspace, LinearGaussianModel, ModelSpec, Record,
        SmootherOutput, SufficientStatistics, Trend, TrendKind,
    };
    pub use crate::modelfile::{FileFit, FileFitWarning, Gaussian, GaussianModel, ModelFile};
    pub use crate::models::{LinearGaussianSmc, Nlbench, NlbenchParams, System, fit_wiener};
    pub use crate::pmcmc::{
        Chain, ChainReport, ChainRun, GibbsOptions, IndependentPrior, ModelFamily, PmmhOptions,
        ScalarPrior, particle_gibbs, pmmh, summarise,
    };
    pub use crate::smc::{
        FilterDiagnostics, FilterOptions, ModelError, ParticleFilter, PathSmoother, Resampling,
        Series, SmcError, Smoother, Trajectories,
    };
    pub use crate::subspace::{N4sidOptions, n4sid};
}

#[cfg(doctest)]
#[doc = include_str!("../docs/guide.md")]
pub struct GuideDoctests;
