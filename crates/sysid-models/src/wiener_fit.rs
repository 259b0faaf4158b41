//! Blind Wiener identification from the two outputs alone (seed 001): the lecture's
//! start, gradient EM with the fully adapted filter, the estimate in canonical form.

use crate::{WienerEstimate, WienerModel, normalised_magnitude_error, wiener_start};
use sysid_em::gradient::{GradientEm, GradientEmError, GradientModel, MStepOptions};
use sysid_em::{CheckedEmOptions, EmObserver, EmOptions, EmResult, FitRun, IterationInfo, run_em};
use sysid_smc::{FfbsiReject, ModelError, Series};

/// Errors of [`fit_wiener`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum WienerFitError {
    /// An option out of range (`particles` below 2, no `iterations`).
    #[error("{name}: {reason}")]
    InvalidOption {
        /// The option.
        name: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// A missing output: the N4SID start needs every `y1` and `y2`.
    #[error("the N4SID start needs every y1 and y2 (missing values found)")]
    MissingOutputs,
    /// The N4SID start failed.
    #[error("{0}")]
    Start(ModelError),
    /// The N4SID start is not a model.
    #[error("the N4SID start is unusable: {0}")]
    Unusable(ModelError),
    /// Gradient EM failed to start.
    #[error("{0}")]
    Em(#[from] GradientEmError),
}

/// The result of [`fit_wiener`].
#[derive(Debug, Clone)]
pub struct WienerFit {
    /// The estimate in canonical form (companion `A`, minimum-phase side of `Q`).
    pub estimate: WienerEstimate,
    /// The runner's result (estimate on the unconstrained scale; a failure inside the
    /// iterations is its termination).
    pub result: EmResult<Vec<f64>, GradientEmError>,
    /// `(loglik, parameters)` after every iteration, the parameters on their natural
    /// scale in the order of [`GradientModel::parameter_names`].
    pub iterates: Vec<(f64, Vec<f64>)>,
}

impl WienerFit {
    /// The estimate's normalised magnitude error against the reference system of the
    /// lecture (seed 001's figure of merit).
    pub fn magnitude_error(&self) -> f64 {
        normalised_magnitude_error(&self.estimate)
    }
}

/// Records the natural parameters of every iteration and asks the run whether to stop.
struct Iterates<'o, 'r> {
    model: &'r WienerModel,
    observer: &'o mut dyn EmObserver<Vec<f64>>,
    run: &'r FitRun<'r>,
    rows: Vec<(f64, Vec<f64>)>,
}

impl EmObserver<Vec<f64>> for Iterates<'_, '_> {
    fn start(&mut self, initial: &Vec<f64>) {
        self.observer.start(initial);
    }
    fn iteration(&mut self, info: &IterationInfo<'_, Vec<f64>>) {
        self.rows
            .push((info.loglik, self.model.constrained(info.estimate)));
        self.observer.iteration(info);
    }
    fn finish(&mut self, estimate: &Vec<f64>, loglik: Option<f64>, iterations: usize) {
        self.observer.finish(estimate, loglik, iterations);
    }
    fn should_stop(&self) -> bool {
        self.observer.should_stop() || (self.run.stop)()
    }
}

/// Options of [`fit_wiener`]; [`WienerFitOptions::check`] gives the only form it takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub struct WienerFitOptions {
    /// Particles of the filter and paths of the rejection FFBSi (at least 2). Default
    /// 100.
    pub particles: usize,
    /// Gradient-EM iterations, run exactly (at least 1). Default 500.
    pub iterations: usize,
}

impl Default for WienerFitOptions {
    fn default() -> Self {
        WienerFitOptions {
            particles: 100,
            iterations: 500,
        }
    }
}

impl WienerFitOptions {
    /// `particles` and `iterations`, the rest default.
    pub fn new(particles: usize, iterations: usize) -> Self {
        WienerFitOptions {
            particles,
            iterations,
        }
    }

    /// Checks the options.
    ///
    /// # Errors
    /// [`WienerFitError::InvalidOption`] naming `particles` (below 2) or `iterations`
    /// (none).
    pub fn check(self) -> Result<CheckedWienerFitOptions, WienerFitError> {
        if self.particles < 2 {
            return Err(WienerFitError::InvalidOption {
                name: "particles",
                reason: "must be at least 2".into(),
            });
        }
        if self.iterations == 0 {
            return Err(WienerFitError::InvalidOption {
                name: "iterations",
                reason: "must be at least 1".into(),
            });
        }
        let em = EmOptions {
            max_iterations: self.iterations,
            tol: 0.0,
            ..EmOptions::default()
        }
        .check()
        .map_err(|e| WienerFitError::InvalidOption {
            name: "iterations",
            reason: e.to_string(),
        })?;
        Ok(CheckedWienerFitOptions {
            particles: self.particles,
            em,
        })
    }
}

/// [`WienerFitOptions`] that passed their checks.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckedWienerFitOptions {
    particles: usize,
    em: CheckedEmOptions,
}

/// Fits the Wiener system of seed 001 to `data` (two outputs, no input): the start is
/// the lecture's (the linear part from N4SID on `y1`, `r1 = r2 = 0.1`, each breakpoint
/// a tenth of the reference system's), then the iterations of gradient EM with the
/// particles of `options` in the filter and as many rejection-FFBSi paths, the fully
/// adapted filter in the E-step. `observer` sees every iteration (unconstrained
/// estimates).
///
/// # Errors
/// See [`WienerFitError`]; a failure inside the iterations is the result's
/// termination.
pub fn fit_wiener(
    data: Series<'_>,
    options: &CheckedWienerFitOptions,
    run: &FitRun<'_>,
    observer: &mut dyn EmObserver<Vec<f64>>,
) -> Result<WienerFit, WienerFitError> {
    let particles = options.particles;
    let outputs: Vec<f64> = (0..data.steps())
        .flat_map(|t| data.output(t).iter().copied())
        .collect();
    if outputs.iter().any(|v| v.is_nan()) {
        return Err(WienerFitError::MissingOutputs);
    }
    let start = wiener_start(&outputs).map_err(WienerFitError::Start)?;
    let theta = start.theta().map_err(WienerFitError::Unusable)?;
    let model = WienerModel::default();
    let smoother = FfbsiReject {
        paths: particles,
        max_trials: None,
        parallel: false,
    };
    let mut em = GradientEm::new(
        &model,
        data,
        particles,
        smoother,
        MStepOptions::default(),
        run.seed,
    )?
    .with_guided_filter();
    let mut iterates = Iterates {
        model: &model,
        observer,
        run,
        rows: Vec::new(),
    };
    let result = run_em(&mut em, theta, &options.em, &mut iterates);
    Ok(WienerFit {
        estimate: WienerEstimate::from_theta(&result.estimate),
        iterates: iterates.rows,
        result,
    })
}
