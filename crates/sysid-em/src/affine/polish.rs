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
//!    within [`SD_TOLERANCE`](crate::likelihood_search::SD_TOLERANCE) nats or the evaluation budget is spent. The best point
//!    evaluated is kept, whatever the solver's last state.
//! 3. **The check**: when the simplex has converged, the log-likelihood's curvature
//!    at the best point by central differences on the same random numbers, probed
//!    along its flattest directions
//!    ([`probe_flat_directions`](crate::likelihood_search)), its Newton point, and a
//!    simplex along the curvature's eigenvectors scaled to its 1-nat contour, repeated
//!    while a round gains [`CLIMB_GAIN`] nats or [`CLIMB_SDS`] Monte Carlo sds (at
//!    most [`CURVATURE_ROUNDS`] times, within another `evaluations` filters). A simplex
//!    stalls on a ridge the data barely determine (the scale of an unmeasured state);
//!    the Newton point and the ridge-shaped simplex walk along it. The last curvature
//!    is the observed information: its inverse gives standard errors
//!    ([`PolishCurvature::standard_errors`]) when it is a maximum's, and otherwise
//!    names the direction that is flat or still rising ([`PolishCurvature::flattest`]).
//!
//! The reported log-likelihood is the mean of [`REPEATS`](crate::likelihood_search::REPEATS) independent filters at the
//! result (not the common-random-numbers value it was selected on, which is biased
//! upward by the selection), with their standard deviation.
//!
//! # Complexity
//! `evaluations + 2 (variances) x MAX_HALVINGS + 2 x REPEATS` filters of
//! `O(T M)` each, and up to `evaluations` more for the check (a curvature of `d`
//! coordinates is `2 d^2 + 2 d` filters); the filter shares its particles among the free processors.

use super::constraints::estimated_variances;
use super::{
    AffineConstraints, AffineEmError, AffineEmSpec, AffineModel, AffineParams, free_structure,
};
use crate::likelihood_search::{Curvature, Search, filtered_loglik, scored};
use nalgebra::DMatrix;
use std::cell::RefCell;
use sysid_smc::{FilterOptions, ParticleFilter, Series};

/// Halvings (or doublings) of each noise variance before Nelder–Mead.
pub const MAX_HALVINGS: usize = 6;

/// Rounds of the check's curvature-shaped restarts: one (a curvature of `d`
/// coordinates costs `2 d^2 + 2 d` filters; on nlbench, 6 coordinates, three rounds
/// took 394 filters and 7 times the fit's time, one round 3 nats of the same gain).
pub const CURVATURE_ROUNDS: usize = 1;

/// A round of the check that gains this many nats (or [`CLIMB_SDS`] times the
/// filter's Monte Carlo sd, if more) is followed by another.
pub const CLIMB_GAIN: f64 = 0.5;

/// A gain smaller than this many Monte Carlo sds of the filter is not a climb: among
/// hundreds of evaluations on common random numbers, a few score that much above
/// their neighbours by chance (on nlbench, sd 0.4, a 0.5-nat rule walked 3.7 nats
/// "up" in 321 filters to a point the independent filters scored no higher).
pub const CLIMB_SDS: f64 = 2.0;

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
    /// Whether the search had converged before its budget ran out: the simplex, and
    /// the check's rounds, the last of which gained less than a climb ([`CLIMB_GAIN`]
    /// or [`CLIMB_SDS`] sds).
    pub converged: bool,
    /// Filters the check (the curvature rounds) ran; 0 when the simplex had not
    /// converged or the run was stopped first.
    pub check_evaluations: usize,
    /// The log-likelihood gained by the check's rounds over the simplex's best
    /// (common random numbers): more than [`CLIMB_GAIN`] means the simplex had
    /// stalled on a ridge.
    pub check_gain: f64,
    /// The log-likelihood's curvature at the result, when the check took one.
    pub curvature: Option<PolishCurvature>,
    /// Whether it was cut short by the run's stop (Ctrl-C).
    pub interrupted: bool,
}

/// The log-likelihood's curvature at the polish's result, in its coordinates (the
/// estimated coefficients and the logarithms of the estimated noise variances): the
/// observed information by central differences of the filter's log-likelihood on
/// common random numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct PolishCurvature {
    base: AffineParams,
    coordinates: Vec<Coordinate>,
    constraints: Option<AffineConstraints>,
    curvature: Curvature,
}

impl PolishCurvature {
    fn params(&self, point: &[f64]) -> AffineParams {
        at(
            &self.base,
            &self.coordinates,
            point,
            self.constraints.as_ref(),
        )
    }

    /// Whether it is a maximum's: the information `-H` is positive definite.
    pub fn is_maximum(&self) -> bool {
        self.curvature.information().is_some()
    }

