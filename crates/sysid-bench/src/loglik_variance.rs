//! `loglik-variance` runner: the single-run Monte Carlo sd of the particle
//! log-likelihood (`sysid_smc`'s genealogy estimator, the default of `sysid pf`)
//! against its independent reference, the sd over `runs` independent filters, on lgss
//! (T = 1000, M = 100 and 1000) and nlbench (T = 1000, M = 1000 and 10 000), systematic
//! resampling; and what the estimate costs: one filter with it against one without,
//! timed in alternating pairs.
//!
//! ```text
//! cargo run --release -p sysid-bench -- loglik-variance [--runs 200 --reps 11]
//! ```

use crate::emit;
use serde_json::json;
use std::time::Instant;
use sysid::models::{LinearGaussianSmc, Nlbench, lgss};
use sysid::smc::{FilterModel, FilterOptions, ParticleFilter, Series, VARIANCE_SPAN, stream};

/// Options of the runner.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Independent runs per case (the reference sd is known to about 1/sqrt(2 runs)).
    #[arg(long, default_value_t = 200)]
    pub runs: u64,
    /// Timed pairs (with and without the estimate) per case; medians are reported.
    #[arg(long, default_value_t = 11)]
    pub reps: usize,
    /// Only the cases of this system (lgss or nlbench).
    #[arg(long)]
    pub system: Option<String>,
}

/// Sample sd.
fn sd(values: &[f64]) -> f64 {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
}

/// The `q`-quantile of sorted `values` (nearest rank).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    sorted[((q * sorted.len() as f64) as usize).min(sorted.len() - 1)]
}

fn case<M: FilterModel + Sync>(system: &str, model: &M, data: &Series<'_>, m: usize, a: &Args) {
    let options = |block| FilterOptions {
        particles: m,
        record_summaries: false,
        variance_block: block,
        ..FilterOptions::default()
    };
    let mut with = ParticleFilter::new(options(Some(VARIANCE_SPAN))).expect("valid options");
    let mut without = ParticleFilter::new(options(None)).expect("valid options");
    let (mut logliks, mut singles) = (Vec::new(), Vec::new());
    for run in 0..a.runs {
        let summary = with.run(model, data, run + 1000).expect("filter");
        logliks.push(summary.loglik);
        singles.push(summary.loglik_variance.expect("estimated").sqrt());
    }
    let reference = sd(&logliks);
    let mut sorted = logliks.clone();
    sorted.sort_by(f64::total_cmp);
    // a robust sd: what the bulk of the runs scatter by, when a few lose the state
    let iqr_sd = (quantile(&sorted, 0.75) - quantile(&sorted, 0.25)) / 1.349;
    singles.sort_by(f64::total_cmp);
    let median = quantile(&singles, 0.5);
    let (mut on, mut off) = (Vec::new(), Vec::new());
    for rep in 0..a.reps as u64 {
        let seed: u64 = rand::RngExt::random(&mut stream(rep, 7));
        let start = Instant::now();
        without.run(model, data, seed).expect("filter");
        off.push(start.elapsed().as_secs_f64() * 1e3);
        let start = Instant::now();
        with.run(model, data, seed).expect("filter");
        on.push(start.elapsed().as_secs_f64() * 1e3);
    }
    let (ms_off, _, _) = crate::summary(&mut off);
    let (ms_on, _, _) = crate::summary(&mut on);
    emit(&json!({
        "task": "loglik_variance",
        "params": {"system": system, "T": data.steps(), "M": m, "runs": a.runs,
            "span": VARIANCE_SPAN, "resampling": "systematic"},
        "sd_over_runs": reference, "iqr_sd_over_runs": iqr_sd,
        "single_run_sd_median": median,
        "single_run_sd_p10": quantile(&singles, 0.1), "single_run_sd_p90": quantile(&singles, 0.9),
        "ratio": median / reference,
        "ms_median_with": ms_on, "ms_median_without": ms_off, "cost_ratio": ms_on / ms_off,
    }));
}

/// Runs the cases.
pub fn run(a: &Args) -> Result<(), String> {
    if a.runs < 3 || a.reps == 0 {
        return Err("--runs must be at least 3 and --reps at least 1".into());
    }
    let wanted = |s: &str| a.system.as_deref().is_none_or(|w| w == s);
    if let Some(s) = &a.system
        && s != "lgss"
        && s != "nlbench"
    {
        return Err(format!("--system {s:?}: lgss or nlbench"));
    }
    if wanted("lgss") {
        let model = lgss();
        let smc = LinearGaussianSmc::new(&model).map_err(|e| e.to_string())?;
        let sim = model
            .simulate(&nalgebra::DMatrix::zeros(0, 1000), &mut stream(5, 0))
            .map_err(|e| e.to_string())?;
        let y: Vec<f64> = sim.record.y.iter().copied().collect();
        let data = Series::new(&y, 1).map_err(|e| e.to_string())?;
        for m in [100, 1000] {
            case("lgss", &smc, &data, m, a);
        }
    }
    if wanted("nlbench") {
        let model = Nlbench::truth();
        let sim = model.simulate(1000, 1);
        let data = Series::new(&sim.outputs, 1).map_err(|e| e.to_string())?;
        // at 1000, `sysid pf`'s default, some runs lose the state: the sd over the runs
        // is theirs, the interquartile sd the others'
        for m in [1000, 10_000] {
            case("nlbench", &model, &data, m, a);
        }
    }
    Ok(())
}
