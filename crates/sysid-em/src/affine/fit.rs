//! One call for particle EM on a model affine in its parameters: the method chosen by
//! name (the robust driver, plain particle EM, PSAEM), its options checked once, the
//! estimate after every iteration, and the method's own report.

use super::{
    AffineEm, AffineEmError, AffineEmSpec, AffineModel, AffineParams, Psaem, RobustFit,
    RobustOptions, StepSizes, fit_robust_until,
};
use crate::{
    CheckedEmOptions, EmAlgorithm, EmObserver, EmOptions, EmResult, FitRun, IterationInfo, run_em,
};
use sysid_smc::{PathSmoother, Series, TransitionBound};

/// How an affine model is fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum AffineMethod {
    /// Several perturbed starts explored, the best refined and averaged
    /// ([`fit_robust_until`]): the default, robust to a poor start.
    Robust,
    /// Plain particle EM from the start (seed 000's algorithm).
    Em,
    /// Particle stochastic approximation EM ([`Psaem`]).
    Psaem,
}

impl AffineMethod {
    /// The names [`AffineMethod::from_name`] knows.
    pub const NAMES: [&'static str; 3] = ["robust", "em", "psaem"];

    /// The method of a name; `None` for an unknown one.
    pub fn from_name(name: &str) -> Option<AffineMethod> {
        match name {
            "robust" => Some(AffineMethod::Robust),
            "em" => Some(AffineMethod::Em),
            "psaem" => Some(AffineMethod::Psaem),
            _ => None,
        }
    }

    /// Its name.
    pub fn name(&self) -> &'static str {
        match self {
            AffineMethod::Robust => Self::NAMES[0],
            AffineMethod::Em => Self::NAMES[1],
            AffineMethod::Psaem => Self::NAMES[2],
        }
    }

    /// What it is, for a message.
    pub fn description(&self) -> &'static str {
        match self {
            AffineMethod::Robust => "the robust particle EM driver (method robust)",
            AffineMethod::Em => "plain particle EM (method em)",
            AffineMethod::Psaem => "particle SAEM (method psaem)",
        }
    }

    /// The settings ([`crate::FitSettings`]) it reads: PSAEM has its own conditional
    /// particle filter (no `smoother`); only the robust driver explores `starts`,
    /// polishes and extrapolates.
    pub fn reads(&self) -> &'static [&'static str] {
        match self {
            AffineMethod::Robust => &[
                "method",
                "particles",
                "smoother",
                "max_iter",
                "starts",
                "polish",
                "extrapolate",
            ],
            AffineMethod::Em => &["method", "particles", "smoother", "max_iter"],
            AffineMethod::Psaem => &["method", "particles", "max_iter"],
        }
    }
}

impl std::fmt::Display for AffineMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for AffineMethod {
    type Err = String;

    /// A method by its name; the error lists the names.
    fn from_str(name: &str) -> Result<Self, String> {
        AffineMethod::from_name(name).ok_or_else(|| {
            format!(
                "unknown method {name:?} (known: {})",
                AffineMethod::NAMES.join(", ")
            )
        })
    }
}

/// Options of [`fit_affine`]; [`AffineFitOptions::check`] gives the only form it takes.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct AffineFitOptions {
    /// The method. Default [`AffineMethod::Robust`].
    pub method: AffineMethod,
    /// What is estimated (which blocks are free). Default: everything.
    pub spec: AffineEmSpec,
    /// Particles of the E-step; the robust driver refines with these and explores with
    /// half as many. Default 100.
    pub particles: usize,
    /// The E-step smoother of `em` and `robust` (PSAEM uses its own). Default
    /// Tanizaki's.
    pub smoother: PathSmoother,
    /// EM or PSAEM iterations, or the robust driver's refinement iterations. Default
    /// 500.
    pub iterations: usize,
    /// Starts the robust driver explores. Default [`RobustOptions::default`]'s.
    pub starts: usize,
    /// Particles of the robust driver's polish (its estimate's likelihood maximised
    /// directly; [`RobustOptions::polish_particles`]); 0 skips it. Default
    /// [`RobustOptions::default`]'s (10 000).
    pub polish_particles: usize,
    /// Whether the robust driver's refinement extrapolates its drift
    /// ([`RobustOptions::extrapolate`]). Default true.
    pub extrapolate: bool,
}

