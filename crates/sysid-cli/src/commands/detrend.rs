//! `--detrend mean`: fit on centred signals, and write a model of the original ones.

use crate::error::CliError;
use crate::files::DataFile;
use nalgebra::{DMatrix, DVector};
use sysid::kalman::LinearGaussianModel;

/// The signals' means over their observed values.
pub struct Means {
    pub inputs: DVector<f64>,
    pub outputs: DVector<f64>,
}

impl Means {
    /// The model file's record of the detrending.
    pub fn describe(&self) -> sysid::kalman::Detrend {
        sysid::kalman::Detrend {
            kind: "mean".into(),
            inputs: self.inputs.iter().copied().collect(),
            outputs: self.outputs.iter().copied().collect(),
        }
    }
}

/// The `--detrend` option: `none` or `mean`.
pub fn parse(text: &str) -> Result<bool, CliError> {
    match text {
        "none" => Ok(false),
        "mean" => Ok(true),
        other => Err(CliError::BadOption {
            option: "--detrend",
            message: format!("unknown detrending {other:?} (known: none, mean)"),
        }),
    }
}

/// Subtracts each input's and output's mean (over its observed values) from the record.
pub fn centre(file: &mut DataFile) -> Means {
    let mean_rows = |m: &DMatrix<f64>| {
        DVector::from_fn(m.nrows(), |i, _| {
            let seen: Vec<f64> = m.row(i).iter().copied().filter(|v| !v.is_nan()).collect();
            seen.iter().sum::<f64>() / seen.len().max(1) as f64
        })
    };
    let means = Means {
        inputs: mean_rows(&file.record.u),
        outputs: mean_rows(&file.record.y),
    };
    for mut col in file.record.u.column_iter_mut() {
        col -= &means.inputs;
    }
    for mut col in file.record.y.column_iter_mut() {
        col -= &means.outputs;
    }
    means
}

/// The model of the original signals equivalent to `model` of the centred ones: with
/// `x_c = (I - A)^{-1} B u_mean`, the state `x + x_c` follows `A`, `B` driven by the
/// original input, and `y = C (x + x_c) + D u + h'` with
/// `h' = h + y_mean - D u_mean - C x_c`; a given `mu` moves by `x_c`.
///
/// # Errors
/// When `I - A` is singular (an integrator: the centred input's mean would have to
/// drive the state without bound, and no offset can absorb it).
pub fn fold(model: &LinearGaussianModel, means: &Means) -> Result<LinearGaussianModel, CliError> {
    let n = model.n();
    let forced = model.b() * &means.inputs;
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
    let h = model.h() + &means.outputs - model.d() * &means.inputs - model.c() * &shift;
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
