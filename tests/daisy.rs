//! N4SID on five measured records (DaISy, `tests/data/daisy/README.md`) against the
//! reference tools' validation fits (nfoursid 1.0.2, SIPPY 1.0.1, from
//! `shared/data/reference_results.json`), scored by the protocol of
//! `shared/data/score_fit.py`, which `Scorer` re-implements and is checked against on
//! nfoursid's own models.

use nalgebra::{DMatrix, DVector};
use sysid::kalman::{LinearGaussianModel, ModelSpec, Record};
use sysid::subspace::{Focus, N4sidOptions, Order, n4sid};

const RECORDS: [&str; 8] = [
    "evaporator",
    "glassfurnace",
    "dryer2",
    "heating_system",
    "thermic_res_wall",
    // three more measured records, found for this test (docs/reproducing.md)
    "dryer",
    "exchanger",
    "CD_player_arm",
];

fn data_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/daisy")
}

/// The record's inputs and outputs (`t,u1..,y1..`), estimation-centred, split at N / 2.
struct Split {
    estimation: Record,
    validation: Record,
}

fn load(name: &str) -> Split {
    let text = std::fs::read_to_string(data_dir().join(format!("{name}.csv"))).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let m = header.iter().filter(|h| h.starts_with('u')).count();
    let p = header.iter().filter(|h| h.starts_with('y')).count();
    let rows: Vec<Vec<f64>> = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').skip(1).map(|v| v.parse().unwrap()).collect())
        .collect();
    let (t_len, half) = (rows.len(), rows.len() / 2);
    let mean = |col: usize| rows[..half].iter().map(|r| r[col]).sum::<f64>() / half as f64;
    let means: Vec<f64> = (0..m + p).map(mean).collect();
    let signal = |range: std::ops::Range<usize>, cols: std::ops::Range<usize>| {
        DMatrix::from_fn(cols.len(), range.len(), |c, t| {
            rows[range.start + t][cols.start + c] - means[cols.start + c]
        })
    };
    Split {
        estimation: Record::new(signal(0..half, 0..m), signal(0..half, m..m + p)),
        validation: Record::new(signal(half..t_len, 0..m), signal(half..t_len, m..m + p)),
    }
}

fn fit_percent(y: &DMatrix<f64>, yhat: &DMatrix<f64>, from: usize) -> f64 {
    let p = y.nrows();
    (0..p)
        .map(|i| {
            let row: Vec<f64> = y.row(i).iter().skip(from).copied().collect();
            let mean = row.iter().sum::<f64>() / row.len() as f64;
            let (mut err, mut dev) = (0.0, 0.0);
            for (k, &v) in row.iter().enumerate() {
                err += (v - yhat[(i, from + k)]).powi(2);
                dev += (v - mean).powi(2);
            }
            100.0 * (1.0 - (err / dev).sqrt())
        })
        .sum::<f64>()
        / p as f64
}

/// Simulation fit with the least-squares initial state.
fn simulation_fit(model: &LinearGaussianModel, data: &Record) -> f64 {
    let (n, p, t_len) = (model.n(), model.p(), data.len());
    let (a, b, c, d, h) = (model.a(), model.b(), model.c(), model.d(), model.h());
    let mut x = DVector::zeros(n);
    let mut free = DMatrix::zeros(p, t_len);
    let mut regressors = DMatrix::zeros(p * t_len, n);
    let mut power = c.clone();
    for t in 0..t_len {
        let u = data.u.column(t);
        free.set_column(t, &(c * &x + d * u + h));
        x = a * &x + b * u;
        regressors.rows_mut(t * p, p).copy_from(&power);
        power = &power * a;
    }
    let residual = DVector::from_fn(p * t_len, |k, _| {
        data.y[(k % p, k / p)] - free[(k % p, k / p)]
    });
    let x0 = regressors
        .clone()
        .svd(true, true)
        .solve(&residual, 1e-14)
        .unwrap();
    let mut yhat = free;
    for t in 0..t_len {
        let correction = regressors.rows(t * p, p) * &x0;
        let mut col = yhat.column_mut(t);
        col += correction;
    }
    fit_percent(&data.y, &yhat, 0)
}

