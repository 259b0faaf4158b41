//! The seed-000 particle-EM study on [`Nlbench`]: one run = one seeded data set, one
//! random start around the truth, one EM run. Shared by the `nlbench-em` runner and the
//! demo, so both run the same experiment.
//!
//! # Algorithm
//! Run `r` of a study with seed `s` draws its data set from `stream(s, 3r)`, its start
//! (each of a, b, c, d times an independent U[0.5, 1.5], ALGORITHMS.md 3) from
//! `stream(s, 3r + 1)` and the EM random streams from `stream(s, 3r + 2)`: a run's
//! result depends only on `(s, r)`, so runs can go in parallel, in any order, or on
//! different machines.

use crate::{Nlbench, NlbenchAffine, NlbenchParams};
use rand::RngExt;
use sysid_em::affine::{AffineEm, AffineEmError, AffineEmSpec, AffineParams};
use sysid_em::linear::Covariance;
use sysid_em::{EmObserver, EmOptions, EmResult, IterationInfo, OptionsError, run_em};
use sysid_smc::{Series, Smoother, stream};
use thiserror::Error;

/// Which noise variances a study estimates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NoiseSetting {
    /// The paper's setting: q and r known, only a, b, c, d estimated.
    #[default]
    Known,
    /// q and r start at 10 times their true values and are estimated.
    Estimated,
    /// q starts at 100 times its true value and is estimated; r known.
    ProcessOnly,
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
    /// EM iterations per run, all of them run (the paper: 1000).
    pub iterations: usize,
    /// Which noise variances are estimated.
    pub noise: NoiseSetting,
}

impl Default for NlbenchStudy {
    /// The paper's settings, seed 1.
    fn default() -> Self {
        NlbenchStudy {
            seed: 1,
            steps: 1000,
            particles: 50,
            iterations: 1000,
            noise: NoiseSetting::Known,
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
    /// (a, b, c, d) after each iteration.
    pub trajectory: Vec<[f64; 4]>,
    /// The EM runner's result (log-likelihood trace, termination, time).
    pub em: EmResult<AffineParams, AffineEmError>,
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
        let mut start = NlbenchParams {
            a: truth.a * factor(),
            b: truth.b * factor(),
            c: truth.c * factor(),
            d: truth.d * factor(),
            ..truth
        };
        match self.noise {
            // a deliberately loose start: EM shrinks q and r as the fit improves
            NoiseSetting::Estimated => {
                start.q = 10.0 * truth.q;
                start.r = 10.0 * truth.r;
            }
            NoiseSetting::ProcessOnly => start.q = 100.0 * truth.q,
            NoiseSetting::Known => {}
        }
        start
    }

    /// Makes run `run` with the E-step smoother `smoother`; `observer` sees every
    /// iteration (progress bars, traces).
    pub fn run<S: Smoother<Nlbench>>(
        &self,
        run: usize,
        smoother: S,
        observer: &mut impl EmObserver<AffineParams>,
    ) -> Result<NlbenchRun, StudyError> {
        let options = EmOptions {
            max_iterations: self.iterations,
            tol: 0.0,
            ..EmOptions::default()
        }
        .check()?;
        let simulation = Nlbench::truth().simulate(self.steps, self.run_seed(run, 0));
        let data = Series::new(&simulation.outputs, 1).map_err(AffineEmError::from)?;
        let start = self.start(run);
        let (pi_x, pi_y) = match self.noise {
            NoiseSetting::Known => (Covariance::Fixed, Covariance::Fixed),
            NoiseSetting::Estimated => (Covariance::Diagonal, Covariance::Diagonal),
            NoiseSetting::ProcessOnly => (Covariance::Diagonal, Covariance::Fixed),
        };
        let spec = AffineEmSpec {
            pi_x,
            pi_y,
            ..AffineEmSpec::default()
        };
        let model = NlbenchAffine;
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
            em: result,
        })
    }
}
