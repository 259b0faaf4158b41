//! Closed-form log-likelihood for one state and one output: the fast path of
//! [`crate::KalmanWorkspace::loglik`] when `n = p = 1`.
//!
//! # Algorithm
//! With `S = c^2 P + r`, `e = y - c x - d u - h`:
//! ```text
//! x_f = x + P c e / S,          P_f = P r / S
//! x'  = a x_f + b u + g (y - c x_f - d u - h),   g = s / r
//! P'  = (a - g c)^2 P_f + (q - g s)
//! ```
//! Every variance is a product or sum of non-negative terms, so it stays non-negative
//! without a square root; it equals the array form to round-off (tested against it
//! and against the dense joint Gaussian).

use crate::{KalmanError, LinearGaussianModel, Record, Result};
use sysid_linalg::{LN_2PI, LogProduct, dot};

pub(crate) fn loglik(
    model: &LinearGaussianModel,
    record: &Record,
    record_index: usize,
) -> Result<f64> {
    let m = model.m();
    let (a, c, q, r, s, h) = (
        model.a()[(0, 0)],
        model.c()[(0, 0)],
        model.q()[(0, 0)],
        model.r()[(0, 0)],
        model.s()[(0, 0)],
        model.h()[0],
    );
    let (b, d) = (model.b().as_slice(), model.d().as_slice());
    let g = if r > 0.0 { s / r } else { 0.0 };
    let a_tilde = a - g * c;
    let q_tilde = (q - g * s).max(0.0);
    let (mut x, mut p) = (model.mu()[0], model.p1()[(0, 0)]);
    let y = record.y.as_slice();
    let u = record.u.as_slice();
    let mut logdet = LogProduct::new();
    let (mut quad, mut observed) = (0.0, 0usize);
    for (t, &yt) in y.iter().enumerate() {
        let ut = &u[t * m..(t + 1) * m];
        let bu = dot(b, ut);
        if yt.is_nan() {
            x = a * x + bu;
            p = a * a * p + q;
            continue;
        }
        let ss = c * c * p + r;
        if ss <= 0.0 {
            return Err(KalmanError::SingularInnovation {
                record: record_index,
                time: t + 1,
                output: 1,
            });
        }
        let inv = 1.0 / ss;
        let e = yt - c * x - dot(d, ut) - h;
        quad += e * e * inv;
        logdet.push(ss);
        observed += 1;
        let xf = x + p * c * e * inv;
        let pf = p * r * inv;
        x = a * xf + bu + g * (yt - c * xf - dot(d, ut) - h);
        p = a_tilde * a_tilde * pf + q_tilde;
    }
    Ok(-0.5 * (observed as f64) * LN_2PI - 0.5 * logdet.ln() - 0.5 * quad)
}