/// One-step prediction fit of the steady-state Kalman predictor, 50 rows of burn-in.
fn prediction_fit(model: &LinearGaussianModel, data: &Record) -> f64 {
    let (a, b, c, d, h) = (model.a(), model.b(), model.c(), model.d(), model.h());
    let (q, r, s) = (model.q(), model.r(), model.s());
    let mut pm = q.clone();
    let mut gain = DMatrix::zeros(model.n(), model.p());
    for _ in 0..100_000 {
        let apc = a * &pm * c.transpose() + s;
        let inn = c * &pm * c.transpose() + r;
        gain = &apc * inn.clone().try_inverse().unwrap();
        let next = a * &pm * a.transpose() + q - &gain * apc.transpose();
        let change = (&next - &pm).amax();
        pm = (&next + next.transpose()) / 2.0;
        if change <= 1e-15 * pm.amax() {
            break;
        }
    }
    let mut x = DVector::zeros(model.n());
    let mut yhat = DMatrix::zeros(model.p(), data.len());
    for t in 0..data.len() {
        let u = data.u.column(t);
        let pred = c * &x + d * u + h;
        let innovation = data.y.column(t) - &pred;
        yhat.set_column(t, &pred);
        x = a * &x + b * u + &gain * innovation;
    }
    fit_percent(&data.y, &yhat, 50)
}

fn references() -> serde_json::Value {
    let text = std::fs::read_to_string(data_dir().join("references.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// The scorer reproduces score_fit.py's figures for nfoursid's models.
#[test]
fn the_scorer_reproduces_score_fit_py_on_nfoursid_models() {
    let refs = references();
    for name in RECORDS {
        let split = load(name);
        let text =
            std::fs::read_to_string(data_dir().join(format!("{name}.nfoursid.json"))).unwrap();
        let model = serde_json::from_str::<ModelSpec>(&text)
            .unwrap()
            .build()
            .unwrap();
        let sim = simulation_fit(&model, &split.validation);
        let pred = prediction_fit(&model, &split.validation);
        let want_sim = refs[name]["nfoursid_simulation_fit"].as_f64().unwrap();
        let want_pred = refs[name]["nfoursid_prediction_fit"].as_f64().unwrap();
        assert!(
            (sim - want_sim).abs() < 1e-6,
            "{name}: sim {sim} vs {want_sim}"
        );
        assert!(
            (pred - want_pred).abs() < 1e-6,
            "{name}: pred {pred} vs {want_pred}"
        );
    }
}

/// At the README's orders, sysid's N4SID with default options reaches the best
/// reference's validation simulation and prediction fits less one point (dryer2:
/// prediction only, its halves sit at different operating points), with a stable A.
#[test]
fn n4sid_matches_the_best_reference_on_every_record() {
    let refs = references();
    for name in RECORDS {
        let split = load(name);
        let order = refs[name]["order"].as_u64().unwrap() as usize;
        let result = n4sid(
            &split.estimation,
            &N4sidOptions {
                order: Order::Fixed(order),
                ..Default::default()
            },
        )
        .unwrap();
        assert!(result.spectral_radius < 1.0, "{name}: unstable");
        let sim = simulation_fit(&result.model, &split.validation);
        let pred = prediction_fit(&result.model, &split.validation);
        let best_sim = refs[name]["best_reference_simulation_fit"]
            .as_f64()
            .unwrap();
        let best_pred = refs[name]["best_reference_prediction_fit"]
            .as_f64()
            .unwrap();
        if name != "dryer2" {
            assert!(
                sim >= best_sim - 1.0,
                "{name}: sim {sim} vs best {best_sim}"
            );
        }
        assert!(
            pred >= best_pred - 1.0,
            "{name}: pred {pred} vs best {best_pred}"
        );
    }
}

/// `Focus::Simulation` improves the simulation fit where the model is simpler than the
/// process (the evaporator: 48.9 -> 52.8 measured) and keeps A stable.
#[test]
fn simulation_focus_improves_the_evaporators_simulation_fit() {
    let split = load("evaporator");
    let fit = |focus| {
        let result = n4sid(
            &split.estimation,
            &N4sidOptions {
                order: Order::Fixed(4),
                focus,
                ..Default::default()
            },
        )
        .unwrap();
        simulation_fit(&result.model, &split.validation)
    };
    let (prediction, simulation) = (fit(Focus::Prediction), fit(Focus::Simulation));
    assert!(
        simulation > prediction + 2.0,
        "{simulation} vs {prediction}"
    );
}

/// `Order::Auto` never picks an unstable candidate when a stable one exists: on the CD
/// player arm orders 1 and 9 come out unstable, and the choice is stable.
#[test]
fn auto_order_prefers_stable_candidates() {
    let split = load("CD_player_arm");
    let result = n4sid(&split.estimation, &N4sidOptions::default()).unwrap();
    assert!(
        result.order_scores.iter().any(|s| s.spectral_radius >= 1.0),
        "the rule must be exercised"
    );
    assert!(result.spectral_radius < 1.0, "order {}", result.order);
    let chosen = result
        .order_scores
        .iter()
        .find(|s| s.order == result.order)
        .unwrap();
    for s in result
        .order_scores
        .iter()
        .filter(|s| s.spectral_radius < 1.0)
    {
        assert!(chosen.criterion <= s.criterion);
    }
}
