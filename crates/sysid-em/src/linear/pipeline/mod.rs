//! The whole linear fit as one call: what `sysid fit lti` does, for a program.
//!
//! [`LinearFit::run`] takes a record ([`Signals`]) and checked options
//! ([`LinearFitOptions::check`]) and does, in order:
//!
//! 1. the split: the first fraction of the steps is fitted, the rest scored;
//! 2. detrending (a mean or a line per signal, [`sysid_kalman::Trend`]);
//! 3. the start: N4SID at the order (its `S` and `mu` set to zero) or a given model,
//!    with the training record's initial state;
//! 4. fixed and diagonal matrices, bounds on the noise variances (`R` is diagonal for
//!    several outputs unless a full one is asked for);
//! 5. EM, accelerated by SQUAREM unless asked otherwise; an output-error model
//!    (`Q` held at zero) skips EM, which cannot move it;
//! 6. the quasi-Newton polish of the exact log-likelihood (by default when at most 20
//!    coordinates are free);
//! 7. standard errors from the observed information (by default for at most 20 free
//!    coordinates, not for a black-box model);
//! 8. the written model: means folded into its offsets, and a new record's initial
//!    state (`stationary` for a stable `A`, `diffuse` otherwise) unless the user's;
//! 9. information criteria, the fits on the held-out steps, and the warnings.
//!
//! With an order range, every order is fitted first (without polish and standard
//! errors), tabulated, and the chosen one fitted in full: the data are given once.
//!
//! # Example
//! ```
//! use sysid_em::linear::{LinearFit, LinearFitOptions, OrderChoice, Signals};
//! use sysid_kalman::LinearGaussianModel;
//! use nalgebra::{DMatrix, dmatrix};
//! use rand::{SeedableRng, rngs::Xoshiro256PlusPlus};
//! let truth = LinearGaussianModel::builder(dmatrix![0.9], dmatrix![1.0], dmatrix![0.2], dmatrix![0.1])
//!     .b(dmatrix![0.5])
//!     .build()?;
//! let u = DMatrix::from_fn(1, 400, |_, t| (t as f64 * 0.37).sin());
//! let record = truth.simulate(&u, &mut Xoshiro256PlusPlus::seed_from_u64(1))?.record;
//! let mut options = LinearFitOptions::default();
//! options.order = OrderChoice::Fixed(1);
//! let fit = LinearFit::run(&Signals::new(record), &options.check()?, &mut ())?;
//! assert!(fit.loglik.is_some() && fit.warnings.is_empty());
//! assert!((fit.model.a()[(0, 0)] - 0.9).abs() < 0.1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod diagnosis;
mod fix;
mod options;
mod orders;
mod signals;
mod warning;

pub use diagnosis::SingularPart;
pub use fix::{Fix, FixValue, Matrix, basis_for_output_matrix, transform_state};
pub use options::{
    Acceleration, CheckedLinearFitOptions, LinearFitOptions, MAX_ORDER, OrderChoice, Selection,
    Start, Switch,
};
pub use orders::{OrderRow, OrderTable};
pub use signals::Signals;
pub use warning::LinearFitWarning;

use crate::linear::{
    Covariance, LinearEmError, LinearEmSpec, LinearObjective, ScoringOptions, ScoringOutcome,
    Uncertainty, coordinate_count, fit, fit_squarem, maximise_by_scoring, standard_errors_of,
};
use crate::{EmObserver, EmOptions, EmResult, Termination};
use nalgebra::DVector;
use std::time::{Duration, Instant};
use sysid_kalman::{
    InitialState, KalmanError, LinearGaussianModel, Metadata, ModelSpec, ParameterCovariance,
    Trend, TrendError, fit_percent,
};
use sysid_subspace::{
    N4sidOptions, Order, SubspaceError, Weighting, WeightingChoice, n4sid, spectral_radius,
};

/// `Switch::Auto` gives standard errors when the free coordinates are at most this many
/// (the observed information costs about twice their square in filter passes).
pub const AUTO_MAX_COORDINATES: usize = 20;

/// `Switch::Auto` finishes EM by scoring when the free coordinates are at most this
/// many (an iteration costs twice as many filter passes; a black-box model of order 8
/// with two inputs and outputs has 138).
pub const AUTO_MAX_FINISH_COORDINATES: usize = 400;

/// With a polish to follow, EM hands over when it is this many nats from its maximum
/// (by its own estimate).
const POLISH_SWITCH_NATS: f64 = 1e-2;

