//! `sysid pmmh` and `sysid pgas`: Bayesian identification of the free parameters of a
//! nonlinear model file (`--model m.toml`, priors from the file), or of a canonical
//! system's (`lgss`: phi, q, r; `nlbench`: a, b, c, d [, q, r]; other built-in names are
//! model files) from a data file.
//!
//! Default priors (override any of them with `--prior FILE`, a JSON object from
//! parameter name to a prior such as `{"q": {"family": "inverse_gamma", "shape": 2,
//! "scale": 1}}`):
//! - lgss: phi ~ N(0, 1), q ~ IG(2, 1), r ~ IG(2, 0.5) (conjugate, so `pgas` can use the
//!   exact Gibbs step);
//! - nlbench: a, d ~ N(0, 10^2), b, c ~ N(0, 100^2), q ~ IG(1, 0.01), r ~ IG(1, 0.1).

use super::particle::series_of;
use crate::DataArgs;
use crate::error::CliError;
use crate::files::{create_output, fmt, json_error};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;
use sysid::models::{LgssConjugate, LgssFamily, NlbenchConjugate, NlbenchFamily};
use sysid::pmcmc::{
    Chain, ChainReport, ChainRun, CsmcKernel, GibbsOptions, IndependentPrior,
    MetropolisWithinGibbs, ModelFamily, PmcmcError, PmmhOptions, ScalarPrior, particle_gibbs,
    particle_gibbs_guided, pmmh,
};
use sysid::smc::Resampling;

/// Options shared by `pmmh` and `pgas`.
#[derive(clap::Args, Debug)]
pub struct ChainArgs {
    /// Canonical system: lgss (phi, q, r), nlbench (a, b, c, d; with
    /// --estimate-noise also q, r), or another built-in model file (pendulum).
    #[arg(long, required_unless_present = "model", conflicts_with = "model")]
    pub system: Option<String>,
    /// A nonlinear model file (`.toml`): its free parameters are sampled, from their
    /// values in the file (a file written by `sysid fit` starts at the estimate), under
    /// the priors the file gives (`--prior` overrides them).
    #[arg(long)]
    pub model: Option<PathBuf>,
    #[command(flatten)]
    pub data: DataArgs,
    /// Iterations per chain, burn-in included.
    #[arg(long, visible_alias = "iters", default_value_t = 10_000)]
    pub iterations: usize,
    /// Leading iterations left out of the summary (default: a fifth of --iters).
    #[arg(long)]
    pub burn_in: Option<usize>,
    /// Number of chains (run in parallel; the result does not depend on --threads).
    #[arg(long, default_value_t = 4)]
    pub chains: usize,
    /// Particles M (default: 100 for pmmh, 10 for pgas).
    #[arg(long)]
    pub particles: Option<usize>,
    /// Prior file (JSON: parameter name -> prior); unlisted parameters keep the
    /// default prior.
    #[arg(long)]
    pub prior: Option<PathBuf>,
    /// Starting parameters, comma separated, in the system's order (default: the
    /// canonical system's values, lgss starts at 0.5, 1, 1; a model file's values).
    #[arg(long, value_delimiter = ',')]
    pub start: Option<Vec<f64>>,
    /// nlbench: also sample the noise variances q and r.
    #[arg(long)]
    pub estimate_noise: bool,
    /// Seed: chain c uses the random stream (seed, c).
    #[arg(long, default_value_t = sysid::smc::DEFAULT_SEED)]
    pub seed: u64,
    /// Write every draw: CSV (chain, iteration, burn_in, parameters, loglik, log_prior,
    /// accepted), or JSON (one object per chain) when the name ends in `.json`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
    /// Print the summary as one JSON line.
    #[arg(long)]
    pub json: bool,
}

impl ChainArgs {
    /// The system's name, or the model file's path.
    fn label(&self) -> String {
        match (&self.system, &self.model) {
            (Some(name), _) => name.clone(),
            (None, Some(path)) => path.display().to_string(),
            (None, None) => String::new(),
        }
    }

    /// The model file the chains run on: `--model`, or a built-in name other than the
    /// tuned lgss and nlbench families.
    fn model_file(&self) -> Result<Option<sysid::modelfile::ModelFile>, CliError> {
        match (&self.system, &self.model) {
            (_, Some(path)) => Ok(Some(super::nonlinear::read(path)?)),
            (Some(name), None) => {
                use super::systems::{System, Use, lookup};
                match lookup(name, Use::Particle)? {
                    // the hand-tuned families
                    System::Lgss | System::Nlbench => Ok(None),
                    _ => Ok(Some(super::nonlinear::system(name)?)),
                }
            }
            (None, None) => Err(bad("--model", "give --model FILE.toml or --system NAME")),
        }
    }
}

