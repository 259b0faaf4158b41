//! Long series: T = 10^6 filter and smoother on `lgss` and `lti2x2`. Linear time (the
//! 10^6 run takes about ten times the 10^5 run), constant memory per step (peak
//! resident memory grows by a bounded number of bytes per stored step for the smoother
//! and not at all for the log-likelihood), and no overflow in the log-likelihood.
//!
//! These take about a minute and a few GiB, so they are ignored by default:
//!
//! ```text
//! cargo test --release -p sysid --test long_series -- --ignored --nocapture --test-threads 1
//! ```
//! (one test at a time: the memory figures are the process's peak).

use std::time::Instant;
use sysid::prelude::*;

/// Peak resident set size of this process, bytes (Linux; 0 elsewhere).
fn peak_rss() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}

/// Times the log-likelihood and the smoother at T = 10^5 and 10^6; prints one JSON line.
fn long_run(system: System, smoother_bytes_per_step: f64) {
    let mut times = Vec::new();
    for steps in [100_000, 1_000_000] {
        let sim = system.simulate(steps, 1).unwrap();
        let model = system.model();
        let mut ws = KalmanWorkspace::new();
        let rss_data = peak_rss();
        let t0 = Instant::now();
        let loglik = ws.loglik(&model, &sim.record).unwrap();
        let loglik_seconds = t0.elapsed().as_secs_f64();
        let rss_loglik = peak_rss();
        assert!(
            loglik.is_finite(),
            "{system:?} T = {steps}: loglik {loglik}"
        );
        // the log-likelihood is a sum of T terms of moderate size: no overflow, no
        // cancellation to nonsense
        let per_step = loglik / steps as f64;
        assert!(per_step.abs() < 50.0, "{system:?}: {per_step} per step");
        let t1 = Instant::now();
        let smoothed = ws.smooth(&model, &sim.record).unwrap();
        let smooth_seconds = t1.elapsed().as_secs_f64();
        let rss_smooth = peak_rss();
        // (lgss's log-likelihood takes the scalar fast path, the smoother the array
        // form: equal to round-off)
        let relative = (smoothed.loglik() - loglik).abs() / loglik.abs();
        assert!(
            relative < 1e-10,
            "smoother and filter log-likelihoods differ by {relative:e}"
        );
        let last = smoothed.mean(steps - 1);
        assert!(last.iter().all(|v| v.is_finite()));
        let smooth_growth = rss_smooth.saturating_sub(rss_loglik) as f64 / steps as f64;
        let loglik_growth = rss_loglik.saturating_sub(rss_data);
        println!(
            "{}",
            serde_json_line(&[
                ("system", format!("\"{system:?}\"")),
                ("T", steps.to_string()),
                ("loglik", format!("{loglik}")),
                ("loglik_seconds", format!("{loglik_seconds:.3}")),
                ("smooth_seconds", format!("{smooth_seconds:.3}")),
                ("loglik_peak_growth_bytes", loglik_growth.to_string()),
                (
                    "smoother_peak_bytes_per_step",
                    format!("{smooth_growth:.0}")
                ),
                ("peak_rss_bytes", rss_smooth.to_string()),
            ])
        );
        // the filter's log-likelihood needs no per-step storage (its workspace is
        // O(n^2)); allow the allocator's slack
        assert!(
            loglik_growth < 64 << 20,
            "loglik grew the peak by {loglik_growth} bytes"
        );
        if steps == 1_000_000 {
            assert!(
                smooth_growth < smoother_bytes_per_step,
                "smoother: {smooth_growth} bytes per step"
            );
        }
        times.push((loglik_seconds, smooth_seconds));
    }
    // linear time: ten times the steps, about ten times the time (generous bounds for a
    // shared machine)
    for (what, small, large) in [
        ("loglik", times[0].0, times[1].0),
        ("smoother", times[0].1, times[1].1),
    ] {
        let ratio = large / small;
        assert!(
            (4.0..25.0).contains(&ratio),
            "{what}: 10x the steps took {ratio:.1}x the time"
        );
    }
}

fn serde_json_line(fields: &[(&str, String)]) -> String {
    let body: Vec<String> = fields
        .iter()
        .map(|(k, v)| format!("\"{k}\": {v}"))
        .collect();
    format!("{{{}}}", body.join(", "))
}

#[test]
#[ignore = "T = 10^6: cargo test --release -p sysid --test long_series -- --ignored --nocapture --test-threads 1"]
fn lgss_a_million_steps() {
    // mean, variance, lag-one covariance and gain per step: well under 200 bytes
    long_run(System::Lgss, 200.0);
}

#[test]
#[ignore = "T = 10^6: cargo test --release -p sysid --test long_series -- --ignored --nocapture --test-threads 1"]
fn lti2x2_a_million_steps() {
    // n = 8: a mean (64 B), a covariance and a lag-one covariance (2 x 512 B) and the
    // factors the smoother keeps; bounded by a few kB per step
    long_run(System::Lti2x2, 4096.0);
}
