//! Values from another tool: statsmodels 0.15.0 (numpy 2.4.6), `MLEModel` with
//! `initialize_known(mu, P1)`, `state_intercept = B u_t`, `obs_intercept = D u_t + h`,
//! then `ssm.smooth()`. The data are closed-form functions of t, rebuilt here; the
//! script that produced the numbers is `tests/reference/statsmodels_kalman.py`.

use nalgebra::{DMatrix, dmatrix, dvector};
use sysid_kalman::{KalmanWorkspace, LinearGaussianModel, Record};

fn close(got: f64, want: f64, what: &str) {
    assert!(
        (got - want).abs() <= 1e-10 * want.abs().max(1.0),
        "{what}: sysid {got} vs statsmodels {want}"
    );
}

/// t = 1..50, y = 2 sin(0.37 t) + 0.3 cos(2.1 t), missing at t = 10, 11, 30;
/// lgss: a = 0.9, c = 1, q = 1, r = 0.5, x1 ~ N(0, 1).
#[test]
fn scalar_model_with_missing_steps() {
    let mut y = DMatrix::from_fn(1, 50, |_, k| {
        let t = (k + 1) as f64;
        2.0 * (0.37 * t).sin() + 0.3 * (2.1 * t).cos()
    });
    for t in [10, 11, 30] {
        y[(0, t - 1)] = f64::NAN;
    }
    let model =
        LinearGaussianModel::builder(dmatrix![0.9], dmatrix![1.0], dmatrix![1.0], dmatrix![0.5])
            .build()
            .unwrap();
    let rec = Record::outputs_only(y);
    let mut ws = KalmanWorkspace::new();
    close(
        ws.loglik(&model, &rec).unwrap(),
        -64.33733590831912,
        "loglik (fast path)",
    );
    let sm = ws.smooth(&model, &rec).unwrap();
    close(sm.loglik(), -64.33733590831912, "loglik (array form)");
    for (k, x, p) in [
        (0, 0.5823920578723146, 0.27901822809233534),
        (9, -0.5785972858472936, 0.932287875061952),
        (49, -0.9218599257468205, 0.36049088595822354),
    ] {
        close(sm.mean(k)[0], x, &format!("smoothed mean at t = {}", k + 1));
        close(
            sm.covariance(k)[(0, 0)],
            p,
            &format!("smoothed variance at t = {}", k + 1),
        );
    }
}

/// t = 1..40, u = cos(0.5 t), y1 = sin(0.2 t) + 0.4 cos(0.9 t),
/// y2 = 0.5 cos(0.3 t) - 0.2 sin(1.3 t); y2 missing at t = 5..8, y1 at t = 20, both at
/// t = 33. Two states, one input, two outputs, offset, correlated Q and R.
#[test]
fn two_state_model_with_inputs_offset_and_partial_missing() {
    let t_len = 40;
    let u = DMatrix::from_fn(1, t_len, |_, k| (0.5 * (k + 1) as f64).cos());
    let mut y = DMatrix::from_fn(2, t_len, |i, k| {
        let t = (k + 1) as f64;
        if i == 0 {
            (0.2 * t).sin() + 0.4 * (0.9 * t).cos()
        } else {
            0.5 * (0.3 * t).cos() - 0.2 * (1.3 * t).sin()
        }
    });
    for t in 5..=8 {
        y[(1, t - 1)] = f64::NAN;
    }
    y[(0, 19)] = f64::NAN;
    y.column_mut(32).fill(f64::NAN);
    let model = LinearGaussianModel::builder(
        dmatrix![0.7, 0.2; -0.1, 0.5],
        dmatrix![1.0, 0.0; 0.5, 1.0],
        dmatrix![0.5, 0.1; 0.1, 0.3],
        dmatrix![0.2, 0.05; 0.05, 0.1],
    )
    .b(dmatrix![1.0; 0.5])
    .d(dmatrix![0.2; 0.0])
    .h(dvector![0.3, -0.1])
    .mu(dvector![0.1, -0.2])
    .p1(dmatrix![1.0, 0.2; 0.2, 2.0])
    .build()
    .unwrap();
    let rec = Record::new(u, y);
    let mut ws = KalmanWorkspace::new();
    close(
        ws.loglik(&model, &rec).unwrap(),
        -84.74869098767446,
        "loglik",
    );
    let sm = ws.smooth(&model, &rec).unwrap();
    for (k, x) in [
        (0, [-0.151559035090198, 0.3687642001084053]),
        (19, [-0.8577018482976845, 0.7497514721321217]),
        (32, [-0.33069572669016223, -0.26617815334573985]),
        (39, [0.6569894466582746, 0.10401252161406177]),
    ] {
        for (i, &want) in x.iter().enumerate() {
            close(
                sm.mean(k)[i],
                want,
                &format!("smoothed x{} at t = {}", i + 1, k + 1),
            );
        }
    }
    let p = sm.covariance(32);
    close(p[(0, 0)], 0.38700743524572023, "P11 at t = 33");
    close(p[(0, 1)], 0.05067957705217025, "P12 at t = 33");
    close(p[(1, 1)], 0.26196214450914646, "P22 at t = 33");
}
