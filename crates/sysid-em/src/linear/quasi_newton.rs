//! Quasi-Newton maximisation of the exact log-likelihood of a linear Gaussian model:
//! the polish after EM, and the fit of models EM cannot move (output-error models,
//! `Q = 0`).

use super::coordinates::Coordinates;
use super::{Covariance, LinearEmError, LinearEmSpec};
use argmin::core::{CostFunction, Executor, Gradient, State, TerminationReason};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::BFGS;
use nalgebra::{DMatrix, DVector};
use std::cell::RefCell;
use sysid_kalman::{LinearGaussianModel, Record, loglik_dataset};

/// Options of [`maximise_loglik`].
#[derive(Debug, Clone, PartialEq)]
pub struct QuasiNewtonOptions {
    /// BFGS iterations at most. Default 500.
    pub max_iterations: u64,
    /// Stop when the gradient's norm (of the log-likelihood per time step, in the
    /// unconstrained coordinates) is below this. Default 1e-7.
    pub tol_grad: f64,
}

impl Default for QuasiNewtonOptions {
    fn default() -> Self {
        QuasiNewtonOptions {
            max_iterations: 500,
            tol_grad: 1e-7,
        }
    }
}

/// What [`maximise_loglik`] did.
#[derive(Debug, Clone)]
pub struct QuasiNewtonOutcome {
    /// The best model found (the start itself if nothing better was).
    pub model: LinearGaussianModel,
    /// `log p(y | start)`.
    pub loglik_before: f64,
    /// `log p(y | model)`.
    pub loglik: f64,
    /// Free parameters (unconstrained coordinates).
    pub parameters: usize,
    /// BFGS iterations.
    pub iterations: u64,
    /// Log-likelihood evaluations (Kalman filter passes).
    pub evaluations: usize,
    /// Why BFGS stopped (argmin's status), or why it did not run.
    pub status: String,
    /// BFGS met its gradient tolerance, and its result was kept or confirmed the start.
    pub converged: bool,
    /// The search headed to a collapsing `R` (a maximum on the boundary of the
    /// parameter set) and its result was not kept.
    pub boundary: bool,
    /// The run's stop ([`maximise_loglik_until`]) ended the search: the result is the
    /// best point evaluated before it (never worse than the start).
    pub interrupted: bool,
}

/// The polish searches only where a free `R` has not collapsed: below this fraction
/// of the outputs' variances ([`r_collapsed`]) the search stops and its result is not
/// kept, so a boundary maximum costs neither thousands of evaluations nor a degenerate
/// model.
const WALL: f64 = 1e-10;

/// State shared between the runs of BFGS and the caller.
type Shared<T> = std::rc::Rc<RefCell<T>>;

/// BFGS restarts at most.
const RESTARTS: usize = 5;

/// Whether `r`'s smallest eigenvalue, relative to the outputs' variances `var`, is
/// below [`WALL`] (exactly zero rows and columns aside). A singular `Q` or `P1` is a
/// valid model (an innovation-form `Q` has rank `p`); a singular `R` makes some output
/// combination noise-free, the degenerate maximum.
pub(crate) fn r_collapsed(r: &DMatrix<f64>, var: &DVector<f64>) -> bool {
    let kept: Vec<usize> = (0..r.nrows()).filter(|&i| r[(i, i)] > 0.0).collect();
    if kept.is_empty() {
        return false;
    }
    let sub = DMatrix::from_fn(kept.len(), kept.len(), |i, j| {
        let (a, b) = (kept[i], kept[j]);
        r[(a, b)] / (var[a] * var[b]).sqrt().max(f64::MIN_POSITIVE)
    });
    nalgebra::SymmetricEigen::new(sub).eigenvalues.min() < WALL
}

/// The cost of a point that is not a valid model (or whose filter fails): finite, so
/// that the line search backtracks instead of stopping.
const INVALID: f64 = 1e30;

/// `-log p(y | theta) / T` and its central-difference gradient.
struct NegativeLoglik<'a> {
    coordinates: Coordinates,
    records: &'a [Record],
    scale: f64,
    /// The outputs' variances, when `R` is free (the wall is watched only then).
    watch_r: Option<DVector<f64>>,
    /// Whether a collapsing `R` stopped the search.
    wall: Shared<bool>,
    evaluations: Shared<usize>,
    /// The best point evaluated (a failed run keeps what it found).
    best: Shared<Option<(f64, Vec<f64>)>>,
    /// Asked before every filter pass: `true` ends the search.
    stop: &'a dyn Fn() -> bool,
    /// Whether `stop` ended it.
    interrupted: Shared<bool>,
}

