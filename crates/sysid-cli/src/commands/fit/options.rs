//! What a `sysid fit` class's command reads: one value filled from the class's
//! arguments ([`super::args`]), the options of other classes at their defaults.

use super::args::{
    AffineArgs, FitClass, FitCommand, LtiArgs, NlbenchArgs, OutputArgs, ParticleEmArgs, WienerArgs,
};
use crate::DataArgs;
use crate::error::CliError;
use std::path::PathBuf;
use sysid::em::FitSettings;
use sysid::em::affine::AffineMethod;
use sysid::modelfile::Criterion;

/// The options of a fit, whatever its class (those of other classes at their
/// defaults: the command line refuses them).
#[derive(Debug, Clone)]
pub struct Options {
    /// Model class: `lti` (linear Gaussian state space, exact EM), `nlbench` (the
    /// seed-000 benchmark, particle EM), `affine` (particle EM for an affine model:
    /// `--system nlbench`, or a linear model given by `--init FILE`) or `wiener`
    /// (blind Wiener identification from y1, y2 by gradient EM, seed 001). Leave it
    /// out with `--model`.
    pub kind: Option<String>,
    /// A nonlinear model file (`.toml`, docs/model-format.md) whose free parameters
    /// are estimated from their values in the file: closed-form particle EM when the
    /// equations are affine in them (`--method robust` or `em`); otherwise the direct
    /// multi-start likelihood fit (`robust`) or gradient EM (`em`).
    /// The fitted model is written as a model file.
    pub model: Option<PathBuf>,
    pub data: DataArgs,
    /// Model order (required with `--init n4sid`; checked against a model file), or
    /// a range `FROM..TO` (linear EM): every order is fitted, a table of
    /// log-likelihood, parameters, AIC, BIC and validation fit is printed, and the one
    /// `--select` chooses is written. BIC and AIC count the identifiable parameters (a
    /// black-box model's, less the n^2 of a change of state basis).
    pub order: Option<String>,
    /// Starting model: `n4sid` (subspace fit; its S is set to zero) or a model file.
    /// For `nlbench`: `a,b,c,d` or `a,b,c,d,q,r` (default: the nominal values
    /// 0.5,25,8,0.05,0.01,0.1).
    pub init: String,
    /// `fit affine`: the affine system (`nlbench`); without it `--init` names a linear
    /// model file.
    pub system: Option<String>,
    /// Hold a matrix fixed: `NAME` at its initial value, or `NAME=VALUE` with a number
    /// (broadcast) or a JSON matrix. Names: A B C D h Q R S mu P1. Repeatable.
    pub fix: Vec<String>,
    /// Estimate these covariances as diagonal (`Q`, `R`, comma separated); a full
    /// initial value is replaced by its diagonal.
    pub diag: Vec<String>,
    /// Linear EM: bound the free noise variances below (`Q, R >= V I`, in the data's
    /// units; 0 = plain maximum likelihood). Use it when the likelihood climbs towards
    /// a singular `Q` or `R`, where EM is no longer numerically monotone.
    pub min_variance: f64,
    /// Linear EM: bound the output noise below relative to each output's sample
    /// variance, `R >= REL diag(var y)`, e.g. 1e-4 for a noise standard deviation of
    /// at least 1 % of each output's. Use it when an output's noise variance heads to
    /// zero (the likelihood then grows without bound). 0 (the default) = plain maximum
    /// likelihood.
    pub min_output_noise: f64,
    /// Linear EM: estimate R as a full covariance. By default R is diagonal when there
    /// are several outputs (independent sensor noise, MARSS's default): with a full R
    /// the likelihood of a record with several outputs often climbs towards a singular
    /// R that makes one combination of the outputs exactly predictable, a degenerate
    /// optimum that predicts each output worse (the DaISy glass furnace: 61 % against
    /// 80 % one-step prediction fit).
    pub full_r: bool,
    /// `--init n4sid`: enforce a stable A in the subspace start (see `sysid n4sid
    /// --stable`).
    pub stable: bool,
    /// `--init n4sid`: the SVD weighting of the subspace start, or `auto` (the
    /// default): EM from each of MOESP, N4SID and CVA, the best finished.
    pub weighting: String,
    /// Linear EM: also estimate the output offset h (by default h is held at the
    /// start's value: for `--init n4sid`, the record's mean output less the
    /// steady-state response to its mean input).
    pub offset: bool,
    /// Linear EM: also estimate the initial state's mean mu and covariance P1 of this
    /// record. By default they are held at the start's values during EM (N4SID: mu = 0,
    /// P1 = the second moment of its state sequence), and the model written describes a
    /// new record's initial state instead ("initial": "stationary" for a stable fitted
    /// A, "diffuse" otherwise), so that it can be run on another record of the same
    /// process.
    pub estimate_initial: bool,
    /// Linear EM: the training record's initial state: `model` (the start's: N4SID's,
    /// or the `--init` file's), `stationary` (the stationary law of the start's state
    /// noise) or `diffuse` (exact diffuse: EM maximises Durbin and Koopman's diffuse
    /// likelihood, as statsmodels does for unit-root models). Whatever the choice, the
    /// model written describes a new record's initial state as `stationary` when its A
    /// is stable and `diffuse` otherwise (unless mu or P1 were estimated or fixed).
    pub initial: String,
    /// Linear EM: `squarem` (the default) accelerates EM by squared extrapolation
    /// (Varadhan and Roland 2008; monotone like EM, three E-steps per cycle, often tens
    /// of times fewer E-steps to the optimum); `none` runs plain EM.
    pub accelerate: String,
    /// After EM, maximise the likelihood directly. Linear EM: the exact log-likelihood
    /// by BFGS (quasi-Newton, superlinear near the maximum, where EM crawls): `auto`
    /// (the default) when the free parameters number at most 20 (structural models),
    /// `on`, `off`. The robust particle driver (`fit nlbench`, `fit affine`): a
    /// 10 000-particle log-likelihood on common random numbers by Nelder-Mead from
    /// its estimate, which undoes the small-particle E-step's bias of the noise
    /// variances (`auto` and `on`), or not (`off`).
    pub polish: String,
    /// The robust particle driver: `on` (the default) lets its refinement jump along
    /// its own drift (overrelaxed EM, a jump kept only when the ranking filter gains a
    /// nat); `off` runs plain EM iterations.
    pub extrapolate: String,
    /// Linear EM: standard errors of the free parameters from the observed information
    /// (the negative Hessian of the exact log-likelihood in the model's entries, by
    /// central differences; a covariance by its upper triangle), with 95 % confidence
    /// intervals: `auto` (the default) for at most 20 free parameters, `on`, `off`.
    /// Black-box models (free A and C) are not identifiable and get none.
    pub std_errors: String,
    /// Linear EM: `mean` removes each signal's mean before the fit and folds the means
    /// into the written model's offset h (and mu), so that it describes, predicts and
    /// simulates the original signals; `linear` removes a straight line in time (the
    /// time column, or the row number) from each signal and stores the lines in the
    /// model: predict, compare, simulate, forecast, resid, loglik, filter and smooth
    /// remove them from a record at its times and return outputs in the original units
    /// (states are those of the detrended signals); `none` (the default) fits the
    /// signals as they are.
    pub detrend: String,
    /// Linear EM: fit on the first FRACTION of the rows (after --range) and report the
    /// fitted model's simulation and one-step prediction fits on the rest (as `sysid
    /// compare` computes them).
    pub split: Option<f64>,
    /// Linear EM with `--order FROM..TO`: the criterion that chooses the order written,
    /// `bic` (the default), `aic`, or `validation` (the best simulation fit on the rows
    /// held out by --split).
    pub select: String,
    /// Maximum number of EM iterations (particle EM runs exactly this many; with
    /// `--accelerate squarem`, a budget of E-steps, three per cycle).
    pub max_iter: usize,
    /// Particle EM: particles M of the filter (and paths of `ffbsi-reject`).
    pub particles: usize,
    /// Particle EM: E-step smoother, `tanizaki` (seed 000's, O(M^2) per step) or
    /// `ffbsi-reject` (O(M) expected per step when the transition density is not too
    /// peaked).
    pub smoother: String,
    /// Particle fits: `robust` (the default: several starts around --init explored
    /// with the noise estimated from an inflated value, the best by a 1000-particle
    /// log-likelihood refined with --particles for --max-iter iterations and averaged;
    /// docs/particle-em.md), `em` (one run of particle EM from --init, seed 000's
    /// algorithm) or `psaem` (stochastic-approximation EM with a conditional particle
    /// filter with ancestor sampling, Lindsten 2013; 15 particles are usually enough).
    pub method: String,
    /// Particle fits with `--method robust`: the number of starts (--init and
    /// perturbations of it, each coefficient times U[0.5, 1.5]).
    pub starts: usize,
    /// Particle EM: seed of the random streams (same seed, same result, any machine).
    pub seed: u64,
    /// `fit --model`: `likelihood` or `simulation`.
    pub criterion: Criterion,
    /// `--criterion simulation`: simulations per run, in units of (unknowns + 1).
    pub patience: usize,
    /// `--criterion simulation`: the perturbations' spread on the log scale.
    pub spread: f64,
    /// Particle fits: which noise covariances are estimated: `--estimate-noise` (or
    /// `=both`) both, `=q` the process noise only, `=r` the output noise only, `=none`
    /// neither (held at --init's values). Default: both for `--method robust` (which
    /// explores with both estimated anyway and holds a noise the user keeps only in its
    /// refinement), none for `em` and `psaem`. At a small process noise (nlbench's
    /// q = 0.01), estimating q is what lets the particle kernel move the trajectory.
    pub estimate_noise: Option<String>,
    /// Linear EM: stop when the estimated distance to the maximum of the
    /// log-likelihood (Aitken's extrapolation of the last three values) is below this
    /// many nats. A run that ends at --max-iter instead says so, with the estimate.
    pub tol_nats: f64,
    /// Stop when the relative log-likelihood change of an iteration is below this
    /// (default: 1e-6, except for linear EM, which uses --tol-nats unless this is
    /// given).
    pub tol: Option<f64>,
    /// Where to write the fitted model (JSON).
    pub out: PathBuf,
    /// Also write the log-likelihood trace (CSV: iteration, loglik).
    pub trace: Option<PathBuf>,
    /// Replace existing output files.
    pub force: bool,
    /// Print `{loglik, iterations, termination, seconds}` as JSON.
    pub json: bool,
    /// The ids of the arguments given on the command line (the others are defaults).
    pub given: Vec<String>,
}

