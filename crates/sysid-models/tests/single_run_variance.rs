//! The single-run estimate of the particle log-likelihood's Monte Carlo variance (from
//! the filter's genealogy, `sysid_smc`'s variance.rs) against its independent
//! reference: the variance over 200 independent runs of the same filter.

use sysid_smc::{FilterOptions, ParticleFilter, Series, stream};

/// lgss, T = 1000, systematic resampling, spans of `VARIANCE_SPAN`: at M = 1000 the sd
/// over 200 runs is 1.63 (known to +-5 %) and the single-run estimates have median
/// 1.47 (10 % low); at M = 100, 4.80 and 4.13 (14 % low, see variance.rs). Both are
/// within the 15 % the estimate is held to, and vary little between runs. The
/// estimate does not change the filter: the log-likelihoods are bit-identical with it
/// on or off.
#[test]
fn the_single_run_sd_is_near_the_sd_over_independent_runs() {
    for particles in [100, 1000] {
        single_run_against_runs(particles);
    }
}

fn single_run_against_runs(particles: usize) {
    let model = sysid_models::lgss();
    let smc = sysid_models::LinearGaussianSmc::new(&model).unwrap();
    let sim = model
        .simulate(&nalgebra::DMatrix::zeros(0, 1000), &mut stream(5, 0))
        .unwrap();
    let y: Vec<f64> = sim.record.y.iter().copied().collect();
    let data = Series::new(&y, 1).unwrap();
    let options = |block| FilterOptions {
        particles,
        record_summaries: false,
        variance_block: block,
        ..FilterOptions::default()
    };
    let mut with = ParticleFilter::new(options(Some(sysid_smc::VARIANCE_SPAN))).unwrap();
    let mut without = ParticleFilter::new(options(None)).unwrap();
    let (mut logliks, mut sds) = (Vec::new(), Vec::new());
    for seed in 0..200u64 {
        let run = with.run(&smc, &data, seed + 1000).unwrap();
        logliks.push(run.loglik);
        sds.push(run.loglik_variance.unwrap().sqrt());
        if seed < 5 {
            let plain = without.run(&smc, &data, seed + 1000).unwrap();
            assert_eq!(plain.loglik.to_bits(), run.loglik.to_bits());
            assert_eq!(plain.loglik_variance, None);
        }
    }
    let mean = logliks.iter().sum::<f64>() / 200.0;
    let sd = (logliks.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / 199.0).sqrt();
    sds.sort_by(f64::total_cmp);
    let (low, median, high) = (sds[20], sds[100], sds[180]);
    assert!(
        (0.85 * sd..1.15 * sd).contains(&median),
        "M = {particles}: sd over runs {sd:.3}, single-run median {median:.3}"
    );
    assert!(high / low < 1.15, "{low:.3}..{high:.3}");
}

/// One outlying observation collapses the weights at its step (the filter recovers, so
/// the state is not lost). There the log-likelihood's error comes from the few
/// weights, which the genealogy cannot measure: the single-run sd is several times too
/// small, and the diagnostics say so; independent repeats show the real scatter.
#[test]
fn a_collapsed_step_flags_the_single_run_sd() {
    use sysid_smc::{FilterDiagnostics, FilterWarning, LoglikSdMethod};
    let model = sysid_models::lgss();
    let smc = sysid_models::LinearGaussianSmc::new(&model).unwrap();
    let sim = model
        .simulate(&nalgebra::DMatrix::zeros(0, 300), &mut stream(5, 0))
        .unwrap();
    let mut y: Vec<f64> = sim.record.y.iter().copied().collect();
    y[150] += OUTLIER;
    let data = Series::new(&y, 1).unwrap();
    let mut pf = ParticleFilter::new(FilterOptions {
        particles: 1000,
        variance_block: Some(sysid_smc::VARIANCE_SPAN),
        ..FilterOptions::default()
    })
    .unwrap();
    let run = pf.run(&smc, &data, 1).unwrap();
    let single = FilterDiagnostics::diagnose(&smc, &data, &pf, &run, 1, 0, || {});
    assert_eq!(single.loglik_sd_method, Some(LoglikSdMethod::SingleRun));
    let flagged = single.warnings.iter().find_map(|w| match w {
        FilterWarning::SingleRunBlind { step, .. } => Some(*step),
        _ => None,
    });
    assert_eq!(flagged, Some(150), "{:?}", single.warnings);
    let repeated = FilterDiagnostics::diagnose(&smc, &data, &pf, &run, 1, 19, || {});
    let (one, many) = (single.loglik_sd.unwrap(), repeated.loglik_sd.unwrap());
    assert!(
        many > 3.0 * one,
        "single run {one:.2}, over 20 runs {many:.2}"
    );
    assert!(
        !repeated
            .warnings
            .iter()
            .any(|w| matches!(w, FilterWarning::SingleRunBlind { .. })),
        "the repeats' sd is not the single run's"
    );
}

/// The outlier of [`a_collapsed_step_flags_the_single_run_sd`]: lgss's state has a
/// predictive sd of about 1.5 and its output noise 0.7, so the particles that explain
/// it sit about 6 predictive sd out, where hardly any of 1000 are (at 8 the sd over 20
/// runs is 1.2 times the single run's, at 10 it is 2.8 times).
const OUTLIER: f64 = 12.0;
