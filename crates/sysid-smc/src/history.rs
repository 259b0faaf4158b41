//! What the filter stores for the smoothers: particles, weights and ancestors.

/// The stored output of a particle filter run, one record per time step.
///
/// At step `t` it holds the particles `x_t^i` (particle-major, stride `state_dim`), their
/// normalised filtering weights `W_t^i` (also as logarithms), the ancestors `a_t^i`
/// (index at `t - 1` of the parent of `x_t^i`; the identity at `t = 0`) and whether the
/// filter resampled after step `t`.
#[derive(Debug, Clone, Default)]
pub struct History {
    state_dim: usize,
    particles: usize,
    steps: usize,
    states: Vec<f64>,
    weights: Vec<f64>,
    log_weights: Vec<f64>,
    ancestors: Vec<usize>,
    resampled: Vec<bool>,
}

impl History {
    /// Makes room for `steps` records of `particles` particles, reusing the buffers.
    pub(crate) fn reset(&mut self, state_dim: usize, particles: usize, steps: usize) {
        self.state_dim = state_dim;
        self.particles = particles;
        self.steps = 0;
        self.states.clear();
        self.states.reserve(steps * particles * state_dim);
        self.weights.clear();
        self.weights.reserve(steps * particles);
        self.log_weights.clear();
        self.log_weights.reserve(steps * particles);
        self.ancestors.clear();
        self.ancestors.reserve(steps * particles);
        self.resampled.clear();
    }

    pub(crate) fn push(
        &mut self,
        states: &[f64],
        weights: &[f64],
        log_weights: &[f64],
        ancestors: &[usize],
    ) {
        self.states.extend_from_slice(states);
        self.weights.extend_from_slice(weights);
        self.log_weights.extend_from_slice(log_weights);
        self.ancestors.extend_from_slice(ancestors);
        self.resampled.push(false);
        self.steps += 1;
    }

    pub(crate) fn mark_resampled(&mut self, t: usize) {
        self.resampled[t] = true;
    }

    /// Number of stored steps T.
    #[inline]
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Number of particles M.
    #[inline]
    pub fn particles(&self) -> usize {
        self.particles
    }

    /// State dimension.
    #[inline]
    pub fn state_dim(&self) -> usize {
        self.state_dim
    }

    /// The particles `x_t^i`, particle-major.
    #[inline]
    pub fn states(&self, t: usize) -> &[f64] {
        let len = self.particles * self.state_dim;
        &self.states[t * len..(t + 1) * len]
    }

    /// The normalised filtering weights `W_t^i`.
    #[inline]
    pub fn weights(&self, t: usize) -> &[f64] {
        &self.weights[t * self.particles..(t + 1) * self.particles]
    }

    /// `log W_t^i`.
    #[inline]
    pub fn log_weights(&self, t: usize) -> &[f64] {
        &self.log_weights[t * self.particles..(t + 1) * self.particles]
    }

    /// The ancestors `a_t^i` (indices into step `t - 1`).
    #[inline]
    pub fn ancestors(&self, t: usize) -> &[usize] {
        &self.ancestors[t * self.particles..(t + 1) * self.particles]
    }

    /// Whether the filter resampled after step `t`, so that the ancestors of step
    /// `t + 1` are an equally weighted resample of step `t`.
    #[inline]
    pub fn resampled_after(&self, t: usize) -> bool {
        self.resampled[t]
    }
}
