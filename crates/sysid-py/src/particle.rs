//! Model files and the particle methods: `particle_filter`, `fit` and `pmmh`, as
//! `sysid pf`, `sysid fit --model` and `sysid pmmh --model` compute them.

use crate::data::{record, times};
use crate::errors::Failure;
use crate::run::{Progress, supervise};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sysid::em::affine::AffineMethod;
use sysid::em::{FitRun, FitSettings};
use sysid::kalman::Record;
use sysid::modelfile::{
    Criterion, ExprSmc, FileFit, FileFitError, FileFitMethod, FileFitReport, ModelFile,
};
use sysid::pmcmc::{Chain, ChainReport, ChainRun, IndependentPrior, PmmhOptions, pmmh};
use sysid::smc::StateSpace as _;
use sysid::smc::{FilterDiagnostics, FilterOptions, ParticleFilter, Resampling, Series};

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<CompiledModel>()?;
    m.add_function(wrap_pyfunction!(particle_filter, m)?)?;
    m.add_function(wrap_pyfunction!(fit_model, m)?)?;
    m.add_function(wrap_pyfunction!(fit_defaults, m)?)?;
    m.add_function(wrap_pyfunction!(pmmh_model, m)?)?;
    m.add_function(wrap_pyfunction!(chain_report, m)?)?;
    Ok(())
}

/// A model file, parsed and checked once (the Python `ModelFile` keeps its text for
/// pickling and this for the computations).
#[pyclass(frozen, module = "sysid._sysid")]
pub(crate) struct CompiledModel {
    pub(crate) file: ModelFile,
}

#[pymethods]
impl CompiledModel {
    /// Parses `text`; `origin` names it in messages (the file's path).
    #[new]
    fn new(text: &str, origin: &str) -> PyResult<Self> {
        let file = ModelFile::parse(text, origin).map_err(|e| Failure::model_file(&e))?;
        Ok(CompiledModel { file })
    }

    /// The free parameters' names.
    fn free_names(&self) -> Vec<String> {
        self.file.free_names()
    }

    /// The free parameters' values in the file.
    fn free_values(&self) -> Vec<f64> {
        self.file.free_values()
    }

    /// Names of the states, inputs and outputs.
    fn names(&self) -> (Vec<String>, Vec<String>, Vec<String>) {
        let spec = self.file.spec();
        (
            spec.states.clone(),
            spec.inputs.clone(),
            spec.outputs.clone(),
        )
    }

    /// Why the closed-form particle EM does not apply (None: it does).
    fn why_not_affine(&self) -> Option<String> {
        self.file.why_not_affine()
    }

    /// The file with `values` as its free parameters' values, as TOML text with
    /// `metadata` lines.
    fn with_values(&self, values: Vec<f64>, metadata: Vec<(String, String)>) -> PyResult<String> {
        if values.len() != self.file.free_names().len() {
            return Err(Failure::data(format!(
                "{} values for the free parameters {}",
                values.len(),
                self.file.free_names().join(", ")
            ))
            .into());
        }
        Ok(self.file.with_values(&values).to_toml(&metadata))
    }
}

impl CompiledModel {
    /// The model at its file's values, for the filter.
    fn smc(&self) -> Result<ExprSmc, Failure> {
        self.file
            .at(&self.file.free_values())
            .map_err(|e| Failure::sysid(format!("{}: {e}", self.file.origin())))
    }

    /// The record's column counts checked against the model's.
    pub(crate) fn check(&self, data: &Record) -> Result<(), Failure> {
        let spec = self.file.spec();
        let (p, m) = (spec.outputs.len(), spec.inputs.len());
        if data.y.nrows() != p || data.u.nrows() != m {
            return Err(Failure::data(format!(
                "{} has {m} inputs ({}) and {p} outputs ({}); the data have {} and {}",
                self.file.origin(),
                spec.inputs.join(", "),
                spec.outputs.join(", "),
                data.u.nrows(),
                data.y.nrows()
            )));
        }
        Ok(())
    }
}

/// The library's series over a record's matrices (time-major, as they are stored).
pub(crate) fn series_of(data: &Record) -> Result<Series<'_>, Failure> {
    Series::new(data.y.as_slice(), data.y.nrows())
        .and_then(|s| s.with_inputs(data.u.as_slice(), data.u.nrows()))
        .map_err(Failure::sysid)
}

