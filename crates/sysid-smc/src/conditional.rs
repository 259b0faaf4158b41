//! Conditional SMC: the Markov kernel of particle Gibbs, plain, with ancestor sampling
//! (PGAS) or with backward simulation (PG-BS).
//!
//! # Model
//! Any [`FilterModel`] with a [`TransitionDensity`]:
//! `x_0 ~ mu`, `x_{t+1} ~ f(. | x_t)`, `y_t ~ g(. | x_t)`.
//!
//! # Algorithm
//! Given a reference trajectory `x'_{0:T-1}`, run a bootstrap filter with `M` particles
//! in which particle `M - 1` is forced to follow the reference: at every step the
//! `M - 1` free particles draw their ancestors multinomially from the normalised
//! weights `W_{t-1}` and propagate through `f`, and `x_t^{M-1} = x'_t`. The reference
//! particle's own ancestor is
//!
//! | kernel | ancestor of the reference at `t` | new trajectory |
//! | --- | --- | --- |
//! | [`CsmcKernel::Plain`] | `M - 1` (the reference's own past) | trace back from `k ~ Cat(W_{T-1})` |
//! | [`CsmcKernel::AncestorSampling`] | `i` w.p. ∝ `W_{t-1}^i f(x'_t \| x_{t-1}^i)` | trace back from `k ~ Cat(W_{T-1})` |
//! | [`CsmcKernel::BackwardSimulation`] | `M - 1` | backward simulation: `b_t` w.p. ∝ `W_t^i f(x~_{t+1} \| x_t^i)` |
//!
//! Each kernel leaves the smoothing distribution `p(x_{0:T-1} | y)` invariant for any
//! `M >= 2`. The plain kernel mixes poorly: far from `T` the traced path collapses
//! onto the reference (path degeneracy), which ancestor sampling and backward
//! simulation repair. Without a reference ([`ConditionalSmc::sample`] with `None`) the
//! run is an ordinary bootstrap filter, which gives a first trajectory.
//!
//! Steps whose outputs are all missing carry the weights unchanged. All randomness
//! comes from the caller's generator, in a fixed order.
//!
//! # Complexity
//! O(T M) time for the plain kernel and ancestor sampling, O(T M) more for backward
//! simulation; O(T M n) memory for the stored particle system.
//!
//! # Example
//! ```
//! use sysid_smc::conditional::{ConditionalSmc, CsmcKernel};
//! # use sysid_smc::*;
//! # use rand_distr::{Distribution, StandardNormal};
//! # struct RandomWalk;
//! # impl StateSpace for RandomWalk { fn state_dim(&self) -> usize { 1 } }
//! # impl InitialSampler for RandomWalk {
//! #     fn sample_initial<R: rand::Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
//! #         x[0] = StandardNormal.sample(rng);
//! #     }
//! # }
//! # impl TransitionSampler for RandomWalk {
//! #     fn sample_transition<R: rand::Rng + ?Sized>(&self, _: usize, x: &[f64], _: &[f64], next: &mut [f64], rng: &mut R) {
//! #         let w: f64 = StandardNormal.sample(rng);
//! #         next[0] = x[0] + w;
//! #     }
//! # }
//! # impl TransitionDensity for RandomWalk {
//! #     fn log_transition(&self, _: usize, x: &[f64], _: &[f64], next: &[f64]) -> f64 {
//! #         -0.5 * (next[0] - x[0]).powi(2)
//! #     }
//! # }
//! # impl ObservationDensity for RandomWalk {
//! #     fn log_observation(&self, _: usize, x: &[f64], _: &[f64], y: &[f64]) -> f64 {
//! #         -0.5 * (y[0] - x[0]).powi(2)
//! #     }
//! # }
//! let y = [0.3, 0.1, -0.4, 0.2];
//! let data = Series::new(&y, 1).unwrap();
//! let mut csmc = ConditionalSmc::new(10, CsmcKernel::AncestorSampling).unwrap();
//! let mut rng = sysid_smc::stream(1, 0);
//! let mut path = vec![0.0; 4];
//! csmc.sample(&RandomWalk, &data, None, &mut path, &mut rng).unwrap();
//! let reference = path.clone();
//! csmc.sample(&RandomWalk, &data, Some(&reference), &mut path, &mut rng).unwrap();
//! ```
//!
//! # References
//! Andrieu, Doucet and Holenstein (2010), *Particle Markov chain Monte Carlo methods*;
//! Whiteley (2010) and Lindsten and Schön (2013) for backward simulation; Lindsten,
//! Jordan and Schön (2014), *Particle Gibbs with ancestor sampling*.

