//! A model file whose equations are affine in the free parameters, in the form of
//! `sysid_em::affine` (closed-form particle EM, seed 000).
//!
//! # Model
//! Each equation is rewritten as `sum_k theta_k alpha_k(x, u, t) + alpha_0(x, u, t)`
//! (symbolically: products and quotients by expressions free of the parameters,
//! sums, differences), so that
//! ```text
//! [x_{t+1}; y_t] = beta alpha(x_t, u_t, t) + noise
//! ```
//! with one regressor per (equation, parameter) and a known coefficient 1 on each
//! equation's remainder `alpha_0` (held: never estimated).
//!
//! It qualifies when: every free parameter of the equations enters them linearly (it
//! may appear in several equations, as an outflow coefficient shared by two tanks, and
//! it may have bounds); each noise variance is either a free parameter of its own or
//! free of parameters (a block may mix the two); the initial law has no free
//! parameter. [`ModelFile::why_not_affine`] says which rule a model breaks.
//!
//! A shared or bounded coefficient, or a noise block that mixes free and fixed
//! variances, makes the form carry [`AffineConstraints`]: the M-step is then the
//! constrained one of `sysid_em::affine` (weighted least squares over the shared
//! coefficients, bounded, alternated with the free variances), still closed form.
//! Bounds are honoured as closed bounds moved inside the file's open support by
//! `1e-9` of their size (at least `1e-9`), so an estimate on a bound stays valid.

use crate::ModelFile;
use crate::expr::{BinOp, Expr, Node, Var};
use crate::program::Program;
use crate::smc::{ExprSmc, with_lanes};
use nalgebra::{DMatrix, DVector};
use sysid_em::affine::{
    AffineConstraints, AffineEmError, AffineEmSpec, AffineModel, AffineParams, CoefficientSlot,
    TiedCoefficient,
};
use sysid_em::linear::Covariance;
use sysid_pmcmc::Support;
use sysid_smc::ModelError;

/// `e` as `sum_k coef_k * param_k + rest`: the terms by parameter (`None`: the rest).
type LinearForm = Vec<(Option<usize>, Expr)>;

fn mul(a: Expr, b: &Expr) -> Expr {
    match (&a.node, &b.node) {
        (Node::Num(x), _) if *x == 1.0 => b.clone(),
        (_, Node::Num(y)) if *y == 1.0 => a,
        _ => Expr::bin(BinOp::Mul, a, b.clone()),
    }
}

fn add_term(form: &mut LinearForm, key: Option<usize>, term: Expr) {
    if let Some((_, e)) = form.iter_mut().find(|(k, _)| *k == key) {
        let previous = std::mem::replace(e, Expr::num(0.0));
        *e = Expr::bin(BinOp::Add, previous, term);
    } else {
        form.push((key, term));
    }
}

/// The linear form of `e` in the parameters for which `free` is true, or why it has
/// none.
fn linear_form(
    e: &Expr,
    free: &dyn Fn(usize) -> bool,
    name: &dyn Fn(usize) -> String,
) -> Result<LinearForm, ModelError> {
    let has_free = |e: &Expr| e.any(&|s| matches!(s.node, Node::Var(Var::Param(k)) if free(k)));
    if !has_free(e) {
        return Ok(vec![(None, e.clone())]);
    }
    match &e.node {
        Node::Var(Var::Param(k)) => Ok(vec![(Some(*k), Expr::num(1.0))]),
        Node::Neg(a) => Ok(linear_form(a, free, name)?
            .into_iter()
            .map(|(k, c)| (k, Expr::negated(c)))
            .collect()),
        Node::Bin(op @ (BinOp::Add | BinOp::Sub), a, b) => {
            let mut form = linear_form(a, free, name)?;
            for (k, c) in linear_form(b, free, name)? {
                let c = if *op == BinOp::Sub {
                    Expr::negated(c)
                } else {
                    c
                };
                add_term(&mut form, k, c);
            }
            Ok(form)
        }
        Node::Bin(BinOp::Mul, a, b) if !has_free(a) => Ok(linear_form(b, free, name)?
            .into_iter()
            .map(|(k, c)| (k, mul((**a).clone(), &c)))
            .collect()),
        Node::Bin(BinOp::Mul, a, b) if !has_free(b) => Ok(linear_form(a, free, name)?
            .into_iter()
            .map(|(k, c)| (k, mul(c, b)))
            .collect()),
        Node::Bin(BinOp::Div, a, b) if !has_free(b) => Ok(linear_form(a, free, name)?
            .into_iter()
            .map(|(k, c)| (k, Expr::bin(BinOp::Div, c, (**b).clone())))
            .collect()),
        _ => {
            let k = (0..)
                .find(|&k| e.uses(Var::Param(k)) && free(k))
                .unwrap_or(0);
            Err(format!(
                "the free parameter {} enters nonlinearly (a product of parameters, a \
                 power, a quotient by or a function of a parameter)",
                name(k)
            )
            .into())
        }
    }
}

