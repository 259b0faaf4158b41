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
            value: f0,
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

/// Whether an information's eigenvalues are those of a maximum's: all finite and
/// above [`FLAT_RATIO`] times the largest (a direction a probe found flat has 0, which
/// rounding may leave a hair above).
pub fn is_definite(eigenvalues: &nalgebra::DVector<f64>) -> bool {
    let largest = eigenvalues.iter().fold(0.0_f64, |m, &l| m.max(l));
    eigenvalues
        .iter()
        .all(|&l| l.is_finite() && l > FLAT_RATIO * largest)
}

/// An information eigenvalue below this fraction of the largest is a flat direction.
pub const FLAT_RATIO: f64 = 1e-9;

/// A local quadratic model of the log-likelihood (see [`Search::curvature`]).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Curvature {
    /// Where it was taken.
    pub(crate) point: Vec<f64>,
    /// The log-likelihood there (common random numbers).
    pub(crate) value: f64,
    /// The gradient there.
    pub(crate) gradient: nalgebra::DVector<f64>,
    /// The Hessian there (symmetric).
    pub(crate) hessian: nalgebra::DMatrix<f64>,
}

impl Curvature {
    /// The information's eigenvector of the smallest eigenvalue (unit length), and that
    /// eigenvalue (0 within [`FLAT_RATIO`] of the largest: a flat direction).
    pub(crate) fn flattest(&self) -> Option<(nalgebra::DVector<f64>, f64)> {
        let eigen = (-&self.hessian).symmetric_eigen();
        let (k, &value) = eigen
            .eigenvalues
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))?;
        let largest = eigen.eigenvalues.iter().fold(0.0_f64, |m, &l| m.max(l));
        let value = if value.abs() <= FLAT_RATIO * largest {
            0.0
        } else {
            value
        };
        Some((eigen.eigenvectors.column(k).into_owned(), value))
    }

    /// The information `-H` and its eigen-decomposition, when `-H` is positive
    /// definite (a maximum's neighbourhood).
    pub(crate) fn information(&self) -> Option<nalgebra::SymmetricEigen<f64, nalgebra::Dyn>> {
        let eigen = (-&self.hessian).symmetric_eigen();
        is_definite(&eigen.eigenvalues).then_some(eigen)
    }

    /// The Newton point `x + (-H)^-1 g` (where the quadratic peaks), or `None` when
    /// `-H` is not positive definite.
    pub(crate) fn newton_point(&self) -> Option<Vec<f64>> {
        self.information()?;
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
    /// curvature taken (for standard errors when it is a maximum's, see
    /// [`Curvature::information`]; otherwise where a direction is flat or rising), and
    /// whether the last round converged.
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
        for round in 0..rounds {
            let before = self.best().1;
            let Some(mut curvature) = self.curvature(steps) else {
                return Ok((last, converged));
            };
            if self.probe_flat_directions(&mut curvature, steps, min_gain) == Probe::Climbed
                && round + 1 < rounds
            {
                // a better point along the flattest direction: the next round starts
                // there (in the last round, the simplex along the ridge does)
                converged = false;
                last = Some(curvature);
                continue;
            }
            converged = true;
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
                // not a maximum's curvature: returned, for the caller to probe or warn
                return Ok((Some(curvature), converged));
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

/// What probing the flattest direction of a curvature found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Probe {
    /// A point along it scored more than the gain asked above the best: it is the best
    /// now, and the curvature is stale.
    Climbed,
    /// Its curvature was measured along it by points that drop by [`PROBE_DROP`]
    /// nats, and replaced the estimate's unless it confirmed it (see
    /// [`Search::probe_flattest`]).
    Measured,
    /// The log-likelihood barely changes along it within [`PROBE_DOUBLINGS`] doublings:
    /// the curvature there is set to 0 (not a maximum's).
    Flat,
    /// A point along it is not a model, or the run was stopped: the curvature stands.
    Unprobed,
}

/// Doublings of the step along the flattest direction before it counts as flat.
pub const PROBE_DOUBLINGS: usize = 8;

/// The target drop (nats) of the log-likelihood over a probe's step: large against
/// the common-random-numbers roughness (tenths of a nat), which the coordinate steps'
/// 0.5 nats are not along a ridge, and small enough that the quadratic still holds
/// (larger drops put the linear model's standard errors 20 % low).
pub const PROBE_DROP: (f64, f64) = (1.0, 4.0);

/// A probe's curvature within this factor of the coordinate steps' estimate confirms
/// it.
pub const CONFIRMED: f64 = 4.0;

impl Search<'_> {
    /// [`Self::probe_flattest`] until the flattest direction is one already measured
    /// (at most once per dimension): a ridge of several parameters has more than one
    /// direction that coordinate steps cannot see. Returns the last probe's outcome, or
    /// [`Probe::Flat`] if any direction was flat.
    pub(crate) fn probe_flat_directions(
        &self,
        curvature: &mut Curvature,
        steps: &[f64],
        min_gain: f64,
    ) -> Probe {
        let mut probed: Vec<nalgebra::DVector<f64>> = Vec::new();
        let mut flat = false;
        for _ in 0..curvature.point.len() {
            let Some((direction, _)) = curvature.flattest() else {
                break;
            };
            if probed.iter().any(|p| p.dot(&direction).abs() > 0.9) {
                break;
            }
            match self.probe_flattest(curvature, steps, min_gain) {
                Probe::Measured => {}
                Probe::Flat => flat = true,
                other => return other,
            }
            probed.push(direction);
        }
        if flat { Probe::Flat } else { Probe::Measured }
    }

    /// Probes the direction along which `curvature` is flattest (the information's
    /// eigenvector of the smallest eigenvalue). The central differences of
    /// [`Self::curvature`] take steps fitted to each coordinate alone; along a ridge
    /// that a combination of coordinates makes, the drop over those steps is below the
    /// Monte Carlo roughness, and the estimated curvature there is noise (even
    /// negative). Along that eigenvector the step grows from the quadratic's
    /// [`PROBE_DROP`] point (or the mean coordinate step) until the two sides drop by
    /// [`PROBE_DROP`] nats on average; a point that scores `min_gain` above the centre
    /// is a climb. A direction whose sides never drop by that much in
    /// [`PROBE_DOUBLINGS`] doublings is flat: its information is set to 0. Otherwise
    /// the second difference `2 (f0 - mean(sides)) / t^2` is the curvature there; it
    /// replaces the coordinate estimate unless it confirms it (within a factor
    /// [`CONFIRMED`]: the coordinate steps are smaller and see the peak's own
    /// curvature, the probe's also some of the fall-off beyond).
    pub(crate) fn probe_flattest(
        &self,
        curvature: &mut Curvature,
        steps: &[f64],
        min_gain: f64,
    ) -> Probe {
        let d = curvature.point.len();
        let Some((direction, value)) = curvature.flattest().filter(|_| d > 0) else {
            return Probe::Unprobed;
        };
        // a point of the curvature's own differences may have scored a little higher
        // than its centre (Monte Carlo roughness); more than `min_gain` is a climb
        if self.best().1 > curvature.value + min_gain {
            return Probe::Climbed;
        }
        let (centre, f0) = (curvature.point.clone(), curvature.value);
        let along = |t: f64| -> f64 {
            let p: Vec<f64> = centre
                .iter()
                .zip(direction.iter())
                .map(|(x, v)| x + t * v)
                .collect();
            self.evaluate(&p)
        };
        let mean_step = (steps.iter().map(|h| h * h).sum::<f64>() / d as f64).sqrt();
        let mut t = if value > 0.0 {
            (2.0 * PROBE_DROP.0 / value).sqrt()
        } else {
            mean_step
        };
        // the step with the smallest drop of at least PROBE_DROP.0: (t, plus, minus)
        let mut measured_at: Option<(f64, f64, f64)> = None;
        for _ in 0..=PROBE_DOUBLINGS {
            if self.stopped() || !(t.is_finite() && t > 0.0) {
                return Probe::Unprobed;
            }
            let (plus, minus) = (along(t), along(-t));
            if plus.max(minus) > f0 + min_gain {
                return Probe::Climbed;
            }
            if !(plus.is_finite() && minus.is_finite()) {
                t *= 0.5;
                continue;
            }
            let drop = f0 - 0.5 * (plus + minus);
            if drop >= PROBE_DROP.0 {
                let smaller =
                    measured_at.is_none_or(|(u, p, m)| drop < f0 - 0.5 * (p + m) || u > t);
                if smaller {
                    measured_at = Some((t, plus, minus));
                }
            }
            if drop < PROBE_DROP.0 {
                if measured_at.is_some() {
                    break; // bracketed: the larger step stands
                }
                t *= 2.0;
            } else if drop > PROBE_DROP.1 {
                t *= 0.5;
            } else {
                break;
            }
        }
        let (measured, slope) = match measured_at {
            Some((t, plus, minus)) => (
                2.0 * (f0 - 0.5 * (plus + minus)) / (t * t),
                (plus - minus) / (2.0 * t),
            ),
            None => (0.0, curvature.gradient.dot(&direction)),
        };
        let confirmed =
            value > 0.0 && measured > 0.0 && (measured / value).ln().abs() < CONFIRMED.ln();
        if !confirmed {
            // -H = I; I' = I + (measured - value) v v'; the slope along v from the sides
            curvature.hessian -= (measured - value) * &direction * direction.transpose();
            let along_gradient = curvature.gradient.dot(&direction);
            curvature.gradient += (slope - along_gradient) * &direction;
        }
        if measured_at.is_some() {
            Probe::Measured
        } else {
            Probe::Flat
        }
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
