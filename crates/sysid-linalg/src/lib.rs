//! Small dense linear-algebra helpers for `sysid`, over [`nalgebra`].
//!
//! These are the kernels the Kalman recursions are built from:
//!
//! * [`cholesky_upper`]: Cholesky factorisation returning a typed error (never a panic)
//!   for a matrix that is not positive definite;
//! * [`psd_factor`]: a square-root factor `F` with `F'F = M` of a positive
//!   *semi*-definite matrix (singular covariances such as `Q = 0` are common);
//! * [`symmetrize`], [`check_symmetric`], [`check_finite`];
//! * [`logdet_from_factor`], [`gaussian_logpdf_from_factor`];
//! * [`triangularize`]: Householder QR triangularisation of a stacked pre-array, the
//!   engine of square-root (array) filtering;
//! * [`solve_upper`], [`solve_upper_transpose`]: triangular solves that treat an exactly
//!   zero pivot row as "no information" (the generalised-inverse convention that
//!   matches the factors `triangularize` produces for singular covariances).
//!
//! [`simd`] runs a hot kernel compiled for the widest vector instruction set the CPU
//! has, with the same bits on every path.
//!
//! Matrices are column-major; the kernels work on slices with an explicit leading
//! dimension so that callers can reuse one buffer for pre-arrays of varying shape.

mod cholesky;
mod dot;
mod error;
mod gaussian;
mod logdet;
mod qr;
mod qr_stacked;
pub mod simd;
mod symmetric;
mod triangular;

pub use cholesky::{check_psd, cholesky_upper, psd_factor};
pub use dot::{axpy, dot};
pub use error::LinalgError;
pub use gaussian::{LN_2PI, gaussian_logpdf_from_factor, logdet_from_factor};
pub use logdet::LogProduct;
pub use qr::{QrScratch, triangularize};
pub use qr_stacked::{triangularize_stacked, triangularize_stacked_leading};
pub use symmetric::{check_finite, check_symmetric, symmetrize};
pub use triangular::{solve_upper, solve_upper_rows, solve_upper_transpose};
