//! `--detrend mean|linear`: fit on detrended signals, and write a model that gives
//! answers in the original units.
//!
//! Means are folded into the written model's offsets ([`fold`]), so the model describes
//! the original signals. A linear trend cannot be folded into a time-invariant model:
//! it is stored in the model's metadata, and the commands that run the model on a
//! record remove it at the record's times ([`Trend::remove`]) and add the outputs'
//! trend back to what they return ([`crate::files::DataFile::restored`]).

use crate::error::CliError;
use crate::files::DataFile;
use nalgebra::{DMatrix, DVector};
use sysid::kalman::{Detrend, LinearGaussianModel};

/// What `--detrend` removes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    None,
    Mean,
    Linear,
}

/// The `--detrend` option: `none`, `mean` or `linear`.
pub fn parse(text: &str) -> Result<Kind, CliError> {
    match text {
        "none" => Ok(Kind::None),
        "mean" => Ok(Kind::Mean),
        "linear" => Ok(Kind::Linear),
        other => Err(CliError::BadOption {
            option: "--detrend",
            message: format!("unknown detrending {other:?} (known: none, mean, linear)"),
        }),
    }
}

/// One straight line per signal, `offset + slope (t - origin)` (slopes zero for
/// `mean`), in the time of the data file (its numeric time column or row numbers).
#[derive(Debug, Clone, PartialEq)]
pub struct Trend {
    pub kind: Kind,
    pub origin: f64,
    pub input_offsets: DVector<f64>,
    pub input_slopes: DVector<f64>,
    pub output_offsets: DVector<f64>,
    pub output_slopes: DVector<f64>,
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
    /// values), with the record's first time as origin.
    ///
    /// # Errors
    /// `linear` on a signal observed at fewer than two times (its slope is undefined).
    pub fn estimate(file: &DataFile, kind: Kind) -> Result<Trend, CliError> {
        let origin = file.time.first().copied().unwrap_or(0.0);
        let linear = kind == Kind::Linear;
        let fit = |m: &DMatrix<f64>, names: &[String]| -> Result<_, CliError> {
            let mut offsets = DVector::zeros(m.nrows());
            let mut slopes = DVector::zeros(m.nrows());
            for i in 0..m.nrows() {
                let seen = m.row(i).iter().filter(|v| !v.is_nan()).count();
                if linear && seen < 2 {
                    return Err(CliError::BadOption {
                        option: "--detrend",
                        message: format!(
                            "linear: column {} has {seen} observed value(s); a line needs two",
                            names.get(i).map_or("?", String::as_str)
                        ),
                    });
                }
                (offsets[i], slopes[i]) =
                    line(m.row(i).iter().copied(), &file.time, origin, linear);
            }
            Ok((offsets, slopes))
        };
        let (input_offsets, input_slopes) = fit(&file.record.u, &file.input_names)?;
        let (output_offsets, output_slopes) = fit(&file.record.y, &file.output_names)?;
        Ok(Trend {
            kind,
            origin,
            input_offsets,
            input_slopes,
            output_offsets,
            output_slopes,
        })
    }

