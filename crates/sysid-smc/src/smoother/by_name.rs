//! Smoothers chosen at run time by name.

use super::{Ffbsi, FfbsiReject, Genealogy, Smoother, SmootherStats, Tanizaki};
use crate::{AdditiveFunctional, History, Series, SmcError, Trajectories, TransitionBound};

/// A smoother of state trajectories chosen by name (`tanizaki`, `ffbsi`,
/// `ffbsi-reject`, `genealogy`): one type for code that takes the choice from its user,
/// as `sysid psmooth --method` does.
///
/// # Example
/// ```
/// use sysid_smc::PathSmoother;
/// let smoother = PathSmoother::from_name("ffbsi", 100, false).unwrap();
/// assert_eq!(smoother.name(), "ffbsi");
/// assert!(PathSmoother::from_name("rts", 100, false).is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PathSmoother {
    /// Tanizaki's pairwise resampling smoother: as many paths as particles.
    Tanizaki(Tanizaki),
    /// Exact FFBSi, O(M) per path and step.
    Ffbsi(Ffbsi),
    /// Rejection FFBSi with the exact fallback.
    FfbsiReject(FfbsiReject),
    /// The filter's genealogy (ancestral paths): cheap, degenerate far from the end.
    Genealogy(Genealogy),
}

impl PathSmoother {
    /// The names [`PathSmoother::from_name`] knows.
    pub const NAMES: [&'static str; 4] = ["tanizaki", "ffbsi", "ffbsi-reject", "genealogy"];

    /// The smoother of a name, drawing `paths` paths (Tanizaki draws one per particle),
    /// in parallel blocks when `parallel` (the same draws either way).
    ///
    /// # Errors
    /// [`SmcError::InvalidOption`] (`method`) for an unknown name.
    pub fn from_name(name: &str, paths: usize, parallel: bool) -> Result<PathSmoother, SmcError> {
        Ok(match name {
            "tanizaki" => PathSmoother::Tanizaki(Tanizaki {
                parallel,
                max_trials: None,
            }),
            "ffbsi" => PathSmoother::Ffbsi(Ffbsi { paths, parallel }),
            "ffbsi-reject" => PathSmoother::FfbsiReject(FfbsiReject {
                paths,
                max_trials: None,
                parallel,
            }),
            "genealogy" => PathSmoother::Genealogy(Genealogy { paths }),
            other => {
                return Err(SmcError::InvalidOption {
                    name: "method",
                    reason: format!(
                        "unknown smoother {other:?} (known: {})",
                        Self::NAMES.join(", ")
                    ),
                });
            }
        })
    }

    /// The names [`PathSmoother::for_em`] knows: the smoothers of particle EM's E-step.
    pub const EM_NAMES: [&'static str; 2] = ["tanizaki", "ffbsi-reject"];

    /// The E-step smoother of particle EM of a name: Tanizaki's (seed 000's) or
    /// rejection FFBSi drawing `paths` paths, serial (EM runs its starts in parallel).
    ///
    /// # Example
    /// ```
    /// use sysid_smc::PathSmoother;
    /// assert!(matches!(PathSmoother::for_em("tanizaki", 100), Ok(PathSmoother::Tanizaki(_))));
    /// assert!(PathSmoother::for_em("genealogy", 100).is_err());
    /// ```
    ///
    /// # Errors
    /// [`SmcError::InvalidOption`] (`smoother`) for another name.
    pub fn for_em(name: &str, paths: usize) -> Result<PathSmoother, SmcError> {
        if !Self::EM_NAMES.contains(&name) {
            return Err(SmcError::InvalidOption {
                name: "smoother",
                reason: format!(
                    "unknown smoother {name:?} (known: {})",
                    Self::EM_NAMES.join(", ")
                ),
            });
        }
        Self::from_name(name, paths, false)
    }

    /// Its name.
    pub fn name(&self) -> &'static str {
        match self {
            PathSmoother::Tanizaki(_) => Self::NAMES[0],
            PathSmoother::Ffbsi(_) => Self::NAMES[1],
            PathSmoother::FfbsiReject(_) => Self::NAMES[2],
            PathSmoother::Genealogy(_) => Self::NAMES[3],
        }
    }
}

impl<M: TransitionBound + Sync> Smoother<M> for PathSmoother {
    fn trajectories(
        &self,
        model: &M,
        history: &History,
        data: &Series,
        seed: u64,
    ) -> Result<(Trajectories, SmootherStats), SmcError> {
        match self {
            PathSmoother::Tanizaki(s) => s.trajectories(model, history, data, seed),
            PathSmoother::Ffbsi(s) => s.trajectories(model, history, data, seed),
            PathSmoother::FfbsiReject(s) => s.trajectories(model, history, data, seed),
            PathSmoother::Genealogy(s) => s.trajectories(model, history, data, seed),
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
            PathSmoother::Tanizaki(s) => s.additive(model, history, data, seed, functional),
            PathSmoother::Ffbsi(s) => s.additive(model, history, data, seed, functional),
            PathSmoother::FfbsiReject(s) => s.additive(model, history, data, seed, functional),
            PathSmoother::Genealogy(s) => s.additive(model, history, data, seed, functional),
        }
    }
}
