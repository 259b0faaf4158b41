//! Simulation-error (output-error) identification of a model file: the deterministic
//! model, every noise term set to zero, fitted by minimising the sum of squared
//! differences between the measured outputs and the outputs simulated from the inputs
//! alone, over the free parameters and the initial state.
//!
//! # Model
//! ```text
//! min over (theta, x_0) of  sum_t sum_j (y_{t,j} - yhat_{t,j}(theta, x_0))^2
//! ```
//! with `yhat` the noise-free simulation of [`Simulator`] (missing outputs left out).
//! This is the maximum-likelihood estimate of the output-error model (white
//! measurement noise, no process noise) and the criterion by which a simulation model
//! is judged. Maximum likelihood with process noise ([`ModelFile::fit`]) optimises the
//! one-step prediction instead; see `docs/guide.md` for when each is right.
//!
//! # Algorithm
//! Levenberg–Marquardt (the MINPACK algorithm of the `levenberg-marquardt` crate) on
//! the parameters' unconstrained coordinates (`ln theta` for a positive parameter, a
//! logit between bounds) and the initial state, with the exact Jacobian from the
//! forward sensitivities. It is run from the file's values and from `starts - 1`
//! random perturbations of them (each free value times `exp(spread N(0, 1))`, seeded);
//! the best end point is the estimate. A trial point where the simulation diverges
//! gets a very large residual, so the trust region shrinks instead of the run failing.
//! After the fit, a measurement variance that is one free parameter alone is set to the
//! mean squared simulation error (its output-error estimate), standard errors come
//! from `s^2 (J'J)^-1`, and [`inseparable`] looks for directions the data cannot see.
//!
//! # Complexity
//! Per evaluation one simulation with sensitivities, `O(T (n + p) (n + k))`; per
//! iteration one QR of the `T p x (k + n)` Jacobian.

use crate::simulation::{SimulationError, Simulator};
use crate::{FileFitError, FileFitWarning, ModelFile};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use lm_nalgebra::{DMatrix, DVector, Dyn, Owned};
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use sysid_pmcmc::Support;
use sysid_smc::Series;

/// Options of [`ModelFile::fit_simulation_error`].
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationFitOptions {
    /// Runs of Levenberg–Marquardt: one from the file's values, the others from random
    /// perturbations of them (at least 1).
    pub starts: usize,
    /// The perturbations' spread on the log scale (0.3: about ±30 %).
    pub spread: f64,
    /// The limit on simulations per run, in units of `(k + n + 1)` (MINPACK's
    /// `patience`; 100 by default).
    pub patience: usize,
    /// Estimate the initial state with the parameters (else it is the file's initial
    /// mean).
    pub estimate_initial_state: bool,
    /// The seed of the perturbations.
    pub seed: u64,
}

impl Default for SimulationFitOptions {
    fn default() -> Self {
        SimulationFitOptions {
            starts: sysid_em::affine::AffineFitOptions::default().starts,
            spread: 0.3,
            patience: 100,
            estimate_initial_state: true,
            seed: 1,
        }
    }
}

/// One run of Levenberg–Marquardt.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationStart {
    /// The root mean square simulation error at its end, over all scored values.
    pub rms: f64,
    /// Simulations made.
    pub evaluations: usize,
    /// Why it stopped (MINPACK's reason).
    pub termination: String,
    /// Whether that reason is convergence.
    pub converged: bool,
}

/// The result of [`ModelFile::fit_simulation_error`].
#[derive(Debug, Clone)]
pub struct SimulationFit {
    /// The model file with the estimates as its free values and the estimated initial
    /// state as its initial means.
    pub fitted: ModelFile,
    /// The free parameters' estimates, in the order of [`ModelFile::free_names`].
    pub estimate: Vec<f64>,
    /// Approximate standard errors of the free parameters (`None` for one the
    /// simulation does not depend on, or when `J'J` is singular).
    pub standard_errors: Vec<Option<f64>>,
    /// The estimated (or the file's) initial state.
    pub initial_state: Vec<f64>,
    /// Root mean square simulation error per output.
    pub rms: Vec<f64>,
    /// MATLAB's fit per output, `100 (1 - |y - yhat| / |y - mean(y)|)`.
    pub fit_percent: Vec<f64>,
    /// Every run, the first from the file's values.
    pub starts: Vec<SimulationStart>,
    /// The index of the best run in `starts`.
    pub best: usize,
    /// Whether a stop request ended the runs early.
    pub interrupted: bool,
    /// What should temper a reading of the estimate.
    pub warnings: Vec<FileFitWarning>,
}

