//! Bayesian identification against exact answers on `lgss` (ALGORITHMS.md 5): the
//! conditional SMC kernels leave the Kalman smoothing distribution invariant; PMMH and
//! particle Gibbs reach the posterior of an exact-likelihood Metropolis chain; PGAS
//! mixes with 10 particles where plain particle Gibbs degenerates; chains are
//! bit-identical for any thread count.

mod common;

use sysid::kalman::{KalmanWorkspace, Record};
use sysid::models::{LgssConjugate, LgssFamily, LinearGaussianSmc, System, lgss};
use sysid::pmcmc::{
    Chain, ChainRun, GibbsOptions, IndependentPrior, MetropolisWithinGibbs, ModelFamily,
    ParameterStep, PmmhOptions, effective_sample_size, particle_gibbs, particle_gibbs_guided, pmmh,
    summarise,
};
use sysid::smc::{ConditionalSmc, CsmcKernel, Rng, Series, stream};

fn lgss_data(steps: usize, seed: u64) -> (Record, Vec<f64>) {
    let sim = System::Lgss.simulate(steps, seed).unwrap();
    let y = sim.record.y.as_slice().to_vec();
    (sim.record, y)
}

fn prior() -> IndependentPrior {
    IndependentPrior::new(
        &LgssFamily::default().parameter_names(),
        LgssFamily::DEFAULT_PRIORS.to_vec(),
    )
    .unwrap()
}

fn conjugate() -> LgssConjugate {
    LgssConjugate::from_priors(&LgssFamily::DEFAULT_PRIORS).unwrap()
}

/// Posterior mean, sd and ESS of each parameter from the exact-likelihood (Kalman)
/// random-walk Metropolis chain.
fn exact_posterior(record: &Record, iterations: usize, seed: u64) -> Vec<(f64, f64, f64)> {
    LgssFamily::default()
        .exact_posterior_draws(
            &prior(),
            record,
            [0.9, 1.0, 0.5],
            iterations,
            iterations / 10,
            seed,
        )
        .unwrap()
        .iter()
        .map(|d| {
            let n = d.len() as f64;
            let mean = d.iter().sum::<f64>() / n;
            let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            (mean, sd, effective_sample_size(d))
        })
        .collect()
}

/// Asserts that the chains' posterior mean and sd of every parameter agree with the
/// exact ones within 4 combined Monte Carlo standard errors (the sd's standard error
/// taken as `sd / sqrt(2 ESS)`, its value for Gaussian draws).
fn assert_matches_exact(name: &str, chains: &[Chain], exact: &[(f64, f64, f64)]) {
    for (s, &(mean, sd, ess)) in summarise(chains).iter().zip(exact) {
        let mean_se = (s.mcse.powi(2) + sd * sd / ess).sqrt();
        let sd_se = (s.sd.powi(2) / (2.0 * s.ess) + sd * sd / (2.0 * ess)).sqrt();
        eprintln!(
            "{name} {}: mean {:.4} vs {mean:.4} (se {mean_se:.4}), sd {:.4} vs {sd:.4} (se {sd_se:.4}), ESS {:.0} vs exact {ess:.0}, R-hat {:.3}",
            s.name, s.mean, s.sd, s.ess, s.rhat
        );
        assert!(
            (s.mean - mean).abs() < 4.0 * mean_se,
            "{name} {}: posterior mean {} vs exact {mean} (se {mean_se})",
            s.name,
            s.mean
        );
        assert!(
            (s.sd - sd).abs() < 4.0 * sd_se,
            "{name} {}: posterior sd {} vs exact {sd} (se {sd_se})",
            s.name,
            s.sd
        );
        // power: a shift of a third of a posterior sd would be detected
        assert!(
            4.0 * mean_se < sd / 3.0,
            "{name} {}: too few effective draws ({})",
            s.name,
            s.ess
        );
        assert!(s.rhat < 1.05, "{name} {}: R-hat {}", s.name, s.rhat);
    }
}

