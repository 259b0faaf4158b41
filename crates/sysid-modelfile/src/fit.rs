//! Fitting a model file's free parameters: closed-form particle EM when the equations
//! are affine in them (the robust driver by default, or plain EM, or PSAEM); otherwise
//! the multi-start direct maximum-likelihood fit by default (`direct.rs`) or gradient
//! EM from the file's values (`em`), with the report and the warnings the method gives.

use crate::fit_method::{FileFitMethod, GradientFitOptions};
use crate::output_error::{SimulationFit, SimulationFitOptions};
use crate::{ExprAffine, ModelFile};
use sysid_em::affine::{AffineEmError, AffineFit, CheckedAffineFitOptions, fit_affine};
use sysid_em::gradient::{
    DirectFit, DirectWarning, GradientEm, GradientEmError, GradientModel, MStepOptions,
};
use sysid_em::{
    EmObserver, EmOptions, EmResult, FitRun, IterationInfo, SettingError, Termination, run_em,
};
use sysid_smc::{FfbsiReject, ModelError, Series};

/// How a model file was fitted.
#[derive(Debug, Clone)]
pub enum FileFitReport {
    /// Closed-form particle EM ([`fit_affine`]); estimates as the file's free values
    /// through [`ExprAffine::theta`].
    Affine(AffineFit),
    /// The multi-start direct maximum-likelihood fit of a file that is not affine
    /// ([`sysid_em::gradient::fit_direct`]); its vectors are on the unconstrained scale.
    Direct {
        /// The fit.
        fit: DirectFit,
        /// The start that is the simulation-error fit's estimate, if it could be made.
        simulation_start: Option<usize>,
    },
    /// Gradient EM with rejection FFBSi (`particles` paths) and analytic gradients.
    Gradient {
        /// The runner's result; its estimate is on the unconstrained scale.
        result: EmResult<Vec<f64>, GradientEmError>,
        /// `(loglik, free values)` after every iteration.
        iterates: Vec<(f64, Vec<f64>)>,
    },
    /// The simulation-error fit ([`ModelFile::fit_simulation_error`]).
    Simulation(SimulationFit),
}

/// The result of [`ModelFile::fit`].
#[derive(Debug, Clone)]
pub struct FileFit {
    /// The model file with the estimates as its free parameters' values.
    pub fitted: ModelFile,
    /// The estimates, in the order of [`ModelFile::free_names`].
    pub estimate: Vec<f64>,
    /// What ran and what it says.
    pub report: FileFitReport,
    /// What should temper a reading of the estimate.
    pub warnings: Vec<FileFitWarning>,
    /// Standard errors of the estimates (see [`FileFit::standard_errors`]).
    pub(crate) standard_errors: Option<Vec<f64>>,
}

impl FileFit {
    /// The method's name: `robust`, `em`, `psaem`, `direct`, `gradient-em` or
    /// `simulation-error`.
    pub fn method(&self) -> &'static str {
        match &self.report {
            FileFitReport::Affine(fit) => fit.method.name(),
            FileFitReport::Direct { .. } => "direct",
            FileFitReport::Gradient { .. } => "gradient-em",
            FileFitReport::Simulation(_) => "simulation-error",
        }
    }

    /// The estimate's log-likelihood estimate (see [`AffineFit::loglik`]; for the
    /// direct fit the mean of independent filters at the estimate; for gradient EM the
    /// last E-step's; none for the simulation-error fit).
    pub fn loglik(&self) -> Option<f64> {
        match &self.report {
            FileFitReport::Affine(fit) => fit.loglik(),
            FileFitReport::Direct { fit, .. } => Some(fit.loglik),
            FileFitReport::Gradient { result, .. } => result.loglik,
            FileFitReport::Simulation(_) => None,
        }
    }

    /// Standard errors of the estimates, in the order of [`ModelFile::free_names`],
    /// from the curvature of an accurate filter's log-likelihood at the estimate (the
    /// observed information on common random numbers, mapped by the delta method)
    /// where the method takes one and it is a maximum's: the direct fit's finish and the
    /// robust driver's polish. `None` otherwise (plain EM, PSAEM, gradient EM, the
    /// simulation-error fit, whose own standard errors are in its report).
    pub fn standard_errors(&self) -> Option<&[f64]> {
        self.standard_errors.as_deref()
    }

    /// Whether the run was ended early.
    pub fn interrupted(&self) -> bool {
        match &self.report {
            FileFitReport::Affine(fit) => fit.interrupted(),
            FileFitReport::Direct { fit, .. } => fit.interrupted,
            FileFitReport::Gradient { result, .. } => {
                matches!(result.termination, Termination::Interrupted { .. })
            }
            FileFitReport::Simulation(fit) => fit.interrupted,
        }
    }
}

