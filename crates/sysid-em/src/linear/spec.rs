//! What linear EM estimates and what it holds fixed.

use super::LinearEmError;
use nalgebra::DMatrix;
use sysid_kalman::LinearGaussianModel;

/// Structure of a free noise covariance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Covariance {
    /// A full symmetric positive semi-definite matrix.
    #[default]
    Full,
    /// A diagonal matrix (independent noise components).
    Diagonal,
    /// Held at its initial value.
    Fixed,
}

/// Individual entries of `A`, `B`, `C`, `D` held at their initial values while the rest
/// of the matrix is estimated (`true` = fixed); shapes as the matrices.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct FixedEntries {
    /// Mask of `A` (n x n).
    pub a: Option<DMatrix<bool>>,
    /// Mask of `B` (n x m).
    pub b: Option<DMatrix<bool>>,
    /// Mask of `C` (p x n).
    pub c: Option<DMatrix<bool>>,
    /// Mask of `D` (p x m).
    pub d: Option<DMatrix<bool>>,
}

/// Which parameters of a [`sysid_kalman::LinearGaussianModel`] EM estimates; everything
/// not estimated is held at its value in the initial model.
///
/// The default estimates `A`, `B`, `C`, `D`, `h`, full `Q` and `R`, `mu` and `P1`, and
/// holds the cross-covariance `S` (usually zero). Fixed individual entries
/// ([`FixedEntries`]) and a free `S` (which needs full `Q` and `R`) make the M-step a
/// conditional maximisation (ECM).
///
/// # Example
/// ```
/// use sysid_em::linear::{Covariance, LinearEmSpec};
/// // D = 0 and h = 0 kept, diagonal R
/// let spec = LinearEmSpec { d: false, h: false, r: Covariance::Diagonal, ..LinearEmSpec::default() };
/// assert!(spec.a && !spec.d);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct LinearEmSpec {
    /// Estimate `A`.
    pub a: bool,
    /// Estimate `B`.
    pub b: bool,
    /// Estimate `C`.
    pub c: bool,
    /// Estimate `D`.
    pub d: bool,
    /// Estimate the output offset `h`.
    pub h: bool,
    /// Structure of `Q`.
    pub q: Covariance,
    /// Structure of `R`.
    pub r: Covariance,
    /// Estimate the initial mean `mu`.
    pub mu: bool,
    /// Estimate the initial covariance `P1`.
    pub p1: bool,
    /// Estimate the cross-covariance `S` (requires full `Q` and `R`).
    pub s: bool,
    /// Entries of `A`, `B`, `C`, `D` held fixed.
    pub fixed_entries: FixedEntries,
    /// Lower bound `v` on the noise variances: a free `Q` and a free `R` are
    /// constrained to `Q >= v I` and `R >= v I` (a diagonal one entry by entry; with `S`
    /// free, the joint `[[Q, S], [S', R]] >= v I`), in the units of the data. `0` (the
    /// default) is plain maximum likelihood.
    ///
    /// Why: the likelihood can grow without bound as `R` (or `Q`) becomes singular, for
    /// example when some output combination is fitted exactly. EM then creeps towards
    /// that boundary, and once the smallest eigenvalue is ~1e-12 of the largest the
    /// smoothed statistics no longer resolve it: the M-step is dominated by rounding
    /// and can lower the likelihood (reported as
    /// [`crate::Termination::LikelihoodDecreased`]). With the bound, the M-step is the
    /// exact constrained maximiser (the unconstrained covariance with its eigenvalues
    /// raised to `v`: the objective `-log det R - tr(R^{-1} E)` separates in the
    /// eigenbasis of `E`), so EM stays monotone and converges to the constrained
    /// maximum.
    pub min_variance: f64,
    /// Lower bound on the output noise, per output: a free `R` is constrained to
    /// `R >= diag(v)` (a diagonal one entry by entry). `None` (the default) is no
    /// bound. The M-step is then the exact constrained maximiser: in the coordinates
    /// `diag(v)^{-1/2} y` the bound is `R >= I`, which [`floor_variances`] solves.
    ///
    /// Why, beside [`LinearEmSpec::min_variance`]: the bound is in each output's own
    /// units, so a floor relative to each output's variance (`sysid fit lti`'s
    /// default) does not depend on how the columns are scaled. On measured records
    /// with several outputs the likelihood often rises without bound towards an `R`
    /// that makes one combination of the outputs exactly predictable (the DaISy glass
    /// furnace: prediction fit 81 % at the start, 61 % at that degenerate optimum).
    /// Not with a free `S`.
    pub output_noise_floor: Option<nalgebra::DVector<f64>>,
}

