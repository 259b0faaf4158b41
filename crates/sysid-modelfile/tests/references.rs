//! Model files against independent references: the built-in nlbench's densities and
//! regressors, the Kalman filter's log-likelihood, and exact EM's estimate.

use nalgebra::{DMatrix, dmatrix};
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use sysid_em::EmOptions;
use sysid_em::affine::{AffineEm, AffineModel};
use sysid_em::linear::{LinearEmSpec, fit};
use sysid_kalman::{LinearGaussianModel, loglik_dataset};
use sysid_modelfile::builtin;
use sysid_models::{Nlbench, NlbenchAffine};
use sysid_smc::{
    FfbsiReject, FilterOptions, InitialDensity, ObservationDensity, ParticleFilter, Series,
    TransitionBound, TransitionDensity, TransitionSampler, stream,
};

fn nlbench_file() -> sysid_modelfile::ModelFile {
    builtin::model("nlbench").unwrap().unwrap()
}

#[test]
fn nlbench_as_a_file_has_the_builtin_densities_and_regressors() {
    let file = nlbench_file();
    let ours = file.at(&file.free_values()).unwrap();
    let theirs = Nlbench::truth();
    let xs = [-25.0, -3.2, -0.4, 0.0, 0.7, 1.9, 12.5];
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + b.abs());
    for t in [0, 1, 7, 999] {
        for &x in &xs {
            for &y in &[-1.0, 0.3, 8.0] {
                let (a, b) = (
                    ours.log_observation(t, &[x], &[], &[y]),
                    theirs.log_observation(t, &[x], &[], &[y]),
                );
                assert!(close(a, b), "g t {t} x {x}: {a} vs {b}");
            }
            for &next in &xs {
                let (a, b) = (
                    ours.log_transition(t, &[x], &[], &[next]),
                    theirs.log_transition(t, &[x], &[], &[next]),
                );
                assert!(close(a, b), "f t {t} x {x}: {a} vs {b}");
            }
        }
        // the many-particle paths: the same draws from the same stream
        let parents: Vec<usize> = (0..xs.len()).rev().collect();
        let (mut a, mut b) = (vec![0.0; xs.len()], vec![0.0; xs.len()]);
        ours.sample_transitions(t, &[], &xs, &parents, &mut a, &mut stream(3, t as u64));
        theirs.sample_transitions(t, &[], &xs, &parents, &mut b, &mut stream(3, t as u64));
        for (a, b) in a.iter().zip(&b) {
            assert!(close(*a, *b), "sampled {a} vs {b}");
        }
        let (mut ga, mut gb) = (vec![0.0; xs.len()], vec![0.0; xs.len()]);
        ours.log_observations(t, &[], &[0.3], &xs, &mut ga);
        theirs.log_observations(t, &[], &[0.3], &xs, &mut gb);
        assert!(ga.iter().zip(&gb).all(|(a, b)| close(*a, *b)));
        assert!(close(
            ours.log_transition_bound(t, &[]),
            theirs.log_transition_bound(t, &[])
        ));
    }
    assert!(close(ours.log_initial(&[0.4]), theirs.log_initial(&[0.4])));

    // the affine form: the benchmark's regressors [x, x/(1+x^2), cos(1.2(t+1)), x^2]
    let affine = file.affine().expect("nlbench is affine in a, b, c, d");
    assert_eq!(
        affine.regressor_texts(),
        ["x", "x/(1 + x^2)", "cos(1.2*(t + 1))", "x^2"]
    );
    for t in [0, 5, 400] {
        let (mut a, mut b) = (vec![0.0; 4 * xs.len()], vec![0.0; 4 * xs.len()]);
        affine.regressor_columns(t, &xs, &[], &mut a);
        NlbenchAffine.regressor_columns(t, &xs, &[], &mut b);
        assert!(a.iter().zip(&b).all(|(a, b)| close(*a, *b)), "t {t}");
    }
    assert_eq!(affine.state_structure(), NlbenchAffine.state_structure());
    assert_eq!(affine.output_structure(), NlbenchAffine.output_structure());
    let params = affine.params(&file.free_values()).unwrap();
    assert_eq!(
        params,
        NlbenchAffine::params(&sysid_models::NlbenchParams::TRUE)
    );
}

fn lgss_data(steps: usize, seed: u64) -> (LinearGaussianModel, Vec<f64>) {
    let truth = sysid_models::lgss();
    let sim = truth
        .simulate(
            &DMatrix::zeros(0, steps),
            &mut Xoshiro256PlusPlus::seed_from_u64(seed),
        )
        .unwrap();
    (truth, sim.record.y.iter().copied().collect())
}

