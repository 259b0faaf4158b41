//! Particle methods against the exact Kalman answer on `lgss` (ALGORITHMS.md 2.1-2.3):
//! unbiasedness of the likelihood estimate, smoothed means against RTS, rejection FFBSi
//! against O(M^2) FFBSi, and bit-identical results for any thread count.

mod common;

use common::{assert_close_to_rts, lgss_data, mean_se};

use sysid::kalman::KalmanWorkspace;
use sysid::models::{LinearGaussianSmc, Nlbench, System, lgss};
use sysid::smc::{
    Ffbsi, FfbsiReject, FilterOptions, Genealogy, ParticleFilter, Resampling, Series, Smoother,
    Tanizaki, Trajectories,
};

/// A filter with `particles` particles that stores its history for the smoothers.
fn stored_filter(particles: usize) -> ParticleFilter {
    ParticleFilter::new(FilterOptions {
        particles,
        store_history: true,
        ..Default::default()
    })
    .unwrap()
}

#[test]
fn likelihood_estimate_is_unbiased_for_every_scheme_and_threshold() {
    let (record, y) = lgss_data(100, 11);
    let exact = KalmanWorkspace::new().loglik(&lgss(), &record).unwrap();
    let model = LinearGaussianSmc::new(&lgss()).unwrap();
    let data = Series::new(&y, 1).unwrap();
    for scheme in Resampling::ALL {
        for threshold in [1.0, 0.5] {
            let mut pf = ParticleFilter::new(FilterOptions {
                particles: 100,
                resampling: scheme,
                ess_threshold: threshold,
                ..Default::default()
            })
            .unwrap();
            let ratios: Vec<f64> = (0..2000)
                .map(|run| (pf.run(&model, &data, run).unwrap().loglik - exact).exp())
                .collect();
            let (mean, se) = mean_se(&ratios);
            eprintln!(
                "{} ess {threshold}: mean exp(l^ - l) = {mean:.4} (se {se:.4})",
                scheme.name()
            );
            assert!(
                (mean - 1.0).abs() < 3.0 * se,
                "{} ess {threshold}: mean ratio {mean} (se {se})",
                scheme.name()
            );
            assert!(
                se < 0.1,
                "{}: the test has no power (se {se})",
                scheme.name()
            );
        }
    }
}

#[test]
fn adaptive_resampling_skips_some_steps() {
    // With a threshold of 0.5 the filter must actually skip resampling on lgss.
    let (_, y) = lgss_data(100, 11);
    let model = LinearGaussianSmc::new(&lgss()).unwrap();
    let data = Series::new(&y, 1).unwrap();
    let mut pf = ParticleFilter::new(FilterOptions {
        particles: 100,
        ess_threshold: 0.5,
        ..Default::default()
    })
    .unwrap();
    let run = pf.run(&model, &data, 3).unwrap();
    assert!(
        run.resampled_steps > 0 && run.resampled_steps < 99,
        "{run:?}"
    );
}

#[test]
fn a_filter_without_summaries_gives_the_same_likelihood_and_history() {
    // PMMH and particle EM switch the per-step means and ESS off; nothing else may move,
    // with resampling at every step and with adaptive resampling (which needs the ESS).
    let (_, y) = lgss_data(100, 12);
    let model = LinearGaussianSmc::new(&lgss()).unwrap();
    let data = Series::new(&y, 1).unwrap();
    for ess_threshold in [1.0, 0.5] {
        let options = |record_summaries| FilterOptions {
            particles: 64,
            ess_threshold,
            store_history: true,
            record_summaries,
            ..Default::default()
        };
        let mut with = ParticleFilter::new(options(true)).unwrap();
        let mut without = ParticleFilter::new(options(false)).unwrap();
        let a = with.run(&model, &data, 4).unwrap();
        let b = without.run(&model, &data, 4).unwrap();
        assert_eq!(a.loglik.to_bits(), b.loglik.to_bits());
        assert_eq!(a.resampled_steps, b.resampled_steps);
        let (h1, h2) = (with.history().unwrap(), without.history().unwrap());
        for t in 0..100 {
            assert_eq!(h1.states(t), h2.states(t));
            assert_eq!(h1.weights(t), h2.weights(t));
            assert_eq!(h1.ancestors(t), h2.ancestors(t));
        }
        assert_eq!((with.means().len(), with.ess().len()), (100, 100));
        assert!(without.means().is_empty() && without.ess().is_empty());
    }
}

