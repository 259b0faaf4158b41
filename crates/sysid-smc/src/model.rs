//! What a state-space model can do, as separate capabilities.
//!
//! # Model
//! ```text
//! x_0     ~ mu(x)
//! x_{t+1} ~ f(x_{t+1} | x_t, u_t, t)
//! y_t     ~ g(y_t | x_t, u_t, t)
//! ```
//! The parameters theta are the model value itself: a model is a cheap value that an
//! estimator re-creates for every new theta. Time `t` is the 0-based index of the data
//! (`t = 0` is the first sample); `u` is `u_t` (empty without inputs).
//!
//! Each algorithm asks only for what it needs: the bootstrap filter for
//! [`InitialSampler`], [`TransitionSampler`] and [`ObservationDensity`]; the backward
//! smoothers also for [`TransitionDensity`]; rejection FFBSi also for [`TransitionBound`].
//! A missing capability is a compile-time error, not a run-time one.

/// The state dimension, shared by every capability.
/// # Example
/// ```
/// use sysid_smc::StateSpace;
/// /// A pendulum: angle and angular velocity.
/// struct Pendulum;
/// impl StateSpace for Pendulum {
///     fn state_dim(&self) -> usize {
///         2
///     }
/// }
/// assert_eq!(Pendulum.state_dim(), 2);
/// ```
pub trait StateSpace {
    /// Dimension of `x`.
    fn state_dim(&self) -> usize;
}

/// Draws `x_0 ~ mu`.
/// # Example
/// `x_0 ~ N(0, 1)`:
/// ```
/// use rand_distr::{Distribution, StandardNormal};
/// use sysid_smc::{InitialSampler, StateSpace};
/// struct Ar1;
/// impl StateSpace for Ar1 { fn state_dim(&self) -> usize { 1 } }
/// impl InitialSampler for Ar1 {
///     fn sample_initial<R: rand::Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
///         x[0] = StandardNormal.sample(rng);
///     }
/// }
/// let mut x = [0.0];
/// Ar1.sample_initial(&mut x, &mut sysid_smc::stream(1, 0));
/// assert!(x[0].is_finite());
/// ```
pub trait InitialSampler: StateSpace {
    /// Writes a draw of the initial state into `x` (length `state_dim`).
    fn sample_initial<R: rand::Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R);

    /// Fills `states` (particle-major) with independent draws. The default calls
    /// [`sample_initial`](Self::sample_initial) for each particle in order.
    fn sample_initials<R: rand::Rng + ?Sized>(&self, states: &mut [f64], rng: &mut R) {
        for x in states.chunks_exact_mut(self.state_dim()) {
            self.sample_initial(x, rng);
        }
    }
}

/// Draws `x_{t+1} ~ f(. | x_t, u_t, t)`.
/// # Example
/// `x_{t+1} = 0.9 x_t + u_t + w_t`, `w_t ~ N(0, 1)`:
/// ```
/// use rand_distr::{Distribution, StandardNormal};
/// use sysid_smc::{StateSpace, TransitionSampler};
/// struct Ar1;
/// impl StateSpace for Ar1 { fn state_dim(&self) -> usize { 1 } }
/// impl TransitionSampler for Ar1 {
///     fn sample_transition<R: rand::Rng + ?Sized>(
///         &self, _t: usize, x: &[f64], u: &[f64], next: &mut [f64], rng: &mut R,
///     ) {
///         let w: f64 = StandardNormal.sample(rng);
///         next[0] = 0.9 * x[0] + u.first().unwrap_or(&0.0) + w;
///     }
/// }
/// let mut next = [0.0];
/// Ar1.sample_transition(0, &[1.0], &[], &mut next, &mut sysid_smc::stream(1, 0));
/// assert!(next[0].is_finite());
/// ```
pub trait TransitionSampler: StateSpace {
    /// Writes a draw of the next state into `next`.
    fn sample_transition<R: rand::Rng + ?Sized>(
        &self,
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
        rng: &mut R,
    );

    /// Propagates many particles: `next_k ~ f(. | from_{parents[k]})`, in order of `k`.
    /// The default calls [`sample_transition`](Self::sample_transition) per particle;
    /// models override it to hoist per-step work and vectorise the deterministic part.
    fn sample_transitions<R: rand::Rng + ?Sized>(
        &self,
        t: usize,
        u: &[f64],
        from: &[f64],
        parents: &[usize],
        next: &mut [f64],
        rng: &mut R,
    ) {
        let n = self.state_dim();
        for (x, &p) in next.chunks_exact_mut(n).zip(parents) {
            self.sample_transition(t, &from[p * n..(p + 1) * n], u, x, rng);
        }
    }
}

