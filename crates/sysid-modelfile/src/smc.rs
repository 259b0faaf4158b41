//! A model file at given parameter values, as an SMC model: sampling, densities and
//! bounds for the particle filters, smoothers and samplers of `sysid-smc`.

use crate::expr::Var;
use crate::program::{Program, Values};
use crate::spec::ModelSpec;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use std::sync::Arc;
use sysid_smc::ModelError;
use sysid_smc::{
    InitialDensity, InitialSampler, ObservationDensity, ScalarGaussianKernel, StateSpace,
    TransitionBound, TransitionDensity, TransitionSampler, add_scaled_normals,
};

/// The equations of a spec, compiled once and shared by every parameter value.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Compiled {
    pub spec: ModelSpec,
    pub transition: Program,
    pub observation: Program,
}

impl Compiled {
    pub fn new(spec: ModelSpec) -> Compiled {
        let transition = Program::compile(&spec.transition.iter().collect::<Vec<_>>());
        let observation = Program::compile(&spec.observation.iter().collect::<Vec<_>>());
        Compiled {
            spec,
            transition,
            observation,
        }
    }
}

/// A Gaussian variance with its log-normaliser.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Variance {
    var: f64,
    sd: f64,
    kernel: ScalarGaussianKernel,
}

impl Variance {
    fn new(v: f64) -> Variance {
        Variance {
            var: v,
            sd: v.sqrt(),
            kernel: ScalarGaussianKernel::with_variance(v),
        }
    }
}

/// A model file's model at one parameter vector (every parameter, fixed ones
/// included, in the file's order). Cheap to build: the equations are compiled once.
#[derive(Debug, Clone, PartialEq)]
pub struct ExprSmc {
    compiled: Arc<Compiled>,
    values: Vec<f64>,
    process: Vec<Variance>,
    measurement: Vec<Variance>,
    initial_mean: Vec<f64>,
    initial_var: Vec<f64>,
}

thread_local! {
    /// The parents' states of a scalar model, gathered once per step.
    static GATHER: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
    /// Columns and registers reused across calls on one thread.
    static SCRATCH: std::cell::RefCell<(Vec<f64>, Vec<f64>, Vec<f64>)> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new(), Vec::new())) };
}

impl ExprSmc {
    /// The model at `values` (one per parameter of the spec).
    ///
    /// # Errors
    /// A noise variance that is not positive and finite, or an initial variance that is
    /// negative, at these values (the message names it).
    pub(crate) fn new(compiled: Arc<Compiled>, values: Vec<f64>) -> Result<ExprSmc, ModelError> {
        let spec = &compiled.spec;
        let lookup = |v: Var| match v {
            Var::Param(k) => values[k],
            _ => f64::NAN,
        };
        let variance = |e: &crate::expr::Expr, name: &str| -> Result<Variance, ModelError> {
            let v = e.eval(&lookup);
            if v > 0.0 && v.is_finite() {
                Ok(Variance::new(v))
            } else {
                Err(format!("the noise variance of {name} is {v}; it must be positive").into())
            }
        };
        let process = spec
            .process_noise
            .iter()
            .zip(&spec.states)
            .map(|(e, n)| variance(e, n))
            .collect::<Result<Vec<_>, _>>()?;
        let measurement = spec
            .measurement_noise
            .iter()
            .zip(&spec.outputs)
            .map(|(e, n)| variance(e, n))
            .collect::<Result<Vec<_>, _>>()?;
        let initial_mean: Vec<f64> = spec.initial_mean.iter().map(|e| e.eval(&lookup)).collect();
        let initial_var: Vec<f64> = spec
            .initial_variance
            .iter()
            .map(|e| e.eval(&lookup))
            .collect();
        for (k, (&m, &v)) in initial_mean.iter().zip(&initial_var).enumerate() {
            if !(m.is_finite() && v.is_finite() && v >= 0.0) {
                return Err(format!(
                    "the initial law of {} is N({m}, {v}); it needs a finite mean and a \
                     non-negative variance",
                    spec.states[k]
                )
                .into());
            }
        }
        Ok(ExprSmc {
            compiled,
            values,
            process,
            measurement,
            initial_mean,
            initial_var,
        })
    }

