//! `sysid pf` and `sysid psmooth`: the particle filter and the particle smoothers on a
//! nonlinear model file (`--model m.toml`), a built-in system (`--system nlbench`,
//! `lgss`, `pendulum`) or a linear Gaussian model file (JSON, through the SMC adapter,
//! for comparison with `smooth`).

use crate::DataArgs;
use crate::error::CliError;
use crate::files::{DataFile, create_output, fmt, read_model};
use std::io::Write;
use std::path::PathBuf;
use sysid::modelfile::ExprSmc;
use sysid::models::{LinearGaussianSmc, Nlbench, lgss};
use sysid::smc::{
    FilterModel, FilterOptions, ParticleFilter, PathSmoother, Resampling, Series, SmcError,
    Smoother, TransitionBound,
};

/// The model and the filter settings shared by `pf` and `psmooth`.
#[derive(clap::Args, Debug)]
pub struct ParticleArgs {
    /// Built-in system: nlbench, lgss or pendulum (or give --model).
    #[arg(long, conflicts_with = "model", required_unless_present = "model")]
    pub system: Option<String>,
    /// Model file: a nonlinear model (`.toml`, docs/model-format.md) or a linear
    /// Gaussian one (JSON; needs S = 0 and positive definite Q and R).
    #[arg(long)]
    pub model: Option<PathBuf>,
    #[command(flatten)]
    pub data: DataArgs,
    /// Number of particles M.
    #[arg(long, default_value_t = 1000)]
    pub particles: usize,
    /// Resampling scheme: multinomial, stratified, systematic or residual.
    #[arg(long, default_value = "systematic")]
    pub resample: String,
    /// Resample when ESS < ess * M; 1 resamples at every step.
    #[arg(long, default_value_t = 1.0)]
    pub ess: f64,
    /// Seed of the random streams.
    #[arg(long, default_value_t = sysid::smc::DEFAULT_SEED)]
    pub seed: u64,
    /// Independent repeats of the filter for the Monte Carlo sd of the log-likelihood
    /// estimate (a warning above 1.5 nats). 0, the default, takes the sd from the
    /// run's own genealogy instead (one filter's cost; 10-17 % low in the measured
    /// cases, and blind to rare losses of the state, which repeats can see).
    #[arg(long, default_value_t = 0)]
    pub repeats: usize,
    /// Output CSV file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
    /// Print a machine-readable summary.
    #[arg(long)]
    pub json: bool,
}

/// Options of `sysid psmooth`.
#[derive(clap::Args, Debug)]
pub struct SmoothArgs {
    #[command(flatten)]
    pub common: ParticleArgs,
    /// Smoother: tanizaki, ffbsi, ffbsi-reject or genealogy.
    #[arg(long, default_value = "ffbsi-reject")]
    pub method: String,
    /// Number of smoothed paths K [default: 100]. Tanizaki's smoother draws exactly M
    /// (one per particle); giving another K with it is an error.
    #[arg(long)]
    pub paths: Option<usize>,
}

/// The number of paths of `method` with `particles` particles: `--paths` (default 100),
/// except for Tanizaki's smoother, which draws one path per particle.
fn paths_of(method: &str, paths: Option<usize>, particles: usize) -> Result<usize, CliError> {
    match (method, paths) {
        ("tanizaki", Some(k)) if k != particles => Err(CliError::BadOption {
            option: "--paths",
            message: format!(
                "tanizaki draws one path per particle ({particles}), not {k}: \
                 drop --paths, or use --method ffbsi or ffbsi-reject for another number"
            ),
        }),
        ("tanizaki", _) => Ok(particles),
        (_, k) => Ok(k.unwrap_or(100)),
    }
}

/// An invalid filter option, blamed on the command-line flag that set it.
fn option_error(source: SmcError) -> CliError {
    if let SmcError::InvalidOption { name, reason } = &source {
        let flag = match *name {
            "particles" => Some("--particles"),
            "ess_threshold" => Some("--ess"),
            "resampling" => Some("--resample"),
            "method" => Some("--method"),
            _ => None,
        };
        if let Some(option) = flag {
            return CliError::BadOption {
                option,
                message: reason.clone(),
            };
        }
    }
    smc_error("options")(source)
}

fn smc_error(context: &str) -> impl Fn(SmcError) -> CliError + '_ {
    move |source| CliError::Smc {
        context: context.to_string(),
        source,
    }
}

/// The most repeats `--repeats` takes: the sd of 1001 runs is known to 2 %.
const MAX_REPEATS: usize = 1000;

