//! The backward pass shared by every smoother: blocks of paths, each with its own
//! random stream, walked from `T - 1` down to 0 by a per-method step.

use rand::RngExt;
use rayon::prelude::*;

use super::paths::feed_step;
use super::{SmootherStats, Trajectories};
use crate::streams::{Rng, stream};
use crate::weights::{DrawFailure, find_cumulative};
use crate::{History, SmcError};

/// Paths per block (and per random stream). Each block pays some costs once per step
/// (its trial numbers' seeding, the nearest-mean pass, the windows' set-up, rounds as
/// long as its slowest path); at 64, particle EM's 50 paths (seed 000) are one block.
/// Parallel smoothing splits by blocks, so only above 64 paths.
pub const PATH_BLOCK: usize = 64;

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

/// A backward step whose body is compiled for the widest vector instruction set: its
/// [`BackwardStep::step`] runs [`step_body`](Self::step_body) through
/// [`crate::simd::dispatch`] (so the model's kernels inlined into it are vectorised
/// too).
pub(crate) trait DispatchedStep {
    fn step_body(
        &mut self,
        t: usize,
        next_states: &[f64],
        out: &mut [usize],
        rng: &mut Rng,
    ) -> Result<(), SmcError>;

    fn step_stats(&self) -> SmootherStats;
}

impl<S: DispatchedStep> BackwardStep for S {
    fn step(
        &mut self,
        t: usize,
        next_states: &[f64],
        _next_indices: &[usize],
        out: &mut [usize],
        rng: &mut Rng,
    ) -> Result<(), SmcError> {
        crate::simd::dispatch(StepKernel {
            step: self,
            t,
            next_states,
            out,
            rng,
        })
    }

    fn stats(&self) -> SmootherStats {
        self.step_stats()
    }
}

struct StepKernel<'s, 'd, S> {
    step: &'s mut S,
    t: usize,
    next_states: &'d [f64],
    out: &'d mut [usize],
    rng: &'d mut Rng,
}

impl<S: DispatchedStep> crate::simd::Kernel for StepKernel<'_, '_, S> {
    type Output = Result<(), SmcError>;

    #[inline(always)]
    fn run(self) -> Self::Output {
        self.step
            .step_body(self.t, self.next_states, self.out, self.rng)
    }
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

/// The walk of one block of paths: its random stream, the indices of its paths at the
/// current step and the one after it, and where its states sit in the shared buffers.
struct BlockWalk {
    first_path: usize,
    /// The block's states in the step buffers of [`run_blocks`].
    span: std::ops::Range<usize>,
    rng: Rng,
    next_indices: Vec<usize>,
    indices: Vec<usize>,
}

impl BlockWalk {
    /// Block `block` of `paths`, started at the last step from `Cat(W_{T-1})`; its
    /// states go to `span` of the step buffers.
    fn start(
        history: &History,
        paths: usize,
        block: usize,
        seed: u64,
        span: std::ops::Range<usize>,
    ) -> Self {
        let size = PATH_BLOCK.min(paths - block * PATH_BLOCK);
        let mut rng = stream(seed, block as u64);
        let final_weights = history.weights(history.steps() - 1);
        let next_indices: Vec<usize> = (0..size)
            .map(|_| find_cumulative(final_weights, rng.random::<f64>()))
            .collect();
        BlockWalk {
            first_path: block * PATH_BLOCK,
            span,
            rng,
            indices: vec![0; size],
            next_indices,
        }
    }

