//! The robust particle-EM driver's polish (its estimate's particle log-likelihood
//! maximised directly) against the exact answer on a linear Gaussian model: the
//! maximum of the Kalman log-likelihood, found by a cyclic golden-section search that
//! shares no code with the driver's Nelder–Mead or its particle filter.

use nalgebra::{DMatrix, DVector, dmatrix};
use sysid_em::affine::{AffineEmSpec, RobustOptions, fit_robust};
use sysid_em::linear::Covariance;
use sysid_kalman::{KalmanWorkspace, LinearGaussianModel, Record};
use sysid_models::LinearAffine;
use sysid_smc::{Series, Tanizaki, stream};

/// `x' = a x + w`, `y = x + e`, `w ~ N(0, q)`, `e ~ N(0, r)`, `x_1 ~ N(0, 1)`.
fn model(a: f64, q: f64, r: f64) -> LinearGaussianModel {
    LinearGaussianModel::builder(dmatrix![a], dmatrix![1.0], dmatrix![q], dmatrix![r])
        .mu(DVector::zeros(1))
        .p1(dmatrix![1.0])
        .build()
        .unwrap()
}

fn exact_loglik(record: &Record, a: f64, q: f64, r: f64) -> f64 {
    KalmanWorkspace::new()
        .loglik(&model(a, q, r), record)
        .unwrap()
}

