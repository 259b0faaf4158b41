//! Observed data for the particle methods: outputs (NaN = missing) and inputs.

use crate::SmcError;

/// A borrowed time series: outputs `y_t` (`output_dim` values per step, NaN marks a
/// missing entry) and optional inputs `u_t` (`input_dim` values per step, all finite).
///
/// Both arrays are time-major: step `t` occupies `[t * dim, (t + 1) * dim)`.
///
/// # Example
/// ```
/// use sysid_smc::Series;
/// let y = [0.1, f64::NAN, 0.3];
/// let data = Series::new(&y, 1).unwrap();
/// assert_eq!(data.steps(), 3);
/// assert!(data.is_missing(1));
/// ```
#[derive(Debug, Clone, Copy)]
pub struct Series<'a> {
    outputs: &'a [f64],
    output_dim: usize,
    inputs: &'a [f64],
    input_dim: usize,
    steps: usize,
}

impl<'a> Series<'a> {
    /// Outputs only. Errors on a length that is not a multiple of `output_dim`, on no
    /// steps at all, and on infinite outputs.
    pub fn new(outputs: &'a [f64], output_dim: usize) -> Result<Self, SmcError> {
        if output_dim == 0 || outputs.is_empty() || !outputs.len().is_multiple_of(output_dim) {
            return Err(SmcError::DimensionMismatch {
                what: "outputs",
                expected: format!("a positive multiple of output_dim = {output_dim}"),
                found: outputs.len(),
            });
        }
        for (k, &v) in outputs.iter().enumerate() {
            if v.is_infinite() {
                return Err(SmcError::NonFiniteData {
                    what: "output",
                    t: k / output_dim,
                    index: k % output_dim,
                    value: v,
                });
            }
        }
        Ok(Series {
            outputs,
            output_dim,
            inputs: &[],
            input_dim: 0,
            steps: outputs.len() / output_dim,
        })
    }

    /// Adds inputs: `steps * input_dim` finite values.
    pub fn with_inputs(mut self, inputs: &'a [f64], input_dim: usize) -> Result<Self, SmcError> {
        if inputs.len() != self.steps * input_dim {
            return Err(SmcError::DimensionMismatch {
                what: "inputs",
                expected: format!("{} steps x {input_dim} inputs", self.steps),
                found: inputs.len(),
            });
        }
        for (k, &v) in inputs.iter().enumerate() {
            if !v.is_finite() {
                return Err(SmcError::NonFiniteData {
                    what: "input",
                    t: k / input_dim,
                    index: k % input_dim,
                    value: v,
                });
            }
        }
        self.inputs = inputs;
        self.input_dim = input_dim;
        Ok(self)
    }

    /// Number of time steps T.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// The first `steps` steps (all of them when there are fewer; at least one).
    pub fn head(&self, steps: usize) -> Series<'a> {
        let steps = steps.clamp(1, self.steps);
        Series {
            outputs: &self.outputs[..steps * self.output_dim],
            inputs: &self.inputs[..steps * self.input_dim],
            steps,
            ..*self
        }
    }

    /// Output dimension.
    pub fn output_dim(&self) -> usize {
        self.output_dim
    }

    /// Input dimension (0 without inputs).
    pub fn input_dim(&self) -> usize {
        self.input_dim
    }

    /// `y_t`.
    #[inline]
    pub fn output(&self, t: usize) -> &'a [f64] {
        &self.outputs[t * self.output_dim..(t + 1) * self.output_dim]
    }

    /// `u_t` (empty without inputs).
    #[inline]
    pub fn input(&self, t: usize) -> &'a [f64] {
        &self.inputs[t * self.input_dim..(t + 1) * self.input_dim]
    }

    /// Whether every entry of `y_t` is missing.
    #[inline]
    pub fn is_missing(&self, t: usize) -> bool {
        self.output(t).iter().all(|v| v.is_nan())
    }
}