fn filter_options(a: &ParticleArgs, store_history: bool) -> Result<FilterOptions, CliError> {
    if a.repeats > MAX_REPEATS {
        return Err(CliError::BadOption {
            option: "--repeats",
            message: format!(
                "{} repeats asked; at most {MAX_REPEATS} (the sd of {} runs is known to 2 %)",
                a.repeats,
                MAX_REPEATS + 1
            ),
        });
    }
    let resampling = Resampling::from_name(&a.resample).ok_or_else(|| CliError::BadOption {
        option: "--resample",
        message: format!(
            "unknown scheme {:?} (known: {})",
            a.resample,
            Resampling::ALL.map(Resampling::name).join(", ")
        ),
    })?;
    let options = FilterOptions {
        particles: a.particles,
        resampling,
        ess_threshold: a.ess,
        store_history,
        parallel: crate::threads() > 1,
        share_busy_processors: false,
        record_summaries: true,
        // the single-run estimate of the log-likelihood's sd (sysid_smc's variance.rs)
        variance_block: Some(sysid::smc::VARIANCE_SPAN),
    };
    options.check().map_err(option_error)?;
    Ok(options)
}

/// What the command runs on.
enum ChosenModel {
    Nlbench(Nlbench),
    Linear(Box<LinearGaussianSmc>),
    File(Box<ExprSmc>),
}

/// The data columns a model reads: by count (the defaults u1.., y1..) or by the names
/// of a model file (when the data have them).
enum Columns<'a> {
    Counts { outputs: usize, inputs: usize },
    Names(&'a ExprSmc),
}

fn choose_model(a: &ParticleArgs) -> Result<ChosenModel, CliError> {
    let adapt = |model: &sysid::kalman::LinearGaussianModel, context: String| {
        LinearGaussianSmc::new(model).map_err(|e| CliError::BadOption {
            option: "--model",
            message: format!("{context}: {e}"),
        })
    };
    match (&a.system, &a.model) {
        (Some(name), _) => {
            use super::systems::{System, Use, lookup};
            match lookup(name, Use::Particle)? {
                System::Nlbench => Ok(ChosenModel::Nlbench(Nlbench::truth())),
                System::Lgss => Ok(ChosenModel::Linear(Box::new(adapt(
                    &lgss(),
                    "lgss".into(),
                )?))),
                _ => file_model(super::nonlinear::system(name)?),
            }
        }
        (None, Some(path)) if super::nonlinear::is_model_file(path) => {
            file_model(super::nonlinear::read(path)?)
        }
        (None, Some(path)) => {
            let model = read_model(path)?;
            Ok(ChosenModel::Linear(Box::new(adapt(
                &model,
                path.display().to_string(),
            )?)))
        }
        (None, None) => Err(CliError::BadOption {
            option: "--system",
            message: "give --system or --model".into(),
        }),
    }
}

/// The model file at its parameters' values.
fn file_model(file: sysid::modelfile::ModelFile) -> Result<ChosenModel, CliError> {
    let smc = file
        .at(&file.free_values())
        .map_err(|message| CliError::BadOption {
            option: "--model",
            message: format!("{}: {message}", file.origin()),
        })?;
    Ok(ChosenModel::File(Box::new(smc)))
}

/// The states' names: a model file's, else `x1, x2, ...` (as `simulate` names them).
fn state_names(columns: &Columns, n: usize) -> Vec<String> {
    match columns {
        Columns::Names(model) if model.spec().states.len() == n => model.spec().states.clone(),
        _ => (1..=n).map(|i| format!("x{i}")).collect(),
    }
}

fn read_series(a: &ParticleArgs, columns: Columns) -> Result<DataFile, CliError> {
    match columns {
        Columns::Counts { outputs, inputs } => {
            let file = a.data.read()?;
            super::check_column_counts(&file, inputs, outputs)?;
            Ok(file)
        }
        Columns::Names(model) => a
            .data
            .read_for_names(&model.spec().inputs, &model.spec().outputs),
    }
}

