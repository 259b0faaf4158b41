//! Detrending a record: a signal's mean or straight line in time, removed before a fit
//! and given back to what a model of the detrended signals returns.
//!
//! Means are folded into a model's offsets ([`Trend::fold`]), so the model describes
//! the original signals. A linear trend cannot be folded into a time-invariant model:
//! it is stored beside the model ([`Trend::describe`], the model file's
//! [`Detrend`]), and whatever runs the model on a record removes it at the record's
//! times ([`Trend::remove_from`]) and adds the outputs' trend back
//! ([`Trend::outputs_at`]).
//!
//! # Example
//! ```
//! use nalgebra::DMatrix;
//! use sysid_kalman::{Record, Trend, TrendKind};
//! let y = DMatrix::from_fn(1, 5, |_, t| 2.0 + 0.5 * t as f64);
//! let mut record = Record::new(DMatrix::zeros(0, 5), y);
//! let time: Vec<f64> = (1..=5).map(f64::from).collect();
//! let trend = Trend::estimate(&record, &time, TrendKind::Linear)?;
//! trend.remove_from(&mut record, &time);
//! assert!(record.y.amax() < 1e-12);
//! # Ok::<(), sysid_kalman::TrendError>(())
//! ```

use crate::{Detrend, KalmanError, LinearGaussianModel, Record};
use nalgebra::{DMatrix, DVector};

/// What detrending removes from each signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrendKind {
    /// The signal's mean over its observed values.
    Mean,
    /// A least-squares straight line in time.
    Linear,
}

impl TrendKind {
    /// The names of a detrending choice: `none`, then each kind's.
    pub const NAMES: [&'static str; 3] = ["none", "mean", "linear"];

    /// `mean` or `linear`.
    pub fn name(self) -> &'static str {
        match self {
            TrendKind::Mean => Self::NAMES[1],
            TrendKind::Linear => Self::NAMES[2],
        }
    }

    /// A detrending choice by name: `none` (nothing removed), `mean` or `linear`.
    ///
    /// # Errors
    /// The message for an unknown name, listing the names.
    pub fn choice(name: &str) -> Result<Option<TrendKind>, String> {
        match name {
            "none" => Ok(None),
            "mean" => Ok(Some(TrendKind::Mean)),
            "linear" => Ok(Some(TrendKind::Linear)),
            other => Err(format!(
                "unknown detrending {other:?} (known: {})",
                Self::NAMES.join(", ")
            )),
        }
    }
}

impl std::fmt::Display for TrendKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Why a trend cannot be estimated, read or folded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TrendError {
    /// A line needs a signal observed at two times at least.
    #[error("linear: {signal} {index} has {seen} observed value(s); a line needs two")]
    TooFewObserved {
        /// `input` or `output`.
        signal: &'static str,
        /// The signal (1-based).
        index: usize,
        /// Its observed values.
        seen: usize,
    },
    /// The record's times are not one per step.
    #[error("{times} times for a record of {steps} steps")]
    Times {
        /// Times given.
        times: usize,
        /// Steps of the record.
        steps: usize,
    },
    /// The model has an integrator: the inputs' means cannot be folded into an offset.
    #[error(
        "the fitted A has an eigenvalue 1 (an integrator): the inputs' means cannot be folded \
         into an output offset; fit without mean detrending"
    )]
    Integrator,
    /// A stored trend that does not fit the model or is not a trend.
    #[error("{0}")]
    Stored(String),
    /// A record whose times are on another base than the fitted record's.
    #[error(
        "the record's time step is {record}, the fitted record's was {model}: its linear \
         trend would be removed at the wrong times; give the record's times in the units of \
         the fitted record's (its time column t)"
    )]
    TimeBase {
        /// The fitted record's time step.
        model: f64,
        /// This record's.
        record: f64,
    },
    /// The folded model failed the model checks.
    #[error("folding the means into the model: {0}")]
    Model(#[from] KalmanError),
}