/// Why a model file's fit should be read with care.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum FileFitWarning {
    /// A warning of the robust driver (its text).
    Robust(String),
    /// A warning of the direct fit of a file that is not affine.
    Direct(DirectWarning),
    /// Too few iterations to judge whether the iterates have settled.
    TooFewIterations {
        /// Iterations made.
        iterations: usize,
    },
    /// A parameter whose mean moved by more than 2 % (and 5 standard errors) between
    /// the last two quarters of the iterations: more iterations are needed.
    StillMoving {
        /// The parameter.
        name: String,
        /// Its mean over the quarter before the last.
        from: f64,
        /// Its mean over the last quarter.
        to: f64,
    },
    /// Parameters (and initial states) whose values the data cannot tell apart: along
    /// a direction of them the simulated outputs barely change.
    Inseparable {
        /// The names involved, largest share first.
        names: Vec<String>,
        /// The smallest over the largest singular value of the column-scaled
        /// simulation Jacobian.
        ratio: f64,
    },
    /// Gradient EM ran but no M-step moved the parameters from the start: the estimate
    /// is the start.
    NoProgress {
        /// Iterations made.
        iterations: usize,
    },
    /// A parameter ended at one of its bounds: the data pull it beyond, so either the
    /// bound is a physical fact the data contradict or the term is not needed.
    AtBound {
        /// The parameter.
        name: String,
        /// Its estimate.
        value: f64,
        /// The bound it reached.
        bound: f64,
    },
    /// The log-likelihood's curvature at the estimate is not a maximum's: along one
    /// direction it is flat (the data do not determine it) or still rising. No standard
    /// errors are given.
    NotAMaximum {
        /// The parameters that make up that direction, largest share first.
        names: Vec<String>,
        /// The information along it (the smallest eigenvalue of minus the
        /// log-likelihood's Hessian in the fit's coordinates): negative where the
        /// log-likelihood still rises.
        information: f64,
    },
    /// The simulation-error fit's best run stopped before its convergence test held.
    NotConverged {
        /// MINPACK's reason.
        reason: String,
    },
}

