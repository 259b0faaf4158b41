//! A parametrised family of state-space models: what the samplers move over.

use sysid_smc::{FilterModel, TransitionDensity};

use crate::{PmcmcError, Support};

/// A family of models `p_theta`, one per parameter vector `theta`.
///
/// The samplers know a family only through this trait: the parameter names (for
/// outputs), where each parameter lives (the random walks run on the unconstrained
/// scale of [`Support`]) and how to build the model. Building must be cheap: PMMH
/// builds a model per iteration.
pub trait ModelFamily: Sync {
    /// The model type the particle methods run.
    type Model: FilterModel + TransitionDensity + Sync;

    /// The parameter names, in order.
    fn parameter_names(&self) -> Vec<String>;

    /// The support of each parameter, in order.
    fn supports(&self) -> Vec<Support>;

    /// The model at `theta`, or why `theta` is not admissible. The samplers treat a
    /// refusal inside the chain as zero posterior density (the proposal is rejected)
    /// and at the start as an error.
    fn model(&self, theta: &[f64]) -> Result<Self::Model, String>;

    /// Number of parameters.
    fn dim(&self) -> usize {
        self.supports().len()
    }
}

/// The supports and the maps between `theta` and the unconstrained `z`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Transform {
    supports: Vec<Support>,
}

impl Transform {
    pub(crate) fn new(supports: Vec<Support>) -> Self {
        Transform { supports }
    }

    /// `z` of `theta`, or the index of a parameter outside its support.
    pub(crate) fn to_unconstrained(&self, theta: &[f64], z: &mut [f64]) -> Result<(), usize> {
        for (k, ((s, &v), zk)) in self
            .supports
            .iter()
            .zip(theta)
            .zip(z.iter_mut())
            .enumerate()
        {
            if !s.contains(v) {
                return Err(k);
            }
            *zk = s.to_unconstrained(v);
        }
        Ok(())
    }

    /// `theta` of `z`, returning `log |d theta / d z|`.
    pub(crate) fn to_constrained(&self, z: &[f64], theta: &mut [f64]) -> f64 {
        let mut log_jacobian = 0.0;
        for ((s, &zk), v) in self.supports.iter().zip(z).zip(theta.iter_mut()) {
            let (value, lj) = s.from_unconstrained(zk);
            *v = value;
            log_jacobian += lj;
        }
        log_jacobian
    }
}

/// Checks a starting point: length, support, and that the family builds a model.
pub(crate) fn check_start<F: ModelFamily>(
    family: &F,
    theta: &[f64],
) -> Result<F::Model, PmcmcError> {
    let names = family.parameter_names();
    if theta.len() != names.len() {
        return Err(PmcmcError::DimensionMismatch {
            what: "initial parameters",
            expected: names.len(),
            found: theta.len(),
        });
    }
    for ((name, s), &v) in names.iter().zip(family.supports()).zip(theta) {
        if !s.contains(v) {
            return Err(PmcmcError::InadmissibleStart {
                reason: format!("{name} = {v} is outside its support {s:?}"),
            });
        }
    }
    family
        .model(theta)
        .map_err(|reason| PmcmcError::InadmissibleStart { reason })
}
