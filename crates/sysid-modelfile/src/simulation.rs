//! The noise-free simulation of a model file from its inputs alone, its sensitivities
//! to the parameters and the initial state, and the initial state that best explains
//! the first samples of a record.
//!
//! # Model
//! ```text
//! x_{t+1} = f(x_t, u_t, t; theta),   yhat_t = g(x_t, u_t, t; theta),   x_0 given
//! ```
//! the model file's equations with every noise term set to zero.
//!
//! # Algorithm
//! The sensitivities `S_t = d x_t / d (theta, x_0)` follow the forward recursion
//! ```text
//! S_0 = [0  I],   S_{t+1} = F_x S_t + [F_theta  0],   d yhat_t = G_x S_t + [G_theta  0]
//! ```
//! with the partial derivatives `F_x`, `F_theta`, `G_x`, `G_theta` taken symbolically
//! once ([`Expr::derivative`]; at a kink of `abs`, `min` or `max` the average of the two
//! sides) and evaluated along the trajectory.
//!
//! # Complexity
//! `O(T (n + p) (n + k))` expression evaluations for `T` steps, `n` states, `p`
//! outputs and `k` parameters; without sensitivities `O(T (n + p))`.

use crate::ModelFile;
use crate::expr::{Expr, Node, Var};

/// Why a noise-free simulation could not be run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SimulationError {
    /// The inputs do not match the model's input count and the steps.
    #[error(
        "{origin}: the inputs have {found} values; {steps} steps of {inputs} inputs need {expected}"
    )]
    Inputs {
        /// The model file.
        origin: String,
        /// Steps asked for.
        steps: usize,
        /// The model's input count.
        inputs: usize,
        /// Values needed.
        expected: usize,
        /// Values given.
        found: usize,
    },
    /// An initial state of the wrong length or not finite.
    #[error("{origin}: the initial state {values:?} needs {states} finite values")]
    InitialState {
        /// The model file.
        origin: String,
        /// The model's state count.
        states: usize,
        /// What was given.
        values: Vec<f64>,
    },
    /// The simulation left the finite numbers: the model diverged from this start.
    #[error(
        "{origin}: the noise-free simulation is not finite at t = {t}: {what} = {value} \
         (the model diverges from this initial state and these parameters)"
    )]
    Diverged {
        /// The model file.
        origin: String,
        /// The 0-based step.
        t: usize,
        /// The state or output (or its sensitivity) that is not finite.
        what: String,
        /// Its value.
        value: f64,
    },
}

/// A noise-free simulation: states and outputs, time-major.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseFree {
    /// `x_0 .. x_{T-1}`, `T x n`.
    pub states: Vec<f64>,
    /// `yhat_0 .. yhat_{T-1}`, `T x p`.
    pub outputs: Vec<f64>,
    /// `d yhat / d (theta, x_0)`, `(T p) x (k + n)` row-major, when asked for.
    pub jacobian: Option<Vec<f64>>,
}

/// `d e / d v` for each variable of a list, with the zero ones left out.
type Partials = Vec<(usize, Expr)>;

fn partials(e: &Expr, vars: &[Var]) -> Partials {
    vars.iter()
        .enumerate()
        .filter_map(|(j, &v)| {
            let d = e.derivative(v);
            (d.node != Node::Num(0.0)).then_some((j, d))
        })
        .collect()
}

/// A model file's noise-free simulation with sensitivities to chosen parameters.
#[derive(Debug, Clone)]
pub struct Simulator {
    file: ModelFile,
    /// The parameters (indices in the file) the sensitivities are taken for.
    params: Vec<usize>,
    fx: Vec<Partials>,
    fp: Vec<Partials>,
    gx: Vec<Partials>,
    gp: Vec<Partials>,
}

impl Simulator {
    /// The simulator of `file`, with sensitivities to the parameters `params`
    /// (indices among every parameter of the file, fixed ones included).
    pub fn new(file: &ModelFile, params: &[usize]) -> Simulator {
        let spec = file.spec();
        let states: Vec<Var> = (0..spec.states.len()).map(Var::State).collect();
        let pvars: Vec<Var> = params.iter().map(|&k| Var::Param(k)).collect();
        let over = |es: &[Expr], vars: &[Var]| es.iter().map(|e| partials(e, vars)).collect();
        Simulator {
            file: file.clone(),
            params: params.to_vec(),
            fx: over(&spec.transition, &states),
            fp: over(&spec.transition, &pvars),
            gx: over(&spec.observation, &states),
            gp: over(&spec.observation, &pvars),
        }
    }