/// A time as the command line prints it.
fn label(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if v.is_infinite() || (1e-5..1e16).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// `sysid pf`: the filter's log-likelihood estimate, filtered means and ESS, and the
/// diagnostics: the sd from the run's genealogy, or from `repeats` more runs.
#[pyfunction]
#[pyo3(signature = (model, y, u=None, time=None, particles=1000, seed=1, resample="systematic",
    ess=1.0, repeats=0, progress=None, threads=None))]
#[allow(clippy::too_many_arguments)]
fn particle_filter<'py>(
    py: Python<'py>,
    model: &CompiledModel,
    y: PyReadonlyArray2<'_, f64>,
    u: Option<PyReadonlyArray2<'_, f64>>,
    time: Option<Vec<f64>>,
    particles: usize,
    seed: u64,
    resample: &str,
    ess: f64,
    repeats: usize,
    progress: Option<Bound<'py, PyAny>>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let resampling = Resampling::from_name(resample).ok_or_else(|| {
        Failure::option(
            "resample",
            format!(
                "unknown scheme {resample:?} (known: {})",
                Resampling::ALL.map(Resampling::name).join(", ")
            ),
        )
    })?;
    let data = record(&y, u.as_ref())?;
    model.check(&data)?;
    let time = times(time, data.len())?;
    let smc = model.smc()?;
    let series = series_of(&data)?;
    let progress = Progress::of(progress, "particle_filter")?;
    let run = supervise(py, threads, &progress, repeats as u64 + 1, |control| {
        let began = std::time::Instant::now();
        let options = FilterOptions {
            particles,
            resampling,
            ess_threshold: ess,
            parallel: rayon::current_num_threads() > 1,
            variance_block: Some(sysid::smc::VARIANCE_SPAN),
            ..FilterOptions::default()
        };
        let mut pf = ParticleFilter::new(options).map_err(|e| option_failure(&e))?;
        let summary = pf.run(&smc, &series, seed).map_err(Failure::sysid)?;
        control.tick();
        let checked =
            FilterDiagnostics::diagnose(&smc, &series, &pf, &summary, seed, repeats, || {
                control.tick()
            });
        let seconds = began.elapsed().as_secs_f64();
        Ok::<_, Failure>((
            summary,
            checked,
            pf.means().to_vec(),
            pf.ess().to_vec(),
            seconds,
        ))
    })?;
    let (summary, checked, means, ess, seconds) = run.value?;
    if let Some(e) = run.stopped_by {
        return Err(e);
    }
    let n = smc.state_dim();
    let steps = means.len() / n.max(1);
    let out = PyDict::new(py);
    out.set_item("loglik", summary.loglik)?;
    out.set_item("resampled_steps", summary.resampled_steps)?;
    // the library's own time (for the overhead of the Python call; not part of the
    // result's equality)
    out.set_item("seconds", seconds)?;
    // (the filtered means are time-major already: one copy into a (T, n) array)
    out.set_item(
        "means",
        PyArray1::from_vec(py, means)
            .reshape([steps, n])
            .map_err(Failure::sysid)?,
    )?;
    out.set_item("ess", PyArray1::from_vec(py, ess))?;
    out.set_item("loglik_sd", checked.loglik_sd)?;
    out.set_item(
        "loglik_sd_method",
        checked.loglik_sd_method.map(|m| m.name()),
    )?;
    out.set_item("loglik_sd_single_run", checked.loglik_sd_single_run)?;
    out.set_item("repeat_logliks", checked.repeat_logliks.clone())?;
    out.set_item("min_ess", checked.min_ess.map(|(e, _)| e))?;
    out.set_item("min_ess_step", checked.min_ess.map(|(_, t)| t))?;
    let time_label = |t: usize| {
        time.get(t)
            .map_or_else(|| (t + 1).to_string(), |v| label(*v))
    };
    let warnings: Vec<String> = checked
        .warnings
        .iter()
        .map(|w| w.describe(&time_label))
        .collect();
    out.set_item("warnings", warnings)?;
    Ok(out)
}

/// A filter option out of range, named as the Python keyword.
fn option_failure(e: &sysid::smc::SmcError) -> Failure {
    match e {
        sysid::smc::SmcError::InvalidOption { name, reason } => Failure::option(
            match *name {
                "ess_threshold" => "ess",
                "resampling" => "resample",
                other => other,
            },
            reason.clone(),
        ),
        other => Failure::sysid(other),
    }
}

