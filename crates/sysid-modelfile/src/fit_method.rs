//! The method a model file's fit runs, with only the options it reads. The user gives
//! a [`Criterion`] and [`FitSettings`]; [`ModelFile::fit_method`] picks the method
//! (closed-form particle EM when the equations are affine in the free parameters, the
//! direct likelihood search or gradient EM otherwise, or the simulation-error fit),
//! fills the settings left out with that method's defaults, and refuses a setting the
//! method does not read, naming the method.

use crate::output_error::SimulationFitOptions;
use crate::{FileFitError, ModelFile};
use sysid_em::affine::{AffineFitOptions, AffineMethod, CheckedAffineFitOptions};
use sysid_em::gradient::DirectOptions;
use sysid_em::{FitSettings, SettingError};

/// What a model file's fit optimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Criterion {
    /// The likelihood with the file's process and measurement noise (particle EM, the
    /// direct search or gradient EM): best for one-step prediction and filtering.
    #[default]
    Likelihood,
    /// The noise-free model's simulation error, minimised over the free parameters and
    /// the initial state by Levenberg–Marquardt: best for a model that is to simulate
    /// from the inputs alone.
    Simulation,
}

impl Criterion {
    /// The names [`Criterion::from_str`](std::str::FromStr) knows.
    pub const NAMES: [&'static str; 2] = ["likelihood", "simulation"];

    /// Its name.
    pub fn name(&self) -> &'static str {
        match self {
            Criterion::Likelihood => Self::NAMES[0],
            Criterion::Simulation => Self::NAMES[1],
        }
    }
}

impl std::fmt::Display for Criterion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Criterion {
    type Err = String;

    /// A criterion by its name; the error lists the names.
    fn from_str(name: &str) -> Result<Self, String> {
        match name {
            "likelihood" => Ok(Criterion::Likelihood),
            "simulation" => Ok(Criterion::Simulation),
            _ => Err(format!(
                "{name:?} is not a criterion: use {}",
                Criterion::NAMES.join(" or ")
            )),
        }
    }
}

/// Options of the direct likelihood search of a file that is not affine in its free
/// parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct DirectFitOptions {
    /// Starts explored: the file's values, the simulation-error fit's estimate, then
    /// perturbations of the file's values. Default: particle EM's
    /// ([`AffineFitOptions::default`], 8).
    pub starts: usize,
    /// Particles of the finishing filter; 0 skips the finish. Default
    /// [`DirectOptions::default`]'s (10 000).
    pub polish_particles: usize,
}

impl Default for DirectFitOptions {
    fn default() -> Self {
        DirectFitOptions {
            starts: AffineFitOptions::default().starts,
            polish_particles: DirectOptions::default().particles,
        }
    }
}

/// Options of gradient EM for a file that is not affine in its free parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct GradientFitOptions {
    /// Particles of the filter and paths of the rejection smoother (at least 2).
    /// Default: particle EM's ([`AffineFitOptions::default`], 100).
    pub particles: usize,
    /// EM iterations. Default: particle EM's (500).
    pub iterations: usize,
}

impl Default for GradientFitOptions {
    fn default() -> Self {
        let affine = AffineFitOptions::default();
        GradientFitOptions {
            particles: affine.particles,
            iterations: affine.iterations,
        }
    }
}

/// Every setting of a model file's fit at its default (the method's, where methods
/// share a setting they share its default): what `sysid fit --help` shows and what a
/// keyword left `None` in Python becomes.
pub fn fit_defaults() -> FitSettings {
    let affine = AffineFitOptions::default();
    let simulation = SimulationFitOptions::default();
    FitSettings {
        method: Some(affine.method),
        particles: Some(affine.particles),
        smoother: Some(affine.smoother.name().to_string()),
        max_iter: Some(affine.iterations),
        starts: Some(affine.starts),
        polish: Some(affine.polish_particles > 0),
        extrapolate: Some(affine.extrapolate),
        patience: Some(simulation.patience),
        spread: Some(simulation.spread),
    }
}

