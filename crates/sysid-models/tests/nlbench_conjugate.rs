//! The conjugate Gibbs step of nlbench against an independent answer: a long
//! random-walk Metropolis chain on `p(a, b, c, d | x, y)` built from the model's own
//! densities (`TransitionDensity::log_transition`, `ObservationDensity::log_observation`
//! and the priors), which share no code with the step's regression formulas (a wrong
//! time index of the cosine, or a wrong regressor, would show).

use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};
use sysid_models::{Nlbench, NlbenchConjugate, NlbenchFamily, NlbenchParams};
use sysid_pmcmc::{ModelFamily, ParameterStep, ScalarPrior};
use sysid_smc::{ObservationDensity, Series, TransitionDensity, stream};

const PRIORS: [ScalarPrior; 4] = [
    ScalarPrior::Normal {
        mean: 0.0,
        sd: 10.0,
    },
    ScalarPrior::Normal {
        mean: 0.0,
        sd: 100.0,
    },
    ScalarPrior::Normal {
        mean: 0.0,
        sd: 100.0,
    },
    ScalarPrior::Normal {
        mean: 0.0,
        sd: 10.0,
    },
];

fn log_target(family: &NlbenchFamily, theta: &[f64], x: &[f64], y: &[f64]) -> f64 {
    let model = family.model(theta).unwrap();
    let prior: f64 = theta
        .iter()
        .zip(PRIORS)
        .map(|(v, p)| match p {
            ScalarPrior::Normal { mean, sd } => -0.5 * ((v - mean) / sd).powi(2),
            _ => unreachable!(),
        })
        .sum();
    let transitions: f64 = (0..x.len() - 1)
        .map(|t| model.log_transition(t, &x[t..=t], &[], &x[t + 1..t + 2]))
        .sum();
    let observations: f64 = (0..x.len())
        .map(|t| model.log_observation(t, &x[t..=t], &[], &y[t..=t]))
        .sum();
    prior + transitions + observations
}

/// Mean and standard deviation of each coordinate.
fn moments(draws: &[Vec<f64>]) -> Vec<(f64, f64)> {
    (0..draws[0].len())
        .map(|k| {
            let n = draws.len() as f64;
            let mean = draws.iter().map(|d| d[k]).sum::<f64>() / n;
            let var = draws.iter().map(|d| (d[k] - mean).powi(2)).sum::<f64>() / (n - 1.0);
            (mean, var.sqrt())
        })
        .collect()
}

#[test]
fn the_conjugate_draws_follow_the_conditional_posterior() {
    let family = NlbenchFamily::default();
    let sim = Nlbench::new(NlbenchParams::TRUE).unwrap().simulate(200, 5);
    let (x, y) = (&sim.states, &sim.outputs);
    let data = Series::new(y, 1).unwrap();
    // the step: independent exact draws (the noise variances are fixed)
    let mut step = NlbenchConjugate::from_priors(&family, &PRIORS).unwrap();
    let mut rng = stream(11, 0);
    let mut theta = vec![0.1, 1.0, 1.0, 0.1];
    let exact: Vec<Vec<f64>> = (0..20_000)
        .map(|_| {
            step.update(&family, &mut theta, x, &data, &mut rng)
                .unwrap();
            theta.clone()
        })
        .collect();
    // the reference: random-walk Metropolis with steps near the posterior's scale
    let scales = moments(&exact[..1000]);
    let mut current = exact[0].clone();
    let mut log_current = log_target(&family, &current, x, y);
    let mut rng = stream(12, 0);
    let mut chain = Vec::new();
    let iterations = 400_000;
    for i in 0..iterations {
        let proposal: Vec<f64> = current
            .iter()
            .zip(&scales)
            .map(|(v, (_, sd))| {
                let e: f64 = StandardNormal.sample(&mut rng);
                v + 1.2 * sd * e
            })
            .collect();
        let log_proposal = log_target(&family, &proposal, x, y);
        if rng.random::<f64>().ln() < log_proposal - log_current {
            (current, log_current) = (proposal, log_proposal);
        }
        if i >= 20_000 && i % 10 == 0 {
            chain.push(current.clone());
        }
    }
    let (ours, reference) = (moments(&exact), moments(&chain));
    for (k, name) in ["a", "b", "c", "d"].into_iter().enumerate() {
        let ((m1, s1), (m2, s2)) = (ours[k], reference[k]);
        // the MH chain's draws (every 10th) are correlated: allow an ESS of 1/10 of them
        let se = (s1 * s1 / exact.len() as f64 + 10.0 * s2 * s2 / chain.len() as f64).sqrt();
        assert!(
            (m1 - m2).abs() < 4.0 * se,
            "{name}: mean {m1} against {m2} (se {se})"
        );
        assert!((s1 / s2 - 1.0).abs() < 0.1, "{name}: sd {s1} against {s2}");
    }
}

#[test]
fn non_conjugate_priors_are_refused() {
    let family = NlbenchFamily {
        estimate_noise: true,
        ..NlbenchFamily::default()
    };
    let mut priors = PRIORS.to_vec();
    priors.extend([ScalarPrior::Normal { mean: 0.0, sd: 1.0 }; 2]);
    let err = NlbenchConjugate::from_priors(&family, &priors).unwrap_err();
    assert!(err.reason.contains("inverse_gamma"), "{err}");
    assert!(NlbenchConjugate::from_priors(&family, &PRIORS).is_err());
}
