//! What enforcing stability cost: the stabilised model's simulation and one-step
//! prediction fits on the record, beside the unstabilised model's prediction fit.
//!
//! Maciejowski's padded shift equation (`N4sidOptions::stable`) moves the poles
//! inside the unit circle but can wreck the fit; this says by how much.

use crate::{N4sidOptions, N4sidResult, n4sid};
use sysid_kalman::{Horizon, Record};

/// A simulation fit below this (%) means stabilising destroyed the model.
pub const DESTROYED_FIT: f64 = 0.0;

/// The fits of a stabilised model on the record it was identified from.
#[derive(Debug, Clone, PartialEq)]
pub struct StabilisedFit {
    /// Mean simulation fit (%) of the stabilised model (least-squares initial state).
    pub simulation_fit: f64,
    /// Mean one-step prediction fit (%) of the stabilised model.
    pub prediction_fit: f64,
    /// The same without stabilisation (`None` when that fit fails).
    pub unstabilised_prediction_fit: Option<f64>,
}

impl StabilisedFit {
    /// Whether the stabilised model no longer simulates the record (fit below
    /// [`DESTROYED_FIT`]).
    pub fn destroyed(&self) -> bool {
        self.simulation_fit < DESTROYED_FIT
    }
}

/// The fits of `result` when stabilisation changed it (`None` otherwise, or when the
/// fits cannot be computed); `options` are the ones it was fitted with.
pub fn stabilised_fit(
    record: &Record,
    result: &N4sidResult,
    options: &N4sidOptions,
) -> Option<StabilisedFit> {
    if !result.stabilised {
        return None;
    }
    let fit = |model: &sysid_kalman::LinearGaussianModel, horizon| {
        model
            .compare(record, horizon, 0, None)
            .ok()
            .map(|c| c.mean_fit_percent())
            .filter(|f| f.is_finite())
    };
    let unstabilised = n4sid(
        record,
        &N4sidOptions {
            stable: false,
            weighting: result.weighting,
            order: crate::Order::Fixed(result.order),
            ..*options
        },
    )
    .ok();
    Some(StabilisedFit {
        simulation_fit: fit(&result.model, Horizon::Simulation)?,
        prediction_fit: fit(&result.model, Horizon::Steps(1))?,
        unstabilised_prediction_fit: unstabilised.and_then(|u| fit(&u.model, Horizon::Steps(1))),
    })
}
