//! Smoothed trajectories and additive functionals of them.

/// `K` smoothed trajectories `x~_{0:T-1}^k`, stored time-major: the `K` states of step
/// `t` are contiguous (path-major within the step, stride `state_dim`).
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectories {
    steps: usize,
    paths: usize,
    state_dim: usize,
    states: Vec<f64>,
}

impl Trajectories {
    pub(crate) fn zeros(steps: usize, paths: usize, state_dim: usize) -> Self {
        Trajectories {
            steps,
            paths,
            state_dim,
            states: vec![0.0; steps * paths * state_dim],
        }
    }

    /// Trajectories from their states, time-major (the `paths` states of step `t`
    /// contiguous, stride `state_dim`); `None` when the length is not
    /// `steps * paths * state_dim` or a count is zero.
    pub fn from_states(
        steps: usize,
        paths: usize,
        state_dim: usize,
        states: Vec<f64>,
    ) -> Option<Self> {
        (steps > 0 && paths > 0 && state_dim > 0 && states.len() == steps * paths * state_dim)
            .then_some(Trajectories {
                steps,
                paths,
                state_dim,
                states,
            })
    }

    /// Number of steps T.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Number of trajectories K.
    pub fn paths(&self) -> usize {
        self.paths
    }

    /// State dimension.
    pub fn state_dim(&self) -> usize {
        self.state_dim
    }

    /// The `K` states at step `t`, path-major.
    #[inline]
    pub fn states(&self, t: usize) -> &[f64] {
        let len = self.paths * self.state_dim;
        &self.states[t * len..(t + 1) * len]
    }

    pub(crate) fn states_mut(&mut self, t: usize) -> &mut [f64] {
        let len = self.paths * self.state_dim;
        &mut self.states[t * len..(t + 1) * len]
    }

    /// The state of path `k` at step `t`.
    #[inline]
    pub fn state(&self, t: usize, k: usize) -> &[f64] {
        let n = self.state_dim;
        &self.states(t)[k * n..(k + 1) * n]
    }

    /// The smoothed means `(1/K) sum_k x~_t^k`, time-major (T x n).
    pub fn means(&self) -> Vec<f64> {
        let n = self.state_dim;
        let mut out = vec![0.0; self.steps * n];
        for (t, mean) in out.chunks_exact_mut(n).enumerate() {
            for x in self.states(t).chunks_exact(n) {
                for (m, &v) in mean.iter_mut().zip(x) {
                    *m += v;
                }
            }
            mean.iter_mut().for_each(|m| *m /= self.paths as f64);
        }
        out
    }

    /// The smoothed standard deviations across paths (divisor K - 1; 0 for K = 1).
    pub fn std_devs(&self) -> Vec<f64> {
        let n = self.state_dim;
        let means = self.means();
        let mut out = vec![0.0; self.steps * n];
        let denom = self.paths.saturating_sub(1).max(1) as f64;
        for (t, sd) in out.chunks_exact_mut(n).enumerate() {
            for x in self.states(t).chunks_exact(n) {
                for ((s, &v), &m) in sd.iter_mut().zip(x).zip(&means[t * n..(t + 1) * n]) {
                    *s += (v - m) * (v - m);
                }
            }
            sd.iter_mut().for_each(|s| *s = (*s / denom).sqrt());
        }
        out
    }

    /// Feeds every pair of the trajectories to an additive functional with weight
    /// `1 / K`, giving the smoothed sum `E[sum_t s(t, x_t, x_{t+1}) | y]`.
    pub fn accumulate<F: AdditiveFunctional + ?Sized>(&self, functional: &mut F) {
        let weight = 1.0 / self.paths as f64;
        for t in 0..self.steps {
            let next = (t + 1 < self.steps).then(|| self.states(t + 1));
            feed_step(functional, t, self.states(t), next, self.state_dim, weight);
        }
    }

    /// Concatenates blocks of paths (all with the same steps and dimension).
    pub(crate) fn concat(blocks: Vec<Trajectories>) -> Trajectories {
        let steps = blocks[0].steps;
        let n = blocks[0].state_dim;
        let paths = blocks.iter().map(|b| b.paths).sum();
        let mut out = Trajectories::zeros(steps, paths, n);
        for t in 0..steps {
            let mut offset = 0;
            for b in &blocks {
                let s = b.states(t);
                out.states_mut(t)[offset..offset + s.len()].copy_from_slice(s);
                offset += s.len();
            }
        }
        out
    }
}

/// Adds the pairs `(x_t^k, x_{t+1}^k)` of one step of several paths (path-major
/// states, stride `n`; `next` is `None` at the last step) to a functional.
pub(crate) fn feed_step<F: AdditiveFunctional + ?Sized>(
    functional: &mut F,
    t: usize,
    states: &[f64],
    next: Option<&[f64]>,
    n: usize,
    weight: f64,
) {
    functional.add_step(t, states, next, n, weight);
}

/// A sum over time of `s(t, x_t, x_{t+1})`, smoothed: the smoothers call
/// [`add`](Self::add) for every time step of every trajectory with the trajectory's
/// weight, so the accumulated value estimates `E[sum_t s(t, x_t, x_{t+1}) | y_{0:T-1}]`.
///
/// `next` is `None` at the last step `t = T - 1`; terms that need only `x_t` (output
/// equations) use every step, transition terms skip the last one.
///
/// Any closure `FnMut(usize, &[f64], Option<&[f64]>, f64)` is a functional.
///
/// # Example
/// The smoothed mean of `sum_t x_t^2`, by rejection-free FFBSi, with a closure:
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
/// # impl TransitionDensity for Ar1 {
/// #     fn log_transition(&self, _t: usize, x: &[f64], _u: &[f64], next: &[f64]) -> f64 {
/// #         ScalarGaussianKernel::with_variance(1.0).log_density(0.9 * x[0], next[0])
/// #     }
/// # }
/// let y = [0.3, -0.4, 1.2, 0.8];
/// let data = Series::new(&y, 1)?;
/// let mut pf = ParticleFilter::new(FilterOptions {
///     particles: 200, store_history: true, ..Default::default()
/// })?;
/// pf.run(&Ar1, &data, 1)?;
/// let mut energy = 0.0;
/// let mut functional = |_t: usize, x: &[f64], _next: Option<&[f64]>, w: f64| energy += w * x[0] * x[0];
/// Ffbsi { paths: 50, parallel: false }.additive(&Ar1, pf.history().unwrap(), &data, 2, &mut functional)?;
/// assert!(energy > 0.0);
/// # Ok::<(), SmcError>(())
/// ```
pub trait AdditiveFunctional {
    /// Adds `weight * s(t, x, next)`.
    fn add(&mut self, t: usize, x: &[f64], next: Option<&[f64]>, weight: f64);

    /// Adds `weight * s(t, x^k, next^k)` for the states of several paths at one step
    /// (path-major, stride `state_dim`; `next` likewise). The smoothers call this; the
    /// default calls [`add`](Self::add) per path, and functionals override it to do
    /// per-step work once.
    fn add_step(
        &mut self,
        t: usize,
        states: &[f64],
        next: Option<&[f64]>,
        state_dim: usize,
        weight: f64,
    ) {
        let n = state_dim;
        for (k, x) in states.chunks_exact(n).enumerate() {
            self.add(t, x, next.map(|s| &s[k * n..(k + 1) * n]), weight);
        }
    }
}

impl<F: FnMut(usize, &[f64], Option<&[f64]>, f64)> AdditiveFunctional for F {
    fn add(&mut self, t: usize, x: &[f64], next: Option<&[f64]>, weight: f64) {
        self(t, x, next, weight)
    }
}
