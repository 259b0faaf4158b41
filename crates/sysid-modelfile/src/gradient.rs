//! Any model file in the form of gradient EM (`sysid_em::gradient`, seed 001): the
//! M-step maximises the particle approximation of `Q` by BFGS over the free
//! parameters on their unconstrained scale (`ln v` for a positive one, a logit for
//! one with bounds).
//!
//! # Algorithm
//! The three log-densities are those of [`ExprSmc`] at the parameters. Their gradients
//! are analytic: every expression is differentiated symbolically with respect to each
//! free parameter once ([`Expr::derivative`]), and each Gaussian term contributes
//! ```text
//! d log N(z; m, v) = (z - m)/v dm + ((z - m)^2/v^2 - 1/v)/2 dv
//! ```
//! times `d theta / d z` of the parameter's transform.

use crate::expr::{Expr, Var};
use crate::{ExprSmc, ModelFile};
use sysid_em::gradient::{GradientEmError, GradientModel, Gradients};
use sysid_pmcmc::{ModelFamily, Support};

/// `d e / d theta_j` for every free parameter `j` that `e` depends on.
type Partials = Vec<(usize, Expr)>;

fn partials(e: &Expr, free: &[usize]) -> Partials {
    free.iter()
        .enumerate()
        .filter_map(|(j, &k)| {
            let d = e.derivative(Var::Param(k));
            (d.node != crate::expr::Node::Num(0.0)).then_some((j, d))
        })
        .collect()
}

/// The partial derivatives of every expression of a model.
#[derive(Debug, Clone)]
struct Derivatives {
    transition: Vec<Partials>,
    observation: Vec<Partials>,
    process: Vec<Partials>,
    measurement: Vec<Partials>,
    initial_mean: Vec<Partials>,
    initial_variance: Vec<Partials>,
}

/// A model file for gradient EM (see the module documentation).
#[derive(Debug, Clone)]
pub struct ExprGradient {
    file: ModelFile,
    supports: Vec<Support>,
    derivatives: Derivatives,
}

/// The model at the parameters and `d theta_j / d z_j` of each free parameter.
#[derive(Debug, Clone)]
pub struct Unpacked {
    model: ExprSmc,
    jacobian: Vec<f64>,
}

/// Adds the gradient of `log N(z; m, v)` (with `dm`, `dv` the partials of the mean and
/// variance, evaluated by `eval`) into `grad`, scaled by the transform's jacobian.
#[allow(clippy::too_many_arguments)]
fn gaussian_gradient(
    z: f64,
    m: f64,
    v: f64,
    dm: &Partials,
    dv: &Partials,
    eval: &impl Fn(&Expr) -> f64,
    jacobian: &[f64],
    grad: &mut [f64],
) {
    let r = z - m;
    for (j, d) in dm {
        grad[*j] += r / v * eval(d) * jacobian[*j];
    }
    let w = 0.5 * (r * r / (v * v) - 1.0 / v);
    for (j, d) in dv {
        grad[*j] += w * eval(d) * jacobian[*j];
    }
}

impl ExprGradient {
    pub(crate) fn new(file: ModelFile) -> ExprGradient {
        let supports = file.supports();
        let spec = file.spec();
        let free = spec.free();
        let all = |es: &[Expr]| es.iter().map(|e| partials(e, &free)).collect();
        let derivatives = Derivatives {
            transition: all(&spec.transition),
            observation: all(&spec.observation),
            process: all(&spec.process_noise),
            measurement: all(&spec.measurement_noise),
            initial_mean: all(&spec.initial_mean),
            initial_variance: all(&spec.initial_variance),
        };
        ExprGradient {
            file,
            supports,
            derivatives,
        }
    }

    /// The unconstrained vector of the free parameters `values` (each inside its
    /// bounds).
    pub fn unconstrained(&self, values: &[f64]) -> Vec<f64> {
        self.supports
            .iter()
            .zip(values)
            .map(|(s, &v)| s.to_unconstrained(v))
            .collect()
    }

    /// The model file.
    pub fn file(&self) -> &ModelFile {
        &self.file
    }
}

impl GradientModel for ExprGradient {
    type Smc = ExprSmc;
    /// The model at the parameters, or `None` where they give an invalid law (a
    /// variance expression that is not positive): its densities are then `-inf`.
    type Params = Option<Unpacked>;

