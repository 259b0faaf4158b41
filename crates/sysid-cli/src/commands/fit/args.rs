//! The command line of `sysid fit`: a subcommand per model class, each listing only
//! the options that class uses, from shared groups (the data, the outputs, particle
//! EM's settings); `sysid fit --model m.toml` fits a model file.

use crate::DataArgs;
use std::path::PathBuf;
use sysid::em::affine::AffineFitOptions;
use sysid::em::linear::{Acceleration, LinearFitOptions, Selection, Switch};
use sysid::kalman::{InitialState, TrendKind};
use sysid::modelfile::{Criterion, SimulationFitOptions};
use sysid::models::WienerFitOptions;
use sysid::subspace::WeightingChoice;

/// A library switch's default as the command line spells it.
fn on_off(on: bool) -> &'static str {
    if on { "on" } else { "off" }
}

/// `sysid fit`: a model class, or a model file (`--model`).
#[derive(clap::Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct FitCommand {
    /// The model class.
    #[command(subcommand)]
    pub class: Option<FitClass>,
    // `fit --model m.toml`: its options are flattened here one by one (clap leaves a
    // flattened optional group empty when it nests groups of its own)
    /// A nonlinear model file (`.toml`, docs/model-format.md) whose free parameters
    /// are estimated from their values in the file: closed-form particle EM when the
    /// equations are affine in them (`--method robust` or `em`); otherwise the
    /// particle likelihood maximised directly from --starts starts (`robust`: the
    /// file's values, the simulation-error fit's estimate, perturbations) or gradient
    /// EM from the file's values (`em`). The fitted model is written as a model file.
    #[arg(long, required = true)]
    pub model: Option<PathBuf>,
    /// The data (`fit --model`).
    #[command(flatten)]
    pub data: Option<DataArgs>,
    /// Particle EM or gradient EM: the number of iterations (particle EM runs exactly
    /// this many; the robust driver's refinement).
    #[arg(long, visible_alias = "iters", default_value_t = AffineFitOptions::default().iterations)]
    pub max_iter: usize,
    /// Particle EM: seed of the random streams (same seed, same result, any machine).
    #[arg(long, default_value_t = sysid::smc::DEFAULT_SEED)]
    pub seed: u64,
    /// `fit --model`: `likelihood` (the default: maximum likelihood with the file's
    /// process and measurement noise, by particle EM; best for one-step prediction and
    /// filtering) or `simulation` (the noise-free model's simulation error, minimised
    /// over the free parameters and the initial state by Levenberg-Marquardt with exact
    /// sensitivities, from the file's values and --starts - 1 perturbations of them;
    /// best for a model that is to simulate from the inputs alone).
    #[arg(long, default_value_t = Criterion::default())]
    pub criterion: Criterion,
    /// `--criterion simulation`: simulations allowed per run, in units of (number of
    /// unknowns + 1).
    #[arg(long, default_value_t = SimulationFitOptions::default().patience)]
    pub patience: usize,
    /// `--criterion simulation`: the spread of the perturbed starts on the log scale
    /// (each free value times exp(spread N(0, 1)); 0.3 is about +-30 %).
    #[arg(long, default_value_t = SimulationFitOptions::default().spread)]
    pub spread: f64,
    /// `fit --model` with the robust method: `on` (the default) finishes the estimate
    /// by maximising a 10 000-particle log-likelihood directly (the robust particle EM
    /// driver's polish; the direct search's finish); `off` keeps the estimate of the
    /// exploration and refinement.
    #[arg(long, default_value = on_off(AffineFitOptions::default().polish_particles > 0), value_parser = ["on", "off"])]
    pub polish: String,
    /// Particle EM's settings (`fit --model`).
    #[command(flatten)]
    pub em: ParticleEmArgs,
    /// The outputs (`fit --model`).
    #[command(flatten)]
    pub output: Option<OutputArgs>,
    /// The ids of the arguments given on the command line (not defaulted), filled
    /// after parsing: a fit refuses a given flag its method does not read.
    #[arg(skip)]
    pub given: Vec<String>,
}

/// The model classes.
#[derive(clap::Subcommand, Debug)]
pub enum FitClass {
    /// Linear Gaussian state space by exact EM (from N4SID or a model file), with
    /// SQUAREM, a Fisher-scoring finish of the written model's likelihood and standard
    /// errors.
    Lti(Box<LtiArgs>),
    /// The seed-000 benchmark by particle EM (the robust driver by default).
    Nlbench(Box<NlbenchArgs>),
    /// Particle EM for an affine model: `--system nlbench`, or a linear model given by
    /// `--init FILE`.
    Affine(Box<AffineArgs>),
    /// Blind Wiener identification from y1, y2 by gradient EM (seed 001).
    Wiener(Box<WienerArgs>),
}

