//! Seeded simulation of a linear Gaussian model.

use crate::{KalmanError, LinearGaussianModel, Record, Result};
use nalgebra::{DMatrix, DVector};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

/// A simulated record together with the true states.
#[derive(Debug, Clone, PartialEq)]
pub struct Simulation {
    /// Inputs and outputs.
    pub record: Record,
    /// States `x_1..x_T` (n x T).
    pub x: DMatrix<f64>,
}

impl LinearGaussianModel {
    /// Simulates `T = u.ncols()` steps driven by the inputs `u` (m x T).
    ///
    /// # Algorithm
    /// `x_1 = mu + F1' z`, `[w_t; e_t] = L' z_t` with standard normal `z` drawn in a
    /// fixed order (initial state, then for each t the noise vector), so a seeded
    /// generator reproduces the run bit for bit.
    ///
    /// # Errors
    /// [`KalmanError::Dimension`] if `u` does not have `m` rows,
    /// [`KalmanError::NonFiniteData`] for a non-finite input.
    ///
    /// # Example
    /// ```
    /// use nalgebra::{dmatrix, DMatrix};
    /// use rand::{SeedableRng, rngs::Xoshiro256PlusPlus};
    /// use sysid_kalman::LinearGaussianModel;
    /// let model = LinearGaussianModel::builder(dmatrix![0.9], dmatrix![1.0], dmatrix![1.0], dmatrix![0.5])
    ///     .build().unwrap();
    /// let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
    /// let sim = model.simulate(&DMatrix::zeros(0, 100), &mut rng).unwrap();
    /// assert_eq!(sim.record.y.ncols(), 100);
    /// ```
    pub fn simulate<R: Rng + ?Sized>(&self, u: &DMatrix<f64>, rng: &mut R) -> Result<Simulation> {
        let (n, p, m) = (self.n(), self.p(), self.m());
        let t_len = u.ncols();
        if u.nrows() != m {
            return Err(KalmanError::Dimension {
                name: "u".into(),
                expected_rows: m,
                expected_cols: t_len,
                rows: u.nrows(),
                cols: t_len,
            });
        }
        if let Some((idx, &value)) = u.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(KalmanError::NonFiniteData {
                record: 0,
                time: idx / m.max(1) + 1,
                what: "input",
                index: idx % m.max(1) + 1,
                value,
            });
        }
        let l = self.noise_factor();
        let mut normal = |k: usize| DVector::from_fn(k, |_, _| StandardNormal.sample(rng));
        let mut x_t = self.mu() + self.initial_factor().transpose() * normal(n);
        let mut xs = DMatrix::zeros(n, t_len);
        let mut ys = DMatrix::zeros(p, t_len);
        for t in 0..t_len {
            let noise = l.transpose() * normal(l.nrows());
            let u_t = u.column(t);
            let y_t = self.c() * &x_t + self.d() * u_t + self.h() + noise.rows(n, p);
            xs.set_column(t, &x_t);
            ys.set_column(t, &y_t);
            x_t = self.a() * &x_t + self.b() * u_t + noise.rows(0, n);
        }
        Ok(Simulation {
            record: Record::new(u.clone(), ys),
            x: xs,
        })
    }
}
