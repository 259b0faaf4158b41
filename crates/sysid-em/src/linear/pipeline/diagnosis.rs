//! Why a fit is not to be trusted or failed: a noise covariance collapsing to a
//! singular one, collinear inputs.

use super::Signals;
use crate::linear::{Covariance, LinearEmSpec};
use nalgebra::DMatrix;
use sysid_kalman::{LinearGaussianModel, stationary_covariance};

/// A variance below this fraction of its scale is numerically zero for EM's
/// statistics.
const SINGULAR: f64 = 1e-10;

/// A free `R` whose smallest variance is below this fraction of the outputs' variance
/// is collapsing: EM is walking to the boundary `R = 0` (the states absorb the
/// measurement noise; on the README tour's record R ends at 5e-7 of the outputs'
/// variance, truth 0.05, and bounding it at 1e-3 of it raises the likelihood of a
/// fresh record from 302.6 to 317.1). A real sensor this quiet (an output 300 times its noise's sd) is
/// rare, and the warning only advises a bound.
const R_COLLAPSING: f64 = 1e-5;

/// A noise covariance (or `P1`) that is numerically singular, with a description.
#[derive(Debug, Clone, PartialEq)]
pub struct SingularPart {
    /// `R`, `Q` or `P1`.
    pub matrix: &'static str,
    /// How small it is, relative to its scale.
    pub description: String,
}

/// The noise covariances (and `P1`) of `model` that are numerically singular: `R`
/// relative to the outputs' sample variances (so a scalar `R` is caught too), `Q` and
/// `P1` relative to the state's scale (the largest eigenvalue of `Q`, `P1` or the
/// stationary covariance).
pub(super) fn singular_parts(model: &LinearGaussianModel, data: &Signals) -> Vec<SingularPart> {
    let smallest = |m: &DMatrix<f64>| {
        if m.nrows() == 0 {
            return f64::INFINITY;
        }
        nalgebra::SymmetricEigen::new(m.clone()).eigenvalues.min()
    };
    let largest = |m: &DMatrix<f64>| {
        if m.nrows() == 0 {
            return 0.0;
        }
        nalgebra::SymmetricEigen::new(m.clone()).eigenvalues.max()
    };
    let state_scale = largest(model.q())
        .max(largest(model.p1()))
        .max(stationary_covariance(model.a(), model.q()).map_or(0.0, |p| largest(&p)));
    let mut out = Vec::new();
    let r_low = whitened_r_low(model, data);
    if r_low < SINGULAR {
        out.push(SingularPart {
            matrix: "R",
            description: format!("R's smallest variance is {r_low:.1e} of the outputs' variance"),
        });
    }
    for (name, m) in [("Q", model.q()), ("P1", model.p1())] {
        // rows and columns that are exactly zero are structure (a deterministic state)
        let kept: Vec<usize> = (0..m.nrows()).filter(|&i| m[(i, i)] != 0.0).collect();
        let sub = DMatrix::from_fn(kept.len(), kept.len(), |i, j| m[(kept[i], kept[j])]);
        let low = smallest(&sub);
        if !kept.is_empty() && state_scale > 0.0 && low < SINGULAR * state_scale {
            out.push(SingularPart {
                matrix: name,
                description: format!(
                    "{name}'s smallest eigenvalue is {:.1e} of the state's scale",
                    low / state_scale
                ),
            });
        }
    }
    out
}

/// The smallest eigenvalue of `R` scaled by the outputs' standard deviations.
fn whitened_r_low(model: &LinearGaussianModel, data: &Signals) -> f64 {
    let var = data.record.output_variances();
    let r = model.r();
    if r.nrows() == 0 {
        return f64::INFINITY;
    }
    let whitened = DMatrix::from_fn(r.nrows(), r.ncols(), |i, j| {
        r[(i, j)] / (var[i] * var[j]).sqrt().max(f64::MIN_POSITIVE)
    });
    nalgebra::SymmetricEigen::new(whitened).eigenvalues.min()
}

/// [`singular_parts`] that EM estimates (a held part is the user's choice).
pub(super) fn estimated_singular_parts(
    model: &LinearGaussianModel,
    data: &Signals,
    spec: &LinearEmSpec,
) -> Vec<SingularPart> {
    singular_parts(model, data)
        .into_iter()
        .filter(|part| match part.matrix {
            "R" => spec.r != Covariance::Fixed,
            "Q" => spec.q != Covariance::Fixed,
            _ => spec.p1,
        })
        .collect()
}

/// Free variances that have (numerically) collapsed to zero: a vanishing `R`, or the
/// `Q` of a single state (a singular `Q` of several states is a valid model: an
/// innovation form has rank `p`).
pub(super) fn collapsed(
    model: &LinearGaussianModel,
    spec: &LinearEmSpec,
    data: &Signals,
) -> Vec<SingularPart> {
    let mut parts: Vec<SingularPart> = singular_parts(model, data)
        .into_iter()
        .filter(|part| match part.matrix {
            "R" => spec.r != Covariance::Fixed,
            "Q" => spec.q != Covariance::Fixed && model.n() == 1,
            _ => false,
        })
        .collect();
    // not yet numerically singular, but on its way to the boundary
    let r_low = whitened_r_low(model, data);
    if spec.r != Covariance::Fixed
        && (SINGULAR..R_COLLAPSING).contains(&r_low)
        && spec.output_noise_floor.is_none()
    {
        parts.push(SingularPart {
            matrix: "R",
            description: format!(
                "R's smallest variance is {r_low:.1e} of the outputs' variance (under \
                 {R_COLLAPSING:.0e})"
            ),
        });
    }
    parts
}

