//! Tier 1: the square-root filter/smoother against the dense joint Gaussian, on 120
//! seeded random stable systems with inputs, S != 0, offsets and missing data.

mod common;
use common::{DenseReference, random_system, rel_diff};
use nalgebra::DMatrix;
use sysid_kalman::{KalmanWorkspace, SufficientStatistics, conventional};

const SYSTEMS: u64 = 120;

#[test]
fn loglik_equals_dense_gaussian_density() {
    let mut ws = KalmanWorkspace::new();
    let mut worst = 0.0_f64;
    for seed in 0..SYSTEMS {
        let (model, rec) = random_system(seed);
        let dense = DenseReference::new(&model, &rec);
        let ll = ws.loglik(&model, &rec).unwrap();
        let rel = (ll - dense.loglik).abs() / dense.loglik.abs();
        worst = worst.max(rel);
        assert!(
            rel < 1e-9,
            "seed {seed}: loglik {ll} vs dense {}",
            dense.loglik
        );
    }
    eprintln!("worst relative loglik error: {worst:e}");
}

#[test]
fn smoother_moments_equal_dense_conditional_moments() {
    let mut ws = KalmanWorkspace::new();
    let mut worst = 0.0_f64;
    for seed in 0..SYSTEMS {
        let (model, rec) = random_system(seed);
        let dense = DenseReference::new(&model, &rec);
        let sm = ws.smooth(&model, &rec).unwrap();
        for k in 0..=rec.len() {
            let mean = sm.mean(k).clone_owned();
            let e_mean = rel_diff(
                &DMatrix::from_column_slice(mean.len(), 1, mean.as_slice()),
                &DMatrix::from_column_slice(mean.len(), 1, dense.x_mean(k).as_slice()),
            );
            let e_cov = rel_diff(&sm.covariance(k), &dense.x_cov(k, k));
            worst = worst.max(e_mean).max(e_cov);
            assert!(
                e_mean < 1e-8 && e_cov < 1e-8,
                "seed {seed} k {k}: mean {e_mean:e} cov {e_cov:e}"
            );
            if k < rec.len() {
                let e_lag = rel_diff(&sm.lag_one_covariance(k), &dense.x_cov(k + 1, k));
                worst = worst.max(e_lag);
                assert!(e_lag < 1e-8, "seed {seed} k {k}: lag-one {e_lag:e}");
            }
        }
    }
    eprintln!("worst smoother error: {worst:e}");
}

#[test]
fn statistics_equal_dense_second_moments() {
    let mut ws = KalmanWorkspace::new();
    for seed in 0..SYSTEMS {
        let (model, rec) = random_system(seed);
        let dense = DenseReference::new(&model, &rec);
        let mut stats = SufficientStatistics::new(model.n(), model.m(), model.p());
        ws.accumulate_statistics(&model, &rec, 0, &mut stats)
            .unwrap();
        let e = rel_diff(stats.second_moment(), &dense.second_moment(&rec));
        assert!(e < 1e-8, "seed {seed}: H differs by {e:e}");
        let x1 = dense.x_mean(0);
        let e1 = rel_diff(
            stats.initial_second_moment_sum(),
            &(dense.x_cov(0, 0) + &x1 * x1.transpose()),
        );
        assert!(e1 < 1e-8, "seed {seed}: initial moments differ by {e1:e}");
        assert_eq!(stats.steps(), rec.len());
    }
}

#[test]
fn square_root_and_conventional_forms_agree() {
    let mut ws = KalmanWorkspace::new();
    for seed in 0..SYSTEMS {
        let (model, rec) = random_system(seed);
        let conv = conventional::filter_smooth(&model, &rec).unwrap();
        let f = ws.filter(&model, &rec).unwrap();
        assert!(
            (f.loglik() - conv.loglik).abs() <= 1e-9 * conv.loglik.abs(),
            "seed {seed}"
        );
        for k in 0..rec.len() {
            assert!(
                rel_diff(&f.filtered_covariance(k), &conv.filtered_covariances[k]) < 1e-9,
                "seed {seed} k {k}"
            );
            let fm = f.filtered_mean(k).clone_owned();
            assert!(
                (fm - &conv.filtered_means[k]).amax()
                    < 1e-9 * conv.filtered_means[k].amax().max(1.0)
            );
            assert!(
                rel_diff(
                    &f.predicted_covariance(k + 1),
                    &conv.predicted_covariances[k + 1]
                ) < 1e-9
            );
        }
        let sm = ws.smooth(&model, &rec).unwrap();
        for k in 0..=rec.len() {
            assert!(
                rel_diff(&sm.covariance(k), &conv.smoothed_covariances[k]) < 1e-9,
                "seed {seed} k {k}"
            );
        }
    }
}

