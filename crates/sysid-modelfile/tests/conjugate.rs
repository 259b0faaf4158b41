//! The conjugate Gibbs step of an affine model file against an independent answer: a
//! long random-walk Metropolis chain on `p(a, b, c, q | x, y)` whose target is the
//! model written out by hand (no code shared with the step or with the model file's
//! affine form). The model has an input, a held nonlinear remainder, a free process
//! variance and a free output coefficient.

use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};
use sysid_modelfile::{AffineConjugate, ModelFile};
use sysid_pmcmc::{ParameterStep, ScalarPrior};
use sysid_smc::{Series, stream};

const MODEL: &str = r#"
format = 1
states = ["x"]
inputs = ["u"]
outputs = ["y"]

[parameters]
a = { value = 0.7, prior = { family = "normal", mean = 0.0, sd = 1.0 } }
b = { value = 0.5, prior = { family = "normal", mean = 0.0, sd = 2.0 } }
c = { value = 1.2, prior = { family = "normal", mean = 0.0, sd = 2.0 } }
q = { value = 0.1, prior = { family = "inverse_gamma", shape = 2.0, scale = 0.1 } }
r = { value = 0.05, fixed = true }

[transition]
x = "a*x + b*u + 0.3*sin(x)"

[observation]
y = "c*x"

[noise]
x = "q"
y = "r"

[initial]
x = { mean = 0, variance = 1 }
"#;

const PRIORS: [ScalarPrior; 4] = [
    ScalarPrior::Normal { mean: 0.0, sd: 1.0 },
    ScalarPrior::Normal { mean: 0.0, sd: 2.0 },
    ScalarPrior::Normal { mean: 0.0, sd: 2.0 },
    ScalarPrior::InverseGamma {
        shape: 2.0,
        scale: 0.1,
    },
];

/// States, inputs and outputs of the model at (0.7, 0.5, 1.2, 0.1), one missing output.
fn data(steps: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut rng = stream(3, 0);
    let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
    let (mut x, mut u, mut y) = (Vec::new(), Vec::new(), Vec::new());
    let mut state = normal();
    for t in 0..steps {
        let input = (0.2 * t as f64).sin() + 0.5 * normal();
        x.push(state);
        u.push(input);
        y.push(if t == 17 {
            f64::NAN
        } else {
            1.2 * state + 0.05f64.sqrt() * normal()
        });
        state = 0.7 * state + 0.5 * input + 0.3 * state.sin() + 0.1f64.sqrt() * normal();
    }
    (x, u, y)
}

/// log p(a, b, c, log q | x, y) + const, written out by hand.
fn log_target(z: &[f64; 4], x: &[f64], u: &[f64], y: &[f64]) -> f64 {
    let [a, b, c, log_q] = *z;
    let q = log_q.exp();
    let prior = -0.5 * a * a - 0.5 * (b / 2.0).powi(2) - 0.5 * (c / 2.0).powi(2)
        // inverse gamma(2, 0.1) density of q, times the Jacobian q of the log scale
        - 3.0 * log_q - 0.1 / q
        + log_q;
    let transitions: f64 = (0..x.len() - 1)
        .map(|t| {
            let mean = a * x[t] + b * u[t] + 0.3 * x[t].sin();
            -0.5 * (x[t + 1] - mean).powi(2) / q - 0.5 * log_q
        })
        .sum();
    let observations: f64 = (0..x.len())
        .filter(|&t| !y[t].is_nan())
        .map(|t| -0.5 * (y[t] - c * x[t]).powi(2) / 0.05)
        .sum();
    prior + transitions + observations
}

fn moments(draws: &[[f64; 4]]) -> Vec<(f64, f64)> {
    (0..4)
        .map(|k| {
            let n = draws.len() as f64;
            let mean = draws.iter().map(|d| d[k]).sum::<f64>() / n;
            let var = draws.iter().map(|d| (d[k] - mean).powi(2)).sum::<f64>() / (n - 1.0);
            (mean, var.sqrt())
        })
        .collect()
}

#[test]
fn the_conjugate_sweep_follows_the_conditional_posterior() {
    let file = ModelFile::parse(MODEL, "test.toml").unwrap();
    let (x, u, y) = data(120);
    let outputs: Vec<f64> = y.clone();
    let series = Series::new(&outputs, 1)
        .unwrap()
        .with_inputs(&u, 1)
        .unwrap();
    let mut step = AffineConjugate::new(&file, &PRIORS).unwrap();
    let mut rng = stream(11, 0);
    let mut theta = vec![0.0, 0.0, 1.0, 1.0];
    let mut gibbs = Vec::new();
    for i in 0..40_000 {
        step.update(&file, &mut theta, &x, &series, &mut rng)
            .unwrap();
        if i >= 1000 {
            gibbs.push([theta[0], theta[1], theta[2], theta[3]]);
        }
    }
    let scales = moments(&gibbs);
    let mut z = [gibbs[0][0], gibbs[0][1], gibbs[0][2], gibbs[0][3].ln()];
    let step_sd = [
        scales[0].1,
        scales[1].1,
        scales[2].1,
        scales[3].1 / scales[3].0,
    ];
    let mut current = log_target(&z, &x, &u, &y);
    let mut rng = stream(12, 0);
    let mut chain = Vec::new();
    for i in 0..600_000 {
        let mut proposal = z;
        for (v, s) in proposal.iter_mut().zip(step_sd) {
            let e: f64 = StandardNormal.sample(&mut rng);
            *v += s * e;
        }
        let candidate = log_target(&proposal, &x, &u, &y);
        if rng.random::<f64>().ln() < candidate - current {
            (z, current) = (proposal, candidate);
        }
        if i >= 20_000 && i % 20 == 0 {
            chain.push([z[0], z[1], z[2], z[3].exp()]);
        }
    }
    let (ours, reference) = (moments(&gibbs), moments(&chain));
    for (k, name) in ["a", "b", "c", "q"].into_iter().enumerate() {
        let ((m1, s1), (m2, s2)) = (ours[k], reference[k]);
        // both chains are autocorrelated: an ESS of a fifth of their draws
        let se = (5.0 * s1 * s1 / gibbs.len() as f64 + 5.0 * s2 * s2 / chain.len() as f64).sqrt();
        assert!(
            (m1 - m2).abs() < 4.0 * se,
            "{name}: mean {m1} against {m2} (se {se})"
        );
        assert!((s1 / s2 - 1.0).abs() < 0.1, "{name}: sd {s1} against {s2}");
    }
}

#[test]
fn models_and_priors_the_step_cannot_take_are_refused() {
    let file = ModelFile::parse(MODEL, "test.toml").unwrap();
    let mut priors = PRIORS;
    priors[3] = ScalarPrior::Normal { mean: 0.0, sd: 1.0 };
    let err = AffineConjugate::new(&file, &priors).unwrap_err();
    assert!(err.reason.contains("q is a noise variance"), "{err}");
    priors = PRIORS;
    priors[0] = ScalarPrior::Flat;
    let err = AffineConjugate::new(&file, &priors).unwrap_err();
    assert!(err.reason.contains("a is a coefficient"), "{err}");
    let nonaffine =
        ModelFile::parse(&MODEL.replace("a*x + b*u", "sin(a*x) + b*u"), "n.toml").unwrap();
    let err = AffineConjugate::new(&nonaffine, &PRIORS).unwrap_err();
    assert!(err.reason.contains("not affine"), "{err}");
}