/// The exact maximum over `(a, ln q, ln r)`: golden-section searches on each
/// coordinate in turn until a sweep changes nothing.
fn exact_maximum(record: &Record) -> ([f64; 3], f64) {
    let f = |v: &[f64; 3]| exact_loglik(record, v[0], v[1].exp(), v[2].exp());
    let mut v = [0.5, 0.0, 0.0];
    let ranges = [(-0.99, 0.99), (-8.0, 4.0), (-8.0, 4.0)];
    for _ in 0..60 {
        let before = v;
        for (k, &(lo, hi)) in ranges.iter().enumerate() {
            let (mut lo, mut hi) = (lo, hi);
            let g = (5f64.sqrt() - 1.0) / 2.0;
            while hi - lo > 1e-9 {
                let (x1, x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
                let (mut v1, mut v2) = (v, v);
                (v1[k], v2[k]) = (x1, x2);
                if f(&v1) > f(&v2) {
                    hi = x2;
                } else {
                    lo = x1;
                }
            }
            v[k] = (lo + hi) / 2.0;
        }
        if before.iter().zip(&v).all(|(x, y)| (x - y).abs() < 1e-8) {
            break;
        }
    }
    let best = f(&v);
    ([v[0], v[1].exp(), v[2].exp()], best)
}

/// From a start with its measurement variance 4 times too large and few particles in
/// EM, the polished estimate is the exact maximum within Monte Carlo error, its
/// reported log-likelihood is the exact one at the estimate within a few Monte Carlo
/// sd, and the polish never ends below the EM estimate.
#[test]
fn the_polish_lands_on_the_exact_maximum_of_a_linear_model() {
    let truth = model(0.8, 0.3, 0.5);
    let mut rng = stream(11, 0);
    let simulation = truth.simulate(&DMatrix::zeros(0, 300), &mut rng).unwrap();
    let record = simulation.record;
    let ([a_hat, q_hat, r_hat], max_loglik) = exact_maximum(&record);
    let (affine, mut start) = LinearAffine::new(&model(0.6, 0.3, 2.0)).unwrap();
    start.pi_y = dmatrix![2.0];
    let y: Vec<f64> = record.y.iter().copied().collect();
    let data = Series::new(&y, 1).unwrap();
    let spec = AffineEmSpec {
        beta_y: false, // C = 1 fixes the state's scale
        pi_x: Covariance::Diagonal,
        pi_y: Covariance::Diagonal,
        ..AffineEmSpec::default()
    };
    let options = RobustOptions {
        starts: 2,
        explore_iterations: 10,
        explore_particles: 20,
        refine_iterations: 20,
        refine_particles: 20,
        select_particles: 500,
        polish_particles: 3000,
        polish_evaluations: 300,
        ..RobustOptions::default()
    };
    let fit = fit_robust(
        &affine,
        data,
        &start,
        &spec,
        &Tanizaki::default(),
        &options,
        3,
    )
    .unwrap();
    let polish = fit.polish.clone().expect("the polish ran");
    let (a, q, r) = (
        fit.estimate.beta_x[(0, 0)],
        fit.estimate.pi_x[(0, 0)],
        fit.estimate.pi_y[(0, 0)],
    );
    let at_estimate = exact_loglik(&record, a, q, r);
    // the estimate's exact log-likelihood is within 0.2 nats of the maximum (the EM
    // estimate before the polish is 0.4 below it; a point
    // moved by one Monte Carlo sd of the particle log-likelihood loses about that)
    assert!(
        max_loglik - at_estimate < 0.2,
        "exact max {max_loglik:.3} at ({a_hat:.4}, {q_hat:.4}, {r_hat:.4}); estimate \
         ({a:.4}, {q:.4}, {r:.4}) scores {at_estimate:.3}; {polish:?}"
    );
    assert!(
        (a - a_hat).abs() < 0.05 && (q / q_hat).ln().abs() < 0.3 && (r / r_hat).ln().abs() < 0.3
    );
    // what it reports is the likelihood there, by independent filters: within 4 sd of
    // the mean of 4 runs of the exact value
    assert!(
        (fit.loglik - at_estimate).abs() < 4.0 * polish.loglik_sd / 2.0 + 0.05,
        "reported {:.3}, exact {at_estimate:.3}, sd {:.3}",
        fit.loglik,
        polish.loglik_sd
    );
    assert_eq!(fit.loglik_particles, 3000);
    assert!(polish.loglik >= polish.start_loglik - 3.0 * polish.loglik_sd);
    assert!(polish.converged, "{polish:?}");
    // (the tiny exploration warns about itself; the polish has nothing to say)
    assert!(
        !fit.warnings
            .iter()
            .any(|w| w.contains("polish") || w.contains("maximisation")),
        "{:?}",
        fit.warnings
    );
    eprintln!(
        "exact max {max_loglik:.3}, at the estimate {at_estimate:.3}, reported {:.3} (sd {:.3}), \
         EM estimate {:.3}",
        fit.loglik, polish.loglik_sd, polish.start_loglik
    );
}

/// A tiny robust fit of 100 steps of the truth (seed `data_seed`) from the truth,
/// `C` held.
fn tiny_fit(data_seed: u64, options: &RobustOptions) -> sysid_em::affine::RobustFit {
    let truth = model(0.8, 0.3, 0.5);
    let simulation = truth
        .simulate(&DMatrix::zeros(0, 100), &mut stream(data_seed, 0))
        .unwrap();
    let y: Vec<f64> = simulation.record.y.iter().copied().collect();
    let (affine, start) = LinearAffine::new(&truth).unwrap();
    let spec = AffineEmSpec {
        beta_y: false,
        ..AffineEmSpec::default()
    };
    let data = Series::new(&y, 1).unwrap();
    fit_robust(
        &affine,
        data,
        &start,
        &spec,
        &Tanizaki::default(),
        options,
        1,
    )
    .unwrap()
}

/// Without the polish the driver reports the selection filter's score and no polish.
#[test]
fn no_polish_when_switched_off() {
    let options = RobustOptions {
        starts: 2,
        explore_iterations: 4,
        explore_particles: 10,
        refine_iterations: 4,
        refine_particles: 10,
        select_particles: 200,
        polish_particles: 0,
        ..RobustOptions::default()
    };
    let fit = tiny_fit(12, &options);
    assert!(fit.polish.is_none());
    assert_eq!(fit.loglik_particles, 200);
}

/// A budget smaller than Nelder–Mead's first simplex ends the polish with the best
/// point evaluated (argmin unwraps the first simplex's costs: the budget must never be
/// an error there).
#[test]
fn a_polish_budget_smaller_than_the_simplex_is_not_a_panic() {
    let options = RobustOptions {
        starts: 1,
        explore_iterations: 2,
        explore_particles: 10,
        refine_iterations: 2,
        refine_particles: 10,
        select_particles: 100,
        polish_particles: 200,
        polish_evaluations: 1,
        ..RobustOptions::default()
    };
    let fit = tiny_fit(13, &options);
    let polish = fit.polish.expect("the polish ran");
    assert!(!polish.converged && !polish.interrupted, "{polish:?}");
    assert!(fit.loglik.is_finite());
}
