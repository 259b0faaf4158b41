//! Particle marginal Metropolis-Hastings (PMMH).
//!
//! # Model
//! A [`ModelFamily`] `p_theta(x, y)` with a [`Prior`] `p(theta)`; the target is
//! `p(theta | y)`.
//!
//! # Algorithm
//! A Gaussian random walk on the unconstrained parameters `z` (see [`Support`](crate::Support)):
//! `z* = z + L e`, `e ~ N(0, I)`. The intractable likelihood is replaced by the
//! bootstrap filter's estimate `p^(y | theta*)`, which is unbiased, so the chain
//! targets the exact posterior (Andrieu, Doucet and Holenstein 2010). Accept with
//! probability
//! `min(1, p^(y|theta*) p(theta*) J(z*) / (p^(y|theta) p(theta) J(z)))`, `J` the
//! Jacobian of `z -> theta`. The estimate of the current state is kept, never
//! recomputed (ALGORITHMS.md 5). Proposals with zero prior density or that the family
//! refuses are rejected without running the filter; a filter whose weights all vanish
//! estimates `p(y) = 0` and is rejected too.
//!
//! **Proposal.** The step is `lambda L e` with `L L'` starting as
//! `diag(proposal_sd^2)` and `lambda = 1`. With `adapt`, during burn-in:
//! - `ln lambda` follows a Robbins-Monro recursion towards the acceptance rate
//!   [`TARGET_ACCEPTANCE`]: `ln lambda += (alpha_k - 0.15) / sqrt(k + 1)`, `alpha_k` the
//!   iteration's acceptance probability (Andrieu and Thoms 2008). This rescues a first
//!   guess that is far too wide or too narrow;
//! - every [`ADAPT_EVERY`] iterations from iteration `max(200, 20 d)`, once the chain
//!   has moved at least `2 d` times, `L L'` becomes `(2.38^2 / d) Cov(z)` of the second
//!   half of the burn-in draws so far (plus `1e-10 I`), the adaptive Metropolis shape
//!   of Haario, Saksman and Tamminen (2001), and `lambda` restarts at 1.
//!
//! Both are frozen at the end of burn-in, so the kept draws come from a fixed, valid MH
//! kernel.
//!
//! **Randomness.** Chain `c` draws from the stream `(seed, c)`; each filter run gets a
//! fresh seed from the chain's stream. Chains are identical whatever the number of
//! threads.
//!
//! # Complexity
//! One particle filter per iteration: O(K T M) for K iterations.
//!
//! # References
//! Andrieu, Doucet and Holenstein (2010); Haario, Saksman and Tamminen (2001);
//! Sherlock, Thiery, Roberts and Rosenthal (2015) on scaling.

use nalgebra::{DMatrix, DVector};
use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use sysid_smc::{FilterOptions, ParticleFilter, Resampling, Series, SmcError, stream};

use crate::family::{Transform, check_start};
use crate::{Chain, ChainRun, ModelFamily, PmcmcError, Prior};

/// Iterations between two adaptations of the proposal shape during burn-in.
pub const ADAPT_EVERY: usize = 100;

/// The acceptance rate the burn-in scaling aims at (a compromise between the 0.234
/// of exact random-walk Metropolis and the 0.07 to 0.15 that suit noisy likelihood
/// estimates, Sherlock et al. 2015).
pub const TARGET_ACCEPTANCE: f64 = 0.15;

/// Settings of PMMH.
#[derive(Debug, Clone, PartialEq)]
pub struct PmmhOptions {
    /// Iterations per chain, burn-in included. Default 10 000.
    pub iterations: usize,
    /// Leading iterations dropped from summaries (and used for adaptation). Default
    /// 2 000.
    pub burn_in: usize,
    /// Particles of the filter M. Default 100.
    pub particles: usize,
    /// Resampling scheme of the filter. Default systematic.
    pub resampling: Resampling,
    /// Random-walk standard deviations on the unconstrained scale, one per parameter;
    /// empty means 0.1 for each. Default empty.
    pub proposal_sd: Vec<f64>,
    /// Adapt the proposal covariance during burn-in. Default true.
    pub adapt: bool,
}

