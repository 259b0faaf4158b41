//! Tied and bounded coefficients, and noise variances held inside an estimated block:
//! the closed-form M-step of physical models.
//!
//! # Model
//! A model whose coefficients are not all separate numbers: one parameter may set
//! several coefficients (what leaves one tank enters the next, so the outflow
//! coefficient sits in both rows), a parameter may have bounds (a flow coefficient is
//! positive), and a diagonal noise block may hold some variances at known values while
//! estimating the others. [`AffineModel::constraints`] describes this; every estimated
//! coefficient then belongs to exactly one [`TiedCoefficient`].
//!
//! # Algorithm
//! The expected complete-data log-likelihood is, over the rows `i` of both blocks with
//! variances `pi_i`,
//! `-1/2 sum_i (N_i log pi_i + E[sum_t (z_it - beta_i' alpha_t)^2] / pi_i)`.
//! With the variances held, it is a quadratic in the tied parameters: a weighted,
//! equality-constrained least squares whose normal equations sum each row's statistics
//! with weight `1 / pi_i`; with bounds, a box-constrained quadratic programme
//! (`crate::box_qp`, exact). With the coefficients held, each free variance is its
//! row's mean squared residual. The M-step alternates the two (an ECM cycle: each
//! conditional maximisation raises the objective, so EM's ascent property holds) until
//! neither moves (relative change below 1e-12, at most 200 cycles); without a tie across
//! rows of different free variances the first cycle is already exact.
//!
//! # References
//! Meng and Rubin (1993), "Maximum likelihood estimation via the ECM algorithm".

use super::{AffineEmError, AffineEmSpec, AffineModel, AffineParams, AffineStatistics};
use crate::box_qp::{BoxQpError, box_qp};
use crate::linear::Covariance;
use nalgebra::{DMatrix, DVector};

/// Where a coefficient sits in [`AffineParams`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoefficientSlot {
    /// `beta_x[(row, col)]`.
    State {
        /// The state row.
        row: usize,
        /// The regressor.
        col: usize,
    },
    /// `beta_y[(row, col)]`.
    Output {
        /// The output row.
        row: usize,
        /// The regressor.
        col: usize,
    },
}

/// One estimated parameter: the coefficients it sets (all equal to it) and its bounds
/// (closed; `-inf`/`inf` for none).
#[derive(Debug, Clone, PartialEq)]
pub struct TiedCoefficient {
    /// The coefficients equal to the parameter (at least one).
    pub slots: Vec<CoefficientSlot>,
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
}

/// The constraints of [`AffineModel::constraints`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AffineConstraints {
    /// One entry per estimated parameter; together they cover every estimated
    /// coefficient once.
    pub coefficients: Vec<TiedCoefficient>,
    /// Process-noise variances (diagonal indices) held at their values although the
    /// block is estimated (diagonally).
    pub held_process_variances: Vec<usize>,
    /// Measurement-noise variances held likewise.
    pub held_measurement_variances: Vec<usize>,
}

fn coefficient(params: &AffineParams, slot: CoefficientSlot) -> f64 {
    match slot {
        CoefficientSlot::State { row, col } => params.beta_x[(row, col)],
        CoefficientSlot::Output { row, col } => params.beta_y[(row, col)],
    }
}

fn coefficient_mut(params: &mut AffineParams, slot: CoefficientSlot) -> &mut f64 {
    match slot {
        CoefficientSlot::State { row, col } => &mut params.beta_x[(row, col)],
        CoefficientSlot::Output { row, col } => &mut params.beta_y[(row, col)],
    }
}

impl AffineConstraints {
    /// The parameters' values in `params` (each its first coefficient).
    pub fn values(&self, params: &AffineParams) -> Vec<f64> {
        self.coefficients
            .iter()
            .map(|c| coefficient(params, c.slots[0]))
            .collect()
    }

    /// Sets every coefficient of each parameter to its value in `values`, clamped to
    /// its bounds.
    pub fn set(&self, params: &mut AffineParams, values: &[f64]) {
        for (c, &v) in self.coefficients.iter().zip(values) {
            let v = v.max(c.lower).min(c.upper);
            for &slot in &c.slots {
                *coefficient_mut(params, slot) = v;
            }
        }
    }

    /// Makes `params` satisfy the constraints: each parameter's coefficients set to
    /// their mean, clamped to its bounds (a perturbed start, an average of estimates).
    pub fn project(&self, params: &mut AffineParams) {
        let values: Vec<f64> = self
            .coefficients
            .iter()
            .map(|c| {
                c.slots.iter().map(|&s| coefficient(params, s)).sum::<f64>() / c.slots.len() as f64
            })
            .collect();
        self.set(params, &values);
    }