#[test]
fn records_add_up() {
    let (model, rec) = random_system(3);
    let (_, rec2) = random_system(3);
    let mut ws = KalmanWorkspace::new();
    let l1 = ws.loglik(&model, &rec).unwrap();
    let total = sysid_kalman::loglik_dataset(&model, &[rec.clone(), rec2.clone()]).unwrap();
    assert!((total - 2.0 * l1).abs() < 1e-9 * l1.abs());
    let (stats, ll) = sysid_kalman::statistics_dataset(&model, &[rec.clone(), rec2]).unwrap();
    assert!((ll - total).abs() < 1e-9 * total.abs());
    let mut single = SufficientStatistics::new(model.n(), model.m(), model.p());
    ws.accumulate_statistics(&model, &rec, 0, &mut single)
        .unwrap();
    let mut doubled = single.clone();
    doubled.merge(&single);
    assert!(rel_diff(stats.second_moment(), doubled.second_moment()) < 1e-12);
    assert_eq!(stats.records(), 2);
    assert_eq!(stats.steps(), 2 * rec.len());
}

/// `loglik` takes a closed-form path for n = p = 1; it must equal the array form
/// (`filter`), including S != 0, inputs, offsets and missing outputs, and agree with
/// the dense reference.
#[test]
fn scalar_fast_path_equals_array_form() {
    use nalgebra::dmatrix;
    use rand::rngs::Xoshiro256PlusPlus;
    use rand::{RngExt, SeedableRng};
    let mut ws = KalmanWorkspace::new();
    for seed in 0..200u64 {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1000 + seed);
        let q: f64 = rng.random_range(0.01..2.0);
        let r: f64 = if seed.is_multiple_of(10) {
            0.0
        } else {
            rng.random_range(0.01..2.0)
        };
        let s = if seed.is_multiple_of(2) {
            rng.random_range(-0.9..0.9) * (q * r).sqrt()
        } else {
            0.0
        };
        let model = sysid_kalman::LinearGaussianModel::builder(
            dmatrix![rng.random_range(-0.99..0.99)],
            dmatrix![rng.random_range(-2.0..2.0)],
            dmatrix![q],
            dmatrix![r],
        )
        .b(dmatrix![rng.random_range(-1.0..1.0), 0.5])
        .d(dmatrix![rng.random_range(-1.0..1.0), -0.3])
        .s(dmatrix![s])
        .h(nalgebra::dvector![rng.random_range(-1.0..1.0)])
        .mu(nalgebra::dvector![0.3])
        .p1(dmatrix![rng.random_range(0.1..3.0)])
        .build()
        .unwrap();
        let u = common::gaussian_matrix(&mut rng, 2, 40);
        let mut rec = model.simulate(&u, &mut rng).unwrap().record;
        for t in 0..40 {
            if rng.random_bool(0.2) {
                rec.y[(0, t)] = f64::NAN;
            }
        }
        let fast = ws.loglik(&model, &rec).unwrap();
        let array = ws.filter(&model, &rec).unwrap().loglik();
        assert!(
            (fast - array).abs() <= 1e-10 * array.abs(),
            "seed {seed}: {fast} vs {array}"
        );
        if r > 0.0 {
            let dense = DenseReference::new(&model, &rec).loglik;
            assert!(
                (fast - dense).abs() <= 1e-9 * dense.abs(),
                "seed {seed}: {fast} vs dense {dense}"
            );
        }
    }
}
