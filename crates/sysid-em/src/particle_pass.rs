//! The forward pass shared by the particle E-steps (affine EM, gradient EM): a
//! bootstrap filter that keeps its history, with the random streams of iteration `k`.

use rand::RngExt;
use sysid_smc::{FilterModel, FilterOptions, History, ParticleFilter, Series, SmcError};

/// A seed for piece `k` of the work seeded by `seed`.
fn sub_seed(seed: u64, k: u64) -> u64 {
    sysid_smc::stream(seed, k).random()
}

/// The filter of a particle E-step and its iteration counter. Iteration `k` filters
/// with the stream `(seed, 2k)` and hands the smoother the seed of `(seed, 2k + 1)`;
/// the final log-likelihood uses `(seed, u64::MAX)`.
pub(crate) struct ParticlePass {
    filter: ParticleFilter,
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
    /// A filter with `particles` particles (systematic resampling at every step).
    pub(crate) fn new(particles: usize, seed: u64) -> Result<Self, SmcError> {
        let filter = ParticleFilter::new(FilterOptions {
            particles,
            store_history: true,
            // the E-step uses the history and the log-likelihood only
            record_summaries: false,
            ..FilterOptions::default()
        })?;
        Ok(ParticlePass {
            filter,
            seed,
            iteration: 0,
        })
    }

    /// The next iteration's forward pass.
    pub(crate) fn run<M: FilterModel + Sync>(
        &mut self,
        model: &M,
        data: &Series,
    ) -> Result<Pass<'_>, SmcError> {
        let k = self.iteration;
        self.iteration += 1;
        let run = self.filter.run(model, data, sub_seed(self.seed, 2 * k))?;
        Ok(Pass {
            loglik: run.loglik,
            history: self.filter.history().expect("history is stored"),
            smoother_seed: sub_seed(self.seed, 2 * k + 1),
        })
    }

    /// The log-likelihood estimate of the final estimate.
    pub(crate) fn loglik<M: FilterModel + Sync>(
        &mut self,
        model: &M,
        data: &Series,
    ) -> Result<f64, SmcError> {
        Ok(self
            .filter
            .run(model, data, sub_seed(self.seed, u64::MAX))?
            .loglik)
    }
}
