//! The intermediate quantity `Q^(theta)` on fixed smoothed trajectories, with its
//! gradient.

use super::{GradientEmError, GradientModel, Gradients, central_difference};
use sysid_smc::{Series, Trajectories};

/// `Q^(theta) = I1 + I2 + I3` of ALGORITHMS.md 4 for the `K` paths of `paths`:
/// ```text
/// I1 = (1/K) sum_k log mu(x_0^k)
/// I2 = (1/K) sum_k sum_{t<T-1} log f(x_{t+1}^k | x_t^k)
/// I3 = (1/K) sum_k sum_t log g(y_t | x_t^k)        (steps with y_t all missing skipped)
/// ```
/// With `grad`, its gradient is written there: from the model's analytic gradients, or
/// by central differences of `Q^`. Summation runs in a fixed order, so the value is
/// reproducible.
///
/// Errors when `theta` (or `grad`) does not have the model's number of parameters, or
/// the trajectories do not fit the model's state dimension or the data's length.
pub fn q_hat<G: GradientModel>(
    model: &G,
    theta: &[f64],
    paths: &Trajectories,
    data: &Series,
    grad: Option<&mut [f64]>,
) -> Result<f64, GradientEmError> {
    q_hat_terms(model, theta, paths, data, grad, Terms::All)
}

/// Which terms of `Q^` to sum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Terms {
    /// `I1 + I2 + I3`.
    All,
    /// `I3` only (the dynamics are held at their closed-form maximiser).
    Observations,
}

/// [`q_hat`] restricted to `terms`.
pub(crate) fn q_hat_terms<G: GradientModel>(
    model: &G,
    theta: &[f64],
    paths: &Trajectories,
    data: &Series,
    grad: Option<&mut [f64]>,
    terms: Terms,
) -> Result<f64, GradientEmError> {
    let d = model.parameter_dim();
    if theta.len() != d || grad.as_ref().is_some_and(|g| g.len() != d) {
        return Err(GradientEmError::InvalidParams(format!(
            "the model has {d} parameters; theta has {}",
            theta.len()
        )));
    }
    if paths.state_dim() != model.state_dim() || paths.steps() != data.steps() {
        return Err(GradientEmError::InvalidParams(format!(
            "trajectories of {} steps of dimension {} do not fit {} data steps and state dimension {}",
            paths.steps(),
            paths.state_dim(),
            data.steps(),
            model.state_dim()
        )));
    }
    Ok(match (grad, model.gradients()) {
        (None, _) => sum_terms(model, theta, paths, data, None, terms),
        (Some(grad), Gradients::Analytic) => {
            sum_terms(model, theta, paths, data, Some(grad), terms)
        }
        (Some(grad), Gradients::FiniteDifferences) => central_difference(theta, grad, |th| {
            sum_terms(model, th, paths, data, None, terms)
        }),
    })
}

fn sum_terms<G: GradientModel>(
    model: &G,
    theta: &[f64],
    paths: &Trajectories,
    data: &Series,
    grad: Option<&mut [f64]>,
    terms: Terms,
) -> f64 {
    let dynamics = terms == Terms::All;
    let p = model.unpack(theta);
    let (k, steps, n) = (paths.paths(), paths.steps(), paths.state_dim());
    let total = match grad {
        None => {
            let mut total: f64 = if dynamics {
                paths
                    .states(0)
                    .chunks_exact(n)
                    .map(|x| model.log_initial(&p, x))
                    .sum()
            } else {
                0.0
            };
            for t in 0..steps {
                let (u, y) = (data.input(t), data.output(t));
                let states = paths.states(t);
                if dynamics && t + 1 < steps {
                    for (x, next) in states
                        .chunks_exact(n)
                        .zip(paths.states(t + 1).chunks_exact(n))
                    {
                        total += model.log_transition(&p, t, x, u, next);
                    }
                }
                if !data.is_missing(t) {
                    for x in states.chunks_exact(n) {
                        total += model.log_observation(&p, t, x, u, y);
                    }
                }
            }
            total
        }
        Some(grad) => {
            grad.fill(0.0);
            let mut total = 0.0;
            if dynamics {
                for x in paths.states(0).chunks_exact(n) {
                    total += model.log_initial_gradient(&p, x, grad);
                }
            }
            for t in 0..steps {
                let (u, y) = (data.input(t), data.output(t));
                let states = paths.states(t);
                if dynamics && t + 1 < steps {
                    for (x, next) in states
                        .chunks_exact(n)
                        .zip(paths.states(t + 1).chunks_exact(n))
                    {
                        total += model.log_transition_gradient(&p, t, x, u, next, grad);
                    }
                }
                if !data.is_missing(t) {
                    for x in states.chunks_exact(n) {
                        total += model.log_observation_gradient(&p, t, x, u, y, grad);
                    }
                }
            }
            grad.iter_mut().for_each(|v| *v /= k as f64);
            total
        }
    };
    total / k as f64
}
