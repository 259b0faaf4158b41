//! The finish of a linear fit: Fisher scoring of the exact log-likelihood of the model
//! as it is written, damped (Levenberg–Marquardt) and restricted to the directions the
//! likelihood can see.

use super::coordinates::Coordinates;
use super::quasi_newton::r_collapsed;
use super::{Covariance, LinearEmError, LinearEmSpec, LinearObjective};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use sysid_kalman::{KalmanWorkspace, LinearGaussianModel};

/// Options of [`maximise_by_scoring`].
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct ScoringOptions {
    /// Scoring iterations at most (each costs `2 k + 1` filter passes for `k` free
    /// coordinates, and one or a few more for its step). Default 100.
    pub max_iterations: usize,
    /// Stop when the predicted gain of a full scoring step, `g' F^+ g / 2` nats, is
    /// below this (the last step, taken, gains it). Default 1e-6.
    pub tol_nats: f64,
}

impl Default for ScoringOptions {
    fn default() -> Self {
        ScoringOptions {
            max_iterations: 100,
            tol_nats: 1e-6,
        }
    }
}

/// What [`maximise_by_scoring`] did.
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct ScoringOutcome {
    /// The best model found (the start itself if nothing better was).
    pub model: LinearGaussianModel,
    /// The objective at the start.
    pub loglik_before: f64,
    /// The objective at [`ScoringOutcome::model`].
    pub loglik: f64,
    /// Free coordinates.
    pub parameters: usize,
    /// Directions the data determine: the rank of the Fisher information at the end
    /// (the free coordinates less the flat directions of the parametrisation, such as
    /// a black-box model's change of state basis).
    pub identified: usize,
    /// Scoring iterations.
    pub iterations: usize,
    /// Filter passes.
    pub evaluations: usize,
    /// The predicted gain of one more full step at the end (nats): the estimated
    /// distance to the maximum.
    pub distance: f64,
    /// Why it stopped.
    pub status: String,
    /// The distance fell below the tolerance.
    pub converged: bool,
    /// A step towards a collapsing `R` was refused (the maximum may be on the boundary
    /// of the parameter set).
    pub boundary: bool,
    /// The stop ended the search: the result is the best point reached.
    pub interrupted: bool,
}

/// The Fisher information uses at most this many observed values (times two moments
/// per value and one column per coordinate, 8 bytes each: 64 MiB at 8 coordinates):
/// it only shapes the steps, the gradient uses every value.
const INFORMATION_VALUES: usize = 8 << 20;

/// Eigenvalues of the scaled information below this fraction of the largest are flat
/// directions (finite differences leave them at about 1e-20 of it).
const FLAT: f64 = 1e-10;

/// Damped steps tried per iteration before the search gives up.
const TRIALS: usize = 16;

