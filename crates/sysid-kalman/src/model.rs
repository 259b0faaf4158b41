//! The linear Gaussian state-space model and its validating builder.

use crate::{KalmanError, Result};
use nalgebra::{DMatrix, DVector};
use sysid_linalg::{check_finite, psd_factor};

/// A linear Gaussian state-space model with inputs, correlated noises and an output
/// offset.
///
/// # Model
/// ```text
/// x_{t+1} = A x_t + B u_t + w_t
/// y_t     = C x_t + D u_t + h + e_t
/// [w_t; e_t] ~ N(0, [[Q, S], [S', R]]),   x_1 = mu + A_d delta + eta,
/// eta ~ N(0, P1),   delta ~ N(0, kappa I), kappa -> infinity
/// ```
/// with `n` states, `m` inputs and `p` outputs. The `n x q` matrix `A_d` of diffuse
/// directions ([`ModelBuilder::diffuse`]) is empty (`q = 0`) unless set: the initial
/// state is then the proper law `N(mu, P1)`. With `q > 0` the filters use the exact
/// diffuse initialisation (see [`KalmanWorkspace::loglik`](crate::KalmanWorkspace::loglik)). Covariances may be singular (e.g.
/// `Q = 0` for an output-error model): they are stored together with square-root
/// factors computed once at construction, which is what the filters use.
///
/// Built only through [`ModelBuilder`], which checks dimensions, finiteness,
/// symmetry and positive semi-definiteness, so a value of this type is always valid.
///
/// # Example
/// ```
/// use nalgebra::dmatrix;
/// use sysid_kalman::LinearGaussianModel;
/// let model = LinearGaussianModel::builder(dmatrix![0.9], dmatrix![1.0], dmatrix![1.0], dmatrix![0.5])
///     .build()
///     .unwrap();
/// assert_eq!((model.n(), model.m(), model.p()), (1, 0, 1));
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct LinearGaussianModel {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    c: DMatrix<f64>,
    d: DMatrix<f64>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    s: DMatrix<f64>,
    h: DVector<f64>,
    mu: DVector<f64>,
    p1: DMatrix<f64>,
    /// `A_d`, n x q: the directions of the initial state with infinite variance.
    diffuse: DMatrix<f64>,
    /// `L` with `L'L = [[Q, S], [S', R]]`; columns `0..n` belong to `w`, `n..n+p` to `e`.
    noise_factor: DMatrix<f64>,
    /// `n x n` factor `F` with `F'F = P1` (zero rows padded for a singular `P1`).
    initial_factor: DMatrix<f64>,
}