/// Smoothed means of `replications` independent filter+smoother runs, per step.
fn replicate_means<S: Smoother<LinearGaussianSmc>>(
    smoother: &S,
    particles: usize,
    y: &[f64],
    replications: u64,
) -> Vec<Vec<f64>> {
    let model = LinearGaussianSmc::new(&lgss()).unwrap();
    let data = Series::new(y, 1).unwrap();
    let mut pf = ParticleFilter::new(FilterOptions {
        particles,
        store_history: true,
        ..Default::default()
    })
    .unwrap();
    (0..replications)
        .map(|r| {
            pf.run(&model, &data, 1000 + r).unwrap();
            let (paths, _) = smoother
                .trajectories(&model, pf.history().unwrap(), &data, 2000 + r)
                .unwrap();
            paths.means()
        })
        .collect()
}

#[test]
fn smoothed_means_match_rts_within_four_standard_errors() {
    // Particle smoothers are consistent with an O(1/M) bias; M = 500 keeps it below
    // the Monte Carlo standard error of 24 replications on a typical record.
    let (record, y) = lgss_data(100, 11);
    let mut ws = KalmanWorkspace::new();
    let rts: Vec<f64> = {
        let out = ws.smooth(&lgss(), &record).unwrap();
        (0..100).map(|t| out.mean(t)[0]).collect()
    };
    let tanizaki = replicate_means(&Tanizaki::default(), 500, &y, 24);
    assert_close_to_rts("tanizaki", &tanizaki, &rts);
    let ffbsi = replicate_means(
        &Ffbsi {
            paths: 500,
            parallel: false,
        },
        500,
        &y,
        24,
    );
    assert_close_to_rts("ffbsi", &ffbsi, &rts);
    let reject = FfbsiReject {
        paths: 500,
        max_trials: None,
        parallel: false,
    };
    let rejection = replicate_means(&reject, 500, &y, 24);
    assert_close_to_rts("ffbsi-reject", &rejection, &rts);
}

/// Two-sample Kolmogorov-Smirnov statistic.
fn ks_statistic(a: &mut [f64], b: &mut [f64]) -> f64 {
    a.sort_by(f64::total_cmp);
    b.sort_by(f64::total_cmp);
    let (mut i, mut j, mut d) = (0, 0, 0.0f64);
    while i < a.len() && j < b.len() {
        let x = a[i].min(b[j]);
        while i < a.len() && a[i] <= x {
            i += 1;
        }
        while j < b.len() && b[j] <= x {
            j += 1;
        }
        d = d.max((i as f64 / a.len() as f64 - j as f64 / b.len() as f64).abs());
    }
    d
}

#[test]
fn rejection_ffbsi_and_exact_ffbsi_draw_the_same_marginals() {
    let (_, y) = lgss_data(100, 31);
    let model = LinearGaussianSmc::new(&lgss()).unwrap();
    let data = Series::new(&y, 1).unwrap();
    // (at most 256 particles: each path's envelope is its own maximum)
    let mut pf = stored_filter(200);
    pf.run(&model, &data, 5).unwrap();
    let history = pf.history().unwrap();
    let k = 2000;
    let (exact, _) = Ffbsi {
        paths: k,
        parallel: false,
    }
    .trajectories(&model, history, &data, 1)
    .unwrap();
    let (rejection, stats) = FfbsiReject {
        paths: k,
        max_trials: None,
        parallel: false,
    }
    .trajectories(&model, history, &data, 2)
    .unwrap();
    assert!(stats.trials > 0);
    assert_same_marginals(&exact, &rejection, &[0, 25, 50, 75, 99]);
}

/// Given the filter, two smoothers that draw i.i.d. paths from the same law: KS at
/// level 0.001 (critical value 1.95 sqrt(2 / k) for k paths each) at the time points.
fn assert_same_marginals(a: &Trajectories, b: &Trajectories, times: &[usize]) {
    let critical = 1.95 * (2.0 / a.paths() as f64).sqrt();
    for &t in times {
        let d = ks_statistic(&mut a.states(t).to_vec(), &mut b.states(t).to_vec());
        assert!(d < critical, "t = {t}: KS {d} >= {critical}");
    }
}