use rand::RngExt;

use crate::model::{FilterModel, GuidedProposal, TransitionDensity};
use crate::resample::multinomial;
use crate::smoother::AdditiveFunctional;
use crate::weights::{DrawFailure, draw_from_log_weights, find_cumulative, normalise_log_weights};
use crate::{History, Series, SmcError};

/// How the conditional SMC treats the reference trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CsmcKernel {
    /// The reference keeps its own ancestry (Andrieu, Doucet and Holenstein 2010).
    Plain,
    /// The reference's ancestor is redrawn at every step (PGAS).
    AncestorSampling,
    /// The new trajectory is drawn by backward simulation (PG-BS).
    BackwardSimulation,
}

impl CsmcKernel {
    /// The name used on the command line: `plain`, `as` or `bs`.
    pub fn name(self) -> &'static str {
        match self {
            CsmcKernel::Plain => "plain",
            CsmcKernel::AncestorSampling => "as",
            CsmcKernel::BackwardSimulation => "bs",
        }
    }

    /// The kernel of a command-line name.
    pub fn from_name(name: &str) -> Option<CsmcKernel> {
        [
            CsmcKernel::Plain,
            CsmcKernel::AncestorSampling,
            CsmcKernel::BackwardSimulation,
        ]
        .into_iter()
        .find(|k| k.name() == name)
    }
}

/// A conditional SMC sampler with its reusable buffers (the stored particle system).
#[derive(Debug, Clone)]
pub struct ConditionalSmc {
    particles: usize,
    kernel: CsmcKernel,
    state_dim: usize,
    steps: usize,
    /// Particles, time-major then particle-major (`T x M x n`).
    states: Vec<f64>,
    /// Normalised log-weights `log W_t^i` (`T x M`).
    log_weights: Vec<f64>,
    /// Ancestors `a_t^i`, indices into step `t - 1` (`T x M`; identity at 0).
    ancestors: Vec<usize>,
    weights: Vec<f64>,
    log_obs: Vec<f64>,
    scratch: Vec<f64>,
    draws: Vec<f64>,
    loglik: f64,
}

/// What one conditional SMC sweep found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsmcSummary {
    /// The filter's log-likelihood estimate of the sweep (biased under conditioning;
    /// a diagnostic only).
    pub loglik: f64,
}

impl ConditionalSmc {
    /// A sampler with `particles >= 2` particles (one of them carries the reference).
    pub fn new(particles: usize, kernel: CsmcKernel) -> Result<Self, SmcError> {
        if particles < 2 {
            return Err(SmcError::InvalidOption {
                name: "particles",
                reason: format!(
                    "conditional SMC needs at least 2 particles (one is the reference), got {particles}"
                ),
            });
        }
        Ok(ConditionalSmc {
            particles,
            kernel,
            state_dim: 0,
            steps: 0,
            states: Vec::new(),
            log_weights: Vec::new(),
            ancestors: Vec::new(),
            weights: Vec::new(),
            log_obs: Vec::new(),
            scratch: Vec::new(),
            draws: Vec::new(),
            loglik: f64::NAN,
        })
    }

    /// Number of particles M.
    pub fn particles(&self) -> usize {
        self.particles
    }

    /// The kernel.
    pub fn kernel(&self) -> CsmcKernel {
        self.kernel
    }

