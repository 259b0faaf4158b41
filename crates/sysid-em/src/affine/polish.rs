//! The robust driver's last stage: its estimate checked, and finished, by an accurate
//! particle likelihood maximised directly.
//!
//! # Why
//! A particle E-step with few particles biases the noise variances upward on a model
//! whose filter needs many particles: on seed 000's benchmark at `q = 0.01`,
//! `r = 0.1` (`y = d x^2`, a transition that multiplies spreads by up to 25 near 0) the
//! 100-particle refinement settles at `r = 0.89`, and a 10 000-particle filter puts it
//! 515 nats below the truth; held at `r = 0.1`, the same E-step drags the
//! coefficients off instead. The EM fixed point is the particle approximation's, not
//! the likelihood's, and nothing in EM itself can see it.
//!
//! # Algorithm
//! The log-likelihood is estimated by a bootstrap filter with `particles` particles on
//! common random numbers (one seed for every point, so that nearby points compare
//! without most of the Monte Carlo noise), over the estimated coefficients and the
//! logarithms of the estimated noise variances (a covariance the spec holds stays;
//! a full covariance is scaled, its correlations kept):
//! 1. each noise variance is halved (or, if that does not help, doubled) while the
//!    likelihood improves, at most [`MAX_HALVINGS`] times: the cheap move that undoes
//!    the E-step's bias;
//! 2. Nelder–Mead (argmin 0.11) from there, with a simplex of 10 % of every
//!    coefficient and a factor 1.35 on every variance, until the simplex's values agree
//!    within [`SD_TOLERANCE`] nats or the evaluation budget is spent. The best point
//!    evaluated is kept, whatever the solver's last state.
//!
//! The reported log-likelihood is the mean of [`REPEATS`] independent filters at the
//! result (not the common-random-numbers value it was selected on, which is biased
//! upward by the selection), with their standard deviation.
//!
//! # Complexity
//! `evaluations + 2 (variances) x MAX_HALVINGS + 2 x REPEATS` filters of
//! `O(T M)` each; the filter shares its particles among the free processors.

use super::constraints::estimated_variances;
use super::{
    AffineConstraints, AffineEmError, AffineEmSpec, AffineModel, AffineParams, free_structure,
};
use argmin::core::{CostFunction, Executor, State, TerminationReason, TerminationStatus};
use argmin::solver::neldermead::NelderMead;
use nalgebra::DMatrix;
use rand::RngExt;
use std::cell::RefCell;
use sysid_smc::{FilterOptions, ParticleFilter, Series, stream};

/// Halvings (or doublings) of each noise variance before Nelder–Mead.
pub const MAX_HALVINGS: usize = 6;

/// Nelder–Mead stops when the standard deviation of the simplex's log-likelihoods is
/// below this (nats).
pub const SD_TOLERANCE: f64 = 0.02;

/// The cost of a point not evaluated (invalid, or past the budget): worse than any
/// valid point.
const UNEVALUATED: f64 = f64::MAX / 4.0;

/// Independent filters that score the result (mean and sd).
pub const REPEATS: usize = 4;

/// A gain (nats) smaller than this does not count as progress ...
pub const STALL_GAIN: f64 = 0.1;

/// ... and Nelder–Mead has stalled (converged, on a function with Monte Carlo
/// roughness) after this many evaluations per vertex of its simplex without progress.
pub const STALL_EVALUATIONS_PER_VERTEX: usize = 5;

/// What the polish did.
#[derive(Debug, Clone, PartialEq)]
pub struct Polish {
    /// Particles of its filter.
    pub particles: usize,
    /// The EM estimate's log-likelihood by that filter (mean of 4 independent runs).
    pub start_loglik: f64,
    /// The polished estimate's (mean of 4 independent filters).
    pub loglik: f64,
    /// The Monte Carlo standard deviation of one filter at the polished estimate,
    /// from the repeats.
    pub loglik_sd: f64,
    /// Filters run on common random numbers (the variance steps and Nelder–Mead).
    pub evaluations: usize,
    /// Whether Nelder–Mead's simplex had converged before the budget ran out.
    pub converged: bool,
    /// Whether it was cut short by the run's stop (Ctrl-C).
    pub interrupted: bool,
}

