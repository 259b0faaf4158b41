//! Exact EM for linear Gaussian state-space models (Shumway and Stoffer 1982; Gibson
//! and Ninness 2005; Blocker 2008).
//!
//! # Model
//! ```text
//! x_{t+1} = A x_t + B u_t + w_t,   y_t = C x_t + D u_t + h + e_t
//! w_t ~ N(0, Q),  e_t ~ N(0, R),  x_1 ~ N(mu, P1)
//! ```
//! with several independent records and missing outputs (NaN) allowed.
//!
//! # Algorithm
//! E-step: the square-root Kalman smoother's statistics
//! `H = sum_t E{c_t c_t' | y}`, `c_t = [x_t; u_t; 1; x_{t+1}; y_t]`
//! ([`sysid_kalman::SufficientStatistics`]). M-step: [`m_step`], closed form by the
//! Cholesky route. The [`crate::run_em`] runner owns the loop; exact EM must never
//! decrease the likelihood, and a decrease stops the run as
//! [`crate::Termination::LikelihoodDecreased`].
//!
//! # Complexity
//! One iteration costs one filter + smoother pass with statistics,
//! `O(T (n + p)^3)`, and an `O((2n + m + p)^3)` M-step.
//!
//! # References
//! Shumway and Stoffer, J. Time Series Analysis 3 (1982); Gibson and Ninness,
//! Automatica 41 (2005); Blocker (2008).

mod coordinates;
mod ecm;
mod mstep;
mod objective;
mod pipeline;
mod quasi_newton;
mod scoring;
mod spec;
mod squarem;
mod uncertainty;

pub use mstep::m_step;
pub use objective::LinearObjective;
pub use pipeline::{
    AUTO_MAX_COORDINATES, Acceleration, CheckedLinearFitOptions, EmFailure, FitStatus, Fix,
    FixValue, InformationCriteria, LinearFit, LinearFitError, LinearFitOptions, LinearFitWarning,
    MAX_ORDER, Matrix, OrderChoice, OrderRow, OrderTable, Selection, Signals, SingularPart, Start,
    StartOutcome, Switch, ValidationFit, basis_for_output_matrix, transform_state,
};
pub use quasi_newton::{
    QuasiNewtonOptions, QuasiNewtonOutcome, coordinate_count, maximise_loglik,
    maximise_loglik_until,
};
pub use scoring::{ScoringOptions, ScoringOutcome, maximise_by_scoring};
pub use squarem::SquaremLinearEm;
pub use uncertainty::{
    ParameterEstimate, Uncertainty, UncertaintyError, standard_errors, standard_errors_of,
};

pub use spec::{Covariance, FixedEntries, LinearEmSpec, floor_output_noise, floor_variances};

use crate::{CheckedEmOptions, EmAlgorithm, EmObserver, EmResult, run_em};
use sysid_kalman::{
    KalmanError, KalmanWorkspace, LinearGaussianModel, Record, SufficientStatistics,
};

/// Errors of linear EM.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LinearEmError {
    /// The E-step (filter/smoother) failed.
    #[error("E-step: {0}")]
    Kalman(#[from] KalmanError),
    /// A matrix of the M-step failed a check.
    #[error("M-step: {0}")]
    Linalg(#[from] sysid_linalg::LinalgError),
    /// The data set has no record or no step.
    #[error("the data set has no time steps")]
    NoSteps,
    /// A combination of fixed and free parameters that this M-step does not handle.
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// The spec is inconsistent (a mask of the wrong shape, `S` free with structured
    /// `Q` or `R`).
    #[error("invalid specification: {0}")]
    InvalidSpec(String),
    /// No output is observed anywhere in the data set: nothing to fit.
    #[error("every output of every record is missing: nothing to fit")]
    NoObservations,
    /// The starting model is outside the parameter set of the spec.
    #[error("initial model: {matrix} {reason}")]
    InitialNotInSpec {
        /// The matrix concerned.
        matrix: &'static str,
        /// Why it is refused.
        reason: &'static str,
    },
}

/// Linear EM over a data set of independent records (an [`EmAlgorithm`]).
pub struct LinearEm<'a> {
    records: &'a [Record],
    spec: LinearEmSpec,
    workspace: KalmanWorkspace,
}