    /// One sweep: runs the conditional filter given `reference` (time-major `T x n`;
    /// `None` runs an unconditional filter) and writes a new trajectory into `out`.
    ///
    /// Errors when the lengths do not fit the data, when the reference is not finite,
    /// when every particle gives an observation zero density (the reference included),
    /// and when the model returns NaN densities.
    pub fn sample<M: FilterModel + TransitionDensity, R: rand::Rng + ?Sized>(
        &mut self,
        model: &M,
        data: &Series,
        reference: Option<&[f64]>,
        out: &mut [f64],
        rng: &mut R,
    ) -> Result<CsmcSummary, SmcError> {
        self.check_output(model.state_dim(), data, out)?;
        self.dispatched_sweep(model, data, reference, &Bootstrap, out, rng)?;
        Ok(CsmcSummary {
            loglik: self.loglik,
        })
    }

    /// As [`sample`](Self::sample), with the locally optimal proposal of
    /// [`GuidedProposal`] at every fully observed step (free particles resampled with
    /// weights `W_{t-1}^i p(y_t | x_{t-1}^i)` and drawn from `p(x_t | x_{t-1}, y_t)`,
    /// all weights then equal; steps with missing outputs stay bootstrap). The
    /// reference's ancestor is drawn as before, with weights
    /// `W_{t-1}^i f(x'_t | x_{t-1}^i)`. With informative observations this keeps the free
    /// particles near the data, so ancestor sampling renews the trajectory at every
    /// step even with few particles.
    pub fn sample_guided<M, R>(
        &mut self,
        model: &M,
        data: &Series,
        reference: Option<&[f64]>,
        out: &mut [f64],
        rng: &mut R,
    ) -> Result<CsmcSummary, SmcError>
    where
        M: FilterModel + TransitionDensity + GuidedProposal,
        R: rand::Rng + ?Sized,
    {
        self.check_output(model.state_dim(), data, out)?;
        self.dispatched_sweep(model, data, reference, &Guided, out, rng)?;
        Ok(CsmcSummary {
            loglik: self.loglik,
        })
    }

    /// The forward pass and the draw of the new trajectory, compiled for the CPU's
    /// widest vector set ([`crate::simd::dispatch`]; the model's methods inlined into
    /// them too); the same numbers on every path.
    fn dispatched_sweep<M, P, R>(
        &mut self,
        model: &M,
        data: &Series,
        reference: Option<&[f64]>,
        proposer: &P,
        out: &mut [f64],
        rng: &mut R,
    ) -> Result<(), SmcError>
    where
        M: FilterModel + TransitionDensity,
        P: Proposer<M>,
        R: rand::Rng + ?Sized,
    {
        crate::simd::dispatch(SweepKernel {
            csmc: self,
            model,
            data,
            reference,
            proposer,
            out,
            rng,
        })
    }

    /// The unconditional guided sweep alone (no reference, no trajectory drawn):
    /// the filter of [`crate::GuidedFilter`]. Returns the log-likelihood estimate.
    pub(crate) fn filter_guided<M, R>(
        &mut self,
        model: &M,
        data: &Series,
        rng: &mut R,
    ) -> Result<f64, SmcError>
    where
        M: FilterModel + TransitionDensity + GuidedProposal,
        R: rand::Rng + ?Sized,
    {
        self.forward(model, data, None, &Guided, rng)?;
        Ok(self.loglik)
    }

    /// Copies the stored particle system of the last sweep into `history`
    /// (particles, normalised weights and their logarithms, ancestors; no step marked
    /// resampled).
    pub(crate) fn write_history(&self, history: &mut History) {
        let (n, m) = (self.state_dim, self.particles);
        history.reset(n, m, self.steps);
        let mut weights = vec![0.0; m];
        for t in 0..self.steps {
            let log_w = &self.log_weights[t * m..(t + 1) * m];
            for (w, l) in weights.iter_mut().zip(log_w) {
                *w = l.exp();
            }
            history.push(
                &self.states[t * m * n..(t + 1) * m * n],
                &weights,
                log_w,
                &self.ancestors[t * m..(t + 1) * m],
            );
        }
    }

