//! The canonical systems as parametrised families for the Bayesian samplers of
//! `sysid-pmcmc`, with exact conjugate parameter steps for `lgss` and `nlbench`.

use rand::RngExt;
use rand_distr::{Distribution, Normal, StandardNormal};
use sysid_kalman::{KalmanWorkspace, LinearGaussianModel, Record};
use sysid_pmcmc::conjugate::{gaussian_from_precision, inverse_gamma};
use sysid_pmcmc::{ModelFamily, ParameterStep, Prior, ScalarPrior, Support};
use sysid_smc::ModelError;
use sysid_smc::{Rng, Series, stream};

use crate::{LinearGaussianSmc, Nlbench, NlbenchParams};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3, dmatrix};

/// The scalar linear Gaussian family with `theta = (phi, q, r)`.
///
/// # Model
/// ```text
/// x_{t+1} = phi x_t + w_t,  w_t ~ N(0, q)
/// y_t     = x_t + e_t,      e_t ~ N(0, r),     x_0 ~ N(0, p1)
/// ```
/// `phi` is real (no stationarity constraint), `q, r > 0`; `p1` is fixed (1 in
/// [`lgss`](crate::lgss)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LgssFamily {
    /// Variance of the initial state.
    pub p1: f64,
}

impl Default for LgssFamily {
    fn default() -> Self {
        LgssFamily { p1: 1.0 }
    }
}

impl LgssFamily {
    /// The default priors of `(phi, q, r)`: `N(0, 1)`, `IG(2, 1)`, `IG(2, 0.5)`
    /// (conjugate, so [`LgssConjugate`] applies).
    pub const DEFAULT_PRIORS: [ScalarPrior; 3] = [
        ScalarPrior::Normal { mean: 0.0, sd: 1.0 },
        ScalarPrior::InverseGamma {
            shape: 2.0,
            scale: 1.0,
        },
        ScalarPrior::InverseGamma {
            shape: 2.0,
            scale: 0.5,
        },
    ];

    /// The posterior draws (after `burn_in`) of an exact-likelihood random-walk
    /// Metropolis chain on `(phi, ln q, ln r)` (steps 0.05, 0.35, 0.35) from `start`:
    /// the Kalman filter's log-likelihood replaces the particle estimate. The reference
    /// for the particle samplers. Returns one vector of draws per parameter.
    pub fn exact_posterior_draws<P: Prior>(
        &self,
        prior: &P,
        record: &Record,
        start: [f64; 3],
        iterations: usize,
        burn_in: usize,
        seed: u64,
    ) -> Result<Vec<Vec<f64>>, ModelError> {
        let mut ws = KalmanWorkspace::new();
        let mut log_target = |z: &[f64; 3]| -> Result<f64, ModelError> {
            let theta = [z[0], z[1].exp(), z[2].exp()];
            let model = self.linear_model(&theta)?;
            let loglik = ws
                .loglik(&model, record)
                .map_err(|e| ModelError::new(e.to_string()))?;
            Ok(loglik + prior.log_density(&theta) + z[1] + z[2])
        };
        let mut rng = stream(seed, 0);
        let mut z = [start[0], start[1].ln(), start[2].ln()];
        let mut current = log_target(&z)?;
        let steps = [0.05, 0.35, 0.35];
        let mut draws: Vec<Vec<f64>> = (0..3)
            .map(|_| Vec::with_capacity(iterations.saturating_sub(burn_in)))
            .collect();
        for i in 0..iterations {
            let mut proposal = z;
            for (p, s) in proposal.iter_mut().zip(steps) {
                let e: f64 = StandardNormal.sample(&mut rng);
                *p += s * e;
            }
            let candidate = log_target(&proposal)?;
            if rng.random::<f64>().ln() < candidate - current {
                (z, current) = (proposal, candidate);
            }
            if i >= burn_in {
                for (d, v) in draws.iter_mut().zip([z[0], z[1].exp(), z[2].exp()]) {
                    d.push(v);
                }
            }
        }
        Ok(draws)
    }

    /// The linear Gaussian model at `theta` (for the Kalman filter's exact likelihood).
    pub fn linear_model(&self, theta: &[f64]) -> Result<LinearGaussianModel, ModelError> {
        let [phi, q, r] = theta else {
            return Err(format!("lgss has 3 parameters (phi, q, r), got {}", theta.len()).into());
        };
        LinearGaussianModel::builder(dmatrix![*phi], dmatrix![1.0], dmatrix![*q], dmatrix![*r])
            .p1(dmatrix![self.p1])
            .build()
            .map_err(|e| ModelError::new(e.to_string()))
    }
}

