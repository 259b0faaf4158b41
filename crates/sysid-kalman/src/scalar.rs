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
//! evaluated in the algebraically equal form that shortens the dependency chain
//! (`P' = (a - g c)^2 r P / S + q - g s`). The same holds as a formula:
//! ```text
//! P' >= 0 whenever P >= 0, r >= 0, q - g s >= 0
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
    reuse_steady_state: bool,
) -> Result<f64> {
    let loglik = loglik_pass::<false>(model, record, record_index, reuse_steady_state)?;
    if loglik.is_finite() {
        return Ok(loglik);
    }
    // rare: find the step where it overflowed (a second pass that checks every step,
    // kept off the fast path)
    loglik_pass::<true>(model, record, record_index, reuse_steady_state)
}

/// One pass of the recursion; with `LOCATE_OVERFLOW` every step is checked and the
/// first non-finite term is reported with its time.
fn loglik_pass<const LOCATE_OVERFLOW: bool>(
    model: &LinearGaussianModel,
    record: &Record,
    record_index: usize,
    reuse_steady_state: bool,
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
    // The variance recursion is the critical dependency chain; it is written so that
    // each step costs one multiply-add, one division and one add on the chain:
    //   S = c^2 P + r,  P' = (a~^2 r) P / S + q~
    // and the mean update is one multiply-add on its chain:
    //   x' = (a~ r / S) x + a~ P c (y - d u - h) / S + b u + g (y - d u - h).
    let (c2, ar2) = (c * c, a_tilde * a_tilde * r);
    // Once P has settled (a change below 16 eps relative: what its own rounding
    // resolves), the step coefficients are reused: no division on the chain.
    let mut steady = false;
    let (mut ss, mut inv, mut x_coef, mut z_coef) = (0.0, 0.0, 0.0, 0.0);
    for (t, &yt) in y.iter().enumerate() {
        let ut = &u[t * m..(t + 1) * m];
        let bu = dot(b, ut);
        if yt.is_nan() {
            x = a * x + bu;
            p = a * a * p + q;
            steady = false;
            continue;
        }
        if !steady {
            ss = c2 * p + r;
            if ss <= 0.0 {
                return Err(KalmanError::SingularInnovation {
                    record: record_index,
                    time: t + 1,
                    output: 1,
                });
            }
            inv = 1.0 / ss;
            x_coef = a_tilde * r * inv;
            z_coef = a_tilde * p * c * inv + g;
            let p_next = ar2 * p * inv + q_tilde;
            steady = reuse_steady_state && (p_next - p).abs() <= 16.0 * f64::EPSILON * p.abs();
            p = p_next;
        }
        let z = yt - dot(d, ut) - h; // y - d u - h
        let e = z - c * x;
        quad += e * e * inv;
        if LOCATE_OVERFLOW && !(quad.is_finite() && x.is_finite()) {
            return Err(KalmanError::Overflow {
                record: record_index,
                time: t + 1,
            });
        }
        logdet.push(ss);
        observed += 1;
        x = x_coef * x + z_coef * z + bu;
    }
    let loglik = -0.5 * (observed as f64) * LN_2PI - 0.5 * logdet.ln() - 0.5 * quad;
    if LOCATE_OVERFLOW && !loglik.is_finite() {
        // every step's term was finite but their sum is not
        return Err(KalmanError::Overflow {
            record: record_index,
            time: y.len(),
        });
    }
    Ok(loglik)
}
