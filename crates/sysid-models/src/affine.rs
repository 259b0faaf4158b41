//! The canonical systems in the affine form of `sysid_em::affine`.

use crate::{LinearGaussianSmc, Nlbench, NlbenchParams};
use nalgebra::{dmatrix, dvector};
use sysid_em::affine::{AffineEmError, AffineModel, AffineParams};
use sysid_kalman::LinearGaussianModel;

/// `nlbench` as an affine model: the state row uses the regressors
/// `[x, x/(1+x²), cos(1.2 (t+1))]`, the output row `[x²]`:
/// ```text
/// alpha_t = [x_t, x_t/(1+x_t^2), cos(1.2 (t+1)), x_t^2]
/// beta_x  = [a, b, c, 0],  beta_y = [0, 0, 0, d],  Pi = diag(q, r)
/// ```
#[derive(Debug, Clone, Copy, Default)]
pub struct NlbenchAffine;

impl NlbenchAffine {
    /// The affine parameters of an [`NlbenchParams`].
    pub fn params(p: &NlbenchParams) -> AffineParams {
        AffineParams {
            beta_x: dmatrix![p.a, p.b, p.c, 0.0],
            beta_y: dmatrix![0.0, 0.0, 0.0, p.d],
            pi_x: dmatrix![p.q],
            pi_y: dmatrix![p.r],
            mu: dvector![p.mu],
            p1: dmatrix![p.p1],
        }
    }

    /// The [`NlbenchParams`] of affine parameters.
    pub fn nlbench_params(p: &AffineParams) -> NlbenchParams {
        NlbenchParams {
            a: p.beta_x[(0, 0)],
            b: p.beta_x[(0, 1)],
            c: p.beta_x[(0, 2)],
            d: p.beta_y[(0, 3)],
            q: p.pi_x[(0, 0)],
            r: p.pi_y[(0, 0)],
            mu: p.mu[0],
            p1: p.p1[(0, 0)],
        }
    }
}

fn check_shapes(p: &AffineParams, n: usize, ny: usize, r: usize) -> Result<(), AffineEmError> {
    let ok = p.beta_x.shape() == (n, r)
        && p.beta_y.shape() == (ny, r)
        && p.pi_x.shape() == (n, n)
        && p.pi_y.shape() == (ny, ny)
        && p.mu.len() == n
        && p.p1.shape() == (n, n);
    if ok {
        Ok(())
    } else {
        Err(AffineEmError::InvalidParams(format!(
            "expected beta_x {n}x{r}, beta_y {ny}x{r}, Pi_x {n}x{n}, Pi_y {ny}x{ny}, mu {n}, P1 {n}x{n}"
        )))
    }
}

impl AffineModel for NlbenchAffine {
    type Smc = Nlbench;

    fn state_dim(&self) -> usize {
        1
    }
    fn output_dim(&self) -> usize {
        1
    }
    fn regressor_dim(&self) -> usize {
        4
    }

    fn regressors(&self, t: usize, x: &[f64], _u: &[f64], out: &mut [f64]) {
        let x = x[0];
        out.copy_from_slice(&[
            x,
            x / (1.0 + x * x),
            crate::nlbench::forcing_cosine(t),
            x * x,
        ]);
    }

    #[inline]
    fn regressor_columns(&self, t: usize, states: &[f64], _u: &[f64], columns: &mut [f64]) {
        let forcing = crate::nlbench::forcing_cosine(t);
        let paths = states.len();
        let (x, rest) = columns.split_at_mut(paths);
        let (ratio, rest) = rest.split_at_mut(paths);
        let (cosine, square) = rest.split_at_mut(paths);
        x.copy_from_slice(states);
        for (r, &x) in ratio.iter_mut().zip(states) {
            *r = x / (1.0 + x * x);
        }
        cosine.fill(forcing);
        for (s, &x) in square.iter_mut().zip(states) {
            *s = x * x;
        }
    }

    fn state_structure(&self) -> Vec<Vec<usize>> {
        vec![vec![0, 1, 2]]
    }

    fn output_structure(&self) -> Vec<Vec<usize>> {
        vec![vec![3]]
    }