/// One coordinate of the polish.
#[derive(Debug, Clone, Copy)]
enum Coordinate {
    /// `beta_x[(row, col)]`.
    StateCoefficient(usize, usize),
    /// `beta_y[(row, col)]`.
    OutputCoefficient(usize, usize),
    /// `ln Pi_x[(i, i)]`.
    ProcessVariance(usize),
    /// `ln Pi_y[(i, i)]`.
    MeasurementVariance(usize),
    /// Tied coefficient `k` of the model's [`AffineConstraints`] (all its coefficients
    /// at once, clamped to its bounds).
    Tied(usize),
}

impl Coordinate {
    fn is_variance(self) -> bool {
        matches!(
            self,
            Coordinate::ProcessVariance(_) | Coordinate::MeasurementVariance(_)
        )
    }
}

/// The coordinates of `base` that `spec` estimates (a variance of 0 cannot be scaled
/// and stays).
fn coordinates<A: AffineModel>(
    model: &A,
    base: &AffineParams,
    spec: &AffineEmSpec,
) -> Vec<Coordinate> {
    let mut out = Vec::new();
    let constraints = model.constraints();
    match &constraints {
        Some(c) if spec.beta_x && spec.beta_y => {
            out.extend((0..c.coefficients.len()).map(Coordinate::Tied));
        }
        _ => {
            if spec.beta_x {
                let free =
                    free_structure(&model.state_structure(), &model.held_state_coefficients());
                for (row, used) in free.iter().enumerate() {
                    out.extend(used.iter().map(|&j| Coordinate::StateCoefficient(row, j)));
                }
            }
            if spec.beta_y {
                let free =
                    free_structure(&model.output_structure(), &model.held_output_coefficients());
                for (row, used) in free.iter().enumerate() {
                    out.extend(used.iter().map(|&j| Coordinate::OutputCoefficient(row, j)));
                }
            }
        }
    }
    let estimated = |covariance, m: &DMatrix<f64>, process| -> Vec<usize> {
        let free = estimated_variances(covariance, m.nrows(), constraints.as_ref(), process);
        (0..m.nrows())
            .filter(|&i| free[i] && m[(i, i)] > 0.0)
            .collect()
    };
    out.extend(
        estimated(spec.pi_x, &base.pi_x, true)
            .into_iter()
            .map(Coordinate::ProcessVariance),
    );
    out.extend(
        estimated(spec.pi_y, &base.pi_y, false)
            .into_iter()
            .map(Coordinate::MeasurementVariance),
    );
    out
}

/// The coordinates' values at `params`.
fn values(
    params: &AffineParams,
    coordinates: &[Coordinate],
    constraints: Option<&AffineConstraints>,
) -> Vec<f64> {
    let tied = constraints.map(|c| c.values(params)).unwrap_or_default();
    coordinates
        .iter()
        .map(|c| match *c {
            Coordinate::Tied(k) => tied[k],
            Coordinate::StateCoefficient(i, j) => params.beta_x[(i, j)],
            Coordinate::OutputCoefficient(i, j) => params.beta_y[(i, j)],
            Coordinate::ProcessVariance(i) => params.pi_x[(i, i)].ln(),
            Coordinate::MeasurementVariance(i) => params.pi_y[(i, i)].ln(),
        })
        .collect()
}

/// `base` with the coordinates set to `point`; a covariance's variances are set by
/// scaling its rows and columns, which keeps it symmetric PSD with the same
/// correlations.
fn at(
    base: &AffineParams,
    coordinates: &[Coordinate],
    point: &[f64],
    constraints: Option<&AffineConstraints>,
) -> AffineParams {
    let mut params = base.clone();
    let mut tied = constraints.map(|c| c.values(base)).unwrap_or_default();
    let mut scale_x = vec![1.0; base.pi_x.nrows()];
    let mut scale_y = vec![1.0; base.pi_y.nrows()];
    for (c, &v) in coordinates.iter().zip(point) {
        match *c {
            Coordinate::StateCoefficient(i, j) => params.beta_x[(i, j)] = v,
            Coordinate::OutputCoefficient(i, j) => params.beta_y[(i, j)] = v,
            Coordinate::ProcessVariance(i) => scale_x[i] = (v - base.pi_x[(i, i)].ln()).exp(),
            Coordinate::MeasurementVariance(i) => {
                scale_y[i] = (v - base.pi_y[(i, i)].ln()).exp();
            }
            Coordinate::Tied(k) => tied[k] = v,
        }
    }
    if let Some(c) = constraints {
        c.set(&mut params, &tied);
    }
    let scaled = |m: &DMatrix<f64>, s: &[f64]| {
        DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| {
            if i == j {
                m[(i, i)] * s[i]
            } else {
                m[(i, j)] * (s[i] * s[j]).sqrt()
            }
        })
    };
    params.pi_x = scaled(&base.pi_x, &scale_x);
    params.pi_y = scaled(&base.pi_y, &scale_y);
    params
}