/// Directions of the parameters (and initial state) that barely change the simulated
/// outputs: the data cannot tell the values along them apart.
#[derive(Debug, Clone, PartialEq)]
pub struct Inseparable {
    /// The names involved (parameters, and `initial <state>`), largest share first.
    pub names: Vec<String>,
    /// The smallest singular value of the column-scaled Jacobian over the largest.
    pub ratio: f64,
}

/// The ratio of singular values below which a direction counts as invisible.
pub const INSEPARABLE_RATIO: f64 = 1e-6;

/// The near-null direction of a Jacobian (`rows x names.len()`, row-major), each
/// column scaled to unit length first, when its smallest singular value is below
/// [`INSEPARABLE_RATIO`] times the largest; the names with a share of at least 0.1 of
/// that direction, largest first.
pub fn inseparable(jacobian: &[f64], rows: usize, names: &[String]) -> Option<Inseparable> {
    let cols = names.len();
    if cols < 2 || rows < cols || jacobian.len() != rows * cols {
        return None;
    }
    let mut j = nalgebra::DMatrix::from_row_slice(rows, cols, jacobian);
    for mut c in j.column_iter_mut() {
        let norm = c.norm();
        if norm > 0.0 {
            c /= norm;
        }
    }
    let svd = j.svd(false, true);
    let v_t = svd.v_t?;
    let (mut lo, mut hi) = (0, 0);
    for (k, &s) in svd.singular_values.iter().enumerate() {
        if s < svd.singular_values[lo] {
            lo = k;
        }
        if s > svd.singular_values[hi] {
            hi = k;
        }
    }
    let ratio = svd.singular_values[lo] / svd.singular_values[hi];
    if ratio.is_nan() || ratio >= INSEPARABLE_RATIO {
        return None;
    }
    let direction = v_t.row(lo);
    let mut shares: Vec<(f64, &String)> = direction
        .iter()
        .map(|v| v.abs())
        .zip(names)
        .filter(|(v, _)| *v >= 0.1)
        .collect();
    shares.sort_by(|a, b| b.0.total_cmp(&a.0));
    Some(Inseparable {
        names: shares.into_iter().map(|(_, n)| n.clone()).collect(),
        ratio,
    })
}

/// The least-squares problem over `(z, x_0)` for the `levenberg-marquardt` crate.
struct Problem<'a> {
    sim: &'a Simulator,
    supports: Vec<Support>,
    values: Vec<f64>,
    fixed_x0: Option<Vec<f64>>,
    inputs: &'a [f64],
    data: Series<'a>,
    unknowns: DVector<f64>,
    residuals: Option<DVector<f64>>,
    stop: &'a (dyn Fn() -> bool + Sync),
    stopped: bool,
}

/// The residual a diverged trial point gets (squared and summed it stays finite).
const DIVERGED: f64 = 1e100;