    /// The spec this model runs.
    pub fn spec(&self) -> &ModelSpec {
        &self.compiled.spec
    }

    /// Every parameter's value, in the file's order.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Simulates `steps` samples with the inputs `inputs` (time-major, `steps x m`;
    /// empty without inputs) from the random stream `(seed, 0)`: per step the
    /// measurement noise, then the process noise. Returns the states and the outputs,
    /// time-major (`steps x n`, `steps x p`).
    ///
    /// # Errors
    /// `inputs` of the wrong length, or a state or output that is not finite (the
    /// model diverged: the message gives the step).
    pub fn simulate(
        &self,
        steps: usize,
        inputs: &[f64],
        seed: u64,
    ) -> Result<(Vec<f64>, Vec<f64>), ModelError> {
        let sds: Vec<f64> = self.measurement.iter().map(|v| v.sd).collect();
        let spec = &self.compiled.spec;
        let observation = |t: usize, x: &[f64], u: &[f64], out: &mut [f64]| {
            let lookup = self.lookup(t, u, x);
            for (o, g) in out.iter_mut().zip(&spec.observation) {
                *o = g.eval(&lookup);
            }
        };
        crate::shared::simulate(
            self,
            (steps, inputs, self.input_dim()),
            &sds,
            seed,
            observation,
        )
    }

    /// Number of outputs.
    pub fn output_dim(&self) -> usize {
        self.measurement.len()
    }

    /// The value of `e` at state `x`, input `u`, time `t` and these parameters.
    pub(crate) fn eval(&self, e: &crate::expr::Expr, t: usize, u: &[f64], x: &[f64]) -> f64 {
        e.eval(&self.lookup(t, u, x))
    }

    /// The process-noise variances.
    pub(crate) fn process_variances(&self) -> impl Iterator<Item = f64> + '_ {
        self.process.iter().map(|v| v.var)
    }

    /// The measurement-noise variances.
    pub(crate) fn measurement_variances(&self) -> impl Iterator<Item = f64> + '_ {
        self.measurement.iter().map(|v| v.var)
    }

    /// The initial means and variances.
    pub(crate) fn initial_law(&self) -> (&[f64], &[f64]) {
        (&self.initial_mean, &self.initial_var)
    }

    /// Number of inputs.
    pub fn input_dim(&self) -> usize {
        self.compiled.spec.inputs.len()
    }

    #[inline]
    fn lookup<'a>(&'a self, t: usize, u: &'a [f64], x: &'a [f64]) -> impl Fn(Var) -> f64 + 'a {
        move |v| match v {
            Var::State(i) => x[i],
            Var::Input(i) => u[i],
            Var::Time => t as f64,
            Var::Param(k) => self.values[k],
        }
    }

    /// The transition mean of state `i` at `x` (the tree, for single evaluations).
    fn transition_mean(&self, i: usize, t: usize, x: &[f64], u: &[f64]) -> f64 {
        self.compiled.spec.transition[i].eval(&self.lookup(t, u, x))
    }

    /// Runs `program` over particle-major `states` at step `t`.
    fn over_lanes<T>(
        &self,
        program: &Program,
        t: usize,
        u: &[f64],
        states: &[f64],
        use_results: impl for<'v> FnOnce(&'v dyn Fn(usize) -> Values<'v>, usize) -> T,
    ) -> T {
        with_lanes(
            program,
            self.state_dim(),
            &self.lookup(t, u, &[]),
            states,
            use_results,
        )
    }

    /// Writes the transition means of particle-major `from` (state by state,
    /// `means[i * lanes + k]`).
    fn transition_means(&self, t: usize, u: &[f64], from: &[f64], means: &mut Vec<f64>) {
        let n = self.state_dim();
        self.over_lanes(&self.compiled.transition, t, u, from, |view, lanes| {
            means.clear();
            for i in 0..n {
                match view(i) {
                    Values::Lanes(v) => means.extend_from_slice(v),
                    Values::Scalar(s) => means.extend(std::iter::repeat_n(s, lanes)),
                }
            }
        });
    }
}

