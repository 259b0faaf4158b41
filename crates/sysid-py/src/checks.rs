//! Checking a fitted linear model on a record: `compare`, `predict`, `forecast` and
//! `resid`, as the commands of the same names compute them (a stored linear trend
//! removed from the record and restored to the outputs, the model's initial state).

use crate::data::{channels, record};
use crate::errors::Failure;
use crate::linear::prepare;
use nalgebra::DMatrix;
use numpy::{PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sysid::kalman::{ForecastIntervals, Horizon, KalmanError, fit_percent};

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(predict, m)?)?;
    m.add_function(wrap_pyfunction!(forecast, m)?)?;
    m.add_function(wrap_pyfunction!(resid, m)?)?;
    Ok(())
}

/// A `k x T` matrix as a `(T, k)` array.
fn by_time<'py>(py: Python<'py>, m: &DMatrix<f64>) -> Bound<'py, PyArray2<f64>> {
    let t = m.transpose();
    // `t` is column-major `T x k`: its transpose's storage is the row-major array
    let rows: Vec<Vec<f64>> = (0..t.nrows())
        .map(|i| t.row(i).iter().copied().collect())
        .collect();
    PyArray2::from_vec2(py, &rows).unwrap_or_else(|_| PyArray2::zeros(py, [t.nrows(), 0], false))
}

/// A library error of a check, an option named as the Python keyword.
fn failure(e: KalmanError) -> Failure {
    match e {
        KalmanError::BadOption { name, message } => Failure::option(name, message),
        other => Failure::sysid(other),
    }
}

/// `sysid compare`: the simulated (`horizon="inf"`) or k-step predicted outputs in the
/// record's units and the fit per output (MATLAB's `compare`).
#[pyfunction]
#[pyo3(signature = (model, y, u=None, time=None, horizon="inf", burn_in=0, initial="model"))]
#[allow(clippy::too_many_arguments)]
fn compare<'py>(
    py: Python<'py>,
    model: &str,
    y: PyReadonlyArray2<'_, f64>,
    u: Option<PyReadonlyArray2<'_, f64>>,
    time: Option<Vec<f64>>,
    horizon: &str,
    burn_in: usize,
    initial: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let horizon: Horizon = horizon.parse().map_err(failure)?;
    let p = prepare(model, record(&y, u.as_ref())?, time, initial)?;
    let trend = p.trend.as_ref().map(|t| t.outputs_at(&p.time));
    let comparison = py
        .detach(|| p.model.compare(&p.record, horizon, burn_in, trend.as_ref()))
        .map_err(failure)?;
    let out = PyDict::new(py);
    out.set_item("outputs", by_time(py, &comparison.outputs))?;
    out.set_item("fit_percent", comparison.fit_percent.clone())?;
    out.set_item("fit_percent_mean", comparison.mean_fit_percent())?;
    Ok(out)
}

/// `sysid predict`: k-step predictions, their sd, the errors and the standardised
/// errors, the fit per output and the rms of the standardised errors.
#[pyfunction]
#[pyo3(signature = (model, y, u=None, time=None, horizon=1, initial="model"))]
fn predict<'py>(
    py: Python<'py>,
    model: &str,
    y: PyReadonlyArray2<'_, f64>,
    u: Option<PyReadonlyArray2<'_, f64>>,
    time: Option<Vec<f64>>,
    horizon: usize,
    initial: &str,
) -> PyResult<Bound<'py, PyDict>> {
    if horizon == 0 {
        return Err(Failure::option("horizon", "must be at least 1").into());
    }
    let p = prepare(model, record(&y, u.as_ref())?, time, initial)?;
    let mut pred = py
        .detach(|| p.model.predict(&p.record, horizon))
        .map_err(failure)?;
    let mut measured = p.record.y.clone();
    if let Some(trend) = &p.trend {
        let line = trend.outputs_at(&p.time);
        pred.mean += &line;
        measured += &line;
    }
    let warnings: Vec<String> = pred.warnings().iter().map(ToString::to_string).collect();
    let out = PyDict::new(py);
    out.set_item("mean", by_time(py, &pred.mean))?;
    out.set_item("sd", by_time(py, &pred.sd))?;
    out.set_item("errors", by_time(py, &pred.errors))?;
    out.set_item("standardised", by_time(py, &pred.standardised))?;
    out.set_item("loglik", pred.loglik)?;
    out.set_item("fit_percent", fit_percent(&measured, &pred.mean, 0))?;
    out.set_item("standardised_rms", pred.standardised_rms())?;
    out.set_item("warnings", warnings)?;
    Ok(out)
}

/// `sysid forecast`: the outputs `steps` past the record's end with intervals of
/// probability `level`, given the future inputs `(steps, m)`.
#[pyfunction]
#[pyo3(signature = (model, y, u=None, time=None, future_u=None, steps=10, level=0.95,
    initial="model"))]