impl std::fmt::Display for FileFitWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FileFitWarning::Robust(text) => f.write_str(text),
            FileFitWarning::Direct(w) => w.fmt(f),
            FileFitWarning::TooFewIterations { iterations } => write!(
                f,
                "only {iterations} EM iterations: too few to tell whether the estimate has \
                 settled (use --max-iter 100 or more)"
            ),
            FileFitWarning::StillMoving { name, from, to } => write!(
                f,
                "{name} is still moving ({from} -> {to} between the last two quarters of the \
                 iterations): run more iterations (--max-iter)"
            ),
            FileFitWarning::Inseparable { names, ratio } if names.len() == 1 => write!(
                f,
                "{} barely changes the simulated output on these data ({ratio:.1e} times as \
                 much as the most visible direction): its value is not determined by them; \
                 fix it (fixed = true) or use data that excite it",
                names[0]
            ),
            FileFitWarning::Inseparable { names, ratio } => write!(
                f,
                "{} cannot be separated by these data: along one direction of them the \
                 simulated output changes {ratio:.1e} times as much as along the most visible \
                 one, so only a combination of them is estimated; fix one of them (fixed = \
                 true) or add a measurement that sees it",
                names.join(", ")
            ),
            FileFitWarning::NoProgress { iterations } => write!(
                f,
                "gradient EM made {iterations} iterations without moving any parameter from \
                 its start: the estimate is the start, not a fit (the M-step found no \
                 ascent; try a start nearer the data, or --criterion simulation)"
            ),
            FileFitWarning::AtBound { name, value, bound } => write!(
                f,
                "{name} = {value:.3e} ended at its bound {bound}: its standard error means \
                 little; the data would move it past the bound (drop the term, or fix {name} \
                 at {bound} if the bound is physical)"
            ),
            FileFitWarning::NotAMaximum { names, information } => write!(
                f,
                "the log-likelihood is not at a maximum: along a direction of {} it is {} \
                 (curvature {information:.2e}), so no standard errors are given; {}",
                names.join(", "),
                if *information < 0.0 {
                    "still rising"
                } else {
                    "flat"
                },
                if *information < 0.0 {
                    "the estimate is short of the maximum: fit again from it"
                } else {
                    "the data do not determine that combination: fix one of them or add a \
                     measurement that sees it"
                }
            ),
            FileFitWarning::NotConverged { reason } => write!(
                f,
                "the simulation-error fit stopped before converging ({reason}): allow more \
                 evaluations (--patience) or start nearer"
            ),
        }
    }
}

