//! `WeightingChoice::Auto` on measured records (DaISy, `tests/data/daisy` at the
//! repository root): it keeps the stable model with the best one-step prediction fit
//! of the three weightings, and that model is the one the fixed weighting gives.

use nalgebra::DMatrix;
use std::path::Path;
use sysid_kalman::{Horizon, Record};
use sysid_subspace::{N4sidOptions, Order, Weighting, WeightingChoice, n4sid, n4sid_weighted};

/// A DaISy CSV (`t,u1..,y1..`), its first half centred as score_fit.py does.
fn estimation_half(name: &str) -> Record {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/daisy")
        .join(format!("{name}.csv"));
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
        .collect();
    let half = rows.len() / 2;
    let pick = |prefix: char| -> DMatrix<f64> {
        let cols: Vec<usize> = (0..header.len())
            .filter(|&k| header[k].starts_with(prefix))
            .collect();
        let mut m = DMatrix::from_fn(cols.len(), half, |i, t| rows[t][cols[i]]);
        for mut row in m.row_iter_mut() {
            let mean = row.mean();
            row.add_scalar_mut(-mean);
        }
        m
    };
    Record::new(pick('u'), pick('y'))
}

#[test]
fn auto_keeps_the_stable_weighting_that_predicts_best() {
    for (name, order) in [("CD_player_arm", 3), ("exchanger", 3), ("glassfurnace", 3)] {
        let record = estimation_half(name);
        let options = N4sidOptions {
            order: Order::Fixed(order),
            ..Default::default()
        };
        let auto = n4sid_weighted(&record, &options, WeightingChoice::Auto).unwrap();
        assert_eq!(auto.candidates.len(), 3);
        // the scores are the fixed weightings' models' one-step fits
        for c in &auto.candidates {
            let fixed = n4sid(
                &record,
                &N4sidOptions {
                    weighting: c.weighting,
                    ..options
                },
            )
            .unwrap();
            let fit = fixed
                .model
                .compare(&record, Horizon::Steps(1), 0, None)
                .unwrap()
                .mean_fit_percent();
            assert_eq!(c.prediction_fit, Some(fit), "{name} {:?}", c.weighting);
            assert_eq!(c.spectral_radius, Some(fixed.spectral_radius));
        }
        let best = auto
            .candidates
            .iter()
            .filter(|c| c.usable())
            .map(|c| c.prediction_fit.unwrap())
            .fold(f64::NEG_INFINITY, f64::max);
        let kept = auto
            .candidates
            .iter()
            .find(|c| c.weighting == auto.result.weighting)
            .unwrap();
        assert_eq!(kept.prediction_fit, Some(best), "{name}");
        assert!(auto.result.spectral_radius < 1.0, "{name}");
    }
    // a fixed weighting is that weighting's fit, unscored
    let record = estimation_half("dryer");
    let options = N4sidOptions {
        order: Order::Fixed(3),
        ..Default::default()
    };
    let fixed = n4sid_weighted(&record, &options, WeightingChoice::Fixed(Weighting::Cva)).unwrap();
    assert!(fixed.candidates.is_empty());
    assert_eq!(fixed.result.weighting, Weighting::Cva);
    assert_eq!(WeightingChoice::parse("AUTO"), Some(WeightingChoice::Auto));
    assert_eq!(WeightingChoice::parse("bogus"), None);
}
