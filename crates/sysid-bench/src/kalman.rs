//! `kalman` runner: time per step of the square-root filter (log-likelihood only) and
//! of filter + smoother + EM statistics, on the canonical systems.

use nalgebra::DMatrix;
use serde_json::json;
use std::time::Instant;
use sysid::kalman::{KalmanWorkspace, SufficientStatistics};
use sysid::models::System;

struct Case {
    task: &'static str,
    system: System,
    /// the true model, or a full-rank noise variant (`Q = 0.01 I`, `P1 = I`): the
    /// typical shape of an EM iterate, where every covariance is non-singular
    full_noise: bool,
    steps: usize,
    /// the acceptance target of issue 2, ns per step
    target_ns: f64,
}

const CASES: [Case; 6] = [
    Case {
        task: "kalman_filter",
        system: System::Lgss,
        full_noise: false,
        steps: 100_000,
        target_ns: 20.0,
    },
    Case {
        task: "kalman_filter",
        system: System::Lti2x2,
        full_noise: false,
        steps: 2000,
        target_ns: f64::NAN,
    },
    Case {
        task: "kalman_filter",
        system: System::Lti2x2,
        full_noise: true,
        steps: 2000,
        target_ns: f64::NAN,
    },
    Case {
        task: "kalman_smooth_stats",
        system: System::Lgss,
        full_noise: false,
        steps: 100_000,
        target_ns: f64::NAN,
    },
    Case {
        task: "kalman_smooth_stats",
        system: System::Lti2x2,
        full_noise: false,
        steps: 2000,
        target_ns: 2000.0,
    },
    Case {
        task: "kalman_smooth_stats",
        system: System::Lti2x2,
        full_noise: true,
        steps: 2000,
        target_ns: f64::NAN,
    },
];

pub fn run(reps: usize, only: Option<&str>) {
    let mut checks = Vec::new();
    for case in CASES
        .iter()
        .filter(|c| only.is_none_or(|s| s == c.system.name()))
    {
        let sim = case
            .system
            .simulate(case.steps, 1)
            .expect("canonical systems simulate");
        let mut model = case.system.model();
        if case.full_noise {
            let n = model.n();
            model = model
                .to_builder()
                .q(DMatrix::identity(n, n) * 0.01)
                .p1(DMatrix::identity(n, n))
                .build()
                .expect("valid variant");
        }
        let mut ws = KalmanWorkspace::new();
        let mut stats = SufficientStatistics::new(model.n(), model.m(), model.p());
        let mut once = || -> f64 {
            if case.task == "kalman_filter" {
                ws.loglik(&model, &sim.record).expect("loglik")
            } else {
                ws.accumulate_statistics(&model, &sim.record, 0, &mut stats)
                    .expect("stats")
            }
        };
        let loglik = once(); // warm-up: buffers grow here
        let mut ns: Vec<f64> = (0..reps)
            .map(|_| {
                let start = Instant::now();
                std::hint::black_box(once());
                start.elapsed().as_secs_f64() * 1e9 / case.steps as f64
            })
            .collect();
        let (median, min, max) = crate::summary(&mut ns);
        println!(
            "{}",
            json!({
                "task": case.task,
                "params": {"system": case.system.name(), "full_noise": case.full_noise, "T": case.steps, "n": model.n(),
                           "m": model.m(), "p": model.p(), "reps": reps},
                "ns_per_step": median, "ns_per_step_min": min, "ns_per_step_max": max,
                "loglik": loglik,
            })
        );
        if case.target_ns.is_finite() {
            checks.push(json!({"task": case.task, "system": case.system.name(),
                "ns_per_step": median, "target_ns_per_step": case.target_ns,
                "met": median <= case.target_ns}));
        }
    }
    println!(
        "{}",
        json!({"task": "kalman_summary", "params": {"reps": reps}, "targets": checks})
    );
}
