//! Linear Gaussian models: `loglik`, `n4sid` and `fit_lti`, as `sysid loglik`,
//! `sysid n4sid` and `sysid fit lti` compute them.

use crate::data::{record, times};
use crate::errors::Failure;
use crate::run::{Progress, supervise};
use numpy::PyReadonlyArray2;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sysid::em::SettingError;
use sysid::em::linear::{
    Fix, FixValue, LinearFit, LinearFitError, LinearFitOptions, Matrix, OrderChoice, Selection,
    Signals, Start,
};
use sysid::kalman::{
    InitialState, KalmanWorkspace, LinearGaussianModel, Metadata, ModelSpec, Record, Trend,
    TrendKind,
};
use sysid::subspace::{
    Criterion, Focus, N4sidOptions, Order, WeightedN4sid, Weighting, WeightingChoice,
    n4sid_weighted,
};

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(loglik, m)?)?;
    m.add_function(wrap_pyfunction!(n4sid_fit, m)?)?;
    m.add_function(wrap_pyfunction!(fit_lti, m)?)?;
    m.add_function(wrap_pyfunction!(fit_lti_defaults, m)?)?;
    crate::checks::register(m)
}

/// A model file's text (`sysid fit lti --out`'s JSON) as the library's spec.
pub(crate) fn spec_of(text: &str) -> Result<ModelSpec, Failure> {
    serde_json::from_str(text)
        .map_err(|e| Failure::data(format!("not a linear model file (JSON): {e}")))
}

/// A stored model ready for a record, as every command of the command line prepares
/// one: built, its stored linear trend removed from the record at its times, its
/// initial state (`initial`: `model` = the file's own) applied to the record.
pub(crate) struct Prepared {
    pub model: LinearGaussianModel,
    pub trend: Option<Trend>,
    pub record: Record,
    pub time: Vec<f64>,
}

pub(crate) fn prepare(
    text: &str,
    mut record: Record,
    time: Option<Vec<f64>>,
    initial: &str,
) -> Result<Prepared, Failure> {
    let spec = spec_of(text)?;
    let model = spec.build().map_err(Failure::sysid)?;
    if record.y.nrows() != model.p() && record.y.nrows() != 0 {
        return Err(Failure::data(format!(
            "the model has {} outputs and the data {}",
            model.p(),
            record.y.nrows()
        )));
    }
    if record.u.nrows() != model.m() {
        return Err(Failure::data(format!(
            "the model has {} inputs and the data {}",
            model.m(),
            record.u.nrows()
        )));
    }
    let time = times(time, record.len())?;
    let trend = Trend::stored(
        spec.metadata.as_ref().and_then(|m| m.detrend.as_ref()),
        model.m(),
        model.p(),
    )
    .map_err(|e| Failure::sysid(format!("model metadata: {e}")))?;
    if let Some(trend) = &trend {
        trend
            .check_time_base(&time)
            .map_err(|e| Failure::data(e.to_string()))?;
        trend.remove_from(&mut record, &time);
    }
    let initial = match initial_state(initial)? {
        InitialState::Given => spec.initial,
        chosen => chosen,
    };
    let model = initial
        .apply_to_record(&model, &record)
        .map_err(Failure::sysid)?;
    Ok(Prepared {
        model,
        trend,
        record,
        time,
    })
}

/// `initial=`: `model`, `stationary` or `diffuse` (the library's names).
fn initial_state(text: &str) -> Result<InitialState, Failure> {
    text.parse().map_err(|m| Failure::option("initial", m))
}

/// `sysid loglik`: the exact log-likelihood of a stored model on a record.
#[pyfunction]
#[pyo3(signature = (model, y, u=None, time=None, initial="model"))]
fn loglik(
    py: Python<'_>,
    model: &str,
    y: PyReadonlyArray2<'_, f64>,
    u: Option<PyReadonlyArray2<'_, f64>>,
    time: Option<Vec<f64>>,
    initial: &str,
) -> PyResult<f64> {
    let data = record(&y, u.as_ref())?;
    let prepared = prepare(model, data, time, initial)?;
    let run = supervise(py, None, &Progress::None, 1, |_| {
        KalmanWorkspace::new()
            .loglik(&prepared.model, &prepared.record)
            .map_err(Failure::sysid)
    })?;
    Ok(run.value?)
}

/// One weighting of `weighting="auto"`: name, order, spectral radius, stable, one-step
/// prediction fit.
type WeightingRow = (String, Option<usize>, Option<f64>, bool, Option<f64>);

/// `sysid n4sid`: the subspace model (JSON), and what the command reports.
#[pyfunction]
#[pyo3(name = "n4sid", signature = (y, u=None, order=None, block_rows=None, weighting="auto",
    focus="prediction", criterion="bic", stable=false, detrend=None, time=None))]
