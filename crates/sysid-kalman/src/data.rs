//! Data records: inputs and outputs of one experiment, and sets of independent records.

use crate::{KalmanError, LinearGaussianModel, Result};
use nalgebra::DMatrix;

/// One experiment: inputs `u` (m x T) and outputs `y` (p x T), one column per time step.
///
/// A NaN output entry means "missing" (a partially observed vector is fine, and a
/// column of NaN is a step with no observation). Inputs must be finite, outputs must
/// not be infinite.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Inputs, `m x T` (zero rows for a model without inputs).
    pub u: DMatrix<f64>,
    /// Outputs, `p x T`; NaN marks a missing entry.
    pub y: DMatrix<f64>,
}

impl Record {
    /// A record with inputs and outputs.
    pub fn new(u: DMatrix<f64>, y: DMatrix<f64>) -> Self {
        Record { u, y }
    }

    /// A record of a model without inputs.
    pub fn outputs_only(y: DMatrix<f64>) -> Self {
        Record {
            u: DMatrix::zeros(0, y.ncols()),
            y,
        }
    }

    /// Number of time steps `T`.
    pub fn len(&self) -> usize {
        self.y.ncols()
    }

    /// Whether the record has no time step.
    pub fn is_empty(&self) -> bool {
        self.y.ncols() == 0
    }

    /// Checks this record against a model: shapes, equal lengths, finite inputs, no
    /// infinite output. `index` is the record's number, used in the error.
    pub fn validate(&self, model: &LinearGaussianModel, index: usize) -> Result<()> {
        if self.is_empty() {
            return Err(KalmanError::EmptyRecord { record: index });
        }
        if self.u.ncols() != self.y.ncols() {
            return Err(KalmanError::LengthMismatch {
                record: index,
                input_steps: self.u.ncols(),
                output_steps: self.y.ncols(),
            });
        }
        let t_len = self.len();
        for (name, mat, rows) in [("u", &self.u, model.m()), ("y", &self.y, model.p())] {
            if mat.nrows() != rows {
                return Err(KalmanError::Dimension {
                    name: format!("record {index} {name}"),
                    expected_rows: rows,
                    expected_cols: t_len,
                    rows: mat.nrows(),
                    cols: mat.ncols(),
                });
            }
        }
        for t in 0..t_len {
            for (i, &v) in self.u.column(t).iter().enumerate() {
                if !v.is_finite() {
                    return Err(non_finite(index, t, "input", i, v));
                }
            }
            for (i, &v) in self.y.column(t).iter().enumerate() {
                if v.is_infinite() {
                    return Err(non_finite(index, t, "output", i, v));
                }
            }
        }
        Ok(())
    }
}

fn non_finite(
    record: usize,
    t: usize,
    what: &'static str,
    index: usize,
    value: f64,
) -> KalmanError {
    KalmanError::NonFiniteData {
        record,
        time: t + 1,
        what,
        index: index + 1,
        value,
    }
}
