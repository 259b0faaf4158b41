//! Long records in bounded memory: the block filter and the checkpointed smoother
//! against the whole-record passes (themselves tested against the dense Gaussian
//! answer), with inputs, missing outputs, correlated noise and diffuse initial states.

mod common;
use common::{gaussian_matrix, random_system, rel_diff};
use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use sysid_kalman::{BlockFilter, KalmanError, KalmanWorkspace, LinearGaussianModel, Record};

/// Columns `start..start+len` of a record.
fn part(rec: &Record, start: usize, len: usize) -> Record {
    Record::new(
        rec.u.columns(start, len).clone_owned(),
        rec.y.columns(start, len).clone_owned(),
    )
}

/// `random_system`'s model over a longer record (T steps, 10 % of outputs missing).
fn long_system(seed: u64, t_len: usize) -> (LinearGaussianModel, Record) {
    let (model, _) = random_system(seed);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed + 500);
    let u = gaussian_matrix(&mut rng, model.m(), t_len);
    let mut sim = model.simulate(&u, &mut rng).unwrap();
    for (k, v) in sim.record.y.iter_mut().enumerate() {
        if (k * 7 + seed as usize).is_multiple_of(10) {
            *v = f64::NAN;
        }
    }
    (model, sim.record)
}

#[test]
fn smoothing_by_blocks_equals_the_whole_record_smoother() {
    for seed in 0..40 {
        let (model, rec) = long_system(seed, 57);
        let mut ws = KalmanWorkspace::new();
        let whole = ws.smooth(&model, &rec).unwrap().clone();
        for block in [1, 4, 13, 57, 100] {
            let (n, t_len) = (model.n(), rec.len());
            let mut seen = vec![false; t_len];
            let loglik = KalmanWorkspace::new()
                .smooth_in_blocks_of(&model, &rec, block, |k, mean, cov| {
                    assert!(!seen[k], "step {k} twice");
                    seen[k] = true;
                    let mean = DMatrix::from_column_slice(n, 1, mean);
                    let cov = DMatrix::from_column_slice(n, n, cov);
                    let ctx = format!("seed {seed}, block {block}, step {k}");
                    assert!(
                        rel_diff(
                            &mean,
                            &DMatrix::from_column_slice(n, 1, whole.mean(k).as_slice())
                        ) < 1e-9,
                        "{ctx}"
                    );
                    assert!(rel_diff(&cov, &whole.covariance(k)) < 1e-9, "{ctx}");
                    assert_eq!(cov, cov.transpose(), "{ctx}");
                })
                .unwrap();
            assert!(seen.iter().all(|&s| s), "seed {seed}, block {block}");
            let tol = 1e-9 * whole.loglik().abs().max(1.0);
            assert!(
                (loglik - whole.loglik()).abs() < tol,
                "seed {seed}, block {block}"
            );
        }
    }
}

/// Filtered moments of each block equal the whole record's, also for a diffuse initial
/// state that the first block determines.
#[test]
fn filtering_by_blocks_equals_the_whole_record_filter() {
    for seed in 0..40 {
        let (model, rec) = long_system(seed, 90);
        let model = if !seed.is_multiple_of(2) {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed + 9);
            let q = 1 + seed as usize % model.n();
            let directions = gaussian_matrix(&mut rng, model.n(), q);
            model.to_builder().diffuse(directions).build().unwrap()
        } else {
            model
        };
        let whole = KalmanWorkspace::new().filter(&model, &rec).unwrap().clone();
        for block in [30, 41] {
            let mut filter = BlockFilter::new(&model);
            let mut start = 0;
            while start < rec.len() {
                let len = block.min(rec.len() - start);
                let out = filter.push(&part(&rec, start, len)).unwrap();
                for k in 0..len {
                    let ctx = format!("seed {seed}, block {block}, step {}", start + k);
                    let col = |v: nalgebra::DVector<f64>| {
                        DMatrix::from_column_slice(v.len(), 1, v.as_slice())
                    };
                    let (a, b) = (
                        col(out.filtered_mean(k)),
                        col(whole.filtered_mean(start + k)),
                    );
                    let undetermined = whole.filtered_undetermined(start + k);
                    assert_eq!(out.filtered_undetermined(k), undetermined, "{ctx}");
                    if undetermined.iter().any(|&u| u) {
                        continue;
                    }
                    assert!(rel_diff(&a, &b) < 1e-8, "{ctx}");
                    let (p, q) = (
                        out.filtered_covariance(k),
                        whole.filtered_covariance(start + k),
                    );
                    assert!(rel_diff(&p, &q) < 1e-8, "{ctx}");
                }
                start += len;
            }
            assert_eq!(filter.steps(), rec.len());
            let tol = 1e-9 * whole.loglik().abs().max(1.0);
            assert!(
                (filter.loglik() - whole.loglik()).abs() < tol,
                "seed {seed}, block {block}: {} vs {}",
                filter.loglik(),
                whole.loglik()
            );
        }
    }
}

#[test]
fn errors_name_the_time_in_the_whole_record() {
    let (model, mut rec) = long_system(2, 100);
    rec.y[(0, 72)] = f64::INFINITY;
    let mut filter = BlockFilter::new(&model);
    filter.push(&part(&rec, 0, 50)).unwrap();
    let err = filter.push(&part(&rec, 50, 50)).unwrap_err();
    assert!(
        matches!(err, KalmanError::NonFiniteData { time: 73, .. }),
        "{err}"
    );
    let err = KalmanWorkspace::new()
        .smooth_in_blocks_of(&model, &rec, 30, |_, _, _| {})
        .unwrap_err();
    assert!(
        matches!(err, KalmanError::NonFiniteData { time: 73, .. }),
        "{err}"
    );
    let diffuse = model
        .to_builder()
        .diffuse(DMatrix::identity(model.n(), 1))
        .build()
        .unwrap();
    let err = KalmanWorkspace::new()
        .smooth_in_blocks(&diffuse, &rec, |_, _, _| {})
        .unwrap_err();
    assert_eq!(err, KalmanError::DiffuseInBlocks);
}
