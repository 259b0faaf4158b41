//! The data of a fit: a record with its times and signal names.

use super::LinearFitError;
use sysid_kalman::Record;

/// A record of inputs and outputs with the time of each step and the signals' names
/// (for linear detrending and for messages).
///
/// # Example
/// ```
/// use nalgebra::DMatrix;
/// use sysid_em::linear::Signals;
/// use sysid_kalman::Record;
/// let record = Record::new(DMatrix::zeros(1, 10), DMatrix::zeros(1, 10));
/// let signals = Signals::new(record);
/// assert_eq!(signals.time[0], 1.0); // row numbers when no times are given
/// let (train, rest) = signals.split(0.6)?;
/// assert_eq!((train.record.len(), rest.record.len()), (6, 4));
/// # Ok::<(), sysid_em::linear::LinearFitError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct Signals {
    /// Inputs and outputs (NaN outputs are missing).
    pub record: Record,
    /// The time of each step (row numbers `1..=T` unless given).
    pub time: Vec<f64>,
    /// The inputs' names (`u1, u2, ...` unless given).
    pub input_names: Vec<String>,
    /// The outputs' names (`y1, y2, ...` unless given).
    pub output_names: Vec<String>,
}

impl Signals {
    /// A record with the row numbers as times and the names `u1, ...`, `y1, ...`.
    pub fn new(record: Record) -> Signals {
        let names = |prefix: &str, count: usize| -> Vec<String> {
            (1..=count).map(|i| format!("{prefix}{i}")).collect()
        };
        Signals {
            time: (1..=record.len()).map(|t| t as f64).collect(),
            input_names: names("u", record.u.nrows()),
            output_names: names("y", record.y.nrows()),
            record,
        }
    }

    /// The same with the time of each step.
    ///
    /// # Errors
    /// A list of another length than the record's.
    pub fn with_time(mut self, time: Vec<f64>) -> Result<Signals, LinearFitError> {
        if time.len() != self.record.len() {
            return Err(LinearFitError::InvalidOption {
                option: "time",
                message: format!(
                    "{} times are needed, one per step; got {}",
                    self.record.len(),
                    time.len()
                ),
            });
        }
        self.time = time;
        Ok(self)
    }

    /// The same with the signals' names.
    ///
    /// # Errors
    /// Lists of other lengths than the record's inputs and outputs.
    pub fn with_names(
        mut self,
        inputs: Vec<String>,
        outputs: Vec<String>,
    ) -> Result<Signals, LinearFitError> {
        if inputs.len() != self.record.u.nrows() || outputs.len() != self.record.y.nrows() {
            return Err(LinearFitError::InvalidOption {
                option: "names",
                message: format!(
                    "{} input and {} output names for a record of {} inputs and {} outputs",
                    inputs.len(),
                    outputs.len(),
                    self.record.u.nrows(),
                    self.record.y.nrows()
                ),
            });
        }
        self.input_names = inputs;
        self.output_names = outputs;
        Ok(self)
    }

    /// Steps `from .. from + len` (0-based); `None` when they are not all in the record.
    pub fn rows(&self, from: usize, len: usize) -> Option<Signals> {
        if from.checked_add(len)? > self.record.len() {
            return None;
        }
        Some(Signals {
            record: Record::new(
                self.record.u.columns(from, len).clone_owned(),
                self.record.y.columns(from, len).clone_owned(),
            ),
            time: self.time[from..from + len].to_vec(),
            input_names: self.input_names.clone(),
            output_names: self.output_names.clone(),
        })
    }

    /// The first `floor(fraction T)` steps and the rest.
    ///
    /// # Errors
    /// A fraction outside `(0, 1)`, or one that leaves fewer than two steps on a side.
    pub fn split(&self, fraction: f64) -> Result<(Signals, Signals), LinearFitError> {
        let total = self.record.len();
        let cut = (fraction * total as f64).floor() as usize;
        let bad = || LinearFitError::InvalidOption {
            option: "split",
            message: format!(
                "{fraction} leaves no useful estimation or validation rows of {total} (give a \
                 fraction strictly between 0 and 1)"
            ),
        };
        if !(fraction > 0.0 && fraction < 1.0) || cut < 2 || cut + 2 > total {
            return Err(bad());
        }
        let first = self.rows(0, cut).ok_or_else(bad)?;
        let rest = self.rows(cut, total - cut).ok_or_else(bad)?;
        Ok((first, rest))
    }
}
