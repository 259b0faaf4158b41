//! A small quadratic programme with box constraints: the bounded least squares of the
//! constrained M-step.
//!
//! # Algorithm
//! Minimise `q(x) = x'Hx/2 - g'x` subject to `lower <= x <= upper`, with `H` symmetric
//! positive definite, by the primal active-set method (Nocedal and Wright 2006,
//! algorithm 16.3, specialised to bounds): the working set holds coordinates at a
//! bound; each iteration minimises `q` over the others (a Cholesky solve of the free
//! block), steps towards that minimiser as far as the bounds allow (adding the
//! blocking bound), and at a minimiser releases the bound whose multiplier has the
//! wrong sign. `q` decreases strictly, so no working set repeats and the method ends
//! after finitely many iterations; at the end the KKT conditions hold.
//!
//! # Complexity
//! `O(m^3)` per iteration for `m` coordinates (a handful in a model file).

use nalgebra::{DMatrix, DVector};

/// Why the programme has no solution.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum BoxQpError {
    /// The free block of `H` is not positive definite (a coefficient the statistics
    /// do not determine).
    Singular,
    /// A lower bound above its upper bound, or a NaN in the inputs.
    Infeasible,
}

/// The minimiser of `x'Hx/2 - g'x` over the box `[lower, upper]`, starting from `start`
/// (clamped into the box).
pub(crate) fn box_qp(
    h: &DMatrix<f64>,
    g: &DVector<f64>,
    lower: &[f64],
    upper: &[f64],
    start: &[f64],
) -> Result<DVector<f64>, BoxQpError> {
    let m = g.len();
    if lower
        .iter()
        .zip(upper)
        .any(|(l, u)| l.is_nan() || u.is_nan() || l > u)
        || h.iter().chain(g.iter()).any(|v| !v.is_finite())
    {
        return Err(BoxQpError::Infeasible);
    }
    let clamp = |i: usize, v: f64| v.max(lower[i]).min(upper[i]);
    let mut x = DVector::from_iterator(m, (0..m).map(|i| clamp(i, start[i])));
    // the working set: coordinates held at a bound
    let mut at_bound: Vec<bool> = (0..m)
        .map(|i| x[i] == lower[i] || x[i] == upper[i])
        .collect();
    for _ in 0..(10 * m + 20) {
        let free: Vec<usize> = (0..m).filter(|&i| !at_bound[i]).collect();
        // the minimiser over the free coordinates, the others held
        let target = if free.is_empty() {
            x.clone()
        } else {
            let hff = DMatrix::from_fn(free.len(), free.len(), |a, b| h[(free[a], free[b])]);
            let rhs = DVector::from_iterator(
                free.len(),
                free.iter().map(|&i| {
                    g[i] - (0..m)
                        .filter(|&j| at_bound[j])
                        .map(|j| h[(i, j)] * x[j])
                        .sum::<f64>()
                }),
            );
            let solved = hff.cholesky().ok_or(BoxQpError::Singular)?.solve(&rhs);
            let mut target = x.clone();
            for (a, &i) in free.iter().enumerate() {
                target[i] = solved[a];
            }
            target
        };
        // the longest step towards it inside the box, and the bound that blocks it
        let mut step = 1.0;
        let mut blocking = None;
        for &i in &free {
            let d = target[i] - x[i];
            let room = if d > 0.0 {
                upper[i] - x[i]
            } else {
                lower[i] - x[i]
            };
            if d != 0.0 && room / d < step {
                step = (room / d).max(0.0);
                blocking = Some(i);
            }
        }
        if let Some(i) = blocking {
            for &j in &free {
                x[j] += step * (target[j] - x[j]);
            }
            x[i] = if target[i] > x[i] { upper[i] } else { lower[i] };
            at_bound[i] = true;
            continue;
        }
        x = target;
        // multipliers: the gradient at a lower bound must point up, at an upper down
        let gradient = h * &x - g;
        let wrong = (0..m)
            .filter(|&i| at_bound[i])
            .map(|i| {
                let push = if x[i] == lower[i] && lower[i] != upper[i] {
                    -gradient[i]
                } else if x[i] == upper[i] && lower[i] != upper[i] {
                    gradient[i]
                } else {
                    0.0
                };
                (i, push)
            })
            .filter(|&(_, push)| push > 0.0)
            .max_by(|a, b| a.1.total_cmp(&b.1));
        match wrong {
            Some((i, _)) => at_bound[i] = false,
            None => return Ok(x),
        }
    }
    Ok(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::RngExt;

    fn q(h: &DMatrix<f64>, g: &DVector<f64>, x: &DVector<f64>) -> f64 {
        0.5 * (x.transpose() * h * x)[(0, 0)] - g.dot(x)
    }

    /// The independent reference: every assignment of each coordinate to its lower
    /// bound, its upper bound or free (3^m systems), the best feasible one.
    fn enumerate(h: &DMatrix<f64>, g: &DVector<f64>, lower: &[f64], upper: &[f64]) -> DVector<f64> {
        let m = g.len();
        let mut best: Option<(f64, DVector<f64>)> = None;
        for code in 0..3usize.pow(m as u32) {
            let mut x = DVector::zeros(m);
            let mut free = Vec::new();
            let mut c = code;
            for i in 0..m {
                match c % 3 {
                    0 => x[i] = lower[i],
                    1 => x[i] = upper[i],
                    _ => free.push(i),
                }
                c /= 3;
            }
            if !free.is_empty() {
                let hff = DMatrix::from_fn(free.len(), free.len(), |a, b| h[(free[a], free[b])]);
                let rhs = DVector::from_iterator(
                    free.len(),
                    free.iter().map(|&i| {
                        g[i] - (0..m)
                            .filter(|j| !free.contains(j))
                            .map(|j| h[(i, j)] * x[j])
                            .sum::<f64>()
                    }),
                );
                let s = hff.lu().solve(&rhs).unwrap();
                for (a, &i) in free.iter().enumerate() {
                    x[i] = s[a];
                }
            }
            let feasible = (0..m).all(|i| x[i] >= lower[i] - 1e-12 && x[i] <= upper[i] + 1e-12);
            if feasible && best.as_ref().is_none_or(|(v, _)| q(h, g, &x) < *v) {
                best = Some((q(h, g, &x), x));
            }
        }
        best.unwrap().1
    }

    #[test]
    fn matches_enumerating_the_active_sets_on_random_problems() {
        let mut rng = sysid_smc::stream(7, 0);
        let mut bounded = 0;
        for _ in 0..300 {
            let m = rng.random_range(1..=5);
            let a = DMatrix::from_fn(m + 2, m, |_, _| rng.random_range(-1.0..1.0));
            let h = a.transpose() * a + DMatrix::identity(m, m) * 0.05;
            let g = DVector::from_fn(m, |_, _| rng.random_range(-2.0..2.0));
            let lower: Vec<f64> = (0..m).map(|_| rng.random_range(-1.0..0.0)).collect();
            let upper: Vec<f64> = lower
                .iter()
                .map(|l| l + rng.random_range(0.1..1.5))
                .collect();
            let start: Vec<f64> = (0..m).map(|_| rng.random_range(-2.0..2.0)).collect();
            let x = box_qp(&h, &g, &lower, &upper, &start).unwrap();
            let reference = enumerate(&h, &g, &lower, &upper);
            assert!(
                (&x - &reference).amax() < 1e-9,
                "{x} against {reference} (h {h}, g {g})"
            );
            let free = h.clone().cholesky().unwrap().solve(&g);
            if (&free - &x).amax() > 1e-6 {
                bounded += 1;
            }
        }
        // the test exercises the bounds, not only the free solution
        assert!(bounded > 100, "{bounded}");
    }

    #[test]
    fn loose_bounds_give_the_unconstrained_solution_and_errors_are_typed() {
        let h = DMatrix::from_row_slice(2, 2, &[2.0, 0.5, 0.5, 1.0]);
        let g = DVector::from_row_slice(&[1.0, -1.0]);
        let inf = f64::INFINITY;
        let x = box_qp(&h, &g, &[-inf, -inf], &[inf, inf], &[0.0, 0.0]).unwrap();
        assert!((&h * &x - &g).amax() < 1e-12);
        let singular = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 1.0]);
        assert_eq!(
            box_qp(&singular, &g, &[-inf, -inf], &[inf, inf], &[0.0, 0.0]),
            Err(BoxQpError::Singular)
        );
        assert_eq!(
            box_qp(&h, &g, &[1.0, 0.0], &[0.0, 1.0], &[0.0, 0.0]),
            Err(BoxQpError::Infeasible)
        );
    }
}
