//! k-step-ahead predictions of a model file's outputs by a bootstrap particle filter:
//! the predictive mean and standard deviation of `y_t` given `y_0 .. y_{t-k}`.
//!
//! # Algorithm
//! A bootstrap filter with systematic resampling at every observed step carries the
//! predictive cloud of `x_t` given `y_{<t}`. At step `t` a copy of that cloud is moved
//! `k - 1` transitions on (process noise drawn, the record's inputs), and the outputs'
//! mean maps over it give the prediction of `y_{t+k-1}`: its mean, and its variance
//! (the spread of the mean maps plus the measurement variance). The first `k - 1`
//! outputs are predicted from the initial law alone. A missing output does not weight
//! the cloud.
//!
//! # Complexity
//! `O(T M k)` transitions for `T` steps, `M` particles and horizon `k`.

use crate::ModelFile;
use crate::expr::Var;
use sysid_smc::{InitialSampler, ObservationDensity, Resampling, Series, TransitionSampler};

/// Why the predictions could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PredictionError {
    /// An option out of its range.
    #[error("{name}: {reason}")]
    InvalidOption {
        /// The option.
        name: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// The model at the file's values is not a model (a non-positive variance).
    #[error("{0}")]
    Model(String),
    /// Every particle had zero likelihood for an output: the filter lost the state.
    #[error(
        "every particle gives y at t = {t} (0-based) zero likelihood: the filter lost the \
         state (more particles, or a model that can produce this output)"
    )]
    Lost {
        /// The 0-based step.
        t: usize,
    },
}

/// Particle predictions of a record's outputs.
#[derive(Debug, Clone, PartialEq)]
pub struct ParticlePredictions {
    /// The horizon `k >= 1`.
    pub horizon: usize,
    /// Predicted outputs, `T x p` time-major.
    pub mean: Vec<f64>,
    /// Their standard deviations (state spread and measurement noise), `T x p`.
    pub sd: Vec<f64>,
}

