//! The closed-form M-step against a direct numerical maximisation (Nelder-Mead with
//! restarts, started from the E-step's parameters) of the expected complete-data
//! log-likelihood, written out independently from the statistics.

use nalgebra::{DMatrix, DVector, dmatrix, dvector};
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use sysid_em::linear::{Covariance, LinearEm, LinearEmSpec, m_step};
use sysid_kalman::{LinearGaussianModel, Record, SufficientStatistics};

const LN_2PI: f64 = 1.8378770664093453;

/// E{log p(x, y | theta)} from the statistics (H over c = [x; u; 1; x+; y]).
fn expected_loglik(model: &LinearGaussianModel, st: &SufficientStatistics) -> f64 {
    let (n, m, p) = (model.n(), model.m(), model.p());
    let d = st.dim();
    let h = st.second_moment();
    let steps = st.steps() as f64;
    let (ou, o1, oxn, oy) = (n, n + m, n + m + 1, 2 * n + m + 1);
    let mut ws = DMatrix::zeros(n, d);
    ws.view_mut((0, 0), (n, n)).copy_from(&-model.a());
    ws.view_mut((0, ou), (n, m)).copy_from(&-model.b());
    ws.view_mut((0, oxn), (n, n)).fill_with_identity();
    let mut wo = DMatrix::zeros(p, d);
    wo.view_mut((0, 0), (p, n)).copy_from(&-model.c());
    wo.view_mut((0, ou), (p, m)).copy_from(&-model.d());
    wo.view_mut((0, o1), (p, 1)).copy_from(&-model.h());
    wo.view_mut((0, oy), (p, p)).fill_with_identity();
    let term = |w: &DMatrix<f64>, cov: &DMatrix<f64>, count: f64| {
        let k = cov.nrows() as f64;
        let resid = w * h * w.transpose();
        -0.5 * (count * (k * LN_2PI + cov.determinant().ln())
            + (cov.clone().try_inverse().unwrap() * resid).trace())
    };
    let records = st.records() as f64;
    let s1 = st.initial_mean_sum();
    let mu = model.mu();
    let init = st.initial_second_moment_sum() - s1 * mu.transpose() - mu * s1.transpose()
        + mu * mu.transpose() * records;
    let p1 = model.p1();
    term(&ws, model.q(), steps) + term(&wo, model.r(), steps)
        - 0.5
            * (records * (n as f64 * LN_2PI + p1.determinant().ln())
                + (p1.clone().try_inverse().unwrap() * init).trace())
}

/// Free parameters of `spec` <-> a flat vector (covariances by log-Cholesky factors).
fn pack(model: &LinearGaussianModel, spec: &LinearEmSpec) -> Vec<f64> {
    let mut v = Vec::new();
    for (free, mat) in [
        (spec.a, model.a()),
        (spec.b, model.b()),
        (spec.c, model.c()),
        (spec.d, model.d()),
    ] {
        if free {
            v.extend(mat.iter());
        }
    }
    if spec.h {
        v.extend(model.h().iter());
    }
    for (structure, cov) in [(spec.q, model.q()), (spec.r, model.r())] {
        pack_cov(&mut v, structure, cov);
    }
    if spec.mu {
        v.extend(model.mu().iter());
    }
    if spec.p1 {
        pack_cov(&mut v, Covariance::Full, model.p1());
    }
    v
}

fn pack_cov(v: &mut Vec<f64>, structure: Covariance, cov: &DMatrix<f64>) {
    match structure {
        Covariance::Fixed => {}
        Covariance::Diagonal => v.extend(cov.diagonal().iter().map(|x| x.ln())),
        Covariance::Full => {
            let l = cov.clone().cholesky().unwrap().l();
            for j in 0..l.ncols() {
                for i in j..l.nrows() {
                    v.push(if i == j { l[(i, j)].ln() } else { l[(i, j)] });
                }
            }
        }
    }
}