#[allow(clippy::too_many_arguments)]
fn n4sid_fit<'py>(
    py: Python<'py>,
    y: PyReadonlyArray2<'_, f64>,
    u: Option<PyReadonlyArray2<'_, f64>>,
    order: Option<usize>,
    block_rows: Option<usize>,
    weighting: &str,
    focus: &str,
    criterion: &str,
    stable: bool,
    detrend: Option<&str>,
    time: Option<Vec<f64>>,
) -> PyResult<Bound<'py, PyDict>> {
    let choice: WeightingChoice = parsed("weighting", weighting)?;
    let options = N4sidOptions {
        order: order.map_or(Order::Auto, Order::Fixed),
        block_rows,
        weighting: match choice {
            WeightingChoice::Fixed(w) => w,
            WeightingChoice::Auto => Weighting::Moesp,
        },
        focus: match focus {
            "prediction" => Focus::Prediction,
            "simulation" => Focus::Simulation,
            other => {
                return Err(Failure::option(
                    "focus",
                    format!("unknown focus {other:?} (known: prediction, simulation)"),
                )
                .into());
            }
        },
        stable,
        criterion: match criterion {
            "bic" => Criterion::Bic,
            "aic" => Criterion::Aic,
            other => {
                return Err(Failure::option(
                    "criterion",
                    format!("unknown criterion {other:?} (known: bic, aic)"),
                )
                .into());
            }
        },
    };
    let mut data = record(&y, u.as_ref())?;
    let time = times(time, data.len())?;
    let trend = match trend_kind(detrend)? {
        None => None,
        Some(kind) => {
            let trend = Trend::estimate(&data, &time, kind).map_err(Failure::sysid)?;
            trend.remove_from(&mut data, &time);
            Some(trend)
        }
    };
    let run = supervise(py, None, &Progress::None, 1, |_| {
        n4sid_weighted(&data, &options, choice)
    })?;
    let WeightedN4sid { result, candidates } = run.value.map_err(Failure::sysid)?;
    let described = match &trend {
        Some(t) => t.written_model(&result.model).map_err(Failure::sysid)?,
        None => result.model.clone(),
    };
    let mut spec = ModelSpec::from_model(&described);
    let chosen = result.order_scores.iter().find(|s| s.order == result.order);
    spec.metadata = Some(Metadata {
        order: Some(result.order),
        loglik: chosen.map(|s| s.loglik),
        parameters: chosen.map(|s| s.parameters),
        detrend: trend.as_ref().map(Trend::describe),
        command: Some("sysid.n4sid (Python)".into()),
        ..Metadata::default()
    });
    let warnings: Vec<String> = result
        .warnings(&options)
        .iter()
        .map(ToString::to_string)
        .collect();
    let out = PyDict::new(py);
    out.set_item("model", spec.to_json())?;
    out.set_item("order", result.order)?;
    out.set_item("block_rows", result.block_rows)?;
    out.set_item("singular_values", result.singular_values.clone())?;
    out.set_item("spectral_radius", result.spectral_radius)?;
    out.set_item("stabilised", result.stabilised)?;
    out.set_item("weighting", result.weighting.name())?;
    let weightings: Vec<WeightingRow> = candidates
        .iter()
        .map(|c| {
            (
                c.weighting.name().to_string(),
                c.order,
                c.spectral_radius,
                c.usable(),
                c.prediction_fit,
            )
        })
        .collect();
    out.set_item("weightings", weightings)?;
    out.set_item("warnings", warnings)?;
    Ok(out)
}

/// `detrend=`: `None`/`"none"`, `"mean"` or `"linear"`.
fn trend_kind(text: Option<&str>) -> Result<Option<TrendKind>, Failure> {
    TrendKind::choice(text.unwrap_or("none")).map_err(|m| Failure::option("detrend", m))
}

/// A keyword's value in the library's spelling (`FromStr` of its option type).
fn parsed<T: std::str::FromStr<Err = String>>(keyword: &str, text: &str) -> Result<T, Failure> {
    text.parse().map_err(|m| Failure::option(keyword, m))
}

/// One `fix=` entry, as the Python half normalises it: a matrix name and no value
/// (held at the start's), a number (broadcast) or rows.
#[derive(FromPyObject)]
enum FixGiven {
    Start(String),
    Number(String, f64),
    Rows(String, Vec<Vec<f64>>),
}

fn fix_of(given: FixGiven) -> Result<Fix, Failure> {
    let matrix = |name: &str| parsed::<Matrix>("fix", name);
    Ok(match given {
        FixGiven::Start(name) => Fix::at_start(matrix(&name)?),
        FixGiven::Number(name, v) => Fix::at(matrix(&name)?, FixValue::Scalar(v)),
        FixGiven::Rows(name, rows) => Fix::at(matrix(&name)?, FixValue::Rows(rows)),
    })
}

