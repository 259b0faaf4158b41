//! The lecture's starting point for blind Wiener identification: the linear part from
//! N4SID on `y1`, the nonlinearity at a tenth of the truth.
//!
//! # Algorithm
//! N4SID (order 2, no inputs) on `y1` gives `A, C` and the residual covariances
//! `Q, R, S` of its state and output equations. The state is put in the basis where
//! `C = [1, 0]`, which keeps `A`'s poles. N4SID's model of `y1` has a direct noise
//! path (`R`, and `S` couples it to the state noise), so its spectrum
//!
//! ```text
//! Phi(w) = v Q v^H + 2 Re(v S) + R,   v = C (e^{iw} I - A)^{-1}
//! ```
//!
//! is biproper, while the estimation model's `z = x_1` has none: `z`'s spectrum is
//! `v Q~ v^H` alone. Dropping `R` and `S` (keeping N4SID's `Q`) moves the zero of the
//! spectrum; instead `Q~` is fitted so that `v Q~ v^H + rho` matches `Phi` in relative
//! least squares on 256 frequencies (`rho`, a white floor, is what the output noise
//! and the nonlinearity's distortion take), then projected onto the positive definite
//! matrices. If the fit fails, N4SID's `Q` is used.

use crate::BlindWiener;
use crate::wiener::{WienerEstimate, output_row};
use nalgebra::{DMatrix, DVector};
use sysid_smc::ModelError;

/// Frequencies of the spectrum fit, `pi (k + 1/2) / 256`.
const FIT_FREQUENCIES: usize = 256;

/// The lecture's starting point from outputs `y` (time-major `T x 2`): the linear part
/// from N4SID (order 2, no inputs) on `y1` alone, in the basis where `C = [1, 0]`, with
/// its noise covariance fitted to N4SID's spectrum (module docs); `r1 = r2 = 0.1`; each
/// breakpoint at a tenth of its true value.
pub fn wiener_start(outputs: &[f64]) -> Result<WienerEstimate, ModelError> {
    use sysid_subspace::{N4sidOptions, Order, n4sid};
    let steps = outputs.len() / 2;
    let y1 = DMatrix::from_iterator(1, steps, outputs.iter().step_by(2).copied());
    let record = sysid_kalman::Record::new(DMatrix::zeros(0, steps), y1);
    let fit = n4sid(
        &record,
        &N4sidOptions {
            order: Order::Fixed(2),
            block_rows: None,
            ..Default::default()
        },
    )
    .map_err(|e| format!("N4SID on y1: {e}"))?;
    let model = &fit.model;
    let (a, c, q) = (model.a(), model.c(), model.q());
    let t = if c[(0, 0)].abs() >= 1e-3 * c[(0, 1)].abs() {
        DMatrix::from_row_slice(2, 2, &[c[(0, 0)], c[(0, 1)], 0.0, 1.0])
    } else {
        DMatrix::from_row_slice(2, 2, &[c[(0, 0)], c[(0, 1)], 1.0, 0.0])
    };
    let t_inv = t.clone().try_inverse().ok_or("N4SID gave C = 0 on y1")?;
    let a2 = &t * a * &t_inv;
    let a2 = [[a2[(0, 0)], a2[(0, 1)]], [a2[(1, 0)], a2[(1, 1)]]];
    let a1 = [[a[(0, 0)], a[(0, 1)]], [a[(1, 0)], a[(1, 1)]]];
    let n4sid_spectrum = |omega: f64| {
        let v = output_row(&a1, &[c[(0, 0)], c[(0, 1)]], omega);
        let mut total = model.r()[(0, 0)];
        for i in 0..2 {
            total += 2.0 * v[i].0 * model.s()[(i, 0)];
            for j in 0..2 {
                total += q[(i, j)] * (v[i].0 * v[j].0 + v[i].1 * v[j].1);
            }
        }
        total
    };
    let q2 = match fitted_noise(&a2, n4sid_spectrum) {
        Some(q) => q,
        None => {
            let mut q2 = &t * q * t.transpose();
            q2 = (&q2 + q2.transpose()) * 0.5;
            if q2.clone().cholesky().is_none() {
                let jitter = 1e-6 * q2.trace().abs().max(1e-12);
                q2 += DMatrix::identity(2, 2) * jitter;
            }
            [[q2[(0, 0)], q2[(0, 1)]], [q2[(1, 0)], q2[(1, 1)]]]
        }
    };
    let b = BlindWiener::BETA;
    Ok(WienerEstimate {
        a: a2,
        q: q2,
        beta: b.map(|v| v / 10.0),
        r: [0.1, 0.1],
    })
}

/// Relative size of the identity added to the rank-one fitted `Q~`, so that it is
/// positive definite (the model's Cholesky parametrisation needs it).
const NOISE_JITTER: f64 = 1e-4;