impl ModelFile {
    /// The `horizon`-step-ahead predictions of `data`'s outputs at the file's values
    /// (see the [module documentation](crate::prediction)), from `particles`
    /// particles and the random stream `(seed, 0)`.
    ///
    /// # Errors
    /// A horizon or particle count of 0; [`PredictionError::Model`];
    /// [`PredictionError::Lost`].
    pub fn predict_particles(
        &self,
        data: Series<'_>,
        horizon: usize,
        particles: usize,
        seed: u64,
    ) -> Result<ParticlePredictions, PredictionError> {
        let invalid = |name, reason: &str| PredictionError::InvalidOption {
            name,
            reason: reason.to_string(),
        };
        if horizon == 0 {
            return Err(invalid("horizon", "must be at least 1"));
        }
        if particles < 2 {
            return Err(invalid("particles", "must be at least 2"));
        }
        let smc = self
            .at(&self.free_values())
            .map_err(|e| PredictionError::Model(format!("{}: {e}", self.origin())))?;
        let spec = self.spec();
        let values = smc.values().to_vec();
        let (n, p, steps, m) = (
            spec.states.len(),
            spec.outputs.len(),
            data.steps(),
            particles,
        );
        let noise: Vec<f64> = spec
            .measurement_noise
            .iter()
            .map(|e| {
                e.eval(&|v| match v {
                    Var::Param(k) => values[k],
                    _ => f64::NAN,
                })
            })
            .collect();
        let mut rng = sysid_smc::stream(seed, 0);
        let mut cloud = vec![0.0; m * n];
        smc.sample_initials(&mut cloud, &mut rng);
        let mut mean = vec![f64::NAN; steps * p];
        let mut sd = vec![f64::NAN; steps * p];
        let mut scratch = vec![0.0; m * n];
        let mut ahead = vec![0.0; m * n];
        let identity: Vec<usize> = (0..m).collect();
        let mut log_w = vec![0.0; m];
        let mut parents = vec![0; m];
        let mut resample_scratch = Default::default();
        let score = |t: usize, states: &[f64], mean: &mut [f64], sd: &mut [f64]| {
            let u = data.input(t);
            for (j, g) in spec.observation.iter().enumerate() {
                let (mut s1, mut s2) = (0.0, 0.0);
                for x in states.chunks_exact(n) {
                    let v = g.eval(&|var| match var {
                        Var::State(i) => x[i],
                        Var::Input(i) => u[i],
                        Var::Time => t as f64,
                        Var::Param(k) => values[k],
                    });
                    s1 += v;
                    s2 += v * v;
                }
                let mu = s1 / m as f64;
                let spread = (s2 / m as f64 - mu * mu).max(0.0);
                mean[t * p + j] = mu;
                sd[t * p + j] = (spread + noise[j]).sqrt();
            }
        };
        for t in 0..steps {
            // the predictions whose data end before t: y_{t+k-1} (and at t = 0 also
            // the first k - 1 outputs, from the initial law alone)
            let first = if t == 0 { 0 } else { t + horizon - 1 };
            let last = (t + horizon - 1).min(steps.saturating_sub(1));
            if first <= last {
                ahead.copy_from_slice(&cloud);
                let mut s = t;
                for target in first..=last {
                    while s < target {
                        smc.sample_transitions(
                            s,
                            data.input(s),
                            &ahead,
                            &identity,
                            &mut scratch,
                            &mut rng,
                        );
                        std::mem::swap(&mut ahead, &mut scratch);
                        s += 1;
                    }
                    score(target, &ahead, &mut mean, &mut sd);
                }
            }
            if t + 1 == steps {
                break;
            }
            let y = data.output(t);
            if y.iter().all(|v| v.is_nan()) {
                parents.copy_from_slice(&identity);
            } else {
                smc.log_observations(t, data.input(t), y, &cloud, &mut log_w);
                let top = log_w.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                if !top.is_finite() {
                    return Err(PredictionError::Lost { t });
                }
                let weights: Vec<f64> = log_w.iter().map(|l| (l - top).exp()).collect();
                let total: f64 = weights.iter().sum();
                let weights: Vec<f64> = weights.iter().map(|w| w / total).collect();
                Resampling::Systematic.resample(
                    &weights,
                    &mut rng,
                    &mut parents,
                    &mut resample_scratch,
                );
            }
            smc.sample_transitions(t, data.input(t), &cloud, &parents, &mut scratch, &mut rng);
            std::mem::swap(&mut cloud, &mut scratch);
        }
        Ok(ParticlePredictions { horizon, mean, sd })
    }
}

impl ModelFile {
    /// The residual tests of the one-step particle predictions of `data` (MATLAB's
    /// `resid` for a nonlinear model): per output, the autocorrelation of the
    /// standardised errors, their cross-correlation with each input and the Ljung-Box
    /// test ([`sysid_kalman::residuals::ResidualTests::of_standardised`]). The particle
    /// predictions' Monte Carlo error adds a little noise to the errors (about
    /// `1 / sqrt(particles)` of their spread).
    ///
    /// # Errors
    /// Those of [`ModelFile::predict_particles`]; too many lags for the record.
    pub fn residual_tests(
        &self,
        data: Series<'_>,
        lags: usize,
        particles: usize,
        seed: u64,
    ) -> Result<sysid_kalman::residuals::ResidualTests, PredictionError> {
        let pred = self.predict_particles(data, 1, particles, seed)?;
        let (p, m, steps) = (data.output_dim(), data.input_dim(), data.steps());
        let standardised = nalgebra::DMatrix::from_fn(p, steps, |j, t| {
            (data.output(t)[j] - pred.mean[t * p + j]) / pred.sd[t * p + j]
        });
        let inputs = nalgebra::DMatrix::from_fn(m, steps, |j, t| data.input(t)[j]);
        sysid_kalman::residuals::ResidualTests::of_standardised(&standardised, &inputs, lags)
            .map_err(|e| PredictionError::InvalidOption {
                name: "lags",
                reason: e.to_string(),
            })
    }
}
