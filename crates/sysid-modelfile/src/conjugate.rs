//! The exact Gibbs draw of an affine model file's parameters given the states, for
//! particle Gibbs.
//!
//! # Algorithm
//! Given a state trajectory, every equation of an affine model file
//! ([`ExprAffine`]) is a linear regression: state row `i` reads
//! `x_{i,t+1} = sum_c beta_{ic} alpha_c(x_t, u_t, t) + w_{i,t}`, output row `j`
//! `y_{j,t} = sum_c beta_{jc} alpha_c(x_t, u_t, t) + e_{j,t}`, with diagonal noise. With
//! normal priors on the free coefficients and inverse-gamma priors on the free noise
//! variances, a systematic-scan sweep draws, row by row, the row's free coefficients
//! from their Gaussian conditional (the held and fixed ones moved to the left-hand
//! side) and then its variance from its inverse-gamma conditional; missing outputs
//! drop out of their rows. The sweep leaves `p(theta | x, y)` invariant; with the
//! variances fixed it is an exact independent draw.
//!
//! # References
//! Gelman et al. (2013), *Bayesian Data Analysis*, 3rd ed., 14.8 (the normal linear
//! model with a known and an unknown variance); Lindsten, Jordan and Schön (2014).

use crate::affine::Slot;
use crate::{ExprAffine, ModelFile};
use nalgebra::{DMatrix, DVector};
use sysid_em::affine::AffineModel;
use sysid_pmcmc::conjugate::{gaussian_from_precision, inverse_gamma};
use sysid_pmcmc::{ParameterStep, ScalarPrior};
use sysid_smc::ModelError;
use sysid_smc::{Rng, Series};

/// The exact conditional draw of an affine model file's free parameters given the
/// states (see the module documentation): [`ParameterStep`] for [`ModelFile`].
///
/// # Example
/// ```
/// use sysid_modelfile::{AffineConjugate, ModelFile};
/// use sysid_pmcmc::{ParameterStep, ScalarPrior};
/// use sysid_smc::{Series, stream};
/// let file = ModelFile::parse(r#"
/// format = 1
/// states = ["x"]
/// outputs = ["y"]
/// [parameters]
/// a = { value = 0.5, prior = { family = "normal", mean = 0.0, sd = 1.0 } }
/// [transition]
/// x = "a*x"
/// [observation]
/// y = "x"
/// [noise]
/// x = 0.1
/// y = 0.1
/// [initial]
/// x = { mean = 0, variance = 1 }
/// "#, "ar1.toml").unwrap();
/// let priors = [ScalarPrior::Normal { mean: 0.0, sd: 1.0 }];
/// let mut step = AffineConjugate::new(&file, &priors).unwrap();
/// let states = [1.0, 0.9, 0.8, 0.75, 0.7];
/// let y = [1.1, 0.8, 0.9, 0.7, 0.6];
/// let mut theta = vec![0.0];
/// step.update(&file, &mut theta, &states, &Series::new(&y, 1).unwrap(), &mut stream(1, 0)).unwrap();
/// assert!(theta[0] > 0.0 && theta[0] < 1.5);
/// ```
#[derive(Debug, Clone)]
pub struct AffineConjugate {
    affine: ExprAffine,
    /// Per free parameter (in `theta`'s order): where it sits and its prior.
    free: Vec<(Slot, ScalarPrior)>,
}

