//! The forward pass shared by the particle E-steps (affine EM, gradient EM): a
//! bootstrap or fully adapted filter that keeps its history, with the random streams
//! of iteration `k`.

use rand::RngExt;
use sysid_smc::{
    FilterModel, FilterOptions, GuidedFilter, GuidedProposal, History, ParticleFilter, Series,
    SmcError, TransitionDensity,
};

/// A seed for piece `k` of the work seeded by `seed`.
fn sub_seed(seed: u64, k: u64) -> u64 {
    sysid_smc::stream(seed, k).random()
}

/// Runs the fully adapted filter on a model type that has a guided proposal. Chosen
/// once, where that capability is known (for example
/// `GradientEm::with_guided_filter`), and stored as a plain function pointer so the
/// E-step itself needs no extra trait bound.
pub(crate) type Guide<M> = fn(&mut GuidedFilter, &M, &Series, u64) -> Result<f64, SmcError>;

/// The [`Guide`] of a model type with a guided proposal.
pub(crate) fn guide<M: FilterModel + TransitionDensity + GuidedProposal>() -> Guide<M> {
    |filter, model, data, seed| filter.run(model, data, seed)
}

/// The filter of a particle E-step and its iteration counter. Iteration `k` filters
/// with the stream `(seed, 2k)` and hands the smoother the seed of `(seed, 2k + 1)`;
/// the final log-likelihood uses `(seed, u64::MAX)`.
pub(crate) struct ParticlePass {
    bootstrap: ParticleFilter,
    /// Made on first use (it needs at least 2 particles).
    guided: Option<GuidedFilter>,
    seed: u64,
    iteration: u64,
}

/// One forward pass: the filter's log-likelihood estimate, its history and the seed
/// for the smoother.
pub(crate) struct Pass<'f> {
    pub loglik: f64,
    pub history: &'f History,
    pub smoother_seed: u64,
}

impl ParticlePass {
    /// A filter with `particles` particles (the bootstrap filter resamples
    /// systematically at every step, the guided one multinomially).
    pub(crate) fn new(particles: usize, seed: u64) -> Result<Self, SmcError> {
        let bootstrap = ParticleFilter::new(FilterOptions {
            particles,
            store_history: true,
            // the E-step uses the history and the log-likelihood only
            record_summaries: false,
            ..FilterOptions::default()
        })?;
        Ok(ParticlePass {
            bootstrap,
            guided: None,
            seed,
            iteration: 0,
        })
    }

    /// The next iteration's forward pass: the guided filter when `guide` is given,
    /// else the bootstrap filter.
    pub(crate) fn run<M: FilterModel + Sync>(
        &mut self,
        model: &M,
        data: &Series,
        guide: Option<Guide<M>>,
    ) -> Result<Pass<'_>, SmcError> {
        let k = self.iteration;
        self.iteration += 1;
        let loglik = self.filter(model, data, guide, sub_seed(self.seed, 2 * k))?;
        let history = match guide {
            Some(_) => self.guided.as_ref().and_then(GuidedFilter::history),
            None => self.bootstrap.history(),
        };
        Ok(Pass {
            loglik,
            history: history.expect("the filter ran and stores its history"),
            smoother_seed: sub_seed(self.seed, 2 * k + 1),
        })
    }

    /// The log-likelihood estimate of the final estimate.
    pub(crate) fn loglik<M: FilterModel + Sync>(
        &mut self,
        model: &M,
        data: &Series,
        guide: Option<Guide<M>>,
    ) -> Result<f64, SmcError> {
        self.filter(model, data, guide, sub_seed(self.seed, u64::MAX))
    }

    fn filter<M: FilterModel + Sync>(
        &mut self,
        model: &M,
        data: &Series,
        guide: Option<Guide<M>>,
        seed: u64,
    ) -> Result<f64, SmcError> {
        match guide {
            Some(run) => {
                let filter = match &mut self.guided {
                    Some(filter) => filter,
                    empty => empty.insert(GuidedFilter::new(self.bootstrap.options().particles)?),
                };
                run(filter, model, data, seed)
            }
            None => Ok(self.bootstrap.run(model, data, seed)?.loglik),
        }
    }
}
