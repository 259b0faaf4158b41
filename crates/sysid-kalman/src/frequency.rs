//! Frequency responses of the deterministic part of a model.

use crate::{KalmanError, LinearGaussianModel, Result};
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

/// One channel's transfer function `G_ij(z) = num(z) / den(z)` in the shift `z`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferFunction {
    /// Numerator coefficients, highest power first (leading zeros removed).
    pub numerator: Vec<f64>,
    /// Denominator coefficients `det(z I - A)`, highest power first (monic).
    pub denominator: Vec<f64>,
    /// Roots of the numerator (the channel's zeros, before any cancellation).
    pub zeros: Vec<Complex<f64>>,
    /// The static gain `G_ij(1)`, `None` with a pole at `z = 1`.
    pub gain: Option<f64>,
}

/// Roots of a polynomial (highest power first) as the eigenvalues of its companion
/// matrix.
fn roots(coefficients: &[f64]) -> Vec<Complex<f64>> {
    let degree = coefficients.len().saturating_sub(1);
    if degree == 0 {
        return Vec::new();
    }
    let lead = coefficients[0];
    let mut companion = DMatrix::zeros(degree, degree);
    for k in 0..degree {
        companion[(0, k)] = -coefficients[k + 1] / lead;
        if k + 1 < degree {
            companion[(k + 1, k)] = 1.0;
        }
    }
    companion.complex_eigenvalues().iter().copied().collect()
}

/// Real coefficients (highest power first) of `prod (z - r)` over roots `r` closed
/// under conjugation.
fn polynomial(roots: &[Complex<f64>]) -> Vec<f64> {
    let mut coefficients = vec![Complex::new(1.0, 0.0)];
    for &r in roots {
        let mut next = vec![Complex::new(0.0, 0.0); coefficients.len() + 1];
        for (k, &c) in coefficients.iter().enumerate() {
            next[k] += c;
            next[k + 1] -= c * r;
        }
        coefficients = next;
    }
    coefficients.iter().map(|c| c.re).collect()
}

impl LinearGaussianModel {
    /// The poles, the eigenvalues of `A`.
    pub fn poles(&self) -> Vec<Complex<f64>> {
        self.a().complex_eigenvalues().iter().copied().collect()
    }

    /// The transfer function from input `j` to output `i`:
    /// `G_ij(z) = C_i (z I - A)^{-1} B_j + D_ij`, whose denominator is
    /// `det(z I - A)` and numerator `G_ij(z) det(z I - A)`, a polynomial of degree at
    /// most `n` found from its values at `n + 1` points of a circle outside the poles
    /// (an inverse discrete Fourier transform). Coefficients below `1e-10` of the
    /// largest are taken as zero before the roots are found.
    ///
    /// # Errors
    /// [`KalmanError::BadOption`] (`channel`) unless `i < p` and `j < m`.
    pub fn transfer_function(&self, i: usize, j: usize) -> Result<TransferFunction> {
        if i >= self.p() || j >= self.m() {
            return Err(KalmanError::BadOption {
                name: "channel",
                message: format!(
                    "output {i}, input {j} (0-based) is not a channel of a model with {} \
                     output(s) and {} input(s)",
                    self.p(),
                    self.m()
                ),
            });
        }
        let n = self.n();
        let poles = self.poles();
        let denominator = polynomial(&poles);
        let radius = 1.5 * poles.iter().map(|p| p.norm()).fold(1.0, f64::max);
        let points = n + 1;
        let eval = |coefficients: &[f64], z: Complex<f64>| {
            coefficients
                .iter()
                .fold(Complex::new(0.0, 0.0), |acc, &c| acc * z + c)
        };
        let c = |m: &DMatrix<f64>| m.map(|v| Complex::new(v, 0.0));
        // values of the numerator at z_k = radius e^{2 pi i k / points}
        let values: Vec<Complex<f64>> = (0..points)
            .map(|k| {
                let z = Complex::from_polar(
                    radius,
                    2.0 * std::f64::consts::PI * k as f64 / points as f64,
                );
                let zi_a = DMatrix::<Complex<f64>>::identity(n, n) * z - c(self.a());
                let b = c(&self.b().columns(j, 1).clone_owned());
                let x = zi_a.lu().solve(&b).expect("z is outside every pole");
                let g = (c(&self.c().rows(i, 1).clone_owned()) * x)[(0, 0)] + self.d()[(i, j)];
                g * eval(&denominator, z)
            })
            .collect();
        // coefficient of z^q: (1 / points) sum_k v_k e^{-2 pi i k q / points} / radius^q
        let ascending: Vec<f64> = (0..points)
            .map(|q| {
                let sum: Complex<f64> = values
                    .iter()
                    .enumerate()
                    .map(|(k, v)| {
                        v * Complex::from_polar(
                            1.0,
                            -2.0 * std::f64::consts::PI * (k * q) as f64 / points as f64,
                        )
                    })
                    .sum();
                (sum / points as f64).re / radius.powi(q as i32)
            })
            .collect();
        let largest = ascending.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let mut numerator: Vec<f64> = ascending
            .iter()
            .rev()
            .map(|&v| if v.abs() <= 1e-10 * largest { 0.0 } else { v })
            .collect();
        while numerator.len() > 1 && numerator[0] == 0.0 {
            numerator.remove(0);
        }
        let zeros = if numerator.iter().all(|&v| v == 0.0) {
            Vec::new()
        } else {
            roots(&numerator)
        };
        let gain = self
            .frequency_response(0.0)
            .map(|g| g[(i, j)].re)
            .filter(|g| g.is_finite());
        Ok(TransferFunction {
            numerator,
            denominator,
            zeros,
            gain,
        })
    }
}