#[test]
fn tanizaki_by_rejection_and_by_exact_draws_give_the_same_marginals() {
    // nlbench: peaked transitions, so both the accepted proposals and the exact
    // fallback are exercised.
    let model = Nlbench::truth();
    let sim = model.simulate(60, 4);
    let data = Series::new(&sim.outputs, 1).unwrap();
    let mut pf = stored_filter(1000);
    pf.run(&model, &data, 3).unwrap();
    let history = pf.history().unwrap();
    let exact_smoother = Tanizaki {
        parallel: false,
        max_trials: Some(0),
    };
    let (exact, exact_stats) = exact_smoother
        .trajectories(&model, history, &data, 1)
        .unwrap();
    assert_eq!(exact_stats.trials, 0);
    // the default cap, and a cap of 2 trials, under which many rows fall back
    for (cap, seed) in [(None, 2), (Some(2), 3)] {
        let smoother = Tanizaki {
            parallel: false,
            max_trials: cap,
        };
        let (rejection, stats) = smoother.trajectories(&model, history, &data, seed).unwrap();
        assert!(stats.trials > 0, "{stats:?}");
        if cap.is_some() {
            assert!(stats.fallbacks > 0, "{stats:?}");
        }
        assert_same_marginals(&exact, &rejection, &[0, 15, 30, 45, 59]);
    }
}

#[test]
fn genealogy_paths_are_filter_ancestries() {
    let (_, y) = lgss_data(50, 41);
    let model = LinearGaussianSmc::new(&lgss()).unwrap();
    let data = Series::new(&y, 1).unwrap();
    let mut pf = stored_filter(100);
    pf.run(&model, &data, 9).unwrap();
    let h = pf.history().unwrap();
    let (paths, _) = Genealogy { paths: 10 }
        .trajectories(&model, h, &data, 3)
        .unwrap();
    for k in 0..10 {
        // Each state at t must be the ancestor of the state at t + 1.
        for t in 0..49 {
            let next = paths.state(t + 1, k)[0];
            let i = h.states(t + 1).iter().position(|&x| x == next).unwrap();
            let parent = h.ancestors(t + 1)[i];
            assert_eq!(paths.state(t, k)[0], h.states(t)[parent]);
        }
    }
}

#[test]
fn same_seed_gives_identical_bits_with_one_and_four_threads() {
    let model = Nlbench::truth();
    let sim = model.simulate(200, 4);
    let data = Series::new(&sim.outputs, 1).unwrap();
    let run = |threads: usize| {
        common::on_threads(threads, || {
            let mut pf = ParticleFilter::new(FilterOptions {
                particles: 5000,
                store_history: true,
                parallel: true,
                // the team itself, whatever else runs on the machine
                share_busy_processors: true,
                ..Default::default()
            })
            .unwrap();
            let loglik = pf.run(&model, &data, 77).unwrap().loglik;
            let history = pf.history().unwrap();
            let (paths, _) = Ffbsi {
                paths: 100,
                parallel: true,
            }
            .trajectories(&model, history, &data, 78)
            .unwrap();
            let (rejected, _) = FfbsiReject {
                paths: 100,
                max_trials: None,
                parallel: true,
            }
            .trajectories(&model, history, &data, 79)
            .unwrap();
            (loglik.to_bits(), pf.means().to_vec(), paths, rejected)
        })
    };
    let one = run(1);
    let four = run(4);
    assert_eq!(one.0, four.0);
    assert!(
        one.1
            .iter()
            .zip(&four.1)
            .all(|(a, b)| a.to_bits() == b.to_bits())
    );
    assert_eq!(one.2, four.2);
    assert_eq!(one.3, four.3);
    // And the parallel filter equals the sequential one.
    let mut pf = ParticleFilter::new(FilterOptions {
        particles: 5000,
        ..Default::default()
    })
    .unwrap();
    assert_eq!(pf.run(&model, &data, 77).unwrap().loglik.to_bits(), one.0);
}