    /// Whether the constraints fit the model: slots inside the shapes, every estimated
    /// coefficient in one parameter exactly, bounds ordered.
    pub fn check<A: AffineModel + ?Sized>(&self, model: &A) -> Result<(), AffineEmError> {
        let invalid = |what: String| Err(AffineEmError::InvalidParams(what));
        let free_x =
            super::free_structure(&model.state_structure(), &model.held_state_coefficients());
        let free_y =
            super::free_structure(&model.output_structure(), &model.held_output_coefficients());
        let mut seen = Vec::new();
        for (k, c) in self.coefficients.iter().enumerate() {
            if c.slots.is_empty() {
                return invalid(format!("tied coefficient {k} sets no coefficient"));
            }
            if c.lower.is_nan() || c.upper.is_nan() || c.lower > c.upper {
                return invalid(format!(
                    "tied coefficient {k} has bounds [{}, {}]",
                    c.lower, c.upper
                ));
            }
            for &slot in &c.slots {
                let (free, row, col) = match slot {
                    CoefficientSlot::State { row, col } => (&free_x, row, col),
                    CoefficientSlot::Output { row, col } => (&free_y, row, col),
                };
                if !free.get(row).is_some_and(|used| used.contains(&col)) {
                    return invalid(format!(
                        "tied coefficient {k} sets {slot:?}, which is not an estimated \
                         coefficient"
                    ));
                }
                if seen.contains(&slot) {
                    return invalid(format!("{slot:?} belongs to two tied coefficients"));
                }
                seen.push(slot);
            }
        }
        let estimated =
            free_x.iter().map(Vec::len).sum::<usize>() + free_y.iter().map(Vec::len).sum::<usize>();
        if seen.len() != estimated {
            return invalid(format!(
                "the tied coefficients set {} of the {estimated} estimated coefficients",
                seen.len()
            ));
        }
        let (n, p) = (model.state_dim(), model.output_dim());
        if self.held_process_variances.iter().any(|&i| i >= n)
            || self.held_measurement_variances.iter().any(|&j| j >= p)
        {
            return invalid("a held noise variance outside its block".into());
        }
        Ok(())
    }
}

/// Whether EM estimates each variance of a block (`process`: the state block): none of
/// a held block, else every one the constraints do not hold.
pub(crate) fn estimated_variances(
    covariance: Covariance,
    rows: usize,
    constraints: Option<&AffineConstraints>,
    process: bool,
) -> Vec<bool> {
    let held = constraints.map_or(&[][..], |c| {
        if process {
            &c.held_process_variances
        } else {
            &c.held_measurement_variances
        }
    });
    (0..rows)
        .map(|i| covariance != Covariance::Fixed && !held.contains(&i))
        .collect()
}

/// One block's statistics and current values, for the constrained M-step.
struct Rows<'a> {
    moments: &'a DMatrix<f64>,
    steps: f64,
    /// Per row: the known part of the coefficients (held ones at their values).
    known: Vec<DVector<f64>>,
    /// Per row: whether its variance is estimated.
    free_variance: Vec<bool>,
}

