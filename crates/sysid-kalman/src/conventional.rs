//! The conventional (covariance-form) Kalman filter with the Joseph update and the
//! textbook RTS smoother, kept as an independent cross-check of the square-root form.
//!
//! # Algorithm
//! ```text
//! S_t = C_o P C_o' + R_oo,  K = P C_o' S_t^{-1},  x_{t|t} = x + K e
//! P_{t|t} = (I - K C_o) P (I - K C_o)' + K R_oo K'                 (Joseph form)
//! x_{t+1|t} = A x_{t|t} + B u + S_o R_oo^{-1} (y_o - C_o x_{t|t} - D_o u - h_o)
//! P_{t+1|t} = A~ P_{t|t} A~' + Q - S_o R_oo^{-1} S_o',  A~ = A - S_o R_oo^{-1} C_o
//! J_t = P_{t|t} A~' P_{t+1|t}^{-1},  P_{t|T} = P_{t|t} + J (P_{t+1|T} - P_{t+1|t}) J'
//! ```
//! It allocates freely and needs `R_oo` and `P_{t+1|t}` invertible: it is a reference,
//! not the production path.

use crate::{KalmanError, LinearGaussianModel, Record, Result};
use nalgebra::{DMatrix, DVector};
use sysid_linalg::{LN_2PI, symmetrize};

/// Result of the conventional filter and smoother (all indices 0-based, time `k + 1`).
#[derive(Debug, Clone)]
pub struct ConventionalOutput {
    /// Log-likelihood.
    pub loglik: f64,
    /// `x_{k+1|k}`, `k = 0..=T`.
    pub predicted_means: Vec<DVector<f64>>,
    /// `P_{k+1|k}`, `k = 0..=T`.
    pub predicted_covariances: Vec<DMatrix<f64>>,
    /// `x_{k+1|k+1}`, `k = 0..T`.
    pub filtered_means: Vec<DVector<f64>>,
    /// `P_{k+1|k+1}`, `k = 0..T`.
    pub filtered_covariances: Vec<DMatrix<f64>>,
    /// `x_{k+1|T}`, `k = 0..=T`.
    pub smoothed_means: Vec<DVector<f64>>,
    /// `P_{k+1|T}`, `k = 0..=T`.
    pub smoothed_covariances: Vec<DMatrix<f64>>,
    /// `Cov(x_{k+2}, x_{k+1} | y)`, `k = 0..T`.
    pub lag_one_covariances: Vec<DMatrix<f64>>,
}

fn select(m: &DMatrix<f64>, rows: &[usize], cols: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), cols.len(), |i, j| m[(rows[i], cols[j])])
}

/// Runs the conventional filter and smoother over one record.
///
/// # Errors
/// Invalid record, or a singular `S_t`, `R_oo` or `P_{t+1|t}` (reported as
/// [`KalmanError::SingularInnovation`] at that time).
pub fn filter_smooth(model: &LinearGaussianModel, record: &Record) -> Result<ConventionalOutput> {
    record.validate(model, 0)?;
    let (n, p) = (model.n(), model.p());
    let all_n: Vec<usize> = (0..n).collect();
    let t_len = record.len();
    let mut x = model.mu().clone();
    let mut pm = model.p1().clone();
    let mut out = ConventionalOutput {
        loglik: 0.0,
        predicted_means: vec![x.clone()],
        predicted_covariances: vec![pm.clone()],
        filtered_means: vec![],
        filtered_covariances: vec![],
        smoothed_means: vec![],
        smoothed_covariances: vec![],
        lag_one_covariances: vec![],
    };
    let mut a_tilde_list = Vec::with_capacity(t_len);
    let singular = |t: usize| KalmanError::SingularInnovation {
        record: 0,
        time: t + 1,
        output: 0,
    };
    for t in 0..t_len {
        let y = record.y.column(t);
        let u = record.u.column(t).clone_owned();
        let o: Vec<usize> = (0..p).filter(|&i| !y[i].is_nan()).collect();
        let c_o = select(model.c(), &o, &all_n);
        let d_o = select(model.d(), &o, &(0..model.m()).collect::<Vec<_>>());
        let r_oo = select(model.r(), &o, &o);
        let s_o = select(model.s(), &all_n, &o);
        let h_o = DVector::from_fn(o.len(), |i, _| model.h()[o[i]]);
        let y_o = DVector::from_fn(o.len(), |i, _| y[o[i]]);
        let (xf, pf, a_t, x_next, p_next);
        if o.is_empty() {
            xf = x.clone();
            pf = pm.clone();
            a_t = model.a().clone();
            x_next = model.a() * &xf + model.b() * &u;
            p_next = model.a() * &pf * model.a().transpose() + model.q();
        } else {
            let st = &c_o * &pm * c_o.transpose() + &r_oo;
            let st_inv = st.clone().try_inverse().ok_or_else(|| singular(t))?;
            let e = &y_o - &c_o * &x - &d_o * &u - &h_o;
            let det = st.determinant();
            if det <= 0.0 {
                return Err(singular(t));
            }
            out.loglik += -0.5 * (o.len() as f64) * LN_2PI
                - 0.5 * det.ln()
                - 0.5 * (e.transpose() * &st_inv * &e)[(0, 0)];
            let k = &pm * c_o.transpose() * &st_inv;
            xf = &x + &k * &e;
            let ikc = DMatrix::identity(n, n) - &k * &c_o;
            let mut joseph = &ikc * &pm * ikc.transpose() + &k * &r_oo * k.transpose();
            symmetrize(&mut joseph);
            pf = joseph;
            let r_inv = r_oo.clone().try_inverse().ok_or_else(|| singular(t))?;
            let g = &s_o * &r_inv;
            a_t = model.a() - &g * &c_o;
            x_next = model.a() * &xf + model.b() * &u + &g * (&y_o - &c_o * &xf - &d_o * &u - &h_o);
            p_next = &a_t * &pf * a_t.transpose() + model.q() - &g * s_o.transpose();
        }
        let mut p_next = p_next;
        symmetrize(&mut p_next);
        out.filtered_means.push(xf);
        out.filtered_covariances.push(pf);
        a_tilde_list.push(a_t);
        x = x_next;
        pm = p_next;
        out.predicted_means.push(x.clone());
        out.predicted_covariances.push(pm.clone());
    }
    // RTS backward pass
    let mut xs = vec![DVector::zeros(n); t_len + 1];
    let mut ps = vec![DMatrix::zeros(n, n); t_len + 1];
    let mut lag = vec![DMatrix::zeros(n, n); t_len];
    xs[t_len] = out.predicted_means[t_len].clone();
    ps[t_len] = out.predicted_covariances[t_len].clone();
    for t in (0..t_len).rev() {
        let p_pred_inv = out.predicted_covariances[t + 1]
            .clone()
            .try_inverse()
            .ok_or_else(|| singular(t))?;
        let j = &out.filtered_covariances[t] * a_tilde_list[t].transpose() * p_pred_inv;
        xs[t] = &out.filtered_means[t] + &j * (&xs[t + 1] - &out.predicted_means[t + 1]);
        let mut p = &out.filtered_covariances[t]
            + &j * (&ps[t + 1] - &out.predicted_covariances[t + 1]) * j.transpose();
        symmetrize(&mut p);
        ps[t] = p;
        lag[t] = &ps[t + 1] * j.transpose();
    }
    out.smoothed_means = xs;
    out.smoothed_covariances = ps;
    out.lag_one_covariances = lag;
    Ok(out)
}
