//! The weightings of the unified subspace theorem (N4SID, MOESP, CVA) and the extended
//! observability matrix they give.

use nalgebra::{DMatrix, SymmetricEigen};

/// Which weighting of the oblique projection `O_i` is factored by the SVD
/// (Van Overschee and De Moor 1996, theorem 13 / section 3.3.4):
/// `W1 O_i W2 = U S V'` and `Gamma_i = W1^{-1} U_1 S_1^{1/2}`. The default is MOESP.
///
/// All three are consistent estimators of the same system; they differ in the basis of
/// the states and in how noise in the data is weighted. On the five DaISy records of
/// `shared/data` their validation fits differ by up to 2.7 points (dryer2's
/// prediction), and MOESP's were never more than 0.35 below the best of the three.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Weighting {
    /// `W1 = I`, `W2 = I` (Van Overschee and De Moor 1994).
    N4sid,
    /// `W1 = I`, `W2 = Pi_{U_f}^perp`: the projection's row space with the future inputs
    /// removed (Verhaegen 1994).
    #[default]
    Moesp,
    /// Canonical variate analysis: `W1 = (Y_f Pi_{U_f}^perp Y_f' / j)^{-1/2}`,
    /// `W2 = Pi_{U_f}^perp` (Larimore 1990); the singular values are canonical
    /// correlations, at most 1.
    Cva,
}

impl Weighting {
    /// The lower-case name used on the command line (`n4sid`, `moesp`, `cva`).
    pub fn name(self) -> &'static str {
        match self {
            Weighting::N4sid => "n4sid",
            Weighting::Moesp => "moesp",
            Weighting::Cva => "cva",
        }
    }

    /// Parses [`Weighting::name`] (case-insensitive).
    pub fn parse(name: &str) -> Option<Weighting> {
        [Weighting::N4sid, Weighting::Moesp, Weighting::Cva]
            .into_iter()
            .find(|w| w.name().eq_ignore_ascii_case(name))
    }
}

/// Projector onto the orthogonal complement of the row space of `b` (in the
/// coefficient space of the factored Hankel matrix, `r x r`).
pub(crate) fn perp_projector(b: &DMatrix<f64>, r: usize) -> DMatrix<f64> {
    let mut proj = DMatrix::<f64>::identity(r, r);
    if b.nrows() == 0 {
        return proj;
    }
    let svd = b.transpose().svd(true, false);
    let u = svd.u.expect("requested");
    let s_max = svd.singular_values.max();
    let tol = b.nrows().max(r) as f64 * f64::EPSILON * s_max;
    for (k, &s) in svd.singular_values.iter().enumerate() {
        if s > tol {
            let col = u.column(k);
            proj -= col * col.transpose();
        }
    }
    proj
}

/// The weighted SVD: singular values (largest first) and, for any order `n`, the
/// extended observability matrix `Gamma_i` in the weighting's basis.
pub(crate) struct WeightedSvd {
    /// Left singular vectors of `W1 O_i W2`, columns sorted by singular value.
    u: DMatrix<f64>,
    /// Singular values, largest first.
    pub singular_values: Vec<f64>,
    /// `W1^{-1}` (identity for N4SID and MOESP).
    w1_inverse: Option<DMatrix<f64>>,
}

impl WeightedSvd {
    /// Factors `W1 O_i W2`. `y_future_perp` is `Y_f Pi_{U_f}^perp`, `perp` is
    /// `Pi_{U_f}^perp`, `columns` is `j` (the Hankel matrices' column count).
    pub fn new(
        weighting: Weighting,
        o_i: &DMatrix<f64>,
        perp: &DMatrix<f64>,
        y_future_perp: &DMatrix<f64>,
        columns: usize,
    ) -> WeightedSvd {
        let (weighted, w1_inverse) = match weighting {
            Weighting::N4sid => (o_i.clone(), None),
            Weighting::Moesp => (o_i * perp, None),
            Weighting::Cva => {
                let mut cov = y_future_perp * y_future_perp.transpose() / columns as f64;
                sysid_linalg::symmetrize(&mut cov);
                let eig = SymmetricEigen::new(cov);
                // a floor relative to the largest eigenvalue keeps W1 finite when an
                // output combination is exactly predictable from the inputs
                let floor = eig.eigenvalues.max().max(f64::MIN_POSITIVE) * 1e-12;
                let root = |power: f64| {
                    let d = eig.eigenvalues.map(|l| l.max(floor).powf(power));
                    &eig.eigenvectors * DMatrix::from_diagonal(&d) * eig.eigenvectors.transpose()
                };
                (root(-0.5) * o_i * perp, Some(root(0.5)))
            }
        };
        let svd = weighted.svd(true, false);
        let u_raw = svd.u.expect("requested");
        let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
        order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
        let u = DMatrix::from_fn(u_raw.nrows(), order.len(), |r, c| u_raw[(r, order[c])]);
        WeightedSvd {
            u,
            singular_values: order.iter().map(|&k| svd.singular_values[k]).collect(),
            w1_inverse,
        }
    }

    /// `Gamma_i = W1^{-1} U_1 S_1^{1/2}` for order `n` (`p i x n`).
    pub fn observability(&self, n: usize) -> DMatrix<f64> {
        let scaled = DMatrix::from_fn(self.u.nrows(), n, |r, c| {
            self.u[(r, c)] * self.singular_values[c].sqrt()
        });
        match &self.w1_inverse {
            Some(w) => w * scaled,
            None => scaled,
        }
    }
}
