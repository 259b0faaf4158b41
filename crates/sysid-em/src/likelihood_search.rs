//! Direct maximisation of a particle log-likelihood on common random numbers: the
//! Nelder–Mead search that the robust driver's polish ([`crate::affine`]) and the
//! multi-start fit of models that are not affine ([`crate::gradient::fit_direct`])
//! share.
//!
//! # Algorithm
//! The objective is a log-likelihood estimate on one seed for every point (nearby
//! points then compare without most of the Monte Carlo noise); `-inf` marks a point
//! that is not a model. Nelder–Mead (argmin 0.11) runs from the best point seen, with
//! the given simplex steps, until the simplex's values agree within [`SD_TOLERANCE`]
//! nats, no evaluation has gained [`STALL_GAIN`] nats in
//! [`STALL_EVALUATIONS_PER_VERTEX`] evaluations per vertex (converged, on a function
//! with Monte Carlo roughness), the budget is spent or the run is stopped. The best
//! point evaluated is kept, whatever the solver's last state.

use argmin::core::{CostFunction, Executor, State, TerminationReason, TerminationStatus};
use argmin::solver::neldermead::NelderMead;
use rand::RngExt;
use std::cell::{Cell, RefCell};
use sysid_smc::{FilterModel, ParticleFilter, Series, stream};

/// Nelder–Mead stops when the standard deviation of the simplex's log-likelihoods is
/// below this (nats).
pub const SD_TOLERANCE: f64 = 0.02;

/// A gain (nats) smaller than this does not count as progress ...
pub const STALL_GAIN: f64 = 0.1;

/// ... and Nelder–Mead has stalled (converged, on a function with Monte Carlo
/// roughness) after this many evaluations per vertex of its simplex without progress.
pub const STALL_EVALUATIONS_PER_VERTEX: usize = 5;

/// Independent filters that score a result (mean and sd).
pub const REPEATS: usize = 4;

/// The cost of a point not evaluated (invalid, or past the budget): worse than any
/// valid point.
const UNEVALUATED: f64 = f64::MAX / 4.0;

/// A log-likelihood on common random numbers, with the best point seen and the count
/// of evaluations.
pub(crate) struct Search<'a> {
    loglik: &'a dyn Fn(&[f64]) -> f64,
    stop: &'a dyn Fn() -> bool,
    evaluations: Cell<usize>,
    best: RefCell<(Vec<f64>, f64)>,
    /// The evaluation count and log-likelihood of the last gain over [`STALL_GAIN`].
    progress: Cell<(usize, f64)>,
    /// Evaluations per vertex without such a gain that end a simplex.
    patience: usize,
}

impl<'a> Search<'a> {
    /// A search of `loglik` (`-inf` where the point is not a model), ended early by
    /// `stop`.
    pub(crate) fn new(loglik: &'a dyn Fn(&[f64]) -> f64, stop: &'a dyn Fn() -> bool) -> Self {
        Search {
            loglik,
            stop,
            evaluations: Cell::new(0),
            best: RefCell::new((Vec::new(), f64::NEG_INFINITY)),
            progress: Cell::new((0, f64::NEG_INFINITY)),
            patience: STALL_EVALUATIONS_PER_VERTEX,
        }
    }

    /// The search with `patience` evaluations per vertex of the simplex without a gain
    /// before it counts as stalled (default [`STALL_EVALUATIONS_PER_VERTEX`], for a
    /// start near the maximum; on a ridge a simplex needs more room to turn).
    pub(crate) fn with_patience(mut self, patience: usize) -> Self {
        self.patience = patience.max(1);
        self
    }

    /// The log-likelihood at `point`, counted and remembered if best.
    pub(crate) fn evaluate(&self, point: &[f64]) -> f64 {
        let count = self.evaluations.get() + 1;
        self.evaluations.set(count);
        let l = (self.loglik)(point);
        let l = if l.is_nan() { f64::NEG_INFINITY } else { l };
        if l > self.progress.get().1 + STALL_GAIN {
            self.progress.set((count, l));
        }
        let mut best = self.best.borrow_mut();
        if l > best.1 {
            *best = (point.to_vec(), l);
        }
        l
    }

    /// The best point evaluated and its log-likelihood.
    pub(crate) fn best(&self) -> (Vec<f64>, f64) {
        self.best.borrow().clone()
    }

    /// Evaluations so far.
    pub(crate) fn evaluations(&self) -> usize {
        self.evaluations.get()
    }

