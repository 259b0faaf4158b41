//! Particle Gibbs: conditional SMC for the states, a user step for the parameters.
//!
//! # Model
//! A [`ModelFamily`] `p_theta(x, y)`; the target is the joint posterior
//! `p(theta, x_{0:T-1} | y)`.
//!
//! # Algorithm
//! Alternate
//! 1. `theta ~ K(theta, . | x)`, a kernel leaving `p(theta | x, y)` invariant: the
//!    user's [`ParameterStep`] (an exact conjugate draw, or [`MetropolisWithinGibbs`]);
//! 2. `x ~` the conditional SMC kernel of `sysid_smc::conditional` given the current
//!    trajectory: plain, with ancestor sampling (PGAS) or with backward simulation
//!    (PG-BS).
//!
//! The first trajectory comes from an unconditional filter at the starting
//! parameters. Per time step the sampler records how often `x_t` changed after
//! burn-in (the update rate: near 0 means the plain kernel's path degeneracy), and the
//! posterior mean of the states.
//!
//! **Randomness.** Chain `c` draws from the stream `(seed, c)`, so chains are
//! identical whatever the number of threads.
//!
//! # Complexity
//! One conditional SMC sweep per iteration, O(T M), plus the parameter step
//! (O(T) for the provided ones).
//!
//! # References
//! Andrieu, Doucet and Holenstein (2010); Lindsten, Jordan and Schön (2014);
//! Lindsten and Schön (2013), *Backward simulation methods for Monte Carlo statistical
//! inference*.

use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use sysid_smc::ModelError;
use sysid_smc::{
    ConditionalSmc, CsmcKernel, CsmcSummary, GuidedProposal, InitialDensity, ObservationDensity,
    Rng, Series, SmcError, TransitionDensity, stream,
};

use crate::family::{Transform, check_start};
use crate::pmmh::{ChainRecorder, check_lengths};
use crate::{Chain, ChainRun, ModelFamily, PmcmcError, Prior};

/// A Markov kernel for `theta` given the states, leaving `p(theta | x, y)` invariant.
///
/// Each chain works on its own clone.
///
/// # Example
/// A random-walk Metropolis step on `phi` of the AR(1) family, whose conditional
/// density given the states is the product of the transition densities (flat prior):
/// ```
/// # use rand_distr::{Distribution, StandardNormal};
/// # use sysid_smc::*;
/// # /// x' = phi x + w (w ~ N(0, q)), y = x + e (e ~ N(0, 0.5)), x_0 ~ N(0, 1)
/// # #[derive(Clone)]
/// # struct Ar { phi: f64, q: f64 }
/// # impl StateSpace for Ar { fn state_dim(&self) -> usize { 1 } }
/// # impl InitialSampler for Ar {
/// #     fn sample_initial<R: rand::Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
/// #         x[0] = StandardNormal.sample(rng);
/// #     }
/// # }
/// # impl TransitionSampler for Ar {
/// #     fn sample_transition<R: rand::Rng + ?Sized>(
/// #         &self, _t: usize, x: &[f64], _u: &[f64], next: &mut [f64], rng: &mut R,
/// #     ) {
/// #         let w: f64 = StandardNormal.sample(rng);
/// #         next[0] = self.phi * x[0] + self.q.sqrt() * w;
/// #     }
/// # }
/// # impl ObservationDensity for Ar {
/// #     fn log_observation(&self, _t: usize, x: &[f64], _u: &[f64], y: &[f64]) -> f64 {
/// #         ScalarGaussianKernel::with_variance(0.5).log_density(x[0], y[0])
/// #     }
/// # }
/// # impl TransitionDensity for Ar {
/// #     fn log_transition(&self, _t: usize, x: &[f64], _u: &[f64], next: &[f64]) -> f64 {
/// #         ScalarGaussianKernel::with_variance(self.q).log_density(self.phi * x[0], next[0])
/// #     }
/// # }
/// use rand::RngExt;
/// use sysid_pmcmc::{ModelFamily, ParameterStep, Support};
/// # struct ArFamily;
/// # impl ModelFamily for ArFamily {
/// #     type Model = Ar;
/// #     fn parameter_names(&self) -> Vec<String> { vec!["phi".into()] }
/// #     fn supports(&self) -> Vec<Support> { vec![Support::Interval(-1.0, 1.0)] }
/// #     fn model(&self, theta: &[f64]) -> Result<Ar, sysid_smc::ModelError> { Ok(Ar { phi: theta[0], q: 1.0 }) }
/// # }
/// #[derive(Clone)]
/// struct PhiStep { sd: f64 }
/// impl ParameterStep<ArFamily> for PhiStep {
///     fn update(&mut self, family: &ArFamily, theta: &mut [f64], x: &[f64], _data: &Series,
///         rng: &mut sysid_smc::Rng) -> Result<bool, sysid_smc::ModelError> {
///         let log_p = |phi: f64| -> f64 {
///             let model = Ar { phi, q: 1.0 };
///             x.windows(2).map(|w| model.log_transition(0, &w[..1], &[], &w[1..])).sum()
///         };
///         let proposal = theta[0] + self.sd * (rng.random::<f64>() - 0.5);
///         if proposal.abs() >= 1.0 {
///             return Ok(false);
///         }
///         let accept = rng.random::<f64>().ln() < log_p(proposal) - log_p(theta[0]);
///         if accept {
///             theta[0] = proposal;
///         }
///         Ok(accept)
///     }
/// }
/// let mut theta = [0.5];
/// let states = [0.0, 0.9, 1.5, 1.2];
/// let y = [0.0; 4];
/// let mut step = PhiStep { sd: 0.2 };
/// step.update(&ArFamily, &mut theta, &states, &Series::new(&y, 1).unwrap(), &mut stream(1, 0)).unwrap();
/// assert!(theta[0].abs() < 1.0);
/// ```
pub trait ParameterStep<F: ModelFamily>: Clone + Send + Sync {
    /// Updates `theta` given the trajectory `x` (time-major `T x n`); returns whether a
    /// proposal was accepted (always true for an exact draw), or why the step failed.
    fn update(
        &mut self,
        family: &F,
        theta: &mut [f64],
        trajectory: &[f64],
        data: &Series,
        rng: &mut Rng,
    ) -> Result<bool, ModelError>;
}