impl Default for PmmhOptions {
    fn default() -> Self {
        PmmhOptions {
            iterations: 10_000,
            burn_in: 2_000,
            particles: 100,
            resampling: Resampling::Systematic,
            proposal_sd: Vec::new(),
            adapt: true,
        }
    }
}

impl PmmhOptions {
    /// Checks the options against a family of dimension `dim`.
    pub fn check(&self, dim: usize) -> Result<(), PmcmcError> {
        check_lengths(self.iterations, self.burn_in)?;
        if self.particles == 0 {
            return Err(PmcmcError::InvalidOption {
                name: "particles",
                reason: "must be at least 1".into(),
            });
        }
        if !self.proposal_sd.is_empty() && self.proposal_sd.len() != dim {
            return Err(PmcmcError::DimensionMismatch {
                what: "proposal_sd",
                expected: dim,
                found: self.proposal_sd.len(),
            });
        }
        if let Some(v) = self
            .proposal_sd
            .iter()
            .find(|v| !(**v > 0.0 && v.is_finite()))
        {
            return Err(PmcmcError::InvalidOption {
                name: "proposal_sd",
                reason: format!("{v} is not a positive finite number"),
            });
        }
        Ok(())
    }
}

/// Checks an iteration count and a burn-in.
pub(crate) fn check_lengths(iterations: usize, burn_in: usize) -> Result<(), PmcmcError> {
    if iterations == 0 {
        return Err(PmcmcError::InvalidOption {
            name: "iterations",
            reason: "must be at least 1".into(),
        });
    }
    if burn_in >= iterations {
        return Err(PmcmcError::InvalidOption {
            name: "burn_in",
            reason: format!("{burn_in} leaves no draws out of {iterations} iterations"),
        });
    }
    Ok(())
}

/// Runs `run.chains` independent PMMH chains from `start` (constrained parameters), in
/// parallel on the current rayon pool. Chain `c` (of [`ChainRun::chain_ids`]) uses the
/// random stream `(run.seed, c)`.
///
/// # Example
/// ```no_run
/// # fn demo<F: sysid_pmcmc::ModelFamily>(family: &F, prior: &sysid_pmcmc::IndependentPrior,
/// #         data: &sysid_smc::Series, start: &[f64]) {
/// use sysid_pmcmc::{ChainRun, PmmhOptions, pmmh};
/// let chains = pmmh(family, prior, data, start, &PmmhOptions::default(), &ChainRun::new(4, 1))
///     .unwrap();
/// println!("acceptance {}", chains[0].acceptance_rate());
/// # }
/// ```
pub fn pmmh<F: ModelFamily, P: Prior>(
    family: &F,
    prior: &P,
    data: &Series,
    start: &[f64],
    options: &PmmhOptions,
    run: &ChainRun<'_>,
) -> Result<Vec<Chain>, PmcmcError> {
    options.check(family.dim())?;
    check_start(family, start)?;
    if !prior.log_density(start).is_finite() {
        return Err(PmcmcError::InadmissibleStart {
            reason: "the prior density is zero (or not finite) at the start".into(),
        });
    }
    let sampler = Pmmh {
        family,
        prior,
        data,
        start,
        options,
        run,
    };
    run.chain_ids()
        .into_par_iter()
        .map(|c| sampler.chain(c))
        .collect()
}

/// A PMMH run.
struct Pmmh<'a, F, P> {
    family: &'a F,
    prior: &'a P,
    data: &'a Series<'a>,
    start: &'a [f64],
    options: &'a PmmhOptions,
    run: &'a ChainRun<'a>,
}

/// The state of a chain: parameters on both scales and the log-target pieces.
#[derive(Clone)]
struct State {
    z: Vec<f64>,
    theta: Vec<f64>,
    log_likelihood: f64,
    log_prior: f64,
    log_jacobian: f64,
}

impl State {
    fn log_target(&self) -> f64 {
        self.log_likelihood + self.log_prior + self.log_jacobian
    }
}