#[test]
fn pmmh_and_particle_gibbs_reach_the_exact_posterior() {
    let (record, y) = lgss_data(100, 5);
    let data = Series::new(&y, 1).unwrap();
    let exact = exact_posterior(&record, 200_000, 1);
    let family = LgssFamily::default();
    let start = [0.5, 1.0, 1.0];

    let pmmh_chains = pmmh(
        &family,
        &prior(),
        &data,
        &start,
        &PmmhOptions {
            iterations: 6_000,
            burn_in: 1_000,
            // The log-likelihood estimate's sd on this record is 1.85 at M = 100 and
            // 1.25 at M = 200 (10 000 filter runs); near 1.2 PMMH mixes well (Doucet et
            // al. 2015), at 1.85 a chain sticks and the ESS varies too much from one
            // random stream to the next for the power check below.
            particles: 200,
            ..Default::default()
        },
        &ChainRun::new(4, 7),
    )
    .unwrap();
    for c in &pmmh_chains {
        assert!(
            c.acceptance_rate() > 0.05,
            "PMMH acceptance {}",
            c.acceptance_rate()
        );
    }
    assert_matches_exact("PMMH", &pmmh_chains, &exact);

    for kernel in [CsmcKernel::AncestorSampling, CsmcKernel::BackwardSimulation] {
        let chains = particle_gibbs(
            &family,
            &prior(),
            &conjugate(),
            &data,
            &start,
            &GibbsOptions {
                iterations: 6_000,
                burn_in: 1_000,
                particles: 10,
                kernel,
            },
            &ChainRun::new(4, 8),
        )
        .unwrap();
        assert_matches_exact(kernel.name(), &chains, &exact);
    }
    let guided = particle_gibbs_guided(
        &family,
        &prior(),
        &conjugate(),
        &data,
        &start,
        &GibbsOptions {
            iterations: 6_000,
            burn_in: 1_000,
            particles: 10,
            kernel: CsmcKernel::AncestorSampling,
        },
        &ChainRun::new(4, 8),
    )
    .unwrap();
    assert_matches_exact("guided PGAS", &guided, &exact);
}

#[test]
fn metropolis_within_gibbs_reaches_the_exact_posterior() {
    let (record, y) = lgss_data(100, 5);
    let data = Series::new(&y, 1).unwrap();
    let exact = exact_posterior(&record, 200_000, 2);
    let step = MetropolisWithinGibbs {
        prior: prior(),
        proposal_sd: vec![0.1, 0.4, 0.4],
        sweeps: 5,
    };
    let chains = particle_gibbs(
        &LgssFamily::default(),
        &prior(),
        &step,
        &data,
        &[0.5, 1.0, 1.0],
        &GibbsOptions {
            iterations: 6_000,
            burn_in: 1_000,
            particles: 10,
            kernel: CsmcKernel::AncestorSampling,
        },
        &ChainRun::new(4, 9),
    )
    .unwrap();
    assert_matches_exact("MH-within-PGAS", &chains, &exact);
}

/// Leaves the parameters where they are (the state kernel alone).
#[derive(Clone)]
struct Fixed;

impl ParameterStep<LgssFamily> for Fixed {
    fn update(
        &mut self,
        _: &LgssFamily,
        _: &mut [f64],
        _: &[f64],
        _: &Series,
        _: &mut Rng,
    ) -> Result<bool, sysid::smc::ModelError> {
        Ok(false)
    }
}

#[test]
fn conditional_smc_kernels_leave_the_smoothing_distribution_invariant() {
    let steps = 50;
    let (record, y) = lgss_data(steps, 11);
    let data = Series::new(&y, 1).unwrap();
    let rts: Vec<f64> = {
        let mut ws = KalmanWorkspace::new();
        let out = ws.smooth(&lgss(), &record).unwrap();
        (0..steps).map(|t| out.mean(t)[0]).collect()
    };
    let model = LinearGaussianSmc::new(&lgss()).unwrap();
    for (kernel, particles, guided) in [
        (CsmcKernel::AncestorSampling, 5, false),
        (CsmcKernel::BackwardSimulation, 5, false),
        (CsmcKernel::Plain, 50, false),
        (CsmcKernel::AncestorSampling, 3, true),
        (CsmcKernel::BackwardSimulation, 3, true),
    ] {
        let name = format!("{}{}", kernel.name(), if guided { " (guided)" } else { "" });
        let mut csmc = ConditionalSmc::new(particles, kernel).unwrap();
        let mut rng = stream(3, 0);
        let mut path = vec![0.0; steps];
        let sweep = |csmc: &mut ConditionalSmc,
                     reference: Option<&[f64]>,
                     path: &mut [f64],
                     rng: &mut Rng| {
            if guided {
                csmc.sample_guided(&model, &data, reference, path, rng)
            } else {
                csmc.sample(&model, &data, reference, path, rng)
            }
        };
        sweep(&mut csmc, None, &mut path, &mut rng).unwrap();
        let iterations = 20_000;
        let mut draws: Vec<Vec<f64>> = (0..steps).map(|_| Vec::with_capacity(iterations)).collect();
        let mut reference = path.clone();
        for _ in 0..iterations {
            reference.copy_from_slice(&path);
            sweep(&mut csmc, Some(&reference), &mut path, &mut rng).unwrap();
            for (d, &x) in draws.iter_mut().zip(&path) {
                d.push(x);
            }
        }
        let mut worst: f64 = 0.0;
        for (t, d) in draws.iter().enumerate() {
            let n = d.len() as f64;
            let mean = d.iter().sum::<f64>() / n;
            let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            let se = sd / effective_sample_size(d).sqrt();
            let z = (mean - rts[t]).abs() / se;
            worst = worst.max(z);
            assert!(
                z < 4.5,
                "{name}: t = {t}, chain mean {mean} vs RTS {} ({z:.2} se)",
                rts[t]
            );
        }
        assert!(worst > 0.5, "{name}: suspiciously exact");
    }
}