impl Problem<'_> {
    /// The scored `(t, j)` entries: the outputs that are not missing.
    fn scored(&self) -> usize {
        (0..self.data.steps())
            .map(|t| self.data.output(t).iter().filter(|v| !v.is_nan()).count())
            .sum()
    }

    /// Every parameter's value and the initial state at `unknowns`, and `d theta / d z`.
    fn unpack(&self, unknowns: &[f64]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let k = self.sim.params().len();
        let mut values = self.values.clone();
        let mut scale = Vec::with_capacity(k);
        for ((&p, s), &z) in self.sim.params().iter().zip(&self.supports).zip(unknowns) {
            let (theta, log_jac) = s.from_unconstrained(z);
            values[p] = theta;
            scale.push(log_jac.exp());
        }
        let x0 = match &self.fixed_x0 {
            Some(x0) => x0.clone(),
            None => unknowns[k..].to_vec(),
        };
        (values, x0, scale)
    }

    /// The residuals at `unknowns` (without the Jacobian).
    fn evaluate_at(&self, unknowns: &[f64]) -> Result<DVector<f64>, SimulationError> {
        let mut at = Problem {
            unknowns: DVector::from_vec(unknowns.to_vec()),
            fixed_x0: self.fixed_x0.clone(),
            supports: self.supports.clone(),
            values: self.values.clone(),
            residuals: None,
            ..*self
        };
        at.stopped = false;
        at.evaluate(false).map(|(r, _)| r)
    }

    /// The residuals at the current unknowns, and with `jacobian` their Jacobian in
    /// the unconstrained coordinates.
    fn evaluate(
        &self,
        jacobian: bool,
    ) -> Result<(DVector<f64>, Option<DMatrix<f64>>), SimulationError> {
        let (values, x0, scale) = self.unpack(self.unknowns.as_slice());
        let steps = self.data.steps();
        let run = self.sim.run(&values, &x0, self.inputs, steps, jacobian)?;
        let full_cols = self.sim.params().len() + x0.len();
        let cols = self.unknowns.len();
        let jac = run.jacobian.unwrap_or_default();
        let p = self.data.output_dim();
        let mut r = Vec::new();
        let mut rows = Vec::new();
        for t in 0..steps {
            for (j, &y) in self.data.output(t).iter().enumerate() {
                if y.is_nan() {
                    continue;
                }
                let i = t * p + j;
                r.push(run.outputs[i] - y);
                if jacobian {
                    let row = &jac[i * full_cols..(i + 1) * full_cols];
                    rows.extend(
                        row[..cols]
                            .iter()
                            .enumerate()
                            .map(|(c, v)| if c < scale.len() { v * scale[c] } else { *v }),
                    );
                }
            }
        }
        let m = r.len();
        let jacobian = jacobian.then(|| DMatrix::from_row_slice(m, cols, &rows));
        Ok((DVector::from_vec(r), jacobian))
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.unknowns.copy_from(x);
        if (self.stop)() {
            self.stopped = true;
            self.residuals = None;
            return;
        }
        self.residuals = Some(match self.evaluate(false) {
            Ok((r, _)) => r,
            Err(_) => DVector::from_element(self.scored(), DIVERGED),
        });
    }
    fn params(&self) -> DVector<f64> {
        self.unknowns.clone()
    }
    fn residuals(&self) -> Option<DVector<f64>> {
        self.residuals.clone()
    }
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        // asked only at accepted points, which simulate
        self.evaluate(true).ok().and_then(|(_, j)| j)
    }
}

/// MATLAB's fit ([`sysid_kalman::fit_percent`]) and the RMS per output over the
/// observed values from step `from`.
fn scores(data: &Series<'_>, outputs: &[f64], from: usize) -> (Vec<f64>, Vec<f64>) {
    let (p, steps) = (data.output_dim(), data.steps());
    let y = nalgebra::DMatrix::from_fn(p, steps, |j, t| data.output(t)[j]);
    let y_hat = nalgebra::DMatrix::from_fn(p, steps, |j, t| outputs[t * p + j]);
    let rms = (0..p)
        .map(|j| {
            let errors: Vec<f64> = (from..steps)
                .filter(|&t| !y[(j, t)].is_nan())
                .map(|t| (y[(j, t)] - y_hat[(j, t)]).powi(2))
                .collect();
            (errors.iter().sum::<f64>() / errors.len().max(1) as f64).sqrt()
        })
        .collect();
    (sysid_kalman::fit_percent(&y, &y_hat, from), rms)
}

impl ModelFile {
    /// The model's initial means at its own parameter values.
    pub fn initial_means(&self) -> Vec<f64> {
        let values = self.full_values(&self.free_values());
        self.spec()
            .initial_mean
            .iter()
            .map(|e| {
                e.eval(&|v| match v {
                    crate::expr::Var::Param(k) => values[k],
                    _ => f64::NAN,
                })
            })
            .collect()
    }

