//! One library, every face: the commands that check a fitted linear model against a
//! record (`predict`, `compare`, `resid`, `forecast`, `tf`, `filter`, `smooth`,
//! `simulate --model`) give the library's numbers to the bit, and its warnings.
//!
//! The model is fitted once by `sysid fit lti` on the first 400 rows of the heating
//! record (a linear trend removed, so the trend's path is exercised too) and checked
//! on rows 401-800. The library side reads the files itself.

mod common;

use common::signals::{data, read_csv};
use common::{json_of, s, scratch_dir, sysid};
use nalgebra::DMatrix;
use std::path::{Path, PathBuf};
use sysid::kalman::residuals::ResidualTests;
use sysid::kalman::{
    ForecastIntervals, Horizon, KalmanWorkspace, LinearGaussianModel, ModelSpec, Record, Trend,
};

/// A model fitted by the binary: `fit lti --order 2 --range :400` with the detrending
/// given.
fn fitted(dir: &Path, detrend: &str) -> PathBuf {
    let out = dir.join(format!("heat_{detrend}.json"));
    let data = data("heating_system.csv");
    let run = sysid(&[
        "fit",
        "lti",
        "--data",
        s(&data),
        "--range",
        ":400",
        "--order",
        "2",
        "--detrend",
        detrend,
        "--out",
        s(&out),
    ]);
    common::assert_ok(&run);
    out
}

/// The library's view of a model file on rows `from..to` of the heating record: the
/// model with its stored initial state applied, the record with the stored trend
/// removed, the record's times and the outputs' trend at them.
struct OnData {
    model: LinearGaussianModel,
    record: Record,
    time: Vec<f64>,
    trend: Option<Trend>,
}

impl OnData {
    fn read(model: &Path, from: usize, to: usize) -> OnData {
        let spec: ModelSpec =
            serde_json::from_str(&std::fs::read_to_string(model).unwrap()).unwrap();
        let built = spec.build().unwrap();
        let trend = Trend::stored(
            spec.metadata.as_ref().and_then(|m| m.detrend.as_ref()),
            built.m(),
            built.p(),
        )
        .unwrap();
        let signals = read_csv(&data("heating_system.csv"), Some((from, to)));
        let mut record = signals.record;
        if let Some(t) = &trend {
            t.remove_from(&mut record, &signals.time);
        }
        let model = spec.initial.apply_to_record(&built, &record).unwrap();
        OnData {
            model,
            record,
            time: signals.time,
            trend,
        }
    }

    /// The outputs' trend at the record's times (zero without a trend).
    fn output_trend(&self) -> DMatrix<f64> {
        match &self.trend {
            Some(t) => t.outputs_at(&self.time),
            None => DMatrix::zeros(self.record.y.nrows(), self.record.len()),
        }
    }
}