fn unpack(model: &LinearGaussianModel, spec: &LinearEmSpec, v: &[f64]) -> LinearGaussianModel {
    let mut it = v.iter().copied();
    let mut take = |r: usize, c: usize| DMatrix::from_iterator(r, c, it.by_ref().take(r * c));
    let (n, m, p) = (model.n(), model.m(), model.p());
    let mut b = model.to_builder();
    if spec.a {
        b = b.a(take(n, n))
    }
    if spec.b {
        b = b.b(take(n, m))
    }
    if spec.c {
        b = b.c(take(p, n))
    }
    if spec.d {
        b = b.d(take(p, m))
    }
    if spec.h {
        b = b.h(DVector::from_column_slice(take(p, 1).as_slice()))
    }
    let cov = |structure: Covariance,
               k: usize,
               take: &mut dyn FnMut(usize, usize) -> DMatrix<f64>| match structure {
        Covariance::Fixed => None,
        Covariance::Diagonal => Some(DMatrix::from_diagonal(&take(k, 1).column(0).map(f64::exp))),
        Covariance::Full => {
            let mut l = DMatrix::zeros(k, k);
            for j in 0..k {
                for i in j..k {
                    let x = take(1, 1)[(0, 0)];
                    l[(i, j)] = if i == j { x.exp() } else { x };
                }
            }
            Some(&l * l.transpose())
        }
    };
    if let Some(q) = cov(spec.q, n, &mut take) {
        b = b.q(q)
    }
    if let Some(r) = cov(spec.r, p, &mut take) {
        b = b.r(r)
    }
    if spec.mu {
        b = b.mu(DVector::from_column_slice(take(n, 1).as_slice()))
    }
    if spec.p1
        && let Some(p1) = cov(Covariance::Full, n, &mut take)
    {
        b = b.p1(p1)
    }
    b.build().unwrap()
}

/// Nelder-Mead minimisation with restarts until a restart no longer improves.
fn nelder_mead(f: impl Fn(&[f64]) -> f64, x0: Vec<f64>) -> Vec<f64> {
    let k = x0.len();
    let mut best = x0;
    let mut best_f = f(&best);
    for _restart in 0..60 {
        let mut simplex: Vec<(Vec<f64>, f64)> = (0..=k)
            .map(|i| {
                let mut x = best.clone();
                if i > 0 {
                    x[i - 1] += 0.05 * x[i - 1].abs().max(0.1);
                }
                let fx = f(&x);
                (x, fx)
            })
            .collect();
        for _ in 0..20_000 {
            simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
            if simplex[k].1 - simplex[0].1 <= 1e-14 * simplex[0].1.abs().max(1.0) {
                break;
            }
            let centroid: Vec<f64> = (0..k)
                .map(|j| simplex[..k].iter().map(|s| s.0[j]).sum::<f64>() / k as f64)
                .collect();
            let point = |t: f64| -> Vec<f64> {
                (0..k)
                    .map(|j| centroid[j] + t * (simplex[k].0[j] - centroid[j]))
                    .collect()
            };
            let xr = point(-1.0);
            let fr = f(&xr);
            if fr < simplex[0].1 {
                let xe = point(-2.0);
                let fe = f(&xe);
                simplex[k] = if fe < fr { (xe, fe) } else { (xr, fr) };
            } else if fr < simplex[k - 1].1 {
                simplex[k] = (xr, fr);
            } else {
                let xc = point(0.5);
                let fc = f(&xc);
                if fc < simplex[k].1 {
                    simplex[k] = (xc, fc);
                } else {
                    let x0 = simplex[0].0.clone();
                    for s in simplex.iter_mut().skip(1) {
                        s.0 = (0..k).map(|j| x0[j] + 0.5 * (s.0[j] - x0[j])).collect();
                        s.1 = f(&s.0);
                    }
                }
            }
        }
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        if simplex[0].1 >= best_f - 1e-13 * best_f.abs() {
            break;
        }
        best = simplex[0].0.clone();
        best_f = simplex[0].1;
    }
    best
}