impl ModelFamily for LgssFamily {
    type Model = LinearGaussianSmc;

    fn parameter_names(&self) -> Vec<String> {
        ["phi", "q", "r"].map(String::from).to_vec()
    }

    fn supports(&self) -> Vec<Support> {
        vec![Support::Real, Support::Positive, Support::Positive]
    }

    fn model(&self, theta: &[f64]) -> Result<LinearGaussianSmc, ModelError> {
        LinearGaussianSmc::new(&self.linear_model(theta)?)
            .map_err(|e| ModelError::new(e.to_string()))
    }
}

/// The exact Gibbs draw of `(phi, q, r)` given the states for [`LgssFamily`], under
/// the conjugate priors `phi ~ N(m, s^2)`, `q ~ IG(a_q, b_q)`, `r ~ IG(a_r, b_r)`.
///
/// # Algorithm
/// In turn (a systematic-scan Gibbs sweep, which leaves `p(theta | x, y)` invariant):
/// ```text
/// phi | x, q ~ N(v (m / s^2 + sum x_t x_{t+1} / q), v),  1/v = 1/s^2 + sum x_t^2 / q
/// q | x, phi ~ IG(a_q + (T-1)/2, b_q + sum (x_{t+1} - phi x_t)^2 / 2)
/// r | x, y   ~ IG(a_r + T_obs/2, b_r + sum_observed (y_t - x_t)^2 / 2)
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LgssConjugate {
    /// Prior of `phi` (must be `Normal`).
    pub phi: ScalarPrior,
    /// Prior of `q` (must be `InverseGamma`).
    pub q: ScalarPrior,
    /// Prior of `r` (must be `InverseGamma`).
    pub r: ScalarPrior,
}

impl LgssConjugate {
    /// The conjugate step for priors `[phi, q, r]`, or why they are not conjugate
    /// (phi must be normal, q and r inverse gamma).
    pub fn from_priors(priors: &[ScalarPrior]) -> Result<Self, ModelError> {
        match priors {
            [
                phi @ ScalarPrior::Normal { .. },
                q @ ScalarPrior::InverseGamma { .. },
                r @ ScalarPrior::InverseGamma { .. },
            ] => Ok(LgssConjugate {
                phi: *phi,
                q: *q,
                r: *r,
            }),
            _ => Err(
                "the conjugate lgss step needs phi ~ normal and q, r ~ inverse_gamma priors".into(),
            ),
        }
    }
}

impl ParameterStep<LgssFamily> for LgssConjugate {
    fn update(
        &mut self,
        _family: &LgssFamily,
        theta: &mut [f64],
        x: &[f64],
        data: &Series,
        rng: &mut Rng,
    ) -> Result<bool, ModelError> {
        let (
            ScalarPrior::Normal { mean: m, sd: s },
            ScalarPrior::InverseGamma {
                shape: aq,
                scale: bq,
            },
            ScalarPrior::InverseGamma {
                shape: ar,
                scale: br,
            },
        ) = (self.phi, self.q, self.r)
        else {
            return Err(
                "the conjugate lgss step needs phi ~ normal, q and r ~ inverse_gamma".into(),
            );
        };
        let pairs = || x.iter().zip(&x[1..]);
        let q = theta[1];
        let precision = 1.0 / (s * s) + pairs().map(|(a, _)| a * a).sum::<f64>() / q;
        let variance = 1.0 / precision;
        let mean = variance * (m / (s * s) + pairs().map(|(a, b)| a * b).sum::<f64>() / q);
        let phi = Normal::new(mean, variance.sqrt())
            .map_err(|e| ModelError::new(e.to_string()))?
            .sample(rng);
        let sq: f64 = pairs().map(|(a, b)| (b - phi * a).powi(2)).sum();
        let q = inverse_gamma(aq + 0.5 * (x.len() - 1) as f64, bq + 0.5 * sq, rng)?;
        let (count, sr) = x
            .iter()
            .enumerate()
            .filter(|&(t, _)| !data.is_missing(t))
            .fold((0usize, 0.0), |(c, s), (t, &xt)| {
                (c + 1, s + (data.output(t)[0] - xt).powi(2))
            });
        let r = inverse_gamma(ar + 0.5 * count as f64, br + 0.5 * sr, rng)?;
        theta.copy_from_slice(&[phi, q, r]);
        Ok(true)
    }
}

/// The nonlinear benchmark [`Nlbench`] as a family: `theta = (a, b, c, d)` with the
/// noise variances fixed, or `(a, b, c, d, q, r)` with `estimate_noise`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NlbenchFamily {
    /// The fixed values (`q`, `r`, `mu`, `p1`, and `a..d` are ignored).
    pub fixed: NlbenchParams,
    /// Whether `q` and `r` are parameters.
    pub estimate_noise: bool,
}