    /// The parameters (and initial states) that `data`'s inputs cannot separate at the
    /// file's values: [`inseparable`] on the noise-free simulation's Jacobian from the
    /// initial means over the observed outputs (`None` when none, or when the
    /// simulation diverges).
    pub fn inseparable_on(&self, data: Series<'_>) -> Option<Inseparable> {
        let params = Simulator::simulated_parameters(self);
        let spec = self.spec();
        let inputs: Vec<f64> = (0..data.steps())
            .flat_map(|t| data.input(t).iter().copied())
            .collect();
        let values = self.full_values(&self.free_values());
        let run = Simulator::new(self, &params)
            .run(&values, &self.initial_means(), &inputs, data.steps(), true)
            .ok()?;
        let jacobian = run.jacobian?;
        let cols = params.len() + spec.states.len();
        let p = data.output_dim();
        let mut rows = Vec::new();
        for t in 0..data.steps() {
            for (j, y) in data.output(t).iter().enumerate() {
                if !y.is_nan() {
                    let i = t * p + j;
                    rows.extend_from_slice(&jacobian[i * cols..(i + 1) * cols]);
                }
            }
        }
        let mut names: Vec<String> = params
            .iter()
            .map(|&k| spec.parameters[k].name.clone())
            .collect();
        names.extend(spec.states.iter().map(|s| format!("initial {s}")));
        inseparable(&rows, rows.len() / cols, &names)
    }

    /// The same model with its initial means replaced by the numbers `x0` (variances
    /// kept).
    pub fn with_initial_means(&self, x0: &[f64]) -> ModelFile {
        let mut spec = self.spec().clone();
        for (e, &v) in spec.initial_mean.iter_mut().zip(x0) {
            *e = crate::expr::Expr::num(v);
        }
        ModelFile::from_spec(spec, self.origin())
    }