    /// Draws the new trajectory from the stored particle system.
    #[inline(always)]
    fn finish<M: TransitionDensity, R: rand::Rng + ?Sized>(
        &mut self,
        model: &M,
        data: &Series,
        out: &mut [f64],
        rng: &mut R,
    ) -> Result<(), SmcError> {
        match self.kernel {
            CsmcKernel::BackwardSimulation => self.backward_simulate(model, data, out, rng)?,
            _ => {
                let k = self.draw_final(rng);
                self.trace(k, out);
            }
        }
        Ok(())
    }

    /// Adds every traced path of the last sweep's particle system to `functional`,
    /// path `i` (traced back from `x_{T-1}^i`) with weight `W_{T-1}^i`: the
    /// Rao-Blackwellised estimate of `E[sum_t s(t, x_t, x_{t+1}) | y]` that PSAEM uses.
    /// Adds nothing before the first sweep.
    pub fn add_weighted_paths<F: AdditiveFunctional + ?Sized>(&self, functional: &mut F) {
        if self.steps == 0 {
            return;
        }
        let (n, m, last) = (self.state_dim, self.particles, self.steps - 1);
        let mut index: Vec<usize> = (0..m).collect();
        let mut next = vec![0.0; m * n];
        let mut current = vec![0.0; m * n];
        let final_weights: Vec<f64> = self.log_weights[last * m..]
            .iter()
            .map(|l| l.exp())
            .collect();
        for t in (0..=last).rev() {
            for (x, &i) in current.chunks_exact_mut(n).zip(&index) {
                x.copy_from_slice(self.state(t, i));
            }
            for (k, x) in current.chunks_exact(n).enumerate() {
                if final_weights[k] > 0.0 {
                    let after = (t < last).then(|| &next[k * n..(k + 1) * n]);
                    functional.add(t, x, after, final_weights[k]);
                }
            }
            for i in index.iter_mut() {
                *i = self.ancestors[t * m + *i];
            }
            std::mem::swap(&mut current, &mut next);
        }
    }

    fn state(&self, t: usize, i: usize) -> &[f64] {
        let n = self.state_dim;
        let start = (t * self.particles + i) * n;
        &self.states[start..start + n]
    }

    fn check_output(&self, n: usize, data: &Series, out: &[f64]) -> Result<(), SmcError> {
        if out.len() != data.steps() * n {
            return Err(SmcError::DimensionMismatch {
                what: "output trajectory",
                expected: format!("T x n = {} x {n} values", data.steps()),
                found: out.len(),
            });
        }
        Ok(())
    }

    fn check(&self, n: usize, data: &Series, reference: Option<&[f64]>) -> Result<(), SmcError> {
        let expected = data.steps() * n;
        if let Some(r) = reference {
            if r.len() != expected {
                return Err(SmcError::DimensionMismatch {
                    what: "reference trajectory",
                    expected: format!("T x n = {} x {n} values", data.steps()),
                    found: r.len(),
                });
            }
            if let Some(k) = r.iter().position(|v| !v.is_finite()) {
                return Err(SmcError::NonFiniteData {
                    what: "reference trajectory",
                    t: k / n,
                    index: k % n,
                    value: r[k],
                });
            }
        }
        Ok(())
    }