/// Settings of particle Gibbs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GibbsOptions {
    /// Iterations per chain, burn-in included. Default 5 000.
    pub iterations: usize,
    /// Leading iterations dropped from summaries. Default 1 000.
    pub burn_in: usize,
    /// Particles of the conditional SMC (>= 2). Default 10.
    pub particles: usize,
    /// The conditional SMC kernel. Default ancestor sampling.
    pub kernel: CsmcKernel,
}

impl Default for GibbsOptions {
    fn default() -> Self {
        GibbsOptions {
            iterations: 5_000,
            burn_in: 1_000,
            particles: 10,
            kernel: CsmcKernel::AncestorSampling,
        }
    }
}

/// Runs `run.chains` particle Gibbs chains from `start`, in parallel on the current
/// rayon pool; chain `c` draws from the random stream `(run.seed, c)`. `prior` is
/// recorded per draw (the step uses its own).
pub fn particle_gibbs<F: ModelFamily, P: Prior, S: ParameterStep<F>>(
    family: &F,
    prior: &P,
    step: &S,
    data: &Series,
    start: &[f64],
    options: &GibbsOptions,
    run: &ChainRun<'_>,
) -> Result<Vec<Chain>, PmcmcError> {
    Gibbs::new(family, prior, step, data, start, options, run)
        .chains(&|csmc, model, reference, out, rng| csmc.sample(model, data, reference, out, rng))
}

/// As [`particle_gibbs`], with the conditional SMC's locally optimal proposal
/// (`ConditionalSmc::sample_guided`) for models that provide one
/// ([`GuidedProposal`]): with informative observations the state trajectory is then
/// renewed at every step even with very few particles.
pub fn particle_gibbs_guided<F, P, S>(
    family: &F,
    prior: &P,
    step: &S,
    data: &Series,
    start: &[f64],
    options: &GibbsOptions,
    run: &ChainRun<'_>,
) -> Result<Vec<Chain>, PmcmcError>
where
    F: ModelFamily,
    F::Model: GuidedProposal,
    P: Prior,
    S: ParameterStep<F>,
{
    Gibbs::new(family, prior, step, data, start, options, run).chains(
        &|csmc, model, reference, out, rng| csmc.sample_guided(model, data, reference, out, rng),
    )
}