/// One straight line per signal, `offset + slope (t - origin)` (slopes zero for
/// [`TrendKind::Mean`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Trend {
    /// What was removed.
    pub kind: TrendKind,
    /// The time at which the offsets hold (the fitted record's first time).
    pub origin: f64,
    /// The inputs' offsets.
    pub input_offsets: DVector<f64>,
    /// The inputs' slopes per unit of time.
    pub input_slopes: DVector<f64>,
    /// The outputs' offsets.
    pub output_offsets: DVector<f64>,
    /// The outputs' slopes per unit of time.
    pub output_slopes: DVector<f64>,
    /// The fitted record's time step (mean spacing of its times; `None` for one time
    /// or a trend stored without it).
    pub time_step: Option<f64>,
}

/// The mean spacing of increasing times (`None` for fewer than two).
fn mean_step(time: &[f64]) -> Option<f64> {
    match time {
        [first, .., last] => Some((last - first) / (time.len() - 1) as f64),
        _ => None,
    }
}

/// Least-squares line `(offset at origin, slope)` through a signal's observed values;
/// the mean and a zero slope for `linear == false`.
fn line(values: impl Iterator<Item = f64>, time: &[f64], origin: f64, linear: bool) -> (f64, f64) {
    let seen: Vec<(f64, f64)> = time
        .iter()
        .zip(values)
        .filter(|(_, v)| !v.is_nan())
        .map(|(&t, v)| (t - origin, v))
        .collect();
    let count = seen.len().max(1) as f64;
    let t_mean = seen.iter().map(|p| p.0).sum::<f64>() / count;
    let v_mean = seen.iter().map(|p| p.1).sum::<f64>() / count;
    if !linear {
        return (v_mean, 0.0);
    }
    let spread: f64 = seen.iter().map(|p| (p.0 - t_mean).powi(2)).sum();
    if spread == 0.0 {
        return (v_mean, 0.0);
    }
    let slope = seen
        .iter()
        .map(|p| (p.0 - t_mean) * (p.1 - v_mean))
        .sum::<f64>()
        / spread;
    (v_mean - slope * t_mean, slope)
}