    /// Fits the free parameters and the initial state by minimising the simulation
    /// error on `data` (see the [module documentation](crate::output_error)). `stop` is
    /// asked before every simulation; a `true` ends the runs with the best point so
    /// far.
    ///
    /// # Errors
    /// [`FileFitError::NothingFree`] when no free parameter enters a transition or
    /// observation equation; [`FileFitError::Setting`] for an option out of its range;
    /// [`FileFitError::Start`]
    /// when the simulation from the file's values diverges.
    pub fn fit_simulation_error(
        &self,
        data: Series<'_>,
        options: &SimulationFitOptions,
        stop: &(dyn Fn() -> bool + Sync),
    ) -> Result<SimulationFit, FileFitError> {
        let params = Simulator::simulated_parameters(self);
        if params.is_empty() {
            return Err(FileFitError::NothingFree {
                origin: self.origin().to_string(),
            });
        }
        let invalid = |setting, reason: &str| {
            FileFitError::Setting(sysid_em::SettingError::Invalid {
                setting,
                reason: reason.to_string(),
            })
        };
        if options.starts == 0 {
            return Err(invalid("starts", "at least 1 run is needed"));
        }
        if !(options.spread.is_finite() && options.spread >= 0.0) {
            return Err(invalid("spread", "a finite spread of at least 0 is needed"));
        }
        if options.patience == 0 {
            return Err(invalid("patience", "at least 1 is needed"));
        }
        let spec = self.spec();
        let inputs: Vec<f64> = (0..data.steps())
            .flat_map(|t| data.input(t).iter().copied())
            .collect();
        let sim = Simulator::new(self, &params);
        let values = self.full_values(&self.free_values());
        let x0 = self.initial_means();
        // the start must simulate
        sim.run(&values, &x0, &inputs, data.steps(), false)
            .map_err(|e| FileFitError::Start(e.to_string().into()))?;
        let supports: Vec<Support> = params.iter().map(|&k| spec.parameters[k].support).collect();
        let start_z: Vec<f64> = params
            .iter()
            .zip(&supports)
            .map(|(&k, s)| s.to_unconstrained(spec.parameters[k].value))
            .collect();
        let problem = Problem {
            sim: &sim,
            supports: supports.clone(),
            values: values.clone(),
            fixed_x0: (!options.estimate_initial_state).then(|| x0.clone()),
            inputs: &inputs,
            data,
            unknowns: DVector::zeros(0),
            residuals: None,
            stop,
            stopped: false,
        };
        let m = problem.scored();
        let solver = LevenbergMarquardt::new().with_patience(options.patience);
        // every start is drawn first, so the runs (in parallel) do not depend on the
        // number of threads
        let mut rng = sysid_smc::stream(options.seed, 0);
        let points: Vec<Vec<f64>> = (0..options.starts)
            .map(|run| {
                let mut z = start_z.clone();
                if run > 0 {
                    for (zj, s) in z.iter_mut().zip(&supports) {
                        let e: f64 = StandardNormal.sample(&mut rng);
                        perturb(zj, *s, options.spread * e);
                    }
                }
                if options.estimate_initial_state {
                    z.extend_from_slice(&x0);
                }
                z
            })
            .collect();
        let outcomes: Vec<(SimulationStart, DVector<f64>, bool)> = points
            .into_par_iter()
            .map(|z| {
                let mut problem = Problem {
                    unknowns: DVector::from_vec(z),
                    fixed_x0: problem.fixed_x0.clone(),
                    supports: problem.supports.clone(),
                    values: problem.values.clone(),
                    residuals: None,
                    ..problem
                };
                let start = problem.unknowns.clone();
                problem.set_params(&start);
                let (solved, report) = solver.minimize(problem);
                let cost = 2.0 * report.objective_function;
                let start = SimulationStart {
                    rms: (cost / m.max(1) as f64).sqrt(),
                    evaluations: report.number_of_evaluations,
                    termination: format!("{:?}", report.termination),
                    converged: report.termination.was_successful(),
                };
                (start, solved.unknowns, solved.stopped)
            })
            .collect();
        let interrupted = outcomes.iter().any(|o| o.2);
        let best = outcomes
            .iter()
            .filter(|o| o.0.rms.is_finite())
            .min_by(|a, b| a.0.rms.total_cmp(&b.0.rms))
            .map(|o| (o.0.rms, o.1.clone()));
        let starts: Vec<SimulationStart> = outcomes.into_iter().map(|o| o.0).collect();
        let best_run = starts
            .iter()
            .enumerate()
            .filter(|(_, s)| s.rms.is_finite())
            .min_by(|a, b| a.1.rms.total_cmp(&b.1.rms))
            .map_or(0, |(k, _)| k);
        let Some((_, unknowns)) = best else {
            return Err(FileFitError::Start(
                "no run of the simulation-error fit ended at a finite error"
                    .to_string()
                    .into(),
            ));
        };
        let (mut values, x0, _) = problem.unpack(unknowns.as_slice());
        let run = sim
            .run(&values, &x0, &inputs, data.steps(), true)
            .map_err(|e| FileFitError::Start(e.to_string().into()))?;
        let (fit_percent, rms) = scores(&data, &run.outputs, 0);
        set_measurement_variances(self, &mut values, &rms);
        let free = spec.free();
        let estimate: Vec<f64> = free.iter().map(|&k| values[k]).collect();
        // the Jacobian in theta (not z) and x0, over the scored entries
        let cols = params.len() + x0.len();
        let jac = run.jacobian.unwrap_or_default();
        let p = data.output_dim();
        let mut rows = Vec::new();
        let mut sse = 0.0;
        for t in 0..data.steps() {
            for (j, y) in data.output(t).iter().enumerate() {
                if !y.is_nan() {
                    let i = t * p + j;
                    rows.extend_from_slice(&jac[i * cols..(i + 1) * cols]);
                    sse += (y - run.outputs[i]).powi(2);
                }
            }
        }
        let mut names: Vec<String> = params
            .iter()
            .map(|&k| spec.parameters[k].name.clone())
            .collect();
        let est_cols = if options.estimate_initial_state {
            cols
        } else {
            params.len()
        };
        names.extend(spec.states.iter().map(|s| format!("initial {s}")));
        names.truncate(est_cols);
        let scored_rows = rows.len() / cols;
        let jt: Vec<f64> = rows
            .chunks(cols)
            .flat_map(|r| r[..est_cols].iter().copied())
            .collect();
        let se = standard_errors(&jt, scored_rows, est_cols, sse);
        let mut standard_errors = vec![None; free.len()];
        for (c, &k) in params.iter().enumerate() {
            if let Some(pos) = free.iter().position(|&f| f == k) {
                standard_errors[pos] = se.as_ref().map(|s| s[c]);
            }
        }
        let mut warnings = Vec::new();
        if let Some(found) = inseparable(&jt, scored_rows, &names) {
            warnings.push(FileFitWarning::Inseparable {
                names: found.names,
                ratio: found.ratio,
            });
        }
        for (&k, &s) in params.iter().zip(&supports) {
            warnings.extend(at_bound(&spec.parameters[k].name, values[k], s));
        }
        if !starts[best_run].converged && !interrupted {
            warnings.push(FileFitWarning::NotConverged {
                reason: starts[best_run].termination.clone(),
            });
        }
        let fitted =
            self.with_values(&estimate)
                .with_initial_means(if options.estimate_initial_state {
                    &x0
                } else {
                    &x0[..0]
                });
        Ok(SimulationFit {
            fitted,
            estimate,
            standard_errors,
            initial_state: x0,
            rms,
            fit_percent,
            starts,
            best: best_run,
            interrupted,
            warnings,
        })
    }
}