impl AffineConjugate {
    /// The conjugate step of `file` with `priors` (one per free parameter, in order),
    /// or why there is none: a model that is not affine in its free parameters
    /// ([`ModelFile::why_not_affine`]), a free parameter that is neither a coefficient
    /// nor a whole noise variance, a coefficient without a normal prior, a variance
    /// without an inverse-gamma prior.
    pub fn new(file: &ModelFile, priors: &[ScalarPrior]) -> Result<AffineConjugate, ModelError> {
        let affine = file.affine().ok_or_else(|| {
            format!(
                "the model is not affine in its free parameters: {}",
                file.why_not_affine().unwrap_or_default()
            )
        })?;
        let spec = file.spec();
        let free_params = spec.free();
        if priors.len() != free_params.len() {
            return Err(format!(
                "{} priors for {} free parameters",
                priors.len(),
                free_params.len()
            )
            .into());
        }
        let mut free = Vec::with_capacity(priors.len());
        for (&k, prior) in free_params.iter().zip(priors) {
            let name = &spec.parameters[k].name;
            let slot = match *affine.slots(k) {
                [] => {
                    return Err(format!(
                        "{name} is neither a coefficient nor a whole noise variance"
                    )
                    .into());
                }
                [slot] => slot,
                _ => {
                    return Err(format!(
                        "{name} appears in {} equations: the conjugate step draws each \
                         coefficient of each equation on its own",
                        affine.slots(k).len()
                    )
                    .into());
                }
            };
            let coefficient = matches!(slot, Slot::StateCoef(..) | Slot::OutputCoef(..));
            if coefficient && spec.parameters[k].support != sysid_pmcmc::Support::Real {
                return Err(format!(
                    "{name} is a bounded coefficient: the conjugate step's normal draw \
                     ignores bounds"
                )
                .into());
            }
            match (coefficient, prior) {
                (true, ScalarPrior::Normal { .. }) | (false, ScalarPrior::InverseGamma { .. }) => {}
                (true, _) => {
                    return Err(format!(
                        "{name} is a coefficient: the conjugate step needs a normal prior"
                    )
                    .into());
                }
                (false, _) => {
                    return Err(format!(
                        "{name} is a noise variance: the conjugate step needs an \
                         inverse_gamma prior"
                    )
                    .into());
                }
            }
            free.push((slot, *prior));
        }
        Ok(AffineConjugate { affine, free })
    }

    /// Draws one row's free coefficients (`cols`, with their priors) given the others:
    /// the regression of `target_t - sum_{held} beta_c alpha_c(t)` on the free
    /// columns over the row's samples, noise variance `variance`.
    fn draw_row(
        beta: &mut DMatrix<f64>,
        row: usize,
        cols: &[(usize, ScalarPrior)],
        data: &RowData<'_>,
        variance: f64,
        rng: &mut Rng,
    ) -> Result<(), ModelError> {
        let RowData { alpha, r, samples } = *data;
        let k = cols.len();
        let free_col = |c: usize| cols.iter().any(|&(fc, _)| fc == c);
        let mut precision = DMatrix::zeros(k, k);
        let mut rhs = DVector::zeros(k);
        for (a, &(_, prior)) in cols.iter().enumerate() {
            let ScalarPrior::Normal { mean, sd } = prior else {
                return Err("a coefficient without a normal prior".into());
            };
            precision[(a, a)] = 1.0 / (sd * sd);
            rhs[a] = mean / (sd * sd);
        }
        let mut z = DVector::zeros(k);
        for &(t, target) in samples {
            let regressors = &alpha[t * r..(t + 1) * r];
            let known: f64 = (0..r)
                .filter(|&c| !free_col(c))
                .map(|c| beta[(row, c)] * regressors[c])
                .sum();
            for (a, &(c, _)) in cols.iter().enumerate() {
                z[a] = regressors[c];
            }
            precision += &z * z.transpose() / variance;
            rhs += &z * ((target - known) / variance);
        }
        let draw = gaussian_from_precision(precision, &rhs, &format!("row {}", row + 1), rng)?;
        for (a, &(c, _)) in cols.iter().enumerate() {
            beta[(row, c)] = draw[a];
        }
        Ok(())
    }

    /// Draws a row's noise variance from its inverse-gamma conditional.
    fn draw_variance(
        beta: &DMatrix<f64>,
        row: usize,
        prior: ScalarPrior,
        data: &RowData<'_>,
        rng: &mut Rng,
    ) -> Result<f64, ModelError> {
        let RowData { alpha, r, samples } = *data;
        let ScalarPrior::InverseGamma { shape, scale } = prior else {
            return Err("a noise variance without an inverse_gamma prior".into());
        };
        let squares: f64 = samples
            .iter()
            .map(|&(t, target)| {
                let fitted: f64 = (0..r).map(|c| beta[(row, c)] * alpha[t * r + c]).sum();
                (target - fitted).powi(2)
            })
            .sum();
        inverse_gamma(
            shape + 0.5 * samples.len() as f64,
            scale + 0.5 * squares,
            rng,
        )
    }
}