/// The bootstrap filter on the lgss model file at M = 10 000 gives the Kalman
/// log-likelihood within Monte Carlo error: 20 independent runs, their mean within 4
/// standard errors (plus the estimator's known downward bias, var / 2).
#[test]
fn a_linear_model_file_gives_the_kalman_loglik_through_the_particle_filter() {
    let (truth, y) = lgss_data(300, 5);
    let exact = loglik_dataset(
        &truth,
        &[sysid_kalman::Record::outputs_only(DMatrix::from_row_slice(
            1,
            y.len(),
            &y,
        ))],
    )
    .unwrap();
    let file = builtin::model("lgss").unwrap().unwrap();
    let model = file.at(&file.free_values()).unwrap();
    let series = Series::new(&y, 1).unwrap();
    let mut pf = ParticleFilter::new(FilterOptions {
        particles: 10_000,
        ..Default::default()
    })
    .unwrap();
    let count = 20;
    let runs: Vec<f64> = (0..count)
        .map(|seed| pf.run(&model, &series, seed).unwrap().loglik)
        .collect();
    let mean = runs.iter().sum::<f64>() / count as f64;
    let var = runs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / (count - 1) as f64;
    let se = (var / count as f64).sqrt();
    eprintln!("pf {mean} (sd {}, se {se}) vs Kalman {exact}", var.sqrt());
    assert!(
        (mean - exact).abs() < 4.0 * se + var / 2.0 + 1e-3,
        "pf {mean} (sd {}) vs Kalman {exact}",
        var.sqrt()
    );
    // the linear SMC adapter's filter on these data: sd about 0.5 nats
    assert!(var.sqrt() < 1.0, "sd {}", var.sqrt());
}

/// Particle EM on the lgss model file (affine in phi; q and r free; c fixed at 1),
/// started away from the answer, reaches exact EM's estimate up to the particle
/// E-step's O(1/M) bias: within 10 % at M = 500, within 3 % at M = 2000.
#[test]
fn particle_em_on_a_linear_model_file_reaches_exact_em() {
    let (truth, y) = lgss_data(500, 11);
    let record = sysid_kalman::Record::outputs_only(DMatrix::from_row_slice(1, y.len(), &y));
    let start = truth
        .to_builder()
        .a(dmatrix![0.5])
        .q(dmatrix![0.5])
        .r(dmatrix![1.0])
        .build()
        .unwrap();
    let spec = LinearEmSpec {
        c: false,
        d: false,
        h: false,
        mu: false,
        p1: false,
        ..LinearEmSpec::default()
    };
    let options = EmOptions {
        max_iterations: 20_000,
        tol: 1e-12,
        ..EmOptions::default()
    }
    .check()
    .unwrap();
    let exact = fit(start, &[record], spec, &options, &mut ()).estimate;
    let exact = [exact.a()[(0, 0)], exact.q()[(0, 0)], exact.r()[(0, 0)]];

    let file = builtin::model("lgss").unwrap().unwrap();
    let affine = file.affine().expect("lgss is affine in phi");
    let series = Series::new(&y, 1).unwrap();
    struct Trace<'a>(&'a sysid_modelfile::ExprAffine, Vec<Vec<f64>>);
    impl sysid_em::EmObserver<sysid_em::affine::AffineParams> for Trace<'_> {
        fn iteration(
            &mut self,
            info: &sysid_em::IterationInfo<'_, sysid_em::affine::AffineParams>,
        ) {
            self.1.push(self.0.theta(info.estimate));
        }
    }
    // the mean of the last 30 of 80 iterates, with M particles and M smoothed paths
    let particle_em = |particles: usize| -> Vec<f64> {
        let smoother = FfbsiReject {
            paths: particles,
            max_trials: None,
            parallel: false,
        };
        let mut em =
            AffineEm::new(&affine, series, particles, smoother, affine.em_spec(), 4).unwrap();
        let mut observer = Trace(&affine, Vec::new());
        let start = affine.params(&[0.5, 0.5, 1.0]).unwrap();
        let options = EmOptions {
            max_iterations: 80,
            tol: 0.0,
            ..EmOptions::default()
        }
        .check()
        .unwrap();
        let run = sysid_em::run_em(&mut em, start, &options, &mut observer);
        assert!(!matches!(
            run.termination,
            sysid_em::Termination::Error { .. }
        ));
        let tail = &observer.1[observer.1.len() - 30..];
        (0..3)
            .map(|k| tail.iter().map(|t| t[k]).sum::<f64>() / 30.0)
            .collect()
    };
    // The particle E-step's bias shrinks as 1/M: measured phi +0.5 %, q -4.6 %,
    // r +6.6 % at M = 500 (300 iterations give the same means: a bias, not slow
    // convergence) and +0.2 %, -1.5 %, +1.8 % at M = 2000 (-0.8 %, +1.0 % after 120
    // iterations), along the q-r ridge where the likelihood is flat.
    let (m500, m2000) = (particle_em(500), particle_em(2000));
    for (k, name) in ["phi", "q", "r"].iter().enumerate() {
        let (e500, e2000) = (
            (m500[k] / exact[k] - 1.0).abs(),
            (m2000[k] / exact[k] - 1.0).abs(),
        );
        eprintln!(
            "{name}: exact EM {} particle EM M=500 {} M=2000 {}",
            exact[k], m500[k], m2000[k]
        );
        assert!(e500 < 0.1, "{name}: M = 500 off by {e500}");
        assert!(e2000 < 0.03, "{name}: M = 2000 off by {e2000}");
        assert!(
            e2000 <= e500 + 0.002,
            "{name}: no closer with more particles"
        );
    }
}