/// `Nlbench` without its scalar-Gaussian capability, so that smoothers take the
/// general path that evaluates every candidate.
struct WithoutScalarMeans(Nlbench);

impl sysid::smc::StateSpace for WithoutScalarMeans {
    fn state_dim(&self) -> usize {
        1
    }
}

impl sysid::smc::TransitionDensity for WithoutScalarMeans {
    fn log_transition(&self, t: usize, x: &[f64], u: &[f64], next: &[f64]) -> f64 {
        self.0.log_transition(t, x, u, next)
    }

    fn log_transition_matrix(
        &self,
        t: usize,
        u: &[f64],
        from: &[f64],
        to: &[f64],
        out: &mut [f64],
        scratch: &mut Vec<f64>,
    ) {
        self.0.log_transition_matrix(t, u, from, to, out, scratch);
    }
}

#[test]
fn tanizaki_by_windows_of_means_and_by_the_general_kernel_draw_the_same_marginals() {
    // nlbench's scalar form sends Tanizaki's smoother down its windowed rejection route
    // (sorted means, each row proposing from its window); the general kernel with no
    // trials draws every path exactly. Pooled over 40 runs (2000 paths) on one history.
    use sysid::smc::TransitionDensity;
    let model = Nlbench::truth();
    assert!(
        model
            .scalar_gaussian_means(0, &[], &[0.5], &mut Vec::new())
            .is_some()
    );
    let sim = model.simulate(300, 8);
    let data = Series::new(&sim.outputs, 1).unwrap();
    let mut pf = stored_filter(50);
    pf.run(&model, &data, 5).unwrap();
    let history = pf.history().unwrap();
    let general = WithoutScalarMeans(Nlbench::truth());
    let times = [0, 75, 150, 225, 299];
    let pooled = |smoother: &Tanizaki, general_kernel: bool| {
        let mut states = vec![Vec::new(); times.len()];
        let mut total = sysid::smc::SmootherStats::default();
        for seed in 0..40 {
            let (paths, stats) = if general_kernel {
                smoother.trajectories(&general, history, &data, 100 + seed)
            } else {
                smoother.trajectories(&model, history, &data, 100 + seed)
            }
            .unwrap();
            for (pool, &t) in states.iter_mut().zip(&times) {
                pool.extend_from_slice(paths.states(t));
            }
            total.trials += stats.trials;
            total.fallbacks += stats.fallbacks;
        }
        (states, total)
    };
    let exact = Tanizaki {
        parallel: false,
        max_trials: Some(0),
    };
    let (mut reference, _) = pooled(&exact, true);
    let critical = 1.95 * (2.0 / reference[0].len() as f64).sqrt();
    for max_trials in [None, Some(1)] {
        let smoother = Tanizaki {
            parallel: false,
            max_trials,
        };
        let (mut windowed, stats) = pooled(&smoother, false);
        let (_, uniform_stats) = pooled(&smoother, true);
        assert!(stats.fallbacks > 0, "{stats:?}");
        // the windows accept more proposals than uniform ones against the row maximum
        assert!(
            stats.trials + stats.fallbacks < uniform_stats.trials + uniform_stats.fallbacks,
            "{stats:?} vs {uniform_stats:?}"
        );
        for (k, &t) in times.iter().enumerate() {
            let d = ks_statistic(&mut reference[k], &mut windowed[k]);
            assert!(
                d < critical,
                "t = {t}, max_trials {max_trials:?}: KS {d} >= {critical}"
            );
        }
    }
}

impl sysid::smc::TransitionBound for WithoutScalarMeans {
    fn log_transition_bound(&self, t: usize, u: &[f64]) -> f64 {
        self.0.log_transition_bound(t, u)
    }
}