    /// One step back, from `t + 1` (states `next_states`) to `t` (into `states`); the
    /// step buffers hold every block's states.
    fn step_back<S: BackwardStep>(
        &mut self,
        history: &History,
        t: usize,
        step: &mut S,
        next_states: &[f64],
        states: &mut [f64],
    ) -> Result<(), SmcError> {
        step.step(
            t,
            &next_states[self.span.clone()],
            &self.next_indices,
            &mut self.indices,
            &mut self.rng,
        )
        .map_err(|e| offset_path(e, self.first_path))?;
        gather(history, t, &self.indices, &mut states[self.span.clone()]);
        std::mem::swap(&mut self.indices, &mut self.next_indices);
        Ok(())
    }
}

/// Runs the blocks `blocks` of `paths` backward in lockstep: every block takes step `t`
/// before any takes `t - 1`, so each step's filter particles (and whatever the step
/// derives from them) are loaded into the cache once for all of them. Calls
/// `sink(t, states_t, states_{t+1})` with the states of all the blocks' paths, in path
/// order, from `t = T - 1` (with `None`) down to 0. Each block keeps its own random
/// stream, so the paths are those of running the blocks one after another.
fn run_blocks<S: BackwardStep>(
    history: &History,
    paths: usize,
    blocks: std::ops::Range<usize>,
    seed: u64,
    step: &mut S,
    sink: &mut impl FnMut(usize, &[f64], Option<&[f64]>),
) -> Result<(), SmcError> {
    let n = history.state_dim();
    let last = history.steps() - 1;
    let first_path = blocks.start * PATH_BLOCK;
    let mut walks: Vec<BlockWalk> = blocks
        .map(|block| {
            let from = (block * PATH_BLOCK - first_path) * n;
            let to = (((block + 1) * PATH_BLOCK).min(paths) - first_path) * n;
            BlockWalk::start(history, paths, block, seed, from..to)
        })
        .collect();
    let len = walks.last().map_or(0, |w| w.span.end);
    let mut next_states = vec![0.0; len];
    let mut states = vec![0.0; len];
    for walk in &walks {
        gather(
            history,
            last,
            &walk.next_indices,
            &mut next_states[walk.span.clone()],
        );
    }
    sink(last, &next_states, None);
    for t in (0..last).rev() {
        for walk in walks.iter_mut() {
            walk.step_back(history, t, step, &next_states, &mut states)?;
        }
        sink(t, &states, Some(&next_states));
        std::mem::swap(&mut states, &mut next_states);
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
    let n = history.state_dim();
    // contiguous groups of blocks, one per worker: the paths do not depend on the split
    let workers = if parallel {
        rayon::current_num_threads().clamp(1, blocks)
    } else {
        1
    };
    let per_group = blocks.div_ceil(workers);
    let groups = blocks.div_ceil(per_group);
    let one_group = |group: usize| -> Result<(Trajectories, SmootherStats), SmcError> {
        let first = group * per_group;
        let range = first..(first + per_group).min(blocks);
        let first_path = first * PATH_BLOCK;
        let size = (range.end * PATH_BLOCK).min(paths) - first_path;
        let mut out = Trajectories::zeros(history.steps(), size, n);
        let mut step = make_step();
        run_blocks(
            history,
            paths,
            range,
            seed,
            &mut step,
            &mut |t, states, _| out.states_mut(t).copy_from_slice(states),
        )?;
        Ok((out, step.stats()))
    };
    let results: Vec<_> = if groups > 1 {
        (0..groups).into_par_iter().map(one_group).collect()
    } else {
        vec![one_group(0)]
    };
    let mut stats = SmootherStats::default();
    let mut pieces = Vec::with_capacity(groups);
    for r in results {
        let (piece, s) = r?;
        stats.merge(&s);
        pieces.push(piece);
    }
    Ok((Trajectories::concat(pieces), stats))
}

/// Streams the pairs of `paths` trajectories into an additive functional, step after
/// step (all paths of step `t`, in path order, from `T - 1` down to 0), without storing
/// the trajectories.
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
    run_blocks(
        history,
        paths,
        0..paths.div_ceil(PATH_BLOCK),
        seed,
        &mut step,
        &mut |t, states, next| feed_step(functional, t, states, next, n, weight),
    )?;
    Ok(step.stats())
}