impl Default for AffineFitOptions {
    fn default() -> Self {
        AffineFitOptions {
            method: AffineMethod::Robust,
            spec: AffineEmSpec::default(),
            particles: 100,
            smoother: PathSmoother::for_em("tanizaki", 100).expect("a known smoother"),
            iterations: 500,
            starts: RobustOptions::default().starts,
            polish_particles: RobustOptions::default().polish_particles,
            extrapolate: RobustOptions::default().extrapolate,
        }
    }
}

impl AffineFitOptions {
    /// The options with `method`.
    pub fn with_method(mut self, method: AffineMethod) -> Self {
        self.method = method;
        self
    }

    /// Checks the options.
    ///
    /// # Errors
    /// [`AffineEmError::InvalidOption`] naming the option: no particles, no
    /// iterations, no starts for the robust driver.
    pub fn check(self) -> Result<CheckedAffineFitOptions, AffineEmError> {
        let bad =
            |name: &'static str, reason: String| AffineEmError::InvalidOption { name, reason };
        if self.particles == 0 {
            return Err(bad("particles", "must be at least 1".into()));
        }
        let em = EmOptions {
            max_iterations: self.iterations,
            tol: 0.0,
            ..EmOptions::default()
        }
        .check()
        .map_err(|e| bad("iterations", e.to_string()))?;
        if self.method == AffineMethod::Robust && self.starts == 0 {
            return Err(bad("starts", "must be at least 1".into()));
        }
        let robust = RobustOptions {
            starts: self.starts,
            refine_iterations: self.iterations,
            refine_particles: self.particles.max(2),
            explore_particles: (self.particles / 2).max(2),
            polish_particles: self.polish_particles,
            extrapolate: self.extrapolate,
            ..RobustOptions::default()
        };
        if self.polish_particles == 1 {
            return Err(bad(
                "polish_particles",
                "must be 0 (no polish) or at least 2".into(),
            ));
        }
        robust.check()?;
        Ok(CheckedAffineFitOptions {
            options: self,
            em,
            robust,
        })
    }
}

/// [`AffineFitOptions`] that passed their checks, with the runners' options derived
/// from them.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckedAffineFitOptions {
    options: AffineFitOptions,
    em: CheckedEmOptions,
    robust: RobustOptions,
}

impl CheckedAffineFitOptions {
    /// The options as given.
    pub fn options(&self) -> &AffineFitOptions {
        &self.options
    }

    /// The runner's options of `em` and `psaem` (no stopping rule: the iterations run).
    pub fn em(&self) -> &CheckedEmOptions {
        &self.em
    }

    /// The robust driver's options.
    pub fn robust(&self) -> &RobustOptions {
        &self.robust
    }

    /// The same options estimating `spec` (a model file's own choice of free blocks).
    pub fn with_spec(mut self, spec: AffineEmSpec) -> Self {
        self.options.spec = spec;
        self
    }
}

/// What each method reports.
#[derive(Debug, Clone)]
pub enum AffineFitReport {
    /// `em` or `psaem`: the runner's result, and the estimate after every iteration
    /// with that iteration's log-likelihood estimate.
    Em {
        /// The runner's result (a failed iteration is its [`crate::Termination`]).
        result: Box<EmResult<AffineParams, AffineEmError>>,
        /// `(loglik, estimate)` after each iteration.
        iterates: Vec<(f64, AffineParams)>,
    },
    /// The robust driver's starts, maxima, refinement and warnings.
    Robust(Box<RobustFit>),
}

/// The result of [`fit_affine`].
#[derive(Debug, Clone)]
pub struct AffineFit {
    /// The method that ran.
    pub method: AffineMethod,
    /// Its report.
    pub report: AffineFitReport,
}

impl AffineFit {
    /// The estimate.
    pub fn estimate(&self) -> &AffineParams {
        match &self.report {
            AffineFitReport::Em { result, .. } => &result.estimate,
            AffineFitReport::Robust(fit) => &fit.estimate,
        }
    }

