//! PSAEM: stochastic-approximation EM with a conditional particle filter with ancestor
//! sampling as its Markov kernel (Lindsten 2013).
//!
//! # Model
//! The affine class of [`AffineModel`] (ALGORITHMS.md 3).
//!
//! # Algorithm
//! Iteration `k`:
//! 1. run the conditional SMC with ancestor sampling (`sysid_smc::conditional`) at
//!    `theta_{k-1}`, conditioned on the reference trajectory `x[k-1]` (the first
//!    iteration runs an unconditional filter); draw the next reference `x[k]`;
//! 2. compute the statistics `S^_k` of the weighted particle system: every traced path
//!    with its final weight (the Rao-Blackwellised estimate);
//! 3. update `S_k = (1 - gamma_k) S_{k-1} + gamma_k S^_k`;
//! 4. M-step: `theta_k` maximises the complete-data likelihood at `S_k` ([`m_step`]).
//!
//! Because the kernel leaves the smoothing distribution invariant for any number of
//! particles, a handful (e.g. 15) suffices: the averaging over iterations does what
//! more particles would do in particle EM. The step sizes satisfy
//! `sum gamma_k = inf`, `sum gamma_k^2 < inf` after a burn-in:
//! `gamma_k = 1` for `k <= burn_in`, then `(k - burn_in)^(-exponent)` ([`StepSizes`];
//! default burn-in 100, exponent 0.7).
//!
//! The trace value of an iteration is the conditional filter's log-likelihood estimate
//! (biased by the conditioning; a diagnostic, not a likelihood). Iteration `k` draws
//! from the random stream `(seed, k)`.
//!
//! # Complexity
//! O(T M) per iteration for the sweep, O(T M (n_alpha + n)^2) for the statistics.
//!
//! # References
//! Lindsten (2013), *An efficient stochastic approximation EM algorithm using
//! conditional particle filters*, ICASSP; Delyon, Lavielle and Moulines (1999).

use super::{
    AffineEmError, AffineEmSpec, AffineModel, AffineParams, AffineStatistics, StatisticsCollector,
    m_step,
};
use crate::EmAlgorithm;
use sysid_smc::{ConditionalSmc, CsmcKernel, Series, StateSpace, stream};

/// The step sizes `gamma_k` of the stochastic approximation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepSizes {
    /// Iterations with `gamma_k = 1` (plain Monte Carlo EM with one sweep). Default 100.
    pub burn_in: usize,
    /// Decay exponent in (0.5, 1]: `gamma_k = (k - burn_in)^(-exponent)`. Default 0.7.
    pub exponent: f64,
}

impl Default for StepSizes {
    fn default() -> Self {
        StepSizes {
            burn_in: 100,
            exponent: 0.7,
        }
    }
}

impl StepSizes {
    /// `gamma_k` for iteration `k` (1-based).
    pub fn gamma(&self, k: usize) -> f64 {
        if k <= self.burn_in {
            1.0
        } else {
            ((k - self.burn_in) as f64).powf(-self.exponent)
        }
    }

    fn check(&self) -> Result<(), AffineEmError> {
        if !(self.exponent > 0.5 && self.exponent <= 1.0) {
            return Err(AffineEmError::InvalidParams(format!(
                "PSAEM step-size exponent {} is not in (0.5, 1]",
                self.exponent
            )));
        }
        Ok(())
    }
}

/// PSAEM as an [`EmAlgorithm`] for the shared runner (run it with `tol = 0` for a
/// fixed number of iterations).
pub struct Psaem<'a, A> {
    model: &'a A,
    data: Series<'a>,
    spec: AffineEmSpec,
    steps: StepSizes,
    csmc: ConditionalSmc,
    reference: Option<Vec<f64>>,
    trajectory: Vec<f64>,
    averaged: Option<AffineStatistics>,
    seed: u64,
    iteration: usize,
}

impl<'a, A: AffineModel> Psaem<'a, A> {
    /// PSAEM on `data` with `particles >= 2` particles in the conditional SMC.
    pub fn new(
        model: &'a A,
        data: Series<'a>,
        particles: usize,
        steps: StepSizes,
        spec: AffineEmSpec,
        seed: u64,
    ) -> Result<Self, AffineEmError> {
        steps.check()?;
        if data.output_dim() != model.output_dim() {
            return Err(AffineEmError::InvalidParams(format!(
                "the data have {} outputs but the model has {}",
                data.output_dim(),
                model.output_dim()
            )));
        }
        Ok(Psaem {
            model,
            data,
            spec,
            steps,
            csmc: ConditionalSmc::new(particles, CsmcKernel::AncestorSampling)?,
            reference: None,
            trajectory: Vec::new(),
            averaged: None,
            seed,
            iteration: 0,
        })
    }

    /// The current reference trajectory (time-major), after the first iteration.
    pub fn reference(&self) -> Option<&[f64]> {
        self.reference.as_deref()
    }
}

/// `a <- (1 - gamma) a + gamma b`, field by field.
fn blend(a: &mut AffineStatistics, b: &AffineStatistics, gamma: f64) {
    let keep = 1.0 - gamma;
    a.state = &a.state * keep + &b.state * gamma;
    a.output = &a.output * keep + &b.output * gamma;
    a.initial_mean = &a.initial_mean * keep + &b.initial_mean * gamma;
    a.initial_second_moment = &a.initial_second_moment * keep + &b.initial_second_moment * gamma;
    a.state_steps = keep * a.state_steps + gamma * b.state_steps;
    a.output_steps = keep * a.output_steps + gamma * b.output_steps;
}

impl<A: AffineModel> EmAlgorithm for Psaem<'_, A> {
    type Estimate = AffineParams;
    type Error = AffineEmError;

    fn step(&mut self, current: &AffineParams) -> Result<(AffineParams, f64), AffineEmError> {
        self.iteration += 1;
        let k = self.iteration;
        let smc = self.model.smc_model(current)?;
        self.trajectory
            .resize(self.data.steps() * smc.state_dim(), 0.0);
        let mut rng = stream(self.seed, k as u64);
        let sweep = self.csmc.sample(
            &smc,
            &self.data,
            self.reference.as_deref(),
            &mut self.trajectory,
            &mut rng,
        )?;
        let mut collector = StatisticsCollector::new(self.model, &self.data);
        self.csmc.add_weighted_paths(&mut collector);
        let fresh = collector.finish();
        match &mut self.averaged {
            Some(averaged) => blend(averaged, &fresh, self.steps.gamma(k)),
            None => self.averaged = Some(fresh),
        }
        match &mut self.reference {
            Some(r) => r.copy_from_slice(&self.trajectory),
            None => self.reference = Some(self.trajectory.clone()),
        }
        let averaged = self.averaged.as_ref().expect("set above");
        let next = m_step(self.model, averaged, current, &self.spec)?;
        Ok((next, sweep.loglik))
    }

    fn loglik(&mut self, estimate: &AffineParams) -> Result<f64, AffineEmError> {
        // an unconditional sweep's estimate: consistent with the particle filter's
        let smc = self.model.smc_model(estimate)?;
        let mut rng = stream(self.seed, u64::MAX);
        let mut path = vec![0.0; self.data.steps() * smc.state_dim()];
        Ok(self
            .csmc
            .sample(&smc, &self.data, None, &mut path, &mut rng)?
            .loglik)
    }

    fn is_exact(&self) -> bool {
        false
    }
}
