//! The compiled half of the Python package `sysid` (distribution `sysid-rs`).
//!
//! Every function here reads numpy arrays and plain options, calls the library as the
//! command line does, and returns plain values (numbers, arrays, model-file text);
//! the Python half (`python/sysid/`) wraps them in result objects. Every computation
//! runs with the GIL released, on a worker thread that the calling thread watches for
//! Ctrl-C and progress (`run::supervise`).

mod checks;
mod data;
mod errors;
mod linear;
mod particle;
mod run;
mod simulation;
mod studies;

use pyo3::prelude::*;

/// The module `sysid._sysid`.
#[pymodule]
fn _sysid(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // the global pool's workers evaluate model files' expression trees, whose deepest
    // allowed form needs more than rayon's default 2 MiB in a release build (a second
    // import in the same process finds the pool built: nothing to do)
    let _ = rayon::ThreadPoolBuilder::new()
        .stack_size(sysid::modelfile::expr::STACK_BYTES)
        .build_global();
    linear::register(m)?;
    particle::register(m)?;
    simulation::register(m)?;
    studies::register(m)?;
    Ok(())
}
