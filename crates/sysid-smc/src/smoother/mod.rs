//! Particle smoothers over a stored filter [`History`].
//!
//! # Algorithm
//! Every smoother draws paths backwards from `x~_{T-1} ~ Cat(W_{T-1})`:
//!
//! | smoother | backward draw at `t` | cost | needs |
//! | --- | --- | --- | --- |
//! | [`Genealogy`] | the filter's ancestor of the path | O(T K) | nothing |
//! | [`Ffbsi`] | `i` with prob. ∝ `W_t^i f(x~_{t+1} \| x_t^i)` | O(T K M) | [`TransitionDensity`] |
//! | [`Tanizaki`] | as FFBSi, over the equally weighted resampled cloud, K = M (by rejection against the row maximum, or for scalar Gaussian transitions from a window of sorted means, then exactly) | O(T M²), expected O(T M) for scalar Gaussian transitions | [`TransitionDensity`] |
//! | [`FfbsiReject`] | propose `i ~ Cat(W_t)`, accept w.p. `f / c` (`c` the row's own maximum for scalar Gaussian transitions and M <= 256, else the model's bound); exact draw after `max_trials` | expected O(T K) | [`TransitionBound`] |
//!
//! Paths are drawn in blocks of [`PATH_BLOCK`]; block `b` uses the random stream
//! `(seed, b)`, so results do not depend on the thread count. The blocks walk back in
//! lockstep (all of them take step `t` before any takes `t - 1`), so that each step's
//! filter particles and the tables derived from them (rejection FFBSi's proposal table,
//! the transition means) are loaded and built once per step, not once per block.
//!
//! Each smoother gives either the trajectories ([`Smoother::trajectories`]) or, without
//! storing them, the smoothed sum of an additive functional
//! ([`Smoother::additive`]), which is what EM's E-step needs.
//!
//! # Complexity
//! See the table; memory O(T K n) for trajectories, O(K M) for the additive form.
//!
//! # References
//! Tanizaki (2001); Schön, Wills and Ninness (2006), Algorithm 4; Godsill, Doucet and
//! West (2004); Douc, Garivier, Moulines and Olsson (2011); Dau and Chopin (2023).
//!
//! [`TransitionDensity`]: crate::TransitionDensity
//! [`TransitionBound`]: crate::TransitionBound

mod alias;
mod backward;
mod by_name;
mod exact;
mod genealogy;
mod nearest;
mod paths;
mod reject;
mod rounds;
mod window;

pub use backward::PATH_BLOCK;
pub use by_name::PathSmoother;
pub use paths::{AdditiveFunctional, Trajectories};

use crate::model::{StateSpace, TransitionBound, TransitionDensity};
use crate::{History, Series, SmcError};
use exact::{Cloud, ExactStep};
use genealogy::GenealogyStep;
use reject::RejectStep;

/// Work done by a smoother.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SmootherStats {
    /// Transition-density evaluations.
    pub density_evaluations: u64,
    /// Rejection-sampling proposals (rejection FFBSi only).
    pub trials: u64,
    /// Draws that reached the trial cap and fell back to the exact draw.
    pub fallbacks: u64,
}

impl SmootherStats {
    fn merge(&mut self, other: &SmootherStats) {
        self.density_evaluations += other.density_evaluations;
        self.trials += other.trials;
        self.fallbacks += other.fallbacks;
    }
}