impl<'a> LinearEm<'a> {
    /// EM on `records` with the parameters of `spec` free.
    pub fn new(records: &'a [Record], spec: LinearEmSpec) -> Self {
        LinearEm {
            records,
            spec,
            workspace: KalmanWorkspace::new(),
        }
    }

    /// The E-step: statistics and log-likelihood at `model`.
    pub fn e_step(
        &mut self,
        model: &LinearGaussianModel,
    ) -> Result<(SufficientStatistics, f64), LinearEmError> {
        if self.records.is_empty() {
            return Err(LinearEmError::NoSteps);
        }
        let mut stats = SufficientStatistics::new(model.n(), model.m(), model.p());
        let mut loglik = 0.0;
        for (i, record) in self.records.iter().enumerate() {
            loglik += self
                .workspace
                .accumulate_statistics(model, record, i, &mut stats)?;
        }
        Ok((stats, loglik))
    }
}

impl EmAlgorithm for LinearEm<'_> {
    type Estimate = LinearGaussianModel;
    type Error = LinearEmError;

    fn step(
        &mut self,
        current: &LinearGaussianModel,
    ) -> Result<(LinearGaussianModel, f64), LinearEmError> {
        let (stats, loglik) = self.e_step(current)?;
        Ok((m_step(current, &stats, &self.spec)?, loglik))
    }

    fn loglik(&mut self, estimate: &LinearGaussianModel) -> Result<f64, LinearEmError> {
        let mut total = 0.0;
        for (i, record) in self.records.iter().enumerate() {
            record.validate(estimate, i)?;
            total += self.workspace.loglik(estimate, record)?;
        }
        Ok(total)
    }
}

/// Fits a linear Gaussian model by EM from `initial`.
///
/// `initial` must satisfy `spec` ([`LinearEmSpec::check`]); otherwise the result is
/// returned at once with [`crate::Termination::Error`] and
/// [`LinearEmError::InitialNotInSpec`].
///
/// # Example
/// ```
/// use nalgebra::DMatrix;
/// use rand::{SeedableRng, rngs::Xoshiro256PlusPlus};
/// use sysid_em::{EmOptions, linear::{LinearEmSpec, fit}};
/// use sysid_kalman::LinearGaussianModel;
/// let truth = LinearGaussianModel::builder(
///     nalgebra::dmatrix![0.9], nalgebra::dmatrix![1.0], nalgebra::dmatrix![1.0], nalgebra::dmatrix![0.5],
/// ).build().unwrap();
/// let data = truth.simulate(&DMatrix::zeros(0, 500), &mut Xoshiro256PlusPlus::seed_from_u64(3)).unwrap();
/// let start = truth.to_builder().a(nalgebra::dmatrix![0.5]).q(nalgebra::dmatrix![0.3]).build().unwrap();
/// let spec = LinearEmSpec { c: false, mu: false, p1: false, ..LinearEmSpec::default() };
/// let options = EmOptions::default().check().unwrap();
/// let result = fit(start, &[data.record], spec, &options, &mut ());
/// assert!((result.estimate.a()[(0, 0)] - 0.9).abs() < 0.1);
/// ```
pub fn fit(
    initial: LinearGaussianModel,
    records: &[Record],
    spec: LinearEmSpec,
    options: &CheckedEmOptions,
    observer: &mut impl EmObserver<LinearGaussianModel>,
) -> EmResult<LinearGaussianModel, LinearEmError> {
    if let Some(refused) = refuse(&initial, records, &spec) {
        return refused;
    }
    run_em(
        &mut LinearEm::new(records, spec),
        initial,
        options,
        observer,
    )
}

