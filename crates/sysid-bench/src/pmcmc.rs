//! `pmcmc` runner: the speed targets of the Bayesian issue and a posterior check.
//!
//! - `pmmh_iteration`: one PMMH iteration on `nlbench` (M = 100, T = 1000), one thread:
//!   the median over repetitions of (time of a 100-iteration chain) / 100;
//! - `pgas_iteration`, `pgas_guided_iteration`: one particle-Gibbs iteration (ancestor
//!   sampling, bootstrap or guided proposal, M = 10, T = 1000)
//!   on `lgss` with the conjugate step;
//! - `pmmh_chains_throughput`: 2 and 8 chains on 1 and on 2 threads, `reps` alternating
//!   pairs (the speed-up of the median times, the range of the pairs' ratios, the
//!   chains' own summed durations on 2 threads over 1 thread, which shows contention,
//!   and the wall time over half the summed durations, which shows the wait for the
//!   slower thread);
//! - `pmcmc_lgss_posterior`: PMMH and PGAS posterior means and sds of (phi, q, r) on an
//!   `lgss` record of T = 100 against an exact-likelihood (Kalman) Metropolis chain,
//!   with the ESS of each.

use crate::emit;
use serde_json::json;
use std::sync::Mutex;
use std::time::Instant;
use sysid::models::{LgssConjugate, LgssFamily, Nlbench, NlbenchFamily, System};
use sysid::pmcmc::{
    ChainObserver, ChainRun, CsmcKernel, GibbsOptions, IndependentPrior, ModelFamily, PmmhOptions,
    ScalarPrior, effective_sample_size, particle_gibbs, particle_gibbs_guided, pmmh, summarise,
};
use sysid::smc::Series;

fn lgss_prior() -> IndependentPrior {
    IndependentPrior::new(
        &LgssFamily::default().parameter_names(),
        LgssFamily::DEFAULT_PRIORS.to_vec(),
    )
    .expect("valid priors")
}

fn conjugate() -> LgssConjugate {
    LgssConjugate::from_priors(&LgssFamily::DEFAULT_PRIORS).expect("conjugate priors")
}

/// Median over `reps` seeded runs of `run(seed)`'s time divided by `iterations`, in ms.
fn ms_per_iteration(reps: usize, iterations: usize, mut run: impl FnMut(u64)) -> f64 {
    let ms: Vec<f64> = (0..reps as u64)
        .map(|r| {
            let start = Instant::now();
            run(r);
            start.elapsed().as_secs_f64() * 1e3 / iterations as f64
        })
        .collect();
    median(ms)
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool")
}

fn median(mut v: Vec<f64>) -> f64 {
    crate::summary(&mut v).0
}

/// Runs every task with `reps` repetitions for the timings.
pub fn run(reps: usize) {
    let one = pool(1);
    // PMMH on nlbench, M = 100, T = 1000
    let sim = Nlbench::truth().simulate(1000, 1);
    let nl = Series::new(&sim.outputs, 1).expect("finite");
    let family = NlbenchFamily::default();
    let nl_prior = IndependentPrior::new(
        &family.parameter_names(),
        vec![ScalarPrior::Flat; family.dim()],
    )
    .expect("flat");
    let iterations = 100;
    let pmmh_options = PmmhOptions {
        iterations,
        burn_in: 1,
        particles: 100,
        ..Default::default()
    };
    let run_pmmh = |chains: usize, iterations: usize, seed: u64, observer: &dyn ChainObserver| {
        pmmh(
            &family,
            &nl_prior,
            &nl,
            &family.truth(),
            &PmmhOptions {
                iterations,
                ..pmmh_options.clone()
            },
            &ChainRun::new(chains, seed).observed_by(observer),
        )
        .expect("runs");
    };
    let pmmh_ms = ms_per_iteration(reps, iterations, |r| {
        one.install(|| run_pmmh(1, iterations, r, &()))
    });
    emit(
        &json!({"task": "pmmh_iteration", "params": {"system": "nlbench", "T": 1000, "M": 100, "threads": 1},
        "ms_median": pmmh_ms, "target_ms": 2.0, "met": pmmh_ms <= 2.0}),
    );

    // PGAS on lgss, M = 10, T = 1000
    let lg = System::Lgss.simulate(1000, 1).expect("simulates");
    let y = lg.record.y.as_slice().to_vec();
    let lg_series = Series::new(&y, 1).expect("finite");
    let gibbs = GibbsOptions {
        iterations,
        burn_in: 1,
        particles: 10,
        kernel: CsmcKernel::AncestorSampling,
    };
    for (guided, task) in [(false, "pgas_iteration"), (true, "pgas_guided_iteration")] {
        let run = if guided {
            particle_gibbs_guided
        } else {
            particle_gibbs
        };
        let ms = ms_per_iteration(reps, iterations, |r| {
            one.install(|| {
                run(
                    &LgssFamily::default(),
                    &lgss_prior(),
                    &conjugate(),
                    &lg_series,
                    &[0.5, 1.0, 1.0],
                    &gibbs,
                    &ChainRun::new(1, r),
                )
            })
            .expect("runs");
        });
        emit(
            &json!({"task": task, "params": {"system": "lgss", "T": 1000, "M": 10, "threads": 1},
            "ms_median": ms}),
        );
    }

    // Throughput of C chains on 1 and 2 threads: `reps` pairs of runs, the two settings
    // alternating so that both see the machine's current mode; the speed-up is the
    // ratio of the medians, and the per-pair ratios give its range. Each chain's own
    // duration separates contention (a chain running slower beside another) from
    // waiting for the slower thread at the end.
    let (one_thread, two_threads) = (pool(1), pool(2));
    let mut speedup_2_chains = f64::NAN;
    for (chains, iterations) in [(2usize, 300usize), (8, 100)] {
        let timed = |p: &rayon::ThreadPool, seed: u64| {
            let clock = ChainClock::new(chains, iterations);
            let start = Instant::now();
            p.install(|| run_pmmh(chains, iterations, seed, &clock));
            (start.elapsed().as_secs_f64(), clock.total_seconds())
        };
        let pairs: Vec<((f64, f64), (f64, f64))> = (0..reps as u64)
            .map(|r| (timed(&one_thread, 9 + r), timed(&two_threads, 9 + r)))
            .collect();
        let serial = median(pairs.iter().map(|p| p.0.0).collect());
        let parallel = median(pairs.iter().map(|p| p.1.0).collect());
        let mut ratios: Vec<f64> = pairs.iter().map(|(s, p)| s.0 / p.0).collect();
        let (_, lowest, highest) = crate::summary(&mut ratios);
        let contention = median(pairs.iter().map(|(s, p)| p.1 / s.1).collect());
        let waiting = median(pairs.iter().map(|(_, p)| p.0 / (p.1 / 2.0)).collect());
        if chains == 2 {
            speedup_2_chains = serial / parallel;
        }
        emit(
            &json!({"task": "pmmh_chains_throughput", "params": {"system": "nlbench", "chains": chains, "iterations": iterations, "M": 100, "reps": reps},
            "seconds_1_thread": serial, "seconds_2_threads": parallel, "speedup": serial / parallel,
            "speedup_range": [lowest, highest],
            "chain_time_2_threads_over_1": contention,
            "wall_over_half_chain_time": waiting}),
        );
    }

    posterior_check();
    emit(&json!({"task": "pmcmc_summary", "params": {"reps": reps},
        "pmmh_ms_per_iteration": pmmh_ms, "pmmh_target_ms": 2.0,
        "chains_speedup_2_threads": speedup_2_chains}));
}

