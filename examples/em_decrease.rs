//! Investigates the exact-EM likelihood decrease found by tests/em_hardening.rs
//! (lti2x2, T = 200, seed 3, from N4SID): evaluates the iterates around the decrease
//! with the square-root filter (steady-state reuse on and off) and the conventional
//! filter.
//!
//!     cargo run --release -p sysid --example em_decrease [T seed iterations]

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

fn main() {
    let arg = |k: usize, default: usize| {
        std::env::args()
            .nth(k)
            .and_then(|a| a.parse().ok())
            .unwrap_or(default)
    };
    let (steps, seed, iterations) = (arg(1, 200), arg(2, 3) as u64, arg(3, 5278));
    let sim = System::Lti2x2.simulate(steps, seed).unwrap();
    let records = [sim.record];
    let subspace = n4sid(
        &records[0],
        &N4sidOptions {
            order: Order::Fixed(8),
            block_rows: None,
        },
    )
    .unwrap();
    let start = lti2x2_experiment_start(&subspace.model);
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
    let result = fit(start, &records, lti2x2_em_spec(), &options, &mut keep);
    println!(
        "T = {steps}, seed {seed}: termination {:?} after {} iterations",
        result.termination, result.iterations
    );
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
}