/// Why a linear fit could not give a model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LinearFitError {
    /// An option (named by its field in [`LinearFitOptions`]) is invalid, alone or for
    /// these data.
    #[error("{option}: {message}")]
    InvalidOption {
        /// The field.
        option: &'static str,
        /// What is wrong and what to do.
        message: String,
    },
    /// A model failed a check or could not be evaluated.
    #[error("{context}: {source}")]
    Kalman {
        /// The step of the fit.
        context: &'static str,
        /// The error.
        source: KalmanError,
    },
    /// The N4SID start failed.
    #[error("{0}")]
    Subspace(#[from] SubspaceError),
    /// Detrending failed.
    #[error("detrend: {0}")]
    Trend(#[from] TrendError),
    /// EM failed at its start (no visible cause in the data).
    #[error("{0}")]
    Em(#[from] LinearEmError),
    /// The start model fails on the data, for a visible reason (a singular `R` or
    /// `Q`) with the options that avoid it.
    #[error("{message}")]
    StartFailed {
        /// The reason and the remedy.
        message: String,
    },
    /// No order of a range could be fitted.
    #[error("no order in {from}..{to} could be fitted")]
    NoOrder {
        /// The range's first order.
        from: usize,
        /// Its last.
        to: usize,
    },
    /// The observer stopped a fit of an order range before the chosen order's.
    #[error("interrupted while fitting order {order} of the range")]
    Interrupted {
        /// The order being fitted.
        order: usize,
    },
}

/// How a fit ended: EM's termination, unless the polish decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum FitStatus {
    /// At the maximum (EM's criterion, or the polish's).
    Converged,
    /// The polish stopped short of its criterion.
    NotConverged,
    /// EM at its iteration limit.
    MaxIterations,
    /// Exact EM lowered the likelihood (the better model is kept).
    LikelihoodDecreased,
    /// EM failed (the last good model is kept).
    Error,
    /// The observer stopped the run.
    Interrupted,
}

impl FitStatus {
    /// `converged`, `not_converged`, `max_iterations`, `likelihood_decreased`,
    /// `error` or `interrupted`.
    pub fn name(self) -> &'static str {
        match self {
            FitStatus::Converged => "converged",
            FitStatus::NotConverged => "not_converged",
            FitStatus::MaxIterations => "max_iterations",
            FitStatus::LikelihoodDecreased => "likelihood_decreased",
            FitStatus::Error => "error",
            FitStatus::Interrupted => "interrupted",
        }
    }

    /// The EM runner's termination.
    pub fn of_em(termination: &Termination<LinearEmError>) -> FitStatus {
        match termination {
            Termination::Converged => FitStatus::Converged,
            Termination::MaxIterations => FitStatus::MaxIterations,
            Termination::LikelihoodDecreased { .. } => FitStatus::LikelihoodDecreased,
            Termination::Error { .. } => FitStatus::Error,
            Termination::Interrupted { .. } => FitStatus::Interrupted,
        }
    }
}

/// The log-likelihood penalised by the identifiable parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InformationCriteria {
    /// Identifiable free parameters: the free coordinates, less the `n^2` of a change
    /// of state basis for a black-box model (free `A` and `C`).
    pub parameters: usize,
    /// Observed output values.
    pub observed: usize,
    /// `-2 l + 2 k`.
    pub aic: Option<f64>,
    /// `-2 l + k ln(observed)`.
    pub bic: Option<f64>,
}

/// The written model's fits on the steps held out by the split, in the data's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValidationFit {
    /// Held-out steps.
    pub rows: usize,
    /// Simulation fit (percent, mean over outputs).
    pub simulation_fit_percent: Option<f64>,
    /// One-step prediction fit (percent, mean over outputs).
    pub prediction_fit_percent: Option<f64>,
}

/// One start of a fit from several (the subspace weightings of an N4SID start).
#[derive(Debug, Clone, PartialEq)]
pub struct StartOutcome {
    /// The weighting of its subspace fit.
    pub weighting: Option<Weighting>,
    /// EM's own objective at its end.
    pub em_loglik: Option<f64>,
    /// The written model's log-likelihood at EM's end (what ranks the starts).
    pub loglik: f64,
    /// EM iterations.
    pub em_iterations: usize,
}

/// EM failed after its start: the last good model is the result.
#[derive(Debug, Clone, PartialEq)]
pub struct EmFailure {
    /// The error.
    pub error: LinearEmError,
    /// The iteration that failed.
    pub iteration: usize,
    /// The cause visible in the data and the option that avoids it, or a request for
    /// a bug report.
    pub diagnosis: String,
    /// Whether the cause is the data's (a collapsing variance).
    pub data_cause: bool,
}