/// The options of `fit_lti`, read from the keyword dictionary the Python half passes
/// (every key present, at the command line's defaults unless the user gave one).
fn fit_options(o: &Bound<'_, PyDict>) -> PyResult<LinearFitOptions> {
    fn get<'py, T: FromPyObjectOwned<'py>>(o: &Bound<'py, PyDict>, key: &str) -> PyResult<T> {
        match o.get_item(key)? {
            Some(v) => v.extract::<T>().map_err(|e| {
                let e: PyErr = e.into();
                Failure::option(key, e.to_string()).into()
            }),
            None => Err(Failure::option(key, "missing (a bug of the Python half)").into()),
        }
    }
    let mut options = LinearFitOptions::default();
    let select = parsed::<Selection>("select", &get::<String>(o, "select")?)?;
    options.order = match (
        get::<Option<usize>>(o, "order")?,
        get::<Option<(usize, usize)>>(o, "order_range")?,
    ) {
        (_, Some((from, to))) => OrderChoice::Range { from, to, select },
        (Some(n), None) => OrderChoice::Fixed(n),
        (None, None) => OrderChoice::OfStart,
    };
    options.start = match get::<Option<String>>(o, "init")? {
        None => Start::N4sid {
            stable: get(o, "stable")?,
            weighting: parsed("weighting", &get::<String>(o, "weighting")?)?,
        },
        Some(text) => {
            // the subspace start's settings do not apply to a start model (a value
            // other than the default is refused; the default changes nothing)
            let weighting: WeightingChoice = parsed("weighting", &get::<String>(o, "weighting")?)?;
            for (setting, set) in [
                ("weighting", weighting != WeightingChoice::default()),
                ("stable", get::<bool>(o, "stable")?),
            ] {
                if set {
                    let e = SettingError::not_applicable(setting, LinearFitOptions::MODEL_START);
                    return Err(Failure::setting(&e).into());
                }
            }
            Start::of_file(&spec_of(&text)?).map_err(Failure::sysid)?
        }
    };
    if select != Selection::default() && !matches!(options.order, OrderChoice::Range { .. }) {
        let e = SettingError::not_applicable("select", LinearFitOptions::ONE_ORDER);
        return Err(Failure::setting(&e).into());
    }
    options.fixes = get::<Vec<FixGiven>>(o, "fix")?
        .into_iter()
        .map(fix_of)
        .collect::<Result<_, _>>()?;
    options.diagonal = get::<Vec<String>>(o, "diag")?
        .iter()
        .map(|name| Matrix::diagonal_from_name(name).map_err(|m| Failure::option("diag", m)))
        .collect::<Result<_, _>>()?;
    options.full_r = get(o, "full_r")?;
    options.min_variance = get(o, "min_variance")?;
    options.min_output_noise = get(o, "min_output_noise")?;
    options.offset = get(o, "offset")?;
    options.estimate_initial = get(o, "estimate_initial")?;
    options.initial = initial_state(&get::<String>(o, "initial")?)?;
    options.acceleration = parsed("accelerate", &get::<String>(o, "accelerate")?)?;
    options.polish = parsed("polish", &get::<String>(o, "polish")?)?;
    options.std_errors = parsed("std_errors", &get::<String>(o, "std_errors")?)?;
    options.detrend = trend_kind(get::<Option<String>>(o, "detrend")?.as_deref())?;
    options.split = get(o, "split")?;
    options.max_iterations = get(o, "max_iter")?;
    options.tol = get(o, "tol")?;
    options.tol_nats = get(o, "tol_nats")?;
    Ok(options)
}

/// The library's default of each keyword of `fit_lti` ([`LinearFitOptions::default`]),
/// in the keywords' spelling: the values its signature must show.
#[pyfunction]
fn fit_lti_defaults(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = LinearFitOptions::default();
    let out = PyDict::new(py);
    let Start::N4sid { stable, weighting } = d.start else {
        return Err(Failure::sysid("the default start is N4SID").into());
    };
    out.set_item("init", "n4sid")?;
    out.set_item("stable", stable)?;
    out.set_item("weighting", weighting.name())?;
    out.set_item("full_r", d.full_r)?;
    out.set_item("min_variance", d.min_variance)?;
    out.set_item("min_output_noise", d.min_output_noise)?;
    out.set_item("offset", d.offset)?;
    out.set_item("estimate_initial", d.estimate_initial)?;
    out.set_item("initial", d.initial.name())?;
    out.set_item("accelerate", d.acceleration.name())?;
    out.set_item("polish", d.polish.name())?;
    out.set_item("std_errors", d.std_errors.name())?;
    out.set_item("detrend", d.detrend.map(TrendKind::name))?;
    out.set_item("split", d.split)?;
    out.set_item("select", Selection::default().name())?;
    out.set_item("max_iter", d.max_iterations)?;
    out.set_item("tol", d.tol)?;
    out.set_item("tol_nats", d.tol_nats)?;
    Ok(out)
}

