//! The EM runner: one loop for every EM variant.
//!
//! # Algorithm
//! An algorithm supplies [`EmAlgorithm::step`]: from the current estimate `theta_k` it
//! runs the E-step (which yields `l_k = log p(y | theta_k)`) and the M-step, returning
//! `theta_{k+1}`. The runner owns everything else: the iteration limit, the stopping
//! rule of Blocker (2008),
//! ```text
//! (l_k - l_{k-1}) / (0.5 |l_k + l_{k-1}| + eps) < tol,
//! ```
//! the log-likelihood trace, the monotonicity check and the observers. For exact EM
//! a decrease beyond `monotonicity_tol * |l_{k-1}|` stops the run with
//! [`Termination::LikelihoodDecreased`] and returns the previous (better) estimate:
//! such a decrease is a bug to report, never a step to take silently. For noisy
//! (particle) E-steps the decreases are counted instead.

use std::time::{Duration, Instant};

/// One EM variant: the E-step and the M-step.
///
/// # Example
/// EM for the mean of `N(mu, 1)` data with half of the values missing at random has a
/// one-line E- and M-step; the runner does the rest:
/// ```
/// use sysid_em::{EmAlgorithm, EmOptions, run_em};
/// struct MeanEm { observed: Vec<f64>, missing: usize }
/// impl MeanEm {
///     fn loglik_of(&self, mu: f64) -> f64 {
///         self.observed.iter().map(|y| -0.5 * (y - mu).powi(2)).sum()
///     }
/// }
/// impl EmAlgorithm for MeanEm {
///     type Estimate = f64;
///     type Error = std::convert::Infallible;
///     fn step(&mut self, mu: &f64) -> Result<(f64, f64), Self::Error> {
///         // E: each missing value is expected at mu; M: the mean of the completed data
///         let total = self.observed.iter().sum::<f64>() + self.missing as f64 * mu;
///         let next = total / (self.observed.len() + self.missing) as f64;
///         Ok((next, self.loglik_of(*mu)))
///     }
///     fn loglik(&mut self, mu: &f64) -> Result<f64, Self::Error> {
///         Ok(self.loglik_of(*mu))
///     }
/// }
/// let mut em = MeanEm { observed: vec![1.0, 2.0, 3.0], missing: 3 };
/// let options = EmOptions { tol: 1e-12, ..EmOptions::default() }.check().unwrap();
/// let result = run_em(&mut em, 0.0, &options, &mut ());
/// assert!((result.estimate - 2.0).abs() < 1e-5);
/// ```
pub trait EmAlgorithm {
    /// The parameter estimate.
    type Estimate: Clone;
    /// What a step can fail with.
    type Error;

    /// Runs the E-step at `current` and the M-step; returns the new estimate and
    /// `log p(y | current)`.
    fn step(&mut self, current: &Self::Estimate) -> Result<(Self::Estimate, f64), Self::Error>;

    /// `log p(y | estimate)` (an E-step without the M-step), for the final estimate.
    fn loglik(&mut self, estimate: &Self::Estimate) -> Result<f64, Self::Error>;

    /// The algorithm's own estimate of the log-likelihood still to gain after its last
    /// step, for [`EmOptions::distance_tol`] (an accelerated EM knows it from the plain
    /// EM steps inside its cycle); `None`, the default, lets the runner extrapolate the
    /// trace ([`remaining_gain`]).
    fn remaining_gain(&self) -> Option<f64> {
        None
    }

    /// Whether the E-step is exact, so that the likelihood must never decrease.
    fn is_exact(&self) -> bool {
        true
    }
}

/// Why the runner stopped.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Termination<E> {
    /// The relative log-likelihood change fell below the tolerance.
    Converged,
    /// The iteration limit was reached.
    MaxIterations,
    /// Exact EM decreased the log-likelihood (a bug): the run stopped and returned the
    /// estimate before the decrease.
    LikelihoodDecreased {
        /// Iteration whose M-step produced the worse estimate.
        iteration: usize,
        /// Log-likelihood before.
        previous: f64,
        /// Log-likelihood after.
        current: f64,
    },
    /// The observer asked the run to stop ([`EmObserver::should_stop`], e.g. on
    /// Ctrl-C): the estimate is the last one with a known log-likelihood.
    Interrupted {
        /// The last iteration completed.
        iteration: usize,
    },
    /// A step failed; the estimate is the last one that succeeded.
    Error {
        /// Iteration that failed (1-based).
        iteration: usize,
        /// The failure.
        error: E,
    },
}