/// `sysid fit --model`: the estimates, the fitted file's text, and the run's report.
/// A keyword left `None` takes the default of the method that runs; a keyword that
/// method does not read is refused (the library's [`ModelFile::fit_method`]).
#[pyfunction]
#[pyo3(signature = (model, y, u=None, criterion="likelihood", method=None, particles=None,
    smoother=None, max_iter=None, starts=None, polish=None, extrapolate=None, patience=None,
    spread=None, seed=1, progress=None, threads=None))]
#[allow(clippy::too_many_arguments)]
fn fit_model<'py>(
    py: Python<'py>,
    model: &CompiledModel,
    y: PyReadonlyArray2<'_, f64>,
    u: Option<PyReadonlyArray2<'_, f64>>,
    criterion: &str,
    method: Option<&str>,
    particles: Option<usize>,
    smoother: Option<String>,
    max_iter: Option<usize>,
    starts: Option<usize>,
    polish: Option<bool>,
    extrapolate: Option<bool>,
    patience: Option<usize>,
    spread: Option<f64>,
    seed: u64,
    progress: Option<Bound<'py, PyAny>>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let criterion: Criterion = criterion
        .parse()
        .map_err(|m| Failure::option("criterion", m))?;
    let method = method
        .map(str::parse::<AffineMethod>)
        .transpose()
        .map_err(|m| Failure::option("method", m))?;
    let settings = FitSettings {
        method,
        particles,
        smoother,
        max_iter,
        starts,
        polish,
        extrapolate,
        patience,
        spread,
    };
    let chosen = model
        .file
        .fit_method(criterion, &settings)
        .map_err(|e| fit_failure(&e))?;
    let data = record(&y, u.as_ref())?;
    model.check(&data)?;
    let series = series_of(&data)?;
    let progress = Progress::of(progress, "fit")?;
    let steps = match &chosen {
        FileFitMethod::ParticleEm(options) => options.options().iterations,
        FileFitMethod::GradientEm(options) => options.iterations,
        _ => 1,
    };
    let run = supervise(py, threads, &progress, steps as u64, |control| {
        let stop = || control.stopped();
        let fit_run = FitRun::new(seed).stopped_by(&stop);
        model
            .file
            .fit(series, &chosen, &fit_run, &mut &*control)
            .map_err(|e| fit_failure(&e))
    })?;
    let fit = run.value?;
    let out = match (&fit.report, &chosen) {
        (FileFitReport::Simulation(report), FileFitMethod::Simulation(options)) => {
            crate::simulation::simulation_report(py, model, report, seed, options.starts)?
        }
        _ => likelihood_report(py, model, &fit, seed, reported_particles(&chosen))?,
    };
    crate::run::result_or_stop(py, run.stopped_by, out)
}

/// The library's default of every setting of `fit` (what a keyword left `None`
/// becomes, and what `sysid fit --help` shows).
#[pyfunction]
fn fit_defaults(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = sysid::modelfile::fit_defaults();
    let out = PyDict::new(py);
    out.set_item("method", d.method.map(|m| m.name()))?;
    out.set_item("particles", d.particles)?;
    out.set_item("smoother", d.smoother)?;
    out.set_item("max_iter", d.max_iter)?;
    out.set_item("starts", d.starts)?;
    out.set_item("polish", d.polish)?;
    out.set_item("extrapolate", d.extrapolate)?;
    out.set_item("patience", d.patience)?;
    out.set_item("spread", d.spread)?;
    Ok(out)
}

/// The particles a likelihood method's report names (its filter's; the direct
/// search's finishing filter's).
fn reported_particles(method: &FileFitMethod) -> usize {
    match method {
        FileFitMethod::ParticleEm(options) => options.options().particles,
        FileFitMethod::GradientEm(options) => options.particles,
        FileFitMethod::Direct(options) => options.polish_particles,
        FileFitMethod::Simulation(_) => 0,
    }
}

/// A fit's failure, named by the keyword at fault.
fn fit_failure(e: &FileFitError) -> Failure {
    match e {
        FileFitError::Setting(setting) => Failure::setting(setting),
        FileFitError::NotAffine { .. } => Failure::option("method", e.to_string()),
        other => Failure::sysid(other),
    }
}