/// The method of a model file's fit, with the options it reads.
#[derive(Debug, Clone, PartialEq)]
pub enum FileFitMethod {
    /// Closed-form particle EM (the file is affine in its free parameters): the
    /// robust driver, plain EM or PSAEM.
    ParticleEm(CheckedAffineFitOptions),
    /// The multi-start direct likelihood search (`robust` for a file that is not
    /// affine).
    Direct(DirectFitOptions),
    /// Gradient EM from the file's values (`em` for a file that is not affine).
    GradientEm(GradientFitOptions),
    /// The simulation-error fit (`criterion = simulation`); its seed is the run's.
    Simulation(SimulationFitOptions),
}

impl FileFitMethod {
    /// The method's name in results: `robust`, `em`, `psaem`, `direct`,
    /// `gradient-em` or `simulation-error`.
    pub fn name(&self) -> &'static str {
        match self {
            FileFitMethod::ParticleEm(options) => options.options().method.name(),
            FileFitMethod::Direct(_) => "direct",
            FileFitMethod::GradientEm(_) => "gradient-em",
            FileFitMethod::Simulation(_) => "simulation-error",
        }
    }
}

/// What the direct search reads.
const DIRECT_READS: &[&str] = &["method", "starts", "polish"];
/// What gradient EM reads.
const GRADIENT_READS: &[&str] = &["method", "particles", "max_iter"];
/// What the simulation-error fit reads.
const SIMULATION_READS: &[&str] = &["starts", "patience", "spread"];

impl ModelFile {
    /// The method that fits this file by `criterion`, with `settings` over its
    /// defaults: for the likelihood, closed-form particle EM by `settings.method`
    /// (robust by default) when the equations are affine in the free parameters;
    /// otherwise the direct search (`robust`) or gradient EM (`em`).
    ///
    /// # Errors
    /// [`FileFitError::Setting`] for a setting the chosen method does not read (named
    /// with the method), or one out of its range; [`FileFitError::NotAffine`] for
    /// PSAEM on a file that is not affine.
    pub fn fit_method(
        &self,
        criterion: Criterion,
        settings: &FitSettings,
    ) -> Result<FileFitMethod, FileFitError> {
        if criterion == Criterion::Simulation {
            settings.refuse_unread(
                "the simulation-error fit (criterion simulation)",
                SIMULATION_READS,
            )?;
            let defaults = SimulationFitOptions::default();
            return Ok(FileFitMethod::Simulation(SimulationFitOptions {
                starts: settings.starts.unwrap_or(defaults.starts),
                patience: settings.patience.unwrap_or(defaults.patience),
                spread: settings.spread.unwrap_or(defaults.spread),
                ..defaults
            }));
        }
        if self.affine().is_some() {
            return Ok(FileFitMethod::ParticleEm(settings.affine_options()?));
        }
        let why = || self.why_not_affine().unwrap_or_default();
        match settings.method.unwrap_or(AffineMethod::Robust) {
            AffineMethod::Robust => {
                settings.refuse_unread(
                    "the direct likelihood search (method robust for a file that is not \
                     affine in its free parameters)",
                    DIRECT_READS,
                )?;
                let defaults = DirectFitOptions::default();
                let options = DirectFitOptions {
                    starts: settings.starts.unwrap_or(defaults.starts),
                    polish_particles: match settings.polish {
                        Some(false) => 0,
                        _ => defaults.polish_particles,
                    },
                };
                if options.starts == 0 {
                    return Err(SettingError::Invalid {
                        setting: "starts",
                        reason: "must be at least 1".into(),
                    }
                    .into());
                }
                Ok(FileFitMethod::Direct(options))
            }
            AffineMethod::Em => {
                settings.refuse_unread(
                    "gradient EM (method em for a file that is not affine in its free \
                     parameters)",
                    GRADIENT_READS,
                )?;
                let defaults = GradientFitOptions::default();
                let options = GradientFitOptions {
                    particles: settings.particles.unwrap_or(defaults.particles),
                    iterations: settings.max_iter.unwrap_or(defaults.iterations),
                };
                if options.particles < 2 {
                    return Err(SettingError::Invalid {
                        setting: "particles",
                        reason: "must be at least 2".into(),
                    }
                    .into());
                }
                Ok(FileFitMethod::GradientEm(options))
            }
            method => Err(FileFitError::NotAffine {
                method: method.name().to_string(),
                origin: self.origin().to_string(),
                why: why(),
            }),
        }
    }
}
