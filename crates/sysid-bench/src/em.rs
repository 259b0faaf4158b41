//! `em` runner: time of one linear EM iteration (E-step + M-step) on lti2x2, and of
//! N4SID, as JSON lines.

use crate::emit;
use serde_json::json;
use std::time::Instant;
use sysid::em::EmAlgorithm;
use sysid::em::linear::LinearEm;
use sysid::models::System;
use sysid::subspace::{N4sidOptions, Order, n4sid};

fn time_ms(reps: usize, mut f: impl FnMut()) -> (f64, f64, f64) {
    f(); // warm-up
    let mut v: Vec<f64> = (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    crate::summary(&mut v)
}

pub fn run(reps: usize) {
    let mut checks = Vec::new();
    for (steps, target_ms) in [(200, 0.3), (2000, 3.0)] {
        let sim = System::Lti2x2.simulate(steps, 1).expect("simulation");
        // an EM iterate: the N4SID start with S = 0, as `sysid fit lti` runs it
        let start = n4sid(
            &sim.record,
            &N4sidOptions {
                order: Order::Fixed(8),
                block_rows: None,
                ..Default::default()
            },
        )
        .expect("n4sid")
        .model;
        let start = start.without_cross_covariance();
        let records = [sim.record];
        let spec = sysid::models::lti2x2_em_spec();
        let mut em = LinearEm::new(&records, spec);
        let (median, min, max) = time_ms(reps, || {
            std::hint::black_box(em.step(&start).expect("step"));
        });
        emit(
            &json!({"task": "em_iteration", "params": {"system": "lti2x2", "T": steps, "n": 8, "reps": reps},
            "ms_median": median, "ms_min": min, "ms_max": max}),
        );
        checks.push(
            json!({"task": "em_iteration", "T": steps, "ms_median": median,
            "target_ms": target_ms, "met": median <= target_ms}),
        );
        if steps == 2000 {
            let options = N4sidOptions {
                order: Order::Fixed(8),
                block_rows: None,
                ..Default::default()
            };
            let (median, min, max) = time_ms(reps, || {
                std::hint::black_box(n4sid(&records[0], &options).expect("n4sid"));
            });
            emit(
                &json!({"task": "n4sid", "params": {"system": "lti2x2", "T": steps, "order": 8, "reps": reps},
                "ms_median": median, "ms_min": min, "ms_max": max}),
            );
            checks.push(json!({"task": "n4sid", "T": steps, "ms_median": median,
                "target_ms": 10.0, "met": median <= 10.0}));
        }
    }
    emit(&json!({"task": "em_summary", "params": {"reps": reps}, "targets": checks}));
}