/// The result of [`LinearFit::run`].
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct LinearFit {
    /// The estimate as fitted: of the detrended training record, with its initial state.
    pub estimate: LinearGaussianModel,
    /// The model to use and save: of the original signals (means folded into its
    /// offsets), its initial state as [`LinearFit::initial`] says.
    pub model: LinearGaussianModel,
    /// A new record's initial state for [`LinearFit::model`]: stationary for a stable
    /// `A`, diffuse otherwise, or the model's own when the user estimated or fixed it.
    pub initial: InitialState,
    /// The trend removed before the fit (a linear one is stored beside the model).
    pub trend: Option<Trend>,
    /// The log-likelihood of the training record under the written model:
    /// [`LinearFit::model`] with the initial state [`LinearFit::initial`] (what `sysid
    /// loglik` gives the file on the training rows). With the finish, the maximum.
    pub loglik: Option<f64>,
    /// EM's own objective at its last iterate: the training record's log-likelihood with
    /// the initial state EM holds (the start's, or `--initial`'s), the scale of
    /// [`LinearFit::trace`].
    pub em_loglik: Option<f64>,
    /// The log-likelihood after every EM iteration (cycle, with SQUAREM).
    pub trace: Vec<f64>,
    /// EM iterations (cycles) from the start that was finished.
    pub iterations: usize,
    /// Every start EM ran from, when there were several (the best was finished).
    pub starts: Vec<StartOutcome>,
    /// E-steps (filter and smoother passes).
    pub e_steps: usize,
    /// How EM was run.
    pub acceleration: Acceleration,
    /// How the fit ended.
    pub status: FitStatus,
    /// The EM runner's own termination.
    pub em_termination: Termination<LinearEmError>,
    /// The scoring finish, when it ran ([`crate::linear::maximise_by_scoring`]).
    pub polish: Option<ScoringOutcome>,
    /// Standard errors and their covariance, when given.
    pub uncertainty: Option<Uncertainty>,
    /// AIC and BIC.
    pub criteria: InformationCriteria,
    /// Fits on the held-out steps (with a split).
    pub validation: Option<ValidationFit>,
    /// Every order of a range (with an order range).
    pub order_table: Option<OrderTable>,
    /// Why the result should not be trusted as it is.
    pub warnings: Vec<LinearFitWarning>,
    /// EM failed mid-run (the estimate is the last good model).
    pub failure: Option<EmFailure>,
    /// Why exact EM lowered the likelihood (with [`FitStatus::LikelihoodDecreased`]).
    pub decrease_diagnosis: Option<String>,
    /// Time spent.
    pub elapsed: Duration,
}

impl LinearFit {
    /// Fits a linear Gaussian state-space model to `data` as the options say (see the
    /// module's documentation for the steps). `observer` sees every EM iteration and
    /// may stop the run ([`EmObserver::should_stop`]): the result is then the estimate
    /// so far, with [`FitStatus::Interrupted`].
    ///
    /// # Errors
    /// [`LinearFitError`]: an option invalid for these data, a start that fails on
    /// them (with the cause and the remedy when one is visible), detrending that cannot
    /// be done. A failure of EM after its start is not an error: the last good model
    /// is returned with [`LinearFit::failure`].
    pub fn run(
        data: &Signals,
        options: &CheckedLinearFitOptions,
        observer: &mut impl EmObserver<LinearGaussianModel>,
    ) -> Result<LinearFit, LinearFitError> {
        if data.record.y.nrows() == 0 {
            return Err(LinearFitError::InvalidOption {
                option: "data",
                message: "the record has no output to fit".into(),
            });
        }
        match options.order {
            OrderChoice::Range { from, to, select } => {
                orders::fit_range(data, options, (from, to), select, observer)
            }
            OrderChoice::Fixed(n) => fit_order(data, options, Some(n), observer),
            OrderChoice::OfStart => fit_order(data, options, None, observer),
        }
    }

    /// The fit's entries of a model file's metadata (order, log-likelihood, criteria,
    /// termination, detrending, the parameters' covariance); the data's entries
    /// (names, source) are the caller's.
    pub fn metadata(&self) -> Metadata {
        Metadata {
            order: Some(self.estimate.n()),
            loglik: self.loglik,
            parameters: Some(self.criteria.parameters),
            aic: self.criteria.aic,
            bic: self.criteria.bic,
            termination: Some(self.status.name().to_string()),
            detrend: self.trend.as_ref().map(Trend::describe),
            covariance: self.uncertainty.as_ref().map(|u| ParameterCovariance {
                names: u.parameters.iter().map(|p| p.name.clone()).collect(),
                matrix: (0..u.covariance.nrows())
                    .map(|i| u.covariance.row(i).iter().copied().collect())
                    .collect(),
            }),
            ..Metadata::default()
        }
    }