/// Runs `program` over the particle-major `states` (`n` per particle), the uniform
/// values from `lookup`, then calls `use_results` with a view of each result and the
/// number of lanes.
pub(crate) fn with_lanes<T>(
    program: &Program,
    n: usize,
    lookup: &impl Fn(Var) -> f64,
    states: &[f64],
    use_results: impl for<'v> FnOnce(&'v dyn Fn(usize) -> Values<'v>, usize) -> T,
) -> T {
    let lanes = states.len() / n;
    SCRATCH.with(|cell| {
        let mut guard = cell.borrow_mut();
        let (columns, regs, slots) = &mut *guard;
        program.uniforms(lookup, slots);
        // a scalar state is its own column (no copy, no allocation)
        let one = [states];
        let many: Vec<&[f64]>;
        let cols: &[&[f64]] = if n == 1 {
            &one
        } else {
            columns.resize(n * lanes, 0.0);
            for (k, x) in states.chunks_exact(n).enumerate() {
                for (i, &v) in x.iter().enumerate() {
                    columns[i * lanes + k] = v;
                }
            }
            many = columns.chunks_exact(lanes.max(1)).take(n).collect();
            &many
        };
        program.run(cols, lanes, slots, regs);
        let view = |k: usize| program.result(k, cols, lanes, slots, regs);
        use_results(&view, lanes)
    })
}

impl StateSpace for ExprSmc {
    fn state_dim(&self) -> usize {
        self.process.len()
    }
}

impl InitialSampler for ExprSmc {
    fn sample_initial<R: Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
        for ((xi, &m), &v) in x.iter_mut().zip(&self.initial_mean).zip(&self.initial_var) {
            let z: f64 = StandardNormal.sample(rng);
            *xi = m + v.sqrt() * z;
        }
    }
}

impl InitialDensity for ExprSmc {
    /// The product of the states' normal densities; a state of initial variance 0 is
    /// a point mass (log-density 0 at its mean, `-inf` elsewhere).
    fn log_initial(&self, x: &[f64]) -> f64 {
        crate::shared::log_initial(x, &self.initial_mean, &self.initial_var)
    }
}

impl TransitionSampler for ExprSmc {
    fn sample_transition<R: Rng + ?Sized>(
        &self,
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
        rng: &mut R,
    ) {
        for (i, nx) in next.iter_mut().enumerate() {
            let z: f64 = StandardNormal.sample(rng);
            *nx = self.transition_mean(i, t, x, u) + self.process[i].sd * z;
        }
    }

    /// The means by the compiled program over all particles, then each state's noise
    /// by `add_scaled_normals` (state by state).
    fn sample_transitions<R: Rng + ?Sized>(
        &self,
        t: usize,
        u: &[f64],
        from: &[f64],
        parents: &[usize],
        next: &mut [f64],
        rng: &mut R,
    ) {
        let n = self.state_dim();
        if n == 1 {
            // gather the parents, then the means straight into `next`
            GATHER.with(|cell| {
                let mut gathered = cell.borrow_mut();
                gathered.clear();
                gathered.extend(parents.iter().map(|&p| from[p]));
                let uniforms = self.lookup(t, u, &[]);
                with_lanes(
                    &self.compiled.transition,
                    1,
                    &uniforms,
                    &gathered,
                    |view, _| match view(0) {
                        Values::Lanes(means) => next.copy_from_slice(means),
                        Values::Scalar(mean) => next.fill(mean),
                    },
                );
            });
            add_scaled_normals(rng, self.process[0].sd, next);
            return;
        }
        // gather the parents into `next`, then compute the means by state
        for (x, &p) in next.chunks_exact_mut(n).zip(parents) {
            x.copy_from_slice(&from[p * n..(p + 1) * n]);
        }
        let mut means = Vec::new();
        self.transition_means(t, u, next, &mut means);
        let lanes = parents.len();
        for (i, column) in means.chunks_exact_mut(lanes).enumerate() {
            add_scaled_normals(rng, self.process[i].sd, column);
        }
        for (k, x) in next.chunks_exact_mut(n).enumerate() {
            for (i, xi) in x.iter_mut().enumerate() {
                *xi = means[i * lanes + k];
            }
        }
    }
}