macro_rules! getters {
    ($($name:ident: $ty:ty, $doc:literal;)*) => {
        $(#[doc = $doc] pub fn $name(&self) -> &$ty { &self.$name })*
    };
}

impl LinearGaussianModel {
    /// Starts a builder from the four matrices every model needs. Inputs, the
    /// cross-covariance `S`, the offset `h` and the initial state default to absent/zero,
    /// `mu = 0` and `P1 = I`.
    pub fn builder(
        a: DMatrix<f64>,
        c: DMatrix<f64>,
        q: DMatrix<f64>,
        r: DMatrix<f64>,
    ) -> ModelBuilder {
        ModelBuilder {
            a,
            c,
            q,
            r,
            b: None,
            d: None,
            s: None,
            h: None,
            mu: None,
            p1: None,
            diffuse: None,
        }
    }

    /// Returns a builder pre-filled with this model's matrices, to change some of them.
    pub fn to_builder(&self) -> ModelBuilder {
        ModelBuilder {
            a: self.a.clone(),
            c: self.c.clone(),
            q: self.q.clone(),
            r: self.r.clone(),
            b: Some(self.b.clone()),
            d: Some(self.d.clone()),
            s: Some(self.s.clone()),
            h: Some(self.h.clone()),
            mu: Some(self.mu.clone()),
            p1: Some(self.p1.clone()),
            diffuse: Some(self.diffuse.clone()),
        }
    }

    /// Number of states `n`.
    pub fn n(&self) -> usize {
        self.a.nrows()
    }
    /// Number of inputs `m`.
    pub fn m(&self) -> usize {
        self.b.ncols()
    }
    /// Number of outputs `p`.
    pub fn p(&self) -> usize {
        self.c.nrows()
    }

    getters! {
        a: DMatrix<f64>, "State transition matrix `A` (n x n).";
        b: DMatrix<f64>, "Input matrix `B` (n x m).";
        c: DMatrix<f64>, "Output matrix `C` (p x n).";
        d: DMatrix<f64>, "Feed-through matrix `D` (p x m).";
        q: DMatrix<f64>, "Process-noise covariance `Q` (n x n).";
        r: DMatrix<f64>, "Measurement-noise covariance `R` (p x p).";
        s: DMatrix<f64>, "Cross-covariance `S = Cov(w_t, e_t)` (n x p).";
        h: DVector<f64>, "Output offset `h` (p).";
        mu: DVector<f64>, "Initial state mean `mu` (n).";
        p1: DMatrix<f64>, "Initial state covariance `P1` (n x n): of the proper part of the initial state when there are diffuse directions.";
        diffuse: DMatrix<f64>, "Diffuse directions `A_d` (n x q, `q = 0` for a proper initial state).";
        noise_factor: DMatrix<f64>, "Factor `L` (rows x (n+p)) with `L'L = [[Q, S], [S', R]]`; columns `0..n` are `w`, `n..n+p` are `e`.";
        initial_factor: DMatrix<f64>, "Factor `F` (n x n) with `F'F = P1`.";
    }

    /// The same model started from `x_1 ~ N(mean, F'F)` (`factor` = `F`, column-major),
    /// without diffuse directions (the state carried between the blocks of a long
    /// record).
    pub(crate) fn with_initial_factor(&self, mean: &[f64], factor: &[f64]) -> LinearGaussianModel {
        let n = self.n();
        let f = DMatrix::from_column_slice(n, n, factor);
        let mut model = self.clone();
        model.p1 = f.transpose() * &f;
        sysid_linalg::symmetrize(&mut model.p1);
        model.initial_factor = f;
        model.mu = DVector::from_column_slice(mean);
        model.diffuse = DMatrix::zeros(n, 0);
        model
    }

    /// The same model with `S = 0` (still valid: `Q` and `R` are PSD on their own).
    /// Linear EM holds `S` fixed, so a subspace estimate (which has an `S`) is usually
    /// started from this.
    pub fn without_cross_covariance(&self) -> LinearGaussianModel {
        self.to_builder()
            .s(DMatrix::zeros(self.n(), self.p()))
            .build()
            .expect("a valid model without S is valid: Q and R are PSD on their own")
    }

    /// Whether the initial state has diffuse directions (`q > 0`).
    pub fn is_diffuse(&self) -> bool {
        self.diffuse.ncols() > 0
    }

    /// Whether the cross-covariance `S` is identically zero.
    pub fn has_cross_covariance(&self) -> bool {
        self.s.iter().any(|&v| v != 0.0)
    }
}

/// Validating builder for [`LinearGaussianModel`] (see [`LinearGaussianModel::builder`]).
#[derive(Debug, Clone)]
pub struct ModelBuilder {
    a: DMatrix<f64>,
    c: DMatrix<f64>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    b: Option<DMatrix<f64>>,
    d: Option<DMatrix<f64>>,
    s: Option<DMatrix<f64>>,
    h: Option<DVector<f64>>,
    mu: Option<DVector<f64>>,
    p1: Option<DMatrix<f64>>,
    diffuse: Option<DMatrix<f64>>,
}

macro_rules! setters {
    ($($name:ident: $ty:ty, $wrap:expr, $doc:literal;)*) => {
        $(#[doc = $doc] pub fn $name(mut self, $name: $ty) -> Self {
            self.$name = $wrap($name);
            self
        })*
    };
}

impl ModelBuilder {
    setters! {
        b: DMatrix<f64>, Some, "Sets the input matrix `B` (n x m); `D` defaults to zero if not set.";
        d: DMatrix<f64>, Some, "Sets the feed-through matrix `D` (p x m); `B` defaults to zero if not set.";
        s: DMatrix<f64>, Some, "Sets the cross-covariance `S = Cov(w_t, e_t)` (n x p).";
        h: DVector<f64>, Some, "Sets the output offset `h` (p).";
        mu: DVector<f64>, Some, "Sets the initial state mean `mu` (n).";
        p1: DMatrix<f64>, Some, "Sets the initial state covariance `P1` (n x n, PSD).";
        diffuse: DMatrix<f64>, Some, "Sets the diffuse directions `A_d` (n x q, linearly independent columns; `q = 0` for none): the initial state is `mu + A_d delta + eta` with `delta` of infinite variance and `eta ~ N(0, P1)`. `DMatrix::identity(n, n)` with `P1 = 0` makes the whole initial state diffuse.";
        a: DMatrix<f64>, std::convert::identity, "Replaces `A`.";
        c: DMatrix<f64>, std::convert::identity, "Replaces `C`.";
        q: DMatrix<f64>, std::convert::identity, "Replaces `Q`.";
        r: DMatrix<f64>, std::convert::identity, "Replaces `R`.";
    }

