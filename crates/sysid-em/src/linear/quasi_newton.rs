//! Quasi-Newton maximisation of the exact log-likelihood of a linear Gaussian model:
//! the polish after EM, and the fit of models EM cannot move (output-error models,
//! `Q = 0`).

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

/// One free block of the model in unconstrained coordinates.
#[derive(Debug, Clone)]
enum Block {
    /// Free entries (column-major indices) of A, B, C, D (0..4) or h (4) or mu (5).
    Entries { matrix: usize, indices: Vec<usize> },
    /// A covariance `F^{1/2} (floor_one I + L L') F^{1/2}` with `L` lower triangular,
    /// its diagonal stored as logarithms (full) or only its diagonal (diagonal; the
    /// entries listed in `zeros` are structural zeros, held at 0).
    Covariance {
        which: usize,
        full: bool,
        scale: DVector<f64>,
        floor_one: bool,
        zeros: Vec<usize>,
    },
}

/// The map between a model and a vector of unconstrained coordinates.
#[derive(Debug, Clone)]
struct Coordinates {
    blocks: Vec<Block>,
    start: LinearGaussianModel,
}

const Q_BLOCK: usize = 0;
const R_BLOCK: usize = 1;
const P1_BLOCK: usize = 2;

fn matrix_of(model: &LinearGaussianModel, which: usize) -> DMatrix<f64> {
    let column = |v: &DVector<f64>| DMatrix::from_column_slice(v.len(), 1, v.as_slice());
    match which {
        0 => model.a().clone(),
        1 => model.b().clone(),
        2 => model.c().clone(),
        3 => model.d().clone(),
        4 => column(model.h()),
        _ => column(model.mu()),
    }
}

fn covariance_of(model: &LinearGaussianModel, which: usize) -> DMatrix<f64> {
    match which {
        Q_BLOCK => model.q().clone(),
        R_BLOCK => model.r().clone(),
        _ => model.p1().clone(),
    }
}

impl Coordinates {
    /// The coordinates of `spec`'s free parameters at `start`, or why there are none.
    fn new(start: &LinearGaussianModel, spec: &LinearEmSpec) -> Result<Coordinates, String> {
        if spec.s {
            return Err("not available with a free S".into());
        }
        let mut blocks = Vec::new();
        let masks = [
            (spec.a, &spec.fixed_entries.a),
            (spec.b, &spec.fixed_entries.b),
            (spec.c, &spec.fixed_entries.c),
            (spec.d, &spec.fixed_entries.d),
        ];
        for (matrix, (free, mask)) in masks.into_iter().enumerate() {
            if free {
                let size = matrix_of(start, matrix).len();
                let indices: Vec<usize> = (0..size)
                    .filter(|&k| mask.as_ref().is_none_or(|m| !m[k]))
                    .collect();
                blocks.push(Block::Entries { matrix, indices });
            }
        }
        for (matrix, free) in [(4, spec.h), (5, spec.mu)] {
            if free {
                let indices = (0..matrix_of(start, matrix).len()).collect();
                blocks.push(Block::Entries { matrix, indices });
            }
        }
        let (n, p) = (start.n(), start.p());
        let covariances = [
            (Q_BLOCK, spec.q, DVector::from_element(n, spec.min_variance)),
            (
                R_BLOCK,
                spec.r,
                match &spec.output_noise_floor {
                    Some(f) => f.map(|v| v.max(spec.min_variance)),
                    None => DVector::from_element(p, spec.min_variance),
                },
            ),
            (
                P1_BLOCK,
                if spec.p1 {
                    Covariance::Full
                } else {
                    Covariance::Fixed
                },
                DVector::zeros(n),
            ),
        ];
        for (which, structure, floor) in covariances {
            let full = match structure {
                Covariance::Fixed => continue,
                Covariance::Full => true,
                Covariance::Diagonal => false,
            };
            let floor_one = floor.iter().all(|&v| v > 0.0);
            let scale = if floor_one {
                floor
            } else {
                DVector::from_element(floor.len(), 1.0)
            };
            let cov = covariance_of(start, which);
            // variances at most 1e-12 of the largest are structural zeros (EM leaves
            // rounding-level values where the start had exact zeros)
            let largest = cov.diagonal().amax();
            let zeros = if full || floor_one {
                Vec::new()
            } else {
                (0..cov.nrows())
                    .filter(|&i| cov[(i, i)] <= 1e-12 * largest)
                    .collect()
            };
            blocks.push(Block::Covariance {
                which,
                full,
                scale,
                floor_one,
                zeros,
            });
        }
        Ok(Coordinates {
            blocks,
            start: start.clone(),
        })
    }

