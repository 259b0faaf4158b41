//! The M-step: maximise `Q^(theta)` on fixed trajectories by BFGS.

use std::cell::RefCell;

use argmin::core::{CostFunction, Executor, Gradient, State};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::BFGS;
use sysid_smc::{Series, Trajectories};

use super::objective::{Terms, q_hat_terms};
use super::{GradientEmError, GradientModel, ObservationSum, q_hat};

/// Settings of the BFGS M-step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MStepOptions {
    /// BFGS iterations at most. Default 50.
    pub max_iterations: u64,
    /// Stop when the gradient norm of `-Q^ / T` falls below this. Default 1e-8.
    pub tol_grad: f64,
    /// Hold the dynamics' entries (those [`GradientModel::maximise_dynamics`] sets) at
    /// their current values and run BFGS over the rest only. No effect for a model
    /// without a closed-form dynamics step. Default false.
    pub hold_dynamics: bool,
    /// After the closed-form dynamics step, use the model's exact maximiser of `I3`
    /// where it has one ([`ObservationSum::maximise`]) instead of BFGS. Default true.
    pub exact_observations: bool,
}

impl Default for MStepOptions {
    fn default() -> Self {
        MStepOptions {
            max_iterations: 50,
            tol_grad: 1e-8,
            hold_dynamics: false,
            exact_observations: true,
        }
    }
}

/// What an M-step did.
#[derive(Debug, Clone, PartialEq)]
pub struct MStepOutcome {
    /// The new parameters (the old ones if BFGS found nothing better).
    pub theta: Vec<f64>,
    /// `Q^` at the old parameters.
    pub q_before: f64,
    /// `Q^` at the new parameters (`>= q_before`).
    pub q_after: f64,
    /// Cost-and-gradient evaluations.
    pub evaluations: usize,
    /// Why BFGS stopped (argmin's termination status, or its error).
    pub status: String,
    /// BFGS's final inverse-Hessian estimate (row-major rows), to warm-start the next
    /// M-step; `None` when BFGS failed.
    pub inverse_hessian: Option<Vec<Vec<f64>>>,
}

/// One evaluation of the cost: the point, `-Q^ / T` and its gradient.
struct Evaluation {
    theta: Vec<f64>,
    cost: f64,
    grad: Vec<f64>,
}

/// `-Q^(theta) / T` and its gradient, computed together and cached for the last
/// point (argmin asks for the cost and the gradient separately).
///
/// With `free`, BFGS moves only those entries of `theta` (the rest stay at `base`'s
/// values, the dynamics' closed-form maximiser) and the cost is `-I3 / T`.
struct NegativeQ<'a, G> {
    model: &'a G,
    paths: &'a Trajectories,
    data: &'a Series<'a>,
    scale: f64,
    base: Vec<f64>,
    free: Option<Vec<usize>>,
    /// The model's prepared `I3` (only with `free`), instead of the term-by-term sum.
    observations: Option<Box<dyn ObservationSum + 'a>>,
    cache: RefCell<Option<Evaluation>>,
    evaluations: RefCell<usize>,
}

impl<G: GradientModel> NegativeQ<'_, G> {
    /// The full parameter vector of BFGS's point.
    fn full(&self, point: &[f64]) -> Vec<f64> {
        match &self.free {
            None => point.to_vec(),
            Some(free) => {
                let mut theta = self.base.clone();
                for (&i, &v) in free.iter().zip(point) {
                    theta[i] = v;
                }
                theta
            }
        }
    }

    fn evaluate(&self, point: &[f64]) -> Result<(f64, Vec<f64>), argmin::core::Error> {
        if let Some(e) = self.cache.borrow().as_ref()
            && e.theta.as_slice() == point
        {
            return Ok((e.cost, e.grad.clone()));
        }
        if point.iter().any(|v| !v.is_finite()) {
            return Err(argmin::core::Error::msg(format!(
                "the line search reached non-finite parameters {point:?}"
            )));
        }
        let theta = self.full(point);
        let terms = match self.free {
            None => Terms::All,
            Some(_) => Terms::Observations,
        };
        let mut full_grad = vec![0.0; theta.len()];
        let q = match &self.observations {
            Some(observations) => observations.value_and_gradient(&theta, &mut full_grad),
            None => q_hat_terms(
                self.model,
                &theta,
                self.paths,
                self.data,
                Some(&mut full_grad),
                terms,
            )
            .map_err(|e| argmin::core::Error::msg(e.to_string()))?,
        };
        *self.evaluations.borrow_mut() += 1;
        if !q.is_finite() || full_grad.iter().any(|g| !g.is_finite()) {
            return Err(argmin::core::Error::msg(format!(
                "Q^ or its gradient is not finite at theta = {theta:?}"
            )));
        }
        let cost = -q * self.scale;
        let mut grad = match &self.free {
            None => full_grad,
            Some(free) => free.iter().map(|&i| full_grad[i]).collect(),
        };
        grad.iter_mut().for_each(|g| *g *= -self.scale);
        *self.cache.borrow_mut() = Some(Evaluation {
            theta: point.to_vec(),
            cost,
            grad: grad.clone(),
        });
        Ok((cost, grad))
    }
}

impl<G: GradientModel> CostFunction for NegativeQ<'_, G> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, theta: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        Ok(self.evaluate(theta)?.0)
    }
}