    /// The model file to write: [`LinearFit::model`] with its initial state and
    /// [`LinearFit::metadata`].
    pub fn model_spec(&self) -> ModelSpec {
        let mut spec = ModelSpec::with_initial(&self.model, self.initial);
        spec.metadata = Some(self.metadata());
        spec
    }
}

/// One order (or the start's), fitted in full.
fn fit_order(
    data: &Signals,
    options: &CheckedLinearFitOptions,
    order: Option<usize>,
    observer: &mut impl EmObserver<LinearGaussianModel>,
) -> Result<LinearFit, LinearFitError> {
    let (training, held_out) = split(data, options)?;
    fit_prepared(training, held_out.as_ref(), options, order, observer)
}

/// The training steps and, with a split, the held-out ones.
fn split(
    data: &Signals,
    options: &CheckedLinearFitOptions,
) -> Result<(Signals, Option<Signals>), LinearFitError> {
    Ok(match options.split {
        Some(fraction) => {
            let (first, rest) = data.split(fraction)?;
            (first, Some(rest))
        }
        None => (data.clone(), None),
    })
}

/// The training record's model and the steps of the fit after the split.
fn fit_prepared(
    mut training: Signals,
    held_out: Option<&Signals>,
    options: &CheckedLinearFitOptions,
    order: Option<usize>,
    observer: &mut impl EmObserver<LinearGaussianModel>,
) -> Result<LinearFit, LinearFitError> {
    let started = Instant::now();
    let trend = match options.detrend {
        Some(kind) => {
            let trend = Trend::estimate(&training.record, &training.time, kind)?;
            trend.remove_from(&mut training.record, &training.time);
            Some(trend)
        }
        None => None,
    };
    let base = LinearEmSpec {
        min_variance: options.min_variance,
        h: options.offset,
        mu: options.estimate_initial,
        p1: options.estimate_initial,
        output_noise_floor: output_noise_floor(&training, options.min_output_noise)?,
        ..LinearEmSpec::default()
    };
    let (candidates, mut warnings) = start_models(&training, options, order, &base)?;
    let records = std::slice::from_ref(&training.record);
    // the user's own initial state is kept in the written model: estimated or fixed
    // mu, P1, or a start file's own (statsmodels' `initialize_known`)
    let user_initial = options.estimate_initial
        || options
            .fixes
            .iter()
            .any(|f| matches!(f.matrix, Matrix::P1 | Matrix::Mu))
        || matches!(
            (&options.start, options.initial),
            (
                Start::Model {
                    initial: InitialState::Given,
                    ..
                },
                InitialState::Given
            )
        );
    // EM from every start; the best by the written model's likelihood is finished
    let mut starts = Vec::new();
    let mut chosen: Option<(
        Candidate,
        EmResult<LinearGaussianModel, LinearEmError>,
        usize,
        f64,
    )> = None;
    let mut first_failure = None;
    let mut total_e_steps = 0;
    let several = candidates.len() > 1;
    for candidate in candidates {
        let polish_on = candidate.finish_on(options.polish);
        let (run, e_steps) = if candidate.output_error() {
            match sysid_kalman::loglik_dataset(&candidate.model, records) {
                Ok(loglik) => (unmoved(candidate.model.clone(), loglik), 0),
                Err(e) => {
                    first_failure.get_or_insert((e.into(), candidate));
                    continue;
                }
            }
        } else {
            run_em(
                &candidate.model,
                records,
                &candidate.spec,
                options,
                polish_on,
                observer,
            )?
        };
        total_e_steps += e_steps;
        if let Termination::Error { error, iteration } = &run.termination
            && (*iteration <= 1 || run.loglik.is_none())
        {
            first_failure.get_or_insert((error.clone(), candidate));
            continue;
        }
        let written = written_initial(&run.estimate, user_initial, options.initial);
        let value = LinearObjective::new(records, written)
            .loglik(&run.estimate, &mut sysid_kalman::KalmanWorkspace::new())
            .unwrap_or(f64::NEG_INFINITY);
        starts.push(StartOutcome {
            weighting: candidate.weighting,
            em_loglik: run.loglik,
            loglik: value,
            em_iterations: run.iterations,
        });
        let interrupted = matches!(run.termination, Termination::Interrupted { .. });
        if chosen.as_ref().is_none_or(|c| value > c.3 || c.3.is_nan()) {
            chosen = Some((candidate, run, e_steps, value));
        }
        if interrupted {
            break;
        }
    }
    let Some((candidate, mut run, _, written_value)) = chosen else {
        let (error, candidate) = first_failure.expect("a start was tried");
        return Err(start_failure(
            error,
            &candidate.model,
            &training,
            &candidate.spec,
        ));
    };
    if !several {
        starts.clear();
    }
    let e_steps = total_e_steps;
    let polish_on = candidate.finish_on(options.polish);
    let Candidate {
        model: start, spec, ..
    } = candidate;
    let coordinates = coordinate_count(&start, &spec);
    let feasible = coordinates > 0 && coordinates <= AUTO_MAX_COORDINATES;
    let interrupted = matches!(run.termination, Termination::Interrupted { .. });
    // the finish maximises the likelihood with the initial state the written model
    // gives a record, so that the log-likelihood reported is the file's
    let initial = written_initial(&run.estimate, user_initial, options.initial);
    let objective = LinearObjective::new(records, initial);
    let em_loglik = run.loglik;
    let mut polish = None;
    if polish_on
        && !interrupted
        && run.loglik.is_some()
        && !matches!(run.termination, Termination::Error { .. })
    {
        let stop = || observer.should_stop();
        let outcome = maximise_by_scoring(
            &run.estimate,
            &objective,
            &spec,
            &ScoringOptions::default(),
            &stop,
        )?;
        run.estimate = outcome.model.clone();
        if outcome.interrupted {
            // Ctrl-C in the finish: the fit ends as interrupted, with EM's estimate or
            // the better point the finish had reached
            run.termination = Termination::Interrupted {
                iteration: run.iterations,
            };
        }
        polish = Some(outcome);
    }
    // the written model's log-likelihood of the training record (what `sysid loglik`
    // of the file gives it)
    if run.loglik.is_some() {
        run.loglik = objective
            .loglik(&run.estimate, &mut sysid_kalman::KalmanWorkspace::new())
            .ok();
    }
    let failure = match &run.termination {
        Termination::Error { error, iteration } if *iteration > 1 && run.loglik.is_some() => {
            let (diagnosis, data_cause) = match error {
                LinearEmError::Kalman(KalmanError::DiffuseNotIdentified { .. }) => (
                    "EM reached a model with a state the outputs hardly see, whose diffuse \
                     initial value the record cannot determine (an order high for the data): \
                     try a lower order, or the stationary initial state (--initial model)"
                        .into(),
                    true,
                ),
                _ => diagnosis::decrease_diagnosis(&run.estimate, &training, &spec),
            };
            Some(EmFailure {
                error: error.clone(),
                iteration: *iteration,
                diagnosis,
                data_cause,
            })
        }
        Termination::Error { error, .. } => {
            return Err(start_failure(error.clone(), &start, &training, &spec));
        }
        _ => None,
    };
    // a polish that ran and stopped short of its own criterion (not at a boundary,
    // which is reported apart) leaves an unconverged estimate, whatever EM did
    // (an interrupted one is reported as the interruption)
    let polish_short = polish
        .as_ref()
        .filter(|p| !p.converged && !p.boundary && !p.interrupted);
    let status = if polish.as_ref().is_some_and(|p| p.converged) {
        FitStatus::Converged
    } else if polish_short.is_some() {
        FitStatus::NotConverged
    } else {
        FitStatus::of_em(&run.termination)
    };
    if status == FitStatus::MaxIterations {
        let last_gain = match run.trace[..] {
            [.., a, b] => b - a,
            _ => f64::NAN,
        };
        warnings.push(LinearFitWarning::MaxIterations {
            max_iterations: options.max_iterations,
            last_gain,
            polished: polish_on,
        });
    }
    if let Some(p) = polish_short {
        warnings.push(LinearFitWarning::PolishShort {
            status: p.status.clone(),
            gain: p.loglik - p.loglik_before,
            distance: p.distance,
            identified: p.identified,
            coordinates: p.parameters,
        });
    }
    if let Some(em) = em_loglik
        && initial == InitialState::Stationary
        && em - written_value > TRANSIENT_NATS
    {
        warnings.push(LinearFitWarning::TransientStart {
            nats: em - written_value,
        });
    }
    if let Some(p) = polish.as_ref().filter(|p| p.boundary && !p.converged) {
        warnings.push(LinearFitWarning::PolishAtBoundary {
            status: p.status.clone(),
        });
    }
    warnings.extend(
        diagnosis::collapsed(&run.estimate, &spec, &training)
            .into_iter()
            .map(LinearFitWarning::Collapsed),
    );
    // an A the user held (a trend or seasonal model's unit roots) is theirs to choose
    let radius = spectral_radius(run.estimate.a());
    if spec.a && radius >= 1.0 {
        warnings.push(LinearFitWarning::Unstable {
            spectral_radius: radius,
        });
    }
    let model = match &trend {
        Some(t) => t.written_model(&run.estimate)?,
        None => run.estimate.clone(),
    };
    let want_errors = match options.std_errors {
        Switch::On => true,
        Switch::Off => false,
        // a black-box model (free A and C, one state included: its scale is free) is
        // not identifiable: no errors unless asked
        Switch::Auto => feasible && !(spec.a && spec.c),
    };
    let uncertainty = match (want_errors
        && !matches!(run.termination, Termination::Interrupted { .. }))
    .then(|| standard_errors_of(&run.estimate, &objective, &spec))
    {
        Some(Ok(u)) => Some(u),
        Some(Err(e)) => {
            warnings.push(LinearFitWarning::NoStandardErrors {
                reason: e.to_string(),
            });
            None
        }
        None => None,
    };
    let observed = training.record.y.iter().filter(|v| !v.is_nan()).count();
    // a black-box model's entries have n^2 redundant directions (a change of state
    // basis changes them, not the likelihood): the criteria count the others
    let parameters = if spec.a && spec.c {
        coordinates.saturating_sub(run.estimate.n().pow(2))
    } else {
        coordinates
    };
    let k = parameters as f64;
    let criteria = InformationCriteria {
        parameters,
        observed,
        aic: run.loglik.map(|l| -2.0 * l + 2.0 * k),
        bic: run.loglik.map(|l| -2.0 * l + k * (observed as f64).ln()),
    };
    let validation = match held_out {
        Some(rest) => Some(validation_fit(&model, initial, trend.as_ref(), rest)?),
        None => None,
    };
    let decrease_diagnosis = matches!(run.termination, Termination::LikelihoodDecreased { .. })
        .then(|| diagnosis::decrease_diagnosis(&run.estimate, &training, &spec).0);
    Ok(LinearFit {
        estimate: run.estimate,
        model,
        initial,
        trend,
        loglik: run.loglik,
        em_loglik,
        trace: run.trace,
        iterations: run.iterations,
        starts,
        e_steps,
        acceleration: options.acceleration,
        status,
        em_termination: run.termination,
        polish,
        uncertainty,
        criteria,
        validation,
        order_table: None,
        warnings,
        failure,
        decrease_diagnosis,
        elapsed: started.elapsed(),
    })
}