/// The report of a likelihood fit: the estimates, the log-likelihood, the warnings and
/// the fitted file's text.
fn likelihood_report<'py>(
    py: Python<'py>,
    model: &CompiledModel,
    fit: &FileFit,
    seed: u64,
    particles: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    out.set_item("method", fit.method())?;
    out.set_item("names", model.file.free_names())?;
    out.set_item("estimate", fit.estimate.clone())?;
    out.set_item("loglik", fit.loglik())?;
    out.set_item("interrupted", fit.interrupted())?;
    out.set_item(
        "standard_errors",
        fit.standard_errors().map(<[f64]>::to_vec),
    )?;
    let warnings: Vec<String> = fit.warnings.iter().map(ToString::to_string).collect();
    out.set_item("warnings", warnings)?;
    let metadata = vec![
        ("method".to_string(), format!("{:?}", fit.method())),
        ("seed".to_string(), seed.to_string()),
        ("particles".to_string(), particles.to_string()),
        (
            "loglik_estimate".to_string(),
            fit.loglik().map_or("nan".into(), |l| format!("{l}")),
        ),
    ];
    out.set_item("text", fit.fitted.to_toml(&metadata))?;
    Ok(out)
}

/// `sysid pmmh --model`: the chains (JSON, as `--out` writes them) of chains
/// `first .. first + chains`.
#[pyfunction]
#[pyo3(signature = (model, y, u=None, chains=4, first=0, iterations=10000, burn_in=None,
    particles=100, seed=1, proposal_sd=None, adapt=true, progress=None, threads=None))]
#[allow(clippy::too_many_arguments)]
fn pmmh_model<'py>(
    py: Python<'py>,
    model: &CompiledModel,
    y: PyReadonlyArray2<'_, f64>,
    u: Option<PyReadonlyArray2<'_, f64>>,
    chains: usize,
    first: usize,
    iterations: usize,
    burn_in: Option<usize>,
    particles: usize,
    seed: u64,
    proposal_sd: Option<Vec<f64>>,
    adapt: bool,
    progress: Option<Bound<'py, PyAny>>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    if chains == 0 {
        return Err(Failure::option("chains", "must be at least 1").into());
    }
    let burn_in = burn_in.unwrap_or(iterations / 5);
    if burn_in >= iterations {
        return Err(Failure::option(
            "burn_in",
            format!("{burn_in} leaves no draws out of {iterations} iterations"),
        )
        .into());
    }
    let file = &model.file;
    let names = file.free_names();
    let priors = names
        .iter()
        .zip(file.priors())
        .map(|(name, prior)| {
            prior.ok_or_else(|| {
                Failure::option(
                    "model",
                    format!(
                        "{}: the free parameter {name} has no prior: add `prior = {{ family = \
                         \"normal\", mean = 0.0, sd = 10.0 }}` (or another family, \
                         docs/model-format.md) to its entry",
                        file.origin()
                    ),
                )
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let prior = IndependentPrior::new(&names, priors).map_err(Failure::sysid)?;
    let data = record(&y, u.as_ref())?;
    model.check(&data)?;
    let series = series_of(&data)?;
    let options = PmmhOptions {
        iterations,
        burn_in,
        particles,
        resampling: Resampling::Systematic,
        proposal_sd: proposal_sd.unwrap_or_default(),
        adapt,
    };
    let start = file.free_values();
    let progress = Progress::of(progress, "pmmh")?;
    let total = (chains * iterations) as u64;
    let run = supervise(py, threads, &progress, total, |control| {
        let chain_run = ChainRun::new(chains, seed)
            .starting_at(first)
            .observed_by(control);
        pmmh(file, &prior, &series, &start, &options, &chain_run).map_err(Failure::sysid)
    })?;
    let drawn = run.value?;
    let out = PyDict::new(py);
    out.set_item(
        "chains",
        serde_json::to_string(&drawn).map_err(Failure::sysid)?,
    )?;
    out.set_item("first", first)?;
    out.set_item("seed", seed)?;
    crate::run::result_or_stop(py, run.stopped_by, out)
}

/// The library's report of chains (JSON as `pmmh` returns them): the summary rows,
/// acceptance rates, warnings and iterations made, as `sysid pmmh --json` prints them.
#[pyfunction]
fn chain_report<'py>(py: Python<'py>, chains: &str) -> PyResult<Bound<'py, PyDict>> {
    let chains: Vec<Chain> = serde_json::from_str(chains).map_err(Failure::sysid)?;
    let report = ChainReport::of(&chains);
    let out = PyDict::new(py);
    out.set_item(
        "summary",
        serde_json::to_string(&report.summary).map_err(Failure::sysid)?,
    )?;
    out.set_item("acceptance", report.acceptance.clone())?;
    let warnings: Vec<String> = report.warnings.iter().map(ToString::to_string).collect();
    out.set_item("warnings", warnings)?;
    out.set_item("iterations", report.iterations)?;
    Ok(out)
}
