//! The E-step smoothers of particle EM, chosen at run time by name.

use super::{FfbsiReject, Smoother, SmootherStats, Tanizaki};
use crate::{AdditiveFunctional, History, Series, SmcError, Trajectories, TransitionBound};

/// The smoother of particle EM's E-step, chosen by name (`tanizaki`, seed 000's, or
/// `ffbsi-reject`): one type for code that takes the choice from its user.
///
/// # Example
/// ```
/// use sysid_smc::EmSmoother;
/// assert!(matches!(EmSmoother::from_name("tanizaki", 100), Some(EmSmoother::Tanizaki(_))));
/// assert_eq!(EmSmoother::from_name("ffbsi-reject", 50).map(|s| s.name()), Some("ffbsi-reject"));
/// assert!(EmSmoother::from_name("kalman", 50).is_none());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EmSmoother {
    /// Tanizaki's pairwise resampling smoother (O(M^2) per step at worst).
    Tanizaki(Tanizaki),
    /// Rejection FFBSi (O(M) expected per step when the transition is not too peaked).
    FfbsiReject(FfbsiReject),
}

impl EmSmoother {
    /// The names [`EmSmoother::from_name`] knows.
    pub const NAMES: [&'static str; 2] = ["tanizaki", "ffbsi-reject"];

    /// The smoother of a name, rejection FFBSi drawing `paths` paths; `None` for an
    /// unknown name.
    pub fn from_name(name: &str, paths: usize) -> Option<EmSmoother> {
        match name {
            "tanizaki" => Some(EmSmoother::Tanizaki(Tanizaki::default())),
            "ffbsi-reject" => Some(EmSmoother::FfbsiReject(FfbsiReject {
                paths,
                max_trials: None,
                parallel: false,
            })),
            _ => None,
        }
    }

    /// Its name.
    pub fn name(&self) -> &'static str {
        match self {
            EmSmoother::Tanizaki(_) => Self::NAMES[0],
            EmSmoother::FfbsiReject(_) => Self::NAMES[1],
        }
    }
}

impl<M: TransitionBound + Sync> Smoother<M> for EmSmoother {
    fn trajectories(
        &self,
        model: &M,
        history: &History,
        data: &Series,
        seed: u64,
    ) -> Result<(Trajectories, SmootherStats), SmcError> {
        match self {
            EmSmoother::Tanizaki(s) => s.trajectories(model, history, data, seed),
            EmSmoother::FfbsiReject(s) => s.trajectories(model, history, data, seed),
        }
    }

    fn additive<F: AdditiveFunctional + ?Sized>(
        &self,
        model: &M,
        history: &History,
        data: &Series,
        seed: u64,
        functional: &mut F,
    ) -> Result<SmootherStats, SmcError> {
        match self {
            EmSmoother::Tanizaki(s) => s.additive(model, history, data, seed, functional),
            EmSmoother::FfbsiReject(s) => s.additive(model, history, data, seed, functional),
        }
    }
}