/// Maximises `objective` over the free parameters of `spec` from `start` by Fisher
/// scoring.
///
/// # Algorithm
/// The coordinates are those of the quasi-Newton polish (entries of `A, B, C, D, h, mu`;
/// a free covariance by the Cholesky factor of its excess over its floor, with a log
/// diagonal). The exact log-likelihood is a sum over the observed values of the
/// log-density of `N(m_i, s_i^2)`, `m_i` and `s_i` the value's one-step mean and
/// standard deviation given the values before it. Central differences of `m_i`,
/// `ln s_i` and the log-likelihood give, for `2 k` filter passes, the gradient `g`
/// and the Fisher information `F = sum_i (dm_i dm_i' / s_i^2 + 2 dln s_i dln s_i')`.
///
/// The step solves `(F + mu I) d = g` in coordinates scaled to a unit diagonal of `F`,
/// on the eigenvectors of `F` whose eigenvalues exceed 1e-10 of the largest: the
/// directions along which the likelihood is exactly flat (a black-box model's change of
/// state basis, `n^2` of them; the process-noise covariances that give the outputs the
/// same spectrum when there are more states than outputs) are never walked, which is
/// what data-driven local coordinates do (McKelvey, Helmersson and Ribarits 2004).
/// `mu` is raised until a step gains and lowered after a good one
/// (Levenberg–Marquardt, with Nielsen's update); small, the step is Gauss–Newton's,
/// which converges fast where the model fits the data. Where the information misses
/// curvature (a weakly determined direction), a structured secant correction `S`
/// (Dennis, Gay and Welsch's, as in NL2SOL) learns it from the gradients' changes: the
/// step and the predicted gain use `F + S`.
///
/// It stops when the full step's predicted gain `g' F^+ g / 2` is below
/// [`ScoringOptions::tol_nats`].
///
/// # Errors
/// The objective at `start` cannot be evaluated; a free `S` is refused as
/// [`LinearEmError::Unsupported`].
///
/// # References
/// McKelvey, Helmersson and Ribarits, Automatica 40 (2004), data-driven local
/// coordinates; Ljung, System Identification (1999), section 10.2 (Gauss–Newton for
/// prediction-error methods).
pub fn maximise_by_scoring(
    start: &LinearGaussianModel,
    objective: &LinearObjective<'_>,
    spec: &LinearEmSpec,
    options: &ScoringOptions,
    stop: &dyn Fn() -> bool,
) -> Result<ScoringOutcome, LinearEmError> {
    let coordinates = Coordinates::new(start, spec).map_err(LinearEmError::Unsupported)?;
    let mut ws = KalmanWorkspace::new();
    let loglik_before = objective.loglik(start, &mut ws)?;
    let mut point = coordinates.point(start);
    let mut outcome = ScoringOutcome {
        model: start.clone(),
        loglik_before,
        loglik: loglik_before,
        parameters: point.len(),
        identified: 0,
        iterations: 0,
        evaluations: 1,
        distance: 0.0,
        status: "no free parameter".into(),
        converged: point.is_empty(),
        boundary: false,
        interrupted: false,
    };
    if point.is_empty() {
        return Ok(outcome);
    }
    let watch_r = (spec.r != Covariance::Fixed)
        .then(|| objective.output_variances())
        .flatten();
    let search = Search {
        coordinates: &coordinates,
        objective: objective.clone(),
        watch_r: watch_r.as_ref(),
    };
    search.run(&mut point, &mut outcome, options, stop);
    outcome.loglik = objective.loglik(&outcome.model, &mut ws)?;
    outcome.evaluations += 1;
    Ok(outcome)
}

/// The difference step of a coordinate at `x`: a thousandth of its standard error
/// `1 / sqrt(F_jj)` once the information is known (the log-likelihood then changes by
/// about 1e-6 nats, well above its rounding, and the differences' truncation is about
/// 1e-6 of the slope), else `1e-5 max(|x|, 0.01)`; at most a hundredth of `max(|x|, 1)`.
fn difference_step(x: f64, information: Option<f64>) -> f64 {
    let largest = 1e-2 * x.abs().max(1.0);
    match information.filter(|&f| f > 0.0 && f.is_finite()) {
        Some(f) => (1e-3 / f.sqrt()).clamp(1e-9 * x.abs().max(1.0), largest),
        None => 1e-5 * x.abs().max(1e-2),
    }
}

/// A filter workspace without the steady-state reuse: the reuse changes the
/// log-likelihood by up to about `T 16 n eps` relative where the step at which it
/// starts moves, which the differences would read as a slope.
fn exact_workspace() -> KalmanWorkspace {
    let mut ws = KalmanWorkspace::new();
    ws.set_steady_state_reuse(false);
    ws
}

/// One scoring search with a fixed objective.
struct Search<'a> {
    coordinates: &'a Coordinates,
    objective: LinearObjective<'a>,
    watch_r: Option<&'a DVector<f64>>,
}

/// The objective at a point.
enum Value {
    /// The log-likelihood.
    Finite(f64),
    /// The point heads to a collapsing `R`.
    Wall,
    /// Not a valid model, or the filter failed.
    Invalid,
}

/// The gradient and information at a point, in the active coordinates.
struct Derivatives {
    gradient: DVector<f64>,
    information: DMatrix<f64>,
}