/// A start of EM: the model, what EM estimates from it, and the subspace weighting that
/// gave it (an N4SID start).
struct Candidate {
    model: LinearGaussianModel,
    spec: LinearEmSpec,
    weighting: Option<Weighting>,
}

impl Candidate {
    /// An output-error model (`Q` held at zero): EM cannot move `A` (the smoothed states
    /// are then a deterministic function of the parameters), so the likelihood is
    /// maximised directly.
    fn output_error(&self) -> bool {
        self.spec.q == Covariance::Fixed && self.model.q().iter().all(|&v| v == 0.0)
    }

    /// Whether the scoring finish runs after EM: as `polish` says (`Auto`: for 1 to
    /// [`AUTO_MAX_FINISH_COORDINATES`] free coordinates), and always for an output-error
    /// model, which EM cannot move.
    fn finish_on(&self, polish: Switch) -> bool {
        let coordinates = coordinate_count(&self.model, &self.spec);
        self.output_error()
            || match polish {
                Switch::On => true,
                Switch::Off => false,
                Switch::Auto => coordinates > 0 && coordinates <= AUTO_MAX_FINISH_COORDINATES,
            }
    }
}

/// The initial state the written model gives a record: the user's own (estimated or
/// fixed `mu`, `P1`), else stationary for a stable `A` and diffuse otherwise.
/// A stationary initial state that costs more than this many nats against the start's
/// (at EM's estimate) is said: the record probably starts away from equilibrium.
const TRANSIENT_NATS: f64 = 10.0;

