//! The fully adapted filter (`GuidedFilter`) against the exact Kalman answer on
//! `lgss`: its likelihood estimate is unbiased, and the smoothers draw from its
//! history the right smoothing distribution (the history's steps are not marked
//! resampled, so the smoothers use the weighted clouds).

mod common;

use common::{assert_close_to_rts, lgss_data, mean_se};
use sysid::kalman::KalmanWorkspace;
use sysid::models::{LinearGaussianSmc, lgss};
use sysid::smc::{FfbsiReject, GuidedFilter, Series, Smoother};

#[test]
fn the_guided_likelihood_estimate_is_unbiased() {
    let (record, y) = lgss_data(100, 11);
    let exact = KalmanWorkspace::new().loglik(&lgss(), &record).unwrap();
    let model = LinearGaussianSmc::new(&lgss()).unwrap();
    let data = Series::new(&y, 1).unwrap();
    let mut filter = GuidedFilter::new(20).unwrap();
    let ratios: Vec<f64> = (0..2000)
        .map(|run| (filter.run(&model, &data, run).unwrap() - exact).exp())
        .collect();
    let (mean, se) = mean_se(&ratios);
    eprintln!("guided, M = 20: mean exp(l^ - l) = {mean:.4} (se {se:.4})");
    assert!((mean - 1.0).abs() < 3.0 * se, "mean ratio {mean} (se {se})");
    assert!(se < 0.05, "the test has no power (se {se})");
    assert!(se > 0.0, "a particle estimate cannot be exact");
}

#[test]
fn smoothing_a_guided_history_matches_rts() {
    let (record, y) = lgss_data(100, 11);
    let mut ws = KalmanWorkspace::new();
    let rts: Vec<f64> = {
        let out = ws.smooth(&lgss(), &record).unwrap();
        (0..100).map(|t| out.mean(t)[0]).collect()
    };
    let model = LinearGaussianSmc::new(&lgss()).unwrap();
    let data = Series::new(&y, 1).unwrap();
    let mut filter = GuidedFilter::new(300).unwrap();
    let smoother = FfbsiReject {
        paths: 300,
        max_trials: None,
        parallel: false,
    };
    let runs: Vec<Vec<f64>> = (0..24)
        .map(|r| {
            filter.run(&model, &data, 1000 + r).unwrap();
            let history = filter.history().unwrap();
            assert!((0..100).all(|t| !history.resampled_after(t)));
            let (paths, _) = smoother
                .trajectories(&model, history, &data, 2000 + r)
                .unwrap();
            paths.means()
        })
        .collect();
    assert_close_to_rts("ffbsi-reject on the guided history", &runs, &rts);
}

#[test]
fn the_same_seed_gives_the_same_bits_and_a_bad_particle_count_is_an_error() {
    let (_, y) = lgss_data(50, 3);
    let model = LinearGaussianSmc::new(&lgss()).unwrap();
    let data = Series::new(&y, 1).unwrap();
    let mut a = GuidedFilter::new(16).unwrap();
    let mut b = GuidedFilter::new(16).unwrap();
    assert!(a.history().is_none());
    let (la, lb) = (
        a.run(&model, &data, 9).unwrap(),
        b.run(&model, &data, 9).unwrap(),
    );
    assert_eq!(la.to_bits(), lb.to_bits());
    assert_eq!(
        a.history().unwrap().states(49),
        b.history().unwrap().states(49)
    );
    assert_ne!(la.to_bits(), a.run(&model, &data, 10).unwrap().to_bits());
    assert!(GuidedFilter::new(1).is_err());
}
