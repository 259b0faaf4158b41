//! The seed-000 particle-EM study on [`Nlbench`] (experiment settings live with the
//! runners, not in the model zoo): one run = one seeded data set, one
//! random start around the truth, one EM run. Shared by the `nlbench-em` runner and the
//! demo, so both run the same experiment.
//!
//! # Algorithm
//! Run `r` of a study with seed `s` draws its data set from `stream(s, 3r)`, its start
//! (each of a, b, c, d times an independent U[0.5, 1.5], ALGORITHMS.md 3) from
//! `stream(s, 3r + 1)` and the EM random streams from `stream(s, 3r + 2)`: a run's
//! result depends only on `(s, r)`, so runs can go in parallel, in any order, or on
//! different machines.

use rand::RngExt;
use sysid::em::affine::{
    AffineEm, AffineEmError, AffineEmSpec, AffineParams, RobustFit, RobustOptions, fit_robust,
};
use sysid::em::linear::Covariance;
use sysid::em::{EmObserver, EmOptions, IterationInfo, OptionsError, run_em};
use sysid::models::{Nlbench, NlbenchAffine, NlbenchParams};
use sysid::smc::{Series, Smoother, stream};
use thiserror::Error;

/// How a study's runs fit the model.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Method {
    /// The paper's Algorithm 2: theta = (beta, Pi) with q and r estimated, started at
    /// 10 times their true values.
    #[default]
    Paper,
    /// A variant: q and r held at their true values, only a, b, c, d estimated.
    HeldNoise,
    /// A variant: q started at 100 times its true value and estimated; r held.
    ProcessNoise,
    /// The robust driver ([`fit_robust`]) from the run's start with the true q and r
    /// as the user's noise guess (inflated by the driver).
    Robust(RobustOptions),
}

impl Method {
    /// The method's name in the runner's output (`paper`, `held-noise`, `q`, `robust`).
    pub fn name(&self) -> &'static str {
        match self {
            Method::Paper => "paper",
            Method::HeldNoise => "held-noise",
            Method::ProcessNoise => "q",
            Method::Robust(_) => "robust",
        }
    }
}

/// The settings of a study.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NlbenchStudy {
    /// Study seed.
    pub seed: u64,
    /// Data length T (the paper: 1000).
    pub steps: usize,
    /// Particles M (the paper: 50).
    pub particles: usize,
    /// EM iterations per run, all of them run (the paper: 1000; the robust method
    /// uses its own counts).
    pub iterations: usize,
    /// How the runs fit the model.
    pub method: Method,
    /// Start every run at the truth (the no-drift check).
    pub at_truth: bool,
}

impl Default for NlbenchStudy {
    /// The paper's settings, seed 1.
    fn default() -> Self {
        NlbenchStudy {
            seed: 1,
            steps: 1000,
            particles: 50,
            iterations: 1000,
            method: Method::Paper,
            at_truth: false,
        }
    }
}

/// Why a run could not be made.
#[derive(Debug, Error)]
pub enum StudyError {
    /// The EM options are invalid (e.g. zero iterations).
    #[error("{0}")]
    Options(#[from] OptionsError),
    /// The data or the particle EM set-up was refused.
    #[error("{0}")]
    Em(#[from] AffineEmError),
}

/// One run's data, start and result.
#[derive(Debug, Clone)]
pub struct NlbenchRun {
    /// Run index within the study.
    pub run: usize,
    /// Simulated states `x_0..x_{T-1}`.
    pub states: Vec<f64>,
    /// Simulated outputs `y_0..y_{T-1}`.
    pub outputs: Vec<f64>,
    /// The random start.
    pub start: NlbenchParams,
    /// The final estimate.
    pub estimate: NlbenchParams,
    /// (a, b, c, d) after each iteration (robust: of the refinement).
    pub trajectory: Vec<[f64; 4]>,
    /// The final log-likelihood estimate: the last E-step's filter (EM), or the large
    /// filter's at the averaged estimate (robust).
    pub loglik: Option<f64>,
    /// EM iterations made (robust: exploration and refinement together).
    pub iterations: usize,
    /// The E-steps' log-likelihood estimates, one per iteration (EM only; empty for
    /// robust).
    pub loglik_trace: Vec<f64>,
    /// Iterations whose log-likelihood estimate decreased (EM only).
    pub decreases: usize,
    /// Wall-clock time of the fit.
    pub elapsed: std::time::Duration,
    /// The robust driver's whole result.
    pub robust: Option<RobustFit>,
}

/// (a, b, c, d) of a parameter set.
pub fn abcd(p: &NlbenchParams) -> [f64; 4] {
    [p.a, p.b, p.c, p.d]
}

/// The paper's success criterion: every one of a, b, c, d within 10 % of the truth.
pub fn within_ten_percent(p: &NlbenchParams) -> bool {
    abcd(p)
        .iter()
        .zip(abcd(&NlbenchParams::TRUE))
        .all(|(v, t)| ((v - t) / t).abs() <= 0.1)
}

/// Records the (a, b, c, d) trajectory and forwards every iteration.
struct Recorder<'o, O> {
    trajectory: Vec<[f64; 4]>,
    inner: &'o mut O,
}

impl<O: EmObserver<AffineParams>> EmObserver<AffineParams> for Recorder<'_, O> {
    fn iteration(&mut self, info: &IterationInfo<'_, AffineParams>) {
        self.trajectory
            .push(abcd(&NlbenchAffine::nlbench_params(info.estimate)));
        self.inner.iteration(info);
    }
}