fn written_initial(
    model: &LinearGaussianModel,
    user_initial: bool,
    chosen: InitialState,
) -> InitialState {
    if user_initial {
        InitialState::Given
    } else if chosen == InitialState::Diffuse {
        InitialState::Diffuse
    } else if spectral_radius(model.a()) < 1.0 {
        InitialState::Stationary
    } else {
        InitialState::Diffuse
    }
}

/// The starts of EM on the (detrended) training record, with the fixes and diagonal
/// covariances applied to each and to its spec, and the starts' warnings: one N4SID fit
/// per weighting of the start's choice (all three under `Auto`; a weighting that fails
/// is left out unless all do), or the user's model.
fn start_models(
    training: &Signals,
    options: &CheckedLinearFitOptions,
    order: Option<usize>,
    base: &LinearEmSpec,
) -> Result<(Vec<Candidate>, Vec<LinearFitWarning>), LinearFitError> {
    let given: Vec<(LinearGaussianModel, Option<Weighting>)> = match &options.start {
        Start::N4sid { stable, weighting } => {
            let n = order.ok_or_else(|| LinearFitError::InvalidOption {
                option: "order",
                message: "an N4SID start needs a model order (--order n)".into(),
            })?;
            let weightings = match weighting {
                WeightingChoice::Auto => vec![Weighting::Moesp, Weighting::N4sid, Weighting::Cva],
                WeightingChoice::Fixed(w) => vec![*w],
            };
            let mut fits = Vec::new();
            let mut first_error = None;
            for w in weightings {
                let fitted = n4sid(
                    &training.record,
                    &N4sidOptions {
                        order: Order::Fixed(n),
                        stable: *stable,
                        weighting: w,
                        ..Default::default()
                    },
                );
                match fitted {
                    // linear EM holds S fixed; start from the subspace model without it
                    Ok(result) => fits.push((
                        result
                            .model
                            .without_cross_covariance()
                            .to_builder()
                            .mu(DVector::zeros(result.model.n()))
                            .build()
                            .map_err(|source| LinearFitError::Kalman {
                                context: "n4sid start",
                                source,
                            })?,
                        Some(w),
                    )),
                    Err(e) => {
                        first_error.get_or_insert(e);
                    }
                }
            }
            if fits.is_empty() {
                return Err(first_error.expect("a weighting was tried").into());
            }
            fits
        }
        Start::Model { model, .. } => {
            if let Some(n) = order.filter(|&n| n != model.n()) {
                return Err(LinearFitError::InvalidOption {
                    option: "order",
                    message: format!("{n} differs from the start model's order {}", model.n()),
                });
            }
            let (m, p) = (training.record.u.nrows(), training.record.y.nrows());
            if (model.m(), model.p()) != (m, p) {
                return Err(LinearFitError::InvalidOption {
                    option: "start",
                    message: format!(
                        "the data have {m} input(s) and {p} output(s), the start model {} and {}",
                        model.m(),
                        model.p()
                    ),
                });
            }
            vec![(model.as_ref().clone(), None)]
        }
    };
    let mut warnings = Vec::new();
    let mut candidates = Vec::new();
    // the training record's initial state: `--initial`'s, or the start file's own
    let initial = match (&options.start, options.initial) {
        (Start::Model { initial, .. }, InitialState::Given) => *initial,
        (_, chosen) => chosen,
    };
    for (model, weighting) in given {
        let start = initial
            .apply_to_record(&model, &training.record)
            .map_err(|source| LinearFitError::InvalidOption {
                option: "initial",
                message: source.to_string(),
            })?;
        // linear EM holds S; beside a non-zero S it cannot estimate Q or R. A start with
        // an S (as n4sid writes) is started without it, as the N4SID start is, unless
        // the user holds S on purpose.
        let start = if start.has_cross_covariance()
            && !options.fixes.iter().any(|f| f.matrix == Matrix::S)
        {
            if !warnings.contains(&LinearFitWarning::CrossCovarianceDropped) {
                warnings.push(LinearFitWarning::CrossCovarianceDropped);
            }
            start.without_cross_covariance()
        } else {
            start
        };
        if options.estimate_initial && start.is_diffuse() {
            return Err(LinearFitError::InvalidOption {
                option: "estimate_initial",
                message: "the initial state is diffuse (no mu or P1 to estimate); drop one of \
                          --estimate-initial and the diffuse initial state"
                    .into(),
            });
        }
        let mut diagonal = options.diagonal.clone();
        if training.record.y.nrows() > 1 && !options.full_r && !diagonal.contains(&Matrix::R) {
            diagonal.push(Matrix::R);
        }
        let mut spec = base.clone();
        let start = fix::apply(start, &mut spec, &options.fixes, &diagonal)?;
        let model = spec.project(&start)?;
        candidates.push(Candidate {
            model,
            spec,
            weighting,
        });
    }
    Ok((candidates, warnings))
}