/// Where the fit goes.
#[derive(clap::Args, Debug, Clone)]
pub struct OutputArgs {
    /// Where to write the fitted model (JSON).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the log-likelihood trace (CSV: iteration, loglik).
    #[arg(long)]
    pub trace: Option<PathBuf>,
    /// Replace existing output files.
    #[arg(long)]
    pub force: bool,
    /// Print `{loglik, iterations, termination, seconds}` as JSON.
    #[arg(long)]
    pub json: bool,
}

/// The settings of particle EM.
#[derive(clap::Args, Debug, Clone)]
pub struct ParticleEmArgs {
    /// Particle EM: particles M of the filter (and paths of `ffbsi-reject`).
    #[arg(long, default_value_t = AffineFitOptions::default().particles)]
    pub particles: usize,
    /// Particle EM: E-step smoother, `tanizaki` (seed 000's, O(M^2) per step) or
    /// `ffbsi-reject` (O(M) expected per step when the transition density is not too
    /// peaked).
    #[arg(long, default_value = AffineFitOptions::default().smoother.name())]
    pub smoother: String,
    /// Particle fits: `robust` (the default: several starts around --init explored
    /// with the noise estimated from an inflated value, the best by a 1000-particle
    /// log-likelihood refined with --particles for --max-iter iterations and averaged;
    /// docs/particle-em.md; for a model file that is not affine, its likelihood
    /// maximised directly from several starts), `em` (one run of particle EM from
    /// --init, seed 000's algorithm; gradient EM for a file that is not affine) or
    /// `psaem` (stochastic-approximation EM with a conditional particle
    /// filter with ancestor sampling, Lindsten 2013; 15 particles are usually enough).
    #[arg(long, default_value = AffineFitOptions::default().method.name())]
    pub method: String,
    /// Particle fits with `--method robust`: the number of starts (--init and
    /// perturbations of it, each coefficient times U[0.5, 1.5]); `--criterion
    /// simulation`: the runs (the file's values and perturbations of them, each free
    /// value times exp(--spread N(0, 1))).
    #[arg(long, default_value_t = AffineFitOptions::default().starts)]
    pub starts: usize,
    /// The robust particle driver (`fit nlbench`, `fit affine`, `fit --model`): `on`
    /// (the default) lets its refinement jump along its own drift every 25 iterations
    /// (overrelaxed EM; a jump is kept only when a 1000-particle filter on common
    /// random numbers gains a nat), which reaches a slow ridge's end in hundreds of
    /// iterations instead of thousands; `off` runs plain EM iterations.
    #[arg(long, default_value = on_off(AffineFitOptions::default().extrapolate), value_parser = ["on", "off"])]
    pub extrapolate: String,
}