/// Options of `sysid pmmh`.
#[derive(clap::Args, Debug)]
pub struct PmmhArgs {
    #[command(flatten)]
    pub common: ChainArgs,
    /// Random-walk standard deviations on the unconstrained scale (log for
    /// variances), comma separated; default 0.1 each.
    #[arg(long, value_delimiter = ',')]
    pub proposal_sd: Option<Vec<f64>>,
    /// Keep the initial proposal (no adaptation during burn-in).
    #[arg(long)]
    pub no_adapt: bool,
}

/// Options of `sysid pgas`.
#[derive(clap::Args, Debug)]
pub struct PgasArgs {
    #[command(flatten)]
    pub common: ChainArgs,
    /// Conditional SMC kernel: as (ancestor sampling), bs (backward simulation) or
    /// plain.
    #[arg(long, default_value = "as")]
    pub kernel: String,
    /// Parameter step: conjugate (the exact draw given the states: lgss, nlbench, and a
    /// model file affine in its parameters, with normal priors on the coefficients and
    /// inverse-gamma ones on the noise variances) or mh (random-walk
    /// Metropolis-within-Gibbs). Default: conjugate where it applies, else mh.
    #[arg(long)]
    pub step: Option<String>,
    /// Metropolis-within-Gibbs: proposal standard deviations (unconstrained scale).
    #[arg(long, value_delimiter = ',')]
    pub proposal_sd: Option<Vec<f64>>,
    /// Propose the states with the locally optimal proposal (lgss only): renews the
    /// whole trajectory even where the data jump, with few particles.
    #[arg(long)]
    pub guided: bool,
}

/// A particle Gibbs sampler: `particle_gibbs` or `particle_gibbs_guided`.
type GibbsRunner<F, S> = fn(
    &F,
    &IndependentPrior,
    &S,
    &sysid::smc::Series,
    &[f64],
    &GibbsOptions,
    &ChainRun<'_>,
) -> Result<Vec<Chain>, PmcmcError>;

/// The sampler for lgss: guided on request.
fn lgss_runner<S: sysid::pmcmc::ParameterStep<LgssFamily>>(
    guided: bool,
) -> GibbsRunner<LgssFamily, S> {
    if guided {
        particle_gibbs_guided::<LgssFamily, IndependentPrior, S>
    } else {
        particle_gibbs::<LgssFamily, IndependentPrior, S>
    }
}

fn bad(option: &'static str, message: impl Into<String>) -> CliError {
    CliError::BadOption {
        option,
        message: message.into(),
    }
}

fn pmcmc_error(context: &str) -> impl Fn(PmcmcError) -> CliError + '_ {
    move |source| CliError::Pmcmc {
        context: context.to_string(),
        source,
    }
}

fn default_priors(system: &str) -> Vec<(&'static str, ScalarPrior)> {
    let normal = |sd: f64| ScalarPrior::Normal { mean: 0.0, sd };
    let ig = |shape: f64, scale: f64| ScalarPrior::InverseGamma { shape, scale };
    match system {
        "lgss" => ["phi", "q", "r"]
            .into_iter()
            .zip(LgssFamily::DEFAULT_PRIORS)
            .collect(),
        _ => vec![
            ("a", normal(10.0)),
            ("b", normal(100.0)),
            ("c", normal(100.0)),
            ("d", normal(10.0)),
            ("q", ig(1.0, 0.01)),
            ("r", ig(1.0, 0.1)),
        ],
    }
}

/// The priors of a built-in family's `names`: its defaults, replaced by the entries of
/// the prior file.
fn priors(a: &ChainArgs, names: &[String]) -> Result<IndependentPrior, CliError> {
    let defaults = default_priors(a.system.as_deref().unwrap_or_default());
    let chosen: Vec<Option<ScalarPrior>> = names
        .iter()
        .map(|n| defaults.iter().find(|(d, _)| d == n).map(|d| d.1))
        .collect();
    priors_over(a, names, chosen)
}