/// Options of the runner, validated by [`EmOptions::check`].
#[derive(Debug, Clone, PartialEq)]
pub struct EmOptions {
    /// Maximum number of iterations (M-steps). Default 1000.
    pub max_iterations: usize,
    /// Tolerance of the relative stopping rule; `0` runs exactly `max_iterations`.
    /// Default 1e-6.
    pub tol: f64,
    /// Exact EM stops when `l_k < l_{k-1} - monotonicity_tol |l_{k-1}|`. Default 1e-10.
    pub monotonicity_tol: f64,
    /// Stop when the last iteration gained less than this many nats and the estimated
    /// distance to the maximum is below it too ([`remaining_gain`]: Aitken's
    /// extrapolation of the last three log-likelihoods, or
    /// [`EmAlgorithm::remaining_gain`]);
    /// `0` (the default) does not use it. Unlike the relative rule it means the same on
    /// every data set, and a run crawling along a ridge (where the per-step gain is small
    /// but steady) is not mistaken for a converged one.
    pub distance_tol: f64,
}

impl Default for EmOptions {
    fn default() -> Self {
        EmOptions {
            max_iterations: 1000,
            tol: 1e-6,
            monotonicity_tol: 1e-10,
            distance_tol: 0.0,
        }
    }
}

/// Invalid runner options.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum OptionsError {
    /// `max_iterations` is zero.
    #[error("max_iterations must be at least 1")]
    NoIterations,
    /// A tolerance is negative or not finite.
    #[error("{name} must be a finite non-negative number, got {value}")]
    BadTolerance {
        /// The matrix (or option) concerned.
        name: &'static str,
        /// The offending value.
        value: f64,
    },
}

/// Options that passed [`EmOptions::check`], the only kind [`run_em`] and the fits
/// take (the guard pattern of linfa's `ParamGuard`): an unchecked value, such as zero
/// iterations, never reaches an algorithm.
///
/// # Example
/// ```
/// use sysid_em::{EmOptions, OptionsError};
/// let checked = EmOptions { max_iterations: 50, ..EmOptions::default() }.check()?;
/// assert_eq!(checked.max_iterations, 50); // reads through to the options
/// let refused = EmOptions { max_iterations: 0, ..EmOptions::default() }.check();
/// assert_eq!(refused, Err(OptionsError::NoIterations));
/// # Ok::<(), OptionsError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct CheckedEmOptions(EmOptions);

impl std::ops::Deref for CheckedEmOptions {
    type Target = EmOptions;
    fn deref(&self) -> &EmOptions {
        &self.0
    }
}

impl CheckedEmOptions {
    /// The options themselves.
    pub fn into_inner(self) -> EmOptions {
        self.0
    }
}

impl Default for CheckedEmOptions {
    /// The default options (valid by construction).
    fn default() -> Self {
        CheckedEmOptions(EmOptions::default())
    }
}

impl EmOptions {
    /// Validates the options: at least one iteration, finite non-negative tolerances.
    pub fn check(self) -> Result<CheckedEmOptions, OptionsError> {
        if self.max_iterations == 0 {
            return Err(OptionsError::NoIterations);
        }
        for (name, value) in [
            ("tol", self.tol),
            ("monotonicity_tol", self.monotonicity_tol),
            ("distance_tol", self.distance_tol),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(OptionsError::BadTolerance { name, value });
            }
        }
        Ok(CheckedEmOptions(self))
    }
}

/// What observers see after every iteration.
#[derive(Debug)]
pub struct IterationInfo<'a, T> {
    /// Iteration number, 1-based.
    pub iteration: usize,
    /// `log p(y | theta_{k-1})`, computed by this iteration's E-step.
    pub loglik: f64,
    /// The new estimate `theta_k`.
    pub estimate: &'a T,
    /// Time since the run started.
    pub elapsed: Duration,
}

