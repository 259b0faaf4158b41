use thiserror::Error;

/// Errors of the linear-algebra layer. Every variant names the matrix concerned.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum LinalgError {
    /// Cholesky failed: the leading minor of order `pivot + 1` is not positive.
    #[error("matrix {name} is not positive definite (pivot {pivot} is {value:e})")]
    NotPositiveDefinite {
        /// The matrix (or option) concerned.
        name: String,
        /// Index of the failing pivot.
        pivot: usize,
        /// The offending value.
        value: f64,
    },
    /// A matrix meant to be a covariance has a clearly negative eigenvalue.
    #[error("matrix {name} is not positive semi-definite (smallest eigenvalue {eigenvalue:e})")]
    NotPositiveSemiDefinite {
        /// The matrix (or option) concerned.
        name: String,
        /// The smallest eigenvalue.
        eigenvalue: f64,
    },
    /// `M[row, col]` and `M[col, row]` differ by more than the tolerance.
    #[error(
        "matrix {name} is not symmetric: entry ({row}, {col}) differs from ({col}, {row}) by {difference:e}"
    )]
    NotSymmetric {
        /// The matrix (or option) concerned.
        name: String,
        /// Row index.
        row: usize,
        /// Column index.
        col: usize,
        /// `|M[row, col] - M[col, row]|`.
        difference: f64,
    },
    /// A NaN or infinite entry.
    #[error("matrix {name} has a non-finite entry {value} at ({row}, {col})")]
    NonFinite {
        /// The matrix (or option) concerned.
        name: String,
        /// Row index.
        row: usize,
        /// Column index.
        col: usize,
        /// The offending value.
        value: f64,
    },
    /// A matrix that must be square is not.
    #[error("matrix {name} must be square, got {rows}x{cols}")]
    NotSquare {
        /// The matrix (or option) concerned.
        name: String,
        /// Rows found.
        rows: usize,
        /// Columns found.
        cols: usize,
    },
}