#[allow(clippy::too_many_arguments)]
fn forecast<'py>(
    py: Python<'py>,
    model: &str,
    y: PyReadonlyArray2<'_, f64>,
    u: Option<PyReadonlyArray2<'_, f64>>,
    time: Option<Vec<f64>>,
    future_u: Option<PyReadonlyArray2<'_, f64>>,
    steps: usize,
    level: f64,
    initial: &str,
) -> PyResult<Bound<'py, PyDict>> {
    if steps == 0 {
        return Err(Failure::option("steps", "must be at least 1").into());
    }
    ForecastIntervals::half_width(level).map_err(failure)?;
    let p = prepare(model, record(&y, u.as_ref())?, time, initial)?;
    let m = p.model.m();
    let future = match (future_u, m) {
        (_, 0) => DMatrix::zeros(0, steps),
        (None, m) => {
            return Err(Failure::option(
                "future_u",
                format!("the model has {m} input(s): give their values over the {steps} steps"),
            )
            .into());
        }
        (Some(f), m) => {
            let f = channels(&f);
            if f.nrows() != m || f.ncols() < steps {
                return Err(Failure::option(
                    "future_u",
                    format!(
                        "expected {steps} rows of {m} inputs, got {} rows of {}",
                        f.ncols(),
                        f.nrows()
                    ),
                )
                .into());
            }
            f.columns(0, steps).clone_owned()
        }
    };
    // the times after the record's last, at its mean spacing
    let last = p.time.last().copied().unwrap_or(0.0);
    let spacing = match p.time.len() {
        0 | 1 => 1.0,
        n => (last - p.time[0]) / (n - 1) as f64,
    };
    let future_times: Vec<f64> = (1..=steps).map(|j| last + spacing * j as f64).collect();
    let future = match &p.trend {
        Some(trend) if m > 0 => future - trend.inputs_at(&future_times),
        _ => future,
    };
    let mut forecast = py
        .detach(|| p.model.forecast(&p.record, &future, steps))
        .map_err(failure)?;
    if let Some(trend) = &p.trend {
        forecast.mean += trend.outputs_at(&future_times);
    }
    let intervals = forecast.intervals(level).map_err(failure)?;
    let out = PyDict::new(py);
    out.set_item("time", future_times)?;
    out.set_item("mean", by_time(py, &forecast.mean))?;
    out.set_item("sd", by_time(py, &forecast.sd))?;
    out.set_item("lower", by_time(py, &intervals.lower))?;
    out.set_item("upper", by_time(py, &intervals.upper))?;
    out.set_item("z", intervals.z)?;
    Ok(out)
}

/// `sysid resid`: whiteness (autocorrelations, Ljung-Box) of the one-step prediction
/// errors and their independence of the inputs (cross-correlations), with warnings.
#[pyfunction]
#[pyo3(signature = (model, y, u, time, lags, initial, outputs, inputs))]
#[allow(clippy::too_many_arguments)]
fn resid<'py>(
    py: Python<'py>,
    model: &str,
    y: PyReadonlyArray2<'_, f64>,
    u: Option<PyReadonlyArray2<'_, f64>>,
    time: Option<Vec<f64>>,
    lags: usize,
    initial: &str,
    outputs: Vec<String>,
    inputs: Vec<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let p = prepare(model, record(&y, u.as_ref())?, time, initial)?;
    let tests = py
        .detach(|| p.model.residual_tests(&p.record, lags))
        .map_err(|e| match e {
            KalmanError::TooManyLags {
                lags,
                usable,
                output,
            } => Failure::option(
                "lags",
                format!(
                    "{lags} must be at least 1 and below the {usable} usable residuals of {}",
                    outputs.get(output - 1).map_or("an output", String::as_str)
                ),
            ),
            other => failure(other),
        })?;
    let rows = PyList::empty(py);
    for t in &tests.outputs {
        let d = PyDict::new(py);
        d.set_item("output", outputs.get(t.output).cloned())?;
        d.set_item("samples", t.samples)?;
        d.set_item("ljung_box_statistic", t.ljung_box.statistic)?;
        d.set_item("ljung_box_p_value", t.ljung_box.p_value)?;
        d.set_item("ljung_box_df", t.ljung_box.df)?;
        d.set_item("acf", t.acf.clone())?;
        d.set_item("ccf", t.ccf.clone())?;
        d.set_item("bound_95", t.bound_95())?;
        d.set_item("acf_beyond_bound", t.acf_beyond_bound())?;
        d.set_item("ccf_beyond_bound", t.ccf_beyond_bound())?;
        rows.append(d)?;
    }
    let warnings: Vec<String> = tests
        .warnings()
        .iter()
        .map(|w| w.message(&outputs, &inputs))
        .collect();
    let out = PyDict::new(py);
    out.set_item("outputs", rows)?;
    out.set_item("lags", tests.lags)?;
    out.set_item("warnings", warnings)?;
    Ok(out)
}