fn check(label: &str, model: &LinearGaussianModel, records: &[Record], spec: LinearEmSpec) {
    let (stats, _) = LinearEm::new(records, spec.clone()).e_step(model).unwrap();
    let closed = m_step(model, &stats, &spec).unwrap();
    let objective = |v: &[f64]| -> f64 {
        let candidate = std::panic::catch_unwind(|| unpack(model, &spec, v));
        match candidate {
            Ok(c) => -expected_loglik(&c, &stats),
            Err(_) => f64::INFINITY,
        }
    };
    let numeric = unpack(model, &spec, &nelder_mead(objective, pack(model, &spec)));
    let (q_closed, q_numeric) = (
        expected_loglik(&closed, &stats),
        expected_loglik(&numeric, &stats),
    );
    assert!(
        q_closed >= q_numeric - 1e-9 * q_closed.abs(),
        "{label}: closed {q_closed} < numeric {q_numeric}"
    );
    let (a, b) = (pack(&closed, &spec), pack(&numeric, &spec));
    let diff = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "{label}: Q closed {q_closed:.10}, numeric {q_numeric:.10}, max parameter difference {diff:.1e}"
    );
    assert!(
        diff < 1e-4,
        "{label}: parameters differ by {diff}: {a:?} vs {b:?}"
    );
}

fn data(model: &LinearGaussianModel, steps: usize, seed: u64, gaps: bool) -> Vec<Record> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let u = DMatrix::from_fn(model.m(), steps, |i, t| ((t * (i + 3)) as f64 * 0.7).sin());
    let mut rec = model.simulate(&u, &mut rng).unwrap().record;
    if gaps {
        for t in (0..steps).step_by(5) {
            rec.y[(0, t)] = f64::NAN;
        }
    }
    vec![rec]
}

#[test]
fn scalar_model_everything_free() {
    let truth =
        LinearGaussianModel::builder(dmatrix![0.8], dmatrix![1.2], dmatrix![0.4], dmatrix![0.3])
            .b(dmatrix![0.5])
            .d(dmatrix![0.2])
            .h(dvector![0.7])
            .mu(dvector![0.3])
            .p1(dmatrix![0.8])
            .build()
            .unwrap();
    let start = truth
        .to_builder()
        .a(dmatrix![0.5])
        .c(dmatrix![0.9])
        .q(dmatrix![1.0])
        .build()
        .unwrap();
    check(
        "scalar, all free",
        &start,
        &data(&truth, 80, 1, false),
        LinearEmSpec::default(),
    );
    check(
        "scalar, all free, gaps",
        &start,
        &data(&truth, 80, 2, true),
        LinearEmSpec::default(),
    );
}

#[test]
fn two_states_with_constraints() {
    let truth = LinearGaussianModel::builder(
        dmatrix![0.7, 0.2; -0.1, 0.5],
        dmatrix![1.0, 0.0; 0.5, 1.0],
        dmatrix![0.3, 0.0; 0.0, 0.2],
        dmatrix![0.2, 0.05; 0.05, 0.1],
    )
    .b(dmatrix![1.0; 0.5])
    .h(dvector![0.3, -0.1])
    .build()
    .unwrap();
    let start = truth
        .to_builder()
        .a(dmatrix![0.5, 0.0; 0.0, 0.5])
        .q(dmatrix![0.6, 0.0; 0.0, 0.6])
        .build()
        .unwrap();
    let spec = LinearEmSpec {
        b: false,
        d: false,
        q: Covariance::Diagonal,
        mu: false,
        p1: false,
        ..LinearEmSpec::default()
    };
    check(
        "two states, B and D fixed, diagonal Q",
        &start,
        &data(&truth, 60, 3, true),
        spec,
    );
    let spec = LinearEmSpec {
        a: false,
        c: false,
        r: Covariance::Diagonal,
        ..LinearEmSpec::default()
    };
    let start = spec.project(&start).unwrap();
    check(
        "two states, A and C fixed, diagonal R",
        &start,
        &data(&truth, 60, 4, false),
        spec,
    );
}

/// E{log p} with the joint noise covariance (S included), up to the initial-state term.
fn expected_loglik_joint(
    gamma: &DMatrix<f64>,
    pi: &DMatrix<f64>,
    st: &SufficientStatistics,
) -> f64 {
    let (q, k) = gamma.shape();
    let mut w = DMatrix::zeros(q, k + q);
    w.view_mut((0, 0), (q, k)).copy_from(&-gamma);
    w.view_mut((0, k), (q, q)).fill_with_identity();
    let resid = &w * st.second_moment() * w.transpose();
    let n = st.steps() as f64;
    -0.5 * (n * (q as f64 * LN_2PI + pi.determinant().ln())
        + (pi.clone().try_inverse().unwrap() * resid).trace())
}

