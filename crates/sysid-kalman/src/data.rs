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
        self.check_initial_scale(model)
    }

    /// Each output's sample variance over its observed (finite) values, `1/N`
    /// normalised; 0 for an output with fewer than two observed values.
    pub fn output_variances(&self) -> nalgebra::DVector<f64> {
        nalgebra::DVector::from_fn(self.y.nrows(), |i, _| {
            let seen: Vec<f64> = self
                .y
                .row(i)
                .iter()
                .copied()
                .filter(|v| v.is_finite())
                .collect();
            if seen.len() < 2 {
                return 0.0;
            }
            let mean = seen.iter().sum::<f64>() / seen.len() as f64;
            seen.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / seen.len() as f64
        })
    }

    /// Refuses a `P1` whose output variance `C P1 C'` exceeds 1e15 times the outputs'
    /// largest sample variance: beyond it the first update cancels every digit (a
    /// "diffuse" prior must be handled exactly, not by a huge number).
    fn check_initial_scale(&self, model: &LinearGaussianModel) -> Result<()> {
        let data = self.output_variances().iter().copied().fold(0.0, f64::max);
        if data <= 0.0 {
            return Ok(());
        }
        let prior = model.c() * model.p1() * model.c().transpose();
        let largest = prior.diagonal().iter().copied().fold(0.0_f64, f64::max);
        if largest > 1e15 * data || !largest.is_finite() {
            return Err(KalmanError::InitialCovarianceTooLarge { largest, data });
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