/// Writes `t, x1.., [x1_sd..]` rows.
fn write_states(
    a: &ParticleArgs,
    time: &[f64],
    names: &[String],
    means: &[f64],
    sds: Option<&[f64]>,
) -> Result<(), CliError> {
    let n = names.len();
    let Some(out) = &a.out else { return Ok(()) };
    let mut w = create_output(out, a.force)?;
    let io = |source| CliError::Io {
        path: out.clone(),
        source,
    };
    let mut header = vec!["t".to_string()];
    header.extend(names.iter().cloned());
    if sds.is_some() {
        header.extend(names.iter().map(|name| format!("{name}_sd")));
    }
    writeln!(w, "{}", header.join(",")).map_err(io)?;
    for (k, &t) in time.iter().enumerate() {
        let mut row = vec![fmt(t)];
        row.extend(means[k * n..(k + 1) * n].iter().map(|&v| fmt(v)));
        if let Some(sd) = sds {
            row.extend(sd[k * n..(k + 1) * n].iter().map(|&v| fmt(v)));
        }
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.commit()
}

/// `sysid pf`.
pub fn run_filter(a: &ParticleArgs) -> Result<(), CliError> {
    crate::files::check_outputs(a.out.as_deref(), a.force)?;
    match choose_model(a)? {
        ChosenModel::Nlbench(m) => filter_with(
            a,
            &m,
            Columns::Counts {
                outputs: 1,
                inputs: 0,
            },
        ),
        ChosenModel::Linear(m) => {
            let (outputs, inputs) = (m.output_dim(), m.input_dim());
            filter_with(a, m.as_ref(), Columns::Counts { outputs, inputs })
        }
        ChosenModel::File(m) => filter_with(a, m.as_ref(), Columns::Names(m.as_ref())),
    }
}

fn filter_with<M: FilterModel + Sync>(
    a: &ParticleArgs,
    model: &M,
    columns: Columns,
) -> Result<(), CliError> {
    let options = filter_options(a, false)?;
    let names = state_names(&columns, model.state_dim());
    let file = read_series(a, columns)?;
    // particles and their copy, weights, log-weights and ancestors; the filtered
    // means of every step
    let n = model.state_dim() as f64;
    crate::resources::check_memory(
        "--particles",
        &format!("{} particles", a.particles),
        8.0 * (a.particles as f64 * (2.0 * n + 4.0) + file.record.len() as f64 * n),
    )?;
    let context = a.data.data.display().to_string();
    let series = series_of(&file, &context)?;
    let mut pf = ParticleFilter::new(options).map_err(option_error)?;
    let start = std::time::Instant::now();
    // one step per filter run: the run, then its repeats
    let progress = crate::progress::Progress::new(a.repeats as u64 + 1, "pf", a.json);
    let run = pf
        .run(model, &series, a.seed)
        .map_err(smc_error(&context))?;
    progress.inc(1);
    let trust = super::filter_trust::diagnose(
        model,
        &series,
        &pf,
        &run,
        (a.seed, a.repeats),
        &file.time,
        &progress,
    );
    progress.finish();
    let seconds = start.elapsed().as_secs_f64();
    write_states(a, &file.time, &names, pf.means(), None)?;
    if a.json {
        let s = serde_json::json!({
            "command": "pf", "loglik": run.loglik, "resampled_steps": run.resampled_steps,
            "steps": series.steps(), "particles": a.particles, "seed": a.seed,
            "seconds": seconds, "out": a.out, "diagnostics": trust.json(),
            "loglik_sd_single_run": run.loglik_variance.map(f64::sqrt),
            "warnings": trust.warnings,
        });
        crate::say(&s.to_string());
    } else {
        let sd = trust.describe_sd(a.repeats);
        let ess = trust
            .min_ess()
            .map(|(e, t)| format!("; smallest ESS {e:.1} at step {}", t + 1))
            .unwrap_or_default();
        crate::say(&format!(
            "loglik estimate {}{sd} ({} particles, resampled at {} of {} steps{ess})",
            run.loglik,
            a.particles,
            run.resampled_steps,
            series.steps()
        ));
    }
    for w in &trust.warnings {
        crate::warn(w);
    }
    Ok(())
}

pub(crate) fn series_of<'a>(file: &'a DataFile, context: &str) -> Result<Series<'a>, CliError> {
    let y = &file.record.y;
    let u = &file.record.u;
    Series::new(y.as_slice(), y.nrows())
        .and_then(|s| s.with_inputs(u.as_slice(), u.nrows()))
        .map_err(smc_error(context))
}

/// `sysid psmooth`.
pub fn run_smoother(a: &SmoothArgs) -> Result<(), CliError> {
    crate::files::check_outputs(a.common.out.as_deref(), a.common.force)?;
    match choose_model(&a.common)? {
        ChosenModel::Nlbench(m) => smooth_with(
            a,
            &m,
            Columns::Counts {
                outputs: 1,
                inputs: 0,
            },
        ),
        ChosenModel::Linear(m) => {
            let (outputs, inputs) = (m.output_dim(), m.input_dim());
            smooth_with(a, m.as_ref(), Columns::Counts { outputs, inputs })
        }
        ChosenModel::File(m) => smooth_with(a, m.as_ref(), Columns::Names(m.as_ref())),
    }
}