/// The warning for a value within `1e-6` of the width of its interval from a bound.
pub(crate) fn at_bound(name: &str, value: f64, support: Support) -> Option<FileFitWarning> {
    let Support::Interval(low, high) = support else {
        return None;
    };
    let near = 1e-6 * (high - low);
    (value - low < near || high - value < near).then(|| FileFitWarning::AtBound {
        name: name.to_string(),
        value,
        bound: if value - low < near { low } else { high },
    })
}

/// Moves an unconstrained coordinate by `step` on the log scale of its parameter.
pub(crate) fn perturb(z: &mut f64, support: Support, step: f64) {
    match support {
        // a real parameter: times exp(step), its sign kept (0 stays 0)
        Support::Real => *z *= step.exp(),
        Support::Positive | Support::Interval(..) => *z += step,
    }
}

/// Sets a free measurement variance that is a parameter alone to the output's mean
/// squared simulation error.
fn set_measurement_variances(file: &ModelFile, values: &mut [f64], rms: &[f64]) {
    let spec = file.spec();
    let free = spec.free();
    for (e, r) in spec.measurement_noise.iter().zip(rms) {
        if let crate::expr::Node::Var(crate::expr::Var::Param(k)) = e.node
            && free.contains(&k)
            && spec.parameters[k].support.contains(r * r)
        {
            values[k] = r * r;
        }
    }
}

/// `sqrt(diag(s^2 (J'J)^-1))` with `s^2 = sse / (rows - cols)`, or `None` when `J'J`
/// is numerically singular or there are no degrees of freedom left.
fn standard_errors(jacobian: &[f64], rows: usize, cols: usize, sse: f64) -> Option<Vec<f64>> {
    if rows <= cols || cols == 0 {
        return None;
    }
    let j = nalgebra::DMatrix::from_row_slice(rows, cols, jacobian);
    let info = j.transpose() * &j;
    let s2 = sse / (rows - cols) as f64;
    let chol = nalgebra::Cholesky::new(info)?;
    let inverse = chol.inverse();
    let se: Vec<f64> = (0..cols).map(|c| (s2 * inverse[(c, c)]).sqrt()).collect();
    se.iter().all(|v| v.is_finite()).then_some(se)
}

/// How the initial state of a simulation is chosen.
#[derive(Debug, Clone, PartialEq)]
pub enum InitialState {
    /// The model file's initial means.
    File,
    /// This state.
    Given(Vec<f64>),
    /// The state that minimises the squared simulation error over the first
    /// `samples` samples (Levenberg–Marquardt from the file's initial means, the
    /// parameters held), as benchmark protocols and MATLAB's `compare` do.
    Estimate {
        /// Samples at the start of the record used (at least 1).
        samples: usize,
    },
}