/// `log g(y_t | x_t, u_t, t)`.
/// # Example
/// `y_t = x_t + e_t`, `e_t ~ N(0, 0.5)`:
/// ```
/// use sysid_smc::{ObservationDensity, StateSpace};
/// struct Ar1;
/// impl StateSpace for Ar1 { fn state_dim(&self) -> usize { 1 } }
/// impl ObservationDensity for Ar1 {
///     fn log_observation(&self, _t: usize, x: &[f64], _u: &[f64], y: &[f64]) -> f64 {
///         let e = y[0] - x[0];
///         -0.5 * (2.0 * std::f64::consts::PI * 0.5).ln() - e * e // e^2 / (2 * 0.5)
///     }
/// }
/// assert!(Ar1.log_observation(0, &[1.0], &[], &[1.0]) > Ar1.log_observation(0, &[1.0], &[], &[2.0]));
/// ```
pub trait ObservationDensity: StateSpace {
    /// The observation log-density. `y` may hold NaN entries (missing) when only some
    /// outputs are missing; steps where every entry is missing are skipped by the
    /// filters and never reach the model. Returning `-inf` is allowed (impossible
    /// observation); NaN and `+inf` are reported as errors by the filters.
    fn log_observation(&self, t: usize, x: &[f64], u: &[f64], y: &[f64]) -> f64;

    /// `out[k] = log g(y | states_k)` for many particles. The default calls
    /// [`log_observation`](Self::log_observation) per particle.
    fn log_observations(&self, t: usize, u: &[f64], y: &[f64], states: &[f64], out: &mut [f64]) {
        for (lg, x) in out.iter_mut().zip(states.chunks_exact(self.state_dim())) {
            *lg = self.log_observation(t, x, u, y);
        }
    }
}

/// `log f(x_{t+1} | x_t, u_t, t)`, needed by the backward smoothers.
/// # Example
/// The density of `x_{t+1} = 0.9 x_t + w_t`, `w_t ~ N(0, 1)`, with the scalar Gaussian
/// form that lets the smoothers find the nearest mean in one pass:
/// ```
/// use sysid_smc::{ScalarGaussianKernel, StateSpace, TransitionDensity};
/// struct Ar1;
/// impl StateSpace for Ar1 { fn state_dim(&self) -> usize { 1 } }
/// impl TransitionDensity for Ar1 {
///     fn log_transition(&self, _t: usize, x: &[f64], _u: &[f64], next: &[f64]) -> f64 {
///         ScalarGaussianKernel::with_variance(1.0).log_density(0.9 * x[0], next[0])
///     }
///     fn scalar_gaussian_means(
///         &self, _t: usize, _u: &[f64], from: &[f64], means: &mut Vec<f64>,
///     ) -> Option<ScalarGaussianKernel> {
///         means.clear();
///         means.extend(from.iter().map(|x| 0.9 * x));
///         Some(ScalarGaussianKernel::with_variance(1.0))
///     }
/// }
/// let (mut out, mut scratch) = (vec![0.0; 4], Vec::new());
/// Ar1.log_transition_matrix(0, &[], &[0.0, 1.0], &[0.0, 0.9], &mut out, &mut scratch);
/// assert_eq!(out[1], Ar1.log_transition(0, &[1.0], &[], &[0.0])); // to_0 from x = 1
/// ```
pub trait TransitionDensity: StateSpace {
    /// The transition log-density of `next` given `x`.
    fn log_transition(&self, t: usize, x: &[f64], u: &[f64], next: &[f64]) -> f64;