impl NegativeLoglik<'_> {
    fn value(&self, point: &[f64]) -> f64 {
        if *self.interrupted.borrow() || (self.stop)() {
            *self.interrupted.borrow_mut() = true;
            return INVALID;
        }
        *self.evaluations.borrow_mut() += 1;
        let value = self
            .coordinates
            .model(point)
            .filter(|m| {
                let hit = self
                    .watch_r
                    .as_ref()
                    .is_some_and(|var| r_collapsed(m.r(), var));
                if hit {
                    *self.wall.borrow_mut() = true;
                }
                !hit
            })
            .and_then(|m| loglik_dataset(&m, self.records).ok())
            .filter(|l| l.is_finite())
            .map_or(INVALID, |l| -l * self.scale);
        let mut best = self.best.borrow_mut();
        if value < INVALID && best.as_ref().is_none_or(|(b, _)| value < *b) {
            *best = Some((value, point.to_vec()));
        }
        value
    }
}

impl CostFunction for NegativeLoglik<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, point: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        let value = self.value(point);
        if *self.wall.borrow() {
            return Err(argmin::core::Error::msg("R collapsed"));
        }
        if *self.interrupted.borrow() {
            return Err(argmin::core::Error::msg("interrupted"));
        }
        Ok(value)
    }
}

impl Gradient for NegativeLoglik<'_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;

    fn gradient(&self, point: &Vec<f64>) -> Result<Vec<f64>, argmin::core::Error> {
        let mut shifted = point.clone();
        let mut grad = vec![0.0; point.len()];
        let centre = self.value(point);
        if centre >= INVALID {
            // a trial point outside the valid models: no direction from here (the
            // line search backtracks on its infinite cost)
            return Ok(grad);
        }
        for k in 0..point.len() {
            let step = 1e-6 * point[k].abs().max(1e-2);
            shifted[k] = point[k] + step;
            let up = self.value(&shifted);
            shifted[k] = point[k] - step;
            let down = self.value(&shifted);
            shifted[k] = point[k];
            grad[k] = match (up < INVALID, down < INVALID) {
                (true, true) => (up - down) / (2.0 * step),
                // next to the edge of the valid models: one-sided
                (true, false) => (up - centre) / step,
                (false, true) => (centre - down) / step,
                (false, false) => 0.0,
            };
        }
        if *self.interrupted.borrow() {
            return Err(argmin::core::Error::msg("interrupted"));
        }
        Ok(grad)
    }
}

/// The number of unconstrained coordinates [`maximise_loglik`] would optimise (0 when it
/// cannot run, e.g. with a free `S`): each gradient costs `2 k + 1` filter passes.
pub fn coordinate_count(start: &LinearGaussianModel, spec: &LinearEmSpec) -> usize {
    Coordinates::new(start, spec).map_or(0, |c| c.point(start).len())
}

/// Maximises the exact log-likelihood over the free parameters of `spec` from `start`
/// by BFGS (argmin 0.11, More-Thuente line search) with central-difference gradients.
///
/// # Coordinates
/// Entries of `A, B, C, D, h, mu` as they are; a free covariance as
/// `F^{1/2} (I + L L') F^{1/2}` with the floor `F` of [`LinearEmSpec::min_variance`]
/// and [`LinearEmSpec::output_noise_floor`] (without a floor, `L L'`), `L` lower
/// triangular with a log diagonal (a diagonal covariance: log variances; a variance
/// that is zero at the start, or at most 1e-12 of the largest, is a structural zero and
/// is held at exactly zero, as EM holds it).
/// So every point is a valid model in the spec. A free `S` is not supported.
///
/// # Why
/// EM's convergence is linear, and slow where the likelihood is flat along a ridge or a
/// variance is small; BFGS converges superlinearly near the maximum. And EM cannot move
/// `A` when `Q = 0` (an output-error model: the smoothed states are then a
/// deterministic function of `A`), where this maximises the likelihood directly.
///
/// The result is never worse than `start`.
///
/// # Cost
/// `2 k + 1` Kalman filter passes per gradient for `k` free coordinates.
pub fn maximise_loglik(
    start: &LinearGaussianModel,
    records: &[Record],
    spec: &LinearEmSpec,
    options: &QuasiNewtonOptions,
) -> Result<QuasiNewtonOutcome, LinearEmError> {
    maximise_loglik_until(start, records, spec, options, &|| false)
}