impl Search<'_> {
    fn value(&self, point: &[f64], ws: &mut KalmanWorkspace) -> Value {
        let Some(model) = self.coordinates.model(point) else {
            return Value::Invalid;
        };
        if self.watch_r.is_some_and(|var| r_collapsed(model.r(), var)) {
            return Value::Wall;
        }
        match self.objective.loglik(&model, ws) {
            Ok(l) if l.is_finite() => Value::Finite(l),
            _ => Value::Invalid,
        }
    }

    /// The moments at `point` (or `None` if it cannot be evaluated).
    fn moments(&self, point: &[f64], ws: &mut KalmanWorkspace) -> Option<(f64, Vec<f64>)> {
        let model = self.coordinates.model(point)?;
        let (mut moments, mut scratch) = (Vec::new(), Vec::new());
        let l = self
            .objective
            .loglik_and_moments(&model, ws, &mut moments, &mut scratch)
            .ok()?;
        (l.is_finite() && moments.iter().all(|v| v.is_finite())).then_some((l, moments))
    }

    /// Central differences of the log-likelihood and the moments at `point`, whose own
    /// are `value` and `centre` (one-sided next to the edge of the valid models, such
    /// as a stationary objective's unit circle; a coordinate that cannot move either
    /// way gets a zero column, which the step leaves alone).
    fn derivatives(
        &self,
        point: &[f64],
        value: f64,
        centre: &[f64],
        information: Option<&DMatrix<f64>>,
    ) -> Derivatives {
        let k = point.len();
        let values = centre.len() / 2;
        let rows = values.min((INFORMATION_VALUES / k.max(1)).max(1));
        let columns: Vec<(f64, Vec<f64>, Vec<f64>)> = (0..k)
            .into_par_iter()
            .map_init(exact_workspace, |ws, j| {
                let step = difference_step(point[j], information.map(|f| f[(j, j)]));
                let mut shifted = point.to_vec();
                shifted[j] = point[j] + step;
                let up = self.moments(&shifted, ws);
                shifted[j] = point[j] - step;
                let down = self.moments(&shifted, ws);
                let ((hi, hi_moments), (lo, lo_moments), width) = match (&up, &down) {
                    (Some(u), Some(d)) => (u, d, 2.0 * step),
                    (Some(u), None) => (u, &(value, centre.to_vec()), step),
                    (None, Some(d)) => (&(value, centre.to_vec()), d, step),
                    (None, None) => return (0.0, vec![0.0; rows], vec![0.0; rows]),
                };
                let mut mean = Vec::with_capacity(rows);
                let mut log_sd = Vec::with_capacity(rows);
                for i in 0..rows {
                    let sd = centre[2 * i + 1].exp();
                    mean.push((hi_moments[2 * i] - lo_moments[2 * i]) / (width * sd));
                    log_sd.push(
                        (hi_moments[2 * i + 1] - lo_moments[2 * i + 1]) / width
                            * std::f64::consts::SQRT_2,
                    );
                }
                ((hi - lo) / width, mean, log_sd)
            })
            .collect();
        let mut gradient = DVector::zeros(k);
        let mut jacobian = DMatrix::zeros(2 * rows, k);
        for (j, (g, mean, log_sd)) in columns.into_iter().enumerate() {
            gradient[j] = g;
            for i in 0..rows {
                jacobian[(i, j)] = mean[i];
                jacobian[(rows + i, j)] = log_sd[i];
            }
        }
        let mut information = jacobian.tr_mul(&jacobian);
        if rows < values {
            information *= values as f64 / rows as f64;
        }
        Derivatives {
            gradient,
            information,
        }
    }

    /// Scoring from `point` (updated in place) with `outcome` holding the best so far.
    fn run(
        &self,
        point: &mut Vec<f64>,
        outcome: &mut ScoringOutcome,
        options: &ScoringOptions,
        stop: &dyn Fn() -> bool,
    ) {
        let mut ws = exact_workspace();
        let k = point.len();
        let mut damping = 1e-3;
        let mut raise = 2.0;
        let Some((mut value, mut centre)) = self.moments(point, &mut ws) else {
            outcome.status = "the start cannot be evaluated".into();
            return;
        };
        outcome.evaluations += 1;
        outcome.loglik = value;
        outcome.converged = false;
        let mut secant = DMatrix::zeros(k, k);
        let mut last_information: Option<DMatrix<f64>> = None;
        let mut last_gain = f64::INFINITY;
        let mut previous: Option<(Vec<f64>, DVector<f64>)> = None;
        for _ in 0..options.max_iterations {
            if stop() {
                outcome.interrupted = true;
                outcome.status = "interrupted".into();
                return;
            }
            let d = self.derivatives(point, value, &centre, last_information.as_ref());
            last_information = Some(d.information.clone());
            outcome.evaluations += 2 * k;
            outcome.iterations += 1;
            if let Some((from, gradient)) = previous.take() {
                let s = DVector::from_iterator(k, point.iter().zip(&from).map(|(a, b)| a - b));
                update_secant(&mut secant, &s, &(gradient - &d.gradient), &d.information);
            }
            let step = ScaledStep::new(&d, &secant);
            outcome.identified = step.rank;
            // the information's prediction, or the corrected model's once the last step
            // confirmed it (gained less than the tolerance)
            outcome.distance = if last_gain < options.tol_nats {
                step.distance.min(step.corrected_distance)
            } else {
                step.distance
            };
            if outcome.distance < options.tol_nats {
                outcome.converged = true;
                outcome.status = "converged".into();
                // the step whose gain was predicted, taken when it gains: near the
                // maximum it cuts the parameters' distance to it by a large factor
                // for one filter pass
                let (delta, _) = step.step(damping);
                let trial: Vec<f64> = point.iter().zip(&delta).map(|(x, d)| x + d).collect();
                outcome.evaluations += 1;
                if let Value::Finite(l) = self.value(&trial, &mut ws)
                    && l > value
                    && let Some(model) = self.coordinates.model(&trial)
                {
                    *point = trial;
                    outcome.model = model;
                    outcome.loglik = l;
                }
                return;
            }
            let mut accepted = false;
            for _ in 0..TRIALS {
                if stop() {
                    outcome.interrupted = true;
                    outcome.status = "interrupted".into();
                    return;
                }
                let (delta, predicted) = step.step(damping);
                let trial: Vec<f64> = point.iter().zip(&delta).map(|(x, d)| x + d).collect();
                outcome.evaluations += 1;
                match self.value(&trial, &mut ws) {
                    Value::Finite(l) if l > value => {
                        let ratio = (l - value) / predicted.max(f64::MIN_POSITIVE);
                        // Nielsen's rule: a smooth decrease after a step the model
                        // predicted well, an increase after a poor one
                        damping *= (1.0 - (2.0 * ratio - 1.0).powi(3)).max(1.0 / 3.0);
                        raise = 2.0;
                        let Some((l, moments)) = self.moments(&trial, &mut ws) else {
                            break;
                        };
                        last_gain = l - value;
                        outcome.evaluations += 1;
                        previous = Some((std::mem::replace(point, trial), d.gradient.clone()));
                        value = l;
                        centre = moments;
                        if let Some(model) = self.coordinates.model(point) {
                            outcome.model = model;
                            outcome.loglik = value;
                        }
                        accepted = true;
                        break;
                    }
                    Value::Wall => {
                        outcome.boundary = true;
                        damping = (damping * raise).max(1e-6);
                        raise *= 2.0;
                    }
                    _ => {
                        damping = (damping * raise).max(1e-6);
                        raise *= 2.0;
                    }
                }
            }
            if !accepted {
                // no step gains: at the maximum to the precision the differences
                // resolve, unless the predicted gain says otherwise
                outcome.converged = outcome.distance < 1e3 * options.tol_nats;
                outcome.status = if outcome.converged {
                    "converged (no step gains further)".into()
                } else if outcome.boundary {
                    "stopped at the boundary: R heads to zero".into()
                } else {
                    "stopped: no damped step gains".into()
                };
                return;
            }
        }
        outcome.status = "iteration limit".into();
    }
}

