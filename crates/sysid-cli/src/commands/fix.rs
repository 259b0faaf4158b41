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

/// The state basis in which the model's `C` is `c`: `T` with `c T = C`, so that
/// `(T A T^-1, T B, C T^-1 = c, D, T Q T', T S, T mu, T P1 T')` is the same model
/// (same likelihood, same input-output behaviour).
///
/// With `c` and `C` of full row rank `p <= n`, `T = [c; W_c]^-1 [C; W_C]`, `W` an
/// orthonormal basis of each row space's complement. `None` when no invertible `T`
/// exists (different ranks, `p > n` with different row spaces).
pub fn basis_for_output_matrix(
    model: &LinearGaussianModel,
    c: &DMatrix<f64>,
) -> Option<DMatrix<f64>> {
    let (n, current) = (model.n(), model.c());
    if c.shape() != current.shape() {
        return None;
    }
    let complete = |m: &DMatrix<f64>| -> Option<DMatrix<f64>> {
        // the rows of m, then an orthonormal basis of its row space's complement
        let svd = m.transpose().svd(true, false);
        let u = svd.u?;
        let tol = n.max(m.nrows()) as f64 * f64::EPSILON * svd.singular_values.max();
        let rank = svd.singular_values.iter().filter(|&&s| s > tol).count();
        if rank != m.nrows() || rank > n {
            return None;
        }
        let row_space = u.columns(0, rank);
        let complement = DMatrix::<f64>::identity(n, n) - row_space * row_space.transpose();
        let eigen = nalgebra::SymmetricEigen::new(complement);
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
        let mut out = DMatrix::zeros(n, n);
        out.rows_mut(0, rank).copy_from(m);
        for (k, &column) in order.iter().take(n - rank).enumerate() {
            out.set_row(rank + k, &eigen.eigenvectors.column(column).transpose());
        }
        Some(out)
    };
    let target = complete(c)?;
    let source = complete(current)?;
    let t = target.lu().solve(&source)?;
    let check = c * &t - current;
    (check.amax() <= 1e-8 * current.amax().max(1.0)).then_some(t)
}

/// `model` in the state basis `t` (`x' = T x`).
pub fn transform_state(
    model: &LinearGaussianModel,
    t: &DMatrix<f64>,
) -> Option<LinearGaussianModel> {
    let t_inv = t.clone().try_inverse()?;
    let congruent = |m: &DMatrix<f64>| {
        let mut out = t * m * t.transpose();
        sysid::linalg::symmetrize(&mut out);
        out
    };
    model
        .to_builder()
        .a(t * model.a() * &t_inv)
        .b(t * model.b())
        .c(model.c() * &t_inv)
        .q(congruent(model.q()))
        .s(t * model.s())
        .mu(t * model.mu())
        .p1(congruent(model.p1()))
        .build()
        .ok()
}

/// The value of a `--fix NAME=VALUE` as a matrix of `shape` (a scalar broadcast).
fn fix_value(
    name: &str,
    value: &FixValue,
    shape: (usize, usize),
) -> Result<DMatrix<f64>, CliError> {
    Ok(match value {
        FixValue::Scalar(x) => DMatrix::from_element(shape.0, shape.1, *x),
        FixValue::Rows(rows) => {
            let cols = rows.first().map_or(0, Vec::len);
            if rows.iter().any(|r| r.len() != cols) || (rows.len(), cols) != shape {
                return Err(CliError::BadOption {
                    option: "--fix",
                    message: format!(
                        "{}: expected a {}x{} value, got {}x{}",
                        name,
                        shape.0,
                        shape.1,
                        rows.len(),
                        cols
                    ),
                });
            }
            DMatrix::from_fn(shape.0, shape.1, |i, j| rows[i][j])
        }
    })
}

/// Applies the `--fix` values to `model` (checking shapes) and the fixes and `--diag`
/// to `spec`. A fixed `C` with a value is reached by a change of state basis of the
/// whole model first (so the other matrices stay consistent with it), when one exists.
pub fn apply(
    model: LinearGaussianModel,
    spec: &mut LinearEmSpec,
    fixes: &[Fix],
    diag: &[String],
) -> Result<LinearGaussianModel, CliError> {
    let mut model = model;
    for fix in fixes {
        if let ("C", Some(value)) = (fix.name, &fix.value) {
            let c = fix_value(fix.name, value, model.c().shape())?;
            if c != *model.c() {
                let t = basis_for_output_matrix(&model, &c).ok_or_else(|| CliError::BadOption {
                    option: "--fix",
                    message: "C: no change of state basis takes the start's C to the given one \
                              (they must have the same rank, and with more outputs than states the \
                              same row space); give a start model in the coordinates of this C \
                              (--init FILE)"
                        .into(),
                })?;
                model = transform_state(&model, &t).ok_or_else(|| CliError::BadOption {
                    option: "--fix",
                    message: "C: the change of state basis is singular".into(),
                })?;
            }
        }
    }
    let mut builder = model.to_builder();
    for fix in fixes {
        let shape = current(&model, fix.name).shape();
        if let Some(value) = &fix.value {
            let m = fix_value(fix.name, value, shape)?;
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