    /// Whether the run was asked to stop.
    pub(crate) fn stopped(&self) -> bool {
        (self.stop)()
    }

    /// Nelder–Mead from the best point so far, its simplex that point and one vertex
    /// per coordinate moved by `steps[k]`, for at most `budget` more evaluations.
    /// Returns whether it converged (see the module docs); the best point is
    /// [`Self::best`].
    ///
    /// # Errors
    /// argmin refuses the simplex (its text).
    pub(crate) fn nelder_mead(&self, steps: &[f64], budget: usize) -> Result<bool, String> {
        let directions: Vec<Vec<f64>> = (0..steps.len())
            .map(|k| {
                let mut d = vec![0.0; steps.len()];
                d[k] = steps[k];
                d
            })
            .collect();
        self.nelder_mead_along(&directions, budget)
    }

    /// [`Self::nelder_mead`] with the simplex's vertices at the best point plus each of
    /// `directions`.
    ///
    /// # Errors
    /// argmin refuses the simplex (its text).
    pub(crate) fn nelder_mead_along(
        &self,
        directions: &[Vec<f64>],
        budget: usize,
    ) -> Result<bool, String> {
        let (from, _) = self.best();
        if directions.is_empty() || budget == 0 || self.stopped() || from.is_empty() {
            return Ok(false);
        }
        let mut simplex = vec![from.clone()];
        for d in directions {
            simplex.push(from.iter().zip(d).map(|(x, dx)| x + dx).collect());
        }
        let steps = directions;
        let solver = NelderMead::new(simplex)
            .with_sd_tolerance(SD_TOLERANCE)
            .map_err(|e| e.to_string())?;
        let budgeted = Budgeted {
            search: self,
            budget: self.evaluations() + budget,
            stall: self.patience * (steps.len() + 1),
            stalled: Cell::new(false),
        };
        // every iteration costs one to n + 2 evaluations: iterations bound loosely, the
        // count of evaluations exactly (the cost refuses past the budget)
        let result = Executor::new(&budgeted, solver)
            .configure(|s| s.max_iters(budget as u64))
            .run();
        Ok((budgeted.stalled.get() && !self.stopped())
            || result.is_ok_and(|r| {
                matches!(
                    r.state().get_termination_status(),
                    TerminationStatus::Terminated(TerminationReason::SolverConverged)
                )
            }))
    }
}