/// Whether two or more inputs are collinear over the record (or one is constant):
/// the smallest singular value of the centred inputs relative to the largest.
fn collinear_inputs(data: &Signals) -> Option<String> {
    let u = &data.record.u;
    if u.nrows() < 1 || u.ncols() < 2 {
        return None;
    }
    let centred = DMatrix::from_fn(u.nrows(), u.ncols(), |i, t| u[(i, t)] - u.row(i).mean());
    let s = centred.singular_values();
    (s.min() <= 1e-10 * s.max().max(f64::MIN_POSITIVE)).then(|| {
        format!(
            "the inputs ({}) are collinear or one is constant (smallest/largest singular value \
             {:.1e}): drop the redundant input column",
            data.input_names.join(", "),
            s.min() / s.max().max(f64::MIN_POSITIVE)
        )
    })
}

/// The option that bounds a singular part.
pub(super) fn bound_option(matrix: &str) -> &'static str {
    match matrix {
        "R" => "--min-output-noise 1e-4, or --min-variance",
        "Q" => "--min-variance (e.g. 1e-6 of the output variance)",
        _ => "do not estimate P1: drop --estimate-initial",
    }
}

/// Why exact EM may have lowered the likelihood (or failed) at `model`: a noise
/// covariance or `P1` that is numerically singular (the statistics no longer resolve
/// its small direction), collinear inputs, or, if none of these, a request for a bug
/// report. The flag is whether a cause was found (the data's, with an option that
/// avoids it).
pub(super) fn decrease_diagnosis(
    model: &LinearGaussianModel,
    data: &Signals,
    spec: &LinearEmSpec,
) -> (String, bool) {
    let singular = estimated_singular_parts(model, data, spec);
    let data_cause = !singular.is_empty();
    let mut causes: Vec<String> = singular
        .into_iter()
        .map(|part| {
            format!(
                "{}: the likelihood is rising towards a singular {}, where rounding dominates \
                 the M-step; bound it ({})",
                part.description,
                part.matrix,
                bound_option(part.matrix)
            )
        })
        .collect();
    causes.extend(collinear_inputs(data));
    if causes.is_empty() {
        ("this is a bug, please report it".into(), data_cause)
    } else {
        (causes.join("; "), data_cause)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dmatrix;
    use sysid_kalman::Record;

    fn outputs() -> Signals {
        let y = DMatrix::from_fn(2, 50, |i, t| ((t * (i + 2)) as f64 * 0.7).sin());
        Signals::new(Record::new(DMatrix::zeros(0, 50), y))
    }

    fn model(r_small: f64) -> LinearGaussianModel {
        LinearGaussianModel::builder(
            dmatrix![0.5],
            dmatrix![1.0; 0.5],
            dmatrix![1.0],
            dmatrix![1.0, 0.0; 0.0, r_small],
        )
        .build()
        .unwrap()
    }

    #[test]
    fn a_decrease_at_a_singular_r_points_to_the_variance_floor() {
        let (message, data_cause) =
            decrease_diagnosis(&model(1e-14), &outputs(), &LinearEmSpec::default());
        assert!(message.contains("towards a singular R"), "{message}");
        assert!(message.contains("--min-output-noise"), "{message}");
        assert!(data_cause);
        let (message, data_cause) =
            decrease_diagnosis(&model(0.1), &outputs(), &LinearEmSpec::default());
        assert!(message.contains("bug") && !data_cause, "{message}");
    }

    #[test]
    fn a_scalar_r_going_to_zero_is_named() {
        let m = LinearGaussianModel::builder(
            dmatrix![0.5],
            dmatrix![1.0],
            dmatrix![1.0],
            dmatrix![1e-13],
        )
        .build()
        .unwrap();
        let y = DMatrix::from_fn(1, 50, |_, t| (t as f64 * 0.7).sin());
        let data = Signals::new(Record::new(DMatrix::zeros(0, 50), y));
        let (message, _) = decrease_diagnosis(&m, &data, &LinearEmSpec::default());
        assert!(message.contains("singular R"), "{message}");
    }

    #[test]
    fn collinear_inputs_are_named() {
        let m = LinearGaussianModel::builder(
            dmatrix![0.5],
            dmatrix![1.0],
            dmatrix![1.0],
            dmatrix![0.3],
        )
        .b(dmatrix![1.0, 1.0])
        .build()
        .unwrap();
        let u = DMatrix::from_fn(2, 50, |_, t| (t as f64 * 0.3).sin());
        let y = DMatrix::from_fn(1, 50, |_, t| (t as f64 * 0.7).sin());
        let data = Signals::new(Record::new(u, y));
        let (message, data_cause) = decrease_diagnosis(&m, &data, &LinearEmSpec::default());
        assert!(message.contains("collinear"), "{message}");
        assert!(message.contains("u1, u2"), "{message}");
        assert!(!data_cause);
    }
}