/// Errors of [`ModelFile::fit`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FileFitError {
    /// Every parameter is fixed.
    #[error("{origin}: every parameter is fixed; nothing to estimate")]
    NothingFree {
        /// The file.
        origin: String,
    },
    /// A method the model does not admit (PSAEM or the robust driver for a model that
    /// is not affine in its parameters).
    #[error(
        "{method:?}: {origin} is not affine in its free parameters ({why}), so it is fitted \
         by its likelihood from several starts (robust) or by gradient EM (em)"
    )]
    NotAffine {
        /// The method asked for.
        method: String,
        /// The file.
        origin: String,
        /// Why it is not affine.
        why: String,
    },
    /// A setting the method that runs does not read, or one out of its range.
    #[error("{0}")]
    Setting(#[from] SettingError),
    /// The file's values are not a model (a variance that is not positive).
    #[error("{0}")]
    Start(#[from] ModelError),
    /// Closed-form particle EM failed to start.
    #[error("{0}")]
    Affine(#[from] AffineEmError),
    /// Gradient EM failed to start.
    #[error("{0}")]
    Gradient(#[from] GradientEmError),
}

/// Passes a model file's free values to the user's observer, and records them.
struct Values<'o, 'r, F> {
    observer: &'o mut dyn EmObserver<Vec<f64>>,
    run: &'r FitRun<'r>,
    values: F,
    rows: Vec<(f64, Vec<f64>)>,
}

impl<T, F: Fn(&T) -> Vec<f64>> EmObserver<T> for Values<'_, '_, F> {
    fn start(&mut self, initial: &T) {
        self.observer.start(&(self.values)(initial));
    }
    fn iteration(&mut self, info: &IterationInfo<'_, T>) {
        let values = (self.values)(info.estimate);
        self.observer.iteration(&IterationInfo {
            iteration: info.iteration,
            loglik: info.loglik,
            estimate: &values,
            elapsed: info.elapsed,
        });
        self.rows.push((info.loglik, values));
    }
    fn finish(&mut self, estimate: &T, loglik: Option<f64>, iterations: usize) {
        self.observer
            .finish(&(self.values)(estimate), loglik, iterations);
    }
    fn should_stop(&self) -> bool {
        self.observer.should_stop() || (self.run.stop)()
    }
}

impl ModelFile {
    /// Fits the free parameters to `data` from their values in the file by `method`
    /// ([`ModelFile::fit_method`] makes it from a criterion and the user's settings):
    /// closed-form particle EM ([`fit_affine`], with the file's own choice of free
    /// noise blocks); the multi-start direct maximum-likelihood fit
    /// ([`sysid_em::gradient::fit_direct`]: the starts explored by a 1000-particle
    /// filter, the best finished by a `polish_particles` one); gradient EM from the
    /// file's values (rejection FFBSi, analytic gradients); or the simulation-error fit
    /// ([`ModelFile::fit_simulation_error`]). `observer` sees the free values after
    /// every EM iteration (the direct and simulation-error fits have none); `run` gives
    /// the seed and the stop.
    ///
    /// # Errors
    /// [`FileFitError::NothingFree`]; [`FileFitError::NotAffine`] for closed-form
    /// particle EM on a model that is not affine; the setup errors of the method. A
    /// failure inside EM's iterations is the result's [`Termination::Error`].
    pub fn fit(
        &self,
        data: Series<'_>,
        method: &FileFitMethod,
        run: &FitRun<'_>,
        observer: &mut dyn EmObserver<Vec<f64>>,
    ) -> Result<FileFit, FileFitError> {
        if self.free_names().is_empty() {
            return Err(FileFitError::NothingFree {
                origin: self.origin().to_string(),
            });
        }
        let mut fit = match method {
            FileFitMethod::ParticleEm(options) => {
                let affine = self.affine().ok_or_else(|| FileFitError::NotAffine {
                    method: options.options().method.name().to_string(),
                    origin: self.origin().to_string(),
                    why: self.why_not_affine().unwrap_or_default(),
                })?;
                self.fit_affine(&affine, data, options, run, observer)
            }
            FileFitMethod::Direct(options) => self.fit_direct(data, options, run),
            FileFitMethod::GradientEm(options) => self.fit_gradient(data, options, run, observer),
            FileFitMethod::Simulation(options) => {
                let options = SimulationFitOptions {
                    seed: run.seed,
                    ..options.clone()
                };
                let fit = self.fit_simulation_error(data, &options, run.stop)?;
                // its own check of separability is on the estimate's Jacobian
                return Ok(FileFit {
                    fitted: fit.fitted.clone(),
                    estimate: fit.estimate.clone(),
                    warnings: fit.warnings.clone(),
                    report: FileFitReport::Simulation(fit),
                    standard_errors: None,
                });
            }
        }?;
        if let Some(found) = fit.fitted.inseparable_on(data) {
            fit.warnings.push(FileFitWarning::Inseparable {
                names: found.names,
                ratio: found.ratio,
            });
        }
        Ok(fit)
    }

    fn fit_affine(
        &self,
        affine: &ExprAffine,
        data: Series<'_>,
        options: &CheckedAffineFitOptions,
        run: &FitRun<'_>,
        observer: &mut dyn EmObserver<Vec<f64>>,
    ) -> Result<FileFit, FileFitError> {
        let start = affine.params(&self.free_values())?;
        let options = options.clone().with_spec(affine.em_spec());
        let mut values = Values {
            observer,
            run,
            values: |p: &sysid_em::affine::AffineParams| affine.theta(p),
            rows: Vec::new(),
        };
        let fit = fit_affine(affine, data, start, &options, run, &mut values)?;
        let estimate = affine.theta(fit.estimate());
        let mut warnings: Vec<FileFitWarning> = match &fit.report {
            sysid_em::affine::AffineFitReport::Robust(r) => r
                .warnings
                .iter()
                .cloned()
                .map(FileFitWarning::Robust)
                .collect(),
            _ => Vec::new(),
        };
        for (k, value, bound) in affine.on_bounds(&estimate) {
            warnings.push(FileFitWarning::AtBound {
                name: self.spec().parameters[k].name.clone(),
                value,
                bound,
            });
        }
        let curvature = match &fit.report {
            sysid_em::affine::AffineFitReport::Robust(r) => {
                r.polish.as_ref().and_then(|p| p.curvature.as_ref())
            }
            _ => None,
        };
        let theta = |p: &sysid_em::affine::AffineParams| affine.theta(p);
        let standard_errors = curvature.and_then(|c| c.standard_errors(theta));
        if let Some(c) = curvature.filter(|c| !c.is_maximum())
            && let Some((direction, information)) = c.flattest(theta)
        {
            warnings.push(FileFitWarning::NotAMaximum {
                names: leading_names(&self.free_names(), &direction),
                information,
            });
        }
        Ok(FileFit {
            fitted: self.with_values(&estimate),
            estimate,
            report: FileFitReport::Affine(fit),
            warnings,
            standard_errors,
        })
    }

    fn fit_gradient(
        &self,
        data: Series<'_>,
        options: &GradientFitOptions,
        run: &FitRun<'_>,
        observer: &mut dyn EmObserver<Vec<f64>>,
    ) -> Result<FileFit, FileFitError> {
        let em_options = EmOptions {
            max_iterations: options.iterations,
            tol: 0.0,
            ..EmOptions::default()
        }
        .check()
        .map_err(SettingError::from)?;
        let gradient = self.gradient();
        let start = gradient.unconstrained(&self.free_values());
        let smoother = FfbsiReject {
            paths: options.particles,
            max_trials: None,
            parallel: false,
        };
        let mut em = GradientEm::new(
            &gradient,
            data,
            options.particles,
            smoother,
            MStepOptions::default(),
            run.seed,
        )?;
        let mut values = Values {
            observer,
            run,
            values: |z: &Vec<f64>| gradient.constrained(z),
            rows: Vec::new(),
        };
        let result = run_em(&mut em, start, &em_options, &mut values);
        let estimate = gradient.constrained(&result.estimate);
        let mut warnings = settling(&self.free_names(), &values.rows);
        let start_values = self.free_values();
        let unmoved = estimate
            .iter()
            .zip(&start_values)
            .all(|(e, s)| (e - s).abs() <= 1e-9 * s.abs().max(1e-12));
        if unmoved && result.iterations > 0 {
            warnings.insert(
                0,
                FileFitWarning::NoProgress {
                    iterations: result.iterations,
                },
            );
        }
        Ok(FileFit {
            fitted: self.with_values(&estimate),
            estimate,
            report: FileFitReport::Gradient {
                result,
                iterates: values.rows,
            },
            warnings,
            standard_errors: None,
        })
    }
}

/// A warning per parameter still drifting: over the last quarter of the iterations,
/// its mean moved by more than 2 % (and 5 standard errors of its iterates) against the
/// quarter before. EM's iterates of a noisy E-step wander; a drift means more
/// iterations are needed.
fn settling(names: &[String], rows: &[(f64, Vec<f64>)]) -> Vec<FileFitWarning> {
    let q = rows.len() / 4;
    if q < 2 {
        return vec![FileFitWarning::TooFewIterations {
            iterations: rows.len(),
        }];
    }
    let last = &rows[rows.len() - q..];
    let before = &rows[rows.len() - 2 * q..rows.len() - q];
    let mut warnings = Vec::new();
    for (k, name) in names.iter().enumerate() {
        let stats = |part: &[(f64, Vec<f64>)]| {
            let v: Vec<f64> = part.iter().map(|r| r.1[k]).collect();
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
            (mean, var.sqrt())
        };
        let ((m1, _), (m2, sd2)) = (stats(before), stats(last));
        let change = (m2 - m1).abs();
        if change > 0.02 * m2.abs().max(1e-12) && change > 5.0 * sd2 / (q as f64).sqrt() {
            warnings.push(FileFitWarning::StillMoving {
                name: name.clone(),
                from: m1,
                to: m2,
            });
        }
    }
    warnings
}

/// The names whose entries of `direction` carry most of it (at least a tenth of the
/// largest), largest first.
pub(crate) fn leading_names(names: &[String], direction: &[f64]) -> Vec<String> {
    let largest = direction.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let mut order: Vec<usize> = (0..names.len().min(direction.len()))
        .filter(|&k| direction[k].abs() >= 0.1 * largest)
        .collect();
    order.sort_by(|&a, &b| direction[b].abs().total_cmp(&direction[a].abs()));
    order.into_iter().map(|k| names[k].clone()).collect()
}