impl Search<'_> {
    /// [`Self::nelder_mead`] restarted from its best point with the full `steps` while
    /// a round gains at least `min_gain` nats and the budget lasts: a simplex that
    /// collapsed on a ridge far from the maximum opens again. Returns whether the last
    /// round converged and gained less than `min_gain`.
    ///
    /// # Errors
    /// As [`Self::nelder_mead`].
    pub(crate) fn nelder_mead_restarted(
        &self,
        steps: &[f64],
        budget: usize,
        min_gain: f64,
    ) -> Result<bool, String> {
        let end = self.evaluations() + budget;
        loop {
            let before = self.best().1;
            let converged = self.nelder_mead(steps, end.saturating_sub(self.evaluations()))?;
            if !converged || self.stopped() || self.evaluations() >= end {
                return Ok(false);
            }
            if self.best().1 < before + min_gain {
                return Ok(true);
            }
        }
    }

    /// The log-likelihood's curvature at the best point by central differences
    /// (`4d (+ re-tries) + 2d(d - 1)` evaluations): along each coordinate the step
    /// starts at `steps[k]` and is doubled (or halved) until the two sides drop by
    /// [`CURVATURE_DROP`] nats on average (at most [`CURVATURE_TRIES`] times), so that
    /// the Monte Carlo roughness of the surface is small against the differences; the
    /// second derivative is taken from the points at one and two steps on each side,
    /// not from the best point itself (the best of many noisy values is biased
    /// upward); the cross terms use the four corners of those steps. `None` where a point is not a
    /// model or the search is stopped.
    pub(crate) fn curvature(&self, steps: &[f64]) -> Option<Curvature> {
        let (x, f0) = self.best();
        let d = x.len();
        let at = |moves: &[(usize, f64)]| {
            let mut p = x.clone();
            for &(k, dx) in moves {
                p[k] += dx;
            }
            self.evaluate(&p)
        };
        let mut h = steps.to_vec();
        let mut sides = vec![(0.0, 0.0); d];
        for k in 0..d {
            for _ in 0..=CURVATURE_TRIES {
                if self.stopped() {
                    return None;
                }
                let (plus, minus) = (at(&[(k, h[k])]), at(&[(k, -h[k])]));
                if !(plus.is_finite() && minus.is_finite()) {
                    h[k] *= 0.5;
                    continue;
                }
                sides[k] = (plus, minus);
                let drop = f0 - 0.5 * (plus + minus);
                if drop < CURVATURE_DROP.0 {
                    h[k] *= 2.0;
                } else if drop > CURVATURE_DROP.1 {
                    h[k] *= 0.5;
                } else {
                    break;
                }
            }
            if !(sides[k].0.is_finite() && sides[k].1.is_finite()) || sides[k] == (0.0, 0.0) {
                return None;
            }
        }
        let mut hessian = nalgebra::DMatrix::zeros(d, d);
        let mut gradient = nalgebra::DVector::zeros(d);
        for k in 0..d {
            let (plus, minus) = sides[k];
            gradient[k] = (plus - minus) / (2.0 * h[k]);
            // not from f0: the best of many evaluations is biased upward by its own
            // Monte Carlo noise, which would make the peak look sharper
            let (far_plus, far_minus) = (at(&[(k, 2.0 * h[k])]), at(&[(k, -2.0 * h[k])]));
            if !(far_plus.is_finite() && far_minus.is_finite()) {
                return None;
            }
            hessian[(k, k)] = (far_plus + far_minus - plus - minus) / (3.0 * h[k] * h[k]);
        }
        for j in 0..d {
            for k in j + 1..d {
                let corners = [
                    at(&[(j, h[j]), (k, h[k])]),
                    at(&[(j, h[j]), (k, -h[k])]),
                    at(&[(j, -h[j]), (k, h[k])]),
                    at(&[(j, -h[j]), (k, -h[k])]),
                ];
                if corners.iter().any(|c| !c.is_finite()) || self.stopped() {
                    return None;
                }
                let cross =
                    (corners[0] - corners[1] - corners[2] + corners[3]) / (4.0 * h[j] * h[k]);
                hessian[(j, k)] = cross;
                hessian[(k, j)] = cross;
            }
        }
        Some(Curvature {
            point: x,
            gradient,
            hessian,
        })
    }
}

/// The target drop (nats) of the log-likelihood over a curvature step: large against
/// the common-random-numbers roughness, small enough for the quadratic to hold.
pub const CURVATURE_DROP: (f64, f64) = (0.5, 8.0);

/// Halvings of a Newton step that does not gain.
pub const NEWTON_HALVINGS: usize = 5;

/// Doublings or halvings of a curvature step.
pub const CURVATURE_TRIES: usize = 4;

/// A local quadratic model of the log-likelihood (see [`Search::curvature`]).
#[derive(Debug, Clone)]
pub(crate) struct Curvature {
    /// Where it was taken.
    pub(crate) point: Vec<f64>,
    /// The gradient there.
    pub(crate) gradient: nalgebra::DVector<f64>,
    /// The Hessian there (symmetric).
    pub(crate) hessian: nalgebra::DMatrix<f64>,
}

impl Curvature {
    /// The information `-H` and its eigen-decomposition, when `-H` is positive
    /// definite (a maximum's neighbourhood).
    pub(crate) fn information(&self) -> Option<nalgebra::SymmetricEigen<f64, nalgebra::Dyn>> {
        let eigen = (-&self.hessian).symmetric_eigen();
        eigen
            .eigenvalues
            .iter()
            .all(|&l| l > 0.0 && l.is_finite())
            .then_some(eigen)
    }

    /// The Newton point `x + (-H)^-1 g` (where the quadratic peaks), or `None` when
    /// `-H` is not positive definite.
    pub(crate) fn newton_point(&self) -> Option<Vec<f64>> {
        let cholesky = (-&self.hessian).cholesky()?;
        let step = cholesky.solve(&self.gradient);
        Some(
            self.point
                .iter()
                .zip(step.iter())
                .map(|(x, s)| x + s)
                .collect(),
        )
    }

    /// A simplex's directions along the information's eigenvectors, each as long as the
    /// quadratic's 1-nat contour there: on a narrow ridge these follow it.
    pub(crate) fn whitened_directions(&self) -> Option<Vec<Vec<f64>>> {
        let eigen = self.information()?;
        Some(
            (0..eigen.eigenvalues.len())
                .map(|i| {
                    let scale = (2.0 / eigen.eigenvalues[i]).sqrt();
                    eigen
                        .eigenvectors
                        .column(i)
                        .iter()
                        .map(|v| v * scale)
                        .collect()
                })
                .collect(),
        )
    }
}

