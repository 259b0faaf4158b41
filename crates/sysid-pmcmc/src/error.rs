//! The error type of `sysid-pmcmc`.

use sysid_smc::SmcError;

/// Errors of the samplers. Each variant names the place.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PmcmcError {
    /// An option is out of range.
    #[error("invalid option `{name}`: {reason}")]
    InvalidOption {
        /// The option's name.
        name: &'static str,
        /// What is wrong with its value.
        reason: String,
    },
    /// A prior's hyperparameters are invalid.
    #[error("prior of `{parameter}`: {reason}")]
    InvalidPrior {
        /// The parameter the prior belongs to.
        parameter: String,
        /// What is wrong.
        reason: String,
    },
    /// A parameter vector has the wrong length.
    #[error("{what}: expected {expected} values, found {found}")]
    DimensionMismatch {
        /// Which vector.
        what: &'static str,
        /// The expected length.
        expected: usize,
        /// The length found.
        found: usize,
    },
    /// The starting point has zero posterior density (outside the support, zero
    /// prior density, or a model the family rejects).
    #[error("the initial parameters are not admissible: {reason}")]
    InadmissibleStart {
        /// Why.
        reason: String,
    },
    /// A particle method failed inside iteration `iteration` of chain `chain`.
    #[error("chain {chain}, iteration {iteration}: {source}")]
    Smc {
        /// Chain index.
        chain: usize,
        /// Iteration index (0-based).
        iteration: usize,
        /// The particle method's error.
        source: SmcError,
    },
    /// A parameter step (for example a conjugate draw) failed.
    #[error("chain {chain}, iteration {iteration}: parameter step failed: {reason}")]
    ParameterStep {
        /// Chain index.
        chain: usize,
        /// Iteration index (0-based).
        iteration: usize,
        /// Why.
        reason: String,
    },
}