    /// The transition log-density at step `t` as a function of `(x, next)`, for many
    /// evaluations at the same step (rejection sampling). Models override it to do
    /// the per-step work (time-varying terms, input terms) once.
    fn log_transition_at<'a>(
        &'a self,
        t: usize,
        u: &'a [f64],
    ) -> impl Fn(&[f64], &[f64]) -> f64 + 'a {
        move |x, next| self.log_transition(t, x, u, next)
    }

    /// All pairs at once: `out[j * m + i] = log f(to_j | from_i)` for the `m` particles
    /// of `from` and the `k` particles of `to` (both particle-major, stride
    /// `state_dim`). `scratch` is the caller's reusable buffer, for example for the
    /// transition means of `from`.
    ///
    /// The default evaluates the kernel of
    /// [`scalar_gaussian_means`](Self::scalar_gaussian_means) when the model provides
    /// one (so the two agree by construction), else calls
    /// [`log_transition`](Self::log_transition) per pair; models override it to share
    /// work across pairs and let the compiler vectorise.
    #[inline(always)] // into the smoothers' vector kernels
    fn log_transition_matrix(
        &self,
        t: usize,
        u: &[f64],
        from: &[f64],
        to: &[f64],
        out: &mut [f64],
        scratch: &mut Vec<f64>,
    ) {
        if let Some(kernel) = self.scalar_gaussian_means(t, u, from, scratch) {
            kernel.log_density_matrix(scratch, to, out);
            return;
        }
        let n = self.state_dim();
        let m = from.len() / n;
        for (row, next) in out.chunks_exact_mut(m).zip(to.chunks_exact(n)) {
            for (value, x) in row.iter_mut().zip(from.chunks_exact(n)) {
                *value = self.log_transition(t, x, u, next);
            }
        }
    }

    /// For a scalar state whose transition is Gaussian around a state-dependent mean,
    /// `x_{t+1} = mean(x_t, u_t, t) + w_t`, `w_t ~ N(0, v)` with `v` free of `x_t`:
    /// writes `mean(from[i], u, t)` into `means` (resized to `from.len()`) and returns
    /// the kernel. `None` (the default) when the model does not have this form at `t`.
    ///
    /// Smoothers that resample with probabilities ∝ `f(x~ | x_i)` then find the
    /// largest candidate in one pass over the means (the nearest one) and evaluate
    /// single candidates on demand instead of materialising every pair. It must agree
    /// bit for bit with [`log_transition_matrix`](Self::log_transition_matrix):
    /// `log f(to_j | from_i) = kernel.log_density(means[i], to_j)`; the default
    /// `log_transition_matrix` is built on it, so only a model that overrides both has
    /// to keep them in step.
    fn scalar_gaussian_means(
        &self,
        t: usize,
        u: &[f64],
        from: &[f64],
        means: &mut Vec<f64>,
    ) -> Option<ScalarGaussianKernel> {
        let _ = (t, u, from, means);
        None
    }
}

/// The log-density of a scalar Gaussian transition `x' ~ N(mean, v)` as a function of
/// `(mean, x')`: `log_norm - half_inv_var * e * e` with `e = x' - mean`, evaluated in
/// exactly that order (models that report this form compute their
/// [`TransitionDensity::log_transition_matrix`] with [`log_density`](Self::log_density),
/// so both give the same bits).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScalarGaussianKernel {
    /// `-ln(2 pi v) / 2`.
    pub log_norm: f64,
    /// `1 / (2 v)`.
    pub half_inv_var: f64,
}

impl ScalarGaussianKernel {
    /// The kernel of `N(mean, variance)`.
    ///
    /// # Example
    /// ```
    /// use sysid_smc::ScalarGaussianKernel;
    /// let k = ScalarGaussianKernel::with_variance(4.0);
    /// let expected = -0.5 * (8.0 * std::f64::consts::PI).ln() - 1.0 / 8.0;
    /// assert!((k.log_density(1.0, 2.0) - expected).abs() < 1e-15);
    /// assert_eq!(k.log_density_at(-3.0), k.log_density_at(3.0));
    /// ```
    pub fn with_variance(variance: f64) -> Self {
        ScalarGaussianKernel {
            log_norm: -0.5 * (2.0 * std::f64::consts::PI * variance).ln(),
            half_inv_var: 0.5 / variance,
        }
    }

    /// `log N(next; mean, v)`.
    #[inline(always)]
    pub fn log_density(&self, mean: f64, next: f64) -> f64 {
        self.log_density_at(next - mean)
    }

    /// `out[j * m + i] = log N(to_j; means[i], v)` for the `m` means: the matrix of
    /// [`TransitionDensity::log_transition_matrix`].
    #[inline(always)]
    pub fn log_density_matrix(&self, means: &[f64], to: &[f64], out: &mut [f64]) {
        for (row, &next) in out.chunks_exact_mut(means.len()).zip(to) {
            for (value, &mean) in row.iter_mut().zip(means) {
                *value = self.log_density(mean, next);
            }
        }
    }

    /// The log-density at a residual `e = next - mean`; the same bits for `e` and `-e`.
    #[inline(always)]
    pub fn log_density_at(&self, e: f64) -> f64 {
        self.log_norm - self.half_inv_var * e * e
    }