impl Default for LinearEmSpec {
    fn default() -> Self {
        LinearEmSpec {
            a: true,
            b: true,
            c: true,
            d: true,
            h: true,
            q: Covariance::Full,
            r: Covariance::Full,
            mu: true,
            p1: true,
            s: false,
            fixed_entries: FixedEntries::default(),
            min_variance: 0.0,
            output_noise_floor: None,
        }
    }
}

/// A free noise covariance with its variances raised to at least `floor`: a full one
/// keeps its eigenvectors and raises its eigenvalues (`V max(Lambda, floor) V'`), a
/// diagonal one its diagonal entries. Returned unchanged (bit for bit) when nothing is
/// below `floor`, so a zero floor is plain maximum likelihood.
///
/// `cov` raised to at least `diag(floor)` (the constrained maximiser of
/// [`LinearEmSpec::output_noise_floor`]): [`floor_variances`] with floor 1 in the
/// coordinates `diag(floor)^{-1/2}`. `None` or a fixed structure return `cov`.
pub fn floor_output_noise(
    cov: DMatrix<f64>,
    structure: Covariance,
    floor: Option<&nalgebra::DVector<f64>>,
) -> DMatrix<f64> {
    let Some(floor) = floor else {
        return cov;
    };
    if structure == Covariance::Fixed || floor.len() != cov.nrows() {
        return cov;
    }
    let scale = floor.map(|v| v.sqrt());
    let whitened = DMatrix::from_fn(cov.nrows(), cov.ncols(), |i, j| {
        cov[(i, j)] / (scale[i] * scale[j])
    });
    let raised = floor_variances(whitened.clone(), structure, 1.0);
    if raised == whitened {
        return cov;
    }
    let mut out = DMatrix::from_fn(cov.nrows(), cov.ncols(), |i, j| {
        raised[(i, j)] * scale[i] * scale[j]
    });
    sysid_linalg::symmetrize(&mut out);
    out
}

/// This is the maximiser of `-log det R - tr(R^{-1} E)` over `R >= floor I` given the
/// unconstrained maximiser `E`: by von Neumann's trace inequality the objective is
/// largest when `R` shares the eigenvectors of `E`, and then it separates into
/// `-log r_i - e_i / r_i`, maximised on `r_i >= floor` at `max(e_i, floor)`.
pub fn floor_variances(cov: DMatrix<f64>, structure: Covariance, floor: f64) -> DMatrix<f64> {
    if floor <= 0.0 {
        return cov;
    }
    match structure {
        Covariance::Fixed => cov,
        Covariance::Diagonal => {
            if cov.diagonal().iter().all(|&v| v >= floor) {
                return cov;
            }
            DMatrix::from_diagonal(&cov.diagonal().map(|v| v.max(floor)))
        }
        Covariance::Full => {
            if cov.nrows() == 0 {
                return cov;
            }
            let eigen = nalgebra::SymmetricEigen::new(cov.clone());
            if eigen.eigenvalues.min() >= floor {
                return cov;
            }
            let raised = eigen.eigenvalues.map(|v| v.max(floor));
            let mut out = &eigen.eigenvectors
                * DMatrix::from_diagonal(&raised)
                * eigen.eigenvectors.transpose();
            sysid_linalg::symmetrize(&mut out);
            out
        }
    }
}

/// The smallest eigenvalue of a symmetric matrix (`+inf` for an empty one).
fn smallest_eigenvalue(m: &DMatrix<f64>) -> f64 {
    if m.nrows() == 0 {
        return f64::INFINITY;
    }
    nalgebra::SymmetricEigen::new(m.clone()).eigenvalues.min()
}

/// Whether a variance of `m` is below `floor` by more than the rounding of
/// [`floor_variances`]'s reconstruction (`1e-10` of the larger of `floor` and `max|m|`).
fn below_floor(m: &DMatrix<f64>, floor: f64) -> bool {
    floor > 0.0 && smallest_eigenvalue(m) < floor - 1e-10 * floor.max(m.amax())
}

/// `[[Q, S], [S', R]]`.
fn joint_noise(model: &LinearGaussianModel) -> DMatrix<f64> {
    let (n, p) = (model.n(), model.p());
    let mut joint = DMatrix::zeros(n + p, n + p);
    joint.view_mut((0, 0), (n, n)).copy_from(model.q());
    joint.view_mut((n, n), (p, p)).copy_from(model.r());
    joint.view_mut((0, n), (n, p)).copy_from(model.s());
    joint
        .view_mut((n, 0), (p, n))
        .copy_from(&model.s().transpose());
    joint
}

fn is_diagonal(m: &DMatrix<f64>) -> bool {
    (0..m.ncols()).all(|j| (0..m.nrows()).all(|i| i == j || m[(i, j)] == 0.0))
}