/// Where a free parameter sits in the affine parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Slot {
    /// `beta_x[(row, col)]`.
    StateCoef(usize, usize),
    /// `beta_y[(row, col)]`.
    OutputCoef(usize, usize),
    /// `Pi_x[(i, i)]`.
    ProcessVar(usize),
    /// `Pi_y[(j, j)]`.
    MeasurementVar(usize),
}

/// The affine form of a model file (see the module documentation).
#[derive(Debug, Clone)]
pub struct ExprAffine {
    file: ModelFile,
    regressors: Vec<Expr>,
    program: Program,
    state_structure: Vec<Vec<usize>>,
    output_structure: Vec<Vec<usize>>,
    state_held: Vec<Vec<usize>>,
    output_held: Vec<Vec<usize>>,
    /// By parameter index (all parameters; empty for fixed ones): where it sits, once
    /// per equation that uses it.
    slots: Vec<Vec<Slot>>,
    spec: AffineEmSpec,
    /// Shared or bounded coefficients, mixed noise blocks; `None` when there are none.
    constraints: Option<AffineConstraints>,
}

/// A parameter's support as closed bounds just inside it (see the module docs).
fn closed_bounds(support: Support) -> (f64, f64) {
    let inside = |b: f64| 1e-9 * b.abs().max(1.0);
    match support {
        Support::Real => (f64::NEG_INFINITY, f64::INFINITY),
        Support::Positive => (inside(0.0), f64::INFINITY),
        Support::Interval(a, b) => (a + inside(a), b - inside(b)),
    }
}

impl ExprAffine {
    /// The affine form of `file`, or which rule it breaks.
    pub(crate) fn new(file: ModelFile) -> Result<ExprAffine, ModelError> {
        let spec = file.spec();
        let params = &spec.parameters;
        let free = |k: usize| !params[k].fixed;
        let name = |k: usize| params[k].name.clone();
        let mut slots: Vec<Vec<Slot>> = vec![Vec::new(); params.len()];
        let mut regressors: Vec<Expr> = Vec::new();
        let (n, p) = (spec.states.len(), spec.outputs.len());
        let mut structures = vec![Vec::new(); n + p];
        let mut held = vec![Vec::new(); n + p];
        let rows = spec.transition.iter().chain(&spec.observation);
        for (row, e) in rows.enumerate() {
            for (key, coef) in linear_form(e, &free, &name)? {
                let col = regressors.len();
                regressors.push(coef);
                structures[row].push(col);
                match key {
                    None => held[row].push(col),
                    Some(k) => slots[k].push(if row < n {
                        Slot::StateCoef(row, col)
                    } else {
                        Slot::OutputCoef(row - n, col)
                    }),
                }
            }
        }
        // each free variance: a slot of its own; a block with some free is estimated
        // diagonally, its fixed entries held
        let block = |variances: &[Expr],
                     block: &str,
                     slot: fn(usize) -> Slot,
                     slots: &mut Vec<Vec<Slot>>|
         -> Result<(Covariance, Vec<usize>), ModelError> {
            let mut fixed = Vec::new();
            for (i, v) in variances.iter().enumerate() {
                match v.node {
                    Node::Var(Var::Param(k)) if free(k) => {
                        if !slots[k].is_empty() {
                            return Err(format!(
                                "the free parameter {} is a noise variance and appears \
                                 elsewhere too",
                                name(k)
                            )
                            .into());
                        }
                        slots[k].push(slot(i));
                    }
                    _ if v.any(&|s| matches!(s.node, Node::Var(Var::Param(k)) if free(k))) => {
                        return Err(format!(
                            "a {block} noise variance is an expression of free parameters \
                             (the closed-form M-step needs each variance to be a free \
                             parameter of its own, or fixed)"
                        )
                        .into());
                    }
                    _ => fixed.push(i),
                }
            }
            Ok(if fixed.len() == variances.len() {
                (Covariance::Fixed, Vec::new())
            } else {
                (Covariance::Diagonal, fixed)
            })
        };
        let (pi_x, held_process) =
            block(&spec.process_noise, "process", Slot::ProcessVar, &mut slots)?;
        let (pi_y, held_measurement) = block(
            &spec.measurement_noise,
            "measurement",
            Slot::MeasurementVar,
            &mut slots,
        )?;
        let mut tied = Vec::new();
        let mut needs_constraints = !held_process.is_empty() || !held_measurement.is_empty();
        for (k, ks) in slots.iter().enumerate() {
            let coefficients: Vec<CoefficientSlot> = ks
                .iter()
                .filter_map(|s| match *s {
                    Slot::StateCoef(row, col) => Some(CoefficientSlot::State { row, col }),
                    Slot::OutputCoef(row, col) => Some(CoefficientSlot::Output { row, col }),
                    _ => None,
                })
                .collect();
            if coefficients.is_empty() {
                continue;
            }
            let (lower, upper) = closed_bounds(params[k].support);
            needs_constraints |= coefficients.len() > 1 || params[k].support != Support::Real;
            tied.push(TiedCoefficient {
                slots: coefficients,
                lower,
                upper,
            });
        }
        let constraints = needs_constraints.then_some(AffineConstraints {
            coefficients: tied,
            held_process_variances: held_process,
            held_measurement_variances: held_measurement,
        });
        let initial_free = spec
            .initial_mean
            .iter()
            .chain(&spec.initial_variance)
            .any(|e| e.any(&|s| matches!(s.node, Node::Var(Var::Param(k)) if free(k))));
        if initial_free {
            return Err(
                "the initial law has a free parameter (the closed-form particle EM \
                        holds the initial law)"
                    .into(),
            );
        }
        let program = Program::compile(&regressors.iter().collect::<Vec<_>>());
        let output_structure = structures.split_off(n);
        let output_held = held.split_off(n);
        Ok(ExprAffine {
            spec: AffineEmSpec {
                beta_x: true,
                beta_y: true,
                pi_x,
                pi_y,
                initial_state: false,
            },
            file,
            regressors,
            program,
            state_structure: structures,
            output_structure,
            state_held: held,
            output_held,
            slots,
            constraints,
        })
    }