    /// Both constants finite and the variance positive, so that the log-density falls
    /// as `|next - mean|` grows and is NaN only where `next - mean` is.
    pub fn is_proper(&self) -> bool {
        self.log_norm.is_finite() && self.half_inv_var.is_finite() && self.half_inv_var > 0.0
    }
}

/// An upper bound `log c >= log f(x' | x, u_t, t)` for all `x, x'`, needed by
/// rejection-sampling FFBSi.
/// # Example
/// A Gaussian transition density is largest at its mean: `log c = -ln(2 pi v) / 2`.
/// ```
/// use sysid_smc::{ScalarGaussianKernel, StateSpace, TransitionBound, TransitionDensity};
/// struct Ar1;
/// impl StateSpace for Ar1 { fn state_dim(&self) -> usize { 1 } }
/// impl TransitionDensity for Ar1 {
///     fn log_transition(&self, _t: usize, x: &[f64], _u: &[f64], next: &[f64]) -> f64 {
///         ScalarGaussianKernel::with_variance(1.0).log_density(0.9 * x[0], next[0])
///     }
/// }
/// impl TransitionBound for Ar1 {
///     fn log_transition_bound(&self, _t: usize, _u: &[f64]) -> f64 {
///         ScalarGaussianKernel::with_variance(1.0).log_norm
///     }
/// }
/// assert!(Ar1.log_transition(0, &[2.0], &[], &[1.8]) <= Ar1.log_transition_bound(0, &[]));
/// ```
pub trait TransitionBound: TransitionDensity {
    /// `log c` at time `t`.
    fn log_transition_bound(&self, t: usize, u: &[f64]) -> f64;
}

/// Everything the bootstrap particle filter needs.
/// # Example
/// Implementing the three capabilities makes a model a `FilterModel`, which the
/// bootstrap filter runs:
/// ```
/// # use rand_distr::{Distribution, StandardNormal};
/// # use sysid_smc::*;
/// # struct Ar1;
/// # impl StateSpace for Ar1 { fn state_dim(&self) -> usize { 1 } }
/// # impl InitialSampler for Ar1 {
/// #     fn sample_initial<R: rand::Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
/// #         x[0] = StandardNormal.sample(rng);
/// #     }
/// # }
/// # impl TransitionSampler for Ar1 {
/// #     fn sample_transition<R: rand::Rng + ?Sized>(
/// #         &self, _t: usize, x: &[f64], _u: &[f64], next: &mut [f64], rng: &mut R,
/// #     ) {
/// #         let w: f64 = StandardNormal.sample(rng);
/// #         next[0] = 0.9 * x[0] + w;
/// #     }
/// # }
/// # impl ObservationDensity for Ar1 {
/// #     fn log_observation(&self, _t: usize, x: &[f64], _u: &[f64], y: &[f64]) -> f64 {
/// #         let e = y[0] - x[0];
/// #         -0.5 * (2.0 * std::f64::consts::PI * 0.5).ln() - e * e
/// #     }
/// # }
/// let y = [0.3, -0.4, 1.2, 0.8];
/// let mut pf = ParticleFilter::new(FilterOptions { particles: 500, ..Default::default() })?;
/// let run = pf.run(&Ar1, &Series::new(&y, 1)?, 7)?;
/// assert!(run.loglik.is_finite());
/// # Ok::<(), SmcError>(())
/// ```
pub trait FilterModel: InitialSampler + TransitionSampler + ObservationDensity {}
impl<M: InitialSampler + TransitionSampler + ObservationDensity> FilterModel for M {}

/// `log mu(x_0)`, the initial-state log-density, needed with [`TransitionDensity`] and
/// [`ObservationDensity`] for the complete-data log-likelihood `log p(x, y)` (particle
/// Gibbs with a Metropolis-within-Gibbs parameter step).
/// # Example
/// `x_0 ~ N(0, 1)`:
/// ```
/// use sysid_smc::{InitialDensity, StateSpace};
/// struct Ar1;
/// impl StateSpace for Ar1 { fn state_dim(&self) -> usize { 1 } }
/// impl InitialDensity for Ar1 {
///     fn log_initial(&self, x: &[f64]) -> f64 {
///         -0.5 * ((2.0 * std::f64::consts::PI).ln() + x[0] * x[0])
///     }
/// }
/// assert!(Ar1.log_initial(&[0.0]) > Ar1.log_initial(&[1.0]));
/// ```
pub trait InitialDensity: StateSpace {
    /// The initial-state log-density of `x`.
    fn log_initial(&self, x: &[f64]) -> f64;
}

