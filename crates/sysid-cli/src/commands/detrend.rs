//! `--detrend mean|linear` on a data file: the library's [`Trend`] at the file's
//! times, and its errors named by the option.
//!
//! Means are folded into the written model's offsets; a linear trend is stored in the
//! model's metadata, and the commands that run the model on a record remove it at the
//! record's times ([`remove`]) and add the outputs' trend back to what they return
//! ([`crate::files::DataFile::restored`]).

use crate::error::CliError;
use crate::files::DataFile;
pub use sysid::kalman::Trend;
use sysid::kalman::{LinearGaussianModel, TrendError, TrendKind};

/// The `--detrend` option: `none`, `mean` or `linear`.
pub fn parse(text: &str) -> Result<Option<TrendKind>, CliError> {
    TrendKind::choice(text).map_err(|message| CliError::BadOption {
        option: "--detrend",
        message,
    })
}

/// A detrending error as the option's.
pub fn error(e: TrendError) -> CliError {
    match e {
        TrendError::Model(source) => CliError::Kalman {
            context: "--detrend mean".into(),
            source,
        },
        other => CliError::BadOption {
            option: "--detrend",
            message: other.to_string(),
        },
    }
}

/// Subtracts a trend from a file's record at its times; a linear trend is remembered
/// by the file so that [`DataFile::restored`] can add it back.
pub fn remove(trend: &Trend, file: &mut DataFile) {
    trend.remove_from(&mut file.record, &file.time);
    if trend.kind == TrendKind::Linear {
        file.trend = Some(trend.clone());
    }
}

/// Removes the trend `kind` from a record about to be fitted; the trend, for the
/// written model (`None` for no detrending).
pub fn apply(file: &mut DataFile, kind: Option<TrendKind>) -> Result<Option<Trend>, CliError> {
    let Some(kind) = kind else { return Ok(None) };
    let trend = Trend::estimate(&file.record, &file.time, kind).map_err(error)?;
    remove(&trend, file);
    Ok(Some(trend))
}

/// The model to write for a model fitted on detrended data: means folded in, a
/// linear trend left to the metadata.
pub fn written_model(
    model: &LinearGaussianModel,
    trend: Option<&Trend>,
) -> Result<LinearGaussianModel, CliError> {
    match trend {
        Some(t) => t.written_model(model).map_err(error),
        None => Ok(model.clone()),
    }
}
