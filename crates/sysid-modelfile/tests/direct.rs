//! The multi-start direct fit of a model file that is not affine in its parameters
//! (`fit --model` with the default method) against the exact answer on a linear
//! Gaussian model written non-affinely: the maximum of the Kalman log-likelihood,
//! found by a grid and a coordinate-wise ternary search that share no code with the
//! fit's Nelder–Mead or its particle filter.

mod common;

use common::ar1::{exact, exact_covariance, exact_maximum, model_file, record_and_series};
use sysid_em::FitRun;
use sysid_modelfile::{DirectFitOptions, FileFitMethod, FileFitReport, ModelFile};
use sysid_smc::Series;

/// `x' = tanh(s) x + w`, `y = x + e`: linear in the state, not affine in `s`. The
/// file's values are a rough start (truth: tanh(s) = 0.8, q = 0.3, r = 0.5). The
/// initial mean is not 0, so that the noise-free simulation (which the fit's
/// identifiability check differentiates) moves.
fn ar1() -> String {
    model_file("ar1-tanh", "s", "tanh(s)*x")
}

fn options(starts: usize, polish_particles: usize) -> FileFitMethod {
    FileFitMethod::Direct(DirectFitOptions {
        starts,
        polish_particles,
    })
}

/// From a start with `a` 0.29 (truth 0.8) and both variances 3-4 times too large, the
/// estimate's exact log-likelihood is within 0.15 nats of the exact maximum (it was
/// 0.8 below before the finish reshaped its simplex by the curvature), the reported
/// log-likelihood is the exact one at the estimate within 4 of its own Monte Carlo sd
/// (plus 0.05 for the log's bias), and the standard errors from the particle
/// log-likelihood's curvature are the exact ones within 30 %.
#[test]
fn the_direct_fit_lands_on_the_exact_maximum_of_a_linear_model() {
    let (record, y) = record_and_series();
    let (best, max_loglik) = exact_maximum(&record);
    let file = ModelFile::parse(&ar1(), "ar1-tanh.toml").unwrap();
    assert!(file.affine().is_none(), "tanh(s) x is not affine in s");
    let fit = file
        .fit(
            Series::new(&y, 1).unwrap(),
            &options(4, 5000),
            &FitRun::new(3),
            &mut (),
        )
        .unwrap();
    assert_eq!(fit.method(), "direct");
    let FileFitReport::Direct { fit: direct, .. } = &fit.report else {
        panic!("not the direct fit")
    };
    let [s, q, r] = [fit.estimate[0], fit.estimate[1], fit.estimate[2]];
    let at_estimate = exact(&record, [s.tanh(), q.ln(), r.ln()]);
    assert!(
        at_estimate > max_loglik - 0.15,
        "exact loglik at the estimate {at_estimate} against the maximum {max_loglik} \
         (a {:.4}, q {:.4}, r {:.4}; exact a {:.4}, q {:.4}, r {:.4})",
        s.tanh(),
        q,
        r,
        best[0],
        best[1].exp(),
        best[2].exp()
    );
    let reported = fit.loglik().unwrap();
    assert!(
        (reported - at_estimate).abs() < 4.0 * direct.loglik_sd + 0.05,
        "reported {reported} (sd {}) against the exact {at_estimate}",
        direct.loglik_sd
    );
    assert!(direct.loglik_sd > 0.0 && direct.loglik_sd < 1.0);
    // s = atanh a, so ds/da = 1 / (1 - a^2); q and r are exp of their coordinates
    let cov = exact_covariance(&record, best);
    let reference = [
        cov[(0, 0)].sqrt() / (1.0 - best[0] * best[0]),
        best[1].exp() * cov[(1, 1)].sqrt(),
        best[2].exp() * cov[(2, 2)].sqrt(),
    ];
    let se = direct.standard_errors.as_ref().expect("standard errors");
    for (k, (got, want)) in se.iter().zip(reference).enumerate() {
        assert!(
            (got / want - 1.0).abs() < 0.3,
            "standard error {k}: {got} against the exact {want} ({se:?}, {reference:?})"
        );
    }
    assert!(fit.warnings.is_empty(), "{:?}", fit.warnings);
}

/// The starts run in parallel; the result is the same bits on one thread and on two.
#[test]
fn the_direct_fit_is_the_same_on_one_thread_and_two() {
    let (_, y) = record_and_series();
    let file = ModelFile::parse(&ar1(), "ar1-tanh.toml").unwrap();
    let options = options(3, 500);
    let on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let fit = file
                    .fit(
                        Series::new(&y, 1).unwrap(),
                        &options,
                        &FitRun::new(8),
                        &mut (),
                    )
                    .unwrap();
                let mut bits: Vec<u64> = fit.estimate.iter().map(|v| v.to_bits()).collect();
                bits.push(fit.loglik().unwrap().to_bits());
                bits
            })
    };
    assert_eq!(on(1), on(2));
}

/// The finish's check probes along the curvature's flattest directions. Before it, the
/// fits from seeds 1, 7 and 8 stopped 1.7, 1.2 and 1.5 nats (exact log-likelihood)
/// below the exact maximum on the `q`-`r` ridge, with standard errors from a
/// curvature that was not a maximum's dropped and no warning; with it they end within
/// 0.04, 0.33 and 0.04 nats (seeds 1 to 8: at most 0.33). Each either ends within
/// 0.5 nats or says why not.
#[test]
fn the_direct_fit_climbs_the_ridge_or_warns() {
    let (record, y) = record_and_series();
    let (_, max_loglik) = exact_maximum(&record);
    let file = ModelFile::parse(&ar1(), "ar1-tanh.toml").unwrap();
    for seed in [1, 7, 8] {
        let fit = file
            .fit(
                Series::new(&y, 1).unwrap(),
                &options(4, 5000),
                &FitRun::new(seed),
                &mut (),
            )
            .unwrap();
        let [s, q, r] = [fit.estimate[0], fit.estimate[1], fit.estimate[2]];
        let gap = max_loglik - exact(&record, [s.tanh(), q.ln(), r.ln()]);
        assert!(
            gap < 0.5 || !fit.warnings.is_empty(),
            "seed {seed}: {gap} nats below the exact maximum, and no warning"
        );
    }
}
