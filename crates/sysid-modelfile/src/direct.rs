//! A model file that is not affine in its free parameters, fitted from several starts
//! by its particle log-likelihood ([`fit_direct`], the default `robust` method for
//! such files). The starts: the file's values; the simulation-error fit's estimate
//! (`output_error.rs`, its own 8 Levenberg–Marquardt runs: deterministic, a few
//! milliseconds, and near the likelihood's maximum when the process noise is small,
//! where a rough start's particle likelihood is too jagged for a simplex to climb);
//! then perturbations of the file's values, each free value times `U[0.5, 1.5]` (on
//! the scale of its bounds), up to `starts`. They are explored with a 1000-particle
//! filter and the best is finished with the polish's filter.
//!
//! Measured on the two-tank file written non-affinely (`sqrt(a1*a1*h1)`,
//! `../shared/data/nonlinear/twotank`, from its rough start): without the
//! simulation-error start, 2 of 8 starts reached the maximum (the others' simplexes
//! stalled 150 to 450 nats below it).

use crate::fit_method::DirectFitOptions;
use crate::output_error::{SimulationFitOptions, at_bound, perturb};
use crate::{FileFit, FileFitError, FileFitReport, FileFitWarning, ModelFile};
use rand::RngExt;
use sysid_em::FitRun;
use sysid_em::gradient::{DirectOptions, GradientModel, fit_direct};
use sysid_pmcmc::{ModelFamily, Support};
use sysid_smc::{Series, stream};

/// The stream of the starts' perturbations (the direct fit's own use 0 to 2).
const STARTS_STREAM: u64 = 3;

/// The exploration simplex's step of a coordinate, on its unconstrained scale: about
/// 35 % of a positive value, half a unit of an interval's logit, 20 % of a real one.
fn step(support: Support, z: f64) -> f64 {
    match support {
        Support::Positive => 0.3,
        Support::Interval(..) => 0.5,
        Support::Real if z != 0.0 => 0.2 * z.abs(),
        Support::Real => 0.2,
    }
}

impl ModelFile {
    /// The simulation-error fit's estimate as an unconstrained start, when that fit
    /// runs and its values are inside the bounds (`None` otherwise: a model whose free
    /// parameters are only noise variances, a simulation that diverges).
    fn simulation_start(&self, data: Series<'_>, run: &FitRun<'_>) -> Option<Vec<f64>> {
        let options = SimulationFitOptions {
            seed: run.seed,
            ..SimulationFitOptions::default()
        };
        let fit = self.fit_simulation_error(data, &options, run.stop).ok()?;
        let inside = self
            .supports()
            .iter()
            .zip(&fit.estimate)
            .all(|(s, &v)| v.is_finite() && s.contains(v));
        inside.then(|| self.gradient().unconstrained(&fit.estimate))
    }

    /// The direct fit of [`ModelFile::fit`] for a file that is not affine.
    pub(crate) fn fit_direct(
        &self,
        data: Series<'_>,
        given: &DirectFitOptions,
        run: &FitRun<'_>,
    ) -> Result<FileFit, FileFitError> {
        let gradient = self.gradient();
        let supports = self.supports();
        let origin = gradient.unconstrained(&self.free_values());
        let mut rng = stream(run.seed, STARTS_STREAM);
        let mut starts = vec![origin.clone()];
        let simulation_start = self
            .simulation_start(data, run)
            .filter(|_| given.starts > 1)
            .map(|z| {
                starts.push(z);
                1
            });
        while starts.len() < given.starts {
            let mut z = origin.clone();
            for (zj, &s) in z.iter_mut().zip(&supports) {
                let factor: f64 = rng.random_range(0.5..1.5);
                perturb(zj, s, factor.ln());
            }
            starts.push(z);
        }
        let steps: Vec<f64> = supports
            .iter()
            .zip(&origin)
            .map(|(&s, &z)| step(s, z))
            .collect();
        let direct = DirectOptions {
            particles: given.polish_particles,
            ..DirectOptions::default()
        };
        let fit = fit_direct(
            &gradient, data, &starts, &steps, &direct, run.seed, run.stop,
        )?;
        let estimate = gradient.constrained(&fit.estimate);
        let mut warnings: Vec<FileFitWarning> = fit
            .warnings
            .iter()
            .cloned()
            .map(FileFitWarning::Direct)
            .collect();
        let spec = self.spec();
        for (k, (&v, &s)) in spec.free().into_iter().zip(estimate.iter().zip(&supports)) {
            warnings.extend(at_bound(&spec.parameters[k].name, v, s));
        }
        Ok(FileFit {
            fitted: self.with_values(&estimate),
            estimate,
            standard_errors: fit.standard_errors.clone(),
            report: FileFitReport::Direct {
                fit,
                simulation_start,
            },
            warnings,
        })
    }
}