    /// The coordinates of `model` (a full covariance on its floor, or singular, is
    /// moved inside by a relative 1e-10 so that its Cholesky factor exists).
    fn point(&self, model: &LinearGaussianModel) -> Vec<f64> {
        let mut out = Vec::new();
        for block in &self.blocks {
            match block {
                Block::Entries { matrix, indices } => {
                    let m = matrix_of(model, *matrix);
                    out.extend(indices.iter().map(|&k| m[k]));
                }
                Block::Covariance {
                    which,
                    full,
                    scale,
                    floor_one,
                    zeros,
                } => {
                    let cov = covariance_of(model, *which);
                    let d = cov.nrows();
                    let mut inner =
                        DMatrix::from_fn(d, d, |i, j| cov[(i, j)] / (scale[i] * scale[j]).sqrt());
                    if *floor_one {
                        inner -= DMatrix::identity(d, d);
                    }
                    let jitter = 1e-10 * inner.diagonal().amax().max(1e-300);
                    if *full {
                        inner += DMatrix::identity(d, d) * jitter;
                        let l = nalgebra::Cholesky::new(inner.clone())
                            .map(|c| c.l())
                            .unwrap_or_else(|| {
                                DMatrix::from_diagonal(
                                    &inner.diagonal().map(|v| v.max(jitter).sqrt()),
                                )
                            });
                        for j in 0..d {
                            for i in j..d {
                                out.push(if i == j { l[(i, i)].ln() } else { l[(i, j)] });
                            }
                        }
                    } else {
                        for i in (0..d).filter(|i| !zeros.contains(i)) {
                            out.push(inner[(i, i)].max(jitter).ln());
                        }
                    }
                }
            }
        }
        out
    }

    /// The model at `point`, or `None` if it is not a valid model.
    fn model(&self, point: &[f64]) -> Option<LinearGaussianModel> {
        let mut at = 0;
        let mut builder = self.start.to_builder();
        for block in &self.blocks {
            match block {
                Block::Entries { matrix, indices } => {
                    let mut m = matrix_of(&self.start, *matrix);
                    for &k in indices {
                        m[k] = point[at];
                        at += 1;
                    }
                    builder = match matrix {
                        0 => builder.a(m),
                        1 => builder.b(m),
                        2 => builder.c(m),
                        3 => builder.d(m),
                        4 => builder.h(m.column(0).clone_owned()),
                        _ => builder.mu(m.column(0).clone_owned()),
                    };
                }
                Block::Covariance {
                    which,
                    full,
                    scale,
                    floor_one,
                    zeros,
                } => {
                    let d = scale.len();
                    let mut inner = if *full {
                        let mut l = DMatrix::zeros(d, d);
                        for j in 0..d {
                            for i in j..d {
                                l[(i, j)] = if i == j { point[at].exp() } else { point[at] };
                                at += 1;
                            }
                        }
                        &l * l.transpose()
                    } else {
                        let mut diag = DVector::zeros(d);
                        for i in (0..d).filter(|i| !zeros.contains(i)) {
                            diag[i] = point[at].exp();
                            at += 1;
                        }
                        DMatrix::from_diagonal(&diag)
                    };
                    if *floor_one {
                        inner += DMatrix::identity(d, d);
                    }
                    let mut cov =
                        DMatrix::from_fn(d, d, |i, j| inner[(i, j)] * (scale[i] * scale[j]).sqrt());
                    sysid_linalg::symmetrize(&mut cov);
                    builder = match *which {
                        Q_BLOCK => builder.q(cov),
                        R_BLOCK => builder.r(cov),
                        _ => builder.p1(cov),
                    };
                }
            }
        }
        builder.build().ok()
    }
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
fn r_collapsed(r: &DMatrix<f64>, var: &DVector<f64>) -> bool {
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