fn gamma_pi(model: &LinearGaussianModel) -> (DMatrix<f64>, DMatrix<f64>) {
    let (n, m, p) = (model.n(), model.m(), model.p());
    let mut g = DMatrix::zeros(n + p, n + m + 1);
    g.view_mut((0, 0), (n, n)).copy_from(model.a());
    g.view_mut((0, n), (n, m)).copy_from(model.b());
    g.view_mut((n, 0), (p, n)).copy_from(model.c());
    g.view_mut((n, n), (p, m)).copy_from(model.d());
    g.view_mut((n, n + m), (p, 1)).copy_from(model.h());
    let mut pi = DMatrix::zeros(n + p, n + p);
    pi.view_mut((0, 0), (n, n)).copy_from(model.q());
    pi.view_mut((0, n), (n, p)).copy_from(model.s());
    pi.view_mut((n, 0), (p, n))
        .copy_from(&model.s().transpose());
    pi.view_mut((n, n), (p, p)).copy_from(model.r());
    (g, pi)
}

/// ECM (fixed entries of C, free S): the coefficient step equals the numerical maximum
/// over the free entries of Gamma at the old Pi, and the covariance step the numerical
/// maximum over the joint Pi at the new Gamma.
#[test]
fn ecm_steps_equal_conditional_maximisations() {
    use sysid_em::linear::FixedEntries;
    let truth = LinearGaussianModel::builder(
        dmatrix![0.8],
        dmatrix![1.0; 0.5],
        dmatrix![0.3],
        dmatrix![0.2, 0.05; 0.05, 0.1],
    )
    .b(dmatrix![1.0])
    .d(dmatrix![0.2; -0.3])
    .h(dvector![0.3, -0.1])
    .s(dmatrix![0.1, 0.05])
    .build()
    .unwrap();
    let start = truth
        .to_builder()
        .a(dmatrix![0.5])
        .c(dmatrix![1.0; 0.9])
        .s(dmatrix![0.0, 0.0])
        .build()
        .unwrap();
    let records = data(&truth, 80, 5, true);
    let spec = LinearEmSpec {
        s: true,
        mu: false,
        p1: false,
        fixed_entries: FixedEntries {
            c: Some(DMatrix::from_row_slice(2, 1, &[true, false])),
            ..FixedEntries::default()
        },
        ..LinearEmSpec::default()
    };
    let (stats, _) = LinearEm::new(&records, spec.clone())
        .e_step(&start)
        .unwrap();
    let new = m_step(&start, &stats, &spec).unwrap();
    assert_eq!(new.c()[(0, 0)], 1.0, "the fixed entry stays");
    let (g_old, pi_old) = gamma_pi(&start);
    let (g_new, pi_new) = gamma_pi(&new);
    // free entries: all of column 0..3 except C[0,0] (row 1, col 0) and the state offset (row 0, col 2)
    let free: Vec<(usize, usize)> = (0..3)
        .flat_map(|j| (0..3).map(move |i| (i, j)))
        .filter(|&(i, j)| !((i == 1 && j == 0) || (i == 0 && j == 2)))
        .collect();
    let set = |v: &[f64]| {
        let mut g = g_old.clone();
        for (a, &(i, j)) in free.iter().enumerate() {
            g[(i, j)] = v[a];
        }
        g
    };
    let x0: Vec<f64> = free.iter().map(|&(i, j)| g_old[(i, j)]).collect();
    let best = nelder_mead(|v| -expected_loglik_joint(&set(v), &pi_old, &stats), x0);
    let g_numeric = set(&best);
    let diff = (&g_numeric - &g_new).amax();
    eprintln!("ECM coefficient step vs numerical: max difference {diff:.1e}");
    assert!(diff < 1e-5, "{g_new} vs {g_numeric}");
    // covariance step: log-Cholesky parameters of the 3x3 joint Pi
    let unpack_pi = |v: &[f64]| {
        let mut l = DMatrix::zeros(3, 3);
        let mut it = v.iter();
        for j in 0..3 {
            for i in j..3 {
                let x = *it.next().unwrap();
                l[(i, j)] = if i == j { x.exp() } else { x };
            }
        }
        &l * l.transpose()
    };
    let l0 = pi_old.clone().cholesky().unwrap().l();
    let x0: Vec<f64> = (0..3)
        .flat_map(|j| (j..3).map(move |i| (i, j)))
        .map(|(i, j)| if i == j { l0[(i, j)].ln() } else { l0[(i, j)] })
        .collect();
    let best = nelder_mead(
        |v| -expected_loglik_joint(&g_new, &unpack_pi(v), &stats),
        x0,
    );
    let diff = (unpack_pi(&best) - &pi_new).amax();
    eprintln!("ECM covariance step vs numerical: max difference {diff:.1e}");
    assert!(diff < 1e-5, "{pi_new} vs {}", unpack_pi(&best));
}

