//! Progress bars on stderr (indicatif) for anything that runs longer than about a
//! second. Hidden under `--quiet` and `--json`. When stderr is not a terminal (a
//! script, a log file, a batch job), a bar is a plain line instead, at most every 30
//! seconds (`SYSID_PROGRESS_SECONDS` sets the interval), so a long run in a log shows
//! that it is alive and how far it got; a run shorter than the interval prints none.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressFinish, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use sysid::em::{EmObserver, IterationInfo};

static QUIET: AtomicBool = AtomicBool::new(false);

/// Set by the first Ctrl-C during a run that can stop and keep what it has.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);
/// Whether the running command stops cleanly on Ctrl-C ([`interruptible`]).
static INTERRUPTIBLE: AtomicBool = AtomicBool::new(false);

/// Installs the Ctrl-C handler (once per process). During a run marked
/// [`interruptible`] (EM, PMMH, particle Gibbs), the first Ctrl-C asks it to stop after
/// the current iteration and write what it has; otherwise, or at a second Ctrl-C,
/// the process exits at once with 130 (no output is left half-written: outputs are
/// moved into place only when complete).
pub fn watch_interrupts() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _ = ctrlc::set_handler(|| {
            if !INTERRUPTIBLE.load(Ordering::SeqCst) || INTERRUPTED.swap(true, Ordering::SeqCst)
            {
                std::process::exit(130);
            }
            eprintln!("\nsysid: stopping after this iteration and keeping the result so far (Ctrl-C again to quit now)");
        });
    });
}

/// Marks the running command as one that stops cleanly on Ctrl-C.
pub fn interruptible() {
    INTERRUPTIBLE.store(true, Ordering::SeqCst);
}

/// Whether Ctrl-C asked the run to stop. Long runs ask often (before every
/// iteration), so off a terminal this is also where a spinner's heartbeat line ticks.
pub fn interrupted() -> bool {
    if let Ok(mut heartbeat) = HEARTBEAT.try_lock()
        && let Some(log) = heartbeat.as_mut()
    {
        log.tick();
    }
    INTERRUPTED.load(Ordering::SeqCst)
}

/// Off a terminal: the running spinner's plain lines (one spinner at a time).
static HEARTBEAT: Mutex<Option<LogLines>> = Mutex::new(None);

/// Sets the global `--quiet`.
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

/// Whether `--quiet` was given.
pub fn quiet() -> bool {
    QUIET.load(Ordering::Relaxed)
}

/// A progress bar, or nothing when progress is not to be shown.
#[derive(Clone)]
pub struct Progress {
    bar: Option<ProgressBar>,
    /// Off a terminal: the plain lines' state.
    log: Option<Arc<Mutex<LogLines>>>,
}

/// The default interval between progress lines off a terminal.
const LOG_INTERVAL: Duration = Duration::from_secs(30);

/// Progress as occasional plain lines (stderr not a terminal).
struct LogLines {
    label: String,
    total: Option<u64>,
    position: u64,
    message: String,
    began: Instant,
    last: Instant,
    interval: Duration,
}

impl LogLines {
    fn new(label: &str, total: Option<u64>) -> Option<Arc<Mutex<LogLines>>> {
        Self::build(label, total).map(|log| Arc::new(Mutex::new(log)))
    }

    fn build(label: &str, total: Option<u64>) -> Option<LogLines> {
        let interval = std::env::var("SYSID_PROGRESS_SECONDS")
            .ok()
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|v| v.is_finite() && *v >= 0.0)
            .map_or(LOG_INTERVAL, Duration::from_secs_f64);
        let now = Instant::now();
        Some(LogLines {
            label: label.trim().to_string(),
            total,
            position: 0,
            message: String::new(),
            began: now,
            last: now,
            interval,
        })
    }

    /// Prints a line when the interval has passed since the last one.
    fn tick(&mut self) {
        if self.last.elapsed() < self.interval {
            return;
        }
        self.last = Instant::now();
        let counts = match self.total {
            Some(total) => format!("{}/{total}", self.position),
            None => "running".to_string(),
        };
        let message = if self.message.is_empty() {
            String::new()
        } else {
            format!(" {}", self.message)
        };
        eprintln!(
            "sysid: {}: {counts}{message} ({:.0} s)",
            self.label,
            self.began.elapsed().as_secs_f64()
        );
    }
}