/// The columns of a CSV the binary wrote, by name.
fn csv_columns(path: &Path) -> Vec<(String, Vec<f64>)> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let rows: Vec<Vec<f64>> = lines
        .map(|l| {
            l.split(',')
                .map(|v| v.parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    header
        .into_iter()
        .enumerate()
        .map(|(j, name)| (name, rows.iter().map(|r| r[j]).collect()))
        .collect()
}

fn column(columns: &[(String, Vec<f64>)], name: &str) -> Vec<f64> {
    columns
        .iter()
        .find(|(n, _)| n == name)
        .unwrap_or_else(|| panic!("no column {name}"))
        .1
        .clone()
}

/// Asserts two series equal to the bit (NaN equal to NaN).
fn assert_bits(what: &str, cli: &[f64], library: impl IntoIterator<Item = f64>) {
    let library: Vec<f64> = library.into_iter().collect();
    assert_eq!(cli.len(), library.len(), "{what}: lengths");
    for (t, (a, b)) in cli.iter().zip(&library).enumerate() {
        assert!(
            a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
            "{what}[{t}]: command {a:e}, library {b:e}"
        );
    }
}

fn json_f64s(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap_or(f64::NAN))
        .collect()
}

#[test]
fn predict_compare_and_resid_equal_the_library_on_a_detrended_model() {
    let dir = scratch_dir();
    let model_path = fitted(&dir, "linear");
    let heat = data("heating_system.csv");
    let lib = OnData::read(&model_path, 400, 800);
    assert!(lib.trend.is_some(), "the fit stored its linear trend");
    let trend = lib.output_trend();

    // predict --horizon 3
    let out = dir.join("pred.csv");
    let run = sysid(&[
        "predict",
        "--model",
        s(&model_path),
        "--data",
        s(&heat),
        "--range",
        "401:800",
        "--horizon",
        "3",
        "--out",
        s(&out),
        "--json",
    ]);
    let summary = json_of(&run);
    let pred = lib.model.predict(&lib.record, 3).unwrap();
    let columns = csv_columns(&out);
    let restored = &pred.mean + &trend;
    assert_bits(
        "y1_pred",
        &column(&columns, "y1_pred"),
        restored.row(0).iter().copied(),
    );
    assert_bits(
        "y1_sd",
        &column(&columns, "y1_sd"),
        pred.sd.row(0).iter().copied(),
    );
    assert_bits(
        "y1_std",
        &column(&columns, "y1_std"),
        pred.standardised.row(0).iter().copied(),
    );
    assert_eq!(
        summary["loglik"].as_f64().unwrap().to_bits(),
        pred.loglik.to_bits()
    );
    assert_bits(
        "standardised_rms",
        &json_f64s(&summary["standardised_rms"]),
        pred.standardised_rms(),
    );
    let fit = sysid::kalman::fit_percent(&(&lib.record.y + &trend), &restored, 0);
    assert_bits("predict fit", &json_f64s(&summary["fit_percent"]), fit);
    let warnings: Vec<String> = pred.warnings().iter().map(ToString::to_string).collect();
    assert_eq!(summary["warnings"], serde_json::json!(warnings));

    // compare, simulation and 5-step predictions, with a burn-in
    for horizon in ["inf", "5"] {
        let run = sysid(&[
            "compare",
            "--model",
            s(&model_path),
            "--data",
            s(&heat),
            "--range",
            "401:800",
            "--horizon",
            horizon,
            "--burn-in",
            "10",
            "--json",
        ]);
        let summary = json_of(&run);
        let chosen: Horizon = horizon.parse().unwrap();
        let comparison = lib
            .model
            .compare(&lib.record, chosen, 10, Some(&trend))
            .unwrap();
        assert_bits(
            &format!("compare {horizon}"),
            &json_f64s(&summary["models"][0]["fit_percent"]),
            comparison.fit_percent.iter().copied(),
        );
        assert_eq!(
            summary["models"][0]["fit_percent_mean"]
                .as_f64()
                .unwrap()
                .to_bits(),
            comparison.mean_fit_percent().to_bits()
        );
    }

    // resid --lags 12: correlations, Ljung-Box and the warnings' text
    let out = dir.join("resid.csv");
    let run = sysid(&[
        "resid",
        "--model",
        s(&model_path),
        "--data",
        s(&heat),
        "--range",
        "401:800",
        "--lags",
        "12",
        "--out",
        s(&out),
        "--json",
    ]);
    let summary = json_of(&run);
    let tests = lib.model.residual_tests(&lib.record, 12).unwrap();
    let again = ResidualTests::of(&lib.model.predict(&lib.record, 1).unwrap(), &lib.record, 12);
    assert_eq!(again.as_ref(), Ok(&tests));
    let output = &tests.outputs[0];
    let cli = &summary["outputs"][0];
    assert_bits("acf", &json_f64s(&cli["acf"]), output.acf.iter().copied());
    assert_eq!(
        cli["ljung_box"]["statistic"].as_f64().unwrap().to_bits(),
        output.ljung_box.statistic.to_bits()
    );
    assert_eq!(
        cli["ljung_box"]["p_value"].as_f64().unwrap().to_bits(),
        output.ljung_box.p_value.to_bits()
    );
    assert_eq!(cli["samples"], output.samples);
    assert_eq!(cli["acf_beyond_bound"], output.acf_beyond_bound());
    let columns = csv_columns(&out);
    assert_bits(
        "y1_u1_ccf",
        &column(&columns, "y1_u1_ccf"),
        output.ccf[0].iter().copied(),
    );
    let names = (vec!["y1".to_string()], vec!["u1".to_string()]);
    let warnings: Vec<String> = tests
        .warnings()
        .iter()
        .map(|w| w.message(&names.0, &names.1))
        .collect();
    assert_eq!(summary["warnings"], serde_json::json!(warnings));
}

#[test]
fn forecast_tf_filter_and_smooth_equal_the_library() {
    let dir = scratch_dir();
    let model_path = fitted(&dir, "mean");
    let heat = data("heating_system.csv");
    let lib = OnData::read(&model_path, 0, 400);
    assert!(lib.trend.is_none(), "means are folded into the model");

    // forecast 20 steps past row 400 with rows 401-420's inputs, 90 % intervals
    let future = dir.join("future.csv");
    let rows = read_csv(&heat, Some((400, 420)));
    let mut text = String::from("u1\n");
    for u in rows.record.u.iter() {
        text += &format!("{u}\n");
    }
    std::fs::write(&future, text).unwrap();
    let out = dir.join("forecast.csv");
    let run = sysid(&[
        "forecast",
        "--model",
        s(&model_path),
        "--data",
        s(&heat),
        "--range",
        ":400",
        "--steps",
        "20",
        "--future-inputs",
        s(&future),
        "--level",
        "0.9",
        "--out",
        s(&out),
        "--json",
    ]);
    let summary = json_of(&run);
    let forecast = lib.model.forecast(&lib.record, &rows.record.u, 20).unwrap();
    let intervals = forecast.intervals(0.9).unwrap();
    assert_eq!(
        summary["z"].as_f64().unwrap().to_bits(),
        ForecastIntervals::half_width(0.9).unwrap().to_bits()
    );
    let columns = csv_columns(&out);
    assert_bits("y1", &column(&columns, "y1"), forecast.mean.iter().copied());
    assert_bits(
        "y1_sd",
        &column(&columns, "y1_sd"),
        forecast.sd.iter().copied(),
    );
    assert_bits(
        "y1_lower",
        &column(&columns, "y1_lower"),
        intervals.lower.iter().copied(),
    );
    assert_bits(
        "y1_upper",
        &column(&columns, "y1_upper"),
        intervals.upper.iter().copied(),
    );
    // a level outside (0, 1) is refused by both, before any work on the command line
    assert!(forecast.intervals(1.0).is_err());
    let bad = sysid(&[
        "forecast",
        "--model",
        s(&model_path),
        "--data",
        s(&heat),
        "--steps",
        "2",
        "--future-inputs",
        s(&future),
        "--level",
        "1",
        "--out",
        s(&dir.join("never.csv")),
    ]);
    common::assert_one_line_error(&bad, &["--level", "strictly between 0 and 1"]);

    // tf: poles and the channel's gain and zeros
    let run = sysid(&["tf", "--model", s(&model_path), "--json"]);
    let summary = json_of(&run);
    let poles: Vec<[f64; 2]> = lib.model.poles().iter().map(|z| [z.re, z.im]).collect();
    assert_eq!(summary["poles"], serde_json::json!(poles));
    let tf = lib.model.transfer_function(0, 0).unwrap();
    assert!(lib.model.transfer_function(1, 0).is_err());
    let channel = &summary["channels"][0];
    assert_eq!(
        channel["gain"].as_f64().map(f64::to_bits),
        tf.gain.map(f64::to_bits)
    );
    assert_eq!(channel["numerator"], serde_json::json!(tf.numerator));
    assert_eq!(channel["denominator"], serde_json::json!(tf.denominator));

    // filter (streamed by blocks) and smooth: the library's whole-record passes
    let mut ws = KalmanWorkspace::new();
    let filtered = ws.filter(&lib.model, &lib.record).unwrap();
    let filtered_loglik = filtered.loglik();
    let mut smoother = KalmanWorkspace::new();
    let smoothed = smoother.smooth(&lib.model, &lib.record).unwrap();
    for (command, loglik) in [("filter", filtered_loglik), ("smooth", smoothed.loglik())] {
        let out = dir.join(format!("{command}.csv"));
        let run = sysid(&[
            command,
            "--model",
            s(&model_path),
            "--data",
            s(&heat),
            "--range",
            ":400",
            "--out",
            s(&out),
            "--json",
        ]);
        let summary = json_of(&run);
        assert_eq!(
            summary["loglik"].as_f64().unwrap().to_bits(),
            loglik.to_bits(),
            "{command}"
        );
        let columns = csv_columns(&out);
        for (state, name) in ["x1", "x2"].into_iter().enumerate() {
            let library: Vec<f64> = (0..lib.record.len())
                .map(|k| match command {
                    "filter" => filtered.filtered_mean(k)[state],
                    _ => smoothed.mean(k)[state],
                })
                .collect();
            // the smoother by checkpoints and the whole-record smoother agree to the bit
            assert_bits(
                &format!("{command} {name}"),
                &column(&columns, name),
                library,
            );
        }
    }
}

#[test]
fn simulate_model_equals_the_library_response_and_realisation() {
    use rand::SeedableRng;
    let dir = scratch_dir();
    let model_path = fitted(&dir, "mean");
    let heat = data("heating_system.csv");
    let lib = OnData::read(&model_path, 400, 800);
    // noise-free, from the initial state that fits the record best
    let out = dir.join("sim.csv");
    let run = sysid(&[
        "simulate",
        "--model",
        s(&model_path),
        "--data",
        s(&heat),
        "--range",
        "401:800",
        "--out",
        s(&out),
        "--json",
    ]);
    let summary = json_of(&run);
    let response = lib.model.response(&lib.record, None).unwrap();
    assert_bits(
        "x0",
        &json_f64s(&summary["x0"]),
        response.initial_state.iter().copied(),
    );
    assert_bits(
        "y1",
        &column(&csv_columns(&out), "y1"),
        response.outputs.iter().copied(),
    );
    let fit = sysid::kalman::fit_percent(&lib.record.y, &response.outputs, 0);
    assert_bits("fit", &json_f64s(&summary["fit_percent"]), fit);
    // a realisation with the model's noise from its own mean, seed 7
    let out = dir.join("noisy.csv");
    let run = sysid(&[
        "simulate",
        "--model",
        s(&model_path),
        "--data",
        s(&heat),
        "--range",
        "401:800",
        "--x0",
        "model",
        "--noise",
        "--seed",
        "7",
        "--out",
        s(&out),
    ]);
    common::assert_ok(&run);
    let n = lib.model.n();
    let start = lib
        .model
        .to_builder()
        .p1(DMatrix::zeros(n, n))
        .diffuse(DMatrix::zeros(n, 0))
        .build()
        .unwrap();
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(7);
    let realisation = start.simulate(&lib.record.u, &mut rng).unwrap();
    assert_bits(
        "noisy y1",
        &column(&csv_columns(&out), "y1"),
        realisation.record.y.iter().copied(),
    );
}