impl LinearEmSpec {
    /// Checks that `model` lies in the parameter set this spec describes (a diagonal
    /// `Q` or `R` where the spec asks for one). EM is monotone only from such a start:
    /// from outside the set, the first M-step may lower the likelihood.
    pub fn check(&self, model: &LinearGaussianModel) -> Result<(), LinearEmError> {
        let masks = [
            ("A", &self.fixed_entries.a, model.a()),
            ("B", &self.fixed_entries.b, model.b()),
            ("C", &self.fixed_entries.c, model.c()),
            ("D", &self.fixed_entries.d, model.d()),
        ];
        for (name, mask, matrix) in masks {
            if let Some(mask) = mask
                && mask.shape() != matrix.shape()
            {
                return Err(LinearEmError::InvalidSpec(format!(
                    "the mask of fixed entries of {name} is {}x{}, the matrix is {}x{}",
                    mask.nrows(),
                    mask.ncols(),
                    matrix.nrows(),
                    matrix.ncols()
                )));
            }
        }
        if self.s && (self.q != Covariance::Full || self.r != Covariance::Full) {
            return Err(LinearEmError::InvalidSpec(
                "estimating S needs full (free) Q and R".into(),
            ));
        }
        if !(self.min_variance.is_finite() && self.min_variance >= 0.0) {
            return Err(LinearEmError::InvalidSpec(format!(
                "min_variance must be a finite non-negative number, got {}",
                self.min_variance
            )));
        }
        if let Some(floor) = &self.output_noise_floor {
            if floor.len() != model.p() || floor.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(LinearEmError::InvalidSpec(format!(
                    "output_noise_floor needs {} positive finite variances, got {:?}",
                    model.p(),
                    floor.as_slice()
                )));
            }
            if self.s {
                return Err(LinearEmError::InvalidSpec(
                    "output_noise_floor is not available with a free S".into(),
                ));
            }
            let whitened = DMatrix::from_fn(model.p(), model.p(), |i, j| {
                model.r()[(i, j)] / (floor[i] * floor[j]).sqrt()
            });
            if self.r != Covariance::Fixed && below_floor(&whitened, 1.0) {
                return Err(LinearEmError::InitialNotInSpec {
                    matrix: "R",
                    reason: "is below output_noise_floor (use LinearEmSpec::project to raise it)",
                });
            }
        }
        for (name, structure, matrix) in [("Q", self.q, model.q()), ("R", self.r, model.r())] {
            if structure == Covariance::Diagonal && !is_diagonal(matrix) {
                return Err(LinearEmError::InitialNotInSpec {
                    matrix: name,
                    reason: "must be diagonal (use LinearEmSpec::project to keep its diagonal)",
                });
            }
            if structure != Covariance::Fixed && !self.s && below_floor(matrix, self.min_variance) {
                return Err(LinearEmError::InitialNotInSpec {
                    matrix: name,
                    reason: "has a variance below min_variance (use LinearEmSpec::project to raise it)",
                });
            }
        }
        if self.s && below_floor(&joint_noise(model), self.min_variance) {
            return Err(LinearEmError::InitialNotInSpec {
                matrix: "[[Q, S], [S', R]]",
                reason: "has a variance below min_variance (use LinearEmSpec::project to raise it)",
            });
        }
        Ok(())
    }

    /// The model moved into this spec's parameter set: a `Q` or `R` to be estimated as
    /// diagonal keeps only its diagonal, and the variances of a free one are raised to
    /// `min_variance` ([`floor_variances`]).
    pub fn project(
        &self,
        model: &LinearGaussianModel,
    ) -> Result<LinearGaussianModel, LinearEmError> {
        let mut builder = model.to_builder();
        if self.s {
            let (n, p) = (model.n(), model.p());
            let joint = floor_variances(joint_noise(model), Covariance::Full, self.min_variance);
            builder = builder
                .q(joint.view((0, 0), (n, n)).clone_owned())
                .r(joint.view((n, n), (p, p)).clone_owned())
                .s(joint.view((0, n), (n, p)).clone_owned());
        } else {
            for (structure, matrix, is_q) in [(self.q, model.q(), true), (self.r, model.r(), false)]
            {
                let projected = match structure {
                    Covariance::Fixed => continue,
                    Covariance::Full => matrix.clone(),
                    Covariance::Diagonal => DMatrix::from_diagonal(&matrix.diagonal()),
                };
                let projected = floor_variances(projected, structure, self.min_variance);
                builder = if is_q {
                    builder.q(projected)
                } else {
                    builder.r(floor_output_noise(
                        projected,
                        structure,
                        self.output_noise_floor.as_ref(),
                    ))
                };
            }
        }
        Ok(builder.build()?)
    }
}

impl LinearEmSpec {
    /// Whether the M-step needs the conditional (ECM) route: fixed individual entries
    /// or a free `S`.
    pub fn needs_ecm(&self) -> bool {
        let f = &self.fixed_entries;
        self.s || f.a.is_some() || f.b.is_some() || f.c.is_some() || f.d.is_some()
    }
}
