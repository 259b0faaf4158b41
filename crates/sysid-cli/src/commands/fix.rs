//! Parsing `--fix NAME=VALUE|NAME` and `--diag Q,R` for `sysid fit lti`.

use crate::error::CliError;
use nalgebra::{DMatrix, DVector};
use sysid::em::linear::{Covariance, LinearEmSpec};
use sysid::kalman::LinearGaussianModel;

/// The matrices a user may name, as written in the model file.
pub const NAMES: [&str; 10] = ["A", "B", "C", "D", "h", "Q", "R", "S", "mu", "P1"];

/// One `--fix` argument: the matrix and, optionally, its value.
#[derive(Debug, Clone)]
pub struct Fix {
    pub name: &'static str,
    pub value: Option<FixValue>,
}

#[derive(Debug, Clone)]
pub enum FixValue {
    /// A scalar broadcast over the matrix.
    Scalar(f64),
    /// A matrix (array of rows) or vector.
    Rows(Vec<Vec<f64>>),
}

fn canonical(name: &str) -> Option<&'static str> {
    NAMES.iter().copied().find(|n| n.eq_ignore_ascii_case(name))
}

/// Parses `NAME` or `NAME=VALUE`; VALUE is a number or JSON (`[[1, 0], [0, 1]]`, `[1, 2]`).
pub fn parse_fix(arg: &str) -> Result<Fix, CliError> {
    let (name, value) = match arg.split_once('=') {
        Some((n, v)) => (n.trim(), Some(v.trim())),
        None => (arg.trim(), None),
    };
    let name = canonical(name).ok_or_else(|| CliError::BadOption {
        option: "--fix",
        message: format!("unknown matrix {name:?} (known: {})", NAMES.join(", ")),
    })?;
    let value = match value {
        None => None,
        Some(v) => Some(if let Ok(x) = v.parse::<f64>() {
            FixValue::Scalar(x)
        } else if let Ok(rows) = serde_json::from_str::<Vec<Vec<f64>>>(v) {
            FixValue::Rows(rows)
        } else if let Ok(vector) = serde_json::from_str::<Vec<f64>>(v) {
            FixValue::Rows(vector.into_iter().map(|x| vec![x]).collect())
        } else {
            return Err(CliError::BadOption {
                option: "--fix",
                message: format!("{name}: cannot read {v:?} as a number or a JSON matrix"),
            });
        }),
    };
    Ok(Fix { name, value })
}

/// The current value of a named matrix (vectors as one column).
fn current(model: &LinearGaussianModel, name: &str) -> DMatrix<f64> {
    let column = |v: &DVector<f64>| DMatrix::from_column_slice(v.len(), 1, v.as_slice());
    match name {
        "A" => model.a().clone(),
        "B" => model.b().clone(),
        "C" => model.c().clone(),
        "D" => model.d().clone(),
        "h" => column(model.h()),
        "Q" => model.q().clone(),
        "R" => model.r().clone(),
        "S" => model.s().clone(),
        "mu" => column(model.mu()),
        _ => model.p1().clone(),
    }
}

/// Applies the `--fix` values to `model` (checking shapes) and the fixes and `--diag`
/// to `spec`.
pub fn apply(
    model: LinearGaussianModel,
    spec: &mut LinearEmSpec,
    fixes: &[Fix],
    diag: &[String],
) -> Result<LinearGaussianModel, CliError> {
    let mut builder = model.to_builder();
    for fix in fixes {
        let shape = current(&model, fix.name).shape();
        if let Some(value) = &fix.value {
            let m = match value {
                FixValue::Scalar(x) => DMatrix::from_element(shape.0, shape.1, *x),
                FixValue::Rows(rows) => {
                    let cols = rows.first().map_or(0, Vec::len);
                    if rows.iter().any(|r| r.len() != cols) || (rows.len(), cols) != shape {
                        return Err(CliError::BadOption {
                            option: "--fix",
                            message: format!(
                                "{}: expected a {}x{} value, got {}x{}",
                                fix.name,
                                shape.0,
                                shape.1,
                                rows.len(),
                                cols
                            ),
                        });
                    }
                    DMatrix::from_fn(shape.0, shape.1, |i, j| rows[i][j])
                }
            };
            let v = DVector::from_column_slice(m.as_slice());
            builder = match fix.name {
                "A" => builder.a(m),
                "B" => builder.b(m),
                "C" => builder.c(m),
                "D" => builder.d(m),
                "h" => builder.h(v),
                "Q" => builder.q(m),
                "R" => builder.r(m),
                "S" => builder.s(m),
                "mu" => builder.mu(v),
                _ => builder.p1(m),
            };
        }
        match fix.name {
            "A" => spec.a = false,
            "B" => spec.b = false,
            "C" => spec.c = false,
            "D" => spec.d = false,
            "h" => spec.h = false,
            "Q" => spec.q = Covariance::Fixed,
            "R" => spec.r = Covariance::Fixed,
            "mu" => spec.mu = false,
            "P1" => spec.p1 = false,
            _ => {} // S is always held fixed by linear EM
        }
    }
    for name in diag {
        match canonical(name.trim()) {
            Some("Q") if spec.q != Covariance::Fixed => spec.q = Covariance::Diagonal,
            Some("R") if spec.r != Covariance::Fixed => spec.r = Covariance::Diagonal,
            Some("Q") | Some("R") => {}
            _ => {
                return Err(CliError::BadOption {
                    option: "--diag",
                    message: format!("{name:?}: only Q and R can be diagonal"),
                });
            }
        }
    }
    builder.build().map_err(|source| CliError::Kalman {
        context: "--fix".into(),
        source,
    })
}
