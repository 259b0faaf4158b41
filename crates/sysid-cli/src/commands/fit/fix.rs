//! Reading `--fix NAME=VALUE|NAME` and `--diag Q,R` of `sysid fit lti` into the
//! library's [`Fix`] and [`Matrix`].

use crate::error::CliError;
use sysid::em::linear::{Fix, FixValue, Matrix};

/// Parses `NAME` or `NAME=VALUE`; VALUE is a number or JSON (`[[1, 0], [0, 1]]`, `[1, 2]`).
pub fn parse_fix(arg: &str) -> Result<Fix, CliError> {
    let (name, value) = match arg.split_once('=') {
        Some((n, v)) => (n.trim(), Some(v.trim())),
        None => (arg.trim(), None),
    };
    let matrix = name
        .parse::<Matrix>()
        .map_err(|message| CliError::BadOption {
            option: "--fix",
            message,
        })?;
    let Some(v) = value else {
        return Ok(Fix::at_start(matrix));
    };
    let value = if let Ok(x) = v.parse::<f64>() {
        FixValue::Scalar(x)
    } else if let Ok(rows) = serde_json::from_str::<Vec<Vec<f64>>>(v) {
        FixValue::Rows(rows)
    } else if let Ok(vector) = serde_json::from_str::<Vec<f64>>(v) {
        FixValue::Rows(vector.into_iter().map(|x| vec![x]).collect())
    } else {
        return Err(CliError::BadOption {
            option: "--fix",
            message: format!("{matrix}: cannot read {v:?} as a number or a JSON matrix"),
        });
    };
    Ok(Fix::at(matrix, value))
}

/// Parses a `--diag` name: `Q` or `R`.
pub fn parse_diagonal(name: &str) -> Result<Matrix, CliError> {
    Matrix::diagonal_from_name(name).map_err(|message| CliError::BadOption {
        option: "--diag",
        message,
    })
}
