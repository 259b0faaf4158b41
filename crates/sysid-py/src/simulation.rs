//! A model file's noise-free simulation and its simulation-error fit, as
//! `sysid simulate --model --noise-free`, `sysid compare --model` and
//! `sysid fit --model --criterion simulation` compute them.

use crate::data::record;
use crate::errors::Failure;
use crate::particle::{CompiledModel, series_of};
use numpy::{PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sysid::modelfile::{InitialState, SimulationFit};

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(simulate_noise_free, m)?)?;
    m.add_function(wrap_pyfunction!(compare_simulation, m)?)?;
    m.add_function(wrap_pyfunction!(predict_particles, m)?)?;
    Ok(())
}

/// Two time-major arrays: `(states, outputs)` of a simulation (`T x n`, `T x p`), or
/// `(mean, sd)` of predictions.
type StatesAndOutputs<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>);

/// A time-major `rows x cols` vector as a 2-D array.
fn matrix<'py>(
    py: Python<'py>,
    values: &[f64],
    cols: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let rows: Vec<Vec<f64>> = values.chunks(cols.max(1)).map(<[f64]>::to_vec).collect();
    if cols == 0 {
        return Ok(PyArray2::zeros(py, [values.len(), 0], false));
    }
    PyArray2::from_vec2(py, &rows).map_err(|e| Failure::sysid(e).into())
}

/// The noise-free simulation of `steps` steps of the inputs `u` (`steps x m`) from
/// `x0` or the file's initial means: `(states, outputs)`.
#[pyfunction]
#[pyo3(signature = (model, u, steps, x0=None))]
fn simulate_noise_free<'py>(
    py: Python<'py>,
    model: &CompiledModel,
    u: PyReadonlyArray2<'_, f64>,
    steps: usize,
    x0: Option<Vec<f64>>,
) -> PyResult<StatesAndOutputs<'py>> {
    let spec = model.file.spec();
    let u = u.as_array();
    if u.ncols() != spec.inputs.len() || (u.ncols() > 0 && u.nrows() != steps) {
        return Err(Failure::data(format!(
            "{} has {} inputs; u has {} columns and {} rows for {steps} steps",
            model.file.origin(),
            spec.inputs.len(),
            u.ncols(),
            u.nrows()
        ))
        .into());
    }
    let inputs: Vec<f64> = u.iter().copied().collect();
    let run = py
        .detach(|| {
            model
                .file
                .simulate_noise_free(&inputs, steps, x0.as_deref())
        })
        .map_err(Failure::sysid)?;
    Ok((
        matrix(py, &run.states, spec.states.len())?,
        matrix(py, &run.outputs, spec.outputs.len())?,
    ))
}

/// `sysid compare --model`: the noise-free simulation of the record from the initial
/// state fitted to its first `initial_samples` samples (all by default) or `x0`.
#[pyfunction]
#[pyo3(signature = (model, y, u=None, initial_samples=None, x0=None, burn_in=0))]
fn compare_simulation<'py>(
    py: Python<'py>,
    model: &CompiledModel,
    y: PyReadonlyArray2<'_, f64>,
    u: Option<PyReadonlyArray2<'_, f64>>,
    initial_samples: Option<usize>,
    x0: Option<Vec<f64>>,
    burn_in: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let data = record(&y, u.as_ref())?;
    model.check(&data)?;
    let series = series_of(&data)?;
    let initial = match (x0, initial_samples) {
        (Some(x0), None) => InitialState::Given(x0),
        (Some(_), Some(_)) => {
            return Err(Failure::option("x0", "give x0 or initial_samples, not both").into());
        }
        (None, Some(0)) => {
            return Err(Failure::option("initial_samples", "at least 1 sample is needed").into());
        }
        (None, samples) => InitialState::Estimate {
            samples: samples.unwrap_or(series.steps()),
        },
    };
    let result = py
        .detach(|| model.file.compare_simulation(series, initial, burn_in))
        .map_err(Failure::sysid)?;
    let out = PyDict::new(py);
    out.set_item("outputs", matrix(py, &result.outputs, series.output_dim())?)?;
    out.set_item("initial_state", result.initial_state)?;
    out.set_item("rms", result.rms)?;
    out.set_item("fit_percent", result.fit_percent)?;
    Ok(out)
}

/// The report of `sysid fit --model --criterion simulation`: the estimate, its
/// runs and the fitted file's text.
pub(crate) fn simulation_report<'py>(
    py: Python<'py>,
    model: &CompiledModel,
    fit: &SimulationFit,
    seed: u64,
    starts: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    out.set_item("names", model.file.free_names())?;
    out.set_item("estimate", fit.estimate.clone())?;
    out.set_item("standard_errors", fit.standard_errors.clone())?;
    out.set_item("initial_state", fit.initial_state.clone())?;
    out.set_item("rms", fit.rms.clone())?;
    out.set_item("fit_percent", fit.fit_percent.clone())?;
    let runs: Vec<(f64, usize, String, bool)> = fit
        .starts
        .iter()
        .map(|s| (s.rms, s.evaluations, s.termination.clone(), s.converged))
        .collect();
    out.set_item("runs", runs)?;
    out.set_item("best", fit.best)?;
    out.set_item("interrupted", fit.interrupted)?;
    let warnings: Vec<String> = fit.warnings.iter().map(ToString::to_string).collect();
    out.set_item("warnings", warnings)?;
    let metadata = vec![
        ("method".to_string(), "\"simulation-error\"".to_string()),
        ("criterion".to_string(), "\"simulation\"".to_string()),
        ("seed".to_string(), seed.to_string()),
        ("starts".to_string(), starts.to_string()),
        ("rms".to_string(), format!("{}", fit.rms[0])),
    ];
    out.set_item("text", fit.fitted.to_toml(&metadata))?;
    Ok(out)
}

/// `sysid predict --model`: the k-step particle predictions, `(mean, sd)` as `T x p`
/// arrays.
#[pyfunction]
#[pyo3(signature = (model, y, u=None, horizon=1, particles=5000, seed=1))]
fn predict_particles<'py>(
    py: Python<'py>,
    model: &CompiledModel,
    y: PyReadonlyArray2<'_, f64>,
    u: Option<PyReadonlyArray2<'_, f64>>,
    horizon: usize,
    particles: usize,
    seed: u64,
) -> PyResult<StatesAndOutputs<'py>> {
    let data = record(&y, u.as_ref())?;
    model.check(&data)?;
    let series = series_of(&data)?;
    let pred = py
        .detach(|| {
            model
                .file
                .predict_particles(series, horizon, particles, seed)
        })
        .map_err(|e| match e {
            sysid::modelfile::PredictionError::InvalidOption { name, reason } => {
                Failure::option(name, reason)
            }
            other => Failure::sysid(other),
        })?;
    let p = series.output_dim();
    Ok((matrix(py, &pred.mean, p)?, matrix(py, &pred.sd, p)?))
}
