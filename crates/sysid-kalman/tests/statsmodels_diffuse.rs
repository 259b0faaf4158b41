//! Values from another tool: statsmodels 0.15.0 (numpy 2.4.6) with the exact diffuse
//! initialisation (`Initialization(k, "diffuse")`, and `"stationary"` for the mixed
//! case), `ssm.smooth()`. The data are closed-form functions of t, rebuilt here; the
//! script is `tests/reference/statsmodels_diffuse.py`.

use nalgebra::{DMatrix, DVector, dmatrix};
use sysid_kalman::{KalmanWorkspace, LinearGaussianModel, Record};

fn close(got: f64, want: f64, what: &str) {
    assert!(
        (got - want).abs() <= 1e-9 * want.abs().max(1.0),
        "{what}: sysid {got} vs statsmodels {want}"
    );
}

fn series(f: impl Fn(f64) -> f64, missing: &[usize]) -> DMatrix<f64> {
    let mut y = DMatrix::from_fn(1, 60, |_, k| f((k + 1) as f64));
    for &k in missing {
        y[(0, k)] = f64::NAN;
    }
    y
}

/// Checks loglik (square-root filter and smoother) and smoothed moments at
/// `(k, mean, covariance by rows)`.
fn check(
    model: &LinearGaussianModel,
    rec: &Record,
    loglik: f64,
    states: &[(usize, &[f64], &[f64])],
) {
    let mut ws = KalmanWorkspace::new();
    close(ws.loglik(model, rec).unwrap(), loglik, "loglik");
    let sm = ws.smooth(model, rec).unwrap();
    close(sm.loglik(), loglik, "loglik (smoother pass)");
    let n = model.n();
    for &(k, mean, cov) in states {
        for i in 0..n {
            close(
                sm.mean(k)[i],
                mean[i],
                &format!("smoothed mean {i} at k = {k}"),
            );
            for j in 0..n {
                close(
                    sm.covariance(k)[(i, j)],
                    cov[i * n + j],
                    &format!("smoothed cov ({i},{j}) at k = {k}"),
                );
            }
        }
    }
}

/// y = 10 + cumsum(sin 0.7 t) + 0.5 cos 1.9 t, missing at k = 4, 5, 30; local level.
#[test]
fn local_level() {
    let mut acc = 0.0;
    let mut y = DMatrix::from_fn(1, 60, |_, k| {
        let t = (k + 1) as f64;
        acc += (0.7 * t).sin();
        10.0 + acc + 0.5 * (1.9 * t).cos()
    });
    for k in [4, 5, 30] {
        y[(0, k)] = f64::NAN;
    }
    let model =
        LinearGaussianModel::builder(dmatrix![1.0], dmatrix![1.0], dmatrix![0.8], dmatrix![1.5])
            .p1(dmatrix![0.0])
            .diffuse(dmatrix![1.0])
            .build()
            .unwrap();
    let rec = Record::outputs_only(y);
    check(
        &model,
        &rec,
        -95.80251789571655,
        &[
            (0, &[11.164267765443565], &[0.7693076967294034]),
            (4, &[11.717974004810353], &[0.9451813596378191]),
            (59, &[12.08274029632696], &[0.7661903790380465]),
        ],
    );
    let f = KalmanWorkspace::new().filter(&model, &rec).unwrap().clone();
    assert_eq!(f.diffuse_steps(), 0);
    for (k, m, p) in [
        (0, 10.48257290380594, 1.5),
        (1, 10.937495143849336, 0.9078947368421055),
        (2, 11.987787992952683, 0.7986054142739952),
    ] {
        close(f.filtered_mean(k)[0], m, "filtered mean");
        close(f.filtered_covariance(k)[(0, 0)], p, "filtered variance");
    }
}

/// y = 0.05 t^1.5 + sin 0.4 t, missing at k = 0, 10, 11, 40; local linear trend, both
/// states diffuse.
#[test]
fn local_linear_trend_with_a_missing_first_value() {
    let y = series(|t| 0.05 * t.powf(1.5) + (0.4 * t).sin(), &[0, 10, 11, 40]);
    let model = LinearGaussianModel::builder(
        dmatrix![1.0, 1.0; 0.0, 1.0],
        dmatrix![1.0, 0.0],
        DMatrix::from_diagonal(&DVector::from_vec(vec![0.3, 0.01])),
        dmatrix![0.7],
    )
    .p1(DMatrix::zeros(2, 2))
    .diffuse(DMatrix::identity(2, 2))
    .build()
    .unwrap();
    check(
        &model,
        &Record::outputs_only(y),
        -69.93383823239043,
        &[
            (
                0,
                &[0.8440278432941836, 0.1149012366020018],
                &[
                    0.8694214056780709,
                    -0.12556500042759067,
                    -0.12556500042759067,
                    0.06952174635482322,
                ],
            ),
            (
                1,
                &[0.9589290798961854, 0.1149012366020018],
                &[
                    0.3878131511777128,
                    -0.056043254072767446,
                    -0.056043254072767446,
                    0.05952174635482322,
                ],
            ),
            (
                30,
                &[8.502500013624307, 0.46961632204916914],
                &[
                    0.22377279082818438,
                    -0.0028669708425317813,
                    -0.0028669708425317813,
                    0.027980813330478055,
                ],
            ),
            (
                59,
                &[22.21383910265198, 0.41895344241302535],
                &[
                    0.38766134046982864,
                    0.055889488801447756,
                    0.055889488801447756,
                    0.06936591308304059,
                ],
            ),
        ],
    );
}

