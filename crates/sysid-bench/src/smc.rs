//! `smc` runner: the speed targets of the SMC issue on `nlbench` (T = 1000): bootstrap
//! filter (M = 1000 and 10 000, one thread; M = 10 000 on two threads), FFBSi O(M^2)
//! and rejection FFBSi (100 paths, M = 1000), and Tanizaki and rejection FFBSi as
//! particle EM's E-step (M = 50, 50 paths). Medians over repetitions, each with its own
//! seed.

use crate::emit;
use serde_json::json;
use std::time::Instant;
use sysid::models::Nlbench;
use sysid::smc::{
    Ffbsi, FfbsiReject, FilterOptions, History, ParticleFilter, Series, Smoother, SmootherStats,
    Tanizaki,
};

const STEPS: usize = 1000;

fn time_ms(reps: usize, mut f: impl FnMut(u64)) -> Vec<f64> {
    (0..reps as u64)
        .map(|r| {
            let start = Instant::now();
            f(r);
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect()
}

fn filter(particles: usize, history: bool, parallel: bool) -> ParticleFilter {
    ParticleFilter::new(FilterOptions {
        particles,
        store_history: history,
        parallel,
        ..Default::default()
    })
    .expect("valid options")
}

struct Report {
    checks: Vec<serde_json::Value>,
}

impl Report {
    fn line(
        &mut self,
        task: &str,
        params: serde_json::Value,
        mut ms: Vec<f64>,
        target_ms: f64,
        work: f64,
    ) {
        let (median, min, max) = crate::summary(&mut ms);
        emit(&json!({
            "task": task, "params": params,
            "ms_median": median, "ms_min": min, "ms_max": max,
            "ns_per_unit_median": median * 1e6 / work,
            "target_ms": target_ms,
        }));
        if target_ms.is_finite() {
            self.checks
                .push(json!({"task": task, "params": params, "ms_median": median,
                "target_ms": target_ms, "met": median <= target_ms}));
        }
    }
}

/// Times rejection FFBSi with `paths` paths on `history` and reports it against
/// `target_ms`.
fn rejection_line(
    report: &mut Report,
    model: &Nlbench,
    history: &History,
    data: &Series,
    reps: usize,
    paths: usize,
    target_ms: f64,
) {
    let reject = FfbsiReject {
        paths,
        max_trials: None,
        parallel: false,
    };
    let (ms, stats) = smooth_ms(&reject, model, history, data, reps);
    let params = json!({"system": "nlbench", "T": STEPS, "M": history.particles(),
        "paths": paths, "trials": stats.trials, "fallbacks": stats.fallbacks});
    report.line("ffbsi_reject", params, ms, target_ms, stats.trials as f64);
}

fn smooth_ms<S: Smoother<Nlbench>>(
    smoother: &S,
    model: &Nlbench,
    history: &History,
    data: &Series,
    reps: usize,
) -> (Vec<f64>, SmootherStats) {
    let mut stats = SmootherStats::default();
    let ms = time_ms(reps, |r| {
        stats = smoother
            .trajectories(model, history, data, r)
            .expect("smoother")
            .1;
    });
    (ms, stats)
}

/// Runs every case with `reps` repetitions.
pub fn run(reps: usize) {
    let model = Nlbench::truth();
    let sim = model.simulate(STEPS, 1);
    let data = Series::new(&sim.outputs, 1).expect("simulated data");
    let mut report = Report { checks: Vec::new() };

    for (particles, target) in [(1000, 20.0), (10_000, 100.0)] {
        let mut pf = filter(particles, false, false);
        let ms = time_ms(reps, |r| {
            pf.run(&model, &data, r).expect("filter");
        });
        let params = json!({"system": "nlbench", "T": STEPS, "M": particles, "threads": 1});
        report.line(
            "pf_bootstrap",
            params,
            ms,
            target,
            (STEPS * particles) as f64,
        );
    }
    // the same filter on nlbench written as a model file (the compiled expressions)
    // against the hand-written model, alternating in one run: the ratio of medians
    let file = sysid::modelfile::builtin::model("nlbench")
        .expect("shipped")
        .expect("valid");
    let from_file = file.at(&file.free_values()).expect("valid values");
    let mut pf = filter(1000, false, false);
    let (mut builtin_ms, mut file_ms) = (Vec::new(), Vec::new());
    for r in 0..reps as u64 {
        builtin_ms.extend(time_ms(1, |_| {
            pf.run(&model, &data, r).expect("filter");
        }));
        file_ms.extend(time_ms(1, |_| {
            pf.run(&from_file, &data, r).expect("filter");
        }));
    }
    let (builtin_median, _, _) = crate::summary(&mut builtin_ms.clone());
    let (file_median, _, _) = crate::summary(&mut file_ms.clone());
    let params = json!({"system": "nlbench model file", "T": STEPS, "M": 1000, "threads": 1,
        "builtin_ms_median": builtin_median, "ratio_to_builtin": file_median / builtin_median});
    report.line(
        "pf_model_file",
        params,
        file_ms,
        2.0 * builtin_median,
        (STEPS * 1000) as f64,
    );

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("pool");
    let mut pf = filter(10_000, false, true);
    let ms = pool.install(|| {
        time_ms(reps, |r| {
            pf.run(&model, &data, r).expect("filter");
        })
    });
    let params = json!({"system": "nlbench", "T": STEPS, "M": 10_000, "threads": 2});
    report.line(
        "pf_bootstrap",
        params,
        ms,
        f64::NAN,
        (STEPS * 10_000) as f64,
    );

    let mut pf = filter(1000, true, false);
    pf.run(&model, &data, 0).expect("filter");
    let history = pf.history().expect("stored");
    let exact = Ffbsi {
        paths: 100,
        parallel: false,
    };
    let (ms, stats) = smooth_ms(&exact, &model, history, &data, reps.div_ceil(4).max(3));
    let params = json!({"system": "nlbench", "T": STEPS, "M": 1000, "paths": 100});
    report.line("ffbsi", params, ms, 500.0, stats.density_evaluations as f64);
    rejection_line(&mut report, &model, history, &data, reps, 100, 20.0);

    let mut pf = filter(50, true, false);
    pf.run(&model, &data, 0).expect("filter");
    let history = pf.history().expect("stored");
    let (ms, stats) = smooth_ms(&Tanizaki::default(), &model, history, &data, reps);
    let params = json!({"system": "nlbench", "T": STEPS, "M": 50});
    report.line(
        "tanizaki",
        params,
        ms,
        2.5,
        stats.density_evaluations as f64,
    );

    // rejection FFBSi as particle EM's E-step (seed 000: 50 paths among M = 50): one
    // run's 1 s per 1000 EM iterations leaves 0.2-0.3 ms per pass once the filter
    // (~0.52 ms) and the statistics (0.2-0.3 ms) are paid; the target takes 0.2 ms
    rejection_line(&mut report, &model, history, &data, reps, 50, 0.2);

    emit(&json!({"task": "smc_summary", "params": {"reps": reps}, "targets": report.checks}));
}