/// The negative log-likelihood on common random numbers, with the best point seen.
struct Objective<'a, A: AffineModel> {
    model: &'a A,
    constraints: Option<AffineConstraints>,
    data: Series<'a>,
    base: &'a AffineParams,
    coordinates: &'a [Coordinate],
    filter: RefCell<ParticleFilter>,
    seed: u64,
    stop: &'a dyn Fn() -> bool,
    evaluations: RefCell<usize>,
    best: RefCell<(Vec<f64>, f64)>,
    /// The evaluation count and log-likelihood of the last gain over [`STALL_GAIN`].
    progress: RefCell<(usize, f64)>,
}

impl<A: AffineModel> Objective<'_, A> {
    /// The log-likelihood at `point` (`-inf` where the model is invalid or the filter
    /// fails).
    fn loglik(&self, point: &[f64], seed: u64) -> f64 {
        let params = at(
            self.base,
            self.coordinates,
            point,
            self.constraints.as_ref(),
        );
        let Ok(smc) = self.model.smc_model(&params) else {
            return f64::NEG_INFINITY;
        };
        match self.filter.borrow_mut().run(&smc, &self.data, seed) {
            Ok(summary) if summary.loglik.is_finite() => summary.loglik,
            _ => f64::NEG_INFINITY,
        }
    }

    /// [`Self::loglik`] on the common seed, counted and remembered if best.
    fn evaluate(&self, point: &[f64]) -> f64 {
        *self.evaluations.borrow_mut() += 1;
        let l = self.loglik(point, self.seed);
        let mut progress = self.progress.borrow_mut();
        if l > progress.1 + STALL_GAIN {
            *progress = (*self.evaluations.borrow(), l);
        }
        let mut best = self.best.borrow_mut();
        if l > best.1 {
            *best = (point.to_vec(), l);
        }
        l
    }

    /// Mean and sd of `REPEATS` independent filters at `point`.
    fn scored(&self, point: &[f64]) -> (f64, f64) {
        let runs: Vec<f64> = (0..REPEATS)
            .map(|k| self.loglik(point, stream(self.seed, k as u64 + 1).random()))
            .collect();
        let n = runs.len() as f64;
        let mean = runs.iter().sum::<f64>() / n;
        let var = runs.iter().map(|l| (l - mean) * (l - mean)).sum::<f64>() / (n - 1.0);
        (mean, var.sqrt())
    }
}

impl<A: AffineModel> CostFunction for Objective<'_, A> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, point: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        let l = self.evaluate(point);
        // Nelder-Mead needs a finite order: an invalid point is worse than any valid one
        Ok(if l.is_finite() { -l } else { UNEVALUATED })
    }
}

