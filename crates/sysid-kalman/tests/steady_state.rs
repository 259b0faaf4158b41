//! The steady-state reuse agrees with the full recursion to round-off (1e-12 relative,
//! and bit for bit where the recursion reaches an exact fixed point, as for lti2x2 with
//! Q = 0 and for the scalar model). The systems are long enough for the covariance
//! recursion to settle, and the test checks that reuse really happened (so it can fail).

mod common;
use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use sysid_kalman::{KalmanWorkspace, LinearGaussianModel, Record, SufficientStatistics};

fn bits(v: &[f64]) -> Vec<f64> {
    v.to_vec()
}

type Outputs = (f64, f64, Vec<f64>, Vec<f64>, Vec<f64>, usize);

fn run(model: &LinearGaussianModel, rec: &Record, reuse: bool) -> Outputs {
    let mut ws = KalmanWorkspace::new();
    ws.set_steady_state_reuse(reuse);
    let ll = ws.loglik(model, rec).unwrap();
    let reused = ws.filter(model, rec).unwrap().reused_steps();
    let sm = ws.smooth(model, rec).unwrap().clone();
    let mut means = Vec::new();
    let mut covs = Vec::new();
    for k in 0..=rec.len() {
        means.extend(bits(sm.mean(k).as_slice()));
        covs.extend(bits(sm.covariance(k).as_slice()));
        if k < rec.len() {
            covs.extend(bits(sm.lag_one_covariance(k).as_slice()));
        }
    }
    let mut stats = SufficientStatistics::new(model.n(), model.m(), model.p());
    let ll_stats = ws.accumulate_statistics(model, rec, 0, &mut stats).unwrap();
    (
        ll,
        ll_stats,
        means,
        covs,
        bits(stats.second_moment().as_slice()),
        reused,
    )
}

/// max |a - b| / max(1e-300, max |b|)
fn rel(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(1e-300_f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

fn check(model: &LinearGaussianModel, rec: &Record, expect_reuse: bool, label: &str) {
    check_with(model, rec, expect_reuse, label, 1e-12)
}

fn check_with(
    model: &LinearGaussianModel,
    rec: &Record,
    expect_reuse: bool,
    label: &str,
    tol: f64,
) {
    let on = run(model, rec, true);
    let off = run(model, rec, false);
    assert_eq!(off.5, 0, "{label}: reuse switched off");
    eprintln!(
        "{label}: reused {}/{} steps; loglik {:.1e}, means {:.1e}, covariances {:.1e}, statistics {:.1e}",
        on.5,
        rec.len(),
        rel(&[on.0], &[off.0]),
        rel(&on.2, &off.2),
        rel(&on.3, &off.3),
        rel(&on.4, &off.4)
    );
    assert!(
        rel(&[on.0], &[off.0]) <= tol,
        "{label}: loglik {} vs {}",
        on.0,
        off.0
    );
    assert!(
        rel(&[on.1], &[off.1]) <= tol,
        "{label}: loglik of the statistics pass"
    );
    assert!(
        rel(&on.2, &off.2) <= tol,
        "{label}: smoothed means {:e}",
        rel(&on.2, &off.2)
    );
    assert!(
        rel(&on.3, &off.3) <= tol,
        "{label}: smoothed covariances {:e}",
        rel(&on.3, &off.3)
    );
    assert!(
        rel(&on.4, &off.4) <= tol,
        "{label}: statistics {:e}",
        rel(&on.4, &off.4)
    );
    if expect_reuse {
        assert!(
            on.5 > rec.len() / 2,
            "{label}: only {} of {} steps reused",
            on.5,
            rec.len()
        );
    }
}

#[test]
fn reuse_is_bit_identical_on_long_series() {
    // lti2x2 (Q = 0: stationary at once) and a full-noise variant (settles after a while)
    let sim = sysid_models_free_lti2x2();
    check_with(&sim.0, &sim.1, true, "lti2x2 (exact fixed point)", 0.0);
    let full = sim
        .0
        .to_builder()
        .q(DMatrix::identity(8, 8) * 0.01)
        .p1(DMatrix::identity(8, 8))
        .build()
        .unwrap();
    check(&full, &sim.1, true, "lti2x2 full noise");
    // random systems (S != 0, offsets), long, with and without missing data
    for seed in 0..12 {
        let (model, _) = common::random_system(seed);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let u = common::gaussian_matrix(&mut rng, model.m(), 1500);
        let mut rec = model.simulate(&u, &mut rng).unwrap().record;
        check(&model, &rec, true, &format!("random {seed}"));
        for t in (0..1500).step_by(7) {
            rec.y[(0, t)] = f64::NAN;
        }
        check(&model, &rec, false, &format!("random {seed} with gaps"));
    }
    // the scalar fast path
    let scalar = LinearGaussianModel::builder(
        nalgebra::dmatrix![0.9],
        nalgebra::dmatrix![1.0],
        nalgebra::dmatrix![1.0],
        nalgebra::dmatrix![0.5],
    )
    .build()
    .unwrap();
    let rec = scalar
        .simulate(
            &DMatrix::zeros(0, 5000),
            &mut Xoshiro256PlusPlus::seed_from_u64(5),
        )
        .unwrap()
        .record;
    check(&scalar, &rec, true, "scalar");
}

/// The lti2x2 system of `sysid-models`, rebuilt here (the kalman crate cannot depend on
/// the models crate): block-diagonal 8-state realisation, Q = 0, P1 = 0, R = 0.01 I.
fn sysid_models_free_lti2x2() -> (LinearGaussianModel, Record) {
    let blocks = [
        (0.0355, 0.02465, 0.3679, 0.9084, 0, 0),
        (0.2364, 0.1038, 0.1353, 0.6065, 1, 0),
        (0.07601, 0.05447, 0.4966, 0.7408, 0, 1),
        (0.1087, 0.07286, 0.4493, 0.6703, 1, 1),
    ];
    let (mut a, mut b, mut c) = (
        DMatrix::zeros(8, 8),
        DMatrix::zeros(8, 2),
        DMatrix::zeros(2, 8),
    );
    for (k, &(b1, b0, p1, p2, input, output)) in blocks.iter().enumerate() {
        let o = 2 * k;
        a[(o, o)] = p1 + p2;
        a[(o, o + 1)] = -p1 * p2;
        a[(o + 1, o)] = 1.0;
        b[(o, input)] = 1.0;
        c[(output, o)] = b1;
        c[(output, o + 1)] = b0;
    }
    let model =
        LinearGaussianModel::builder(a, c, DMatrix::zeros(8, 8), DMatrix::identity(2, 2) * 0.01)
            .b(b)
            .p1(DMatrix::zeros(8, 8))
            .build()
            .unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
    let u = common::gaussian_matrix(&mut rng, 2, 2000);
    let rec = model.simulate(&u, &mut rng).unwrap().record;
    (model, rec)
}