impl Default for NlbenchFamily {
    fn default() -> Self {
        NlbenchFamily {
            fixed: NlbenchParams::TRUE,
            estimate_noise: false,
        }
    }
}

impl NlbenchFamily {
    /// The true parameter vector of this family.
    pub fn truth(&self) -> Vec<f64> {
        let p = NlbenchParams::TRUE;
        let mut theta = vec![p.a, p.b, p.c, p.d];
        if self.estimate_noise {
            theta.extend([p.q, p.r]);
        }
        theta
    }
}

impl ModelFamily for NlbenchFamily {
    type Model = Nlbench;

    fn parameter_names(&self) -> Vec<String> {
        let names: &[&str] = if self.estimate_noise {
            &["a", "b", "c", "d", "q", "r"]
        } else {
            &["a", "b", "c", "d"]
        };
        names.iter().map(|s| s.to_string()).collect()
    }

    fn supports(&self) -> Vec<Support> {
        let mut s = vec![Support::Real; 4];
        if self.estimate_noise {
            s.extend([Support::Positive, Support::Positive]);
        }
        s
    }

    fn model(&self, theta: &[f64]) -> Result<Nlbench, ModelError> {
        let expected = self.dim();
        if theta.len() != expected {
            return Err(format!("nlbench has {expected} parameters, got {}", theta.len()).into());
        }
        let mut p = self.fixed;
        (p.a, p.b, p.c, p.d) = (theta[0], theta[1], theta[2], theta[3]);
        if self.estimate_noise {
            (p.q, p.r) = (theta[4], theta[5]);
        }
        Nlbench::new(p)
    }
}

/// The exact Gibbs draw of the parameters given the states for [`NlbenchFamily`], under
/// conjugate priors: `a, b, c, d` normal, and (with `estimate_noise`) `q, r` inverse
/// gamma.
///
/// # Algorithm
/// Given the states, the transition is a linear regression of `x_{t+1}` on
/// `z_t = [x_t, x_t / (1 + x_t^2), cos(1.2 (t + 1))]` and the observation one of `y_t`
/// on `x_t^2`. In turn (a systematic-scan Gibbs sweep, which leaves
/// `p(theta | x, y)` invariant):
/// ```text
/// (a, b, c) | x, q ~ N(P^{-1} (S0^{-1} m0 + sum z_t x_{t+1} / q), P^{-1}),
///                     P = S0^{-1} + sum z_t z_t' / q
/// q | x, a, b, c   ~ IG(a_q + (T-1)/2, b_q + sum (x_{t+1} - z_t'(a, b, c))^2 / 2)
/// d | x, y, r      ~ N((m_d / s_d^2 + sum y_t x_t^2 / r) / p, 1 / p),
///                     p = 1 / s_d^2 + sum x_t^4 / r   (observed t)
/// r | x, y, d      ~ IG(a_r + T_obs / 2, b_r + sum (y_t - d x_t^2)^2 / 2)
/// ```
/// With the noise variances fixed the sweep draws `theta` exactly from its conditional
/// (independent draws given the states), where a random-walk step is rejected almost
/// always: with 1000 states the conditional of `b` has a standard deviation near 0.1.
///
/// # Example
/// ```
/// use sysid_models::{NlbenchConjugate, NlbenchFamily, Nlbench, NlbenchParams};
/// use sysid_pmcmc::{ParameterStep, ScalarPrior};
/// use sysid_smc::{Series, stream};
/// let family = NlbenchFamily::default();
/// let sim = Nlbench::new(NlbenchParams::TRUE).unwrap().simulate(500, 3);
/// let data = Series::new(&sim.outputs, 1).unwrap();
/// let normal = |sd| ScalarPrior::Normal { mean: 0.0, sd };
/// let mut step = NlbenchConjugate::from_priors(&family, &[normal(10.0), normal(100.0), normal(100.0), normal(10.0)]).unwrap();
/// let mut theta = vec![1.0, 1.0, 1.0, 1.0];
/// step.update(&family, &mut theta, &sim.states, &data, &mut stream(1, 0)).unwrap();
/// assert!((theta[1] - 25.0).abs() < 2.0); // b, from one draw given the true states
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct NlbenchConjugate {
    /// `(mean, sd)` of the normal priors of `a, b, c, d`.
    normal: [(f64, f64); 4],
    /// `(shape, scale)` of the inverse-gamma priors of `q, r` (with `estimate_noise`).
    inverse_gamma: Option<[(f64, f64); 2]>,
}