/// Maximises the `particles`-particle log-likelihood over what `spec` estimates,
/// from `start`, with at most `evaluations` Nelder–Mead evaluations; returns the best
/// point and what happened (see the module docs).
///
/// # Errors
/// The filter cannot be built (`particles < 2`); the start cannot be scored.
#[allow(clippy::too_many_arguments)]
pub(crate) fn polish<A: AffineModel>(
    model: &A,
    data: Series<'_>,
    start: &AffineParams,
    spec: &AffineEmSpec,
    particles: usize,
    evaluations: usize,
    seed: u64,
    stop: &dyn Fn() -> bool,
) -> Result<(AffineParams, Polish), AffineEmError> {
    let filter = ParticleFilter::new(FilterOptions {
        particles,
        record_summaries: false,
        parallel: true,
        ..FilterOptions::default()
    })?;
    let coords = coordinates(model, start, spec);
    let constraints = model.constraints();
    let objective = Objective {
        model,
        constraints: constraints.clone(),
        data,
        base: start,
        coordinates: &coords,
        filter: RefCell::new(filter),
        seed,
        stop,
        evaluations: RefCell::new(0),
        best: RefCell::new((Vec::new(), f64::NEG_INFINITY)),
        progress: RefCell::new((0, f64::NEG_INFINITY)),
    };
    let origin = values(start, &coords, constraints.as_ref());
    let (start_loglik, _) = objective.scored(&origin);
    if !start_loglik.is_finite() || objective.evaluate(&origin) == f64::NEG_INFINITY {
        return Err(AffineEmError::InvalidParams(format!(
            "robust EM: the estimate cannot be scored by a {particles}-particle filter"
        )));
    }
    // 1. the variances, a factor 2 at a time
    for (k, c) in coords.iter().enumerate() {
        if !c.is_variance() {
            continue;
        }
        for step in [-std::f64::consts::LN_2, std::f64::consts::LN_2] {
            let mut moved = false;
            for _ in 0..MAX_HALVINGS {
                if stop() {
                    break;
                }
                let (mut point, current) = objective.best.borrow().clone();
                point[k] += step;
                if objective.evaluate(&point) <= current {
                    break;
                }
                moved = true;
            }
            if moved {
                break;
            }
        }
    }
    // 2. Nelder-Mead from the best point so far
    let (from, _) = objective.best.borrow().clone();
    let mut simplex = vec![from.clone()];
    for (k, c) in coords.iter().enumerate() {
        let mut vertex = from.clone();
        vertex[k] += if c.is_variance() {
            0.3
        } else if from[k] != 0.0 {
            0.1 * from[k].abs()
        } else {
            0.1
        };
        simplex.push(vertex);
    }
    let mut converged = false;
    if !coords.is_empty() && evaluations > 0 && !stop() {
        let solver = NelderMead::new(simplex)
            .with_sd_tolerance(SD_TOLERANCE)
            .map_err(|e| AffineEmError::InvalidParams(e.to_string()))?;
        let budget = *objective.evaluations.borrow() + evaluations;
        // every iteration costs one to n + 2 evaluations: iterations bound loosely, the
        // count of evaluations exactly (the cost refuses past the budget)
        let budgeted = Budgeted {
            inner: &objective,
            budget,
            stall: STALL_EVALUATIONS_PER_VERTEX * (coords.len() + 1),
            stalled: RefCell::new(false),
        };
        let result = Executor::new(&budgeted, solver)
            .configure(|s| s.max_iters(evaluations as u64))
            .run();
        converged = (*budgeted.stalled.borrow() && !stop())
            || result.is_ok_and(|r| {
                matches!(
                    r.state().get_termination_status(),
                    TerminationStatus::Terminated(TerminationReason::SolverConverged)
                )
            });
    }
    let (point, _) = objective.best.borrow().clone();
    let (loglik, loglik_sd) = objective.scored(&point);
    let polished = at(start, &coords, &point, constraints.as_ref());
    let evaluations = *objective.evaluations.borrow();
    Ok((
        polished,
        Polish {
            particles,
            start_loglik,
            loglik,
            loglik_sd,
            evaluations,
            converged,
            interrupted: stop(),
        },
    ))
}

/// The objective, refusing to evaluate past a budget or after `stall` evaluations
/// without progress (the run then ends with the best point seen).
struct Budgeted<'a, 'b, A: AffineModel> {
    inner: &'a Objective<'b, A>,
    budget: usize,
    stall: usize,
    stalled: RefCell<bool>,
}

impl<A: AffineModel> CostFunction for &Budgeted<'_, '_, A> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, point: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        // never an error: argmin's Nelder-Mead unwraps the costs of its first simplex;
        // past the budget, a stall or a stop, the rest of its iterations are cheap
        // no-ops and the best point evaluated is the answer
        let count = *self.inner.evaluations.borrow();
        if count - self.inner.progress.borrow().0 >= self.stall {
            *self.stalled.borrow_mut() = true;
        }
        if *self.stalled.borrow() || count >= self.budget || (self.inner.stop)() {
            return Ok(UNEVALUATED);
        }
        self.inner.cost(point)
    }
}
