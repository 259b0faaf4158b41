//! Holding matrices fixed, at their start's value or at a value of the user's.

use super::LinearFitError;
use crate::linear::{Covariance, LinearEmSpec};
use nalgebra::{DMatrix, DVector};
use sysid_kalman::LinearGaussianModel;

/// A matrix of the linear Gaussian model, as named in a model file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Matrix {
    /// The state transition `A`.
    A,
    /// The input matrix `B`.
    B,
    /// The output matrix `C`.
    C,
    /// The feedthrough `D`.
    D,
    /// The output offset `h`.
    H,
    /// The process noise covariance `Q`.
    Q,
    /// The output noise covariance `R`.
    R,
    /// The cross-covariance `S` (always held by linear EM).
    S,
    /// The initial state's mean `mu`.
    Mu,
    /// The initial state's covariance `P1`.
    P1,
}

impl Matrix {
    /// Every matrix, in the model file's order.
    pub const ALL: [Matrix; 10] = [
        Matrix::A,
        Matrix::B,
        Matrix::C,
        Matrix::D,
        Matrix::H,
        Matrix::Q,
        Matrix::R,
        Matrix::S,
        Matrix::Mu,
        Matrix::P1,
    ];

    /// The name in a model file: `A`, `h`, `mu`, `P1`, ...
    pub fn name(self) -> &'static str {
        match self {
            Matrix::A => "A",
            Matrix::B => "B",
            Matrix::C => "C",
            Matrix::D => "D",
            Matrix::H => "h",
            Matrix::Q => "Q",
            Matrix::R => "R",
            Matrix::S => "S",
            Matrix::Mu => "mu",
            Matrix::P1 => "P1",
        }
    }

    /// The matrix of a name, ignoring case (`p1`, `MU`).
    pub fn from_name(name: &str) -> Option<Matrix> {
        Matrix::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(name))
    }

    /// A covariance that may be estimated as diagonal (`Q` or `R`), by name.
    ///
    /// # Errors
    /// The message for any other name.
    pub fn diagonal_from_name(name: &str) -> Result<Matrix, String> {
        match Matrix::from_name(name.trim()) {
            Some(m @ (Matrix::Q | Matrix::R)) => Ok(m),
            _ => Err(Matrix::not_diagonal(name)),
        }
    }

    /// Why `name` cannot be diagonal.
    pub(crate) fn not_diagonal(name: &str) -> String {
        format!("{name:?}: only Q and R can be diagonal")
    }

    /// Its current value in `model` (vectors as one column).
    fn of(self, model: &LinearGaussianModel) -> DMatrix<f64> {
        let column = |v: &DVector<f64>| DMatrix::from_column_slice(v.len(), 1, v.as_slice());
        match self {
            Matrix::A => model.a().clone(),
            Matrix::B => model.b().clone(),
            Matrix::C => model.c().clone(),
            Matrix::D => model.d().clone(),
            Matrix::H => column(model.h()),
            Matrix::Q => model.q().clone(),
            Matrix::R => model.r().clone(),
            Matrix::S => model.s().clone(),
            Matrix::Mu => column(model.mu()),
            Matrix::P1 => model.p1().clone(),
        }
    }
}

impl std::str::FromStr for Matrix {
    type Err = String;

    /// A matrix by its name, ignoring case; the error lists the names.
    fn from_str(name: &str) -> Result<Matrix, String> {
        Matrix::from_name(name.trim()).ok_or_else(|| {
            format!(
                "unknown matrix {name:?} (known: {})",
                Matrix::ALL.map(Matrix::name).join(", ")
            )
        })
    }
}

impl std::fmt::Display for Matrix {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The value a fixed matrix is held at.
#[derive(Debug, Clone, PartialEq)]
pub enum FixValue {
    /// A number broadcast over the matrix.
    Scalar(f64),
    /// A matrix as its rows (a vector as rows of one entry).
    Rows(Vec<Vec<f64>>),
}

/// One matrix held fixed: at the start's value (`value: None`) or at a given one.
#[derive(Debug, Clone, PartialEq)]
pub struct Fix {
    /// The matrix.
    pub matrix: Matrix,
    /// Its value, or `None` for the start's.
    pub value: Option<FixValue>,
}

impl Fix {
    /// `matrix` held at the start's value.
    pub fn at_start(matrix: Matrix) -> Fix {
        Fix {
            matrix,
            value: None,
        }
    }