/// Options of `sysid fit lti`.
#[derive(clap::Args, Debug, Clone)]
pub struct LtiArgs {
    #[command(flatten)]
    pub data: DataArgs,
    /// Model order (required with `--init n4sid`; checked against a model file), or
    /// a range `FROM..TO` (linear EM): every order is fitted, a table of
    /// log-likelihood, parameters, AIC, BIC and validation fit is printed, and the one
    /// `--select` chooses is written. BIC and AIC count the identifiable parameters (a
    /// black-box model's, less the n^2 of a change of state basis).
    #[arg(long)]
    pub order: Option<String>,
    /// Starting model: `n4sid` (subspace fit; its S is set to zero) or a model file.
    /// For `nlbench`: `a,b,c,d` or `a,b,c,d,q,r` (default: the nominal values
    /// 0.5,25,8,0.05,0.01,0.1).
    #[arg(long, default_value = "n4sid")]
    pub init: String,
    /// Hold a matrix fixed: `NAME` at its initial value, or `NAME=VALUE` with a number
    /// (broadcast) or a JSON matrix. Names: A B C D h Q R S mu P1. Repeatable.
    #[arg(long, value_name = "NAME[=VALUE]")]
    pub fix: Vec<String>,
    /// Estimate these covariances as diagonal (`Q`, `R`, comma separated); a full
    /// initial value is replaced by its diagonal.
    #[arg(long, value_delimiter = ',')]
    pub diag: Vec<String>,
    /// Linear EM: bound the free noise variances below (`Q, R >= V I`, in the data's
    /// units; 0 = plain maximum likelihood). Use it when the likelihood climbs towards
    /// a singular `Q` or `R`, where EM is no longer numerically monotone.
    #[arg(long, value_name = "V", default_value_t = LinearFitOptions::default().min_variance)]
    pub min_variance: f64,
    /// Linear EM: bound the output noise below relative to each output's sample
    /// variance, `R >= REL diag(var y)`, e.g. 1e-4 for a noise standard deviation of
    /// at least 1 % of each output's. Use it when an output's noise variance heads to
    /// zero (the likelihood then grows without bound). 0 (the default) = plain maximum
    /// likelihood.
    #[arg(long, value_name = "REL", default_value_t = LinearFitOptions::default().min_output_noise)]
    pub min_output_noise: f64,
    /// Linear EM: estimate R as a full covariance. By default R is diagonal when there
    /// are several outputs (independent sensor noise, MARSS's default): with a full R
    /// the likelihood of a record with several outputs often climbs towards a singular
    /// R that makes one combination of the outputs exactly predictable, a degenerate
    /// optimum that predicts each output worse (the DaISy glass furnace: 61 % against
    /// 80 % one-step prediction fit).
    #[arg(long)]
    pub full_r: bool,
    /// `--init n4sid`: enforce a stable A in the subspace start (see `sysid n4sid
    /// --stable`).
    #[arg(long)]
    pub stable: bool,
    /// `--init n4sid`: the SVD weighting of the subspace start (`moesp`, `n4sid`,
    /// `cva`), or `auto`: EM runs from each of the three and the best, by the written
    /// model's likelihood, is finished (a black-box likelihood has several local maxima,
    /// and the weightings often start in different ones).
    #[arg(long, default_value = WeightingChoice::default().name(), value_parser = WeightingChoice::NAMES)]
    pub weighting: String,
    /// Linear EM: also estimate the output offset h (by default h is held at the
    /// start's value: for `--init n4sid`, the record's mean output less the
    /// steady-state response to its mean input).
    #[arg(long)]
    pub offset: bool,
    /// Linear EM: also estimate the initial state's mean mu and covariance P1 of this
    /// record. By default they are held at the start's values during EM (N4SID: mu = 0,
    /// P1 = the second moment of its state sequence), and the model written describes a
    /// new record's initial state instead ("initial": "stationary" for a stable fitted
    /// A, "diffuse" otherwise), so that it can be run on another record of the same
    /// process.
    #[arg(long)]
    pub estimate_initial: bool,
    /// Linear EM: the training record's initial state: `model` (the start's: N4SID's,
    /// or the `--init` file's), `stationary` (the stationary law of the start's state
    /// noise) or `diffuse` (exact diffuse: EM maximises Durbin and Koopman's diffuse
    /// likelihood, as statsmodels does for unit-root models). Whatever the choice, the
    /// model written describes a new record's initial state as `stationary` when its A
    /// is stable and `diffuse` otherwise (unless mu or P1 were estimated or fixed).
    #[arg(long, default_value = LinearFitOptions::default().initial.name(), value_parser = InitialState::NAMES)]
    pub initial: String,
    /// Linear EM: `squarem` (the default) accelerates EM by squared extrapolation
    /// (Varadhan and Roland 2008; monotone like EM, three E-steps per cycle, often tens
    /// of times fewer E-steps to the optimum); `none` runs plain EM.
    #[arg(long, default_value = LinearFitOptions::default().acceleration.name(), value_parser = Acceleration::NAMES)]
    pub accelerate: String,
    /// After EM, maximise the likelihood directly. Linear EM: the exact log-likelihood
    /// of the model as written (its initial state included) by damped Fisher scoring
    /// that never walks the directions the data cannot see (a black-box model's change
    /// of basis): `auto` (the default) for at most 400 free coordinates, `on`, `off`. The robust particle driver (`fit nlbench`, `fit affine`): a
    /// 10 000-particle log-likelihood on common random numbers by Nelder-Mead from
    /// its estimate, which undoes the small-particle E-step's bias of the noise
    /// variances (`auto` and `on`), or not (`off`).
    #[arg(long, default_value = LinearFitOptions::default().polish.name(), value_parser = Switch::NAMES)]
    pub polish: String,
    /// Linear EM: standard errors of the free parameters from the observed information
    /// (the negative Hessian of the exact log-likelihood in the model's entries, by
    /// central differences; a covariance by its upper triangle), with 95 % confidence
    /// intervals: `auto` (the default) for at most 20 free parameters, `on`, `off`.
    /// Black-box models (free A and C) are not identifiable and get none.
    #[arg(long, default_value = LinearFitOptions::default().std_errors.name(), value_parser = Switch::NAMES)]
    pub std_errors: String,
    /// Linear EM: `mean` removes each signal's mean before the fit and folds the means
    /// into the written model's offset h (and mu), so that it describes, predicts and
    /// simulates the original signals; `linear` removes a straight line in time (the
    /// time column, or the row number) from each signal and stores the lines in the
    /// model: predict, compare, simulate, forecast, resid, loglik, filter and smooth
    /// remove them from a record at its times and return outputs in the original units
    /// (states are those of the detrended signals); `none` (the default) fits the
    /// signals as they are.
    #[arg(long, default_value = LinearFitOptions::default().detrend.map_or(TrendKind::NAMES[0], TrendKind::name), value_parser = TrendKind::NAMES)]
    pub detrend: String,
    /// Linear EM: fit on the first FRACTION of the rows (after --range) and report the
    /// fitted model's simulation and one-step prediction fits on the rest (as `sysid
    /// compare` computes them).
    #[arg(long)]
    pub split: Option<f64>,
    /// Linear EM with `--order FROM..TO`: the criterion that chooses the order written,
    /// `bic` (the default), `aic`, or `validation` (the best simulation fit on the rows
    /// held out by --split).
    #[arg(long, default_value = Selection::default().name(), value_parser = Selection::NAMES)]
    pub select: String,
    /// Maximum number of EM iterations (particle EM runs exactly this many; with
    /// `--accelerate squarem`, a budget of E-steps, three per cycle).
    #[arg(long, visible_alias = "iters", default_value_t = LinearFitOptions::default().max_iterations)]
    pub max_iter: usize,
    /// Linear EM: stop when the estimated distance to the maximum of the
    /// log-likelihood (Aitken's extrapolation of the last three values) is below this
    /// many nats. A run that ends at --max-iter instead says so, with the estimate.
    #[arg(long, value_name = "NATS", default_value_t = LinearFitOptions::default().tol_nats)]
    pub tol_nats: f64,
    /// Stop when the relative log-likelihood change of an iteration is below this
    /// (default: 1e-6, except for linear EM, which uses --tol-nats unless this is
    /// given).
    #[arg(long)]
    pub tol: Option<f64>,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// Options of `sysid fit nlbench`.
#[derive(clap::Args, Debug, Clone)]
pub struct NlbenchArgs {
    #[command(flatten)]
    pub data: DataArgs,
    /// Starting values `a,b,c,d` or `a,b,c,d,q,r` (default: the nominal values
    /// 0.5,25,8,0.05,0.01,0.1); for `fit affine` without --system, a linear model file.
    #[arg(long, default_value = "n4sid", hide_default_value = true)]
    pub init: String,
    /// Maximum number of EM iterations (particle EM runs exactly this many; with
    /// `--accelerate squarem`, a budget of E-steps, three per cycle).
    #[arg(long, visible_alias = "iters", default_value_t = AffineFitOptions::default().iterations)]
    pub max_iter: usize,
    /// Particle EM: seed of the random streams (same seed, same result, any machine).
    #[arg(long, default_value_t = sysid::smc::DEFAULT_SEED)]
    pub seed: u64,
    /// Particle fits: which noise covariances are estimated: `--estimate-noise` (or
    /// `=both`) both, `=q` the process noise only, `=r` the output noise only, `=none`
    /// neither (held at --init's values). Default: both for `--method robust` (which
    /// explores with both estimated anyway and holds a noise the user keeps only in its
    /// refinement), none for `em` and `psaem`. At a small process noise (nlbench's
    /// q = 0.01), estimating q is what lets the particle kernel move the trajectory.
    #[arg(
        long,
        value_name = "WHICH",
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "both",
        value_parser = ["q", "r", "both", "none"]
    )]
    pub estimate_noise: Option<String>,
    #[command(flatten)]
    pub em: ParticleEmArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// Options of `sysid fit affine`.
#[derive(clap::Args, Debug, Clone)]
pub struct AffineArgs {
    /// `fit affine`: the affine system (`nlbench`); without it `--init` names a linear
    /// model file.
    #[arg(long)]
    pub system: Option<String>,
    #[command(flatten)]
    pub nlbench: NlbenchArgs,
}

/// Options of `sysid fit wiener`.
#[derive(clap::Args, Debug, Clone)]
pub struct WienerArgs {
    #[command(flatten)]
    pub data: DataArgs,
    /// Maximum number of EM iterations (particle EM runs exactly this many; with
    /// `--accelerate squarem`, a budget of E-steps, three per cycle).
    #[arg(long, visible_alias = "iters", default_value_t = WienerFitOptions::default().iterations)]
    pub max_iter: usize,
    /// Particle EM: particles M of the filter (and paths of `ffbsi-reject`).
    #[arg(long, default_value_t = WienerFitOptions::default().particles)]
    pub particles: usize,
    /// Particle EM: seed of the random streams (same seed, same result, any machine).
    #[arg(long, default_value_t = sysid::smc::DEFAULT_SEED)]
    pub seed: u64,
    #[command(flatten)]
    pub output: OutputArgs,
}
