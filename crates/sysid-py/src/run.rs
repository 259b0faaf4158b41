//! Running a computation from Python: the GIL released, Ctrl-C and a progress
//! callback honoured within a fraction of a second, and the threads of the call.
//!
//! The computation runs on a scoped worker thread (inside a rayon pool of `threads`
//! threads when asked); the calling thread, which holds the Python thread state,
//! sleeps without the GIL on a condition variable and wakes every
//! [`POLL`] to check for signals and report progress. A signal or an exception of the
//! callback sets the stop flag that the library's runs poll after every iteration; the
//! worker then returns what it has, and the caller raises the error with it.

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::Duration;

/// How often the calling thread looks at signals and progress.
const POLL: Duration = Duration::from_millis(50);

/// What a running computation shares with the thread that watches it.
pub(crate) struct Control {
    stop: AtomicBool,
    done: AtomicU64,
}

impl Control {
    /// Whether the run should end now (Ctrl-C, or the progress callback raised).
    pub fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// One more unit of work done (an iteration, a filter run).
    pub fn tick(&self) {
        self.done.fetch_add(1, Ordering::Relaxed);
    }
}

/// The library's EM runs see iterations through this and stop on it.
impl<T> sysid::em::EmObserver<T> for &Control {
    fn iteration(&mut self, _info: &sysid::em::IterationInfo<'_, T>) {
        self.tick();
    }
    fn should_stop(&self) -> bool {
        self.stopped()
    }
}

/// The samplers' chains too.
impl sysid::pmcmc::ChainObserver for Control {
    fn iteration(&self, _chain: usize, _iteration: usize) {
        self.tick();
    }
    fn should_stop(&self) -> bool {
        self.stopped()
    }
}

/// The progress callback: `True` prints a line to stderr, a callable is called with
/// `(done, total)`.
pub(crate) enum Progress<'py> {
    None,
    Print(&'static str),
    Call(Bound<'py, PyAny>),
}

impl<'py> Progress<'py> {
    /// `progress=` of a Python call: `None`/`False`, `True`, or a callable.
    pub fn of(value: Option<Bound<'py, PyAny>>, label: &'static str) -> PyResult<Self> {
        let Some(value) = value else {
            return Ok(Progress::None);
        };
        if value.is_callable() {
            return Ok(Progress::Call(value));
        }
        match value.is_truthy()? {
            true => Ok(Progress::Print(label)),
            false => Ok(Progress::None),
        }
    }

    fn report(&self, py: Python<'py>, done: u64, total: u64, last: bool) -> PyResult<()> {
        match self {
            Progress::None => Ok(()),
            Progress::Call(f) => f.call1((done, total)).map(drop),
            Progress::Print(label) => {
                let end = if last { "\n" } else { "" };
                let line = format!("\r{label}: {done}/{total}{end}");
                let sys = py.import("sys")?;
                let stderr = sys.getattr("stderr")?;
                stderr.call_method1("write", (line,))?;
                stderr.call_method0("flush").map(drop)
            }
        }
    }
}

/// The outcome of a supervised run: the worker's value and the Python error that
/// stopped it early (Ctrl-C's `KeyboardInterrupt`, the callback's exception), if any.
pub(crate) struct Supervised<T> {
    pub value: T,
    pub stopped_by: Option<PyErr>,
}

/// The result of a run that Ctrl-C or the callback may have stopped: `out`, or the
/// error that stopped the run with `out` on it as `.partial` (the result so far).
pub(crate) fn result_or_stop<'py>(
    py: Python<'py>,
    stopped_by: Option<PyErr>,
    out: Bound<'py, pyo3::types::PyDict>,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    match stopped_by {
        Some(e) => {
            e.value(py).setattr("partial", &out)?;
            Err(e)
        }
        None => Ok(out),
    }
}

/// A rayon pool of `threads` threads, or none for the caller's (the global pool,
/// sized by `RAYON_NUM_THREADS` or the machine).
fn pool(threads: Option<usize>) -> PyResult<Option<rayon::ThreadPool>> {
    match threads {
        None => Ok(None),
        Some(0) => Err(crate::errors::Failure::option("threads", "must be at least 1").into()),
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .stack_size(sysid::modelfile::expr::STACK_BYTES)
            .build()
            .map(Some)
            .map_err(|e| PyRuntimeError::new_err(format!("cannot start {n} threads: {e}"))),
    }
}

/// Marks the work finished and wakes the caller when dropped.
struct Finish<'a>(&'a (Mutex<bool>, Condvar));

impl Drop for Finish<'_> {
    fn drop(&mut self) {
        let (flag, wake) = self.0;
        *flag.lock().unwrap_or_else(|e| e.into_inner()) = true;
        wake.notify_all();
    }
}

/// Runs `work` without the GIL on a worker thread (in a pool of `threads` threads),
/// watching for Ctrl-C and reporting progress (`total` units) until it returns.
pub(crate) fn supervise<T: Send>(
    py: Python<'_>,
    threads: Option<usize>,
    progress: &Progress<'_>,
    total: u64,
    work: impl FnOnce(&Control) -> T + Send,
) -> PyResult<Supervised<T>> {
    let pool = pool(threads)?;
    let control = Control {
        stop: AtomicBool::new(false),
        done: AtomicU64::new(0),
    };
    let finished = (Mutex::new(false), Condvar::new());
    std::thread::scope(|scope| {
        let worker = scope.spawn(|| {
            // wakes the caller however the work ends, a panic included
            let _finish = Finish(&finished);
            match &pool {
                Some(pool) => pool.install(|| work(&control)),
                None => work(&control),
            }
        });
        let mut stopped_by: Option<PyErr> = None;
        let mut reported = None;
        loop {
            let done = py.detach(|| {
                let (flag, wake) = &finished;
                let guard = flag.lock().unwrap_or_else(|e| e.into_inner());
                let (guard, _) = wake
                    .wait_timeout_while(guard, POLL, |done| !*done)
                    .unwrap_or_else(|e| e.into_inner());
                *guard
            });
            if stopped_by.is_none()
                && let Err(e) = py.check_signals()
            {
                control.stop.store(true, Ordering::Relaxed);
                stopped_by = Some(e);
            }
            let count = control.done.load(Ordering::Relaxed);
            if stopped_by.is_none() && reported != Some(count) && (count > 0 || done) {
                reported = Some(count);
                if let Err(e) = progress.report(py, count, total, done) {
                    control.stop.store(true, Ordering::Relaxed);
                    stopped_by = Some(e);
                }
            }
            if done {
                break;
            }
        }
        let value = worker
            .join()
            .map_err(|_| PyRuntimeError::new_err("sysid: the computation panicked (a bug)"))?;
        Ok(Supervised { value, stopped_by })
    })
}
