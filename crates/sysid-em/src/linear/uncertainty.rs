//! Standard errors of a maximum-likelihood fit from the observed information: the
//! negative Hessian of the exact log-likelihood in the model's own entries.

use super::LinearObjective;
use super::{Covariance, LinearEmSpec};
use nalgebra::{DMatrix, DVector};
use sysid_kalman::{KalmanWorkspace, LinearGaussianModel, Record};

/// One free parameter's estimate and its uncertainty.
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterEstimate {
    /// The entry, 1-based: `A[1,2]`, `Q[2,2]`, `h[1]`, ...
    pub name: String,
    /// The estimate.
    pub value: f64,
    /// The standard error `sqrt((I^{-1})_{kk})`, `I` the observed information.
    pub std_error: f64,
}

/// The free parameters' estimates, standard errors and covariance.
#[derive(Debug, Clone, PartialEq)]
pub struct Uncertainty {
    /// One entry per free parameter, in the order of the covariance's rows.
    pub parameters: Vec<ParameterEstimate>,
    /// `I^{-1}`, the inverse observed information.
    pub covariance: DMatrix<f64>,
    /// Log-likelihood evaluations (Kalman filter passes) spent.
    pub evaluations: usize,
}

/// Why standard errors could not be given.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UncertaintyError {
    /// A free `S` (its entries are not parametrised here).
    #[error("standard errors are not available with a free S")]
    FreeCrossCovariance,
    /// The observed information is not positive definite: a direction in which the
    /// likelihood is flat (a model not identifiable in this parametrisation, e.g. a
    /// free `A, B, C` with its `n^2` similarity directions) or not at a maximum.
    #[error(
        "the observed information is singular or indefinite (smallest eigenvalue {smallest:.2e} \
         of {largest:.2e}): {reason}"
    )]
    NotIdentified {
        /// Smallest eigenvalue of the information.
        smallest: f64,
        /// Largest eigenvalue.
        largest: f64,
        /// The likely reason.
        reason: &'static str,
    },
    /// The likelihood could not be evaluated near the estimate (a variance on its
    /// boundary, zero).
    #[error(
        "the log-likelihood cannot be evaluated around the estimate ({0}); a variance at zero?"
    )]
    Evaluation(String),
}

/// A free entry: which matrix, and where (row, column).
#[derive(Debug, Clone, Copy)]
struct Entry {
    matrix: Part,
    row: usize,
    col: usize,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Part {
    A,
    B,
    C,
    D,
    H,
    Mu,
    Q,
    R,
    P1,
}

impl Part {
    fn name(self) -> &'static str {
        match self {
            Part::A => "A",
            Part::B => "B",
            Part::C => "C",
            Part::D => "D",
            Part::H => "h",
            Part::Mu => "mu",
            Part::Q => "Q",
            Part::R => "R",
            Part::P1 => "P1",
        }
    }

    fn of(self, model: &LinearGaussianModel) -> DMatrix<f64> {
        let column = |v: &DVector<f64>| DMatrix::from_column_slice(v.len(), 1, v.as_slice());
        match self {
            Part::A => model.a().clone(),
            Part::B => model.b().clone(),
            Part::C => model.c().clone(),
            Part::D => model.d().clone(),
            Part::H => column(model.h()),
            Part::Mu => column(model.mu()),
            Part::Q => model.q().clone(),
            Part::R => model.r().clone(),
            Part::P1 => model.p1().clone(),
        }
    }

    fn is_covariance(self) -> bool {
        matches!(self, Part::Q | Part::R | Part::P1)
    }
}

