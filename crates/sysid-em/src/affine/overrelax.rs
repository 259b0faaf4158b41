//! Extrapolated steps for the robust driver's refinement, where EM crawls.
//!
//! # Algorithm
//! EM converges slowly where the complete data say much more than the observed data,
//! as with a small held process noise: the smoothed paths follow the current dynamics
//! closely and each M-step moves the coefficients a little along the same direction
//! (the two-tank model moves for 2500 iterations along a ridge of constant steady
//! level). Adaptive overrelaxed EM (Salakhutdinov and Roweis 2003) steps further along
//! the EM direction while the likelihood keeps rising. Particle EM's single steps are
//! noisy, so the direction here is the drift of block averages: every `block`
//! iterations the mean of the last half block is compared with the previous one, and
//! the point `mean + factor (mean - previous)` (variances on the log scale, ties and
//! bounds kept) is scored against `mean` by the driver's filter on common random
//! numbers. A jump that gains at least [`JUMP_GAIN`] nats is taken and the factor
//! doubles (up to [`MAX_FACTOR`]); otherwise the factor returns to its start. Jumps are
//! only taken in the first three quarters of the refinement; the iterates after the
//! last jump (at least the last quarter), whose average is the estimate and whose
//! quarters decide whether it settled, are plain EM.

use super::constraints::estimated_variances;
use super::{AffineEmSpec, AffineModel, AffineParams, free_structure};
use crate::linear::Covariance;

/// Iterations between extrapolation attempts.
pub(crate) const BLOCK: usize = 25;
/// The first factor of an attempt (blocks' worth of drift jumped).
const FIRST_FACTOR: f64 = 4.0;
/// The largest factor.
const MAX_FACTOR: f64 = 64.0;
/// The smallest log-likelihood gain (nats, on common random numbers) that takes a jump.
pub(crate) const JUMP_GAIN: f64 = 1.0;

/// The state of the extrapolation (see the module documentation).
pub(crate) struct Overrelaxation {
    previous: Option<AffineParams>,
    factor: f64,
    /// Jumps taken.
    pub(crate) jumps: usize,
    /// The trace length at the last jump taken (the estimate averages after it).
    pub(crate) last_jump: usize,
}

impl Overrelaxation {
    pub(crate) fn new() -> Overrelaxation {
        Overrelaxation {
            previous: None,
            factor: FIRST_FACTOR,
            jumps: 0,
            last_jump: 0,
        }
    }

    /// At the end of a block whose last half averages to `mean`: the point to try, if
    /// there is a previous block to extrapolate from.
    pub(crate) fn propose<A: AffineModel>(
        &mut self,
        model: &A,
        spec: &AffineEmSpec,
        mean: &AffineParams,
    ) -> Option<AffineParams> {
        let previous = self.previous.replace(mean.clone())?;
        Some(extrapolated(model, spec, &previous, mean, self.factor))
    }

    /// The proposal was taken at trace length `at`: the next drift starts afresh.
    pub(crate) fn taken(&mut self, at: usize) {
        self.jumps += 1;
        self.last_jump = at;
        self.previous = None;
        self.factor = (self.factor * 2.0).min(MAX_FACTOR);
    }

    /// The proposal lost likelihood.
    pub(crate) fn refused(&mut self) {
        self.factor = FIRST_FACTOR;
    }
}

/// `to + factor (to - from)` in the estimated coefficients, and on the log scale in the
/// estimated (diagonal) variances; ties and bounds applied.
fn extrapolated<A: AffineModel>(
    model: &A,
    spec: &AffineEmSpec,
    from: &AffineParams,
    to: &AffineParams,
    factor: f64,
) -> AffineParams {
    let mut out = to.clone();
    let constraints = model.constraints();
    let step = |a: f64, b: f64| b + factor * (b - a);
    for (estimated, structure, held, beta_from, beta_to, beta_out) in [
        (
            spec.beta_x,
            model.state_structure(),
            model.held_state_coefficients(),
            &from.beta_x,
            &to.beta_x,
            &mut out.beta_x,
        ),
        (
            spec.beta_y,
            model.output_structure(),
            model.held_output_coefficients(),
            &from.beta_y,
            &to.beta_y,
            &mut out.beta_y,
        ),
    ] {
        if !estimated {
            continue;
        }
        for (row, used) in free_structure(&structure, &held).iter().enumerate() {
            for &j in used {
                beta_out[(row, j)] = step(beta_from[(row, j)], beta_to[(row, j)]);
            }
        }
    }
    for (process, covariance, pi_from, pi_to) in [
        (true, spec.pi_x, &from.pi_x, &to.pi_x),
        (false, spec.pi_y, &from.pi_y, &to.pi_y),
    ] {
        // a diagonal block only: a full one would need its correlations kept
        if covariance != Covariance::Diagonal {
            continue;
        }
        let estimated =
            estimated_variances(covariance, pi_to.nrows(), constraints.as_ref(), process);
        for i in 0..pi_to.nrows() {
            let (a, b) = (pi_from[(i, i)], pi_to[(i, i)]);
            if !(estimated[i] && a > 0.0 && b > 0.0) {
                continue;
            }
            let v = step(a.ln(), b.ln()).exp();
            if v.is_finite() && v > 0.0 {
                let m = if process {
                    &mut out.pi_x
                } else {
                    &mut out.pi_y
                };
                m[(i, i)] = v;
            }
        }
    }
    if let Some(c) = constraints {
        c.project(&mut out);
    }
    out
}
