//! What the two additive-Gaussian models (a model file's and a `GaussianModel`'s)
//! compute the same way: the simulation loop and the diagonal initial density.

use rand_distr::{Distribution, StandardNormal};
use sysid_smc::ModelError;
use sysid_smc::{InitialSampler, Rng, ScalarGaussianKernel, TransitionSampler};

/// Simulates `steps` samples from the random stream `(seed, 0)`: the initial state,
/// then per step the measurement noise (`observation_mean` writes `g(x, u, t)`, and
/// `measurement_sd` scales the draws) and the process noise. Returns the states and
/// outputs, time-major; an error for inputs of the wrong length or a value that is not
/// finite.
pub(crate) fn simulate<M: InitialSampler + TransitionSampler>(
    model: &M,
    (steps, inputs, m): (usize, &[f64], usize),
    measurement_sd: &[f64],
    seed: u64,
    observation_mean: impl Fn(usize, &[f64], &[f64], &mut [f64]),
) -> Result<(Vec<f64>, Vec<f64>), ModelError> {
    if inputs.len() != steps * m {
        return Err(format!(
            "{} input values given for {steps} steps of {m} inputs",
            inputs.len()
        )
        .into());
    }
    let (n, p) = (model.state_dim(), measurement_sd.len());
    let mut rng: Rng = sysid_smc::stream(seed, 0);
    let mut x = vec![0.0; n];
    model.sample_initial(&mut x, &mut rng);
    let mut states = Vec::with_capacity(steps * n);
    let mut outputs = Vec::with_capacity(steps * p);
    let (mut next, mut mean) = (vec![0.0; n], vec![0.0; p]);
    for t in 0..steps {
        let u = &inputs[t * m..(t + 1) * m];
        states.extend_from_slice(&x);
        observation_mean(t, &x, u, &mut mean);
        for (g, sd) in mean.iter().zip(measurement_sd) {
            let z: f64 = StandardNormal.sample(&mut rng);
            outputs.push(g + sd * z);
        }
        model.sample_transition(t, &x, u, &mut next, &mut rng);
        if let Some(bad) = next
            .iter()
            .chain(&outputs[t * p..])
            .find(|v| !v.is_finite())
        {
            return Err(format!("the simulation diverged at step {t} (value {bad})").into());
        }
        std::mem::swap(&mut x, &mut next);
    }
    Ok((states, outputs))
}

/// `log N(x; mean, diag var)`, a zero variance being a point mass (0 at its mean,
/// `-inf` elsewhere).
pub(crate) fn log_initial(x: &[f64], mean: &[f64], var: &[f64]) -> f64 {
    let mut total = 0.0;
    for ((&xi, &m), &v) in x.iter().zip(mean).zip(var) {
        if v == 0.0 {
            if xi != m {
                return f64::NEG_INFINITY;
            }
            continue;
        }
        total += ScalarGaussianKernel::with_variance(v).log_density(m, xi);
    }
    total
}
