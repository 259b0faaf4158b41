//! Progress bars on stderr (indicatif) for anything that runs longer than about a
//! second. Hidden under `--quiet` and `--json`, and when stderr is not a terminal, so
//! scripts and logs see only results.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressFinish, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
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

/// Whether Ctrl-C asked the run to stop.
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

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
        if json || quiet() || !std::io::stderr().is_terminal() {
            return Progress { bar: None };
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
        Progress { bar: Some(bar) }
    }

    /// A spinner labelled `label`, for one long computation without steps (shown on
    /// a terminal only, as [`new`](Self::new)).
    pub fn spinner(label: &str, json: bool) -> Progress {
        if json || quiet() || !std::io::stderr().is_terminal() {
            return Progress { bar: None };
        }
        let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr())
            .with_finish(ProgressFinish::AndClear);
        if let Ok(style) = ProgressStyle::with_template("{prefix:>12} {spinner} {elapsed}") {
            bar.set_style(style);
        }
        bar.set_prefix(label.to_string());
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        Progress { bar: Some(bar) }
    }

    /// Moves to step `position`.
    pub fn set_position(&self, position: u64) {
        if let Some(bar) = &self.bar {
            bar.set_position(position);
        }
    }

    /// Advances by `n` steps.
    pub fn inc(&self, n: u64) {
        if let Some(bar) = &self.bar {
            bar.inc(n);
        }
    }

    /// Shows `message` after the counts.
    pub fn message(&self, message: String) {
        if let Some(bar) = &self.bar {
            bar.set_message(message);
        }
    }

    /// Removes the bar.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
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
