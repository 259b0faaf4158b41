//! Nonlinear state-space models from a model file (`docs/model-format.md`): one
//! definition that the particle filters and smoothers, particle EM (closed form when
//! the equations are affine in the free parameters), gradient EM and PMMH all use. For
//! a model the file format cannot express, [`GaussianModel`] is the same in Rust: one
//! impl of the mean maps, the noise variances and the initial law.
//!
//! # Model
//! ```text
//! x_{t+1,i} = f_i(x_t, u_t, t; theta) + w_{t,i},   w_{t,i} ~ N(0, q_i(theta))
//! y_{t,j}   = g_j(x_t, u_t, t; theta) + e_{t,j},   e_{t,j} ~ N(0, r_j(theta))
//! x_{0,i}   ~ N(m_i(theta), p_i(theta))
//! ```
//! every noise term independent; `f`, `g`, `q`, `r`, `m`, `p` are expressions in the
//! states, inputs, the 0-based time `t` and named parameters, each free (estimated,
//! with bounds) or fixed.
//!
//! # Algorithm
//! The file is parsed and checked once ([`ModelSpec::parse`]: unknown names, syntax,
//! arity, unused parameters, divisions by a parameter that may be 0, non-finite
//! values at the start; each error gives the line and column). The equations are
//! compiled into straight-line programs evaluated over all particles at once
//! ([`program`]), so a bootstrap filter on a model file runs close to a hand-written
//! model. [`ModelFile::affine`] recognises equations affine in the free parameters and
//! then gives the closed-form particle EM of `sysid_em::affine`; every model also has
//! the gradient-EM form ([`ModelFile::gradient`]) and is a PMMH family
//! ([`ModelFile`] implements `ModelFamily`).
//!
//! # Example
//! ```
//! use sysid_modelfile::ModelFile;
//! use sysid_smc::{FilterOptions, ParticleFilter, Series};
//!
//! let model = ModelFile::parse(r#"
//! format = 1
//! states = ["x"]
//! outputs = ["y"]
//! [parameters]
//! a = { value = 0.8 }
//! q = { value = 0.5 }
//! [transition]
//! x = "a*x + sin(x)"
//! [observation]
//! y = "x"
//! [noise]
//! x = "q"
//! y = 0.1
//! [initial]
//! x = { mean = 0, variance = 1 }
//! "#, "example.toml")?;
//! assert_eq!(model.free_names(), ["a", "q"]);
//! assert!(model.affine().is_some()); // a enters linearly: closed-form particle EM
//!
//! let smc = model.at(&model.free_values())?;
//! let y = [0.3, -0.1, 0.4, 0.2];
//! let mut pf = ParticleFilter::new(FilterOptions { particles: 500, ..Default::default() })?;
//! let loglik = pf.run(&smc, &Series::new(&y, 1)?, 7)?.loglik;
//! assert!(loglik.is_finite());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Complexity
//! Per particle and step, one pass of each compiled instruction; parsing is linear in
//! the file.

pub mod affine;
pub mod builtin;
pub mod conjugate;
mod direct;
pub mod expr;
mod fit;
mod fit_method;
pub mod gaussian;
pub mod gradient;
pub mod output_error;
pub mod prediction;
pub mod program;
mod shared;
pub mod simulation;
mod smc;
pub mod spec;
mod write;

pub use affine::ExprAffine;
pub use conjugate::AffineConjugate;
pub use fit::{FileFit, FileFitError, FileFitReport, FileFitWarning};
pub use fit_method::{
    Criterion, DirectFitOptions, FileFitMethod, GradientFitOptions, fit_defaults,
};
pub use gaussian::{Gaussian, GaussianModel, GaussianSmc};
pub use gradient::ExprGradient;
pub use output_error::{
    InitialState, Inseparable, SimulationComparison, SimulationFit, SimulationFitOptions,
    SimulationStart,
};
pub use prediction::{ParticlePredictions, PredictionError};
pub use simulation::{NoiseFree, SimulationError, Simulator};
pub use smc::ExprSmc;
pub use spec::{FORMAT, ModelFileError, ModelSpec, Parameter};

use smc::Compiled;
use std::sync::Arc;
use sysid_pmcmc::{ModelFamily, ScalarPrior, Support};
use sysid_smc::ModelError;

/// A checked, compiled model file; the family of models over its free parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelFile {
    compiled: Arc<Compiled>,
    origin: String,
}

impl ModelFile {
    /// Parses and checks a model file's text; `origin` names it in errors.
    ///
    /// # Errors
    /// The first problem, with line and column ([`ModelFileError`]).
    pub fn parse(text: &str, origin: &str) -> Result<ModelFile, ModelFileError> {
        let spec = ModelSpec::parse(text, origin)?;
        Ok(ModelFile {
            compiled: Arc::new(Compiled::new(spec)),
            origin: origin.to_string(),
        })
    }