    /// Validates and builds the model.
    ///
    /// # Errors
    /// [`KalmanError::EmptyModel`] for a model without states (`A` has no rows) or
    /// without outputs (`C` has no rows); [`KalmanError::Dimension`] naming the first
    /// matrix of the wrong shape;
    /// [`KalmanError::Matrix`] for a non-finite entry, a non-symmetric covariance or one
    /// that is not positive semi-definite (checked for `Q`, `R`, the joint
    /// `[[Q, S], [S', R]]` and `P1`); [`KalmanError::DiffuseRank`] for diffuse
    /// directions that are linearly dependent.
    pub fn build(self) -> Result<LinearGaussianModel> {
        let n = self.a.nrows();
        let p = self.c.nrows();
        for (what, matrix, m) in [("state", "A", &self.a), ("output", "C", &self.c)] {
            if m.nrows() == 0 {
                return Err(KalmanError::EmptyModel {
                    what,
                    matrix,
                    rows: m.nrows(),
                    cols: m.ncols(),
                });
            }
        }
        let m = match (&self.b, &self.d) {
            (Some(b), _) => b.ncols(),
            (None, Some(d)) => d.ncols(),
            (None, None) => 0,
        };
        let b = self.b.unwrap_or_else(|| DMatrix::zeros(n, m));
        let d = self.d.unwrap_or_else(|| DMatrix::zeros(p, m));
        let s = self.s.unwrap_or_else(|| DMatrix::zeros(n, p));
        let h = self.h.unwrap_or_else(|| DVector::zeros(p));
        let mu = self.mu.unwrap_or_else(|| DVector::zeros(n));
        let p1 = self.p1.unwrap_or_else(|| DMatrix::identity(n, n));
        let diffuse = self.diffuse.unwrap_or_else(|| DMatrix::zeros(n, 0));
        if diffuse.nrows() != n || diffuse.ncols() > n {
            return Err(KalmanError::Dimension {
                name: "diffuse".to_string(),
                expected_rows: n,
                expected_cols: diffuse.ncols().min(n),
                rows: diffuse.nrows(),
                cols: diffuse.ncols(),
            });
        }
        check_finite("diffuse", &diffuse)?;
        check_diffuse_rank(&diffuse)?;
        let h_mat = DMatrix::from_column_slice(h.len(), 1, h.as_slice());
        let mu_mat = DMatrix::from_column_slice(mu.len(), 1, mu.as_slice());
        let shapes: [(&str, &DMatrix<f64>, usize, usize); 10] = [
            ("A", &self.a, n, n),
            ("B", &b, n, m),
            ("C", &self.c, p, n),
            ("D", &d, p, m),
            ("Q", &self.q, n, n),
            ("R", &self.r, p, p),
            ("S", &s, n, p),
            ("h", &h_mat, p, 1),
            ("mu", &mu_mat, n, 1),
            ("P1", &p1, n, n),
        ];
        for (name, mat, rows, cols) in shapes {
            if mat.nrows() != rows || mat.ncols() != cols {
                return Err(KalmanError::Dimension {
                    name: name.to_string(),
                    expected_rows: rows,
                    expected_cols: cols,
                    rows: mat.nrows(),
                    cols: mat.ncols(),
                });
            }
            check_finite(name, mat)?;
        }
        let q_factor = psd_factor("Q", &self.q)?;
        let r_factor = psd_factor("R", &self.r)?;
        let noise_factor = if s.iter().all(|&v| v == 0.0) {
            // block-diagonal factor: keeps very different scales of Q and R exact
            let rows = q_factor.nrows() + r_factor.nrows();
            let mut l = DMatrix::zeros(rows, n + p);
            l.view_mut((0, 0), q_factor.shape()).copy_from(&q_factor);
            l.view_mut((q_factor.nrows(), n), r_factor.shape())
                .copy_from(&r_factor);
            l
        } else {
            let mut joint = DMatrix::zeros(n + p, n + p);
            joint.view_mut((0, 0), (n, n)).copy_from(&self.q);
            joint.view_mut((0, n), (n, p)).copy_from(&s);
            joint.view_mut((n, 0), (p, n)).copy_from(&s.transpose());
            joint.view_mut((n, n), (p, p)).copy_from(&self.r);
            psd_factor("[[Q, S], [S', R]]", &joint)?
        };
        let f1 = psd_factor("P1", &p1)?;
        let mut initial_factor = DMatrix::zeros(n, n);
        initial_factor.view_mut((0, 0), f1.shape()).copy_from(&f1);
        Ok(LinearGaussianModel {
            a: self.a,
            b,
            c: self.c,
            d,
            q: self.q,
            r: self.r,
            s,
            h,
            mu,
            p1,
            diffuse,
            noise_factor,
            initial_factor,
        })
    }
}

/// Refuses diffuse directions that are linearly dependent (numerically: a singular
/// value below `q n eps` times the largest), whose weights the data could never tell
/// apart.
fn check_diffuse_rank(diffuse: &DMatrix<f64>) -> Result<()> {
    let q = diffuse.ncols();
    if q == 0 {
        return Ok(());
    }
    let sv = diffuse.clone().singular_values();
    let largest = sv.max();
    let tol = (q * diffuse.nrows()) as f64 * f64::EPSILON * largest;
    let rank = sv.iter().filter(|&&v| v > tol).count();
    if rank < q {
        return Err(KalmanError::DiffuseRank { columns: q, rank });
    }
    Ok(())
}