/// Records when each chain finished its first and its last iteration.
struct ChainClock {
    last: usize,
    marks: Mutex<Vec<(Option<Instant>, Option<Instant>)>>,
}

impl ChainClock {
    fn new(chains: usize, iterations: usize) -> Self {
        ChainClock {
            last: iterations - 1,
            marks: Mutex::new(vec![(None, None); chains]),
        }
    }

    /// The chains' durations (first to last iteration) added up, in seconds.
    fn total_seconds(&self) -> f64 {
        let marks = self.marks.lock().expect("not poisoned");
        marks
            .iter()
            .map(|m| match m {
                (Some(a), Some(b)) => (*b - *a).as_secs_f64(),
                _ => 0.0,
            })
            .sum()
    }
}

impl ChainObserver for ChainClock {
    fn iteration(&self, chain: usize, iteration: usize) {
        if iteration == 0 || iteration == self.last {
            let now = Instant::now();
            let mut marks = self.marks.lock().expect("not poisoned");
            if iteration == 0 {
                marks[chain].0 = Some(now);
            } else {
                marks[chain].1 = Some(now);
            }
        }
    }
}

/// PMMH and PGAS against an exact-likelihood random-walk Metropolis chain on lgss.
fn posterior_check() {
    let sim = System::Lgss.simulate(100, 5).expect("simulates");
    let y = sim.record.y.as_slice().to_vec();
    let data = Series::new(&y, 1).expect("finite");
    let family = LgssFamily::default();
    let prior = lgss_prior();
    let draws = family
        .exact_posterior_draws(&prior, &sim.record, [0.9, 1.0, 0.5], 200_000, 20_000, 1)
        .expect("finite likelihoods");
    let exact: Vec<serde_json::Value> = draws
        .iter()
        .map(|d| {
            let n = d.len() as f64;
            let mean = d.iter().sum::<f64>() / n;
            let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            json!({"mean": mean, "sd": sd, "ess": effective_sample_size(d)})
        })
        .collect();
    let start = [0.5, 1.0, 1.0];
    let pmmh_chains = pmmh(
        &family,
        &prior,
        &data,
        &start,
        &PmmhOptions {
            iterations: 6_000,
            burn_in: 1_000,
            particles: 100,
            ..Default::default()
        },
        &ChainRun::new(4, 7),
    )
    .expect("runs");
    let pgas_chains = particle_gibbs(
        &family,
        &prior,
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
    .expect("runs");
    emit(
        &json!({"task": "pmcmc_lgss_posterior", "params": {"T": 100, "chains": 4, "iterations": 6000, "burn_in": 1000,
            "pmmh_M": 100, "pgas_M": 10, "exact_iterations": 200_000},
        "exact": exact, "pmmh": summarise(&pmmh_chains), "pgas": summarise(&pgas_chains),
        "pmmh_acceptance": pmmh_chains.iter().map(|c| c.acceptance_rate()).collect::<Vec<_>>()}),
    );
}
