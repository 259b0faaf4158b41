use sysid_linalg::LinalgError;
use thiserror::Error;

/// Errors of the linear Gaussian layer. Each variant names the place: the matrix, or
/// the record (0-based) and the time step and component (1-based, as in the equations).
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum KalmanError {
    /// A model matrix failed a check (non-finite, non-symmetric, not PSD, ...).
    #[error("invalid model: {0}")]
    Matrix(#[from] LinalgError),
    /// A model without states or without outputs (an empty `A` or `C`).
    #[error("a model needs at least one {what}: {matrix} is {rows}x{cols}")]
    EmptyModel {
        /// `state` or `output`.
        what: &'static str,
        /// The matrix whose size gives the dimension (`A` or `C`).
        matrix: &'static str,
        /// Rows found.
        rows: usize,
        /// Columns found.
        cols: usize,
    },
    /// A model matrix or a data array has the wrong shape.
    #[error("matrix {name} must be {expected_rows}x{expected_cols}, got {rows}x{cols}")]
    Dimension {
        /// The matrix (or option) concerned.
        name: String,
        /// Rows expected.
        expected_rows: usize,
        /// Columns expected.
        expected_cols: usize,
        /// Rows found.
        rows: usize,
        /// Columns found.
        cols: usize,
    },
    /// An infinite output, or a NaN/Inf input (NaN outputs mean "missing").
    #[error("record {record}, time {time}: {what} {index} is {value}")]
    NonFiniteData {
        /// Record index (0-based).
        record: usize,
        /// Time step (1-based).
        time: usize,
        /// What the value is (`input` or `output`).
        what: &'static str,
        /// Component of the vector (1-based).
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// The innovation covariance `C P C' + R` is singular at this step, so the
    /// observation has no density (e.g. `R = 0` with a perfectly known state).
    #[error(
        "record {record}, time {time}: innovation covariance is singular (output {output} is exactly predictable)"
    )]
    SingularInnovation {
        /// Record index (0-based).
        record: usize,
        /// Time step (1-based).
        time: usize,
        /// Output (1-based).
        output: usize,
    },
    /// The log-likelihood or the state estimate overflows at this step: an output far
    /// outside the model's scale (e.g. 1e308 with unit noise).
    #[error(
        "record {record}, time {time}: the log-likelihood overflows (an output far outside the model's scale?)"
    )]
    Overflow {
        /// Record index (0-based).
        record: usize,
        /// Time step (1-based).
        time: usize,
    },
    /// `P1` so large against the data that the filter loses its precision.
    #[error(
        "P1 is too large for the data: the initial state's output variance C P1 C' reaches \
         {largest:.1e}, more than 1e15 times the outputs' largest sample variance ({data:.1e}), \
         where the filter's first update loses every significant digit; use a P1 of about 1e6 \
         times the outputs' variance, or the exact diffuse initialisation (`diffuse` directions; \
         `--initial diffuse` on the command line)"
    )]
    InitialCovarianceTooLarge {
        /// The largest eigenvalue of `C P1 C'`.
        largest: f64,
        /// The largest sample variance of the outputs.
        data: f64,
    },
    /// Diffuse directions that are linearly dependent.
    #[error(
        "the {columns} diffuse directions of the initial state are linearly dependent (rank {rank}); \
         give independent columns"
    )]
    DiffuseRank {
        /// Columns of `A_d`.
        columns: usize,
        /// Their numerical rank.
        rank: usize,
    },
    /// The record does not determine the diffuse part of the initial state, so the
    /// diffuse likelihood and the smoothed states do not exist.
    #[error(
        "record {record}: the data do not determine the diffuse initial state (rank {rank} of \
         {directions} directions): a state the outputs never see, or fewer observations than \
         diffuse states; give it a proper initial law (P1) instead"
    )]
    DiffuseNotIdentified {
        /// Record index (0-based).
        record: usize,
        /// Number of diffuse directions `q`.
        directions: usize,
        /// How many the data determine.
        rank: usize,
    },
    /// A stationary initial state asked of a model whose `A` is not stable.
    #[error(
        "the initial state cannot be stationary: A is not stable (spectral radius {radius:.6}); \
         use the diffuse initial state"
    )]
    NotStationary {
        /// The spectral radius of `A`.
        radius: f64,
    },
    /// A model file that gives `mu`, `p1` or `diffuse` beside an `initial` law that
    /// defines them.
    #[error(
        "\"{key}\" conflicts with \"initial\": a stationary or diffuse initial state defines \
         mu, P1 and the diffuse directions; remove one of the two"
    )]
    InitialConflict {
        /// The key given beside `initial`.
        key: &'static str,
    },
    /// A noise-free simulation that overflows (an unstable `A` over a long record).
    #[error(
        "the model's simulation diverges at time {time} (an unstable A?): its response cannot \
         be compared with the data"
    )]
    SimulationDiverges {
        /// Time step (1-based) at which it overflowed.
        time: usize,
    },
    /// Smoothing by blocks asked of a model with a diffuse initial state (its
    /// smoothed states depend on the diffuse part's posterior given the whole record).
    #[error(
        "a model with a diffuse initial state is smoothed over the whole record, not by \
         blocks; give it a proper initial law (e.g. `--initial stationary`) for a long record"
    )]
    DiffuseInBlocks,
    /// A data set with no record, or a record of length zero.
    #[error("record {record} has no time steps")]
    EmptyRecord {
        /// Record index (0-based).
        record: usize,
    },
    /// An option of a computation out of its range (a horizon of 0, a level outside
    /// (0, 1), more lags than residuals).
    #[error("{name}: {message}")]
    BadOption {
        /// The option, as the library spells it (`level`, `horizon`, `lags`).
        name: &'static str,
        /// What is wrong with its value.
        message: String,
    },
    /// Residual tests asked for more lags than an output has usable residuals, or for
    /// none.
    #[error(
        "lags: {lags} must be at least 1 and below the {usable} usable residuals of output {output}"
    )]
    TooManyLags {
        /// The lags asked for.
        lags: usize,
        /// The output's residuals where it is observed and determined.
        usable: usize,
        /// The output (1-based).
        output: usize,
    },
    /// Inputs and outputs of one record disagree in length.
    #[error("record {record}: inputs have {input_steps} steps but outputs have {output_steps}")]
    LengthMismatch {
        /// Record index (0-based).
        record: usize,
        /// Time steps of the inputs.
        input_steps: usize,
        /// Time steps of the outputs.
        output_steps: usize,
    },
}

impl KalmanError {
    /// The error of a block that starts after `steps` steps of a longer record, with its
    /// time counted from the start of the record.
    pub(crate) fn at_offset(self, steps: usize) -> Self {
        let mut e = self;
        match &mut e {
            KalmanError::NonFiniteData { time, .. }
            | KalmanError::SingularInnovation { time, .. }
            | KalmanError::Overflow { time, .. }
            | KalmanError::SimulationDiverges { time } => *time += steps,
            _ => {}
        }
        e
    }
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, KalmanError>;