    fn smc_model(&self, params: &AffineParams) -> Result<Nlbench, AffineEmError> {
        check_shapes(params, 1, 1, 4)?;
        Nlbench::new(NlbenchAffine::nlbench_params(params))
            .map_err(|e| AffineEmError::InvalidParams(e.reason))
    }
}

/// A linear Gaussian model without inputs, offsets or cross-covariance, as an affine
/// model with `alpha = x`: `beta_x = A`, `beta_y = C`, `Pi = blockdiag(Q, R)`. Used
/// to check particle EM against exact linear EM.
#[derive(Debug, Clone)]
pub struct LinearAffine {
    n: usize,
    p: usize,
}

impl LinearAffine {
    /// The affine form of `model` and its parameters. Errors for a model with inputs
    /// or a non-zero cross-covariance (the form has neither).
    pub fn new(model: &LinearGaussianModel) -> Result<(Self, AffineParams), AffineEmError> {
        if model.m() > 0 || model.has_cross_covariance() || model.h().iter().any(|&v| v != 0.0) {
            return Err(AffineEmError::Unsupported(
                "the linear affine form has no inputs, offset or cross-covariance".into(),
            ));
        }
        if model.is_diffuse() {
            // particle EM samples x_0: a flat prior has no draws (it used to become
            // x_0 = 0 exactly)
            return Err(AffineEmError::Unsupported(
                "the model's initial state is diffuse; particle EM needs a proper initial \
                 law: give its mu and P1 (\"initial\": \"given\")"
                    .into(),
            ));
        }
        let params = AffineParams {
            beta_x: model.a().clone(),
            beta_y: model.c().clone(),
            pi_x: model.q().clone(),
            pi_y: model.r().clone(),
            mu: model.mu().clone(),
            p1: model.p1().clone(),
        };
        Ok((
            LinearAffine {
                n: model.n(),
                p: model.p(),
            },
            params,
        ))
    }

    /// The linear Gaussian model of affine parameters.
    pub fn model(&self, p: &AffineParams) -> Result<LinearGaussianModel, AffineEmError> {
        check_shapes(p, self.n, self.p, self.n)?;
        LinearGaussianModel::builder(
            p.beta_x.clone(),
            p.beta_y.clone(),
            p.pi_x.clone(),
            p.pi_y.clone(),
        )
        .mu(p.mu.clone())
        .p1(p.p1.clone())
        .build()
        .map_err(|e| AffineEmError::InvalidParams(e.to_string()))
    }
}

impl AffineModel for LinearAffine {
    type Smc = LinearGaussianSmc;

    fn state_dim(&self) -> usize {
        self.n
    }
    fn output_dim(&self) -> usize {
        self.p
    }
    fn regressor_dim(&self) -> usize {
        self.n
    }

    fn regressors(&self, _t: usize, x: &[f64], _u: &[f64], out: &mut [f64]) {
        out.copy_from_slice(x);
    }

    fn smc_model(&self, params: &AffineParams) -> Result<LinearGaussianSmc, AffineEmError> {
        LinearGaussianSmc::new(&self.model(params)?)
            .map_err(|e| AffineEmError::InvalidParams(e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The E-step reads the columns; they hold the same numbers as `regressors` path by
    /// path, bit for bit (the default transposition of the trait).
    #[test]
    fn nlbench_columns_are_the_transposed_regressors() {
        let states = [-3.2, -0.4, 0.0, 0.7, 1.9, 12.5, -25.0];
        let paths = states.len();
        for t in [0, 7, 999, 5000] {
            let mut columns = vec![f64::NAN; 4 * paths];
            NlbenchAffine.regressor_columns(t, &states, &[], &mut columns);
            for (k, &x) in states.iter().enumerate() {
                let mut alpha = [0.0; 4];
                NlbenchAffine.regressors(t, &[x], &[], &mut alpha);
                for (i, &a) in alpha.iter().enumerate() {
                    assert_eq!(columns[i * paths + k].to_bits(), a.to_bits(), "t {t}");
                }
            }
            assert_eq!(columns[2 * paths], (1.2 * (t as f64 + 1.0)).cos());
        }
    }
}
