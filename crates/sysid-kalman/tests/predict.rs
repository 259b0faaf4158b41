//! k-step predictions and the least-squares response against independent answers:
//! the one-step prediction of a record whose last k - 1 outputs are hidden, and a
//! dense least-squares solve for the initial state.

mod common;
use common::{random_system, rel_diff};
use nalgebra::{DMatrix, DVector};
use sysid_kalman::fit_percent;

#[test]
fn k_step_predictions_are_one_step_predictions_with_the_gap_hidden() {
    for seed in 0..40 {
        let (model, rec) = random_system(seed);
        for k in [2, 3, 5] {
            let pred = model.predict(&rec, k).unwrap();
            for t in 0..rec.len() {
                // hide the k - 1 outputs before y_t: the one-step prediction of y_t
                // then uses the outputs up to t - k only
                let mut hidden = rec.clone();
                for j in (t + 1).saturating_sub(k)..t {
                    hidden.y.column_mut(j).fill(f64::NAN);
                }
                let one = model.predict(&hidden, 1).unwrap();
                let got = pred.mean.column(t).clone_owned();
                let want = one.mean.column(t).clone_owned();
                let scale = want.amax().max(1.0);
                assert!(
                    (got - &want).amax() < 1e-9 * scale,
                    "seed {seed} k {k} t {t}: mean"
                );
                let e = rel_diff(&pred.covariances[t], &one.covariances[t]);
                assert!(e < 1e-9, "seed {seed} k {k} t {t}: covariance {e:e}");
            }
        }
    }
}

#[test]
fn the_least_squares_initial_state_solves_the_dense_problem() {
    for seed in 0..40 {
        let (model, rec) = random_system(seed);
        let (n, p, t_len) = (model.n(), model.p(), rec.len());
        let response = model.response(&rec, None).unwrap();
        // dense: stack C A^t over the observed outputs, solve by SVD
        let free = model
            .response(&rec, Some(&DVector::zeros(n)))
            .unwrap()
            .outputs;
        let mut rows = Vec::new();
        let mut rhs = Vec::new();
        let mut power = model.c().clone();
        for t in 0..t_len {
            for i in 0..p {
                if !rec.y[(i, t)].is_nan() {
                    rows.push(power.row(i).clone_owned());
                    rhs.push(rec.y[(i, t)] - free[(i, t)]);
                }
            }
            power = &power * model.a();
        }
        let a = DMatrix::from_rows(&rows);
        let x0 = a
            .clone()
            .svd(true, true)
            .solve(&DVector::from_vec(rhs), 1e-12)
            .unwrap();
        let fitted = model.response(&rec, Some(&x0)).unwrap().outputs;
        // the same residual (the minimiser is unique up to unobservable directions)
        let fit_ours = fit_percent(&rec.y, &response.outputs, 0);
        let fit_dense = fit_percent(&rec.y, &fitted, 0);
        for (a, b) in fit_ours.iter().zip(&fit_dense) {
            assert!(
                (a - b).abs() < 1e-8 * b.abs().max(1.0),
                "seed {seed}: fit {a} vs {b}"
            );
        }
        assert!(
            (&response.initial_state - &x0).amax() < 1e-7 * x0.amax().max(1.0),
            "seed {seed}: x0 {} vs {}",
            response.initial_state,
            x0
        );
    }
}

#[test]
fn fit_percent_is_the_nrmse_fit() {
    let y = DMatrix::from_row_slice(2, 4, &[1.0, 2.0, 3.0, 4.0, 5.0, 5.0, 5.0, 5.0]);
    let perfect = fit_percent(&y, &y, 0);
    assert_eq!(perfect, vec![100.0, 100.0]);
    let mean = DMatrix::from_row_slice(2, 4, &[2.5, 2.5, 2.5, 2.5, 5.0, 5.0, 5.0, 6.0]);
    let fit = fit_percent(&y, &mean, 0);
    assert!((fit[0] - 0.0).abs() < 1e-12);
    assert_eq!(fit[1], f64::NEG_INFINITY, "no spread and not matched");
    let from_two = fit_percent(&y, &mean, 2);
    assert!(
        (from_two[0] - 0.0).abs() > 1.0,
        "scored from step 3: {}",
        from_two[0]
    );
}