    /// `matrix` held at `value`.
    pub fn at(matrix: Matrix, value: FixValue) -> Fix {
        Fix {
            matrix,
            value: Some(value),
        }
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

/// `model` in the state basis `t` (`x' = T x`); `None` for a singular `t`.
pub fn transform_state(
    model: &LinearGaussianModel,
    t: &DMatrix<f64>,
) -> Option<LinearGaussianModel> {
    let t_inv = t.clone().try_inverse()?;
    let congruent = |m: &DMatrix<f64>| {
        let mut out = t * m * t.transpose();
        sysid_linalg::symmetrize(&mut out);
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

fn fix_error(message: String) -> LinearFitError {
    LinearFitError::InvalidOption {
        option: "fix",
        message,
    }
}

/// A fixed value as a matrix of `shape` (a scalar broadcast).
fn fix_value(
    matrix: Matrix,
    value: &FixValue,
    shape: (usize, usize),
) -> Result<DMatrix<f64>, LinearFitError> {
    Ok(match value {
        FixValue::Scalar(x) => DMatrix::from_element(shape.0, shape.1, *x),
        FixValue::Rows(rows) => {
            let cols = rows.first().map_or(0, Vec::len);
            if rows.iter().any(|r| r.len() != cols) || (rows.len(), cols) != shape {
                return Err(fix_error(format!(
                    "{matrix}: expected a {}x{} value, got {}x{}",
                    shape.0,
                    shape.1,
                    rows.len(),
                    cols
                )));
            }
            DMatrix::from_fn(shape.0, shape.1, |i, j| rows[i][j])
        }
    })
}

/// Applies the fixed values to `model` (checking shapes) and the fixes and diagonal
/// covariances to `spec`. A fixed `C` with a value is reached by a change of state
/// basis of the whole model first (so the other matrices stay consistent with it),
/// when one exists.
pub(super) fn apply(
    model: LinearGaussianModel,
    spec: &mut LinearEmSpec,
    fixes: &[Fix],
    diagonal: &[Matrix],
) -> Result<LinearGaussianModel, LinearFitError> {
    let mut model = model;
    for fix in fixes {
        if let (Matrix::C, Some(value)) = (fix.matrix, &fix.value) {
            let c = fix_value(fix.matrix, value, model.c().shape())?;
            if c != *model.c() {
                let t = basis_for_output_matrix(&model, &c).ok_or_else(|| {
                    fix_error(
                        "C: no change of state basis takes the start's C to the given one (they \
                         must have the same rank, and with more outputs than states the same row \
                         space); give a start model in the coordinates of this C"
                            .into(),
                    )
                })?;
                model = transform_state(&model, &t)
                    .ok_or_else(|| fix_error("C: the change of state basis is singular".into()))?;
            }
        }
    }
    let mut builder = model.to_builder();
    for fix in fixes {
        let shape = fix.matrix.of(&model).shape();
        if let Some(value) = &fix.value {
            let m = fix_value(fix.matrix, value, shape)?;
            let v = DVector::from_column_slice(m.as_slice());
            builder = match fix.matrix {
                Matrix::A => builder.a(m),
                Matrix::B => builder.b(m),
                Matrix::C => builder.c(m),
                Matrix::D => builder.d(m),
                Matrix::H => builder.h(v),
                Matrix::Q => builder.q(m),
                Matrix::R => builder.r(m),
                Matrix::S => builder.s(m),
                Matrix::Mu => builder.mu(v),
                Matrix::P1 => builder.p1(m),
            };
        }
        match fix.matrix {
            Matrix::A => spec.a = false,
            Matrix::B => spec.b = false,
            Matrix::C => spec.c = false,
            Matrix::D => spec.d = false,
            Matrix::H => spec.h = false,
            Matrix::Q => spec.q = Covariance::Fixed,
            Matrix::R => spec.r = Covariance::Fixed,
            Matrix::Mu => spec.mu = false,
            Matrix::P1 => spec.p1 = false,
            Matrix::S => {} // S is always held fixed by linear EM
        }
    }
    for matrix in diagonal {
        match matrix {
            Matrix::Q if spec.q != Covariance::Fixed => spec.q = Covariance::Diagonal,
            Matrix::R if spec.r != Covariance::Fixed => spec.r = Covariance::Diagonal,
            Matrix::Q | Matrix::R => {}
            other => {
                return Err(LinearFitError::InvalidOption {
                    option: "diag",
                    message: Matrix::not_diagonal(other.name()),
                });
            }
        }
    }
    builder.build().map_err(|source| LinearFitError::Kalman {
        context: "fixed values",
        source,
    })
}
