//! Studies run by parts: one run of the nlbench particle-EM study by its index (the
//! `sysid-bench nlbench-em` runner's per-run code), and the merge of run lines into
//! the study's output, so that any engine (Dask, joblib, Ray, a job array) can spread
//! the runs and get the sharded study's lines.

use crate::errors::Failure;
use crate::run::{Progress, supervise};
use pyo3::prelude::*;
use sysid_bench::nlbench_em::{args_from, merged, run_line};

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(nlbench_em_run, m)?)?;
    m.add_function(wrap_pyfunction!(nlbench_em_merge, m)?)?;
    Ok(())
}

/// Run `run` of the study the runner's `flags` describe: its JSON line.
#[pyfunction]
#[pyo3(signature = (flags, run, threads=None))]
fn nlbench_em_run(
    py: Python<'_>,
    flags: Vec<String>,
    run: usize,
    threads: Option<usize>,
) -> PyResult<String> {
    let args = args_from(&flags).map_err(|m| Failure::option("settings", m))?;
    let done = supervise(py, threads, &Progress::None, 1, |_| run_line(&args, run))?;
    if let Some(e) = done.stopped_by {
        return Err(e);
    }
    let line = done.value.map_err(Failure::sysid)?;
    Ok(line.to_string())
}

/// The run lines among `lines` (JSON), each run once in run order, then the summary.
#[pyfunction]
fn nlbench_em_merge(lines: Vec<String>, label: &str) -> PyResult<Vec<String>> {
    let values = lines
        .iter()
        .map(|l| serde_json::from_str(l))
        .collect::<Result<Vec<serde_json::Value>, _>>()
        .map_err(|e| Failure::data(format!("not a JSON line: {e}")))?;
    let out = merged(values, label).map_err(Failure::data)?;
    Ok(out.iter().map(ToString::to_string).collect())
}