/// The locally optimal ("fully adapted") proposal, for models where it is tractable
/// (for example linear Gaussian observations): `x_0 ~ p(x_0 | y_0)`,
/// `x_t ~ p(x_t | x_{t-1}, y_t)`, with the predictive densities `p(y_0)` and
/// `p(y_t | x_{t-1})`. Samplers that use it propose particles where the data are,
/// which keeps them alive when an observation is far from the prediction.
///
/// Called only for steps whose output is fully observed (`y` has no NaN).
/// # Example
/// For `x_{t+1} = a x_t + w_t`, `w ~ N(0, q)`, `y_t = x_t + e_t`, `e ~ N(0, r)` and
/// `x_0 ~ N(0, p0)`, the locally optimal proposal and the predictive densities are
/// Gaussian (a one-step Kalman update):
/// ```
/// use rand_distr::{Distribution, StandardNormal};
/// use sysid_smc::{GuidedProposal, ScalarGaussianKernel, StateSpace};
/// struct Ar1 { a: f64, q: f64, r: f64, p0: f64 }
/// impl StateSpace for Ar1 { fn state_dim(&self) -> usize { 1 } }
/// impl Ar1 {
///     /// Mean and variance of x given a prior N(m, v) and an observation y.
///     fn update(&self, m: f64, v: f64, y: f64) -> (f64, f64) {
///         let k = v / (v + self.r);
///         (m + k * (y - m), (1.0 - k) * v)
///     }
/// }
/// impl GuidedProposal for Ar1 {
///     fn sample_initial_guided<R: rand::Rng + ?Sized>(&self, _u: &[f64], y: &[f64], x: &mut [f64], rng: &mut R) {
///         let (m, v) = self.update(0.0, self.p0, y[0]);
///         let z: f64 = StandardNormal.sample(rng);
///         x[0] = m + v.sqrt() * z;
///     }
///     fn log_initial_predictive(&self, _u: &[f64], y: &[f64]) -> f64 {
///         ScalarGaussianKernel::with_variance(self.p0 + self.r).log_density(0.0, y[0])
///     }
///     fn log_predictive(&self, _t: usize, x: &[f64], _u: &[f64], _u_next: &[f64], y_next: &[f64]) -> f64 {
///         ScalarGaussianKernel::with_variance(self.q + self.r).log_density(self.a * x[0], y_next[0])
///     }
///     fn sample_guided<R: rand::Rng + ?Sized>(
///         &self, _t: usize, x: &[f64], _u: &[f64], _u_next: &[f64], y_next: &[f64],
///         next: &mut [f64], rng: &mut R,
///     ) {
///         let (m, v) = self.update(self.a * x[0], self.q, y_next[0]);
///         let z: f64 = StandardNormal.sample(rng);
///         next[0] = m + v.sqrt() * z;
///     }
/// }
/// let model = Ar1 { a: 0.9, q: 1.0, r: 0.5, p0: 1.0 };
/// assert!(model.log_predictive(0, &[1.0], &[], &[], &[0.9]) > model.log_predictive(0, &[1.0], &[], &[], &[3.0]));
/// ```
pub trait GuidedProposal: StateSpace {
    /// Draws `x_0 ~ p(x_0 | y_0)` into `x`.
    fn sample_initial_guided<R: rand::Rng + ?Sized>(
        &self,
        u: &[f64],
        y: &[f64],
        x: &mut [f64],
        rng: &mut R,
    );
    /// `log p(y_0)`.
    fn log_initial_predictive(&self, u: &[f64], y: &[f64]) -> f64;
    /// `log p(y_{t+1} | x_t)`: the output one step after `x` (the transition at step `t`
    /// with input `u`, the output with input `u_next`).
    fn log_predictive(&self, t: usize, x: &[f64], u: &[f64], u_next: &[f64], y_next: &[f64])
    -> f64;
    /// Draws `x_{t+1} ~ p(x_{t+1} | x_t, y_{t+1})` into `next`.
    #[allow(clippy::too_many_arguments)]
    fn sample_guided<R: rand::Rng + ?Sized>(
        &self,
        t: usize,
        x: &[f64],
        u: &[f64],
        u_next: &[f64],
        y_next: &[f64],
        next: &mut [f64],
        rng: &mut R,
    );
}
