//! N4SID on five measured records (DaISy, `tests/data/daisy/README.md`) against the
//! reference tools' validation fits (nfoursid 1.0.2, SIPPY 1.0.1, from
//! `shared/data/reference_results.json`), scored by the protocol of
//! `shared/data/score_fit.py`, which `Scorer` re-implements and is checked against on
//! nfoursid's own models.

use nalgebra::DMatrix;
use sysid::kalman::{LinearGaussianModel, ModelSpec, Record, fit_percent};
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

/// Mean over outputs of the library's fit figure.
fn mean_fit(y: &DMatrix<f64>, y_hat: &DMatrix<f64>, from: usize) -> f64 {
    let fit = fit_percent(y, y_hat, from);
    fit.iter().sum::<f64>() / fit.len() as f64
}

/// Simulation fit with the least-squares initial state (`LinearGaussianModel::response`,
/// what `sysid compare` runs).
fn simulation_fit(model: &LinearGaussianModel, data: &Record) -> f64 {
    let response = model.response(data, None).unwrap();
    mean_fit(&data.y, &response.outputs, 0)
}

/// One-step prediction fit, 50 steps of burn-in (`LinearGaussianModel::predict`, what
/// `sysid compare --horizon 1 --burn-in 50` runs). The Kalman filter from the model's
/// initial state converges to score_fit.py's steady-state predictor started at zero
/// within the burn-in (measured: to 3e-5 points on every record).
fn prediction_fit(model: &LinearGaussianModel, data: &Record) -> f64 {
    let predictions = model.predict(data, 1).unwrap();
    mean_fit(&data.y, &predictions.mean, 50)
}

fn references() -> serde_json::Value {
    let text = std::fs::read_to_string(data_dir().join("references.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// The library's simulation and prediction fits (what `sysid compare` prints)
/// reproduce score_fit.py's figures for nfoursid's models: the simulation to 1e-9
/// points, the prediction to 1e-3 (a filter from the model's initial state against the
/// scorer's steady-state predictor from zero, 50 steps of burn-in).
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
            (sim - want_sim).abs() < 1e-9,
            "{name}: sim {sim} vs {want_sim}"
        );
        assert!(
            (pred - want_pred).abs() < 1e-3,
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