impl Progress {
    /// A bar of `total` steps labelled `label`; hidden under `--quiet`, `json`, or when
    /// stderr is not a terminal.
    pub fn new(total: u64, label: &str, json: bool) -> Progress {
        Self::with_counts(total, label, json, "{pos}/{len} {msg}")
    }

    /// A bar over `total` bytes of a file being read (as [`new`](Self::new)).
    pub fn bytes(total: u64, label: &str, json: bool) -> Progress {
        Self::with_counts(total, label, json, "{bytes}/{total_bytes}")
    }

    fn with_counts(total: u64, label: &str, json: bool, counts: &str) -> Progress {
        if json || quiet() {
            return Progress {
                bar: None,
                log: None,
            };
        }
        if !std::io::stderr().is_terminal() {
            return Progress {
                bar: None,
                log: LogLines::new(label, Some(total)),
            };
        }
        // cleared when the last clone is dropped, also on an early error return
        let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr())
            .with_finish(ProgressFinish::AndClear);
        let style = ProgressStyle::with_template(&format!(
            "{{prefix:>12}} [{{bar:32}}] {counts} ({{elapsed}}, eta {{eta}})"
        ))
        .map(|s| s.progress_chars("=> "))
        .unwrap_or_else(|_| ProgressStyle::default_bar());
        bar.set_style(style);
        bar.set_prefix(label.to_string());
        Progress {
            bar: Some(bar),
            log: None,
        }
    }

    /// A spinner labelled `label`, for one long computation without steps (shown on
    /// a terminal only, as [`new`](Self::new)).
    pub fn spinner(label: &str, json: bool) -> Progress {
        if json || quiet() {
            return Progress {
                bar: None,
                log: None,
            };
        }
        if !std::io::stderr().is_terminal() {
            // no steps to count: the lines tick whenever the run asks whether to stop
            if let Ok(mut heartbeat) = HEARTBEAT.lock() {
                *heartbeat = LogLines::build(label, None);
            }
            return Progress {
                bar: None,
                log: None,
            };
        }
        let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr())
            .with_finish(ProgressFinish::AndClear);
        if let Ok(style) = ProgressStyle::with_template("{prefix:>12} {spinner} {elapsed}") {
            bar.set_style(style);
        }
        bar.set_prefix(label.to_string());
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        Progress {
            bar: Some(bar),
            log: None,
        }
    }

    /// Moves to step `position`.
    pub fn set_position(&self, position: u64) {
        if let Some(bar) = &self.bar {
            bar.set_position(position);
        }
        self.logged(|log| log.position = position);
    }

    fn logged(&self, update: impl FnOnce(&mut LogLines)) {
        if let Some(log) = &self.log
            && let Ok(mut log) = log.lock()
        {
            update(&mut log);
            log.tick();
        }
    }

    /// Advances by `n` steps.
    pub fn inc(&self, n: u64) {
        if let Some(bar) = &self.bar {
            bar.inc(n);
        }
        self.logged(|log| log.position += n);
    }

    /// Shows `message` after the counts.
    pub fn message(&self, message: String) {
        if let Some(bar) = &self.bar {
            bar.set_message(message.clone());
        }
        self.logged(|log| log.message = message);
    }

    /// Removes the bar.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
        if let Ok(mut heartbeat) = HEARTBEAT.lock() {
            *heartbeat = None;
        }
    }
}

impl<T> EmObserver<T> for Progress {
    fn iteration(&mut self, info: &IterationInfo<'_, T>) {
        self.inc(1);
        if info.loglik.is_finite() {
            self.message(format!("loglik {:.3}", info.loglik));
        }
    }

    fn should_stop(&self) -> bool {
        interrupted()
    }
}

impl sysid::pmcmc::ChainObserver for Progress {
    fn iteration(&self, _chain: usize, _iteration: usize) {
        self.inc(1);
    }

    fn should_stop(&self) -> bool {
        interrupted()
    }
}

/// Prints a note on stderr unless `--quiet`.
pub fn note(text: &str) {
    if !quiet() {
        eprintln!("{text}");
    }
}