/// The structured secant update of Dennis, Gay and Welsch (NL2SOL): `F + S` should map
/// the last step `s` to the change `y` of the negative log-likelihood's gradient, where
/// `F` is the new Fisher information; `S` holds what the information misses (the
/// residuals' own curvature). `S` is first shrunk towards zero when it overstates the
/// curvature along `s`; a step along which the gradient did not turn is skipped.
fn update_secant(
    secant: &mut DMatrix<f64>,
    s: &DVector<f64>,
    y: &DVector<f64>,
    information: &DMatrix<f64>,
) {
    let ys = y.dot(s);
    let threshold = 1e-12 * y.norm() * s.norm();
    if ys.is_nan() || threshold.is_nan() || ys <= threshold {
        return;
    }
    let y_sharp = y - information * s;
    let ss = s.dot(&(&*secant * s));
    if ss.abs() > 0.0 {
        *secant *= (s.dot(&y_sharp).abs() / ss.abs()).min(1.0);
    }
    let r = &y_sharp - &*secant * s;
    let rs = r.dot(s);
    *secant += (&r * y.transpose() + y * r.transpose()) / ys - y * y.transpose() * (rs / (ys * ys));
}

/// The scoring step in coordinates scaled to a unit diagonal of the information,
/// restricted to its non-flat eigenvectors, with the secant correction.
struct ScaledStep {
    /// `1 / sqrt(F_jj)` per coordinate (0 for a coordinate the data do not see).
    scale: DVector<f64>,
    /// The kept eigenvectors of the scaled information times the eigenvectors of the
    /// corrected model restricted to them, as columns.
    vectors: DMatrix<f64>,
    /// The corrected model's eigenvalues in the kept subspace.
    values: DVector<f64>,
    /// The scaled gradient on each of [`ScaledStep::vectors`].
    projections: DVector<f64>,
    /// The least damping that makes the model positive definite.
    floor: f64,
    /// The predicted gain of the undamped scoring step, `g' F^+ g / 2`.
    distance: f64,
    /// The same for the corrected model `F + S` (infinite when it is not positive
    /// definite): the better estimate where the information misses curvature.
    corrected_distance: f64,
    rank: usize,
}

