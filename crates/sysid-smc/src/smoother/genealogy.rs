//! Ancestor tracing: the filter's own genealogy as smoothed paths.

use super::SmootherStats;
use super::backward::BackwardStep;
use crate::streams::Rng;
use crate::{History, SmcError};

pub(crate) struct GenealogyStep<'a> {
    pub history: &'a History,
}

impl BackwardStep for GenealogyStep<'_> {
    fn step(
        &mut self,
        t: usize,
        _next_states: &[f64],
        next_indices: &[usize],
        out: &mut [usize],
        _rng: &mut Rng,
    ) -> Result<(), SmcError> {
        let ancestors = self.history.ancestors(t + 1);
        for (o, &i) in out.iter_mut().zip(next_indices) {
            *o = ancestors[i];
        }
        Ok(())
    }

    fn stats(&self) -> SmootherStats {
        SmootherStats::default()
    }
}