/// The free entries of `spec` at `model`: every free entry of `A, B, C, D`, `h` and
/// `mu`; the upper triangle of a full covariance, the diagonal of a diagonal one
/// (structural zeros of the estimate, at most 1e-12 of the largest variance, held).
fn free_entries(model: &LinearGaussianModel, spec: &LinearEmSpec) -> Vec<Entry> {
    let mut out = Vec::new();
    let masks = [
        (Part::A, spec.a, &spec.fixed_entries.a),
        (Part::B, spec.b, &spec.fixed_entries.b),
        (Part::C, spec.c, &spec.fixed_entries.c),
        (Part::D, spec.d, &spec.fixed_entries.d),
    ];
    for (part, free, mask) in masks {
        if !free {
            continue;
        }
        let m = part.of(model);
        for col in 0..m.ncols() {
            for row in 0..m.nrows() {
                let k = col * m.nrows() + row;
                if mask.as_ref().is_none_or(|mask| !mask[k]) {
                    out.push(Entry {
                        matrix: part,
                        row,
                        col,
                    });
                }
            }
        }
    }
    for (part, free) in [(Part::H, spec.h), (Part::Mu, spec.mu)] {
        if free {
            out.extend((0..part.of(model).nrows()).map(|row| Entry {
                matrix: part,
                row,
                col: 0,
            }));
        }
    }
    let p1 = if spec.p1 {
        Covariance::Full
    } else {
        Covariance::Fixed
    };
    for (part, structure) in [(Part::Q, spec.q), (Part::R, spec.r), (Part::P1, p1)] {
        let m = part.of(model);
        let largest = m.diagonal().amax();
        match structure {
            Covariance::Fixed => {}
            Covariance::Diagonal => {
                out.extend(
                    (0..m.nrows())
                        .filter(|&i| m[(i, i)] > 1e-12 * largest)
                        .map(|i| Entry {
                            matrix: part,
                            row: i,
                            col: i,
                        }),
                );
            }
            Covariance::Full => {
                for col in 0..m.ncols() {
                    for row in 0..=col {
                        out.push(Entry {
                            matrix: part,
                            row,
                            col,
                        });
                    }
                }
            }
        }
    }
    out
}

/// `model` with the free entries moved by `delta` (symmetric entries of a covariance
/// both); `None` if that is not a valid model.
fn moved(
    model: &LinearGaussianModel,
    entries: &[Entry],
    delta: &[f64],
) -> Option<LinearGaussianModel> {
    let parts = [
        Part::A,
        Part::B,
        Part::C,
        Part::D,
        Part::H,
        Part::Mu,
        Part::Q,
        Part::R,
        Part::P1,
    ];
    let mut builder = model.to_builder();
    for part in parts {
        if !entries
            .iter()
            .zip(delta)
            .any(|(e, &d)| e.matrix == part && d != 0.0)
        {
            continue;
        }
        let mut m = part.of(model);
        for (e, &d) in entries.iter().zip(delta) {
            if e.matrix == part && d != 0.0 {
                m[(e.row, e.col)] += d;
                if part.is_covariance() && e.row != e.col {
                    m[(e.col, e.row)] += d;
                }
            }
        }
        builder = match part {
            Part::A => builder.a(m),
            Part::B => builder.b(m),
            Part::C => builder.c(m),
            Part::D => builder.d(m),
            Part::H => builder.h(m.column(0).clone_owned()),
            Part::Mu => builder.mu(m.column(0).clone_owned()),
            Part::Q => builder.q(m),
            Part::R => builder.r(m),
            Part::P1 => builder.p1(m),
        };
    }
    builder.build().ok()
}

/// Standard errors of `spec`'s free parameters at the estimate `model`, from the
/// observed information `I = -H`, `H` the Hessian of the exact log-likelihood of the
/// records in the model's own entries (a covariance by its upper triangle), by central
/// differences: `H_kl ~ [f(+,+) - f(+,-) - f(-,+) + f(-,-)] / (4 h_k h_l)` and
/// `H_kk ~ [f(+2) - 2 f + f(-2)] / (4 h_k^2)`, with steps `h_k = 1e-4 max(|theta_k|,
/// s_k)` (`s_k` the scale of the entry's matrix). statsmodels' `MLEModel` default
/// (`cov_type="approx"`) is the same quantity, by complex-step differences of its own
/// parameters. The estimate must be an interior maximum: on a boundary (a variance at
/// zero) the information says nothing.
///
/// # Errors
/// [`UncertaintyError::NotIdentified`] when `I` is not positive definite (a flat
/// direction: black-box `A, B, C` have `n^2` of them); the others when the likelihood
/// cannot be evaluated near the estimate or `S` is free.
pub fn standard_errors(
    model: &LinearGaussianModel,
    records: &[Record],
    spec: &LinearEmSpec,
) -> Result<Uncertainty, UncertaintyError> {
    standard_errors_of(
        model,
        &LinearObjective::new(records, sysid_kalman::InitialState::Given),
        spec,
    )
}

