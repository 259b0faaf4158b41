//! The check of the robust particle EM fit's answer (the polish's curvature, probed
//! along its flattest directions) against the exact answer on a linear Gaussian model
//! written as an affine model file: the estimate is the exact maximum's, and the
//! standard errors from the particle log-likelihood's curvature are the exact ones
//! within 30 %.

mod common;

use common::ar1::{exact, exact_covariance, exact_maximum, model_file, record_and_series};
use sysid_em::{FitRun, FitSettings};
use sysid_modelfile::{Criterion, FileFitReport, ModelFile};
use sysid_smc::Series;

/// `x' = a x + w`, `y = x + e`: affine in `a`, so the default fit is the robust
/// driver. The file's values are a rough start (truth a = 0.8, q = 0.3, r = 0.5).
fn ar1() -> String {
    model_file("ar1", "a", "a*x")
}

/// At its defaults the robust fit ends within 0.3 nats (exact log-likelihood) of the
/// exact maximum, with no warning, and its standard errors are the exact ones within
/// 30 %. `q` and `r` are strongly negatively correlated (the noise can sit in the
/// state or in the measurement): the direction a coordinate-wise curvature sees worst.
/// Over seeds 1 to 8 the fits ended 0.001 to 0.11 nats below the maximum, and the
/// standard errors were 0.81 to 1.34 times the exact ones (2 of 24 beyond 30 %:
/// seed 1's `q`, 1.34, seed 8's `a`, 1.31); seed 5 is one of them.
#[test]
fn the_robust_fits_standard_errors_are_the_exact_ones() {
    let (record, y) = record_and_series();
    let (best, max_loglik) = exact_maximum(&record);
    let file = ModelFile::parse(&ar1(), "ar1.toml").unwrap();
    let method = file
        .fit_method(Criterion::Likelihood, &FitSettings::default())
        .unwrap();
    let fit = file
        .fit(
            Series::new(&y, 1).unwrap(),
            &method,
            &FitRun::new(5),
            &mut (),
        )
        .unwrap();
    assert_eq!(fit.method(), "robust");
    let FileFitReport::Affine(affine) = &fit.report else {
        panic!("not the affine fit")
    };
    let [a, q, r] = [fit.estimate[0], fit.estimate[1], fit.estimate[2]];
    let at_estimate = exact(&record, [a, q.ln(), r.ln()]);
    assert!(
        at_estimate > max_loglik - 0.3,
        "exact loglik at the estimate {at_estimate} against the maximum {max_loglik} \
         (a {a:.4}, q {q:.4}, r {r:.4}; exact a {:.4}, q {:.4}, r {:.4})",
        best[0],
        best[1].exp(),
        best[2].exp()
    );
    assert!(affine.loglik().is_some());
    let cov = exact_covariance(&record, best);
    let reference = [
        cov[(0, 0)].sqrt(),
        best[1].exp() * cov[(1, 1)].sqrt(),
        best[2].exp() * cov[(2, 2)].sqrt(),
    ];
    let se = fit.standard_errors().expect("standard errors");
    for (k, (got, want)) in se.iter().zip(reference).enumerate() {
        assert!(
            (got / want - 1.0).abs() < 0.3,
            "standard error {k}: {got} against the exact {want} ({se:?}, {reference:?})"
        );
    }
    assert!(fit.warnings.is_empty(), "{:?}", fit.warnings);
}
