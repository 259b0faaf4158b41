//! The intermediate quantity `Q^(theta)` on fixed smoothed trajectories, with its
//! gradient.

use super::GradientModel;
use sysid_smc::{Series, Trajectories};

/// `Q^(theta) = I1 + I2 + I3` of ALGORITHMS.md 4 for the `K` paths of `paths`:
/// ```text
/// I1 = (1/K) sum_k log mu(x_0^k)
/// I2 = (1/K) sum_k sum_{t<T-1} log f(x_{t+1}^k | x_t^k)
/// I3 = (1/K) sum_k sum_t log g(y_t | x_t^k)        (steps with y_t all missing skipped)
/// ```
/// With `grad`, its gradient is written there (overwritten). Summation runs in a fixed
/// order, so the value is reproducible.
pub fn q_hat<G: GradientModel>(
    model: &G,
    theta: &[f64],
    paths: &Trajectories,
    data: &Series,
    grad: Option<&mut [f64]>,
) -> f64 {
    let k = paths.paths();
    let steps = paths.steps();
    let mut total = 0.0;
    match grad {
        None => {
            for j in 0..k {
                total += model.log_initial(theta, paths.state(0, j));
            }
            for t in 0..steps {
                let (u, observed) = (data.input(t), !data.is_missing(t));
                for j in 0..k {
                    let x = paths.state(t, j);
                    if t + 1 < steps {
                        total += model.log_transition(theta, t, x, u, paths.state(t + 1, j));
                    }
                    if observed {
                        total += model.log_observation(theta, t, x, u, data.output(t));
                    }
                }
            }
        }
        Some(grad) => {
            grad.fill(0.0);
            for j in 0..k {
                total += model.log_initial_gradient(theta, paths.state(0, j), grad);
            }
            for t in 0..steps {
                let (u, observed) = (data.input(t), !data.is_missing(t));
                for j in 0..k {
                    let x = paths.state(t, j);
                    if t + 1 < steps {
                        let next = paths.state(t + 1, j);
                        total += model.log_transition_gradient(theta, t, x, u, next, grad);
                    }
                    if observed {
                        total +=
                            model.log_observation_gradient(theta, t, x, u, data.output(t), grad);
                    }
                }
            }
            grad.iter_mut().for_each(|g| *g /= k as f64);
        }
    }
    total / k as f64
}