/// One conditional SMC sweep (bootstrap or guided).
type Sweep<'a, M> = dyn Fn(
        &mut ConditionalSmc,
        &M,
        Option<&[f64]>,
        &mut [f64],
        &mut Rng,
    ) -> Result<CsmcSummary, SmcError>
    + Sync
    + 'a;

fn check_options(options: &GibbsOptions) -> Result<(), PmcmcError> {
    check_lengths(options.iterations, options.burn_in)?;
    ConditionalSmc::new(options.particles, options.kernel).map_err(|source| {
        PmcmcError::InvalidOption {
            name: "particles",
            reason: source.to_string(),
        }
    })?;
    Ok(())
}

/// A particle Gibbs run: what both samplers share but the sweep.
struct Gibbs<'a, F, P, S> {
    family: &'a F,
    prior: &'a P,
    step: &'a S,
    data: &'a Series<'a>,
    start: &'a [f64],
    options: &'a GibbsOptions,
    run: &'a ChainRun<'a>,
}

impl<'a, F: ModelFamily, P: Prior, S: ParameterStep<F>> Gibbs<'a, F, P, S> {
    /// The run of `step` and `prior` on `data` from `start`.
    fn new(
        family: &'a F,
        prior: &'a P,
        step: &'a S,
        data: &'a Series<'a>,
        start: &'a [f64],
        options: &'a GibbsOptions,
        run: &'a ChainRun<'a>,
    ) -> Self {
        Gibbs {
            family,
            prior,
            step,
            data,
            start,
            options,
            run,
        }
    }

    /// Checks the options and the start, then runs the chains in parallel.
    fn chains(&self, sweep: &Sweep<'_, F::Model>) -> Result<Vec<Chain>, PmcmcError> {
        check_options(self.options)?;
        check_start(self.family, self.start)?;
        self.run
            .chain_ids()
            .into_par_iter()
            .map(|c| self.chain(c, sweep))
            .collect()
    }

    /// Chain `chain`.
    fn chain(&self, chain: usize, sweep: &Sweep<'_, F::Model>) -> Result<Chain, PmcmcError> {
        let Gibbs {
            family,
            prior,
            data,
            start,
            options,
            ..
        } = *self;
        let (seed, observer) = (self.run.seed, self.run.observer);
        let mut step = self.step.clone();
        let smc_error = |iteration: usize| {
            move |source| PmcmcError::Smc {
                chain,
                iteration,
                source,
            }
        };
        let mut rng = stream(seed, chain as u64);
        let mut csmc =
            ConditionalSmc::new(options.particles, options.kernel).map_err(smc_error(0))?;
        let mut theta = start.to_vec();
        let model = family
            .model(&theta)
            .map_err(|e| PmcmcError::InadmissibleStart { reason: e.reason })?;
        let n = sysid_smc::StateSpace::state_dim(&model);
        let steps = data.steps();
        let mut trajectory = vec![0.0; steps * n];
        sweep(&mut csmc, &model, None, &mut trajectory, &mut rng).map_err(smc_error(0))?;
        let mut previous = trajectory.clone();
        let mut changes = vec![0usize; steps];
        let mut state_sum = vec![0.0; steps * n];
        let mut out = ChainRecorder::new(
            family.parameter_names(),
            options.iterations,
            options.burn_in,
        );
        for iteration in 0..options.iterations {
            let accepted = step
                .update(family, &mut theta, &trajectory, data, &mut rng)
                .map_err(|e| PmcmcError::ParameterStep {
                    chain,
                    iteration,
                    reason: e.reason,
                })?;
            let model = family
                .model(&theta)
                .map_err(|reason| PmcmcError::ParameterStep {
                    chain,
                    iteration,
                    reason: format!("the step moved to an inadmissible point: {reason}"),
                })?;
            previous.copy_from_slice(&trajectory);
            let result = sweep(
                &mut csmc,
                &model,
                Some(&previous),
                &mut trajectory,
                &mut rng,
            )
            .map_err(smc_error(iteration))?;
            if iteration >= options.burn_in {
                for (t, (new, old)) in trajectory
                    .chunks_exact(n)
                    .zip(previous.chunks_exact(n))
                    .enumerate()
                {
                    if new != old {
                        changes[t] += 1;
                    }
                }
                for (s, &x) in state_sum.iter_mut().zip(&trajectory) {
                    *s += x;
                }
            }
            out.push(&theta, result.loglik, prior.log_density(&theta), accepted);
            observer.iteration(chain, iteration);
            if observer.should_stop() && iteration + 1 < options.iterations {
                out.interrupt();
                break;
            }
        }
        // the post-burn-in iterations actually made (fewer when interrupted)
        let kept = out.len().saturating_sub(options.burn_in).max(1) as f64;
        let mut result = out.finish();
        result.state_update_rate = Some(changes.iter().map(|&c| c as f64 / kept).collect());
        result.state_mean = Some(state_sum.iter().map(|s| s / kept).collect());
        Ok(result)
    }
}

