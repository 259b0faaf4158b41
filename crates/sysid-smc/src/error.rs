//! The error type of `sysid-smc`.

/// Errors of the particle filters and smoothers. Each variant names the place.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SmcError {
    /// An option is out of range (zero particles, an ESS threshold outside (0, 1], ...).
    #[error("invalid option `{name}`: {reason}")]
    InvalidOption {
        /// The option's name.
        name: &'static str,
        /// What is wrong with its value.
        reason: String,
    },
    /// A data array has a length that does not fit the stated dimensions.
    #[error("{what}: length {found} does not fit {expected}")]
    DimensionMismatch {
        /// Which array.
        what: &'static str,
        /// What was expected, in words.
        expected: String,
        /// The length found.
        found: usize,
    },
    /// An input, or an output other than a NaN (missing) entry, is not finite.
    #[error("{what} at time {t}, entry {index}: value {value} is not allowed")]
    NonFiniteData {
        /// `"input"` or `"output"`.
        what: &'static str,
        /// Time index (0-based).
        t: usize,
        /// Entry within the vector at time `t`.
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// Every particle has zero weight: the observation at `t` is impossible under the
    /// model (or far in the tails of every particle).
    #[error(
        "degenerate particle weights at time {t}: every particle gives the observation zero density"
    )]
    DegenerateWeights {
        /// Time index (0-based).
        t: usize,
    },
    /// The model returned a NaN or +inf density.
    #[error("the model's {what} is {value} at time {t}, particle {particle}")]
    InvalidDensity {
        /// Which density.
        what: &'static str,
        /// Time index (0-based).
        t: usize,
        /// Particle index.
        particle: usize,
        /// The value returned.
        value: f64,
    },
    /// A backward draw found every particle unable to reach the next smoothed state.
    #[error(
        "backward smoothing at time {t}: no filter particle can reach the next state of path {path}"
    )]
    DegenerateBackward {
        /// Time index (0-based).
        t: usize,
        /// Path index.
        path: usize,
    },
    /// The model's transition density exceeded its stated bound (rejection FFBSi).
    #[error("transition log-density {log_density} exceeds the bound {log_bound} at time {t}")]
    BoundViolated {
        /// Time index (0-based).
        t: usize,
        /// The density found.
        log_density: f64,
        /// The bound stated by the model.
        log_bound: f64,
    },
    /// A smoother needs the filter's stored history, which was not kept.
    #[error("the smoother needs the filter history: run the filter with `store_history`")]
    MissingHistory,
    /// The history was made from other data than the smoother is given.
    #[error("the history holds {history} steps but the data hold {data}")]
    HistoryMismatch {
        /// Steps in the history.
        history: usize,
        /// Steps in the data.
        data: usize,
    },
}

/// Why a model cannot be built or used at the parameters given: a variance that is not
/// positive, a value outside the model's domain, a draw that failed. A model family
/// ([`sysid_pmcmc`'s `ModelFamily`], a model file) returns it for a parameter vector it
/// does not admit; the samplers treat it inside a chain as zero posterior density.
///
/// The reason is the family's own words, shown to the user as written.
///
/// [`sysid_pmcmc`'s `ModelFamily`]: https://docs.rs/sysid-pmcmc
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{reason}")]
pub struct ModelError {
    /// What is wrong, in words.
    pub reason: String,
}

impl ModelError {
    /// The error with this reason.
    pub fn new(reason: impl Into<String>) -> Self {
        ModelError {
            reason: reason.into(),
        }
    }
}

impl From<String> for ModelError {
    fn from(reason: String) -> Self {
        ModelError { reason }
    }
}

impl From<&str> for ModelError {
    fn from(reason: &str) -> Self {
        ModelError::new(reason)
    }
}
