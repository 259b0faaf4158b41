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
#[derive(Debug, Clone, PartialEq, Eq)]
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
        }
    }
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
        for (name, structure, matrix) in [("Q", self.q, model.q()), ("R", self.r, model.r())] {
            if structure == Covariance::Diagonal && !is_diagonal(matrix) {
                return Err(LinearEmError::InitialNotInSpec {
                    matrix: name,
                    reason: "must be diagonal (use LinearEmSpec::project to keep its diagonal)",
                });
            }
        }
        Ok(())
    }

    /// The model moved into this spec's parameter set: a `Q` or `R` to be estimated as
    /// diagonal keeps only its diagonal.
    pub fn project(
        &self,
        model: &LinearGaussianModel,
    ) -> Result<LinearGaussianModel, LinearEmError> {
        let mut builder = model.to_builder();
        if self.q == Covariance::Diagonal {
            builder = builder.q(DMatrix::from_diagonal(&model.q().diagonal()));
        }
        if self.r == Covariance::Diagonal {
            builder = builder.r(DMatrix::from_diagonal(&model.r().diagonal()));
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