impl NlbenchConjugate {
    /// The conjugate step for `family`'s priors (`a, b, c, d` normal, then `q, r`
    /// inverse gamma with `estimate_noise`), or why they are not conjugate.
    pub fn from_priors(family: &NlbenchFamily, priors: &[ScalarPrior]) -> Result<Self, ModelError> {
        let refused = || -> ModelError {
            format!(
                "the conjugate nlbench step needs a, b, c, d ~ normal{} priors",
                if family.estimate_noise {
                    " and q, r ~ inverse_gamma"
                } else {
                    ""
                }
            )
            .into()
        };
        if priors.len() != family.dim() {
            return Err(refused());
        }
        let mut normal = [(0.0, 1.0); 4];
        for (slot, prior) in normal.iter_mut().zip(priors) {
            let ScalarPrior::Normal { mean, sd } = *prior else {
                return Err(refused());
            };
            *slot = (mean, sd);
        }
        let inverse_gamma = match &priors[4..] {
            [] => None,
            [
                ScalarPrior::InverseGamma {
                    shape: aq,
                    scale: bq,
                },
                ScalarPrior::InverseGamma {
                    shape: ar,
                    scale: br,
                },
            ] => Some([(*aq, *bq), (*ar, *br)]),
            _ => return Err(refused()),
        };
        Ok(NlbenchConjugate {
            normal,
            inverse_gamma,
        })
    }
}

impl ParameterStep<NlbenchFamily> for NlbenchConjugate {
    fn update(
        &mut self,
        family: &NlbenchFamily,
        theta: &mut [f64],
        x: &[f64],
        data: &Series,
        rng: &mut Rng,
    ) -> Result<bool, ModelError> {
        if theta.len() != family.dim() || x.len() < 2 {
            return Err(format!(
                "nlbench: {} parameters and {} states (expected {} and at least 2)",
                theta.len(),
                x.len(),
                family.dim()
            )
            .into());
        }
        let noise = self.inverse_gamma.filter(|_| family.estimate_noise);
        let (q, r) = if family.estimate_noise {
            (theta[4], theta[5])
        } else {
            (family.fixed.q, family.fixed.r)
        };
        let regressors = |t: usize| {
            let xt = x[t];
            Vector3::new(xt, xt / (1.0 + xt * xt), (1.2 * (t + 1) as f64).cos())
        };
        // (a, b, c) | x, q
        let mut precision = Matrix3::zeros();
        let mut rhs = Vector3::zeros();
        for k in 0..3 {
            let (m, s) = self.normal[k];
            precision[(k, k)] = 1.0 / (s * s);
            rhs[k] = m / (s * s);
        }
        let mut gram = Matrix3::zeros();
        let mut cross = Vector3::zeros();
        for t in 0..x.len() - 1 {
            let z = regressors(t);
            gram += z * z.transpose();
            cross += z * x[t + 1];
        }
        let precision = precision + gram / q;
        let abc = gaussian_from_precision(
            DMatrix::from_column_slice(3, 3, precision.as_slice()),
            &DVector::from_column_slice((rhs + cross / q).as_slice()),
            "(a, b, c)",
            rng,
        )?;
        let abc = Vector3::new(abc[0], abc[1], abc[2]);
        theta[..3].copy_from_slice(abc.as_slice());
        if let Some([(aq, bq), _]) = noise {
            let sq: f64 = (0..x.len() - 1)
                .map(|t| (x[t + 1] - regressors(t).dot(&abc)).powi(2))
                .sum();
            theta[4] = inverse_gamma(aq + 0.5 * (x.len() - 1) as f64, bq + 0.5 * sq, rng)?;
        }
        // d | x, y, r
        let observed = || {
            (0..x.len())
                .filter(|&t| !data.is_missing(t))
                .map(|t| (x[t] * x[t], data.output(t)[0]))
        };
        let (md, sd) = self.normal[3];
        let p = 1.0 / (sd * sd) + observed().map(|(s, _)| s * s).sum::<f64>() / r;
        let mean = (md / (sd * sd) + observed().map(|(s, y)| s * y).sum::<f64>() / r) / p;
        let eps: f64 = StandardNormal.sample(rng);
        theta[3] = mean + eps / p.sqrt();
        if let Some([_, (ar, br)]) = noise {
            let (count, sr) = observed().fold((0usize, 0.0), |(c, s), (sq, y)| {
                (c + 1, s + (y - theta[3] * sq).powi(2))
            });
            theta[5] = inverse_gamma(ar + 0.5 * count as f64, br + 0.5 * sr, rng)?;
        }
        Ok(true)
    }
}