/// EM (SQUAREM or plain) from `start`: the run and its E-steps.
fn run_em(
    start: &LinearGaussianModel,
    records: &[sysid_kalman::Record],
    spec: &LinearEmSpec,
    options: &CheckedLinearFitOptions,
    polish_on: bool,
    observer: &mut impl EmObserver<LinearGaussianModel>,
) -> Result<(EmResult<LinearGaussianModel, LinearEmError>, usize), LinearFitError> {
    let checked = |options: EmOptions| options.check().map_err(options::em_options_error);
    // with a polish to follow, EM only needs to reach the maximum's neighbourhood
    let em = if polish_on {
        checked(EmOptions {
            distance_tol: options.em.distance_tol.max(POLISH_SWITCH_NATS),
            ..options.em.clone().into_inner()
        })?
    } else {
        options.em.clone()
    };
    Ok(match options.acceleration {
        Acceleration::None => {
            let run = fit(start.clone(), records, spec.clone(), &em, observer);
            let e_steps = run.trace.len();
            (run, e_steps)
        }
        Acceleration::Squarem => {
            let cycles = checked(EmOptions {
                max_iterations: options.max_iterations.div_ceil(3).max(1),
                ..em.into_inner()
            })?;
            let accelerated = fit_squarem(start.clone(), records, spec.clone(), &cycles, observer);
            (accelerated.run, accelerated.e_steps)
        }
    })
}