/// A particle smoother usable with model `M`.
///
/// # Example
/// A smoother is chosen by value and run on a filter's history; a new smoother
/// implements both methods (here, one that delegates to the genealogy smoother):
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
/// struct Ancestry;
/// impl<M: StateSpace> Smoother<M> for Ancestry {
///     fn trajectories(&self, model: &M, history: &History, data: &Series, seed: u64)
///         -> Result<(Trajectories, SmootherStats), SmcError> {
///         Genealogy { paths: 10 }.trajectories(model, history, data, seed)
///     }
///     fn additive<F: AdditiveFunctional + ?Sized>(&self, model: &M, history: &History,
///         data: &Series, seed: u64, functional: &mut F) -> Result<SmootherStats, SmcError> {
///         Genealogy { paths: 10 }.additive(model, history, data, seed, functional)
///     }
/// }
/// let y = [0.3, -0.4, 1.2, 0.8];
/// let data = Series::new(&y, 1)?;
/// let mut pf = ParticleFilter::new(FilterOptions {
///     particles: 100, store_history: true, ..Default::default()
/// })?;
/// pf.run(&Ar1, &data, 1)?;
/// let (paths, _) = Ancestry.trajectories(&Ar1, pf.history().unwrap(), &data, 3)?;
/// assert_eq!(paths.paths(), 10);
/// # Ok::<(), SmcError>(())
/// ```
pub trait Smoother<M> {
    /// Draws smoothed trajectories from the filter history.
    fn trajectories(
        &self,
        model: &M,
        history: &History,
        data: &Series,
        seed: u64,
    ) -> Result<(Trajectories, SmootherStats), SmcError>;

    /// Accumulates the smoothed sum of an additive functional without storing the
    /// trajectories. Each path contributes with weight `1 / K`.
    fn additive<F: AdditiveFunctional + ?Sized>(
        &self,
        model: &M,
        history: &History,
        data: &Series,
        seed: u64,
        functional: &mut F,
    ) -> Result<SmootherStats, SmcError>;
}

fn check_history(history: &History, data: &Series) -> Result<(), SmcError> {
    if history.steps() != data.steps() {
        return Err(SmcError::HistoryMismatch {
            history: history.steps(),
            data: data.steps(),
        });
    }
    Ok(())
}

/// Implements [`Smoother`] for a backward smoother from what is its own: its number of
/// paths, whether it draws path blocks in parallel, and its step kernel. The history is
/// checked against the data, then the paths are drawn block by block
/// ([`backward::trajectories`]) or the additive functional accumulated
/// ([`backward::additive`]).
macro_rules! backward_smoother {
    (
        impl Smoother<M> for $smoother:ty where M: [$($bound:tt)+];
        |$s:ident, $model:ident, $history:ident, $data:ident| {
            paths: $paths:expr,
            parallel: $parallel:expr,
            step: $step:expr $(,)?
        }
    ) => {
        impl<M: $($bound)+> Smoother<M> for $smoother {
            fn trajectories(
                &self,
                model: &M,
                history: &History,
                data: &Series,
                seed: u64,
            ) -> Result<(Trajectories, SmootherStats), SmcError> {
                check_history(history, data)?;
                let ($s, $model, $history, $data) = (self, model, history, data);
                backward::trajectories($history, $paths, seed, $parallel, || $step)
            }

            fn additive<F: AdditiveFunctional + ?Sized>(
                &self,
                model: &M,
                history: &History,
                data: &Series,
                seed: u64,
                functional: &mut F,
            ) -> Result<SmootherStats, SmcError> {
                check_history(history, data)?;
                let ($s, $model, $history, $data) = (self, model, history, data);
                backward::additive($history, $paths, seed, $step, functional)
            }
        }
    };
}

/// Ancestor tracing: follow the filter's genealogy back from `K` draws at `T - 1`.
/// Cheap, but the paths collapse onto few ancestors far from `T` (path degeneracy).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Genealogy {
    /// Number of paths K.
    pub paths: usize,
}

backward_smoother! {
    impl Smoother<M> for Genealogy where M: [StateSpace];
    |genealogy, _model, history, _data| {
        paths: genealogy.paths,
        parallel: false,
        step: GenealogyStep { history },
    }
}

/// Forward filtering, backward simulation with the exact O(M) draw per path and step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ffbsi {
    /// Number of paths K.
    pub paths: usize,
    /// Draw blocks of paths in parallel (same result either way).
    pub parallel: bool,
}

backward_smoother! {
    impl Smoother<M> for Ffbsi where M: [TransitionDensity + Sync];
    |ffbsi, model, history, data| {
        paths: ffbsi.paths,
        parallel: ffbsi.parallel,
        step: ExactStep::new(model, history, data, Cloud::Weighted),
    }
}