    /// What EM estimates: coefficients, and each noise block diagonal or held.
    pub fn em_spec(&self) -> AffineEmSpec {
        self.spec
    }

    /// The model file.
    pub fn file(&self) -> &ModelFile {
        &self.file
    }

    /// Where parameter `k` (an index of all the file's parameters) sits, once per
    /// equation that uses it; empty for a fixed one.
    pub(crate) fn slots(&self, k: usize) -> &[Slot] {
        &self.slots[k]
    }

    /// The bounded coefficients among the free values `theta` that sit on a bound:
    /// (index in the file's parameters, value, the file's bound). The M-step's closed
    /// bounds are `1e-9` inside the file's open ones; a value within `1e-7` of the
    /// file's bound is on it (an average of iterates that left the bound is further).
    pub(crate) fn on_bounds(&self, theta: &[f64]) -> Vec<(usize, f64, f64)> {
        let spec = self.file.spec();
        let values = self.file.full_values(theta);
        let mut out = Vec::new();
        for (k, slots) in self.slots.iter().enumerate() {
            let coefficient = slots
                .iter()
                .any(|s| matches!(s, Slot::StateCoef(..) | Slot::OutputCoef(..)));
            let (low, high) = match spec.parameters[k].support {
                Support::Real => continue,
                Support::Positive => (0.0, f64::INFINITY),
                Support::Interval(a, b) => (a, b),
            };
            if !coefficient {
                continue;
            }
            let v = values[k];
            let near = |b: f64| (v - b).abs() <= 1e-7 * b.abs().max(1.0);
            if near(low) {
                out.push((k, v, low));
            } else if high.is_finite() && near(high) {
                out.push((k, v, high));
            }
        }
        out
    }

    /// The regressors as text (for messages and the docs).
    pub fn regressor_texts(&self) -> Vec<String> {
        let spec = self.file.spec();
        self.regressors
            .iter()
            .map(|e| e.display(&|v| spec.var_name(v)).to_string())
            .collect()
    }

