//! numpy arrays in: `(T, k)` arrays of any memory layout (C, Fortran, strided), copied
//! once into the library's channel-by-time matrices. The Python half turns 1-D arrays
//! and DataFrames into these; NaN in an output is a missing value.

use crate::errors::Failure;
use nalgebra::DMatrix;
use numpy::PyReadonlyArray2;
use sysid::kalman::Record;

/// A `(T, k)` array as the `k x T` matrix the library reads (column `t` is time `t`),
/// read through the array's strides whatever its layout.
pub(crate) fn channels(array: &PyReadonlyArray2<'_, f64>) -> DMatrix<f64> {
    let view = array.as_array();
    let (steps, k) = view.dim();
    DMatrix::from_fn(k, steps, |i, t| view[[t, i]])
}

/// The record of outputs `y` `(T, p)` and inputs `u` `(T, m)`, or of `y` alone.
pub(crate) fn record(
    y: &PyReadonlyArray2<'_, f64>,
    u: Option<&PyReadonlyArray2<'_, f64>>,
) -> Result<Record, Failure> {
    let y = channels(y);
    let u = match u {
        Some(u) => channels(u),
        None => DMatrix::zeros(0, y.ncols()),
    };
    if u.ncols() != y.ncols() {
        return Err(Failure::data(format!(
            "the inputs have {} rows and the outputs {}: give one row per time step",
            u.ncols(),
            y.ncols()
        )));
    }
    if let Some(k) = u.iter().position(|v| !v.is_finite()) {
        return Err(Failure::data(format!(
            "input {} at row {} is {}: inputs must be finite (NaN marks a missing output only)",
            k % u.nrows().max(1) + 1,
            k / u.nrows().max(1),
            u[k]
        )));
    }
    if let Some(k) = y.iter().position(|v| v.is_infinite()) {
        return Err(Failure::data(format!(
            "output {} at row {} is {}: outputs must be finite or NaN (missing)",
            k % y.nrows().max(1) + 1,
            k / y.nrows().max(1),
            y[k]
        )));
    }
    Ok(Record::new(u, y))
}

/// The times of a record: the given ones (checked), else the row numbers 1..T, as the
/// command line numbers the rows of a file without a time column.
pub(crate) fn times(time: Option<Vec<f64>>, steps: usize) -> Result<Vec<f64>, Failure> {
    match time {
        None => Ok((1..=steps).map(|t| t as f64).collect()),
        Some(time) if time.len() != steps => Err(Failure::data(format!(
            "{} times for {steps} rows",
            time.len()
        ))),
        Some(time) => Ok(time),
    }
}