    #[inline(always)]
    fn forward<M: FilterModel + TransitionDensity, P: Proposer<M>, R: rand::Rng + ?Sized>(
        &mut self,
        model: &M,
        data: &Series,
        reference: Option<&[f64]>,
        proposer: &P,
        rng: &mut R,
    ) -> Result<(), SmcError> {
        let n = model.state_dim();
        self.check(n, data, reference)?;
        let (m, steps) = (self.particles, data.steps());
        self.state_dim = n;
        self.steps = steps;
        self.states.resize(steps * m * n, 0.0);
        self.log_weights.resize(steps * m, 0.0);
        self.ancestors.resize(steps * m, 0);
        self.weights.resize(m, 0.0);
        self.log_obs.resize(m, 0.0);
        self.draws.resize(m, 0.0);
        // free particles: all of them without a reference, else all but the last
        let free = if reference.is_some() { m - 1 } else { m };
        let mut loglik = 0.0;
        let mut carried = vec![-(m as f64).ln(); m];
        for t in 0..steps {
            let (before, rest) = self.states.split_at_mut(t * m * n);
            let current = &mut rest[..m * n];
            let guided = proposer.guided(data, t);
            // log p(y_t | y_{0:t-1}) of a guided step
            let mut predictive = 0.0;
            if t == 0 {
                if guided {
                    predictive = proposer.initial(model, data, &mut current[..free * n], rng);
                } else {
                    model.sample_initials(&mut current[..free * n], rng);
                }
                for (i, a) in self.ancestors[..m].iter_mut().enumerate() {
                    *a = i;
                }
            } else {
                let previous = &before[(t - 1) * m * n..];
                let parents = &mut self.ancestors[t * m..(t + 1) * m];
                let u = data.input(t - 1);
                if guided {
                    // selection weights W_{t-1}^i p(y_t | x_{t-1}^i)
                    proposer.log_predictive(model, t, previous, data, &mut self.draws);
                    for (d, &c) in self.draws.iter_mut().zip(&carried) {
                        *d += c;
                    }
                    predictive = normalise_log_weights(&self.draws, &mut self.weights)
                        .unwrap_or(f64::NEG_INFINITY);
                    if !predictive.is_finite() {
                        return Err(weight_failure(&self.draws, predictive, t));
                    }
                    multinomial(&self.weights, rng, &mut parents[..free], &mut self.scratch);
                    proposer.propagate(
                        model,
                        t,
                        previous,
                        &parents[..free],
                        data,
                        &mut current[..free * n],
                        rng,
                    );
                } else {
                    multinomial(&self.weights, rng, &mut parents[..free], &mut self.scratch);
                    model.sample_transitions(
                        t - 1,
                        u,
                        previous,
                        &parents[..free],
                        &mut current[..free * n],
                        rng,
                    );
                }
                if let Some(r) = reference {
                    parents[m - 1] = match self.kernel {
                        CsmcKernel::AncestorSampling => {
                            let target = &r[t * n..(t + 1) * n];
                            model.log_transition_matrix(
                                t - 1,
                                u,
                                previous,
                                target,
                                &mut self.draws,
                                &mut self.scratch,
                            );
                            for (d, &lw) in self.draws.iter_mut().zip(&carried) {
                                *d += lw;
                            }
                            draw_from_log_weights(&mut self.draws, rng.random::<f64>())
                                .map_err(|f| backward_failure(f, t))?
                        }
                        _ => m - 1,
                    };
                }
                carried.fill(-(m as f64).ln());
            }
            if let Some(r) = reference {
                current[(m - 1) * n..].copy_from_slice(&r[t * n..(t + 1) * n]);
            }
            let log_w = &mut self.log_weights[t * m..(t + 1) * m];
            if guided {
                // fully adapted: every particle, the reference included, weighs the same
                log_w.fill(-(m as f64).ln());
                self.weights.fill(1.0 / m as f64);
                loglik += predictive;
                carried.copy_from_slice(log_w);
                continue;
            }
            if data.is_missing(t) {
                log_w.copy_from_slice(&carried);
            } else {
                model.log_observations(
                    t,
                    data.input(t),
                    data.output(t),
                    current,
                    &mut self.log_obs,
                );
                for ((l, &c), &g) in log_w.iter_mut().zip(&carried).zip(&self.log_obs) {
                    *l = c + g;
                }
            }
            let increment =
                normalise_log_weights(log_w, &mut self.weights).unwrap_or(f64::NEG_INFINITY);
            if !increment.is_finite() {
                return Err(weight_failure(&self.log_obs, increment, t));
            }
            for l in log_w.iter_mut() {
                *l -= increment;
            }
            loglik += increment;
            carried.copy_from_slice(log_w);
        }
        self.loglik = loglik;
        Ok(())
    }

