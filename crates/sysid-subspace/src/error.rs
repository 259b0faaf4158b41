use sysid_kalman::KalmanError;
use thiserror::Error;

/// Errors of subspace identification; each names what is wrong and where.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum SubspaceError {
    /// The requested order exceeds what the block Hankel matrices can reveal.
    #[error(
        "order {order} is larger than the data allow with {block_rows} block rows (at most {max})"
    )]
    OrderTooLarge {
        /// The requested order.
        order: usize,
        /// Block rows of the Hankel matrices.
        block_rows: usize,
        /// The largest order the data allow.
        max: usize,
    },
    /// Not enough samples for the number of block rows.
    #[error("{block_rows} block rows need at least {needed} samples, the data have {got}")]
    TooFewSamples {
        /// Block rows of the Hankel matrices.
        block_rows: usize,
        /// Samples needed.
        needed: usize,
        /// Samples available.
        got: usize,
    },
    /// Fewer than two block rows, or zero order.
    #[error("invalid option: {0}")]
    InvalidOption(String),
    /// N4SID needs complete data.
    #[error(
        "output {output} is missing at time {time}: N4SID needs complete data (fill or cut the gaps, or start EM from another model)"
    )]
    MissingData {
        /// Time step (1-based).
        time: usize,
        /// Output (1-based).
        output: usize,
    },
    /// An output never changes: it carries no information about the system.
    #[error(
        "output y{output} is constant ({value}) over the whole record: it has zero variance, so no model can be identified from it (drop the column)"
    )]
    ConstantOutput {
        /// The output (1-based).
        output: usize,
        /// Its value.
        value: f64,
    },
    /// The data have no outputs.
    #[error("the data have no output")]
    NoOutputs,
    /// Inputs and outputs disagree in length, or a value is not finite.
    #[error("invalid data: {0}")]
    Data(#[from] KalmanError),
    /// A factorization failed (should not happen on finite data).
    #[error("numerical failure: {0}")]
    Numerical(String),
}