/// The constrained M-step (see the module documentation).
pub(crate) fn constrained_m_step<A: AffineModel>(
    model: &A,
    stats: &AffineStatistics,
    current: &AffineParams,
    spec: &AffineEmSpec,
    constraints: &AffineConstraints,
) -> Result<(AffineParams, usize), AffineEmError> {
    constraints.check(model)?;
    if !(spec.beta_x && spec.beta_y) {
        return Err(AffineEmError::Unsupported(
            "tied or bounded coefficients need every coefficient estimated".into(),
        ));
    }
    if spec.pi_x == Covariance::Full || spec.pi_y == Covariance::Full {
        return Err(AffineEmError::Unsupported(
            "tied or bounded coefficients need diagonal noise covariances".into(),
        ));
    }
    let r = model.regressor_dim();
    let known = |beta: &DMatrix<f64>, held: Vec<Vec<usize>>| -> Vec<DVector<f64>> {
        (0..beta.nrows())
            .map(|row| {
                let mut h = DVector::zeros(r);
                for &c in held.get(row).map(Vec::as_slice).unwrap_or(&[]) {
                    h[c] = beta[(row, c)];
                }
                h
            })
            .collect()
    };
    let blocks = [
        Rows {
            moments: &stats.state,
            steps: stats.state_steps,
            known: known(&current.beta_x, model.held_state_coefficients()),
            free_variance: estimated_variances(
                spec.pi_x,
                model.state_dim(),
                Some(constraints),
                true,
            ),
        },
        Rows {
            moments: &stats.output,
            steps: stats.output_steps,
            known: known(&current.beta_y, model.held_output_coefficients()),
            free_variance: estimated_variances(
                spec.pi_y,
                model.output_dim(),
                Some(constraints),
                false,
            ),
        },
    ];
    for (name, block) in [
        ("state statistics", &blocks[0]),
        ("output statistics", &blocks[1]),
    ] {
        if block.steps <= 0.0 {
            return Err(AffineEmError::NoSteps { block: name });
        }
        sysid_linalg::check_finite(name, block.moments)?;
    }
    // per block, per row: the tied parameters it uses, with their regressors
    let mut ties: [Vec<Vec<(usize, usize)>>; 2] = [
        vec![Vec::new(); model.state_dim()],
        vec![Vec::new(); model.output_dim()],
    ];
    for (k, c) in constraints.coefficients.iter().enumerate() {
        for &slot in &c.slots {
            match slot {
                CoefficientSlot::State { row, col } => ties[0][row].push((k, col)),
                CoefficientSlot::Output { row, col } => ties[1][row].push((k, col)),
            }
        }
    }
    let mut variances = [current.pi_x.diagonal(), current.pi_y.diagonal()];
    let (lower, upper): (Vec<f64>, Vec<f64>) = constraints
        .coefficients
        .iter()
        .map(|c| (c.lower, c.upper))
        .unzip();
    let m = constraints.coefficients.len();
    let mut theta = DVector::from_vec(constraints.values(current));
    let mut next = current.clone();
    let mut cycles = 0;
    loop {
        cycles += 1;
        // the coefficients given the variances
        let mut h = DMatrix::zeros(m, m);
        let mut g = DVector::zeros(m);
        for (b, block) in blocks.iter().enumerate() {
            for (row, used) in ties[b].iter().enumerate() {
                if used.is_empty() {
                    continue;
                }
                let v = variances[b][row];
                if !(v > 0.0 && v.is_finite()) {
                    return Err(AffineEmError::InvalidParams(format!(
                        "the {} noise variance of row {row} is {v}: the tied coefficients \
                         weigh each row by its inverse",
                        if b == 0 { "process" } else { "measurement" }
                    )));
                }
                let a = block.moments.view((0, 0), (r, r));
                let ah = a * &block.known[row];
                for &(k, c) in used {
                    g[k] += (block.moments[(c, r + row)] - ah[c]) / v;
                    for &(k2, c2) in used {
                        h[(k, k2)] += a[(c, c2)] / v;
                    }
                }
            }
        }
        let start: Vec<f64> = theta.iter().copied().collect();
        let solved = box_qp(&h, &g, &lower, &upper, &start).map_err(|e| {
            AffineEmError::InvalidParams(match e {
                BoxQpError::Singular => "the smoothed statistics do not determine the tied \
                                         coefficients (singular normal equations)"
                    .into(),
                BoxQpError::Infeasible => "the tied coefficients' normal equations are not \
                                          finite, or a lower bound is above its upper bound"
                    .into(),
            })
        })?;
        let moved = relative_change(&theta, &solved);
        theta = solved;
        constraints.set(&mut next, theta.as_slice());
        // the free variances given the coefficients
        let mut variance_moved: f64 = 0.0;
        for (b, block) in blocks.iter().enumerate() {
            let beta = if b == 0 { &next.beta_x } else { &next.beta_y };
            for row in 0..beta.nrows() {
                if !block.free_variance[row] {
                    continue;
                }
                let mut v = DVector::zeros(r + beta.nrows());
                for c in 0..r {
                    v[c] = -beta[(row, c)];
                }
                v[r + row] = 1.0;
                let residual = (v.transpose() * block.moments * &v)[(0, 0)].max(0.0) / block.steps;
                let old = variances[b][row];
                variance_moved = variance_moved.max((residual - old).abs() / old.abs().max(1e-300));
                variances[b][row] = residual;
            }
        }
        if (moved < 1e-12 && variance_moved < 1e-12) || cycles >= 200 {
            break;
        }
    }
    next.pi_x = DMatrix::from_diagonal(&variances[0]);
    next.pi_y = DMatrix::from_diagonal(&variances[1]);
    if spec.initial_state {
        next.mu = stats.initial_mean.clone();
        let mut p1 = &stats.initial_second_moment - &next.mu * next.mu.transpose();
        sysid_linalg::symmetrize(&mut p1);
        next.p1 = p1;
    }
    Ok((next, cycles))
}

fn relative_change(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    a.iter()
        .zip(b.iter())
        .map(|(x, y)| (x - y).abs() / x.abs().max(y.abs()).max(1e-300))
        .fold(0.0, f64::max)
}