impl Options {
    /// The defaults of every class, for these data and outputs.
    fn new(kind: Option<&str>, data: DataArgs, output: OutputArgs) -> Options {
        Options {
            kind: kind.map(String::from),
            model: None,
            data,
            order: None,
            init: "n4sid".into(),
            system: None,
            fix: Vec::new(),
            diag: Vec::new(),
            min_variance: 0.0,
            min_output_noise: 0.0,
            full_r: false,
            stable: false,
            weighting: "auto".into(),
            offset: false,
            estimate_initial: false,
            initial: "model".into(),
            accelerate: "squarem".into(),
            polish: "auto".into(),
            extrapolate: "on".into(),
            std_errors: "auto".into(),
            detrend: "none".into(),
            split: None,
            select: "bic".into(),
            max_iter: 500,
            particles: 100,
            smoother: "tanizaki".into(),
            method: "robust".into(),
            starts: 8,
            seed: 1,
            criterion: Criterion::default(),
            patience: 100,
            spread: 0.3,
            estimate_noise: None,
            tol_nats: 1e-4,
            tol: None,
            out: output.out,
            trace: output.trace,
            force: output.force,
            json: output.json,
            given: Vec::new(),
        }
    }

    /// The particle-fit settings given on the command line (`None` for a flag left at
    /// its default: the method that runs fills it with its own default, and refuses a
    /// given flag it does not read).
    pub fn settings(&self) -> Result<FitSettings, CliError> {
        let given = |id: &str| self.given.iter().any(|g| g == id);
        let method =
            self.method
                .parse::<AffineMethod>()
                .map_err(|message| CliError::BadOption {
                    option: "--method",
                    message,
                })?;
        Ok(FitSettings {
            method: given("method").then_some(method),
            particles: given("particles").then_some(self.particles),
            smoother: given("smoother").then(|| self.smoother.clone()),
            max_iter: given("max_iter").then_some(self.max_iter),
            starts: given("starts").then_some(self.starts),
            polish: given("polish").then_some(self.polish != "off"),
            extrapolate: given("extrapolate").then_some(self.extrapolate == "on"),
            patience: given("patience").then_some(self.patience),
            spread: given("spread").then_some(self.spread),
        })
    }

