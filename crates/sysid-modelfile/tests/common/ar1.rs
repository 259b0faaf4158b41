//! The linear Gaussian AR(1) with noisy measurements, `x' = a x + w`, `y = x + e`
//! (truth a = 0.8, q = 0.3, r = 0.5, T = 300): its exact log-likelihood by the Kalman
//! filter, its exact maximum by a grid and coordinate-wise ternary searches, and the
//! exact covariance of the estimate from the observed information. They share no code
//! with the fits' searches or particle filters.

use nalgebra::{DMatrix, DVector, dmatrix};
use sysid_kalman::{KalmanWorkspace, LinearGaussianModel, Record};
use sysid_smc::stream;

pub fn linear(a: f64, q: f64, r: f64) -> LinearGaussianModel {
    LinearGaussianModel::builder(dmatrix![a], dmatrix![1.0], dmatrix![q], dmatrix![r])
        .mu(DVector::from_element(1, 2.0))
        .p1(dmatrix![1.0])
        .build()
        .unwrap()
}

/// The exact log-likelihood at `(a, ln q, ln r)`.
pub fn exact(record: &Record, v: [f64; 3]) -> f64 {
    KalmanWorkspace::new()
        .loglik(&linear(v[0], v[1].exp(), v[2].exp()), record)
        .unwrap()
}

/// The exact maximum: the best point of a 25^3 grid, then ternary searches along each
/// coordinate in turn, shrinking the bracket, until a sweep moves nothing.
pub fn exact_maximum(record: &Record) -> ([f64; 3], f64) {
    let lows = [-0.98, -6.0, -6.0];
    let highs = [0.98, 3.0, 3.0];
    let at = |k: usize, i: usize| lows[k] + (highs[k] - lows[k]) * i as f64 / 24.0;
    let mut best = ([0.0; 3], f64::NEG_INFINITY);
    for i in 0..25 {
        for j in 0..25 {
            for l in 0..25 {
                let v = [at(0, i), at(1, j), at(2, l)];
                let f = exact(record, v);
                if f > best.1 {
                    best = (v, f);
                }
            }
        }
    }
    let mut v = best.0;
    let mut width = [0.08, 0.4, 0.4];
    for _ in 0..200 {
        let before = v;
        for k in 0..3 {
            let (mut lo, mut hi) = (v[k] - width[k], v[k] + width[k]);
            if k == 0 {
                (lo, hi) = (lo.max(-0.999), hi.min(0.999));
            }
            while hi - lo > 1e-10 {
                let (m1, m2) = (lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0);
                let (mut v1, mut v2) = (v, v);
                (v1[k], v2[k]) = (m1, m2);
                if exact(record, v1) < exact(record, v2) {
                    lo = m1;
                } else {
                    hi = m2;
                }
            }
            v[k] = 0.5 * (lo + hi);
            width[k] = (width[k] * 0.7).max(1e-3);
        }
        if before.iter().zip(&v).all(|(x, y)| (x - y).abs() < 1e-9) {
            break;
        }
    }
    (v, exact(record, v))
}

pub fn record_and_series() -> (Record, Vec<f64>) {
    let mut rng = stream(11, 0);
    let simulation = linear(0.8, 0.3, 0.5)
        .simulate(&DMatrix::zeros(0, 300), &mut rng)
        .unwrap();
    let y: Vec<f64> = simulation.record.y.iter().copied().collect();
    (simulation.record, y)
}

/// The exact covariance of `(a, ln q, ln r)` at `v`: the inverse of the observed
/// information, by central differences of the Kalman log-likelihood.
pub fn exact_covariance(record: &Record, v: [f64; 3]) -> DMatrix<f64> {
    let h = 1e-3;
    let mut info = DMatrix::zeros(3, 3);
    for j in 0..3 {
        for k in 0..3 {
            let f = |dj: f64, dk: f64| {
                let mut p = v;
                p[j] += dj;
                p[k] += dk;
                exact(record, p)
            };
            info[(j, k)] = -(f(h, h) - f(h, -h) - f(-h, h) + f(-h, -h)) / (4.0 * h * h);
        }
    }
    info.try_inverse().unwrap()
}

/// The model as a model file whose transition is `x = "<transition>"` in one parameter
/// `coefficient` (started at 0.3); the noise variances start at q = 1, r = 2 (truth
/// 0.3 and 0.5). The initial mean is not 0, so that the noise-free simulation (which
/// the fit's identifiability check differentiates) moves.
pub fn model_file(name: &str, coefficient: &str, transition: &str) -> String {
    format!(
        r#"
format = 1
name = "{name}"
states = ["x"]
outputs = ["y"]
[parameters]
{coefficient} = {{ value = 0.3 }}
q = {{ value = 1.0, min = 0 }}
r = {{ value = 2.0, min = 0 }}
[transition]
x = "{transition}"
[observation]
y = "x"
[noise]
x = "q"
y = "r"
[initial]
x = {{ mean = 2.0, variance = 1.0 }}
"#
    )
}