impl ObservationDensity for ExprSmc {
    fn log_observation(&self, t: usize, x: &[f64], u: &[f64], y: &[f64]) -> f64 {
        let lookup = self.lookup(t, u, x);
        let mut total = 0.0;
        for ((g, noise), &yj) in self
            .compiled
            .spec
            .observation
            .iter()
            .zip(&self.measurement)
            .zip(y)
        {
            if !yj.is_nan() {
                total += noise.kernel.log_density(g.eval(&lookup), yj);
            }
        }
        total
    }

    fn log_observations(&self, t: usize, u: &[f64], y: &[f64], states: &[f64], out: &mut [f64]) {
        self.over_lanes(&self.compiled.observation, t, u, states, |view, _| {
            out.fill(0.0);
            for (j, (noise, &yj)) in self.measurement.iter().zip(y).enumerate() {
                if yj.is_nan() {
                    continue;
                }
                let k = noise.kernel;
                match view(j) {
                    Values::Lanes(means) => {
                        for (o, &m) in out.iter_mut().zip(means) {
                            *o += k.log_density(m, yj);
                        }
                    }
                    Values::Scalar(m) => {
                        let v = k.log_density(m, yj);
                        out.iter_mut().for_each(|o| *o += v);
                    }
                }
            }
        });
    }
}

impl TransitionDensity for ExprSmc {
    fn log_transition(&self, t: usize, x: &[f64], u: &[f64], next: &[f64]) -> f64 {
        let lookup = self.lookup(t, u, x);
        self.compiled
            .spec
            .transition
            .iter()
            .zip(&self.process)
            .zip(next)
            .map(|((f, noise), &xn)| noise.kernel.log_density(f.eval(&lookup), xn))
            .sum()
    }

    fn log_transition_matrix(
        &self,
        t: usize,
        u: &[f64],
        from: &[f64],
        to: &[f64],
        out: &mut [f64],
        scratch: &mut Vec<f64>,
    ) {
        let n = self.state_dim();
        self.transition_means(t, u, from, scratch);
        let m = from.len() / n;
        if n == 1 {
            self.process[0].kernel.log_density_matrix(scratch, to, out);
            return;
        }
        for (row, next) in out.chunks_exact_mut(m).zip(to.chunks_exact(n)) {
            row.fill(0.0);
            for (i, noise) in self.process.iter().enumerate() {
                let means = &scratch[i * m..(i + 1) * m];
                for (value, &mean) in row.iter_mut().zip(means) {
                    *value += noise.kernel.log_density(mean, next[i]);
                }
            }
        }
    }

    fn scalar_gaussian_means(
        &self,
        t: usize,
        u: &[f64],
        from: &[f64],
        means: &mut Vec<f64>,
    ) -> Option<ScalarGaussianKernel> {
        if self.state_dim() != 1 {
            return None;
        }
        self.transition_means(t, u, from, means);
        Some(self.process[0].kernel)
    }
}

impl TransitionBound for ExprSmc {
    fn log_transition_bound(&self, _t: usize, _u: &[f64]) -> f64 {
        self.process.iter().map(|p| p.kernel.log_norm).sum()
    }
}
