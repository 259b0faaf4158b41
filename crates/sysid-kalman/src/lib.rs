//! Linear Gaussian state-space models: simulation, square-root Kalman filtering,
//! RTS smoothing with lag-one covariances, exact log-likelihood, and the EM sufficient
//! statistics.
//!
//! # Model
//! $$
//! x_{t+1} = A x_t + B u_t + w_t, \qquad y_t = C x_t + D u_t + h + e_t,
//! $$
//! $$
//! \begin{bmatrix} w_t \\ e_t \end{bmatrix} \sim
//! \mathcal N\left(0, \begin{bmatrix} Q & S \\ S^\top & R \end{bmatrix}\right),
//! \qquad x_1 \sim \mathcal N(\mu, P_1).
//! $$
//!
//! # Algorithm
//! One Householder triangularisation per step of the pre-array
//! $\begin{bmatrix} U C^\top & U A^\top & U \\ L_e & L_w & 0 \end{bmatrix}$, with
//! $U^\top U = P_{t|t-1}$ and $L^\top L$ the noise covariance, gives the innovation
//! factor, the gain and the next predicted factor: every covariance is a product
//! $L^\top L$, symmetric and positive semi-definite by construction. The
//! log-likelihood is $\sum_t \log \mathcal N(y_t; \hat y_{t|t-1}, \Sigma_t)$ with
//! $\log\det \Sigma_t$ from the factor's diagonal.
//!
//! # Complexity
//! $O(T (n + p)^3)$ time for $T$ steps, $n$ states and $p$ outputs; the smoother keeps
//! $O(T n^2)$ memory, the filter's log-likelihood $O(n^2)$.
//! Missing outputs are NaN entries (partially observed vectors and wholly missing steps
//! are both fine).
//!
//! # Example
//! ```
//! use nalgebra::{dmatrix, DMatrix};
//! use rand::{SeedableRng, rngs::Xoshiro256PlusPlus};
//! use sysid_kalman::{KalmanWorkspace, LinearGaussianModel};
//! let model = LinearGaussianModel::builder(dmatrix![0.9], dmatrix![1.0], dmatrix![1.0], dmatrix![0.5])
//!     .build().unwrap();
//! let sim = model.simulate(&DMatrix::zeros(0, 200), &mut Xoshiro256PlusPlus::seed_from_u64(7)).unwrap();
//! let mut ws = KalmanWorkspace::new();
//! let loglik = ws.loglik(&model, &sim.record).unwrap();
//! let smoothed = ws.smooth(&model, &sim.record).unwrap();
//! assert!((smoothed.loglik() - loglik).abs() < 1e-9);
//! assert!(smoothed.covariance(0)[(0, 0)] > 0.0);
//! ```
//!
//! # References
//! Kalman (1960); Rauch, Tung, Striebel (1965); Shumway and Stoffer (1982);
//! Gibson and Ninness, "Robust maximum-likelihood estimation of multivariable dynamic
//! systems", Automatica 41 (2005).

mod compare;
pub mod conventional;
mod data;
mod dense;
mod diffuse;
mod error;
mod filter;
mod frequency;
mod initial;
mod long;
mod model;
mod predict;
pub mod residuals;
mod response;
mod scalar;
mod simulate;
mod smoother;
mod spec;
mod stats;
mod trend;

pub use compare::{Comparison, Horizon};
pub use data::Record;
pub use error::{KalmanError, Result};
pub use filter::{FilterOutput, KalmanWorkspace};
pub use frequency::TransferFunction;
pub use initial::{
    InitialState, early_input_mean, spectral_radius, stationary_covariance,
    stationary_input_memory, stationary_input_window,
};
pub use long::{BLOCK_STEPS, BlockFilter};
pub use model::{LinearGaussianModel, ModelBuilder};
pub use predict::{Forecast, ForecastIntervals, PredictionWarning, Predictions};
pub use response::{Response, fit_percent};
pub use simulate::Simulation;
pub use smoother::SmootherOutput;
pub use spec::{Detrend, Metadata, ModelSpec, ParameterCovariance};
pub use stats::SufficientStatistics;
pub use trend::{Trend, TrendError, TrendKind};

/// Log-likelihood of a data set of independent records sharing one model: the sum of
/// the records' log-likelihoods.
pub fn loglik_dataset(model: &LinearGaussianModel, records: &[Record]) -> Result<f64> {
    let mut ws = KalmanWorkspace::new();
    let mut total = 0.0;
    for (i, rec) in records.iter().enumerate() {
        rec.validate(model, i)?;
        total += ws.run(model, rec, i, filter::Keep::LoglikOnly)?;
    }
    Ok(total)
}

/// EM statistics of a data set of independent records (summed) and its log-likelihood.
pub fn statistics_dataset(
    model: &LinearGaussianModel,
    records: &[Record],
) -> Result<(SufficientStatistics, f64)> {
    let mut ws = KalmanWorkspace::new();
    let mut stats = SufficientStatistics::new(model.n(), model.m(), model.p());
    let mut total = 0.0;
    for (i, rec) in records.iter().enumerate() {
        total += ws.accumulate_statistics(model, rec, i, &mut stats)?;
    }
    Ok((stats, total))
}
