//! Rough timing of the SMC kernels on `nlbench` (T = 1000); the criterion group `smc`
//! and the runner `sysid-bench smc` are the measurements of record.
//! Usage: `cargo run --release --example pf_quick [pf|pf10k|pf2|tanizaki|ffbsi|reject|all]`
//! (`pf10k`: only the M = 10 000 filter on one thread; `pf2`: the same on a 2-thread
//! pool with `parallel` set)
//! (`PF_QUICK_DEFAULT_ONLY=1` stops `tanizaki` after its default settings, for profiling).
use std::time::Instant;
use sysid::prelude::*;
use sysid::smc::{Ffbsi, FfbsiReject, Tanizaki};

fn median(mut f: impl FnMut(u64), reps: u64) -> f64 {
    let mut t: Vec<f64> = (0..reps)
        .map(|r| {
            let s = Instant::now();
            f(r);
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn main() {
    let what = std::env::args().nth(1).unwrap_or_else(|| "all".into());
    let model = Nlbench::truth();
    let sim = model.simulate(1000, 3);
    let data = Series::new(&sim.outputs, 1).unwrap();
    let filter = |m: usize, history: bool| {
        ParticleFilter::new(FilterOptions {
            particles: m,
            store_history: history,
            ..Default::default()
        })
        .unwrap()
    };
    if what == "pf" || what == "all" {
        for (m, history) in [(50usize, true), (100, false), (1000, false), (10000, false)] {
            let mut pf = filter(m, history);
            let ms = median(
                |r| {
                    pf.run(&model, &data, r).unwrap();
                },
                15,
            );
            println!("pf M={m} (history {history}): {ms:.3} ms");
        }
    }
    if what == "pf10k" {
        let mut pf = filter(10_000, false);
        let ms = median(
            |r| {
                pf.run(&model, &data, r).unwrap();
            },
            15,
        );
        println!("pf M=10000, 1 thread: {ms:.3} ms");
    }
    if what == "pf2" || what == "all" {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let mut pf = ParticleFilter::new(FilterOptions {
            particles: 10_000,
            parallel: true,
            ..Default::default()
        })
        .unwrap();
        let ms = pool.install(|| {
            median(
                |r| {
                    pf.run(&model, &data, r).unwrap();
                },
                15,
            )
        });
        println!("pf M=10000, 2 threads: {ms:.3} ms");
    }
    if what == "tanizaki" || what == "all" {
        let mut pf = filter(50, true);
        pf.run(&model, &data, 1).unwrap();
        let h = pf.history().unwrap();
        let ms = median(
            |r| {
                Tanizaki::default()
                    .trajectories(&model, h, &data, r)
                    .unwrap();
            },
            41,
        );
        let stats = Tanizaki::default()
            .trajectories(&model, h, &data, 0)
            .unwrap()
            .1;
        println!("tanizaki M=50: {ms:.3} ms {stats:?}");
        if std::env::var_os("PF_QUICK_DEFAULT_ONLY").is_some() {
            return;
        }
        let exact = Tanizaki {
            parallel: false,
            max_trials: Some(0),
        };
        let ms = median(
            |r| {
                exact.trajectories(&model, h, &data, r).unwrap();
            },
            41,
        );
        println!("tanizaki M=50, exact draws only: {ms:.3} ms");
    }
    let mut pf = filter(1000, true);
    pf.run(&model, &data, 1).unwrap();
    let h = pf.history().unwrap();
    if what == "ffbsi" || what == "all" {
        let ms = median(
            |r| {
                Ffbsi {
                    paths: 100,
                    parallel: false,
                }
                .trajectories(&model, h, &data, r)
                .unwrap();
            },
            5,
        );
        println!("ffbsi 100 paths M=1000: {ms:.3} ms");
    }
    if what == "reject" || what == "all" {
        let smoother = FfbsiReject {
            paths: 100,
            max_trials: None,
            parallel: false,
        };
        let ms = median(
            |r| {
                smoother.trajectories(&model, h, &data, r).unwrap();
            },
            11,
        );
        let stats = smoother.trajectories(&model, h, &data, 0).unwrap().1;
        println!("ffbsi-reject 100 paths M=1000: {ms:.3} ms {stats:?}");
    }
}