    /// The affine parameters of the free parameters `theta` (fixed ones from the file).
    pub fn params(&self, theta: &[f64]) -> Result<AffineParams, ModelError> {
        self.file.at(theta)?;
        let values = self.file.full_values(theta);
        let spec = self.file.spec();
        let (n, p, r) = (spec.states.len(), spec.outputs.len(), self.regressors.len());
        let mut beta_x = DMatrix::zeros(n, r);
        let mut beta_y = DMatrix::zeros(p, r);
        for (row, cols) in self.state_held.iter().enumerate() {
            for &c in cols {
                beta_x[(row, c)] = 1.0;
            }
        }
        for (row, cols) in self.output_held.iter().enumerate() {
            for &c in cols {
                beta_y[(row, c)] = 1.0;
            }
        }
        for (slots, &v) in self.slots.iter().zip(&values) {
            for slot in slots {
                match slot {
                    Slot::StateCoef(i, c) => beta_x[(*i, *c)] = v,
                    Slot::OutputCoef(j, c) => beta_y[(*j, *c)] = v,
                    _ => {}
                }
            }
        }
        let lookup = |v: crate::expr::Var| match v {
            Var::Param(k) => values[k],
            _ => f64::NAN,
        };
        let diag = |es: &[Expr]| {
            DMatrix::from_diagonal(&DVector::from_iterator(
                es.len(),
                es.iter().map(|e| e.eval(&lookup)),
            ))
        };
        Ok(AffineParams {
            beta_x,
            beta_y,
            pi_x: diag(&spec.process_noise),
            pi_y: diag(&spec.measurement_noise),
            mu: DVector::from_iterator(n, spec.initial_mean.iter().map(|e| e.eval(&lookup))),
            p1: diag(&spec.initial_variance),
        })
    }

    /// The free parameters of affine parameters.
    pub fn theta(&self, params: &AffineParams) -> Vec<f64> {
        let spec = self.file.spec();
        spec.free()
            .into_iter()
            .map(|k| match self.slots[k].first() {
                Some(Slot::StateCoef(i, c)) => params.beta_x[(*i, *c)],
                Some(Slot::OutputCoef(j, c)) => params.beta_y[(*j, *c)],
                Some(Slot::ProcessVar(i)) => params.pi_x[(*i, *i)],
                Some(Slot::MeasurementVar(j)) => params.pi_y[(*j, *j)],
                None => spec.parameters[k].value,
            })
            .collect()
    }
}

impl AffineModel for ExprAffine {
    type Smc = ExprSmc;

    fn state_dim(&self) -> usize {
        self.state_structure.len()
    }
    fn output_dim(&self) -> usize {
        self.output_structure.len()
    }
    fn regressor_dim(&self) -> usize {
        self.regressors.len()
    }

    fn regressors(&self, t: usize, x: &[f64], u: &[f64], out: &mut [f64]) {
        let values = &self.file.spec().parameters;
        let lookup = |v: Var| match v {
            Var::State(i) => x[i],
            Var::Input(i) => u[i],
            Var::Time => t as f64,
            Var::Param(k) => values[k].value,
        };
        for (o, e) in out.iter_mut().zip(&self.regressors) {
            *o = e.eval(&lookup);
        }
    }

    fn regressor_columns(&self, t: usize, states: &[f64], u: &[f64], columns: &mut [f64]) {
        let values = &self.file.spec().parameters;
        let lookup = |v: Var| match v {
            Var::Input(i) => u[i],
            Var::Time => t as f64,
            Var::Param(k) => values[k].value,
            Var::State(_) => f64::NAN,
        };
        let n = self.state_dim();
        with_lanes(&self.program, n, &lookup, states, |view, lanes| {
            for (i, col) in columns
                .chunks_exact_mut(lanes.max(1))
                .enumerate()
                .take(self.regressors.len())
            {
                match view(i) {
                    crate::program::Values::Lanes(v) => col.copy_from_slice(v),
                    crate::program::Values::Scalar(s) => col.fill(s),
                }
            }
        });
    }

    fn state_structure(&self) -> Vec<Vec<usize>> {
        self.state_structure.clone()
    }
    fn output_structure(&self) -> Vec<Vec<usize>> {
        self.output_structure.clone()
    }
    fn held_state_coefficients(&self) -> Vec<Vec<usize>> {
        self.state_held.clone()
    }
    fn held_output_coefficients(&self) -> Vec<Vec<usize>> {
        self.output_held.clone()
    }

    fn constraints(&self) -> Option<AffineConstraints> {
        self.constraints.clone()
    }

    fn smc_model(&self, params: &AffineParams) -> Result<ExprSmc, AffineEmError> {
        let theta = self.theta(params);
        ExprSmc::new(self.file.compiled().clone(), self.file.full_values(&theta))
            .map_err(|e| AffineEmError::InvalidParams(e.reason))
    }
}