    fn draw_final<R: rand::Rng + ?Sized>(&self, rng: &mut R) -> usize {
        let m = self.particles;
        let last = self.steps - 1;
        let weights: Vec<f64> = self.log_weights[last * m..]
            .iter()
            .map(|l| l.exp())
            .collect();
        find_cumulative(&weights, rng.random::<f64>())
    }

    /// Copies the path traced back from `x_{T-1}^k` into `out`.
    fn trace(&self, mut k: usize, out: &mut [f64]) {
        let (n, m) = (self.state_dim, self.particles);
        for t in (0..self.steps).rev() {
            out[t * n..(t + 1) * n].copy_from_slice(self.state(t, k));
            k = self.ancestors[t * m + k];
        }
    }

    fn backward_simulate<M: TransitionDensity, R: rand::Rng + ?Sized>(
        &mut self,
        model: &M,
        data: &Series,
        out: &mut [f64],
        rng: &mut R,
    ) -> Result<(), SmcError> {
        let (n, m) = (self.state_dim, self.particles);
        let last = self.steps - 1;
        let mut k = self.draw_final(rng);
        out[last * n..].copy_from_slice(self.state(last, k));
        for t in (0..last).rev() {
            let (head, tail) = out.split_at_mut((t + 1) * n);
            let next = &tail[..n];
            let from = &self.states[t * m * n..(t + 1) * m * n];
            model.log_transition_matrix(
                t,
                data.input(t),
                from,
                next,
                &mut self.draws,
                &mut self.scratch,
            );
            for (d, &lw) in self
                .draws
                .iter_mut()
                .zip(&self.log_weights[t * m..(t + 1) * m])
            {
                *d += lw;
            }
            k = draw_from_log_weights(&mut self.draws, rng.random::<f64>())
                .map_err(|f| backward_failure(f, t))?;
            head[t * n..].copy_from_slice(self.state(t, k));
        }
        Ok(())
    }
}

/// The error of a failed ancestor or backward draw at `t`.
fn backward_failure(failure: DrawFailure, t: usize) -> SmcError {
    match failure {
        DrawFailure::Degenerate => SmcError::DegenerateBackward { t, path: 0 },
        DrawFailure::Invalid => SmcError::InvalidDensity {
            what: "transition log-density",
            t,
            particle: 0,
            value: f64::NAN,
        },
    }
}

/// The error of a weight normalisation that failed at `t`.
fn weight_failure(log_obs: &[f64], increment: f64, t: usize) -> SmcError {
    match log_obs
        .iter()
        .enumerate()
        .find(|(_, v)| v.is_nan() || **v == f64::INFINITY)
    {
        Some((particle, &value)) => SmcError::InvalidDensity {
            what: "observation log-density",
            t,
            particle,
            value,
        },
        None if increment == f64::NEG_INFINITY => SmcError::DegenerateWeights { t },
        None => SmcError::InvalidDensity {
            what: "observation log-density",
            t,
            particle: 0,
            value: increment,
        },
    }
}

/// How the free particles of a step are proposed.
/// [`ConditionalSmc::dispatched_sweep`]'s work as a [`crate::simd::Kernel`].
struct SweepKernel<'a, 'd, M, P, R: ?Sized> {
    csmc: &'a mut ConditionalSmc,
    model: &'a M,
    data: &'a Series<'d>,
    reference: Option<&'a [f64]>,
    proposer: &'a P,
    out: &'a mut [f64],
    rng: &'a mut R,
}