impl Trend {
    /// The trends of a record's inputs and outputs (over each signal's observed
    /// values) at the given times (one per step), with the first time as origin.
    ///
    /// # Errors
    /// [`TrendError::Times`] for a time list of another length;
    /// [`TrendError::TooFewObserved`] for a line through a signal observed at fewer
    /// than two times.
    pub fn estimate(record: &Record, time: &[f64], kind: TrendKind) -> Result<Trend, TrendError> {
        if time.len() != record.len() {
            return Err(TrendError::Times {
                times: time.len(),
                steps: record.len(),
            });
        }
        let origin = time.first().copied().unwrap_or(0.0);
        let linear = kind == TrendKind::Linear;
        let fit = |m: &DMatrix<f64>, signal: &'static str| -> Result<_, TrendError> {
            let mut offsets = DVector::zeros(m.nrows());
            let mut slopes = DVector::zeros(m.nrows());
            for i in 0..m.nrows() {
                let seen = m.row(i).iter().filter(|v| !v.is_nan()).count();
                if linear && seen < 2 {
                    return Err(TrendError::TooFewObserved {
                        signal,
                        index: i + 1,
                        seen,
                    });
                }
                (offsets[i], slopes[i]) = line(m.row(i).iter().copied(), time, origin, linear);
            }
            Ok((offsets, slopes))
        };
        let (input_offsets, input_slopes) = fit(&record.u, "input")?;
        let (output_offsets, output_slopes) = fit(&record.y, "output")?;
        Ok(Trend {
            kind,
            origin,
            input_offsets,
            input_slopes,
            output_offsets,
            output_slopes,
            time_step: mean_step(time),
        })
    }

    /// A linear trend stored in a model file, checked against the model's sizes;
    /// `None` for no trend or means (already folded into the model).
    ///
    /// # Errors
    /// [`TrendError::Stored`] for an unknown kind, a size that is not the model's or a
    /// non-finite entry.
    pub fn stored(
        detrend: Option<&Detrend>,
        inputs: usize,
        outputs: usize,
    ) -> Result<Option<Trend>, TrendError> {
        let Some(d) = detrend else { return Ok(None) };
        match d.kind.as_str() {
            "mean" => return Ok(None),
            "linear" => {}
            other => {
                return Err(TrendError::Stored(format!(
                    "unknown detrend kind {other:?} (known: mean, linear)"
                )));
            }
        }
        for (what, found, expected) in [
            ("inputs", d.inputs.len(), inputs),
            ("input_slopes", d.input_slopes.len(), inputs),
            ("outputs", d.outputs.len(), outputs),
            ("output_slopes", d.output_slopes.len(), outputs),
        ] {
            if found != expected {
                return Err(TrendError::Stored(format!(
                    "detrend.{what} has {found} entries; the model has {expected}"
                )));
            }
        }
        let values = d
            .inputs
            .iter()
            .chain(&d.outputs)
            .chain(&d.input_slopes)
            .chain(&d.output_slopes)
            .chain(d.origin.iter());
        if values.clone().any(|v| !v.is_finite()) || d.origin.is_none() {
            return Err(TrendError::Stored(
                "a linear detrend needs a finite origin, offsets and slopes".into(),
            ));
        }
        Ok(Some(Trend {
            kind: TrendKind::Linear,
            origin: d.origin.unwrap_or(0.0),
            input_offsets: DVector::from_column_slice(&d.inputs),
            input_slopes: DVector::from_column_slice(&d.input_slopes),
            output_offsets: DVector::from_column_slice(&d.outputs),
            output_slopes: DVector::from_column_slice(&d.output_slopes),
            time_step: d.time_step.filter(|s| s.is_finite() && *s != 0.0),
        }))
    }

    /// Checks that a record's times are on the fitted record's base: a linear trend
    /// evaluated at times in other units (row numbers for seconds) scored a model at
    /// -2 088 199 775 %. Mean detrending, a trend stored without its time step and a
    /// record of one step pass.
    ///
    /// # Errors
    /// [`TrendError::TimeBase`] when the mean time steps differ by more than 1 %.
    pub fn check_time_base(&self, time: &[f64]) -> Result<(), TrendError> {
        let (Some(model), Some(record), TrendKind::Linear) =
            (self.time_step, mean_step(time), self.kind)
        else {
            return Ok(());
        };
        if (record / model - 1.0).abs() > 0.01 || !record.is_finite() {
            return Err(TrendError::TimeBase { model, record });
        }
        Ok(())
    }

    /// The model file's record of the detrending.
    pub fn describe(&self) -> Detrend {
        let list = |v: &DVector<f64>| v.iter().copied().collect();
        let linear = self.kind == TrendKind::Linear;
        let slopes = |v: &DVector<f64>| if linear { list(v) } else { Vec::new() };
        Detrend {
            kind: if linear { "linear" } else { "mean" }.into(),
            inputs: list(&self.input_offsets),
            outputs: list(&self.output_offsets),
            origin: linear.then_some(self.origin),
            input_slopes: slopes(&self.input_slopes),
            output_slopes: slopes(&self.output_slopes),
            time_step: if linear { self.time_step } else { None },
        }
    }

    fn at(&self, offsets: &DVector<f64>, slopes: &DVector<f64>, time: &[f64]) -> DMatrix<f64> {
        DMatrix::from_fn(offsets.len(), time.len(), |i, t| {
            offsets[i] + slopes[i] * (time[t] - self.origin)
        })
    }

    /// The inputs' trend at the given times (one column per time).
    pub fn inputs_at(&self, time: &[f64]) -> DMatrix<f64> {
        self.at(&self.input_offsets, &self.input_slopes, time)
    }

    /// The outputs' trend at the given times (one column per time).
    pub fn outputs_at(&self, time: &[f64]) -> DMatrix<f64> {
        self.at(&self.output_offsets, &self.output_slopes, time)
    }

    /// Subtracts the trends from a record at the given times (one per step). An
    /// inputs-only record (one to simulate) keeps its empty outputs.
    pub fn remove_from(&self, record: &mut Record, time: &[f64]) {
        record.u -= self.inputs_at(time);
        if record.y.nrows() == self.output_offsets.len() {
            record.y -= self.outputs_at(time);
        }
    }

    /// The model of the original signals equivalent to `model` of the signals less
    /// their means: with `x_c = (I - A)^{-1} B u_mean`, the state `x + x_c` follows
    /// `A`, `B` driven by the original input, and `y = C (x + x_c) + D u + h'` with
    /// `h' = h + y_mean - D u_mean - C x_c`; `mu` moves by `x_c`.
    ///
    /// # Errors
    /// [`TrendError::Integrator`] when `I - A` is singular (the centred input's mean
    /// would drive the state without bound, and no offset can absorb it).
    pub fn fold(&self, model: &LinearGaussianModel) -> Result<LinearGaussianModel, TrendError> {
        let n = model.n();
        let forced = model.b() * &self.input_offsets;
        let shift = if forced.iter().all(|&v| v == 0.0) {
            DVector::zeros(n)
        } else {
            (DMatrix::identity(n, n) - model.a())
                .lu()
                .solve(&forced)
                .ok_or(TrendError::Integrator)?
        };
        let h =
            model.h() + &self.output_offsets - model.d() * &self.input_offsets - model.c() * &shift;
        Ok(model.to_builder().h(h).mu(model.mu() + &shift).build()?)
    }

    /// The model to write for `model` fitted on signals less this trend: means folded
    /// in ([`Trend::fold`]), a linear trend left to be stored beside it.
    ///
    /// # Errors
    /// As [`Trend::fold`].
    pub fn written_model(
        &self,
        model: &LinearGaussianModel,
    ) -> Result<LinearGaussianModel, TrendError> {
        match self.kind {
            TrendKind::Mean => self.fold(model),
            TrendKind::Linear => Ok(model.clone()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dmatrix;

    #[test]
    fn a_line_through_a_gap_is_the_least_squares_line_of_the_observed_values() {
        // y = 1 + 2 (t - 10) at t = 10, 11, 13 (t = 12 missing): exact line
        let y = dmatrix![1.0, 3.0, f64::NAN, 7.0];
        let record = Record::new(DMatrix::zeros(0, 4), y);
        let trend = Trend::estimate(&record, &[10.0, 11.0, 12.0, 13.0], TrendKind::Linear).unwrap();
        assert!((trend.output_offsets[0] - 1.0).abs() < 1e-12);
        assert!((trend.output_slopes[0] - 2.0).abs() < 1e-12);
        assert_eq!(trend.origin, 10.0);
        let mean = Trend::estimate(&record, &[10.0, 11.0, 12.0, 13.0], TrendKind::Mean).unwrap();
        assert!((mean.output_offsets[0] - 11.0 / 3.0).abs() < 1e-12);
        assert_eq!(mean.output_slopes[0], 0.0);
    }

    #[test]
    fn a_line_needs_two_observed_values_and_one_time_per_step() {
        let record = Record::new(DMatrix::zeros(0, 3), dmatrix![f64::NAN, 1.0, f64::NAN]);
        assert_eq!(
            Trend::estimate(&record, &[1.0, 2.0, 3.0], TrendKind::Linear),
            Err(TrendError::TooFewObserved {
                signal: "output",
                index: 1,
                seen: 1
            })
        );
        assert!(Trend::estimate(&record, &[1.0, 2.0, 3.0], TrendKind::Mean).is_ok());
        assert!(matches!(
            Trend::estimate(&record, &[1.0], TrendKind::Mean),
            Err(TrendError::Times { times: 1, steps: 3 })
        ));
    }

    #[test]
    fn folded_means_give_the_same_outputs_as_the_centred_model_plus_the_means() {
        // steady state of the folded model at the mean input equals the output mean
        // (builder: A, C, Q, R)
        let model = LinearGaussianModel::builder(
            dmatrix![0.5],
            dmatrix![2.0],
            dmatrix![1.0],
            dmatrix![0.1],
        )
        .b(dmatrix![1.0])
        .d(dmatrix![0.3])
        .build()
        .unwrap();
        let trend = Trend {
            kind: TrendKind::Mean,
            origin: 0.0,
            input_offsets: DVector::from_element(1, 4.0),
            input_slopes: DVector::zeros(1),
            output_offsets: DVector::from_element(1, 7.0),
            output_slopes: DVector::zeros(1),
            time_step: None,
        };
        let folded = trend.fold(&model).unwrap();
        let x_ss = 4.0 / (1.0 - 0.5);
        let y_ss = 2.0 * x_ss + 0.3 * 4.0 + folded.h()[0];
        assert!((y_ss - 7.0).abs() < 1e-12, "{y_ss}");
        let integrator = model.to_builder().a(dmatrix![1.0]).build().unwrap();
        assert_eq!(trend.fold(&integrator), Err(TrendError::Integrator));
    }
}