    /// The log-likelihood estimate of the estimate: the last E-step's (`em`, `psaem`),
    /// or the robust driver's selection filter's.
    pub fn loglik(&self) -> Option<f64> {
        match &self.report {
            AffineFitReport::Em { result, .. } => result.loglik,
            AffineFitReport::Robust(fit) => Some(fit.loglik),
        }
    }

    /// Whether [`FitRun::stop`] (or the observer) ended the run early.
    pub fn interrupted(&self) -> bool {
        match &self.report {
            AffineFitReport::Em { result, .. } => {
                matches!(result.termination, crate::Termination::Interrupted { .. })
            }
            AffineFitReport::Robust(fit) => fit.interrupted,
        }
    }

    /// `(loglik, estimate)` per iteration: EM's or PSAEM's, or the robust refinement's.
    pub fn iterates(&self) -> Vec<(f64, &AffineParams)> {
        match &self.report {
            AffineFitReport::Em { iterates, .. } => iterates.iter().map(|(l, p)| (*l, p)).collect(),
            AffineFitReport::Robust(fit) => fit
                .refine_loglik
                .iter()
                .copied()
                .zip(&fit.refine_trace)
                .collect(),
        }
    }
}

/// Records the estimate after every iteration and asks the run and the observer
/// whether to stop.
struct Iterates<'o, 'r> {
    observer: &'o mut dyn EmObserver<AffineParams>,
    run: &'r FitRun<'r>,
    rows: Vec<(f64, AffineParams)>,
}

impl EmObserver<AffineParams> for Iterates<'_, '_> {
    fn start(&mut self, initial: &AffineParams) {
        self.observer.start(initial);
    }
    fn iteration(&mut self, info: &IterationInfo<'_, AffineParams>) {
        self.rows.push((info.loglik, info.estimate.clone()));
        self.observer.iteration(info);
    }
    fn finish(&mut self, estimate: &AffineParams, loglik: Option<f64>, iterations: usize) {
        self.observer.finish(estimate, loglik, iterations);
    }
    fn should_stop(&self) -> bool {
        self.observer.should_stop() || (self.run.stop)()
    }
}

/// Fits `model` to `data` from `start` by the method of `options`, with the random
/// streams of `run.seed`; `observer` hears of every EM or PSAEM iteration (the robust
/// driver runs its starts in parallel and reports at the end), and the run ends early
/// when `run.stop()` or the observer says so.
///
/// # Errors
/// Those of the method's setup (the model at `start`, the particle filter); a failure
/// inside EM's iterations is the result's [`crate::Termination::Error`].
pub fn fit_affine<A>(
    model: &A,
    data: Series<'_>,
    start: AffineParams,
    options: &CheckedAffineFitOptions,
    run: &FitRun<'_>,
    observer: &mut dyn EmObserver<AffineParams>,
) -> Result<AffineFit, AffineEmError>
where
    A: AffineModel,
    A::Smc: TransitionBound,
{
    let given = options.options();
    let method = given.method;
    let report = match method {
        AffineMethod::Robust => AffineFitReport::Robust(Box::new(fit_robust_until(
            model,
            data,
            &start,
            &given.spec,
            &given.smoother,
            options.robust(),
            run,
        )?)),
        AffineMethod::Em => {
            let em = AffineEm::new(
                model,
                data,
                given.particles,
                given.smoother,
                given.spec,
                run.seed,
            )?;
            iterate(em, start, options, run, observer)
        }
        AffineMethod::Psaem => {
            let psaem = Psaem::new(
                model,
                data,
                given.particles,
                StepSizes::default(),
                given.spec,
                run.seed,
            )?;
            iterate(psaem, start, options, run, observer)
        }
    };
    Ok(AffineFit { method, report })
}

fn iterate<E>(
    mut em: E,
    start: AffineParams,
    options: &CheckedAffineFitOptions,
    run: &FitRun<'_>,
    observer: &mut dyn EmObserver<AffineParams>,
) -> AffineFitReport
where
    E: EmAlgorithm<Estimate = AffineParams, Error = AffineEmError>,
{
    let mut iterates = Iterates {
        observer,
        run,
        rows: Vec::new(),
    };
    let result = run_em(&mut em, start, options.em(), &mut iterates);
    AffineFitReport::Em {
        result: Box::new(result),
        iterates: iterates.rows,
    }
}