#[test]
fn rejection_ffbsi_by_windows_of_means_and_exact_ffbsi_draw_the_same_marginals() {
    // nlbench's scalar form sends rejection FFBSi down its windowed route at the steps
    // whose means spread (weighted candidates, each row proposing from its window of
    // sorted means); the exact FFBSi evaluates every candidate of every draw.
    use sysid::smc::TransitionBound;
    let model = Nlbench::truth();
    let sim = model.simulate(300, 8);
    let data = Series::new(&sim.outputs, 1).unwrap();
    let mut pf = stored_filter(50);
    pf.run(&model, &data, 5).unwrap();
    let history = pf.history().unwrap();
    let paths = 2000;
    let times = [0, 75, 150, 225, 299];
    let (reference, _) = Ffbsi {
        paths,
        parallel: false,
    }
    .trajectories(&model, history, &data, 1)
    .unwrap();
    // the model's own bound (the general route) for comparison
    let general = WithoutScalarMeans(Nlbench::truth());
    assert!(general.log_transition_bound(0, &[]).is_finite());
    for max_trials in [None, Some(1)] {
        let smoother = FfbsiReject {
            paths,
            max_trials,
            parallel: false,
        };
        let (windowed, stats) = smoother.trajectories(&model, history, &data, 2).unwrap();
        let (_, general_stats) = smoother.trajectories(&general, history, &data, 3).unwrap();
        assert!(stats.fallbacks > 0, "{stats:?}");
        assert!(
            stats.trials + stats.fallbacks < general_stats.trials + general_stats.fallbacks,
            "{stats:?} vs {general_stats:?}"
        );
        assert_same_marginals(&reference, &windowed, &times);
    }
}

/// Everything a filter run leaves behind, as bits.
fn filter_bits(pf: &ParticleFilter, loglik: f64, resampled: usize) -> Vec<u64> {
    let mut bits = vec![loglik.to_bits(), resampled as u64];
    bits.extend(pf.means().iter().chain(pf.ess()).map(|v| v.to_bits()));
    if let Some(h) = pf.history() {
        for t in 0..h.steps() {
            let floats = h
                .states(t)
                .iter()
                .chain(h.weights(t))
                .chain(h.log_weights(t));
            bits.extend(floats.map(|v| v.to_bits()));
            bits.extend(h.ancestors(t).iter().map(|&a| a as u64));
        }
    }
    bits
}

/// The filter's team of threads (any size, any split of the chunks) gives the bits of
/// the sequential filter: chunks that do not divide M, missing outputs, adaptive
/// resampling with every scheme, eight states with inputs, with and without summaries.
#[test]
fn the_filter_team_gives_the_sequential_bits_in_every_setting() {
    let sim = System::Lti2x2.simulate(60, 5).unwrap();
    let mut y = sim.record.y.as_slice().to_vec();
    y[2 * 7] = f64::NAN; // step 7 partly missing
    y[2 * 20..2 * 23].fill(f64::NAN); // steps 20-22 missing
    let data = Series::new(&y, 2)
        .unwrap()
        .with_inputs(sim.record.u.as_slice(), 2)
        .unwrap();
    // (lti2x2 drives its states without noise; the particle filter needs Q > 0)
    let q = nalgebra::DMatrix::identity(8, 8) * 0.01;
    let noisy = sysid::models::lti2x2().to_builder().q(q).build().unwrap();
    let model = LinearGaussianSmc::new(&noisy).unwrap();
    let mut cases = vec![(2500, Resampling::Systematic, 1.0, true)];
    for scheme in Resampling::ALL {
        cases.push((2100, scheme, 0.5, true));
    }
    cases.push((3 * 1024, Resampling::Systematic, 1.0, false));
    for (particles, resampling, ess_threshold, record_summaries) in cases {
        let run = |threads: usize| {
            common::on_threads(threads, || {
                let mut pf = ParticleFilter::new(FilterOptions {
                    particles,
                    resampling,
                    ess_threshold,
                    store_history: true,
                    parallel: threads > 1,
                    share_busy_processors: true,
                    record_summaries,
                    // the genealogy's variance estimate: thread-independent too
                    variance_block: Some(2),
                })
                .unwrap();
                let summary = pf.run(&model, &data, 31).unwrap();
                (
                    filter_bits(&pf, summary.loglik, summary.resampled_steps),
                    summary.loglik_variance.map(f64::to_bits),
                )
            })
        };
        let sequential = run(1);
        for threads in [2, 3] {
            assert!(
                sequential == run(threads),
                "{particles} particles, {}, ESS {ess_threshold}, {threads} threads",
                resampling.name()
            );
        }
    }
}