/// Tanizaki's pairwise resampling smoother (seed 000, Algorithm 4): `M` smoothed
/// particles, each resampled at every step among the equally weighted filter particles
/// with probabilities ∝ `f(x~_{t+1} | x_{t|t}^i)`.
///
/// Each draw computes the `M` transition log-densities (cheap: no exponentials), then
/// tries up to `max_trials` proposals `i ~ U{1..M}`, accepted with probability
/// `f_i / max_j f_j` (tested as `l_i - max_j l_j > -E`, `E ~ Exp(1)`), before the
/// exact O(M) draw. The draws have exactly the same distribution either way; rejection
/// needs one exponential variate per trial instead of `M` exponentials,
/// which makes the smoother several times faster when the candidates' densities are of
/// comparable size (seed 000's benchmark: about half of the proposals are accepted).
///
/// For a scalar Gaussian transition
/// ([`TransitionDensity::scalar_gaussian_means`] returns a kernel, as for `nlbench` and
/// scalar linear models) the row maximum is the nearest transition mean, found without
/// evaluating the row, and only the proposed candidates are evaluated. Where the
/// step's means spread wider than a few transition standard deviations, the means are
/// sorted into buckets and each path proposes from its window of nearby means (the
/// rest with at most `e^-4` of the largest density): the same distribution with about
/// 2 trials per draw instead of 5-10 on seed 000's benchmark, where a draw among
/// uniformly proposed candidates often meets a single candidate that carries it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Tanizaki {
    /// Draw blocks of paths in parallel (same result either way).
    pub parallel: bool,
    /// Rejection trials per draw before the exact draw; `None` means
    /// `max(2, M / 4)` (about the cost of one exact draw), `Some(0)` always draws
    /// exactly.
    pub max_trials: Option<usize>,
}

impl Tanizaki {
    fn step<'a, M: TransitionDensity>(
        &self,
        model: &'a M,
        history: &'a History,
        data: &'a Series<'a>,
    ) -> ExactStep<'a, M> {
        let trials = self
            .max_trials
            .unwrap_or_else(|| (history.particles() / 4).max(2));
        let mut step = ExactStep::new(model, history, data, Cloud::Resampled);
        step.rejection_trials = (trials > 0).then_some(trials);
        step
    }
}

backward_smoother! {
    impl Smoother<M> for Tanizaki where M: [TransitionDensity + Sync];
    |tanizaki, model, history, data| {
        paths: history.particles(),
        parallel: tanizaki.parallel,
        step: tanizaki.step(model, history, data),
    }
}

/// FFBSi by rejection sampling with a trial cap and an exact fallback.
///
/// Proposals come from `Cat(W_t)` and are accepted with probability `f / c`: `c` is
/// each path's own largest transition density (from the nearest transition mean) for
/// scalar Gaussian transitions with at most 256 particles, else the model's
/// [`TransitionBound`]. In the first case, at steps whose transition means spread
/// wider than the transition noise allows one path to reach, each path proposes from
/// the window of means around it instead (weighted by `W_t`, with a bound for the
/// means outside), which needs far fewer trials; the draws have the same law.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FfbsiReject {
    /// Number of paths K.
    pub paths: usize,
    /// Proposals per draw before the exact O(M) fallback; `None` means M (the
    /// suggestion of ALGORITHMS.md 2.3), which bounds the cost of a draw by about
    /// twice that of the exact draw.
    pub max_trials: Option<usize>,
    /// Draw blocks of paths in parallel (same result either way).
    pub parallel: bool,
}

impl FfbsiReject {
    fn step<'a, M: TransitionBound>(
        &self,
        model: &'a M,
        history: &'a History,
        data: &'a Series<'a>,
    ) -> RejectStep<'a, M> {
        let max_trials = self.max_trials.unwrap_or(history.particles());
        RejectStep::new(model, history, data, max_trials)
    }
}

backward_smoother! {
    impl Smoother<M> for FfbsiReject where M: [TransitionBound + Sync];
    |reject, model, history, data| {
        paths: reject.paths,
        parallel: reject.parallel,
        step: reject.step(model, history, data),
    }
}
