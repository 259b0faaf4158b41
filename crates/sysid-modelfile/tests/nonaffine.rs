//! A two-state model that is not affine in its parameters, from a model file:
//! gradient EM recovers its parameters, and PMMH's posterior covers the truth.

use sysid_em::gradient::{GradientEm, MStepOptions};
use sysid_em::{EmOptions, run_em};
use sysid_modelfile::ModelFile;
use sysid_pmcmc::{ChainRun, IndependentPrior, PmmhOptions, pmmh, summarise};
use sysid_smc::{FfbsiReject, Series};

/// A damped pendulum parametrised by its natural frequency `w0` and damping ratio
/// `zeta` (products and a square of parameters: not affine), driven by a torque.
pub const PENDULUM: &str = r#"
format = 1
name = "pendulum-w0-zeta"
states = ["theta", "omega"]
inputs = ["u"]
outputs = ["y"]

[parameters]
w0 = { value = 3.0, min = 0, prior = { family = "log_normal", mu = 1.0, sigma = 1.0 } }
zeta = { value = 0.2, min = 0, max = 2, prior = { family = "uniform", low = 0.0, high = 2.0 } }
k = { value = 4.0, prior = { family = "normal", mean = 0.0, sd = 10.0 } }
r = { value = 0.01, min = 0, prior = { family = "inverse_gamma", shape = 1.0, scale = 0.01 } }
dt = 0.05

[transition]
theta = "theta + dt*omega"
omega = "omega + dt*(-2*zeta*w0*omega - w0^2*sin(theta) + k*u)"

[observation]
y = "theta"

[noise]
theta = 1e-4
omega = 1e-2
y = "r"

[initial]
theta = { mean = 0, variance = 0.01 }
omega = { mean = 0, variance = 0.01 }
"#;

/// Piecewise-constant N(0, 1) torque levels held for 10 samples.
fn torque(steps: usize) -> Vec<f64> {
    use rand::Rng;
    use rand_distr::{Distribution, StandardNormal};
    let mut rng = sysid_smc::stream(77, 0);
    let mut level = 0.0;
    (0..steps)
        .map(|t| {
            if t % 10 == 0 {
                level = StandardNormal.sample(&mut rng);
                let _ = rng.next_u64();
            }
            level
        })
        .collect()
}

#[test]
fn gradient_em_and_pmmh_recover_a_non_affine_model() {
    let steps = 500;
    let file = ModelFile::parse(PENDULUM, "pendulum.toml").unwrap();
    assert!(file.affine().is_none(), "products of parameters");
    assert!(file.why_not_affine().unwrap().contains("nonlinearly"));
    let truth = [9.81f64.sqrt(), 0.16, 4.0, 0.01];
    let u = torque(steps);
    let (_, y) = file.at(&truth).unwrap().simulate(steps, &u, 3).unwrap();
    let series = Series::new(&y, 1).unwrap().with_inputs(&u, 1).unwrap();

    // gradient EM from 30 % off
    let gradient = file.gradient();
    let start = [
        truth[0] * 1.3,
        truth[1] * 1.3,
        truth[2] * 0.7,
        truth[3] * 2.0,
    ];
    let smoother = FfbsiReject {
        paths: 100,
        max_trials: None,
        parallel: false,
    };
    let mut em =
        GradientEm::new(&gradient, series, 300, smoother, MStepOptions::default(), 5).unwrap();
    let options = EmOptions {
        max_iterations: 40,
        tol: 0.0,
        ..EmOptions::default()
    }
    .check()
    .unwrap();
    let began = std::time::Instant::now();
    let run = run_em(&mut em, gradient.unconstrained(&start), &options, &mut ());
    assert!(
        !matches!(run.termination, sysid_em::Termination::Error { .. }),
        "{:?}",
        run.termination
    );
    let estimate = sysid_em::gradient::GradientModel::constrained(&gradient, &run.estimate);
    eprintln!("gradient EM {:.1} s", began.elapsed().as_secs_f64());
    let began = std::time::Instant::now();

    // PMMH from the EM estimate: the posterior sd is the standard error
    let names = file.free_names();
    let prior = IndependentPrior::new(
        &names,
        file.priors().into_iter().map(Option::unwrap).collect(),
    )
    .unwrap();
    let options = PmmhOptions {
        iterations: 6000,
        burn_in: 1500,
        particles: 200,
        proposal_sd: vec![0.02, 0.1, 0.02, 0.1],
        ..PmmhOptions::default()
    };
    let chains = pmmh(
        &file,
        &prior,
        &series,
        &estimate,
        &options,
        &ChainRun::new(2, 9),
    )
    .unwrap();
    let summary = summarise(&chains);
    eprintln!("PMMH {:.1} s", began.elapsed().as_secs_f64());
    let mut report = Vec::new();
    for (k, s) in summary.iter().enumerate() {
        report.push(format!(
            "{}: truth {} EM {} posterior {} +- {} (5-95 % {}..{}), R-hat {}",
            s.name, truth[k], estimate[k], s.mean, s.sd, s.q05, s.q95, s.rhat
        ));
    }
    let report = report.join("\n");
    eprintln!("{report}");
    for (k, s) in summary.iter().enumerate() {
        assert!(
            (estimate[k] - truth[k]).abs() < 3.0 * s.sd,
            "EM off by > 3 se\n{report}"
        );
        // a 99.9 % interval from the mean and sd (the 5-95 % band misses 10 % by design)
        assert!(
            (s.mean - truth[k]).abs() < 3.3 * s.sd,
            "posterior misses the truth\n{report}"
        );
        assert!(s.rhat < 1.1, "the chains have not mixed\n{report}");
    }
}

/// The analytic gradients of the three log-densities (symbolic derivatives and the
/// transforms' jacobians) equal central differences of the densities.
#[test]
fn analytic_gradients_match_central_differences() {
    use sysid_em::gradient::{GradientModel, central_difference};
    let file = ModelFile::parse(PENDULUM, "pendulum.toml").unwrap();
    let g = file.gradient();
    let theta = g.unconstrained(&[3.1, 0.3, 3.5, 0.02]);
    let (x, next, u, y) = ([0.4, -1.2], [0.35, -1.0], [0.7], [0.5]);
    type Density<'a> = Box<dyn Fn(&[f64], &mut [f64]) -> f64 + 'a>;
    let cases: Vec<(&str, Density)> = vec![
        (
            "initial",
            Box::new(|th: &[f64], grad: &mut [f64]| {
                g.log_initial_gradient(&g.unpack(th), &x, grad)
            }),
        ),
        (
            "transition",
            Box::new(|th: &[f64], grad: &mut [f64]| {
                g.log_transition_gradient(&g.unpack(th), 3, &x, &u, &next, grad)
            }),
        ),
        (
            "observation",
            Box::new(|th: &[f64], grad: &mut [f64]| {
                g.log_observation_gradient(&g.unpack(th), 3, &x, &u, &y, grad)
            }),
        ),
    ];
    for (name, density) in &cases {
        let mut analytic = vec![0.0; 4];
        let value = density(&theta, &mut analytic);
        let mut numeric = vec![0.0; 4];
        let plain = central_difference(&theta, &mut numeric, |th| density(th, &mut [0.0; 4]));
        assert!((value - plain).abs() < 1e-12, "{name}");
        for (a, n) in analytic.iter().zip(&numeric) {
            assert!(
                (a - n).abs() <= 1e-6 * (1.0 + n.abs()),
                "{name}: {analytic:?} vs {numeric:?}"
            );
        }
    }
}
