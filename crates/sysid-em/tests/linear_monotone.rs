//! Exact EM never decreases the likelihood: 200 seeded random systems mixing fixed
//! matrices, fixed individual entries, a free S, diagonal Q/R, inputs, offsets and
//! missing data, 25 iterations each; one system in four also bounds the noise variances
//! from below (`min_variance`).

use nalgebra::{DMatrix, DVector};
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use sysid_em::linear::{Covariance, FixedEntries, LinearEmSpec, fit};
use sysid_em::{EmOptions, Termination};
use sysid_kalman::{LinearGaussianModel, Record};

fn gaussian(rng: &mut Xoshiro256PlusPlus, r: usize, c: usize) -> DMatrix<f64> {
    DMatrix::from_fn(r, c, |_, _| StandardNormal.sample(rng))
}

fn spd(rng: &mut Xoshiro256PlusPlus, n: usize, floor: f64) -> DMatrix<f64> {
    let g = gaussian(rng, n, n);
    (&g * g.transpose()) / n as f64 + DMatrix::identity(n, n) * floor
}

fn covariance(rng: &mut Xoshiro256PlusPlus) -> Covariance {
    match rng.random_range(0..3) {
        0 => Covariance::Full,
        1 => Covariance::Diagonal,
        _ => Covariance::Fixed,
    }
}

/// A random system, its data (with gaps) and a random mix of free and fixed parameters,
/// and a perturbed starting model.
fn case(seed: u64) -> (LinearGaussianModel, Vec<Record>, LinearEmSpec) {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let n = rng.random_range(1..=4);
    let p = rng.random_range(1..=3);
    let m = rng.random_range(0..=2);
    let g = gaussian(&mut rng, n, n);
    let a = &g * (rng.random_range(0.3..0.95) / g.norm());
    let truth = LinearGaussianModel::builder(
        a,
        gaussian(&mut rng, p, n),
        spd(&mut rng, n, 0.05),
        spd(&mut rng, p, 0.05),
    )
    .b(gaussian(&mut rng, n, m))
    .d(gaussian(&mut rng, p, m))
    .h(DVector::from_fn(p, |_, _| rng.random_range(-1.0..1.0)))
    .p1(spd(&mut rng, n, 0.1))
    .build()
    .unwrap();
    let records: Vec<Record> = (0..rng.random_range(1..=2))
        .map(|_| {
            let u = gaussian(&mut rng, m, 60);
            let mut rec = truth.simulate(&u, &mut rng).unwrap().record;
            for t in 0..60 {
                if rng.random_bool(0.05) {
                    rec.y.column_mut(t).fill(f64::NAN);
                } else if rng.random_bool(0.1) {
                    let i = rng.random_range(0..p);
                    rec.y[(i, t)] = f64::NAN;
                }
            }
            rec
        })
        .collect();
    let mut mask = |r: usize, c: usize| {
        rng.random_bool(0.3)
            .then(|| DMatrix::from_fn(r, c, |_, _| rng.random_bool(0.3)))
    };
    let fixed_entries = FixedEntries {
        a: mask(n, n),
        b: mask(n, m),
        c: mask(p, n),
        d: mask(p, m),
    };
    let s_free = rng.random_bool(0.2);
    let spec = LinearEmSpec {
        s: s_free,
        fixed_entries,
        a: rng.random_bool(0.7),
        b: rng.random_bool(0.7),
        c: rng.random_bool(0.7),
        d: rng.random_bool(0.5),
        h: rng.random_bool(0.5),
        q: if s_free {
            Covariance::Full
        } else {
            covariance(&mut rng)
        },
        r: if s_free {
            Covariance::Full
        } else {
            covariance(&mut rng)
        },
        mu: rng.random_bool(0.5),
        p1: rng.random_bool(0.5),
        // every fourth system: a floor above some of the true noise variances (>= 0.05)
        min_variance: if seed % 4 == 1 { 0.3 } else { 0.0 },
        // every fourth system: a per-output floor on R, above some true variances
        output_noise_floor: (seed % 4 == 2 && !s_free)
            .then(|| nalgebra::DVector::from_fn(p, |i, _| 0.1 + 0.2 * i as f64)),
    };
    let start = truth
        .to_builder()
        .a(truth.a() * 0.6)
        .c(truth.c() + gaussian(&mut rng, p, n) * 0.3)
        .q(truth.q() * 2.0)
        .r(truth.r() * 0.5)
        .build()
        .unwrap();
    let start = spec.project(&start).unwrap();
    (start, records, spec)
}