    /// The parameters that the noise-free simulation depends on: every free parameter
    /// used by a transition or observation equation (indices in the file).
    pub fn simulated_parameters(file: &ModelFile) -> Vec<usize> {
        let spec = file.spec();
        spec.free()
            .into_iter()
            .filter(|&k| {
                let var = Var::Param(k);
                spec.transition.iter().any(|e| e.uses(var))
                    || spec.observation.iter().any(|e| e.uses(var))
            })
            .collect()
    }

    /// The model file.
    pub fn file(&self) -> &ModelFile {
        &self.file
    }

    /// The parameters the sensitivities are taken for (indices in the file).
    pub fn params(&self) -> &[usize] {
        &self.params
    }

    /// Simulates `steps` samples with every parameter at `values` (the file's order,
    /// fixed ones included) from `x0`; `inputs` is time-major (`steps x m`). With
    /// `jacobian`, also `d yhat / d (params, x_0)`.
    ///
    /// # Errors
    /// Inputs or an initial state of the wrong size; [`SimulationError::Diverged`].
    pub fn run(
        &self,
        values: &[f64],
        x0: &[f64],
        inputs: &[f64],
        steps: usize,
        jacobian: bool,
    ) -> Result<NoiseFree, SimulationError> {
        let spec = self.file.spec();
        let origin = || self.file.origin().to_string();
        let (n, p, m) = (spec.states.len(), spec.outputs.len(), spec.inputs.len());
        if inputs.len() != steps * m {
            return Err(SimulationError::Inputs {
                origin: origin(),
                steps,
                inputs: m,
                expected: steps * m,
                found: inputs.len(),
            });
        }
        if x0.len() != n || x0.iter().any(|v| !v.is_finite()) {
            return Err(SimulationError::InitialState {
                origin: origin(),
                states: n,
                values: x0.to_vec(),
            });
        }
        let k = self.params.len();
        let cols = k + n;
        let mut states = Vec::with_capacity(steps * n);
        let mut outputs = Vec::with_capacity(steps * p);
        let mut jac = if jacobian {
            Vec::with_capacity(steps * p * cols)
        } else {
            Vec::new()
        };
        // S = d x_t / d (theta, x0), n x cols
        let mut s = vec![0.0; n * cols];
        for i in 0..n {
            s[i * cols + k + i] = 1.0;
        }
        let mut next_s = vec![0.0; n * cols];
        let mut x = x0.to_vec();
        let mut next_x = vec![0.0; n];
        let diverged = |t: usize, what: String, value: f64| SimulationError::Diverged {
            origin: origin(),
            t,
            what,
            value,
        };
        for t in 0..steps {
            let u = &inputs[t * m..(t + 1) * m];
            let lookup = |v: Var| match v {
                Var::State(i) => x[i],
                Var::Input(i) => u[i],
                Var::Time => t as f64,
                Var::Param(k) => values[k],
            };
            states.extend_from_slice(&x);
            for (j, g) in spec.observation.iter().enumerate() {
                let y = g.eval(&lookup);
                if !y.is_finite() {
                    return Err(diverged(t, spec.outputs[j].clone(), y));
                }
                outputs.push(y);
                if jacobian {
                    let row = jac.len();
                    jac.resize(row + cols, 0.0);
                    chain_row(&self.gx[j], &self.gp[j], &s, cols, &lookup, &mut jac[row..]);
                    if let Some(bad) = jac[row..].iter().find(|v| !v.is_finite()) {
                        return Err(diverged(
                            t,
                            format!("d {} / d parameters", spec.outputs[j]),
                            *bad,
                        ));
                    }
                }
            }
            if t + 1 == steps {
                break;
            }
            for (i, f) in spec.transition.iter().enumerate() {
                let v = f.eval(&lookup);
                if !v.is_finite() {
                    return Err(diverged(t + 1, spec.states[i].clone(), v));
                }
                next_x[i] = v;
                if jacobian {
                    let row = &mut next_s[i * cols..(i + 1) * cols];
                    row.fill(0.0);
                    chain_row(&self.fx[i], &self.fp[i], &s, cols, &lookup, row);
                    if let Some(bad) = row.iter().find(|v| !v.is_finite()) {
                        return Err(diverged(
                            t + 1,
                            format!("d {} / d parameters", spec.states[i]),
                            *bad,
                        ));
                    }
                }
            }
            std::mem::swap(&mut x, &mut next_x);
            std::mem::swap(&mut s, &mut next_s);
        }
        Ok(NoiseFree {
            states,
            outputs,
            jacobian: jacobian.then_some(jac),
        })
    }
}