/// [`maximise_loglik`] that ends when `stop()` turns true (asked before every filter
/// pass, so within one pass of a Ctrl-C), with the best point evaluated so far and
/// [`QuasiNewtonOutcome::interrupted`] set.
///
/// # Errors
/// As [`maximise_loglik`].
pub fn maximise_loglik_until(
    start: &LinearGaussianModel,
    records: &[Record],
    spec: &LinearEmSpec,
    options: &QuasiNewtonOptions,
    stop: &dyn Fn() -> bool,
) -> Result<QuasiNewtonOutcome, LinearEmError> {
    let loglik_before = loglik_dataset(start, records)?;
    let unchanged = |status: String, parameters| QuasiNewtonOutcome {
        model: start.clone(),
        loglik_before,
        loglik: loglik_before,
        parameters,
        iterations: 0,
        evaluations: 1,
        status,
        converged: false,
        boundary: false,
        interrupted: false,
    };
    let coordinates = match Coordinates::new(start, spec) {
        Ok(c) => c,
        Err(why) => return Ok(unchanged(why, 0)),
    };
    let first = coordinates.point(start);
    if first.is_empty() {
        return Ok(unchanged("no free parameter".into(), 0));
    }
    // the outputs' variances (the first record's: the scale of the data)
    let watch_r = (spec.r != Covariance::Fixed)
        .then(|| records.first().map(Record::output_variances))
        .flatten();
    if watch_r
        .as_ref()
        .is_some_and(|var| r_collapsed(start.r(), var))
    {
        return Ok(unchanged(
            "not run: R has already collapsed towards zero".into(),
            first.len(),
        ));
    }
    let steps: usize = records.iter().map(|r| r.len()).sum();
    let parameters = first.len();
    let best_seen: Shared<Option<(f64, Vec<f64>)>> = Shared::default();
    let wall: Shared<bool> = Shared::default();
    let evaluations: Shared<usize> = Shared::default();
    let interrupted: Shared<bool> = Shared::default();
    let (mut point, mut iterations, mut status) = (first, 0u64, String::new());
    let mut converged = false;
    // BFGS, restarted from its best point with a fresh inverse Hessian when it stops
    // short of convergence (a line search that fails near the edge of the valid
    // models, the iteration limit) but still gained
    for _ in 0..RESTARTS {
        let value_before = best_seen.borrow().as_ref().map_or(f64::INFINITY, |b| b.0);
        let problem = NegativeLoglik {
            coordinates: coordinates.clone(),
            records,
            scale: 1.0 / steps.max(1) as f64,
            watch_r: watch_r.clone(),
            wall: std::rc::Rc::clone(&wall),
            evaluations: std::rc::Rc::clone(&evaluations),
            best: std::rc::Rc::clone(&best_seen),
            stop,
            interrupted: std::rc::Rc::clone(&interrupted),
        };
        let solver = BFGS::new(MoreThuenteLineSearch::new())
            .with_tolerance_grad(options.tol_grad)
            .and_then(|s| s.with_tolerance_cost(0.0))
            .map_err(|e| LinearEmError::InvalidSpec(e.to_string()))?;
        let identity: Vec<Vec<f64>> = (0..parameters)
            .map(|i| {
                (0..parameters)
                    .map(|j| f64::from(u8::from(i == j)))
                    .collect()
            })
            .collect();
        let budget = options.max_iterations.saturating_sub(iterations).max(1);
        let run = Executor::new(problem, solver)
            .configure(|state| {
                state
                    .param(point.clone())
                    .inv_hessian(identity)
                    .max_iters(budget)
            })
            .run();
        converged = match run {
            Ok(r) => {
                iterations += r.state.get_iter();
                status = r.state.get_termination_status().to_string();
                r.state.get_termination_reason() == Some(&TerminationReason::SolverConverged)
            }
            Err(e) => {
                status = format!("stopped: {e}");
                false
            }
        };
        let Some((value, best)) = best_seen.borrow().clone() else {
            break;
        };
        if *wall.borrow() || *interrupted.borrow() {
            break;
        }
        point = best;
        let gained = value_before - value;
        if converged || iterations >= options.max_iterations || gained <= 1e-12 * value.abs() {
            break;
        }
    }
    let evaluations = *evaluations.borrow();
    let interrupted = *interrupted.borrow();
    if interrupted {
        status = "interrupted".into();
        converged = false;
    }
    let tracked = best_seen.borrow_mut().take().map(|(_, x)| x);
    if let Some(model) = tracked.and_then(|p| coordinates.model(&p))
        && let Ok(loglik) = loglik_dataset(&model, records)
        && loglik.is_finite()
        && loglik >= loglik_before
    {
        if *wall.borrow() {
            return Ok(QuasiNewtonOutcome {
                iterations,
                evaluations,
                boundary: true,
                ..unchanged(
                    format!(
                        "not kept: R headed to zero (the maximum is on the boundary of the \
                         parameter set; {:.3} nats higher there)",
                        loglik - loglik_before
                    ),
                    parameters,
                )
            });
        }
        return Ok(QuasiNewtonOutcome {
            model,
            loglik_before,
            loglik,
            parameters,
            iterations,
            evaluations,
            status,
            converged,
            boundary: false,
            interrupted,
        });
    }
    // BFGS may meet its tolerance without improving on the start (EM had reached the
    // maximum): the start is then confirmed, and converged
    Ok(QuasiNewtonOutcome {
        iterations,
        evaluations,
        converged: converged && !*wall.borrow(),
        interrupted,
        ..unchanged(format!("{status} (no improvement kept)"), parameters)
    })
}