/// The most transition densities a smoother may evaluate (about 20 minutes at 1 ns
/// each; `psmooth --method ffbsi --particles 100000 --paths 100000` asked for 10^13 on
/// 1000 steps and ran for hours without a word).
const MAX_SMOOTHING_WORK: f64 = 1e12;

/// Refuses an O(M K T) or O(M^2 T) smoother too large to finish, before the filter.
fn check_smoothing_work(
    method: &str,
    particles: usize,
    paths: usize,
    steps: usize,
) -> Result<(), CliError> {
    let (m, k, t) = (particles as f64, paths as f64, steps as f64);
    let (work, option) = match method {
        "ffbsi" => (m * k * t, "--paths"),
        "tanizaki" => (m * m * t, "--particles"),
        _ => return Ok(()),
    };
    if work > MAX_SMOOTHING_WORK {
        return Err(CliError::BadOption {
            option,
            message: format!(
                "--method {method} with {particles} particles and {paths} paths over {steps} \
                 steps evaluates about {work:.1e} transition densities (hours); use \
                 --method ffbsi-reject (O(M) per path on average), or fewer particles or paths"
            ),
        });
    }
    Ok(())
}

fn smooth_with<M: FilterModel + TransitionBound + Sync>(
    a: &SmoothArgs,
    model: &M,
    columns: Columns,
) -> Result<(), CliError> {
    let c = &a.common;
    let path_count = paths_of(&a.method, a.paths, c.particles)?;
    let smoother = PathSmoother::from_name(&a.method, path_count, crate::threads() > 1)
        .map_err(option_error)?;
    let options = filter_options(c, true)?;
    let names = state_names(&columns, model.state_dim());
    let file = read_series(c, columns)?;
    // the filter's history (states, weights, ancestors at every step) and the paths
    let (n, steps) = (model.state_dim() as f64, file.record.len() as f64);
    let history = c.particles as f64 * steps * (n + 2.0);
    let trajectories = path_count as f64 * steps * n;
    let option = if trajectories > history {
        "--paths"
    } else {
        "--particles"
    };
    crate::resources::check_memory(
        option,
        &format!(
            "{} particles and {path_count} paths over {} steps",
            c.particles,
            file.record.len()
        ),
        8.0 * (history + trajectories),
    )?;
    check_smoothing_work(&a.method, c.particles, path_count, file.record.len())?;
    let context = c.data.data.display().to_string();
    let series = series_of(&file, &context)?;
    let mut pf = ParticleFilter::new(options).map_err(option_error)?;
    let start = std::time::Instant::now();
    // the filter, the smoother, then the filter's repeats
    let progress = crate::progress::Progress::new(c.repeats as u64 + 2, "psmooth", c.json);
    let run = pf
        .run(model, &series, c.seed)
        .map_err(smc_error(&context))?;
    progress.inc(1);
    let history = pf.history().expect("history stored");
    let (paths, stats) = smoother
        .trajectories(model, history, &series, c.seed.wrapping_add(1))
        .map_err(smc_error(&context))?;
    // the smoothed paths are drawn from the filter's particles: a filter that lost the
    // state smooths the wrong trajectory there
    progress.inc(1);
    let trust = super::filter_trust::diagnose(
        model,
        &series,
        &pf,
        &run,
        (c.seed, c.repeats),
        &file.time,
        &progress,
    );
    progress.finish();
    let seconds = start.elapsed().as_secs_f64();
    let (means, sds) = (paths.means(), paths.std_devs());
    write_states(c, &file.time, &names, &means, Some(&sds))?;
    if c.json {
        let s = serde_json::json!({
            "command": "psmooth", "method": a.method, "loglik": run.loglik,
            "paths": paths.paths(), "particles": c.particles, "steps": series.steps(),
            "density_evaluations": stats.density_evaluations, "trials": stats.trials,
            "fallbacks": stats.fallbacks, "seed": c.seed, "seconds": seconds, "out": c.out,
            "diagnostics": trust.json(), "warnings": trust.warnings,
        });
        crate::say(&s.to_string());
    } else {
        let sd = trust.describe_sd(c.repeats);
        crate::say(&format!(
            "{}: {} paths from {} particles; filter loglik estimate {}{sd}",
            a.method,
            paths.paths(),
            c.particles,
            run.loglik
        ));
    }
    for w in &trust.warnings {
        crate::warn(w);
    }
    Ok(())
}