impl<G: GradientModel> Gradient for NegativeQ<'_, G> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;

    fn gradient(&self, theta: &Vec<f64>) -> Result<Vec<f64>, argmin::core::Error> {
        Ok(self.evaluate(theta)?.1)
    }
}

/// Maximises `Q^` over `theta` from `start` by BFGS with the More-Thuente line search
/// (argmin 0.11), on `-Q^ / T` (per-step scale, so that the identity is a sensible
/// first inverse Hessian). `inverse_hessian` warm-starts BFGS (the previous M-step's
/// final estimate: consecutive `Q^` differ little); `None` starts from the identity.
///
/// When the model has a closed-form dynamics step
/// ([`GradientModel::maximise_dynamics`]), the dynamics' entries are set to it first
/// (or held, with [`MStepOptions::hold_dynamics`]) and BFGS maximises `I3` over the
/// other entries only.
///
/// The result never has a smaller `Q^` than `start`: if BFGS fails (a non-finite
/// value at a trial point) or ends lower, the best point it visited is kept, or the
/// closed-form point, or `start` itself.
pub fn m_step<G: GradientModel>(
    model: &G,
    paths: &Trajectories,
    data: &Series,
    start: &[f64],
    options: &MStepOptions,
    inverse_hessian: Option<Vec<Vec<f64>>>,
) -> Result<MStepOutcome, GradientEmError> {
    let q_before = q_hat(model, start, paths, data, None)?;
    if !q_before.is_finite() {
        return Err(GradientEmError::NonFiniteQ {
            theta: start.to_vec(),
        });
    }
    // BFGS starts from `base`: the closed-form dynamics (or the held ones) with the
    // rest of `start`
    let mut base = start.to_vec();
    let held = model.maximise_dynamics(paths, &mut base);
    if options.hold_dynamics || held.is_none() {
        base.copy_from_slice(start);
    }
    let free = held.map(|held| {
        (0..start.len())
            .filter(|i| !held.contains(i))
            .collect::<Vec<_>>()
    });
    let observations = free
        .as_ref()
        .and_then(|_| model.prepare_observations(paths, data));
    let exact =
        options.exact_observations && observations.as_ref().is_some_and(|o| o.maximise(&mut base));
    let bfgs = if exact {
        Bfgs {
            candidate: None,
            status: "closed form".into(),
            evaluations: 0,
            inverse_hessian,
        }
    } else {
        let problem = NegativeQ {
            model,
            paths,
            data,
            scale: 1.0 / data.steps() as f64,
            base: base.clone(),
            observations,
            free,
            cache: RefCell::new(None),
            evaluations: RefCell::new(0),
        };
        run_bfgs(problem, options, inverse_hessian)?
    };
    let mut outcome = MStepOutcome {
        theta: start.to_vec(),
        q_before,
        q_after: q_before,
        evaluations: bfgs.evaluations,
        status: bfgs.status,
        inverse_hessian: bfgs.inverse_hessian,
    };
    for theta in bfgs.candidate.into_iter().chain(std::iter::once(base)) {
        let q = q_hat(model, &theta, paths, data, None)?;
        if q.is_finite() && q >= q_before {
            outcome.theta = theta;
            outcome.q_after = q;
            break;
        }
    }
    Ok(outcome)
}

/// What BFGS returned: its best point (full parameters), why it stopped, how many
/// evaluations it made, its final inverse Hessian.
struct Bfgs {
    candidate: Option<Vec<f64>>,
    status: String,
    evaluations: usize,
    inverse_hessian: Option<Vec<Vec<f64>>>,
}

/// BFGS on `problem` from the free entries of its `base` (all of them without `free`).
fn run_bfgs<G: GradientModel>(
    problem: NegativeQ<'_, G>,
    options: &MStepOptions,
    inverse_hessian: Option<Vec<Vec<f64>>>,
) -> Result<Bfgs, GradientEmError> {
    let first_point: Vec<f64> = match &problem.free {
        None => problem.base.clone(),
        Some(free) => free.iter().map(|&i| problem.base[i]).collect(),
    };
    let d = first_point.len();
    let linesearch = MoreThuenteLineSearch::new();
    let solver = BFGS::new(linesearch)
        .with_tolerance_grad(options.tol_grad)
        .map_err(|e| GradientEmError::InvalidOption(e.to_string()))?;
    let usable = |h: &Vec<Vec<f64>>| {
        h.len() == d
            && h.iter()
                .all(|row| row.len() == d && row.iter().all(|v| v.is_finite()))
    };
    let first_inverse = inverse_hessian.filter(usable).unwrap_or_else(|| {
        (0..d)
            .map(|i| (0..d).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
            .collect()
    });
    let result = Executor::new(problem, solver)
        .configure(|state| {
            state
                .param(first_point)
                .inv_hessian(first_inverse)
                .max_iters(options.max_iterations)
        })
        .run();
    Ok(match result {
        Ok(mut r) => {
            let problem = r.problem.problem.take();
            Bfgs {
                status: r.state.get_termination_status().to_string(),
                evaluations: problem.as_ref().map_or(0, |p| *p.evaluations.borrow()),
                inverse_hessian: r.state.take_inv_hessian(),
                candidate: r
                    .state
                    .take_best_param()
                    .zip(problem)
                    .map(|(point, p)| p.full(&point)),
            }
        }
        Err(e) => Bfgs {
            candidate: None,
            status: format!("error: {e}"),
            evaluations: 0,
            inverse_hessian: None,
        },
    })
}