impl NlbenchStudy {
    /// A 64-bit seed of run `run`'s stream `k` (0 data, 1 start, 2 EM).
    pub fn run_seed(&self, run: usize, k: u64) -> u64 {
        stream(self.seed, 3 * run as u64 + k).random()
    }

    /// The starting point of run `run`.
    pub fn start(&self, run: usize) -> NlbenchParams {
        let mut rng = stream(self.run_seed(run, 1), 0);
        let mut factor = || rng.random_range(0.5..1.5);
        let truth = NlbenchParams::TRUE;
        if self.at_truth {
            return truth;
        }
        let mut start = NlbenchParams {
            a: truth.a * factor(),
            b: truth.b * factor(),
            c: truth.c * factor(),
            d: truth.d * factor(),
            ..truth
        };
        match self.method {
            // a deliberately loose start: EM shrinks q and r as the fit improves
            Method::Paper => {
                start.q = 10.0 * truth.q;
                start.r = 10.0 * truth.r;
            }
            Method::ProcessNoise => start.q = 100.0 * truth.q,
            // the robust driver inflates the noise itself
            Method::HeldNoise | Method::Robust(_) => {}
        }
        start
    }

    /// Makes run `run` with the E-step smoother `smoother`; `observer` sees every
    /// iteration (progress bars, traces).
    pub fn run<S: Smoother<Nlbench> + Clone + Send + Sync>(
        &self,
        run: usize,
        smoother: S,
        observer: &mut impl EmObserver<AffineParams>,
    ) -> Result<NlbenchRun, StudyError> {
        let simulation = Nlbench::truth().simulate(self.steps, self.run_seed(run, 0));
        let data = Series::new(&simulation.outputs, 1).map_err(AffineEmError::from)?;
        let start = self.start(run);
        let model = NlbenchAffine;
        let (pi_x, pi_y) = match self.method {
            Method::HeldNoise => (Covariance::Fixed, Covariance::Fixed),
            Method::Paper | Method::Robust(_) => (Covariance::Diagonal, Covariance::Diagonal),
            Method::ProcessNoise => (Covariance::Diagonal, Covariance::Fixed),
        };
        let spec = AffineEmSpec {
            pi_x,
            pi_y,
            ..AffineEmSpec::default()
        };
        if let Method::Robust(options) = self.method {
            let began = std::time::Instant::now();
            let fit = fit_robust(
                &model,
                data,
                &NlbenchAffine::params(&start),
                &spec,
                &smoother,
                &RobustOptions {
                    explore_particles: self.particles,
                    ..options
                },
                self.run_seed(run, 2),
            )?;
            let trajectory = fit
                .refine_trace
                .iter()
                .map(|p| abcd(&NlbenchAffine::nlbench_params(p)))
                .collect();
            return Ok(NlbenchRun {
                run,
                estimate: NlbenchAffine::nlbench_params(&fit.estimate),
                start,
                trajectory,
                states: simulation.states,
                outputs: simulation.outputs,
                loglik: Some(fit.loglik),
                iterations: options.starts * options.explore_iterations + options.refine_iterations,
                decreases: 0,
                loglik_trace: Vec::new(),
                elapsed: began.elapsed(),
                robust: Some(fit),
            });
        }
        let options = EmOptions {
            max_iterations: self.iterations,
            tol: 0.0,
            ..EmOptions::default()
        }
        .check()?;
        let mut em = AffineEm::new(
            &model,
            data,
            self.particles,
            smoother,
            spec,
            self.run_seed(run, 2),
        )?;
        let mut recorder = Recorder {
            trajectory: Vec::with_capacity(self.iterations),
            inner: observer,
        };
        let result = run_em(
            &mut em,
            NlbenchAffine::params(&start),
            &options,
            &mut recorder,
        );
        Ok(NlbenchRun {
            run,
            estimate: NlbenchAffine::nlbench_params(&result.estimate),
            start,
            trajectory: recorder.trajectory,
            states: simulation.states,
            outputs: simulation.outputs,
            loglik: result.loglik,
            iterations: result.iterations,
            decreases: result.decreases,
            loglik_trace: result.trace,
            elapsed: result.elapsed,
            robust: None,
        })
    }
}
