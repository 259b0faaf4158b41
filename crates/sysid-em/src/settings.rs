//! What a user sets for a particle fit, by the names both faces use (`particles`,
//! `max_iter`, ...: the command line spells them `--particles`, `--max-iter`, Python
//! as keywords). A setting left `None` takes the default of the method that runs,
//! written once on that method's options ([`AffineFitOptions::default`] for particle
//! EM). A setting the method that runs does not read is refused with
//! [`SettingError::NotApplicable`], never dropped.

use crate::OptionsError;
use crate::affine::{AffineEmError, AffineFitOptions, AffineMethod, CheckedAffineFitOptions};
use sysid_smc::PathSmoother;

/// The settings of a particle fit; `None` leaves a setting at the method's default.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FitSettings {
    /// `robust`, `em` or `psaem` ([`AffineMethod`]).
    pub method: Option<AffineMethod>,
    /// Particles of the filter (paths of a rejection smoother).
    pub particles: Option<usize>,
    /// The E-step smoother, by name ([`PathSmoother::EM_NAMES`]).
    pub smoother: Option<String>,
    /// EM iterations (the robust driver's refinement iterations).
    pub max_iter: Option<usize>,
    /// Starts explored.
    pub starts: Option<usize>,
    /// Whether the robust driver's estimate (or the direct fit's) is finished by a
    /// large filter's likelihood maximised directly.
    pub polish: Option<bool>,
    /// Whether the robust driver's refinement extrapolates its drift.
    pub extrapolate: Option<bool>,
    /// Simulations per run of a simulation-error fit, in units of unknowns + 1.
    pub patience: Option<usize>,
    /// The spread of a simulation-error fit's perturbed starts (log scale).
    pub spread: Option<f64>,
}

impl FitSettings {
    /// The names of the settings given (not `None`), in the order of the fields.
    pub fn given(&self) -> Vec<&'static str> {
        let pairs = [
            ("method", self.method.is_some()),
            ("particles", self.particles.is_some()),
            ("smoother", self.smoother.is_some()),
            ("max_iter", self.max_iter.is_some()),
            ("starts", self.starts.is_some()),
            ("polish", self.polish.is_some()),
            ("extrapolate", self.extrapolate.is_some()),
            ("patience", self.patience.is_some()),
            ("spread", self.spread.is_some()),
        ];
        pairs
            .into_iter()
            .filter_map(|(name, given)| given.then_some(name))
            .collect()
    }

    /// Refuses the first given setting that `method` (described as `description`)
    /// does not read.
    ///
    /// # Errors
    /// [`SettingError::NotApplicable`].
    pub fn refuse_unread(
        &self,
        description: &str,
        reads: &'static [&'static str],
    ) -> Result<(), SettingError> {
        match self.given().into_iter().find(|g| !reads.contains(g)) {
            Some(setting) => Err(SettingError::NotApplicable {
                setting,
                method: description.to_string(),
                reads,
            }),
            None => Ok(()),
        }
    }

    /// The options of closed-form particle EM: the method's defaults
    /// ([`AffineFitOptions::default`]) with the given settings, checked. A setting
    /// the method does not read ([`AffineMethod::reads`]) is refused.
    ///
    /// # Errors
    /// [`SettingError::NotApplicable`]; [`SettingError::Invalid`] naming the setting.
    pub fn affine_options(&self) -> Result<CheckedAffineFitOptions, SettingError> {
        let defaults = AffineFitOptions::default();
        let method = self.method.unwrap_or(defaults.method);
        self.refuse_unread(method.description(), method.reads())?;
        let mut options = defaults.with_method(method);
        if let Some(particles) = self.particles {
            options.particles = particles;
        }
        let smoother = self.smoother.as_deref().unwrap_or(options.smoother.name());
        options.smoother = PathSmoother::for_em(smoother, options.particles).map_err(|e| {
            SettingError::Invalid {
                setting: "smoother",
                reason: match e {
                    sysid_smc::SmcError::InvalidOption { reason, .. } => reason,
                    other => other.to_string(),
                },
            }
        })?;
        if let Some(iterations) = self.max_iter {
            options.iterations = iterations;
        }
        if let Some(starts) = self.starts {
            options.starts = starts;
        }
        if self.polish == Some(false) {
            options.polish_particles = 0;
        }
        if let Some(extrapolate) = self.extrapolate {
            options.extrapolate = extrapolate;
        }
        options.check().map_err(|e| match e {
            AffineEmError::InvalidOption { name, reason } => SettingError::Invalid {
                setting: match name {
                    "iterations" => "max_iter",
                    "polish_particles" => "polish",
                    other => other,
                },
                reason,
            },
            other => SettingError::Invalid {
                setting: "method",
                reason: other.to_string(),
            },
        })
    }
}

/// A setting the method cannot take.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SettingError {
    /// A setting given for a method that does not read it.
    #[error("{}", self.describe(|name| name.to_string()))]
    NotApplicable {
        /// The setting.
        setting: &'static str,
        /// The method that runs, described.
        method: String,
        /// The settings it reads.
        reads: &'static [&'static str],
    },
    /// A value out of its range.
    #[error("{setting}: {reason}")]
    Invalid {
        /// The setting.
        setting: &'static str,
        /// What is wrong with it.
        reason: String,
    },
}

/// The runner's refusal of EM's options, named as the fits' settings (`max_iter`,
/// `tol`, `tol_nats`).
impl From<OptionsError> for SettingError {
    fn from(e: OptionsError) -> SettingError {
        match e {
            OptionsError::NoIterations => SettingError::Invalid {
                setting: "max_iter",
                reason: "must be at least 1".into(),
            },
            OptionsError::BadTolerance { name, value } => SettingError::Invalid {
                setting: match name {
                    "distance_tol" => "tol_nats",
                    other => other,
                },
                reason: format!("must be a finite non-negative number, got {value}"),
            },
        }
    }
}

impl SettingError {
    /// `setting` given where `what` runs, which does not read it.
    pub fn not_applicable(setting: &'static str, what: &str) -> SettingError {
        SettingError::NotApplicable {
            setting,
            method: what.to_string(),
            reads: &[],
        }
    }

    /// The setting at fault.
    pub fn setting(&self) -> &'static str {
        match self {
            SettingError::NotApplicable { setting, .. } | SettingError::Invalid { setting, .. } => {
                setting
            }
        }
    }

    /// The message, with each setting named by `name` (a face's spelling: `--max-iter`
    /// on the command line, `max_iter` in Python).
    pub fn describe(&self, name: impl Fn(&str) -> String) -> String {
        match self {
            SettingError::NotApplicable {
                setting,
                method,
                reads,
            } => {
                let read: Vec<String> = reads.iter().map(|r| name(r)).collect();
                let read = match read.is_empty() {
                    true => String::new(),
                    false => format!(" (it reads {})", read.join(", ")),
                };
                format!(
                    "{} does not apply to {method}, which runs here{read}; leave it out",
                    name(setting)
                )
            }
            SettingError::Invalid { setting, reason } => format!("{}: {reason}", name(setting)),
        }
    }
}