impl<F: ModelFamily, P: Prior> Pmmh<'_, F, P> {
    /// Chain `chain`.
    fn chain(&self, chain: usize) -> Result<Chain, PmcmcError> {
        let Pmmh {
            family,
            prior,
            data,
            start,
            options,
            ..
        } = *self;
        let (seed, observer) = (self.run.seed, self.run.observer);
        let d = family.dim();
        let transform = Transform::new(family.supports());
        let mut rng = stream(seed, chain as u64);
        let mut filter = ParticleFilter::new(FilterOptions {
            particles: options.particles,
            resampling: options.resampling,
            // only the log-likelihood estimate is used
            record_summaries: false,
            ..Default::default()
        })
        .map_err(|source| PmcmcError::Smc {
            chain,
            iteration: 0,
            source,
        })?;
        let mut z = vec![0.0; d];
        transform
            .to_unconstrained(start, &mut z)
            .expect("the start was checked");
        let mut current = State {
            log_jacobian: transform.to_constrained(&z, &mut vec![0.0; d]),
            z,
            theta: start.to_vec(),
            log_likelihood: 0.0,
            log_prior: prior.log_density(start),
        };
        let model = family
            .model(start)
            .map_err(|e| PmcmcError::InadmissibleStart { reason: e.reason })?;
        current.log_likelihood = match filter.run(&model, data, rng.random::<u64>()) {
            Ok(run) => run.loglik,
            Err(SmcError::DegenerateWeights { t }) => {
                return Err(PmcmcError::InadmissibleStart {
                    reason: format!("the particle filter's weights vanish at time {t}"),
                });
            }
            Err(source) => {
                return Err(PmcmcError::Smc {
                    chain,
                    iteration: 0,
                    source,
                });
            }
        };
        let mut proposal = Proposal::new(options, d);
        let mut out = ChainRecorder::new(
            family.parameter_names(),
            options.iterations,
            options.burn_in,
        );
        let mut candidate = current.clone();
        let mut noise = vec![0.0; d];
        // the unconstrained draws, for adapting the proposal's shape during burn-in
        let mut visited = Vec::with_capacity(options.burn_in * d);
        let mut moves = 0usize;
        for iteration in 0..options.iterations {
            let adapting = options.adapt && iteration < options.burn_in;
            if adapting && moves >= 2 * d {
                proposal.adapt_shape(iteration, &visited);
            }
            for e in noise.iter_mut() {
                *e = StandardNormal.sample(&mut rng);
            }
            proposal.step(&current.z, &noise, &mut candidate.z);
            let filter_seed = rng.random::<u64>();
            let uniform = rng.random::<f64>();
            candidate.log_jacobian = transform.to_constrained(&candidate.z, &mut candidate.theta);
            candidate.log_prior = prior.log_density(&candidate.theta);
            let mut accepted = false;
            if candidate.log_prior > f64::NEG_INFINITY
                && let Ok(model) = family.model(&candidate.theta)
            {
                candidate.log_likelihood = match filter.run(&model, data, filter_seed) {
                    Ok(run) => run.loglik,
                    // a proposal outside the model's domain (its states blow up to a
                    // NaN density, e.g. a negative spring constant) has likelihood zero
                    // and is rejected; at the start the same is an error
                    Err(SmcError::DegenerateWeights { .. } | SmcError::InvalidDensity { .. }) => {
                        f64::NEG_INFINITY
                    }
                    Err(source) => {
                        return Err(PmcmcError::Smc {
                            chain,
                            iteration,
                            source,
                        });
                    }
                };
                let log_ratio = candidate.log_target() - current.log_target();
                if adapting {
                    proposal.adapt_scale(iteration, log_ratio.min(0.0).exp());
                }
                if uniform.ln() < log_ratio {
                    std::mem::swap(&mut current, &mut candidate);
                    accepted = true;
                    moves += 1;
                }
            } else if adapting {
                proposal.adapt_scale(iteration, 0.0);
            }
            out.push(
                &current.theta,
                current.log_likelihood,
                current.log_prior,
                accepted,
            );
            if adapting {
                visited.extend_from_slice(&current.z);
            }
            observer.iteration(chain, iteration);
            if observer.should_stop() && iteration + 1 < options.iterations {
                out.interrupt();
                break;
            }
        }
        Ok(out.finish())
    }
}