/// A model file's noise-free simulation of a record, scored.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationComparison {
    /// The simulated outputs, `T x p` time-major.
    pub outputs: Vec<f64>,
    /// The initial state used.
    pub initial_state: Vec<f64>,
    /// Root mean square simulation error per output (over the observed values).
    pub rms: Vec<f64>,
    /// MATLAB's fit per output.
    pub fit_percent: Vec<f64>,
}

impl ModelFile {
    /// The noise-free simulation of `steps` steps of the inputs `inputs` (time-major,
    /// `steps x m`) from `x0`, or from the file's initial means, at the file's values.
    ///
    /// # Errors
    /// See [`Simulator::run`].
    pub fn simulate_noise_free(
        &self,
        inputs: &[f64],
        steps: usize,
        x0: Option<&[f64]>,
    ) -> Result<crate::NoiseFree, SimulationError> {
        let means;
        let x0 = match x0 {
            Some(x0) => x0,
            None => {
                means = self.initial_means();
                &means
            }
        };
        let values = self.full_values(&self.free_values());
        Simulator::new(self, &[]).run(&values, x0, inputs, steps, false)
    }

    /// The initial state that minimises the squared simulation error over the first
    /// `samples` samples of `data`, the parameters at the file's values
    /// (Levenberg–Marquardt from the file's initial means).
    ///
    /// # Errors
    /// The simulation from the file's initial means diverges, or `samples` is 0.
    pub fn estimate_initial_state(
        &self,
        data: Series<'_>,
        samples: usize,
    ) -> Result<Vec<f64>, SimulationError> {
        let x0 = self.initial_means();
        let origin = || self.origin().to_string();
        if samples == 0 {
            return Err(SimulationError::InitialState {
                origin: origin(),
                states: x0.len(),
                values: Vec::new(),
            });
        }
        let head = data.head(samples);
        let inputs: Vec<f64> = (0..head.steps())
            .flat_map(|t| head.input(t).iter().copied())
            .collect();
        let sim = Simulator::new(self, &[]);
        let values = self.full_values(&self.free_values());
        sim.run(&values, &x0, &inputs, head.steps(), false)?;
        let never = || false;
        let mut problem = Problem {
            sim: &sim,
            supports: Vec::new(),
            values,
            fixed_x0: None,
            inputs: &inputs,
            data: head,
            unknowns: DVector::from_vec(x0.clone()),
            residuals: None,
            stop: &never,
            stopped: false,
        };
        if problem.scored() == 0 {
            return Ok(x0);
        }
        let start = problem.unknowns.clone();
        problem.set_params(&start);
        let (solved, report) = LevenbergMarquardt::new().minimize(problem);
        let x = solved.unknowns.as_slice().to_vec();
        let start_cost = solved
            .evaluate_at(&x0)
            .map_or(f64::INFINITY, |r| r.norm_squared());
        // never worse than the file's initial means
        Ok(
            if (2.0 * report.objective_function).is_finite()
                && 2.0 * report.objective_function <= start_cost
            {
                x
            } else {
                x0
            },
        )
    }

    /// The noise-free simulation of `data`'s inputs from the initial state `initial`,
    /// scored against its outputs from step `burn_in` (0-based) on.
    ///
    /// # Errors
    /// See [`ModelFile::estimate_initial_state`] and [`Simulator::run`].
    pub fn compare_simulation(
        &self,
        data: Series<'_>,
        initial: InitialState,
        burn_in: usize,
    ) -> Result<SimulationComparison, SimulationError> {
        let x0 = match initial {
            InitialState::File => self.initial_means(),
            InitialState::Given(x0) => x0,
            InitialState::Estimate { samples } => self.estimate_initial_state(data, samples)?,
        };
        let inputs: Vec<f64> = (0..data.steps())
            .flat_map(|t| data.input(t).iter().copied())
            .collect();
        let values = self.full_values(&self.free_values());
        let run = Simulator::new(self, &[]).run(&values, &x0, &inputs, data.steps(), false)?;
        let (fit_percent, rms) = scores(&data, &run.outputs, burn_in);
        Ok(SimulationComparison {
            outputs: run.outputs,
            initial_state: x0,
            rms,
            fit_percent,
        })
    }
}