/// `log p_theta(x, y) = log mu(x_0) + sum_t log f(x_{t+1} | x_t) + sum_t log g(y_t | x_t)`
/// for a trajectory `x` (time-major `T x n`); steps with every output missing have no
/// observation term.
pub fn complete_data_log_likelihood<M>(model: &M, data: &Series, trajectory: &[f64]) -> f64
where
    M: InitialDensity + TransitionDensity + ObservationDensity,
{
    let n = model.state_dim();
    let mut total = model.log_initial(&trajectory[..n]);
    for (t, x) in trajectory.chunks_exact(n).enumerate() {
        if let Some(next) = trajectory.get((t + 1) * n..(t + 2) * n) {
            total += model.log_transition(t, x, data.input(t), next);
        }
        if !data.is_missing(t) {
            total += model.log_observation(t, x, data.input(t), data.output(t));
        }
    }
    total
}

/// A random-walk Metropolis step for `theta | x, y` on the unconstrained scale:
/// `sweeps` proposals `z* = z + diag(proposal_sd) e`, each accepted with probability
/// `min(1, p(x, y | theta*) p(theta*) J(z*) / (p(x, y | theta) p(theta) J(z)))`.
///
/// Works for any family whose models have an [`InitialDensity`]; costs O(T) per
/// proposal.
#[derive(Debug, Clone, PartialEq)]
pub struct MetropolisWithinGibbs<P> {
    /// The prior.
    pub prior: P,
    /// Random-walk standard deviation per parameter (unconstrained scale).
    pub proposal_sd: Vec<f64>,
    /// Proposals per Gibbs iteration.
    pub sweeps: usize,
}

impl<F, P> ParameterStep<F> for MetropolisWithinGibbs<P>
where
    F: ModelFamily,
    F::Model: InitialDensity,
    P: Prior + Clone + Send,
{
    fn update(
        &mut self,
        family: &F,
        theta: &mut [f64],
        trajectory: &[f64],
        data: &Series,
        rng: &mut Rng,
    ) -> Result<bool, ModelError> {
        let d = theta.len();
        if self.proposal_sd.len() != d {
            return Err(format!(
                "proposal_sd has {} entries for {d} parameters",
                self.proposal_sd.len()
            )
            .into());
        }
        let transform = Transform::new(family.supports());
        let mut z = vec![0.0; d];
        transform
            .to_unconstrained(theta, &mut z)
            .map_err(|k| format!("parameter {k} = {} is outside its support", theta[k]))?;
        let log_target = |theta: &[f64], log_jacobian: f64| -> f64 {
            let prior = self.prior.log_density(theta);
            if prior == f64::NEG_INFINITY {
                return prior;
            }
            match family.model(theta) {
                Ok(model) => {
                    prior + log_jacobian + complete_data_log_likelihood(&model, data, trajectory)
                }
                Err(_) => f64::NEG_INFINITY,
            }
        };
        let mut current_theta = theta.to_vec();
        let mut proposal = vec![0.0; d];
        let mut proposal_theta = vec![0.0; d];
        let mut current = log_target(
            &current_theta,
            transform.to_constrained(&z, &mut proposal_theta),
        );
        let mut any = false;
        for _ in 0..self.sweeps {
            for ((p, &zk), &sd) in proposal.iter_mut().zip(&z).zip(&self.proposal_sd) {
                let e: f64 = StandardNormal.sample(rng);
                *p = zk + sd * e;
            }
            let log_jacobian = transform.to_constrained(&proposal, &mut proposal_theta);
            let candidate = log_target(&proposal_theta, log_jacobian);
            if rng.random::<f64>().ln() < candidate - current {
                z.copy_from_slice(&proposal);
                current_theta.copy_from_slice(&proposal_theta);
                current = candidate;
                any = true;
            }
        }
        theta.copy_from_slice(&current_theta);
        Ok(any)
    }
}