/// The result of an EM run that could not start: `initial` not in `spec`, or no
/// observation at all.
fn refuse(
    initial: &LinearGaussianModel,
    records: &[Record],
    spec: &LinearEmSpec,
) -> Option<EmResult<LinearGaussianModel, LinearEmError>> {
    let observed = records.iter().any(|r| r.y.iter().any(|v| !v.is_nan()));
    let check = if observed {
        spec.check(initial)
    } else {
        Err(LinearEmError::NoObservations)
    };
    let error = check.err()?;
    Some(crate::EmResult {
        estimate: initial.clone(),
        loglik: None,
        trace: Vec::new(),
        iterations: 0,
        termination: crate::Termination::Error {
            iteration: 0,
            error,
        },
        decreases: 0,
        elapsed: std::time::Duration::ZERO,
    })
}

/// What [`fit_squarem`] returns: the run (each iteration a SQUAREM cycle, the trace one
/// entry per cycle) and its cost.
#[derive(Debug, Clone)]
pub struct SquaremResult {
    /// The run, as [`fit`]'s (iterations are cycles).
    pub run: EmResult<LinearGaussianModel, LinearEmError>,
    /// E-steps (filter and smoother passes) spent, the final evaluation included.
    pub e_steps: usize,
    /// Cycles whose extrapolation was kept (the others were plain EM steps).
    pub accepted: usize,
}

/// Fits a linear Gaussian model by EM accelerated by SQUAREM ([`SquaremLinearEm`]),
/// monotone like [`fit`]; `options.max_iterations` counts cycles (three E-steps each).
///
/// # Example
/// ```
/// use nalgebra::{DMatrix, dmatrix};
/// use rand::{SeedableRng, rngs::Xoshiro256PlusPlus};
/// use sysid_em::{EmOptions, linear::{LinearEmSpec, fit, fit_squarem}};
/// use sysid_kalman::LinearGaussianModel;
/// let truth = LinearGaussianModel::builder(dmatrix![0.98], dmatrix![1.0], dmatrix![0.01], dmatrix![1.0])
///     .build().unwrap();
/// let data = truth.simulate(&DMatrix::zeros(0, 500), &mut Xoshiro256PlusPlus::seed_from_u64(3)).unwrap();
/// let start = truth.to_builder().q(dmatrix![0.5]).build().unwrap();
/// let spec = LinearEmSpec { c: false, mu: false, p1: false, ..LinearEmSpec::default() };
/// let options = EmOptions { max_iterations: 5000, tol: 1e-10, ..EmOptions::default() }
///     .check()
///     .unwrap();
/// let records = [data.record];
/// let plain = fit(start.clone(), &records, spec.clone(), &options, &mut ());
/// let fast = fit_squarem(start, &records, spec, &options, &mut ());
/// assert!(fast.e_steps < plain.iterations / 2);
/// assert!((fast.run.loglik.unwrap() - plain.loglik.unwrap()).abs() < 1e-3);
/// ```
pub fn fit_squarem(
    initial: LinearGaussianModel,
    records: &[Record],
    spec: LinearEmSpec,
    options: &CheckedEmOptions,
    observer: &mut impl EmObserver<LinearGaussianModel>,
) -> SquaremResult {
    if let Some(run) = refuse(&initial, records, &spec) {
        return SquaremResult {
            run,
            e_steps: 0,
            accepted: 0,
        };
    }
    let mut algorithm = SquaremLinearEm::new(records, spec);
    let run = run_em(&mut algorithm, initial, options, observer);
    let final_evaluation = matches!(run.termination, crate::Termination::MaxIterations) as usize;
    SquaremResult {
        run,
        e_steps: algorithm.e_steps + final_evaluation,
        accepted: algorithm.accepted,
    }
}