/// Watches a run (progress bars, CSV traces, logging). Every method has a default.
///
/// # Example
/// An observer that keeps the log-likelihood of every iteration and notes the start
/// and the end:
/// ```
/// use sysid_em::{EmObserver, IterationInfo};
/// #[derive(Default)]
/// struct Log { started: bool, trace: Vec<f64>, finished_after: Option<usize> }
/// impl<T> EmObserver<T> for Log {
///     fn start(&mut self, _initial: &T) { self.started = true; }
///     fn iteration(&mut self, info: &IterationInfo<'_, T>) { self.trace.push(info.loglik); }
///     fn finish(&mut self, _estimate: &T, _loglik: Option<f64>, iterations: usize) {
///         self.finished_after = Some(iterations);
///     }
/// }
/// let mut log = Log::default();
/// EmObserver::<f64>::start(&mut log, &0.5);
/// assert!(log.started);
/// ```
pub trait EmObserver<T> {
    /// Called once before the first iteration, with the starting estimate.
    fn start(&mut self, _initial: &T) {}
    /// Called after every iteration.
    fn iteration(&mut self, _info: &IterationInfo<'_, T>) {}
    /// Called once when the run ends (converged, at the limit, or stopped by an
    /// error), with the returned estimate, its log-likelihood and the iterations made.
    fn finish(&mut self, _estimate: &T, _loglik: Option<f64>, _iterations: usize) {}
    /// Asked after every iteration: `true` ends the run with
    /// [`Termination::Interrupted`] (a user's Ctrl-C, a time budget). Default: never.
    fn should_stop(&self) -> bool {
        false
    }
}

/// The observer that does nothing.
impl<T> EmObserver<T> for () {}

/// An observer lent to a run.
impl<T, O: EmObserver<T> + ?Sized> EmObserver<T> for &mut O {
    fn start(&mut self, initial: &T) {
        (**self).start(initial);
    }
    fn iteration(&mut self, info: &IterationInfo<'_, T>) {
        (**self).iteration(info);
    }
    fn finish(&mut self, estimate: &T, loglik: Option<f64>, iterations: usize) {
        (**self).finish(estimate, loglik, iterations);
    }
    fn should_stop(&self) -> bool {
        (**self).should_stop()
    }
}

/// Two observers, called in order (e.g. a trace and a progress bar).
impl<T, A: EmObserver<T>, B: EmObserver<T>> EmObserver<T> for (A, B) {
    fn start(&mut self, initial: &T) {
        self.0.start(initial);
        self.1.start(initial);
    }
    fn iteration(&mut self, info: &IterationInfo<'_, T>) {
        self.0.iteration(info);
        self.1.iteration(info);
    }
    fn finish(&mut self, estimate: &T, loglik: Option<f64>, iterations: usize) {
        self.0.finish(estimate, loglik, iterations);
        self.1.finish(estimate, loglik, iterations);
    }
    fn should_stop(&self) -> bool {
        self.0.should_stop() || self.1.should_stop()
    }
}

/// The result of a run.
#[derive(Debug, Clone)]
pub struct EmResult<T, E> {
    /// The final estimate: the last one whose log-likelihood is known and that did not
    /// decrease it (see [`Termination`]).
    pub estimate: T,
    /// `log p(y | estimate)`; `None` only if no log-likelihood could be computed (the
    /// first E-step failed).
    pub loglik: Option<f64>,
    /// `trace[k] = log p(y | theta_k)` for every estimate evaluated, `theta_0` the
    /// initial one (a rejected estimate's value included, as the last entry).
    pub trace: Vec<f64>,
    /// Number of M-steps that produced `estimate`.
    pub iterations: usize,
    /// Why the run stopped.
    pub termination: Termination<E>,
    /// Number of iterations whose log-likelihood decreased beyond the tolerance: for
    /// noisy E-steps a statistic, for exact EM at most one (the one that stopped it).
    pub decreases: usize,
    /// Wall-clock time of the run.
    pub elapsed: Duration,
}

/// The seed-002 relative change `(l - l_prev) / (0.5 |l + l_prev| + eps)`.
pub fn relative_change(l: f64, l_prev: f64) -> f64 {
    (l - l_prev) / (0.5 * (l + l_prev).abs() + f64::EPSILON)
}

/// Aitken's estimate of the log-likelihood still to gain after `l2`, from three
/// successive values `l0, l1, l2`: with the linear rate `rho = (l2 - l1) / (l1 - l0)`,
/// `(l2 - l1) rho / (1 - rho)`. Infinite when the gains do not shrink (`rho >= 1`),
/// zero when the last step gained nothing.
pub fn remaining_gain(l0: f64, l1: f64, l2: f64) -> f64 {
    let (d1, d2) = (l1 - l0, l2 - l1);
    if d2 <= 0.0 {
        return 0.0;
    }
    if d1 <= 0.0 {
        return f64::INFINITY;
    }
    let rho = d2 / d1;
    if rho >= 1.0 {
        f64::INFINITY
    } else {
        d2 * rho / (1.0 - rho)
    }
}

/// Runs EM from `initial`.
///
/// # Example
/// ```
/// use sysid_em::{EmAlgorithm, EmOptions, Termination, run_em};
/// // a toy "EM" that halves the distance to 3 and whose likelihood is -(x - 3)^2
/// struct Toy;
/// impl EmAlgorithm for Toy {
///     type Estimate = f64;
///     type Error = ();
///     fn step(&mut self, x: &f64) -> Result<(f64, f64), ()> { Ok(((x + 3.0) / 2.0, -(x - 3.0).powi(2))) }
///     fn loglik(&mut self, x: &f64) -> Result<f64, ()> { Ok(-(x - 3.0).powi(2)) }
/// }
/// let options = EmOptions { max_iterations: 60, tol: 0.0, ..EmOptions::default() }.check().unwrap();
/// let result = run_em(&mut Toy, 1.0, &options, &mut ());
/// assert_eq!(result.termination, Termination::MaxIterations);
/// assert!((result.estimate - 3.0).abs() < 1e-12);
/// assert_eq!(result.trace.len(), 61);
/// ```
pub fn run_em<A: EmAlgorithm>(
    algorithm: &mut A,
    initial: A::Estimate,
    options: &CheckedEmOptions,
    observer: &mut impl EmObserver<A::Estimate>,
) -> EmResult<A::Estimate, A::Error> {
    observer.start(&initial);
    let result = iterate(algorithm, initial, options, observer);
    observer.finish(&result.estimate, result.loglik, result.iterations);
    result
}

/// The iterations of [`run_em`] (between the observer's start and finish).
fn iterate<A: EmAlgorithm>(
    algorithm: &mut A,
    initial: A::Estimate,
    options: &CheckedEmOptions,
    observer: &mut impl EmObserver<A::Estimate>,
) -> EmResult<A::Estimate, A::Error> {
    let start = Instant::now();
    let exact = algorithm.is_exact();
    // theta_{k-1} (current) and theta_{k-2} (previous), trace[j] = l(theta_j)
    let mut current = initial;
    let mut previous: Option<A::Estimate> = None;
    let mut trace: Vec<f64> = Vec::new();
    let mut decreases = 0;
    let result = |estimate, loglik, trace, iterations, termination, decreases| EmResult {
        estimate,
        loglik,
        trace,
        iterations,
        termination,
        decreases,
        elapsed: start.elapsed(),
    };
    for iteration in 1..=options.max_iterations {
        let (next, l_current) = match algorithm.step(&current) {
            Ok(v) => v,
            Err(error) => {
                // theta_{k-1}'s log-likelihood is unknown: return theta_{k-2} if any
                let termination = Termination::Error { iteration, error };
                let loglik = trace.last().copied();
                return match previous {
                    Some(p) => result(p, loglik, trace, iteration - 2, termination, decreases),
                    None => result(current, None, trace, 0, termination, decreases),
                };
            }
        };
        trace.push(l_current);
        if let [.., l_prev, _] = trace[..] {
            if l_current < l_prev - options.monotonicity_tol * l_prev.abs() {
                decreases += 1;
                if exact {
                    let termination = Termination::LikelihoodDecreased {
                        iteration: iteration - 1,
                        previous: l_prev,
                        current: l_current,
                    };
                    let estimate = previous.expect("a decrease needs two evaluated estimates");
                    return result(
                        estimate,
                        Some(l_prev),
                        trace,
                        iteration - 2,
                        termination,
                        decreases,
                    );
                }
            }
            let near = options.distance_tol > 0.0
                && l_current - l_prev < options.distance_tol
                && match (algorithm.remaining_gain(), &trace[..]) {
                    (Some(gain), _) => gain < options.distance_tol,
                    (None, [.., l0, l1, l2]) => {
                        remaining_gain(*l0, *l1, *l2) < options.distance_tol
                    }
                    _ => false,
                };
            if near || (options.tol > 0.0 && relative_change(l_current, l_prev).abs() < options.tol)
            {
                let termination = Termination::Converged;
                return result(
                    current,
                    Some(l_current),
                    trace,
                    iteration - 1,
                    termination,
                    decreases,
                );
            }
        }
        observer.iteration(&IterationInfo {
            iteration,
            loglik: l_current,
            estimate: &next,
            elapsed: start.elapsed(),
        });
        if observer.should_stop() {
            // theta_{k-1}, whose log-likelihood this iteration computed
            let termination = Termination::Interrupted {
                iteration: iteration - 1,
            };
            return result(
                current,
                Some(l_current),
                trace,
                iteration - 1,
                termination,
                decreases,
            );
        }
        previous = Some(std::mem::replace(&mut current, next));
    }
    // the iteration limit: evaluate the last estimate
    let iterations = options.max_iterations;
    match algorithm.loglik(&current) {
        Ok(l) => {
            let l_prev = *trace.last().expect("at least one iteration ran");
            trace.push(l);
            if l < l_prev - options.monotonicity_tol * l_prev.abs() {
                decreases += 1;
                if exact {
                    let termination = Termination::LikelihoodDecreased {
                        iteration: iterations,
                        previous: l_prev,
                        current: l,
                    };
                    let estimate = previous.expect("at least one iteration ran");
                    return result(
                        estimate,
                        Some(l_prev),
                        trace,
                        iterations - 1,
                        termination,
                        decreases,
                    );
                }
            }
            result(
                current,
                Some(l),
                trace,
                iterations,
                Termination::MaxIterations,
                decreases,
            )
        }
        Err(error) => {
            let termination = Termination::Error {
                iteration: iterations + 1,
                error,
            };
            let estimate = previous.expect("at least one iteration ran");
            let loglik = trace.last().copied();
            result(
                estimate,
                loglik,
                trace,
                iterations - 1,
                termination,
                decreases,
            )
        }
    }
}