/// A state row or an output row.
#[derive(Clone, Copy)]
enum Which {
    State(usize),
    Output(usize),
}

impl Which {
    fn row(self) -> usize {
        match self {
            Which::State(i) | Which::Output(i) => i,
        }
    }

    /// The column of `slot` when it is a coefficient of this row.
    fn coefficient(self, slot: Slot) -> Option<usize> {
        match (self, slot) {
            (Which::State(i), Slot::StateCoef(r, c))
            | (Which::Output(i), Slot::OutputCoef(r, c))
                if r == i =>
            {
                Some(c)
            }
            _ => None,
        }
    }

    /// Whether `slot` is this row's noise variance.
    fn is_variance(self, slot: Slot) -> bool {
        matches!(
            (self, slot),
            (Which::State(i), Slot::ProcessVar(r)) | (Which::Output(i), Slot::MeasurementVar(r))
                if r == i
        )
    }
}

impl AffineConjugate {
    /// Draws a row's free coefficients, then its noise variance if it is free.
    fn sweep_row(
        &self,
        which: Which,
        beta: &mut DMatrix<f64>,
        pi: &mut DMatrix<f64>,
        data: &RowData<'_>,
        rng: &mut Rng,
    ) -> Result<(), ModelError> {
        let row = which.row();
        let cols: Vec<(usize, ScalarPrior)> = self
            .free
            .iter()
            .filter_map(|&(slot, prior)| which.coefficient(slot).map(|c| (c, prior)))
            .collect();
        if !cols.is_empty() {
            let v = pi[(row, row)];
            Self::draw_row(beta, row, &cols, data, v, rng)?;
        }
        let prior = self
            .free
            .iter()
            .find_map(|&(slot, prior)| which.is_variance(slot).then_some(prior));
        if let Some(prior) = prior {
            pi[(row, row)] = Self::draw_variance(beta, row, prior, data, rng)?;
        }
        Ok(())
    }
}

/// One row's regression data: the regressors of every step (`r` per step) and the
/// row's `(step, target)` samples.
#[derive(Clone, Copy)]
struct RowData<'a> {
    alpha: &'a [f64],
    r: usize,
    samples: &'a [(usize, f64)],
}

impl ParameterStep<ModelFile> for AffineConjugate {
    fn update(
        &mut self,
        _family: &ModelFile,
        theta: &mut [f64],
        trajectory: &[f64],
        data: &Series,
        rng: &mut Rng,
    ) -> Result<bool, ModelError> {
        let affine = &self.affine;
        let (n, p, r) = (
            affine.state_dim(),
            affine.output_dim(),
            affine.regressor_dim(),
        );
        let steps = trajectory.len() / n.max(1);
        if steps < 2 || steps > data.steps() {
            return Err(format!(
                "a trajectory of {steps} steps for {} observations",
                data.steps()
            )
            .into());
        }
        let mut params = affine.params(theta)?;
        let mut alpha = vec![0.0; steps * r];
        for t in 0..steps {
            affine.regressors(
                t,
                &trajectory[t * n..(t + 1) * n],
                data.input(t),
                &mut alpha[t * r..(t + 1) * r],
            );
        }
        for i in 0..n {
            let samples: Vec<(usize, f64)> = (0..steps - 1)
                .map(|t| (t, trajectory[(t + 1) * n + i]))
                .collect();
            let row = RowData {
                alpha: &alpha,
                r,
                samples: &samples,
            };
            let which = Which::State(i);
            self.sweep_row(which, &mut params.beta_x, &mut params.pi_x, &row, rng)?;
        }
        for j in 0..p {
            let samples: Vec<(usize, f64)> = (0..steps)
                .map(|t| (t, data.output(t)[j]))
                .filter(|(_, y)| !y.is_nan())
                .collect();
            let row = RowData {
                alpha: &alpha,
                r,
                samples: &samples,
            };
            let which = Which::Output(j);
            self.sweep_row(which, &mut params.beta_y, &mut params.pi_y, &row, rng)?;
        }
        theta.copy_from_slice(&affine.theta(&params));
        Ok(true)
    }
}