/// The result of an EM run that did not move its start.
fn unmoved(
    start: LinearGaussianModel,
    loglik: f64,
) -> EmResult<LinearGaussianModel, LinearEmError> {
    EmResult {
        estimate: start,
        loglik: Some(loglik),
        trace: vec![loglik],
        iterations: 0,
        termination: Termination::Converged,
        decreases: 0,
        elapsed: Duration::ZERO,
    }
}

/// `R >= rel diag(var y)`: each output's sample variance over the observed steps.
fn output_noise_floor(
    training: &Signals,
    rel: f64,
) -> Result<Option<DVector<f64>>, LinearFitError> {
    if rel == 0.0 {
        return Ok(None);
    }
    let variances = training.record.output_variances();
    let mut floor = DVector::zeros(variances.len());
    for (i, &var) in variances.iter().enumerate() {
        if var <= 0.0 {
            return Err(LinearFitError::InvalidOption {
                option: "data",
                message: format!(
                    "output {} has zero variance (it is constant or has fewer than two observed \
                     values): it carries no information; drop the column",
                    training.output_names[i]
                ),
            });
        }
        floor[i] = rel * var;
    }
    Ok(Some(floor))
}

/// The error when EM cannot evaluate its start: why, if a cause is visible (a singular
/// `R` or `Q` of the start, e.g. N4SID's on noise-free data), with the options that
/// avoid it; else the error itself.
fn start_failure(
    error: LinearEmError,
    start: &LinearGaussianModel,
    training: &Signals,
    spec: &LinearEmSpec,
) -> LinearFitError {
    let causes = diagnosis::estimated_singular_parts(start, training, spec);
    if causes.is_empty() {
        return LinearFitError::Em(error);
    }
    let causes: Vec<String> = causes
        .into_iter()
        .map(|part| {
            format!(
                "{} (bound it: {})",
                part.description,
                diagnosis::bound_option(part.matrix)
            )
        })
        .collect();
    LinearFitError::StartFailed {
        message: format!(
            "the start model fails on the data ({error}): {} (noise-free data, or an order too \
             high for them?); nothing was written",
            causes.join("; ")
        ),
    }
}

/// The written model (original units, a new record's initial state) on the held-out
/// steps: a linear trend continues over them; the fits are in the data's units.
fn validation_fit(
    model: &LinearGaussianModel,
    initial: InitialState,
    trend: Option<&Trend>,
    rest: &Signals,
) -> Result<ValidationFit, LinearFitError> {
    let mut record = rest.record.clone();
    let linear = trend.filter(|t| t.kind == sysid_kalman::TrendKind::Linear);
    if let Some(t) = linear {
        t.remove_from(&mut record, &rest.time);
    }
    let restored = |outputs: &nalgebra::DMatrix<f64>| match linear {
        Some(t) => outputs + t.outputs_at(&rest.time),
        None => outputs.clone(),
    };
    let measured = restored(&record.y);
    let model =
        initial
            .apply_to_record(model, &record)
            .map_err(|source| LinearFitError::Kalman {
                context: "split",
                source,
            })?;
    let mean = |v: Vec<f64>| v.iter().sum::<f64>() / v.len() as f64;
    let simulation = model
        .response(&record, None)
        .map(|r| mean(fit_percent(&measured, &restored(&r.outputs), 0)));
    let prediction = model
        .predict(&record, 1)
        .map(|p| mean(fit_percent(&measured, &restored(&p.mean), 0)));
    Ok(ValidationFit {
        rows: record.len(),
        simulation_fit_percent: simulation.ok(),
        prediction_fit_percent: prediction.ok(),
    })
}