/// y = 3 + sin 0.3 t + 0.4 cos 2.3 t, missing at k = 20; a diffuse level plus a
/// stationary AR(1) (variance 0.5 / (1 - 0.49)).
#[test]
fn diffuse_level_plus_stationary_ar1() {
    let y = series(|t| 3.0 + (0.3 * t).sin() + 0.4 * (2.3 * t).cos(), &[20]);
    let model = LinearGaussianModel::builder(
        dmatrix![1.0, 0.0; 0.0, 0.7],
        dmatrix![1.0, 1.0],
        dmatrix![0.1, 0.0; 0.0, 0.5],
        dmatrix![0.2],
    )
    .p1(dmatrix![0.0, 0.0; 0.0, 0.5 / (1.0 - 0.49)])
    .diffuse(dmatrix![1.0; 0.0])
    .build()
    .unwrap();
    check(
        &model,
        &Record::outputs_only(y),
        -61.81414766973851,
        &[
            (
                0,
                &[3.2847121403035793, -0.14634116944598358],
                &[
                    0.5449837679460474,
                    -0.48021825595379664,
                    -0.48021825595379664,
                    0.573510819483847,
                ],
            ),
            (
                59,
                &[2.612628819957907, -0.10178915155035001],
                &[
                    0.5449520923872657,
                    -0.4801892854435061,
                    -0.4801892854435061,
                    0.5734843230146834,
                ],
            ),
        ],
    );
}

/// Two outputs with correlated noise, one input, y2 missing at k = 0, y1 at k = 5, 6,
/// both at k = 33; both states diffuse (one of them a unit root).
#[test]
fn two_outputs_with_inputs_and_correlated_noise() {
    let t = |k: usize| (k + 1) as f64;
    let u = DMatrix::from_fn(1, 60, |_, k| (0.5 * t(k)).cos());
    let mut y = DMatrix::from_fn(2, 60, |i, k| {
        let t = t(k);
        if i == 0 {
            (0.2 * t).sin() + 0.4 * (0.9 * t).cos()
        } else {
            0.5 * (0.3 * t).cos() - 0.2 * (1.3 * t).sin() + 0.02 * t
        }
    });
    y[(1, 0)] = f64::NAN;
    y[(0, 5)] = f64::NAN;
    y[(0, 6)] = f64::NAN;
    y.column_mut(33).fill(f64::NAN);
    let model = LinearGaussianModel::builder(
        dmatrix![0.9, 0.3; 0.0, 1.0],
        dmatrix![1.0, 0.0; 0.5, 1.0],
        dmatrix![0.5, 0.1; 0.1, 0.3],
        dmatrix![0.2, 0.05; 0.05, 0.1],
    )
    .b(dmatrix![1.0; 0.2])
    .p1(DMatrix::zeros(2, 2))
    .diffuse(DMatrix::identity(2, 2))
    .build()
    .unwrap();
    check(
        &model,
        &Record::new(u, y),
        -119.08638790685016,
        &[
            (
                0,
                &[0.19947612035542203, -0.016665750406822076],
                &[
                    0.1602389342280969,
                    -0.010503474145945497,
                    -0.010503474145945497,
                    0.37549369271292804,
                ],
            ),
            (
                1,
                &[0.40498088430200974, 0.14508202876303555],
                &[
                    0.12349662165952524,
                    -0.022161677079948677,
                    -0.02216167707994865,
                    0.07420392069124304,
                ],
            ),
            (
                33,
                &[0.14216255325380855, 0.1743932425240324],
                &[
                    0.33833753951794937,
                    0.017813174072041898,
                    0.017813174072041877,
                    0.18395480421705218,
                ],
            ),
            (
                59,
                &[-0.8142871744059973, 1.8008456932854087],
                &[
                    0.14225208796005137,
                    -0.02394723334902429,
                    -0.023947233349024318,
                    0.07433270571372833,
                ],
            ),
        ],
    );
}
