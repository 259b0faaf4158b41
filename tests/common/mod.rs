//! Helpers shared by the facade's integration tests.
#![allow(dead_code)]

/// Asserts that the mean of a particle EM's late iterates `values` (one estimate per
/// iteration) lies within 4 of their standard deviations of the exact EM value, and
/// that they are precise enough (sd below 5 % of the value) for that to mean something.
pub fn assert_iterates_match(method: &str, name: &str, values: &[f64], exact: f64) {
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let sd =
        (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (values.len() - 1) as f64).sqrt();
    eprintln!("{name}: {method} {mean:.5} (sd {sd:.5}), exact EM {exact:.5}");
    assert!(sd < 0.05 * exact.abs(), "{name}: too noisy to test ({sd})");
    assert!(
        (mean - exact).abs() < 4.0 * sd.max(1e-3 * exact.abs()),
        "{name}: {mean} vs {exact}"
    );
}

/// Runs `work` on a fresh rayon pool of `threads` threads.
pub fn on_threads<T: Send>(threads: usize, work: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a rayon pool")
        .install(work)
}

/// A simulated `lgss` record of `steps` samples and its outputs.
pub fn lgss_data(steps: usize, seed: u64) -> (sysid::kalman::Record, Vec<f64>) {
    let sim = sysid::models::System::Lgss.simulate(steps, seed).unwrap();
    let y = sim.record.y.as_slice().to_vec();
    (sim.record, y)
}

/// Mean and standard error of a sample.
pub fn mean_se(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// Asserts that the replicated smoothed means `runs` (one vector per replication)
/// lie within 4 standard errors of the RTS means at every step, and that the worst
/// step is not suspiciously close.
pub fn assert_close_to_rts(name: &str, runs: &[Vec<f64>], rts: &[f64]) {
    let mut worst: f64 = 0.0;
    for (t, &exact) in rts.iter().enumerate() {
        let values: Vec<f64> = runs.iter().map(|r| r[t]).collect();
        let (mean, se) = mean_se(&values);
        let z = (mean - exact).abs() / se;
        worst = worst.max(z);
        if std::env::var("SMC_DEBUG").is_ok() && z > 3.0 {
            eprintln!("{name}: t = {t}, mean {mean}, RTS {exact}, z {z:.2}");
            continue;
        }
        assert!(
            z < 4.0,
            "{name}: t = {t}, mean {mean}, RTS {exact}, {z:.2} standard errors"
        );
    }
    assert!(worst > 0.5, "{name}: suspiciously exact ({worst})");
}