    /// The standard errors of `f(params)` by the delta method, `J (-H)^-1 J'` with `J`
    /// the Jacobian of `f` in the polish's coordinates by central differences; `None`
    /// when the curvature is not a maximum's.
    ///
    /// # Example
    /// The standard error of every state coefficient (with `fit` a
    /// [`RobustFit`](super::RobustFit)):
    /// ```ignore
    /// let se = fit.polish.unwrap().curvature.unwrap()
    ///     .standard_errors(|p| p.beta_x.iter().copied().collect());
    /// ```
    pub fn standard_errors(&self, f: impl Fn(&AffineParams) -> Vec<f64>) -> Option<Vec<f64>> {
        self.curvature.information()?;
        let covariance = (-&self.curvature.hessian).cholesky()?.inverse();
        let jacobian = self.jacobian(&f, &covariance)?;
        let spread = &jacobian * covariance * jacobian.transpose();
        Some(
            (0..spread.nrows())
                .map(|i| spread[(i, i)].max(0.0).sqrt())
                .collect(),
        )
    }

    /// The direction along which the log-likelihood is flattest (or rises): the
    /// information's eigenvector of the smallest eigenvalue, as the change of `f(params)`
    /// along it divided by `|f|` (not divided where `f` is 0), and that eigenvalue (negative
    /// where the log-likelihood rises, 0 where a probe found it flat: the data do not
    /// determine it).
    pub fn flattest(&self, f: impl Fn(&AffineParams) -> Vec<f64>) -> Option<(Vec<f64>, f64)> {
        let (direction, value) = self.curvature.flattest()?;
        let scale = DMatrix::identity(direction.len(), direction.len());
        let jacobian = self.jacobian(&f, &scale)?;
        let centre = f(&self.params(&self.curvature.point));
        let moved = jacobian * direction;
        Some((
            moved
                .iter()
                .zip(&centre)
                .map(|(m, c)| if *c != 0.0 { m / c.abs() } else { *m })
                .collect(),
            value,
        ))
    }

    /// The Jacobian of `f` in the coordinates by central differences with steps of a
    /// hundredth of `spread`'s standard deviations (a coordinate's scale).
    fn jacobian(
        &self,
        f: &impl Fn(&AffineParams) -> Vec<f64>,
        spread: &DMatrix<f64>,
    ) -> Option<DMatrix<f64>> {
        let point = &self.curvature.point;
        let d = point.len();
        let rows = f(&self.params(point)).len();
        let mut jacobian = DMatrix::zeros(rows, d);
        for k in 0..d {
            let h = 0.01 * spread[(k, k)].sqrt();
            if !(h.is_finite() && h > 0.0) {
                return None;
            }
            let mut plus = point.clone();
            let mut minus = point.clone();
            plus[k] += h;
            minus[k] -= h;
            let (fp, fm) = (f(&self.params(&plus)), f(&self.params(&minus)));
            for i in 0..rows {
                jacobian[(i, k)] = (fp[i] - fm[i]) / (2.0 * h);
            }
        }
        Some(jacobian)
    }
}

/// One coordinate of the polish.
#[derive(Debug, Clone, Copy, PartialEq)]
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
    let filter = RefCell::new(filter);
    // the log-likelihood at a point (`-inf` where the model is invalid or the filter fails)
    let loglik = |point: &[f64], seed: u64| {
        let params = at(start, &coords, point, constraints.as_ref());
        filtered_loglik(&filter, model.smc_model(&params), &data, seed)
    };
    let common = |point: &[f64]| loglik(point, seed);
    let search = Search::new(&common, stop);
    let origin = values(start, &coords, constraints.as_ref());
    let (start_loglik, start_sd) = scored(&loglik, &origin, seed);
    if !start_loglik.is_finite() || search.evaluate(&origin) == f64::NEG_INFINITY {
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
                let (mut point, current) = search.best();
                point[k] += step;
                if search.evaluate(&point) <= current {
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
    let (from, _) = search.best();
    let steps: Vec<f64> = coords
        .iter()
        .zip(&from)
        .map(|(c, &v)| {
            if c.is_variance() {
                0.3
            } else if v != 0.0 {
                0.1 * v.abs()
            } else {
                0.1
            }
        })
        .collect();
    let mut converged = search
        .nelder_mead(&steps, evaluations)
        .map_err(AffineEmError::InvalidParams)?;
    // 3. the check: the curvature, its Newton point, a simplex along the ridge
    let (simplex_end, simplex_loglik) = search.best();
    let simplex_evaluations = search.evaluations();
    let mut curvature = None;
    if converged && !stop() {
        let third: Vec<f64> = steps.iter().map(|s| s / 3.0).collect();
        let (last, rounds_converged) = search
            .curvature_rounds(
                &third,
                evaluations,
                CLIMB_GAIN.max(CLIMB_SDS * start_sd),
                CURVATURE_ROUNDS,
            )
            .map_err(AffineEmError::InvalidParams)?;
        converged = rounds_converged;
        curvature = last.map(|curvature| PolishCurvature {
            base: start.clone(),
            coordinates: coords.clone(),
            constraints: constraints.clone(),
            curvature,
        });
    }
    let (point, best_loglik) = search.best();
    let check_gain = if point == simplex_end {
        0.0
    } else {
        best_loglik - simplex_loglik
    };
    let (loglik, loglik_sd) = scored(&loglik, &point, seed);
    let polished = at(start, &coords, &point, constraints.as_ref());
    let evaluations = search.evaluations();
    Ok((
        polished,
        Polish {
            particles,
            start_loglik,
            loglik,
            loglik_sd,
            evaluations,
            converged,
            check_evaluations: evaluations - simplex_evaluations,
            check_gain,
            curvature,
            interrupted: stop(),
        },
    ))
}
