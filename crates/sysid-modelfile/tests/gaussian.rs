//! A model given in Rust by its maps (`GaussianModel`, one impl) has the same
//! densities as the same model from a model file, and its filter gives the Kalman
//! log-likelihood on a linear model.

use sysid_em::gradient::GradientModel;
use sysid_modelfile::{Gaussian, GaussianModel, builtin};
use sysid_pmcmc::{ModelFamily, Support};
use sysid_smc::{
    FilterOptions, InitialDensity, ObservationDensity, ParticleFilter, Series, TransitionBound,
    TransitionDensity,
};

/// lgss: x' = phi x + w (q), y = x + e (r), x_0 ~ N(0, 1); theta = (phi, q, r).
struct Lgss;
impl GaussianModel for Lgss {
    fn state_dim(&self) -> usize {
        1
    }
    fn output_dim(&self) -> usize {
        1
    }
    fn parameter_names(&self) -> Vec<String> {
        ["phi", "q", "r"].map(String::from).to_vec()
    }
    fn supports(&self) -> Vec<Support> {
        vec![Support::Real, Support::Positive, Support::Positive]
    }
    fn transition_mean(&self, th: &[f64], _t: usize, x: &[f64], _u: &[f64], out: &mut [f64]) {
        out[0] = th[0] * x[0];
    }
    fn observation_mean(&self, _th: &[f64], _t: usize, x: &[f64], _u: &[f64], out: &mut [f64]) {
        out[0] = x[0];
    }
    fn process_variances(&self, th: &[f64], out: &mut [f64]) {
        out[0] = th[1];
    }
    fn measurement_variances(&self, th: &[f64], out: &mut [f64]) {
        out[0] = th[2];
    }
    fn initial(&self, _th: &[f64], mean: &mut [f64], var: &mut [f64]) {
        mean[0] = 0.0;
        var[0] = 1.0;
    }
}

#[test]
fn a_rust_model_has_the_model_files_densities_and_the_kalman_likelihood() {
    let family = Gaussian::new(Lgss);
    let theta = [0.9, 1.0, 0.5];
    let ours = family.model(&theta).unwrap();
    let file = builtin::model("lgss").unwrap().unwrap();
    let theirs = file.at(&file.free_values()).unwrap();
    for x in [-2.0, 0.0, 1.3] {
        for z in [-1.0, 0.4] {
            assert!(
                (ours.log_transition(0, &[x], &[], &[z])
                    - theirs.log_transition(0, &[x], &[], &[z]))
                .abs()
                    < 1e-12
            );
            assert!(
                (ours.log_observation(0, &[x], &[], &[z])
                    - theirs.log_observation(0, &[x], &[], &[z]))
                .abs()
                    < 1e-12
            );
        }
        assert!((ours.log_initial(&[x]) - theirs.log_initial(&[x])).abs() < 1e-12);
    }
    assert_eq!(
        ours.log_transition_bound(0, &[]),
        theirs.log_transition_bound(0, &[])
    );

    // the gradient-EM form evaluates the same densities on the unconstrained scale
    let z = family.unconstrained(&theta);
    let p = family.unpack(&z);
    assert!((family.constrained(&z)[1] - 1.0).abs() < 1e-15);
    assert!(
        (GradientModel::log_transition(&family, &p, 0, &[1.0], &[], &[0.5])
            - ours.log_transition(0, &[1.0], &[], &[0.5]))
        .abs()
            < 1e-12
    );

    // the filter on simulated data: the Kalman log-likelihood within Monte Carlo error
    let (_, y) = ours.simulate(300, &[], 5).unwrap();
    let kalman = sysid_kalman::loglik_dataset(
        &sysid_models::lgss(),
        &[sysid_kalman::Record::outputs_only(
            nalgebra::DMatrix::from_row_slice(1, y.len(), &y),
        )],
    )
    .unwrap();
    let series = Series::new(&y, 1).unwrap();
    let mut pf = ParticleFilter::new(FilterOptions {
        particles: 10_000,
        ..Default::default()
    })
    .unwrap();
    let runs: Vec<f64> = (0..20)
        .map(|s| pf.run(&ours, &series, s).unwrap().loglik)
        .collect();
    let mean = runs.iter().sum::<f64>() / 20.0;
    let var = runs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / 19.0;
    assert!(
        (mean - kalman).abs() < 4.0 * (var / 20.0).sqrt() + var / 2.0 + 1e-3,
        "{mean} vs {kalman} (sd {})",
        var.sqrt()
    );

    // outside its support, the family refuses with the parameter's name
    assert!(
        family
            .model(&[0.9, -1.0, 0.5])
            .unwrap_err()
            .reason
            .contains("q = -1")
    );
}