impl ScaledStep {
    fn new(d: &Derivatives, secant: &DMatrix<f64>) -> ScaledStep {
        let k = d.gradient.len();
        let largest = d.information.diagonal().amax();
        let scale = d.information.diagonal().map(|v| {
            if v > 1e-300 && v > 1e-14 * largest {
                1.0 / v.sqrt()
            } else {
                0.0
            }
        });
        let scaled = DMatrix::from_fn(k, k, |i, j| d.information[(i, j)] * scale[i] * scale[j]);
        let eig = scaled.clone().symmetric_eigen();
        let top = eig.eigenvalues.max();
        let kept: Vec<usize> = (0..k)
            .filter(|&i| top > 0.0 && eig.eigenvalues[i] > FLAT * top)
            .collect();
        let basis = DMatrix::from_fn(k, kept.len(), |i, j| eig.eigenvectors[(i, kept[j])]);
        let scaled_gradient = d.gradient.component_mul(&scale);
        let on_basis = basis.tr_mul(&scaled_gradient);
        let distance = 0.5
            * kept
                .iter()
                .enumerate()
                .map(|(j, &i)| on_basis[j] * on_basis[j] / eig.eigenvalues[i])
                .sum::<f64>();
        // the corrected model F + S in the kept subspace of the scaled coordinates
        let scaled_secant = DMatrix::from_fn(k, k, |i, j| secant[(i, j)] * scale[i] * scale[j]);
        let mut model = basis.tr_mul(&(&scaled + scaled_secant)) * &basis;
        sysid_linalg::symmetrize(&mut model);
        let inner = model.symmetric_eigen();
        let floor = (-inner.eigenvalues.min()).max(0.0) * 1.01;
        let projections = inner.eigenvectors.tr_mul(&on_basis);
        let corrected_distance = if floor > 0.0 {
            f64::INFINITY
        } else {
            0.5 * projections
                .iter()
                .zip(inner.eigenvalues.iter())
                .map(|(c, l)| c * c / l)
                .sum::<f64>()
        };
        ScaledStep {
            corrected_distance,
            scale,
            rank: kept.len(),
            projections,
            vectors: basis * inner.eigenvectors,
            values: inner.eigenvalues,
            floor,
            distance,
        }
    }

    /// The step `(M + mu I)^{-1} g` of the corrected model `M` (damping raised to keep
    /// it positive definite) in the original coordinates, and its predicted gain.
    fn step(&self, damping: f64) -> (Vec<f64>, f64) {
        let damping = damping + self.floor;
        let mut gain = 0.0;
        let weights = DVector::from_fn(self.values.len(), |i, _| {
            let (c, l) = (self.projections[i], self.values[i]);
            let w = if l + damping > 0.0 {
                c / (l + damping)
            } else {
                0.0
            };
            gain += c * w - 0.5 * l * w * w;
            w
        });
        let scaled = &self.vectors * weights;
        (
            scaled.component_mul(&self.scale).iter().copied().collect(),
            gain,
        )
    }
}