impl<M, P, R> crate::simd::Kernel for SweepKernel<'_, '_, M, P, R>
where
    M: FilterModel + TransitionDensity,
    P: Proposer<M>,
    R: rand::Rng + ?Sized,
{
    type Output = Result<(), SmcError>;

    #[inline(always)]
    fn run(self) -> Self::Output {
        let (model, data) = (self.model, self.data);
        self.csmc
            .forward(model, data, self.reference, self.proposer, &mut *self.rng)?;
        self.csmc.finish(model, data, self.out, self.rng)
    }
}

trait Proposer<M> {
    /// Whether step `t` uses the guided proposal.
    fn guided(&self, data: &Series, t: usize) -> bool;
    /// Fills `states` with draws of `p(x_0 | y_0)`; returns `log p(y_0)`.
    fn initial<R: rand::Rng + ?Sized>(
        &self,
        model: &M,
        data: &Series,
        states: &mut [f64],
        rng: &mut R,
    ) -> f64;
    /// `out[i] = log p(y_t | x_{t-1}^i)`.
    fn log_predictive(&self, model: &M, t: usize, previous: &[f64], data: &Series, out: &mut [f64]);
    /// `next_k ~ p(x_t | x_{t-1}^{parents[k]}, y_t)`.
    #[allow(clippy::too_many_arguments)]
    fn propagate<R: rand::Rng + ?Sized>(
        &self,
        model: &M,
        t: usize,
        previous: &[f64],
        parents: &[usize],
        data: &Series,
        next: &mut [f64],
        rng: &mut R,
    );
}

/// The bootstrap proposal: never guided (the other methods are not called).
struct Bootstrap;

impl<M> Proposer<M> for Bootstrap {
    fn guided(&self, _data: &Series, _t: usize) -> bool {
        false
    }
    fn initial<R: rand::Rng + ?Sized>(&self, _: &M, _: &Series, _: &mut [f64], _: &mut R) -> f64 {
        0.0
    }
    fn log_predictive(&self, _: &M, _: usize, _: &[f64], _: &Series, _: &mut [f64]) {}
    fn propagate<R: rand::Rng + ?Sized>(
        &self,
        _: &M,
        _: usize,
        _: &[f64],
        _: &[usize],
        _: &Series,
        _: &mut [f64],
        _: &mut R,
    ) {
    }
}

/// The locally optimal proposal of [`GuidedProposal`] at fully observed steps.
struct Guided;

impl<M: GuidedProposal> Proposer<M> for Guided {
    fn guided(&self, data: &Series, t: usize) -> bool {
        !data.output(t).iter().any(|v| v.is_nan())
    }

    fn initial<R: rand::Rng + ?Sized>(
        &self,
        model: &M,
        data: &Series,
        states: &mut [f64],
        rng: &mut R,
    ) -> f64 {
        let (u, y) = (data.input(0), data.output(0));
        for x in states.chunks_exact_mut(model.state_dim()) {
            model.sample_initial_guided(u, y, x, rng);
        }
        model.log_initial_predictive(u, y)
    }

    fn log_predictive(
        &self,
        model: &M,
        t: usize,
        previous: &[f64],
        data: &Series,
        out: &mut [f64],
    ) {
        let (u, u_next, y) = (data.input(t - 1), data.input(t), data.output(t));
        for (o, x) in out.iter_mut().zip(previous.chunks_exact(model.state_dim())) {
            *o = model.log_predictive(t - 1, x, u, u_next, y);
        }
    }

    fn propagate<R: rand::Rng + ?Sized>(
        &self,
        model: &M,
        t: usize,
        previous: &[f64],
        parents: &[usize],
        data: &Series,
        next: &mut [f64],
        rng: &mut R,
    ) {
        let n = model.state_dim();
        let (u, u_next, y) = (data.input(t - 1), data.input(t), data.output(t));
        for (x, &p) in next.chunks_exact_mut(n).zip(parents) {
            model.sample_guided(t - 1, &previous[p * n..(p + 1) * n], u, u_next, y, x, rng);
        }
    }
}
