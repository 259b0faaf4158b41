//! Frequency responses of the deterministic part of a model.

use crate::LinearGaussianModel;
use nalgebra::{Complex, DMatrix};

impl LinearGaussianModel {
    /// The transfer matrix `G(z) = C (z I - A)^{-1} B + D` at `z = exp(i omega)`
    /// (`p x m`), or `None` if `z` is an eigenvalue of `A`.
    ///
    /// # Example
    /// ```
    /// use nalgebra::dmatrix;
    /// use sysid_kalman::LinearGaussianModel;
    /// let m = LinearGaussianModel::builder(dmatrix![0.5], dmatrix![1.0], dmatrix![0.0], dmatrix![1.0])
    ///     .b(dmatrix![1.0]).build().unwrap();
    /// let g = m.frequency_response(0.0).unwrap(); // G(1) = 1 / (1 - 0.5)
    /// assert!((g[(0, 0)].re - 2.0).abs() < 1e-12);
    /// ```
    pub fn frequency_response(&self, omega: f64) -> Option<DMatrix<Complex<f64>>> {
        let n = self.n();
        let c = |m: &DMatrix<f64>| m.map(|v| Complex::new(v, 0.0));
        let z = Complex::from_polar(1.0, omega);
        let zi_a = DMatrix::<Complex<f64>>::identity(n, n) * z - c(self.a());
        let x = zi_a.lu().solve(&c(self.b()))?;
        Some(c(self.c()) * x + c(self.d()))
    }

    /// Relative H2-type error of this model's frequency response against `truth` on
    /// `points` frequencies evenly spaced in `[0, pi)`:
    /// `sqrt(sum |G - G_true|_F^2 / sum |G_true|_F^2)`; `None` on a pole on the unit circle
    /// or mismatched input/output dimensions.
    pub fn relative_response_error(
        &self,
        truth: &LinearGaussianModel,
        points: usize,
    ) -> Option<f64> {
        if self.m() != truth.m() || self.p() != truth.p() {
            return None;
        }
        let (mut err, mut norm) = (0.0, 0.0);
        for k in 0..points {
            let omega = std::f64::consts::PI * k as f64 / points as f64;
            let g = self.frequency_response(omega)?;
            let g_true = truth.frequency_response(omega)?;
            err += (g - &g_true).norm_squared();
            norm += g_true.norm_squared();
        }
        Some((err / norm).sqrt())
    }
}