    fn with_particle_em(mut self, em: ParticleEmArgs) -> Options {
        self.particles = em.particles;
        self.smoother = em.smoother;
        self.method = em.method;
        self.starts = em.starts;
        self.extrapolate = em.extrapolate;
        self
    }

    fn nlbench(kind: &str, a: NlbenchArgs) -> Options {
        let mut o = Options::new(Some(kind), a.data, a.output).with_particle_em(a.em);
        o.init = a.init;
        o.max_iter = a.max_iter;
        o.seed = a.seed;
        o.estimate_noise = a.estimate_noise;
        o
    }

    /// The options of a class's command.
    pub fn of_class(class: FitClass, given: Vec<String>) -> Options {
        let o = match class {
            FitClass::Lti(a) => Options::lti(*a),
            FitClass::Nlbench(a) => Options::nlbench("nlbench", *a),
            FitClass::Affine(a) => {
                let AffineArgs { system, nlbench } = *a;
                Options {
                    system,
                    ..Options::nlbench("affine", nlbench)
                }
            }
            FitClass::Wiener(a) => {
                let WienerArgs {
                    data,
                    max_iter,
                    particles,
                    seed,
                    output,
                } = *a;
                Options {
                    max_iter,
                    particles,
                    seed,
                    ..Options::new(Some("wiener"), data, output)
                }
            }
        };
        Options { given, ..o }
    }

    fn lti(a: LtiArgs) -> Options {
        Options {
            order: a.order,
            init: a.init,
            fix: a.fix,
            diag: a.diag,
            min_variance: a.min_variance,
            min_output_noise: a.min_output_noise,
            full_r: a.full_r,
            stable: a.stable,
            weighting: a.weighting,
            offset: a.offset,
            estimate_initial: a.estimate_initial,
            initial: a.initial,
            accelerate: a.accelerate,
            polish: a.polish,
            std_errors: a.std_errors,
            detrend: a.detrend,
            split: a.split,
            select: a.select,
            max_iter: a.max_iter,
            tol_nats: a.tol_nats,
            tol: a.tol,
            ..Options::new(Some("lti"), a.data, a.output)
        }
    }

    /// The options of `fit --model m.toml`; `None` without its data or outputs.
    pub fn of_model_file(a: FitCommand) -> Option<Options> {
        let mut o = Options::new(None, a.data?, a.output?).with_particle_em(a.em);
        o.given = a.given;
        o.polish = a.polish;
        o.model = a.model;
        o.max_iter = a.max_iter;
        o.seed = a.seed;
        o.criterion = a.criterion;
        o.patience = a.patience;
        o.spread = a.spread;
        Some(o)
    }
}