    /// A linear trend stored in a model file, checked against the model's sizes;
    /// `None` for no trend or means (already folded into the model).
    pub fn stored(
        detrend: Option<&Detrend>,
        inputs: usize,
        outputs: usize,
    ) -> Result<Option<Trend>, String> {
        let Some(d) = detrend else { return Ok(None) };
        match d.kind.as_str() {
            "mean" => return Ok(None),
            "linear" => {}
            other => {
                return Err(format!(
                    "unknown detrend kind {other:?} (known: mean, linear)"
                ));
            }
        }
        for (what, found, expected) in [
            ("inputs", d.inputs.len(), inputs),
            ("input_slopes", d.input_slopes.len(), inputs),
            ("outputs", d.outputs.len(), outputs),
            ("output_slopes", d.output_slopes.len(), outputs),
        ] {
            if found != expected {
                return Err(format!(
                    "detrend.{what} has {found} entries; the model has {expected}"
                ));
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
            return Err("a linear detrend needs a finite origin, offsets and slopes".into());
        }
        Ok(Some(Trend {
            kind: Kind::Linear,
            origin: d.origin.unwrap_or(0.0),
            input_offsets: DVector::from_column_slice(&d.inputs),
            input_slopes: DVector::from_column_slice(&d.input_slopes),
            output_offsets: DVector::from_column_slice(&d.outputs),
            output_slopes: DVector::from_column_slice(&d.output_slopes),
        }))
    }

    /// The model file's record of the detrending.
    pub fn describe(&self) -> Detrend {
        let list = |v: &DVector<f64>| v.iter().copied().collect();
        let linear = self.kind == Kind::Linear;
        Detrend {
            kind: if linear { "linear" } else { "mean" }.into(),
            inputs: list(&self.input_offsets),
            outputs: list(&self.output_offsets),
            origin: linear.then_some(self.origin),
            input_slopes: if linear {
                list(&self.input_slopes)
            } else {
                Vec::new()
            },
            output_slopes: if linear {
                list(&self.output_slopes)
            } else {
                Vec::new()
            },
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

    /// Subtracts the trends from a record at the given times (one per step).
    pub fn remove_from(&self, record: &mut sysid::kalman::Record, time: &[f64]) {
        record.u -= self.inputs_at(time);
        // an inputs-only record (a file to simulate) has no outputs to detrend
        if record.y.nrows() == self.output_offsets.len() {
            record.y -= self.outputs_at(time);
        }
    }

    /// Subtracts the trends from a record at its times; a linear trend is remembered
    /// by the file so that [`DataFile::restored`] can add it back.
    pub fn remove(&self, file: &mut DataFile) {
        self.remove_from(&mut file.record, &file.time);
        if self.kind == Kind::Linear {
            file.trend = Some(self.clone());
        }
    }
}

/// The model of the original signals equivalent to `model` of the centred ones: with
/// `x_c = (I - A)^{-1} B u_mean`, the state `x + x_c` follows `A`, `B` driven by the
/// original input, and `y = C (x + x_c) + D u + h'` with
/// `h' = h + y_mean - D u_mean - C x_c`; a given `mu` moves by `x_c`.
///
/// # Errors
/// When `I - A` is singular (an integrator: the centred input's mean would have to
/// drive the state without bound, and no offset can absorb it).
pub fn fold(model: &LinearGaussianModel, means: &Trend) -> Result<LinearGaussianModel, CliError> {
    let n = model.n();
    let forced = model.b() * &means.input_offsets;
    let shift = if forced.iter().all(|&v| v == 0.0) {
        DVector::zeros(n)
    } else {
        (DMatrix::identity(n, n) - model.a())
            .lu()
            .solve(&forced)
            .ok_or_else(|| CliError::BadOption {
                option: "--detrend",
                message: "the fitted A has an eigenvalue 1 (an integrator): the inputs' means \
                          cannot be folded into an output offset; fit without --detrend mean"
                    .into(),
            })?
    };
    let h =
        model.h() + &means.output_offsets - model.d() * &means.input_offsets - model.c() * &shift;
    model
        .to_builder()
        .h(h)
        .mu(model.mu() + &shift)
        .build()
        .map_err(|source| CliError::Kalman {
            context: "--detrend mean".into(),
            source,
        })
}

/// Removes the trend `kind` from a record about to be fitted; the trend, for the
/// written model (`None` for `none`).
pub fn apply(file: &mut DataFile, kind: Kind) -> Result<Option<Trend>, CliError> {
    if kind == Kind::None {
        return Ok(None);
    }
    let trend = Trend::estimate(file, kind)?;
    trend.remove(file);
    Ok(Some(trend))
}

/// The model to write for a model fitted on detrended data: means folded in, a
/// linear trend left to the metadata.
pub fn written_model(
    model: &LinearGaussianModel,
    trend: Option<&Trend>,
) -> Result<LinearGaussianModel, CliError> {
    match trend {
        Some(t) if t.kind == Kind::Mean => fold(model, t),
        _ => Ok(model.clone()),
    }
}
