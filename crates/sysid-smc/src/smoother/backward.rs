//! The backward pass shared by every smoother: blocks of paths, each with its own
//! random stream, walked from `T - 1` down to 0 by a per-method step.

use rand::RngExt;
use rayon::prelude::*;

use super::paths::feed_step;
use super::{SmootherStats, Trajectories};
use crate::streams::{Rng, stream};
use crate::weights::{DrawFailure, find_cumulative};
use crate::{History, SmcError};

/// Paths per block (and per random stream).
pub const PATH_BLOCK: usize = 32;

/// One backward step of a smoother: given the particle indices (into step `t + 1`) and
/// states of a block of paths, choose their indices into step `t`.
pub(crate) trait BackwardStep {
    fn step(
        &mut self,
        t: usize,
        next_states: &[f64],
        next_indices: &[usize],
        out: &mut [usize],
        rng: &mut Rng,
    ) -> Result<(), SmcError>;

    fn stats(&self) -> SmootherStats;
}

/// Maps a failed categorical draw to the smoother error at `t`, path `path`.
pub(crate) fn backward_error(failure: DrawFailure, t: usize, path: usize) -> SmcError {
    match failure {
        DrawFailure::Degenerate => SmcError::DegenerateBackward { t, path },
        DrawFailure::Invalid => SmcError::InvalidDensity {
            what: "transition log-density",
            t,
            particle: path,
            value: f64::NAN,
        },
    }
}

/// Copies the states `indices` of step `t` (stride `state_dim`) into `out`.
pub(crate) fn gather(history: &History, t: usize, indices: &[usize], out: &mut [f64]) {
    let n = history.state_dim();
    let states = history.states(t);
    if n == 1 {
        // scalar states: plain indexing, no per-element copy call
        for (x, &i) in out.iter_mut().zip(indices) {
            *x = states[i];
        }
        return;
    }
    for (x, &i) in out.chunks_exact_mut(n).zip(indices) {
        x.copy_from_slice(&states[i * n..(i + 1) * n]);
    }
}

/// Runs block `block` (paths `[block * PATH_BLOCK, ...)`) of `paths` backward, calling
/// `sink(t, states_t, states_{t+1})` from `t = T - 1` (with `None`) down to 0.
fn run_block<S: BackwardStep>(
    history: &History,
    paths: usize,
    block: usize,
    seed: u64,
    step: &mut S,
    sink: &mut impl FnMut(usize, &[f64], Option<&[f64]>),
) -> Result<(), SmcError> {
    let n = history.state_dim();
    let size = PATH_BLOCK.min(paths - block * PATH_BLOCK);
    let last = history.steps() - 1;
    let mut rng = stream(seed, block as u64);
    let mut next_indices = vec![0usize; size];
    let mut indices = vec![0usize; size];
    let mut next_states = vec![0.0; size * n];
    let mut states = vec![0.0; size * n];
    let final_weights = history.weights(last);
    for i in next_indices.iter_mut() {
        *i = find_cumulative(final_weights, rng.random::<f64>());
    }
    gather(history, last, &next_indices, &mut next_states);
    sink(last, &next_states, None);
    for t in (0..last).rev() {
        step.step(t, &next_states, &next_indices, &mut indices, &mut rng)
            .map_err(|e| offset_path(e, block * PATH_BLOCK))?;
        gather(history, t, &indices, &mut states);
        sink(t, &states, Some(&next_states));
        std::mem::swap(&mut states, &mut next_states);
        std::mem::swap(&mut indices, &mut next_indices);
    }
    Ok(())
}

fn offset_path(error: SmcError, offset: usize) -> SmcError {
    match error {
        SmcError::DegenerateBackward { t, path } => SmcError::DegenerateBackward {
            t,
            path: path + offset,
        },
        other => other,
    }
}

pub(crate) fn check_paths(paths: usize) -> Result<(), SmcError> {
    if paths == 0 {
        return Err(SmcError::InvalidOption {
            name: "paths",
            reason: "must be at least 1".into(),
        });
    }
    Ok(())
}

/// Draws `paths` trajectories, blocks in parallel when `parallel` is set (the result
/// does not depend on it).
pub(crate) fn trajectories<S, F>(
    history: &History,
    paths: usize,
    seed: u64,
    parallel: bool,
    make_step: F,
) -> Result<(Trajectories, SmootherStats), SmcError>
where
    S: BackwardStep,
    F: Fn() -> S + Sync,
{
    check_paths(paths)?;
    let blocks = paths.div_ceil(PATH_BLOCK);
    let one_block = |block: usize| -> Result<(Trajectories, SmootherStats), SmcError> {
        let size = PATH_BLOCK.min(paths - block * PATH_BLOCK);
        let n = history.state_dim();
        let mut out = Trajectories::zeros(history.steps(), size, n);
        let mut step = make_step();
        run_block(
            history,
            paths,
            block,
            seed,
            &mut step,
            &mut |t, states, _| {
                out.states_mut(t).copy_from_slice(states);
            },
        )?;
        Ok((out, step.stats()))
    };
    let results: Vec<_> = if parallel && blocks > 1 {
        (0..blocks).into_par_iter().map(one_block).collect()
    } else {
        (0..blocks).map(one_block).collect()
    };
    let mut stats = SmootherStats::default();
    let mut pieces = Vec::with_capacity(blocks);
    for r in results {
        let (piece, s) = r?;
        stats.merge(&s);
        pieces.push(piece);
    }
    Ok((Trajectories::concat(pieces), stats))
}

/// Streams the pairs of `paths` trajectories into an additive functional, block after
/// block, without storing the trajectories.
pub(crate) fn additive<S, F>(
    history: &History,
    paths: usize,
    seed: u64,
    mut step: S,
    functional: &mut F,
) -> Result<SmootherStats, SmcError>
where
    S: BackwardStep,
    F: super::AdditiveFunctional + ?Sized,
{
    check_paths(paths)?;
    let n = history.state_dim();
    let weight = 1.0 / paths as f64;
    for block in 0..paths.div_ceil(PATH_BLOCK) {
        run_block(
            history,
            paths,
            block,
            seed,
            &mut step,
            &mut |t, states, next| feed_step(functional, t, states, next, n, weight),
        )?;
    }
    Ok(step.stats())
}