#[test]
fn exact_em_never_decreases_the_likelihood() {
    let options = EmOptions {
        max_iterations: 25,
        tol: 0.0,
        ..EmOptions::default()
    }
    .check()
    .unwrap();
    let mut worst = 0.0_f64;
    let mut gains = Vec::new();
    let mut ecm_runs = 0;
    let mut floor_active = 0;
    let (mut output_floor_runs, mut output_floor_active) = (0, 0);
    for seed in 0..200 {
        let (start, records, spec) = case(seed);
        ecm_runs += spec.needs_ecm() as usize;
        let result = fit(start, &records, spec.clone(), &options, &mut ());
        if spec.min_variance > 0.0 {
            floor_active += floor_holds(&result.estimate, &spec, seed) as usize;
        }
        if let Some(floor) = &spec.output_noise_floor
            && spec.r != Covariance::Fixed
        {
            output_floor_runs += 1;
            let r = result.estimate.r();
            let whitened = DMatrix::from_fn(r.nrows(), r.ncols(), |i, j| {
                r[(i, j)] / (floor[i] * floor[j]).sqrt()
            });
            let low = nalgebra::SymmetricEigen::new(whitened).eigenvalues.min();
            assert!(
                low >= 1.0 - 1e-9,
                "seed {seed}: R below its output floor ({low})"
            );
            output_floor_active += (low <= 1.0 + 1e-9) as usize;
        }
        assert_eq!(
            result.termination,
            Termination::MaxIterations,
            "seed {seed} ({spec:?})"
        );
        for w in result.trace.windows(2) {
            let rel = (w[0] - w[1]) / w[0].abs();
            worst = worst.max(rel);
            assert!(rel <= 1e-10, "seed {seed}: {} -> {} ({spec:?})", w[0], w[1]);
        }
        gains.push(result.trace[result.trace.len() - 1] - result.trace[0]);
    }
    // the test must be able to fail: EM really moves the likelihood
    let moved = gains.iter().filter(|&&g| g > 1.0).count();
    assert!(
        moved > 150,
        "only {moved} of 200 runs improved the log-likelihood by more than 1"
    );
    eprintln!(
        "largest relative decrease {worst:e}; runs improving by > 1: {moved}/200; ECM runs {ecm_runs}"
    );
    assert!(ecm_runs > 50, "the mix must exercise the conditional route");
    eprintln!("runs ending on the variance floor: {floor_active}/50");
    assert!(floor_active >= 10, "the floor must bind in some runs");
    eprintln!("runs ending on the output floor: {output_floor_active}/{output_floor_runs}");
    assert!(
        output_floor_active >= 5,
        "the output floor must bind in some runs"
    );
}

/// Asserts that the free noise covariances respect the floor; returns whether one of
/// them sits on it.
fn floor_holds(model: &LinearGaussianModel, spec: &LinearEmSpec, seed: u64) -> bool {
    let smallest = |m: &DMatrix<f64>| nalgebra::SymmetricEigen::new(m.clone()).eigenvalues.min();
    let mut on_floor = false;
    let mut free = Vec::new();
    if spec.s {
        // the joint [[Q, S], [S', R]] from the model's own factor L'L
        let l = model.noise_factor();
        let joint = l.transpose() * l;
        free.push(joint);
    } else {
        for (structure, m) in [(spec.q, model.q()), (spec.r, model.r())] {
            if structure != Covariance::Fixed {
                free.push(m.clone());
            }
        }
    }
    for m in free {
        let low = smallest(&m);
        assert!(
            low >= spec.min_variance * (1.0 - 1e-9),
            "seed {seed}: a variance {low} below the floor {}",
            spec.min_variance
        );
        on_floor |= low <= spec.min_variance * (1.0 + 1e-9);
    }
    on_floor
}

#[test]
fn a_start_outside_the_spec_is_refused() {
    let (start, records, spec) = case(4);
    let full_q = start
        .to_builder()
        .q(start.q() + DMatrix::from_element(start.n(), start.n(), 0.01))
        .build()
        .unwrap();
    let spec = LinearEmSpec {
        q: Covariance::Diagonal,
        ..spec
    };
    let result = fit(
        full_q,
        &records,
        spec,
        &sysid_em::CheckedEmOptions::default(),
        &mut (),
    );
    assert!(matches!(
        result.termination,
        Termination::Error {
            error: sysid_em::linear::LinearEmError::InitialNotInSpec { matrix: "Q", .. },
            ..
        }
    ));
}