#[test]
fn ancestor_sampling_mixes_with_ten_particles_where_plain_particle_gibbs_degenerates() {
    let steps = 1000;
    let (_, y) = lgss_data(steps, 13);
    let data = Series::new(&y, 1).unwrap();
    let truth = [0.9, 1.0, 0.5];
    let options = |kernel| GibbsOptions {
        iterations: 600,
        burn_in: 100,
        particles: 10,
        kernel,
    };
    let family = LgssFamily::default();
    let rates = |kernel, guided: bool| {
        let run = if guided {
            particle_gibbs_guided
        } else {
            particle_gibbs
        };
        let chains = run(
            &family,
            &prior(),
            &Fixed,
            &data,
            &truth,
            &options(kernel),
            &ChainRun::new(1, 4),
        )
        .unwrap();
        chains[0].state_update_rate.clone().unwrap()
    };
    let summary = |rates: &[f64]| {
        let mut sorted = rates.to_vec();
        sorted.sort_by(f64::total_cmp);
        (sorted[0], sorted[steps / 10], sorted[steps / 2])
    };
    // PGAS with the locally optimal proposal: the free particles follow the data, so
    // x_t is renewed at every step
    let guided = rates(CsmcKernel::AncestorSampling, true);
    let (min, _, median) = summary(&guided);
    eprintln!("guided PGAS M = 10: update rate min {min:.3}, median {median:.3}");
    assert!(min >= 0.5, "guided PGAS update rate falls to {min}");
    // Bootstrap PGAS: at a few steps where y jumps by several innovation sd, the
    // reference (drawn from the smoothing distribution) outweighs every blind proposal
    // of the 9 free particles, and x_t is rarely renewed there (docs/pmcmc.md)
    let bootstrap = rates(CsmcKernel::AncestorSampling, false);
    let (min, decile, median) = summary(&bootstrap);
    let below = bootstrap.iter().filter(|&&r| r < 0.5).count();
    eprintln!(
        "bootstrap PGAS M = 10: min {min:.3}, 10 % quantile {decile:.3}, median {median:.3}; {below} of {steps} steps below 0.5"
    );
    assert!(
        decile >= 0.5,
        "bootstrap PGAS: more than 10 % of steps below 0.5"
    );
    assert!(
        median >= 0.75,
        "bootstrap PGAS: median update rate {median}"
    );
    // Plain particle Gibbs degenerates far from T - 1, guided or not
    for guided in [false, true] {
        let plain = rates(CsmcKernel::Plain, guided);
        let early: f64 = plain[..50].iter().sum::<f64>() / 50.0;
        let late = plain[steps - 1];
        eprintln!(
            "plain PG M = 10 (guided {guided}): mean update rate over t < 50 {early:.3}, at T - 1 {late:.3}"
        );
        assert!(
            early < 0.1,
            "plain particle Gibbs did not degenerate: {early}"
        );
        assert!(
            late > 0.5,
            "plain particle Gibbs should still move at the end: {late}"
        );
    }
}

#[test]
fn chains_are_bit_identical_for_any_thread_count() {
    let (_, y) = lgss_data(100, 5);
    let data = Series::new(&y, 1).unwrap();
    let family = LgssFamily::default();
    let run = |threads: usize| {
        common::on_threads(threads, || {
            let a = pmmh(
                &family,
                &prior(),
                &data,
                &[0.5, 1.0, 1.0],
                &PmmhOptions {
                    iterations: 300,
                    burn_in: 100,
                    particles: 50,
                    ..Default::default()
                },
                &ChainRun::new(3, 21),
            )
            .unwrap();
            let b = particle_gibbs(
                &family,
                &prior(),
                &conjugate(),
                &data,
                &[0.5, 1.0, 1.0],
                &GibbsOptions {
                    iterations: 300,
                    burn_in: 100,
                    ..Default::default()
                },
                &ChainRun::new(3, 21),
            )
            .unwrap();
            (a, b)
        })
    };
    let one = run(1);
    assert_eq!(one, run(4));
    assert_ne!(one.0[0].samples, one.0[1].samples, "chains must differ");
}