/// `row = sum_j d e / d x_j * S[j, :] + d e / d theta` (the parameter columns first).
fn chain_row(
    dx: &Partials,
    dp: &Partials,
    s: &[f64],
    cols: usize,
    lookup: &impl Fn(Var) -> f64,
    row: &mut [f64],
) {
    for (j, d) in dx {
        let a = d.eval(lookup);
        for (r, sv) in row.iter_mut().zip(&s[j * cols..(j + 1) * cols]) {
            *r += a * sv;
        }
    }
    for (j, d) in dp {
        row[*j] += d.eval(lookup);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TANKS: &str = r#"
format = 1
states = ["h1", "h2"]
inputs = ["u"]
outputs = ["y"]
[parameters]
k1 = { value = 0.2 }
k2 = { value = 0.15 }
k3 = { value = 0.2 }
kp = { value = 0.2 }
top = { value = 9.0 }
r = { value = 0.01 }
[transition]
h1 = "min(h1 - k1*sqrt(abs(h1)) + kp*u, top)"
h2 = "h2 + k2*sqrt(abs(h1)) - k3*sqrt(abs(h2)) + max(h1 - k1*sqrt(abs(h1)) + kp*u - top, 0)"
[observation]
y = "min(h2, 10)"
[noise]
h1 = 0.01
h2 = 0.01
y = "r"
[initial]
h1 = { mean = 5, variance = 1 }
h2 = { mean = 4, variance = 1 }
"#;

    fn inputs(steps: usize) -> Vec<f64> {
        (0..steps)
            .map(|t| 3.0 + 2.5 * (t as f64 * 0.07).sin())
            .collect()
    }

    #[test]
    fn sensitivities_match_central_differences() {
        let file = ModelFile::parse(TANKS, "tanks.toml").unwrap();
        let params = Simulator::simulated_parameters(&file);
        assert_eq!(params.len(), 5, "r is not simulated");
        let sim = Simulator::new(&file, &params);
        let values = file.full_values(&file.free_values());
        let (x0, u) = ([5.0, 4.0], inputs(80));
        let run = sim.run(&values, &x0, &u, 80, true).unwrap();
        let jac = run.jacobian.unwrap();
        let cols = params.len() + 2;
        let h = 1e-6;
        for c in 0..cols {
            let (mut vp, mut vm, mut xp, mut xm) = (values.clone(), values.clone(), x0, x0);
            if c < params.len() {
                vp[params[c]] += h;
                vm[params[c]] -= h;
            } else {
                xp[c - params.len()] += h;
                xm[c - params.len()] -= h;
            }
            let up = sim.run(&vp, &xp, &u, 80, false).unwrap().outputs;
            let down = sim.run(&vm, &xm, &u, 80, false).unwrap().outputs;
            for t in 0..80 {
                let fd = (up[t] - down[t]) / (2.0 * h);
                let exact = jac[t * cols + c];
                assert!(
                    (fd - exact).abs() <= 1e-5 * (1.0 + exact.abs()),
                    "t {t} column {c}: {exact} against {fd}"
                );
            }
        }
    }

    #[test]
    fn wrong_sizes_and_divergence_are_errors() {
        let file = ModelFile::parse(TANKS, "tanks.toml").unwrap();
        let sim = Simulator::new(&file, &[]);
        let values = file.full_values(&file.free_values());
        assert!(matches!(
            sim.run(&values, &[1.0, 1.0], &[1.0; 3], 4, false),
            Err(SimulationError::Inputs {
                expected: 4,
                found: 3,
                ..
            })
        ));
        assert!(matches!(
            sim.run(&values, &[1.0, f64::NAN], &[1.0; 4], 4, false),
            Err(SimulationError::InitialState { .. })
        ));
        let mut wild = values.clone();
        // no cap on h1 and a pump that doubles the largest float: h1 overflows at t = 2
        wild[3] = f64::MAX;
        wild[4] = f64::INFINITY;
        let e = sim
            .run(&wild, &[1.0, 1.0], &[1.0; 4], 4, false)
            .unwrap_err();
        assert!(
            matches!(&e, SimulationError::Diverged { t: 2, what, .. } if what == "h1"),
            "{e}"
        );
    }
}