/// A library error of `fit_lti` as the Python exception, named by the keyword.
fn fit_failure(e: LinearFitError) -> Failure {
    match e {
        LinearFitError::InvalidOption { option, message } => Failure::option(option, message),
        other => Failure::sysid(other),
    }
}

/// `sysid fit lti`: the fitted model (JSON, as `--out` writes it but for the data
/// file's entries) and the summary `--json` prints.
#[pyfunction]
#[pyo3(signature = (y, u, time, input_names, output_names, options, progress=None, threads=None))]
#[allow(clippy::too_many_arguments)]
fn fit_lti<'py>(
    py: Python<'py>,
    y: PyReadonlyArray2<'_, f64>,
    u: Option<PyReadonlyArray2<'_, f64>>,
    time: Option<Vec<f64>>,
    input_names: Option<Vec<String>>,
    output_names: Option<Vec<String>>,
    options: &Bound<'py, PyDict>,
    progress: Option<Bound<'py, PyAny>>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let options = fit_options(options)?;
    let max_iterations = options.max_iterations as u64;
    let options = options.check().map_err(fit_failure)?;
    let data = record(&y, u.as_ref())?;
    let steps = data.len();
    let mut signals = Signals::new(data)
        .with_time(times(time, steps)?)
        .map_err(fit_failure)?;
    if let (Some(inputs), Some(outputs)) = (input_names, output_names) {
        signals = signals.with_names(inputs, outputs).map_err(fit_failure)?;
    }
    let progress = Progress::of(progress, "fit_lti")?;
    let run = supervise(py, threads, &progress, max_iterations, |control| {
        let began = std::time::Instant::now();
        let fit = LinearFit::run(&signals, &options, &mut &*control);
        (fit, began.elapsed().as_secs_f64())
    })?;
    let (fit, seconds) = run.value;
    let fit = fit.map_err(fit_failure)?;
    let mut spec = fit.model_spec();
    spec.metadata = Some(Metadata {
        inputs: signals.input_names.clone(),
        outputs: signals.output_names.clone(),
        command: Some("sysid.fit_lti (Python)".into()),
        ..fit.metadata()
    });
    let out = PyDict::new(py);
    out.set_item("model", spec.to_json())?;
    out.set_item("loglik", fit.loglik)?;
    out.set_item("aic", fit.criteria.aic)?;
    out.set_item("bic", fit.criteria.bic)?;
    out.set_item("nobs", fit.criteria.observed)?;
    out.set_item("df_model", fit.criteria.parameters)?;
    out.set_item("iterations", fit.iterations)?;
    out.set_item("e_steps", fit.e_steps)?;
    out.set_item("termination", fit.status.name())?;
    out.set_item("trace", fit.trace.clone())?;
    // the library call's own time (for the overhead of the Python call)
    out.set_item("seconds", seconds)?;
    let warnings: Vec<String> = fit.warnings.iter().map(ToString::to_string).collect();
    out.set_item("warnings", warnings)?;
    if let Some(u) = &fit.uncertainty {
        let rows = PyList::empty(py);
        for p in &u.parameters {
            rows.append((p.name.clone(), p.value, p.std_error))?;
        }
        out.set_item("parameters", rows)?;
        let n = u.covariance.nrows();
        let cov: Vec<Vec<f64>> = (0..n)
            .map(|i| (0..n).map(|j| u.covariance[(i, j)]).collect())
            .collect();
        out.set_item("covariance", cov)?;
    }
    if let Some(v) = &fit.validation {
        let d = PyDict::new(py);
        d.set_item("rows", v.rows)?;
        d.set_item("simulation_fit_percent", v.simulation_fit_percent)?;
        d.set_item("prediction_fit_percent", v.prediction_fit_percent)?;
        out.set_item("validation", d)?;
    }
    if let Some(table) = &fit.order_table {
        let rows = PyList::empty(py);
        for r in &table.rows {
            rows.append((
                r.order,
                r.loglik,
                r.parameters,
                r.aic(),
                r.bic(),
                r.validation,
            ))?;
        }
        out.set_item("order_table", rows)?;
        out.set_item("order_chosen", table.chosen)?;
    }
    if let Some(f) = &fit.failure {
        out.set_item(
            "failure",
            format!(
                "EM failed at iteration {}: {}; the estimate is the last good model; {}",
                f.iteration, f.error, f.diagnosis
            ),
        )?;
    }
    crate::run::result_or_stop(py, run.stopped_by, out)
}
