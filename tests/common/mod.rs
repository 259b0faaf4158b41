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