#[test]
fn bad_starts_and_options_are_typed_errors() {
    let (_, y) = lgss_data(20, 5);
    let data = Series::new(&y, 1).unwrap();
    let family = LgssFamily::default();
    let options = PmmhOptions {
        iterations: 10,
        burn_in: 2,
        ..Default::default()
    };
    let err = pmmh(
        &family,
        &prior(),
        &data,
        &[0.5, -1.0, 1.0],
        &options,
        &ChainRun::new(1, 1),
    )
    .unwrap_err();
    assert!(err.to_string().contains("q = -1"), "{err}");
    let err = pmmh(
        &family,
        &prior(),
        &data,
        &[0.5, 1.0],
        &options,
        &ChainRun::new(1, 1),
    )
    .unwrap_err();
    assert!(err.to_string().contains("expected 3"), "{err}");
    let bad = PmmhOptions {
        burn_in: 10,
        ..options.clone()
    };
    let err = pmmh(
        &family,
        &prior(),
        &data,
        &[0.5, 1.0, 1.0],
        &bad,
        &ChainRun::new(1, 1),
    )
    .unwrap_err();
    assert!(err.to_string().contains("burn_in"), "{err}");
    let err = particle_gibbs(
        &family,
        &prior(),
        &conjugate(),
        &data,
        &[0.5, 1.0, 1.0],
        &GibbsOptions {
            particles: 1,
            ..Default::default()
        },
        &ChainRun::new(1, 1),
    )
    .unwrap_err();
    assert!(err.to_string().contains("at least 2 particles"), "{err}");
}

#[test]
fn conditional_smc_refuses_bad_trajectories() {
    let (_, y) = lgss_data(20, 5);
    let data = Series::new(&y, 1).unwrap();
    let model = LinearGaussianSmc::new(&lgss()).unwrap();
    let mut csmc = ConditionalSmc::new(5, CsmcKernel::AncestorSampling).unwrap();
    let mut rng = stream(1, 0);
    let mut short = vec![0.0; 19];
    let err = csmc
        .sample(&model, &data, None, &mut short, &mut rng)
        .unwrap_err();
    assert!(err.to_string().contains("output trajectory"), "{err}");
    let mut path = vec![0.0; 20];
    let mut reference = vec![0.0; 20];
    reference[7] = f64::NAN;
    let err = csmc
        .sample(&model, &data, Some(&reference), &mut path, &mut rng)
        .unwrap_err();
    assert!(err.to_string().contains("time 7"), "{err}");
    let err = csmc
        .sample(&model, &data, Some(&reference[..10]), &mut path, &mut rng)
        .unwrap_err();
    assert!(err.to_string().contains("reference trajectory"), "{err}");
    // nothing to add before a successful sweep: no panic
    let mut count = 0;
    ConditionalSmc::new(3, CsmcKernel::Plain)
        .unwrap()
        .add_weighted_paths(&mut |_: usize, _: &[f64], _: Option<&[f64]>, _: f64| count += 1);
    assert_eq!(count, 0);
}

/// A proposal outside the model's domain has likelihood zero: PMMH rejects it and goes
/// on, where it used to end the run with an error. The guide's oscillator with a
/// negative spring constant `k` sends some particles' states to infinity, whose
/// observation density is NaN; `sysid pmmh` on it failed at iteration 86.
#[test]
fn pmmh_rejects_proposals_outside_the_model_s_domain() {
    use sysid::modelfile::ModelFile;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let file = ModelFile::read(&root.join("examples/models/oscillator.toml")).unwrap();
    let text = std::fs::read_to_string(root.join("examples/data/oscillator.csv")).unwrap();
    let y: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    let series = Series::new(&y, 1).unwrap();
    let priors = file.priors().into_iter().map(Option::unwrap).collect();
    let prior = IndependentPrior::new(&file.free_names(), priors).unwrap();
    // `sysid pmmh --model oscillator.toml --iters 300 --chains 2`: chain 0 proposed
    // such a k at iteration 86
    let options = PmmhOptions {
        iterations: 300,
        burn_in: 60,
        particles: 100,
        ..PmmhOptions::default()
    };
    let start = file.free_values();
    let chains = pmmh(
        &file,
        &prior,
        &series,
        &start,
        &options,
        &ChainRun::new(2, 1),
    )
    .unwrap();
    for chain in &chains {
        assert_eq!(chain.iterations(), 300);
        let k: Vec<f64> = chain.samples.iter().step_by(2).copied().collect();
        assert!(k.iter().all(|&k| k > 0.0), "k <= 0 accepted");
    }
}