/// A positive definite `Q~` with `v Q~ v^H + rho` close to `spectrum` in relative least
/// squares, `v = [1, 0] (e^{iw} I - A)^{-1}`; `None` if the spectrum is not positive on
/// the grid or the fit has no valid factor.
///
/// With `d(w) = det(e^{iw} I - A)`, every `v Q v^H` is `(n0 + n1 cos w) / |d|^2`: only
/// two numbers of `Q` reach the spectrum. The fit finds `(n0, n1, rho)`, factors
/// `n0 + n1 cos w = |c0 + c1 e^{iw}|^2`, and takes the rank-one `Q = b b'` with
/// `v b = (c0 + c1 e^{iw}) / d`, plus `NOISE_JITTER |b|^2 I`.
fn fitted_noise(a: &[[f64; 2]; 2], spectrum: impl Fn(f64) -> f64) -> Option<[[f64; 2]; 2]> {
    let mut design = DMatrix::zeros(FIT_FREQUENCIES, 3);
    let target = DVector::from_element(FIT_FREQUENCIES, 1.0);
    for k in 0..FIT_FREQUENCIES {
        let omega = std::f64::consts::PI * (k as f64 + 0.5) / FIT_FREQUENCIES as f64;
        let phi = spectrum(omega);
        if !(phi.is_finite() && phi > 0.0) {
            return None;
        }
        let (c, s) = (omega.cos(), omega.sin());
        let d = (
            (c - a[0][0]) * (c - a[1][1]) - s * s - a[0][1] * a[1][0],
            s * (c - a[1][1]) + s * (c - a[0][0]),
        );
        let d2 = d.0 * d.0 + d.1 * d.1;
        for (j, value) in [1.0 / d2, c / d2, 1.0].iter().enumerate() {
            design[(k, j)] = value / phi;
        }
    }
    let x = design.svd(true, true).solve(&target, 1e-12).ok()?;
    let (n0, n1) = (x[0], x[1].clamp(-x[0].abs(), x[0].abs()));
    if !(n0.is_finite() && n0 > 0.0) || a[0][1].abs() < 1e-12 {
        return None;
    }
    let (p, m) = ((n0 + n1).sqrt(), (n0 - n1).sqrt());
    let (c0, c1) = ((p + m) / 2.0, (p - m) / 2.0);
    // v = [e^{iw} - a22, a12] / d, so v b = (c1 e^{iw} + c0) / d for these b
    let b = [c1, (c0 + a[1][1] * c1) / a[0][1]];
    let jitter = NOISE_JITTER * (b[0] * b[0] + b[1] * b[1]);
    let q = [
        [b[0] * b[0] + jitter, b[0] * b[1]],
        [b[0] * b[1], b[1] * b[1] + jitter],
    ];
    q.iter().flatten().all(|v| v.is_finite()).then_some(q)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::normalised_magnitude_error;
    use crate::wiener::spectral_magnitude;

    #[test]
    fn the_noise_fit_recovers_a_representable_spectrum() {
        // the true linear part in the basis C = [1, 0] (T = [[1, 0.3], [0, 1]]), its
        // rank-one Q, and a white floor: the fitted Q must give back the spectrum
        let a = [[1.3, -1.29], [1.0, -0.3]];
        let q = [[1.0, 0.0], [0.0, 0.0]];
        let shape = |q: &[[f64; 2]; 2], w: f64| spectral_magnitude(&a, q, &[1.0, 0.0], w);
        let fitted = fitted_noise(&a, |w| shape(&q, w).powi(2) + 0.5).expect("a fit");
        for k in 1..64 {
            let w = std::f64::consts::PI * k as f64 / 64.0;
            let (want, got) = (shape(&q, w), shape(&fitted, w));
            // the jitter adds 1e-4 |b|^2 of white-ish power
            assert!(
                (got - want).abs() < 1e-3 * want.max(1.0),
                "w = {w}: {got} vs {want}"
            );
        }
        assert!(
            WienerEstimate {
                a,
                q: fitted,
                beta: [-1.0, 1.0, -1.0, 1.0],
                r: [1.0, 1.0],
            }
            .theta()
            .is_ok()
        );
        // a spectrum that is not positive has no fit
        assert!(fitted_noise(&a, |_| -1.0).is_none());
    }

    #[test]
    fn the_start_has_the_shape_of_the_linear_part() {
        // with N4SID's Q as it comes (R and S dropped) the error was 0.22-0.28
        for seed in 1..=3 {
            let sim = BlindWiener::simulate(1000, seed);
            let start = wiener_start(&sim.outputs).unwrap();
            let error = normalised_magnitude_error(&start);
            assert!(error < 0.15, "seed {seed}: magnitude error {error}");
            assert!(start.theta().is_ok());
        }
    }
}