/// [`standard_errors`] of the log-likelihood `objective` (the written model's, with the
/// initial state its file gives each record: what a fit reports).
///
/// # Errors
/// As [`standard_errors`].
pub fn standard_errors_of(
    model: &LinearGaussianModel,
    objective: &LinearObjective<'_>,
    spec: &LinearEmSpec,
) -> Result<Uncertainty, UncertaintyError> {
    if spec.s {
        return Err(UncertaintyError::FreeCrossCovariance);
    }
    let entries = free_entries(model, spec);
    let k = entries.len();
    let theta: Vec<f64> = entries
        .iter()
        .map(|e| e.matrix.of(model)[(e.row, e.col)])
        .collect();
    let steps: Vec<f64> = entries
        .iter()
        .zip(&theta)
        .map(|(e, &v)| {
            let scale = e.matrix.of(model).amax().max(f64::MIN_POSITIVE);
            1e-4 * v.abs().max(if e.matrix.is_covariance() {
                1e-3 * scale
            } else {
                scale
            })
        })
        .collect();
    let mut evaluations = 0;
    let mut ws = KalmanWorkspace::new();
    // the differences must not see the steady-state reuse's switch points
    ws.set_steady_state_reuse(false);
    let mut f = |delta: &[f64]| -> Result<f64, UncertaintyError> {
        evaluations += 1;
        let m = moved(model, &entries, delta)
            .ok_or_else(|| UncertaintyError::Evaluation("a step leaves the valid models".into()))?;
        objective
            .loglik(&m, &mut ws)
            .map_err(|e| UncertaintyError::Evaluation(e.to_string()))
    };
    let f0 = f(&vec![0.0; k])?;
    let mut hessian = DMatrix::zeros(k, k);
    let mut delta = vec![0.0; k];
    for a in 0..k {
        delta[a] = 2.0 * steps[a];
        let plus = f(&delta)?;
        delta[a] = -2.0 * steps[a];
        let minus = f(&delta)?;
        delta[a] = 0.0;
        hessian[(a, a)] = (plus - 2.0 * f0 + minus) / (4.0 * steps[a] * steps[a]);
        for b in 0..a {
            let mut corner = |sa: f64, sb: f64| {
                delta[a] = sa * steps[a];
                delta[b] = sb * steps[b];
                let v = f(&delta);
                delta[a] = 0.0;
                delta[b] = 0.0;
                v
            };
            let v = (corner(1.0, 1.0)? - corner(1.0, -1.0)? - corner(-1.0, 1.0)?
                + corner(-1.0, -1.0)?)
                / (4.0 * steps[a] * steps[b]);
            hessian[(a, b)] = v;
            hessian[(b, a)] = v;
        }
    }
    let information = -hessian;
    let eig = information.clone().symmetric_eigen();
    let (smallest, largest) = (eig.eigenvalues.min(), eig.eigenvalues.max());
    if !(smallest > 1e-10 * largest && largest > 0.0) {
        let black_box = spec.a && spec.c && model.n() > 1;
        return Err(UncertaintyError::NotIdentified {
            smallest,
            largest,
            reason: if black_box {
                "a free A and C are not identifiable (any change of state basis gives the \
                 same likelihood); fix C (--fix C=...) or report the transfer function"
            } else {
                "a parameter the data do not determine, or not at a maximum"
            },
        });
    }
    let inv_values = eig.eigenvalues.map(|v| 1.0 / v);
    let covariance =
        &eig.eigenvectors * DMatrix::from_diagonal(&inv_values) * eig.eigenvectors.transpose();
    let parameters = entries
        .iter()
        .zip(&theta)
        .enumerate()
        .map(|(i, (e, &value))| ParameterEstimate {
            name: if e.matrix == Part::H || e.matrix == Part::Mu {
                format!("{}[{}]", e.matrix.name(), e.row + 1)
            } else {
                format!("{}[{},{}]", e.matrix.name(), e.row + 1, e.col + 1)
            },
            value,
            std_error: covariance[(i, i)].max(0.0).sqrt(),
        })
        .collect();
    Ok(Uncertainty {
        parameters,
        covariance,
        evaluations,
    })
}