    /// A model from a checked spec (a spec this crate changed, never a user's).
    pub(crate) fn from_spec(spec: ModelSpec, origin: &str) -> ModelFile {
        ModelFile {
            compiled: Arc::new(Compiled::new(spec)),
            origin: origin.to_string(),
        }
    }

    /// Reads and checks the model file at `path`.
    ///
    /// # Errors
    /// The file cannot be read (line 1, column 1, the I/O error), or it is malformed.
    pub fn read(path: &std::path::Path) -> Result<ModelFile, ModelFileError> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| ModelFileError {
            origin: origin.clone(),
            line: 1,
            column: 1,
            message: format!("cannot read the model file: {e}"),
        })?;
        ModelFile::parse(&text, &origin)
    }

    /// The checked spec.
    pub fn spec(&self) -> &ModelSpec {
        &self.compiled.spec
    }

    /// The file (or built-in) this model came from.
    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// Names of the free parameters, in the file's order.
    pub fn free_names(&self) -> Vec<String> {
        let spec = self.spec();
        spec.free()
            .into_iter()
            .map(|k| spec.parameters[k].name.clone())
            .collect()
    }

    /// The free parameters' values in the file.
    pub fn free_values(&self) -> Vec<f64> {
        let spec = self.spec();
        spec.free()
            .into_iter()
            .map(|k| spec.parameters[k].value)
            .collect()
    }

    /// Every parameter's value with the free ones set to `theta`.
    pub fn full_values(&self, theta: &[f64]) -> Vec<f64> {
        let spec = self.spec();
        let mut values: Vec<f64> = spec.parameters.iter().map(|p| p.value).collect();
        for (k, &v) in spec.free().into_iter().zip(theta) {
            values[k] = v;
        }
        values
    }

    /// The model at the free parameters `theta`.
    ///
    /// # Errors
    /// `theta` of the wrong length, outside a bound, or giving a non-positive noise
    /// variance (the message names the parameter or variance).
    pub fn at(&self, theta: &[f64]) -> Result<ExprSmc, ModelError> {
        let names = self.free_names();
        if theta.len() != names.len() {
            return Err(format!(
                "{} free parameters given, the model has {} ({})",
                theta.len(),
                names.len(),
                names.join(", ")
            )
            .into());
        }
        for ((name, &v), k) in names.iter().zip(theta).zip(self.spec().free()) {
            let support = self.spec().parameters[k].support;
            if !support.contains(v) {
                return Err(format!(
                    "{name} = {v} is outside its bounds ({})",
                    spec::describe_support(support)
                )
                .into());
            }
        }
        ExprSmc::new(self.compiled.clone(), self.full_values(theta))
    }

    /// The same model with the free parameters' values replaced by `theta` (the
    /// estimate of a fit, to be written back).
    pub fn with_values(&self, theta: &[f64]) -> ModelFile {
        let mut spec = self.spec().clone();
        for (k, &v) in spec.free().into_iter().zip(theta) {
            spec.parameters[k].value = v;
        }
        ModelFile {
            compiled: Arc::new(Compiled::new(spec)),
            origin: self.origin.clone(),
        }
    }

    /// The model file's text (format [`FORMAT`]); `metadata` lines (TOML `key = value`)
    /// are written in a `[metadata]` table. Reading it back gives the same model.
    pub fn to_toml(&self, metadata: &[(String, String)]) -> String {
        write::to_toml(self.spec(), metadata)
    }

    /// The priors the file gives, by free parameter (`None` where it gives none).
    pub fn priors(&self) -> Vec<Option<ScalarPrior>> {
        let spec = self.spec();
        spec.free()
            .into_iter()
            .map(|k| spec.parameters[k].prior)
            .collect()
    }

    /// The closed-form particle-EM form, when the equations are affine in the free
    /// parameters ([`ExprAffine`] says what qualifies); `None` otherwise.
    pub fn affine(&self) -> Option<ExprAffine> {
        ExprAffine::new(self.clone()).ok()
    }

    /// Why the model has no closed-form particle-EM form (`None` when it has one).
    pub fn why_not_affine(&self) -> Option<String> {
        ExprAffine::new(self.clone()).err().map(|e| e.reason)
    }

    /// The gradient-EM form (every model has one).
    pub fn gradient(&self) -> ExprGradient {
        ExprGradient::new(self.clone())
    }

    pub(crate) fn compiled(&self) -> &Arc<Compiled> {
        &self.compiled
    }
}

impl ModelFamily for ModelFile {
    type Model = ExprSmc;

    fn parameter_names(&self) -> Vec<String> {
        self.free_names()
    }

    fn supports(&self) -> Vec<Support> {
        let spec = self.spec();
        spec.free()
            .into_iter()
            .map(|k| spec.parameters[k].support)
            .collect()
    }

    fn model(&self, theta: &[f64]) -> Result<ExprSmc, ModelError> {
        self.at(theta)
    }
}