/// The priors of `names`: `defaults` (`None`: none given), replaced by the entries of
/// the prior file; every parameter needs one.
fn priors_over(
    a: &ChainArgs,
    names: &[String],
    defaults: Vec<Option<ScalarPrior>>,
) -> Result<IndependentPrior, CliError> {
    let mut chosen = defaults;
    if let Some(path) = &a.prior {
        let text = std::fs::read_to_string(path).map_err(|source| CliError::Input {
            path: path.clone(),
            source,
        })?;
        let file: BTreeMap<String, ScalarPrior> =
            serde_json::from_str(&text).map_err(|e| json_error(path, "prior", &e))?;
        for (name, prior) in file {
            let k = names.iter().position(|n| *n == name).ok_or_else(|| {
                bad(
                    "--prior",
                    format!(
                        "{}: unknown parameter {name:?} (the {} parameters are {})",
                        path.display(),
                        a.label(),
                        names.join(", ")
                    ),
                )
            })?;
            chosen[k] = Some(prior);
        }
    }
    let chosen = names
        .iter()
        .zip(chosen)
        .map(|(name, prior)| {
            prior.ok_or_else(|| {
                bad(
                    "--prior",
                    format!(
                        "{}: the free parameter {name} has no prior: add `prior = {{ family = \
                         \"normal\", mean = 0.0, sd = 10.0 }}` (or another family, \
                         docs/model-format.md) to its entry, or give it in a --prior file",
                        a.label()
                    ),
                )
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    IndependentPrior::new(names, chosen).map_err(pmcmc_error(
        &a.prior
            .as_ref()
            .map_or("default prior".into(), |p| p.display().to_string()),
    ))
}

/// The priors of a model file's free parameters: the file's own, replaced by the
/// entries of `--prior`.
fn file_priors(
    a: &ChainArgs,
    file: &sysid::modelfile::ModelFile,
) -> Result<IndependentPrior, CliError> {
    priors_over(a, &file.free_names(), file.priors())
}

/// The most chains a run takes.
const MAX_CHAINS: usize = 1024;

fn check_common(a: &ChainArgs) -> Result<usize, CliError> {
    // refuse before a long run, not after it
    crate::files::check_outputs(a.out.as_deref(), a.force)?;
    if a.chains == 0 {
        return Err(bad("--chains", "must be at least 1"));
    }
    // (a million chains ran for hours without a word)
    if a.chains > MAX_CHAINS {
        return Err(bad(
            "--chains",
            format!(
                "{} chains: at most {MAX_CHAINS} (R-hat and the ESS need 4; more draws come \
                 from --iters, or from runs with other seeds)",
                a.chains
            ),
        ));
    }
    // every chain keeps its draws (at least one parameter and the log-posterior)
    crate::resources::check_memory(
        "--iters",
        &format!("{} chains x {} iterations", a.chains, a.iterations),
        8.0 * 2.0 * a.chains as f64 * a.iterations as f64,
    )?;
    let burn_in = a.burn_in.unwrap_or(a.iterations / 5);
    if burn_in >= a.iterations {
        return Err(bad(
            "--burn-in",
            format!(
                "{burn_in} leaves no draws out of {} iterations",
                a.iterations
            ),
        ));
    }
    Ok(burn_in)
}

fn start_of<F: ModelFamily>(
    a: &ChainArgs,
    family: &F,
    default: Vec<f64>,
) -> Result<Vec<f64>, CliError> {
    let start = a.start.clone().unwrap_or(default);
    if start.len() != family.dim() {
        return Err(bad(
            "--start",
            format!(
                "{} values given, {} has {} parameters ({})",
                start.len(),
                a.label(),
                family.dim(),
                family.parameter_names().join(", ")
            ),
        ));
    }
    Ok(start)
}

/// What both samplers need before they run: the burn-in, the start and the data.
struct Prepared {
    burn_in: usize,
    start: Vec<f64>,
    file: crate::files::DataFile,
    context: String,
}

fn prepare<F: ModelFamily>(
    a: &ChainArgs,
    family: &F,
    default_start: Vec<f64>,
) -> Result<Prepared, CliError> {
    let burn_in = check_common(a)?;
    let start = start_of(a, family, default_start)?;
    let file = match a.model_file()? {
        Some(model) => a
            .data
            .read_for_names(&model.spec().inputs, &model.spec().outputs)?,
        None => {
            let file = a.data.read()?;
            super::check_column_counts(&file, 0, 1)?;
            file
        }
    };
    Ok(Prepared {
        burn_in,
        start,
        file,
        context: a.data.data.display().to_string(),
    })
}

/// `sysid pmmh`.
pub fn run_pmmh(a: &PmmhArgs) -> Result<(), CliError> {
    let c = &a.common;
    if let Some(file) = c.model_file()? {
        if c.estimate_noise {
            return Err(bad(
                "--estimate-noise",
                "a model file says which parameters are sampled (fixed = true holds one)",
            ));
        }
        let start = file.free_values();
        let prior = file_priors(c, &file)?;
        return pmmh_with(a, &file, start, &prior);
    }
    match c.system.as_deref().unwrap_or_default() {
        "lgss" => {
            let family = LgssFamily::default();
            let prior = priors(c, &family.parameter_names())?;
            pmmh_with(a, &family, vec![0.5, 1.0, 1.0], &prior)
        }
        "nlbench" => {
            let family = NlbenchFamily {
                estimate_noise: c.estimate_noise,
                ..NlbenchFamily::default()
            };
            let prior = priors(c, &family.parameter_names())?;
            pmmh_with(a, &family, family.truth(), &prior)
        }
        other => Err(CliError::UnknownSystem {
            name: other.into(),
            known: "lgss, nlbench".into(),
        }),
    }
}

fn pmmh_with<F: ModelFamily>(
    a: &PmmhArgs,
    family: &F,
    default_start: Vec<f64>,
    prior: &IndependentPrior,
) -> Result<(), CliError> {
    let c = &a.common;
    let particles = c.particles.unwrap_or(100);
    sample_and_report(
        c,
        family,
        default_start,
        "pmmh",
        particles,
        |series, start, burn_in, observer| {
            let options = PmmhOptions {
                iterations: c.iterations,
                burn_in,
                particles,
                resampling: Resampling::Systematic,
                proposal_sd: a.proposal_sd.clone().unwrap_or_default(),
                adapt: !a.no_adapt,
            };
            pmmh(
                family,
                prior,
                series,
                start,
                &options,
                &ChainRun::new(c.chains, c.seed).observed_by(observer),
            )
        },
    )
}

/// `sysid pgas`.
pub fn run_pgas(a: &PgasArgs) -> Result<(), CliError> {
    let c = &a.common;
    let kernel = CsmcKernel::from_name(&a.kernel).ok_or_else(|| {
        bad(
            "--kernel",
            format!("unknown kernel {:?} (known: as, bs, plain)", a.kernel),
        )
    })?;
    if let Some(file) = c.model_file()? {
        if c.estimate_noise || a.guided {
            return Err(bad(
                if a.guided {
                    "--guided"
                } else {
                    "--estimate-noise"
                },
                "not for a model file (its fixed = true says which parameters are sampled; \
                 it has no locally optimal proposal)",
            ));
        }
        let prior = file_priors(c, &file)?;
        let start = file.free_values();
        // the exact draw when the file is affine in its parameters with conjugate
        // priors (the default), else the random-walk step
        let conjugate = sysid::modelfile::AffineConjugate::new(&file, prior.priors());
        match (a.step.as_deref(), conjugate) {
            (None | Some("conjugate"), Ok(conjugate)) => {
                let run = particle_gibbs::<sysid::modelfile::ModelFile, IndependentPrior, _>;
                return pgas_with(a, &file, &prior, &conjugate, kernel, start, run);
            }
            (Some("conjugate"), Err(why)) => {
                return Err(bad("--step", format!("{why} (or use --step mh)")));
            }
            (None, Err(why)) => {
                crate::progress::note(&format!(
                    "pgas: the random-walk parameter step (no conjugate draw: {why})"
                ));
            }
            (Some("mh"), _) => {}
            (Some(other), _) => {
                return Err(bad(
                    "--step",
                    format!("unknown step {other:?} (known: conjugate, mh)"),
                ));
            }
        }
        let step = mh_step(a, &prior, file.dim())?;
        let run = particle_gibbs::<sysid::modelfile::ModelFile, IndependentPrior, _>;
        return pgas_with(a, &file, &prior, &step, kernel, start, run);
    }
    let system = c.system.clone().unwrap_or_default();
    let step = a.step.clone().unwrap_or_else(|| "conjugate".to_string());
    match (system.as_str(), step.as_str()) {
        ("lgss", "conjugate") => {
            let family = LgssFamily::default();
            let prior = priors(c, &family.parameter_names())?;
            let conjugate = LgssConjugate::from_priors(prior.priors())
                .map_err(|e| bad("--step", format!("{e} (or use --step mh)")))?;
            let run = lgss_runner(a.guided);
            pgas_with(
                a,
                &family,
                &prior,
                &conjugate,
                kernel,
                vec![0.5, 1.0, 1.0],
                run,
            )
        }
        ("lgss", "mh") => {
            let family = LgssFamily::default();
            let prior = priors(c, &family.parameter_names())?;
            let step = mh_step(a, &prior, family.dim())?;
            let run = lgss_runner(a.guided);
            pgas_with(a, &family, &prior, &step, kernel, vec![0.5, 1.0, 1.0], run)
        }
        ("nlbench", step @ ("conjugate" | "mh")) => {
            let family = NlbenchFamily {
                estimate_noise: c.estimate_noise,
                ..NlbenchFamily::default()
            };
            let prior = priors(c, &family.parameter_names())?;
            if a.guided {
                return Err(bad(
                    "--guided",
                    "nlbench has no tractable locally optimal proposal (its output is nonlinear in the state); use the bootstrap kernel",
                ));
            }
            let start = family.truth();
            if step == "conjugate" {
                let conjugate = NlbenchConjugate::from_priors(&family, prior.priors())
                    .map_err(|e| bad("--step", format!("{e} (or use --step mh)")))?;
                let run = particle_gibbs::<NlbenchFamily, IndependentPrior, _>;
                pgas_with(a, &family, &prior, &conjugate, kernel, start, run)
            } else {
                let step = mh_step(a, &prior, family.dim())?;
                let run = particle_gibbs::<NlbenchFamily, IndependentPrior, _>;
                pgas_with(a, &family, &prior, &step, kernel, start, run)
            }
        }
        ("lgss" | "nlbench", other) => Err(bad(
            "--step",
            format!("{other:?} is not available for {system} (known: conjugate, mh)"),
        )),
        (other, _) => Err(CliError::UnknownSystem {
            name: other.into(),
            known: "lgss, nlbench".into(),
        }),
    }
}

fn mh_step(
    a: &PgasArgs,
    prior: &IndependentPrior,
    dim: usize,
) -> Result<MetropolisWithinGibbs<IndependentPrior>, CliError> {
    let sd = a.proposal_sd.clone().unwrap_or_else(|| vec![0.05; dim]);
    if sd.len() != dim || sd.iter().any(|v| !(*v > 0.0 && v.is_finite())) {
        return Err(bad(
            "--proposal-sd",
            format!("needs {dim} positive finite values, got {sd:?}"),
        ));
    }
    Ok(MetropolisWithinGibbs {
        prior: prior.clone(),
        proposal_sd: sd,
        sweeps: 5,
    })
}

fn pgas_with<F, S>(
    a: &PgasArgs,
    family: &F,
    prior: &IndependentPrior,
    step: &S,
    kernel: CsmcKernel,
    default_start: Vec<f64>,
    run: GibbsRunner<F, S>,
) -> Result<(), CliError>
where
    F: ModelFamily,
    S: sysid::pmcmc::ParameterStep<F>,
{
    let c = &a.common;
    let particles = c.particles.unwrap_or(10);
    sample_and_report(
        c,
        family,
        default_start,
        "pgas",
        particles,
        |series, start, burn_in, observer| {
            let options = GibbsOptions {
                iterations: c.iterations,
                burn_in,
                particles,
                kernel,
            };
            run(
                family,
                prior,
                step,
                series,
                start,
                &options,
                &ChainRun::new(c.chains, c.seed).observed_by(observer),
            )
        },
    )
}

/// What both samplers do around the sampling: check the options and the start, read
/// the data, run `sample(series, start, burn_in, progress)`, and report.
fn sample_and_report<F: ModelFamily>(
    c: &ChainArgs,
    family: &F,
    default_start: Vec<f64>,
    command: &str,
    particles: usize,
    sample: impl FnOnce(
        &sysid::smc::Series,
        &[f64],
        usize,
        &dyn sysid::pmcmc::ChainObserver,
    ) -> Result<Vec<Chain>, PmcmcError>,
) -> Result<(), CliError> {
    let Prepared {
        burn_in,
        start,
        file,
        context,
    } = prepare(c, family, default_start)?;
    let series = series_of(&file, &context)?;
    let started = std::time::Instant::now();
    let progress =
        crate::progress::Progress::new((c.chains * c.iterations) as u64, command, c.json);
    crate::progress::interruptible();
    let chains = sample(&series, &start, burn_in, &progress).map_err(pmcmc_error(&context))?;
    progress.finish();
    finish(
        c,
        command,
        particles,
        &chains,
        started.elapsed().as_secs_f64(),
    )?;
    if chains.iter().any(|chain| chain.interrupted) {
        // every chain stopped at Ctrl-C; they were written as far as they went
        let done = chains.iter().map(Chain::iterations).min().unwrap_or(0);
        return Err(CliError::Interrupted {
            iteration: done,
            written: c.out.iter().cloned().collect(),
        });
    }
    Ok(())
}

/// Writes the draws and prints the summary.
fn finish(
    a: &ChainArgs,
    command: &str,
    particles: usize,
    chains: &[Chain],
    seconds: f64,
) -> Result<(), CliError> {
    if let Some(path) = &a.out {
        write_chains(path, a.force, chains)?;
    }
    let ChainReport {
        summary,
        acceptance,
        min_state_update_rate: min_update_rate,
        warnings,
        iterations: made,
    } = ChainReport::of(chains);
    let warnings: Vec<String> = warnings.iter().map(ToString::to_string).collect();
    let interrupted = chains.iter().any(|c| c.interrupted);
    let iterations = (made.max(1) * chains.len()) as f64;
    for w in &warnings {
        crate::warn(w);
    }
    crate::report(
        a.json,
        serde_json::json!({
            "command": command, "system": a.label(), "chains": chains.len(),
            "iterations": a.iterations, "burn_in": chains[0].burn_in, "particles": particles,
            "seed": a.seed, "acceptance": acceptance, "summary": summary,
            "interrupted": interrupted, "iterations_made": made,
            "min_state_update_rate": min_update_rate, "warnings": warnings,
            "seconds": seconds, "ms_per_iteration": 1e3 * seconds * crate::threads().min(chains.len()) as f64 / iterations,
            "out": a.out,
        }),
        || {
            let made = if interrupted {
                format!("{made} of {} iterations (interrupted)", a.iterations)
            } else {
                format!("{made} iterations")
            };
            let mut lines = vec![format!(
                "{command}: {} chains x {made} ({} burn-in, {particles} particles) in {seconds:.2} s; acceptance {}",
                chains.len(),
                chains[0].burn_in,
                if acceptance.is_empty() {
                    "-".to_string()
                } else {
                    acceptance
                        .iter()
                        .map(|v| format!("{v:.3}"))
                        .collect::<Vec<_>>()
                        .join(" ")
                }
            )];
            if summary.is_empty() {
                return lines.join("\n");
            }
            lines.push(format!(
                "{:>6} {:>12} {:>12} {:>10} {:>8} {:>8} {:>7} {:>12} {:>12}",
                "param", "mean", "sd", "mcse", "ess_bulk", "ess_tail", "rhat", "q05", "q95"
            ));
            for s in &summary {
                lines.push(format!(
                    "{:>6} {:>12.6} {:>12.6} {:>10.2e} {:>8.0} {:>8.0} {:>7.3} {:>12.6} {:>12.6}",
                    s.name, s.mean, s.sd, s.mcse, s.ess_bulk, s.ess_tail, s.rhat, s.q05, s.q95
                ));
            }
            if let Some(r) = min_update_rate {
                lines.push(format!("lowest per-step state update rate {r:.3}"));
            }
            lines.join("\n")
        },
    );
    Ok(())
}

fn write_chains(path: &std::path::Path, force: bool, chains: &[Chain]) -> Result<(), CliError> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
    {
        let text = serde_json::to_string(&serde_json::json!({ "chains": chains }))
            .expect("chains serialise");
        return crate::files::write_output(path, force, &(text + "\n"));
    }
    let mut w = create_output(path, force)?;
    let io = |source| CliError::Io {
        path: path.to_path_buf(),
        source,
    };
    let names = &chains[0].names;
    writeln!(
        w,
        "chain,iteration,burn_in,{},loglik,log_prior,accepted",
        names.join(",")
    )
    .map_err(io)?;
    for (k, c) in chains.iter().enumerate() {
        for i in 0..c.iterations() {
            let values: Vec<String> = c.sample(i).iter().map(|&v| fmt(v)).collect();
            writeln!(
                w,
                "{k},{i},{},{},{},{},{}",
                u8::from(i < c.burn_in),
                values.join(","),
                fmt(c.log_likelihood[i]),
                fmt(c.log_prior[i]),
                u8::from(c.accepted[i])
            )
            .map_err(io)?;
        }
    }
    w.commit()
}
