//! Investigates the exact-EM likelihood decrease found by tests/em_hardening.rs
//! (lti2x2, T = 200, seed 3, from N4SID): evaluates the iterates around the decrease
//! with the square-root filter (steady-state reuse on and off) and the conventional
//! filter. Then it redoes the last M-step from statistics perturbed at the level of
//! their rounding (`H + 1e-16 |H| v v'` for random unit vectors `v`) and prints the
//! spread of the resulting log-likelihoods, against the change of the last iteration.
//!
//!     cargo run --release -p sysid --example em_decrease [T seed iterations [min_variance]]
//!
//! With `DUMP=dir` it also writes the data (`dir/data.json`) and the last iterates
//! (`dir/theta_<k>.json`, every entry in round-trip precision), for an independent
//! high-precision evaluation (`tests/reference/em_decrease_mpmath.py`).

use nalgebra::SymmetricEigen;
use sysid::em::linear::fit;
use sysid::em::{EmObserver, EmOptions, IterationInfo};
use sysid::kalman::{KalmanWorkspace, LinearGaussianModel, conventional};
use sysid::models::{System, lti2x2_em_spec, lti2x2_experiment_start};
use sysid::subspace::{N4sidOptions, Order, n4sid};

struct Keep {
    from: usize,
    models: Vec<(usize, LinearGaussianModel, f64)>,
}

impl EmObserver<LinearGaussianModel> for Keep {
    fn iteration(&mut self, info: &IterationInfo<'_, LinearGaussianModel>) {
        if info.iteration >= self.from {
            self.models
                .push((info.iteration, info.estimate.clone(), info.loglik));
        }
    }
}

/// A matrix as JSON rows, every entry in round-trip precision.
fn json_rows(m: &nalgebra::DMatrix<f64>) -> String {
    let rows: Vec<String> = m
        .row_iter()
        .map(|r| {
            let v: Vec<String> = r.iter().map(|x| format!("{x:?}")).collect();
            format!("[{}]", v.join(", "))
        })
        .collect();
    format!("[{}]", rows.join(", "))
}

fn dump_model(path: &std::path::Path, model: &LinearGaussianModel) {
    let text = format!(
        "{{\"a\": {}, \"b\": {}, \"c\": {}, \"d\": {}, \"q\": {}, \"r\": {}, \"s\": {}, \"h\": {}, \"mu\": {}, \"p1\": {}}}\n",
        json_rows(model.a()),
        json_rows(model.b()),
        json_rows(model.c()),
        json_rows(model.d()),
        json_rows(model.q()),
        json_rows(model.r()),
        json_rows(model.s()),
        json_rows(&nalgebra::DMatrix::from_column_slice(
            model.p(),
            1,
            model.h().as_slice()
        )),
        json_rows(&nalgebra::DMatrix::from_column_slice(
            model.n(),
            1,
            model.mu().as_slice()
        )),
        json_rows(model.p1()),
    );
    std::fs::write(path, text).unwrap();
}

fn main() {
    let arg = |k: usize, default: usize| {
        std::env::args()
            .nth(k)
            .and_then(|a| a.parse().ok())
            .unwrap_or(default)
    };
    let (steps, seed, iterations) = (arg(1, 200), arg(2, 3) as u64, arg(3, 5278));
    let min_variance: f64 = std::env::args()
        .nth(4)
        .and_then(|a| a.parse().ok())
        .unwrap_or(0.0);
    let spec = sysid::em::linear::LinearEmSpec {
        min_variance,
        ..lti2x2_em_spec()
    };
    let sim = System::Lti2x2.simulate(steps, seed).unwrap();
    let records = [sim.record];
    let subspace = n4sid(
        &records[0],
        &N4sidOptions {
            order: Order::Fixed(8),
            block_rows: None,
            ..Default::default()
        },
    )
    .unwrap();
    let start = spec
        .project(&lti2x2_experiment_start(&subspace.model))
        .unwrap();
    let options = EmOptions {
        max_iterations: iterations,
        tol: 0.0,
        ..EmOptions::default()
    }
    .check()
    .unwrap();
    let mut keep = Keep {
        from: iterations.saturating_sub(5),
        models: Vec::new(),
    };
    let result = fit(start, &records, spec.clone(), &options, &mut keep);
    println!(
        "T = {steps}, seed {seed}: termination {:?} after {} iterations",
        result.termination, result.iterations
    );
    if let Some(dir) = std::env::var_os("DUMP") {
        let dir = std::path::PathBuf::from(dir);
        std::fs::create_dir_all(&dir).unwrap();
        let data = format!(
            "{{\"y\": {}, \"u\": {}}}\n",
            json_rows(&records[0].y),
            json_rows(&records[0].u)
        );
        std::fs::write(dir.join("data.json"), data).unwrap();
        for (k, model, _) in &keep.models {
            dump_model(&dir.join(format!("theta_{k}.json")), model);
        }
    }
    for (k, model, loglik_reported) in &keep.models {
        let mut ws = KalmanWorkspace::new();
        let on = ws.loglik(model, &records[0]).unwrap();
        ws.set_steady_state_reuse(false);
        let off = ws.loglik(model, &records[0]).unwrap();
        let conv = conventional::filter_smooth(model, &records[0])
            .map(|c| c.loglik)
            .unwrap_or(f64::NAN);
        let q = SymmetricEigen::new(model.q().clone()).eigenvalues;
        let r = SymmetricEigen::new(model.r().clone()).eigenvalues;
        println!(
            "theta_{k}: reported(prev) {loglik_reported:.9}  sqrt reuse {on:.9}  no reuse {off:.9}  conventional {conv:.9}  Q eig [{:.3e}, {:.3e}]  R eig [{:.3e}, {:.3e}]",
            q.min(),
            q.max(),
            r.min(),
            r.max()
        );
    }
    rounding_sensitivity(&records, &keep.models, &spec);
}

/// The M-step from the statistics at the second-last kept iterate, perturbed by
/// `1e-16 max|H|` in random rank-one directions: the spread of the log-likelihoods of
/// the results is what the rounding of the statistics alone can do.
fn rounding_sensitivity(
    records: &[sysid::kalman::Record],
    models: &[(usize, LinearGaussianModel, f64)],
    spec: &sysid::em::linear::LinearEmSpec,
) {
    use rand::{RngExt, SeedableRng};
    let Some((k, model, _)) = models.iter().rev().nth(1) else {
        return;
    };
    let mut em = sysid::em::linear::LinearEm::new(records, spec.clone());
    let (stats, before) = em.e_step(model).unwrap();
    let scale = stats.second_moment().amax();
    let mut ws = KalmanWorkspace::new();
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(1);
    let mut values = Vec::new();
    for trial in 0..20 {
        let mut perturbed = stats.clone();
        if trial > 0 {
            let v: Vec<f64> = (0..stats.dim())
                .map(|_| rng.random::<f64>() - 0.5)
                .collect();
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            let v: Vec<f64> = v.iter().map(|x| x / norm).collect();
            perturbed.observe_weighted_sample(&v, 1e-16 * scale);
        }
        let next = sysid::em::linear::m_step(model, &perturbed, spec).unwrap();
        values.push(ws.loglik(&next, &records[0]).unwrap() - before);
    }
    let (lo, hi) = values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    println!(
        "M-step from theta_{k}: change of loglik {:.3e} unperturbed; with H perturbed by 1e-16 max|H| = {:.1e}: from {lo:.3e} to {hi:.3e} (19 draws)",
        values[0],
        1e-16 * scale
    );
}