/// The random-walk proposal `z* = z + lambda L e`.
struct Proposal {
    lower: DMatrix<f64>,
    log_scale: f64,
}

impl Proposal {
    fn new(options: &PmmhOptions, d: usize) -> Self {
        let sd = |k: usize| options.proposal_sd.get(k).copied().unwrap_or(0.1);
        Proposal {
            lower: DMatrix::from_fn(d, d, |i, j| if i == j { sd(i) } else { 0.0 }),
            log_scale: 0.0,
        }
    }

    fn step(&self, z: &[f64], noise: &[f64], out: &mut [f64]) {
        let scale = self.log_scale.exp();
        for (i, o) in out.iter_mut().enumerate() {
            *o = z[i] + scale * (0..=i).map(|j| self.lower[(i, j)] * noise[j]).sum::<f64>();
        }
    }

    /// Robbins-Monro step of `ln lambda` towards [`TARGET_ACCEPTANCE`].
    fn adapt_scale(&mut self, iteration: usize, acceptance_probability: f64) {
        let gain = 1.0 / ((iteration + 1) as f64).sqrt();
        self.log_scale += gain * (acceptance_probability - TARGET_ACCEPTANCE);
    }

    /// Adaptive Metropolis: at the scheduled iterations, `L L' = (2.38^2/d) Cov(z)` of
    /// the second half of the draws so far (`history` is iteration-major).
    fn adapt_shape(&mut self, iteration: usize, history: &[f64]) {
        let d = self.lower.nrows();
        let first = (20 * d).max(200);
        if iteration < first || !(iteration - first).is_multiple_of(ADAPT_EVERY) {
            return;
        }
        let rows: Vec<&[f64]> = history.chunks_exact(d).skip(iteration / 2).collect();
        let count = rows.len() as f64;
        let mut mean = DVector::zeros(d);
        for r in &rows {
            mean += DVector::from_column_slice(r);
        }
        mean /= count;
        let mut cov = DMatrix::zeros(d, d);
        for r in &rows {
            let e = DVector::from_column_slice(r) - &mean;
            cov += &e * e.transpose();
        }
        cov *= 2.38 * 2.38 / (d as f64 * (count - 1.0));
        cov += DMatrix::identity(d, d) * 1e-10;
        if let Some(chol) = cov.cholesky() {
            self.lower = chol.l();
            self.log_scale = 0.0;
        }
    }
}

/// Collects the draws of a chain.
pub(crate) struct ChainRecorder {
    chain: Chain,
}

impl ChainRecorder {
    pub(crate) fn new(names: Vec<String>, iterations: usize, burn_in: usize) -> Self {
        let d = names.len();
        ChainRecorder {
            chain: Chain {
                names,
                burn_in,
                samples: Vec::with_capacity(iterations * d),
                log_likelihood: Vec::with_capacity(iterations),
                log_prior: Vec::with_capacity(iterations),
                accepted: Vec::with_capacity(iterations),
                state_update_rate: None,
                state_mean: None,
                interrupted: false,
            },
        }
    }

    pub(crate) fn push(
        &mut self,
        theta: &[f64],
        log_likelihood: f64,
        log_prior: f64,
        accepted: bool,
    ) {
        self.chain.samples.extend_from_slice(theta);
        self.chain.log_likelihood.push(log_likelihood);
        self.chain.log_prior.push(log_prior);
        self.chain.accepted.push(accepted);
    }

    /// Marks the chain as stopped early.
    pub(crate) fn interrupt(&mut self) {
        self.chain.interrupted = true;
    }

    /// Iterations recorded so far.
    pub(crate) fn len(&self) -> usize {
        self.chain.accepted.len()
    }

    pub(crate) fn finish(self) -> Chain {
        self.chain
    }
}