/// With a variance floor the M-step is the constrained maximiser: C and R free (full and
/// diagonal), against Nelder-Mead over C and `R = v I + L L'` (`v + l_i^2` for a
/// diagonal R), on a case where the floor binds.
#[test]
fn with_a_variance_floor_the_m_step_is_the_constrained_maximiser() {
    let truth = LinearGaussianModel::builder(
        dmatrix![0.7, 0.2; -0.1, 0.5],
        dmatrix![1.0, 0.0; 0.5, 1.0],
        dmatrix![0.3, 0.0; 0.0, 0.2],
        dmatrix![0.2, 0.05; 0.05, 0.02],
    )
    .build()
    .unwrap();
    let records = data(&truth, 60, 5, true);
    for structure in [Covariance::Full, Covariance::Diagonal] {
        let free = LinearEmSpec {
            a: false,
            b: false,
            d: false,
            h: false,
            q: Covariance::Fixed,
            r: structure,
            mu: false,
            p1: false,
            ..LinearEmSpec::default()
        };
        let start = free
            .project(
                &truth
                    .to_builder()
                    .r(dmatrix![1.0, 0.0; 0.0, 1.0])
                    .build()
                    .unwrap(),
            )
            .unwrap();
        let (stats, _) = LinearEm::new(&records, free.clone())
            .e_step(&start)
            .unwrap();
        let smallest =
            |m: &DMatrix<f64>| nalgebra::SymmetricEigen::new(m.clone()).eigenvalues.min();
        let unconstrained = m_step(&start, &stats, &free).unwrap();
        // a floor above the smallest variance of the unconstrained maximiser (and below
        // the start's, which must lie in the constrained set)
        let floor = 2.0 * smallest(unconstrained.r());
        assert!(floor < 1.0);
        let spec = LinearEmSpec {
            min_variance: floor,
            ..free
        };
        let closed = m_step(&start, &stats, &spec).unwrap();
        assert!(
            (smallest(closed.r()) - floor).abs() < 1e-12,
            "the floor binds"
        );
        let candidate = |v: &[f64]| {
            let c = DMatrix::from_column_slice(2, 2, &v[..4]);
            let r = match structure {
                Covariance::Diagonal => {
                    DMatrix::from_diagonal(&dvector![floor + v[4] * v[4], floor + v[5] * v[5]])
                }
                _ => {
                    let l = dmatrix![v[4], 0.0; v[5], v[6]];
                    DMatrix::identity(2, 2) * floor + &l * l.transpose()
                }
            };
            start.to_builder().c(c).r(r).build()
        };
        let objective = |v: &[f64]| match candidate(v) {
            Ok(model) => -expected_loglik(&model, &stats),
            Err(_) => f64::INFINITY,
        };
        let mut x0: Vec<f64> = start.c().iter().copied().collect();
        x0.extend([0.3, 0.1, 0.3]);
        let numeric = candidate(&nelder_mead(objective, x0)).unwrap();
        let (q_closed, q_numeric) = (
            expected_loglik(&closed, &stats),
            expected_loglik(&numeric, &stats),
        );
        let diff = (closed.r() - numeric.r())
            .amax()
            .max((closed.c() - numeric.c()).amax());
        eprintln!(
            "{structure:?} R, floor {floor:.4}: Q closed {q_closed:.10}, numeric {q_numeric:.10}, max difference {diff:.1e}"
        );
        assert!(q_closed >= q_numeric - 1e-9 * q_closed.abs());
        assert!(diff < 1e-4, "closed {closed:?} vs numeric {numeric:?}");
        // and the unconstrained maximiser is better but infeasible
        assert!(expected_loglik(&unconstrained, &stats) > q_closed);
    }
}