impl Search<'_> {
    /// Restarts a search that has converged with simplexes shaped by the local
    /// curvature ([`Self::curvature`] from `steps`, its Newton point, then Nelder–Mead
    /// along [`Curvature::whitened_directions`]), while a round gains `min_gain` nats,
    /// at most `rounds` times and within `budget` evaluations. Returns the last
    /// curvature taken at the final point when it is a maximum's (for standard
    /// errors), and whether the last round converged.
    ///
    /// # Errors
    /// argmin refuses a simplex (its text).
    pub(crate) fn curvature_rounds(
        &self,
        steps: &[f64],
        budget: usize,
        min_gain: f64,
        rounds: usize,
    ) -> Result<(Option<Curvature>, bool), String> {
        let end = self.evaluations() + budget;
        let mut converged = true;
        let mut last = None;
        for _ in 0..rounds {
            let before = self.best().1;
            let Some(curvature) = self.curvature(steps) else {
                return Ok((last, converged));
            };
            if let Some(newton) = curvature.newton_point() {
                // backtracking: along a ridge the quadratic overshoots
                let x = &curvature.point;
                let mut t = 1.0;
                for _ in 0..NEWTON_HALVINGS {
                    let p: Vec<f64> = x
                        .iter()
                        .zip(&newton)
                        .map(|(a, b)| a + t * (b - a))
                        .collect();
                    if self.evaluate(&p) > before {
                        break;
                    }
                    t *= 0.5;
                }
            }
            let Some(directions) = curvature.whitened_directions() else {
                return Ok((last, converged));
            };
            converged =
                self.nelder_mead_along(&directions, end.saturating_sub(self.evaluations()))?;
            last = Some(curvature);
            if !converged || self.stopped() || self.evaluations() >= end {
                return Ok((last, false));
            }
            if self.best().1 < before + min_gain {
                return Ok((last, true));
            }
        }
        Ok((last, converged))
    }
}

/// The search, refusing to evaluate past a budget or after `stall` evaluations without
/// progress (the run then ends with the best point seen).
struct Budgeted<'s, 'a> {
    search: &'s Search<'a>,
    budget: usize,
    stall: usize,
    stalled: Cell<bool>,
}

impl CostFunction for &Budgeted<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, point: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        // never an error: argmin's Nelder-Mead unwraps the costs of its first simplex;
        // past the budget, a stall or a stop, the rest of its iterations are cheap
        // no-ops and the best point evaluated is the answer
        let count = self.search.evaluations();
        if count - self.search.progress.get().0 >= self.stall {
            self.stalled.set(true);
        }
        if self.stalled.get() || count >= self.budget || self.search.stopped() {
            return Ok(UNEVALUATED);
        }
        let l = self.search.evaluate(point);
        // Nelder-Mead needs a finite order: an invalid point is worse than any valid one
        Ok(if l.is_finite() { -l } else { UNEVALUATED })
    }
}

/// The log-likelihood of `model` on `data` by `filter` with `seed`, or `-inf` where
/// the parameters are not a model or the filter fails: the objective of every search.
pub(crate) fn filtered_loglik<M: FilterModel + Sync, E>(
    filter: &RefCell<ParticleFilter>,
    model: Result<M, E>,
    data: &Series<'_>,
    seed: u64,
) -> f64 {
    let Ok(model) = model else {
        return f64::NEG_INFINITY;
    };
    match filter.borrow_mut().run(&model, data, seed) {
        Ok(summary) if summary.loglik.is_finite() => summary.loglik,
        _ => f64::NEG_INFINITY,
    }
}

/// Mean and standard deviation of [`REPEATS`] independent log-likelihood estimates at
/// `point` (`loglik(point, seed)`), on streams of `seed` other than the common one.
pub(crate) fn scored(loglik: &dyn Fn(&[f64], u64) -> f64, point: &[f64], seed: u64) -> (f64, f64) {
    let runs: Vec<f64> = (0..REPEATS)
        .map(|k| loglik(point, stream(seed, k as u64 + 1).random()))
        .collect();
    let n = runs.len() as f64;
    let mean = runs.iter().sum::<f64>() / n;
    let var = runs.iter().map(|l| (l - mean) * (l - mean)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}