    fn parameter_dim(&self) -> usize {
        self.supports.len()
    }
    fn state_dim(&self) -> usize {
        self.file.spec().states.len()
    }
    fn parameter_names(&self) -> Vec<String> {
        self.file.free_names()
    }
    fn constrained(&self, theta: &[f64]) -> Vec<f64> {
        self.supports
            .iter()
            .zip(theta)
            .map(|(s, &z)| s.from_unconstrained(z).0)
            .collect()
    }
    fn smc_model(&self, theta: &[f64]) -> Result<ExprSmc, GradientEmError> {
        self.file
            .at(&self.constrained(theta))
            .map_err(|e| GradientEmError::InvalidParams(e.reason))
    }
    fn unpack(&self, theta: &[f64]) -> Option<Unpacked> {
        let model = self.file.at(&self.constrained(theta)).ok()?;
        let jacobian = self
            .supports
            .iter()
            .zip(theta)
            .map(|(s, &z)| s.from_unconstrained(z).1.exp())
            .collect();
        Some(Unpacked { model, jacobian })
    }
    fn gradients(&self) -> Gradients {
        Gradients::Analytic
    }

    fn log_initial(&self, p: &Option<Unpacked>, x: &[f64]) -> f64 {
        use sysid_smc::InitialDensity;
        p.as_ref()
            .map_or(f64::NEG_INFINITY, |p| p.model.log_initial(x))
    }
    fn log_transition(
        &self,
        p: &Option<Unpacked>,
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &[f64],
    ) -> f64 {
        use sysid_smc::TransitionDensity;
        p.as_ref()
            .map_or(f64::NEG_INFINITY, |p| p.model.log_transition(t, x, u, next))
    }
    fn log_observation(
        &self,
        p: &Option<Unpacked>,
        t: usize,
        x: &[f64],
        u: &[f64],
        y: &[f64],
    ) -> f64 {
        use sysid_smc::ObservationDensity;
        p.as_ref()
            .map_or(f64::NEG_INFINITY, |p| p.model.log_observation(t, x, u, y))
    }

    fn log_initial_gradient(&self, p: &Option<Unpacked>, x: &[f64], grad: &mut [f64]) -> f64 {
        let value = self.log_initial(p, x);
        let Some(p) = p else { return value };
        let (means, variances) = p.model.initial_law();
        let eval = |e: &Expr| p.model.eval(e, 0, &[], &[]);
        let d = &self.derivatives;
        for i in 0..x.len() {
            // a point mass (variance 0) has no gradient
            if variances[i] > 0.0 {
                gaussian_gradient(
                    x[i],
                    means[i],
                    variances[i],
                    &d.initial_mean[i],
                    &d.initial_variance[i],
                    &eval,
                    &p.jacobian,
                    grad,
                );
            }
        }
        value
    }

    fn log_transition_gradient(
        &self,
        p: &Option<Unpacked>,
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        let Some(p) = p else {
            return f64::NEG_INFINITY;
        };
        let d = &self.derivatives;
        let rows = Rows {
            means: &self.file.spec().transition,
            mean_partials: &d.transition,
            variance_partials: &d.process,
        };
        rows.log_density(p, (t, u, x), next, p.model.process_variances(), grad)
    }

    fn log_observation_gradient(
        &self,
        p: &Option<Unpacked>,
        t: usize,
        x: &[f64],
        u: &[f64],
        y: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        let Some(p) = p else {
            return f64::NEG_INFINITY;
        };
        let d = &self.derivatives;
        let rows = Rows {
            means: &self.file.spec().observation,
            mean_partials: &d.observation,
            variance_partials: &d.measurement,
        };
        rows.log_density(p, (t, u, x), y, p.model.measurement_variances(), grad)
    }
}

/// Independent Gaussian rows `z_i ~ N(m_i(x, u, t), v_i)`: the transition's or the
/// observation's, with the partials of their means and variances.
struct Rows<'a> {
    means: &'a [Expr],
    mean_partials: &'a [Partials],
    variance_partials: &'a [Partials],
}

impl Rows<'_> {
    /// `sum_i log N(z_i; m_i, v_i)` over the rows whose `z_i` is observed (not NaN),
    /// adding its gradient into `grad`.
    fn log_density(
        &self,
        p: &Unpacked,
        (t, u, x): (usize, &[f64], &[f64]),
        z: &[f64],
        variances: impl Iterator<Item = f64>,
        grad: &mut [f64],
    ) -> f64 {
        let eval = |e: &Expr| p.model.eval(e, t, u, x);
        let mut value = 0.0;
        for (i, (mean, v)) in self.means.iter().zip(variances).enumerate() {
            if z[i].is_nan() {
                continue;
            }
            let m = eval(mean);
            value += log_normal(z[i], m, v);
            gaussian_gradient(
                z[i],
                m,
                v,
                &self.mean_partials[i],
                &self.variance_partials[i],
                &eval,
                &p.jacobian,
                grad,
            );
        }
        value
    }
}

/// `log N(z; m, v)`.
fn log_normal(z: f64, m: f64, v: f64) -> f64 {
    let r = z - m;
    -0.5 * (sysid_linalg::LN_2PI + v.ln()) - 0.5 * r * r / v
}
