//! `filter` and `smooth` on records longer than one block (the filter streams the data
//! file block by block, the smoother works by checkpoints): the states they write equal
//! the whole-record filter and smoother of the library on the same rows, with text time
//! labels, missing outputs, `--range` and every initial state.

mod common;
use common::{assert_ok, assert_one_line_error, entries, json_of, s, scratch_dir, sysid};
use nalgebra::DMatrix;
use std::path::Path;
use sysid::kalman::{InitialState, KalmanWorkspace, LinearGaussianModel, ModelSpec, Record};

/// Steps of the test record: three blocks of the streamed filter.
const STEPS: usize = 9000;

/// `lti2x2` data with time labels `s1, s2, ...` and every 37th first output missing;
/// returns (data file, model file, the record).
fn long_data(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf, Record) {
    let (raw, model) = (dir.join("raw.csv"), dir.join("true.json"));
    let steps = STEPS.to_string();
    assert_ok(&sysid(&[
        "simulate",
        "lti2x2",
        "--steps",
        &steps,
        "--out",
        s(&raw),
        "--model-out",
        s(&model),
    ]));
    let text = std::fs::read_to_string(&raw).unwrap();
    let mut lines = text.lines();
    let mut out = format!("{}\n", lines.next().unwrap());
    let (mut u, mut y) = (Vec::new(), Vec::new());
    for (k, line) in lines.enumerate() {
        let mut fields: Vec<String> = line.split(',').map(str::to_string).collect();
        fields[0] = format!("s{}", k + 1);
        if k % 37 == 5 {
            fields[3] = String::new();
        }
        out.push_str(&fields.join(","));
        out.push('\n');
        let value = |f: &String| f.parse::<f64>().unwrap_or(f64::NAN);
        u.extend(fields[1..3].iter().map(value));
        y.extend(fields[3..5].iter().map(value));
    }
    let data = dir.join("d.csv");
    std::fs::write(&data, out).unwrap();
    let record = Record::new(
        DMatrix::from_vec(2, STEPS, u),
        DMatrix::from_vec(2, STEPS, y),
    );
    (data, model, record)
}

fn read_model(path: &Path) -> LinearGaussianModel {
    let spec: ModelSpec = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    spec.build().unwrap()
}

/// The rows of a states file: label and numbers.
fn states(path: &Path) -> Vec<(String, Vec<f64>)> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .map(|l| {
            let mut f = l.split(',');
            let label = f.next().unwrap().to_string();
            (label, f.map(|v| v.parse().unwrap()).collect())
        })
        .collect()
}

fn close(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 1e-9 * b.abs().max(1e-3)
}

#[test]
fn streamed_filter_and_checkpointed_smoother_equal_the_whole_record_passes() {
    let dir = scratch_dir();
    let (data, model_file, record) = long_data(&dir);
    let base = read_model(&model_file);
    for (initial, range) in [
        ("model", None),
        ("stationary", Some((3, 8800))),
        ("diffuse", Some((1, STEPS))),
    ] {
        let (from, to) = range.unwrap_or((1, STEPS));
        let rows = Record::new(
            record.u.columns(from - 1, to - from + 1).clone_owned(),
            record.y.columns(from - 1, to - from + 1).clone_owned(),
        );
        let model = match initial {
            "model" => InitialState::Given,
            "stationary" => InitialState::Stationary,
            _ => InitialState::Diffuse,
        }
        .apply_to_record(&base, &rows)
        .unwrap();
        let mut ws = KalmanWorkspace::new();
        let filtered = ws.filter(&model, &rows).unwrap().clone();
        let smoothed = ws.smooth(&model, &rows).unwrap().clone();
        let range_arg = format!("{from}:{to}");
        for command in ["filter", "smooth"] {
            let out = dir.join(format!("{command}-{initial}.csv"));
            let mut args = vec![
                command,
                "--model",
                s(&model_file),
                "--data",
                s(&data),
                "--out",
                s(&out),
                "--initial",
                initial,
                "--json",
            ];
            if range.is_some() {
                args.extend(["--range", &range_arg]);
            }
            let summary = json_of(&sysid(&args));
            let loglik = summary["loglik"].as_f64().unwrap();
            assert!(
                close(loglik, filtered.loglik()),
                "{command} {initial}: {loglik}"
            );
            let written = states(&out);
            assert_eq!(written.len(), rows.len(), "{command} {initial}");
            for (k, (label, values)) in written.iter().enumerate() {
                let ctx = format!("{command} {initial}, row {k}");
                assert_eq!(label, &format!("s{}", from + k), "{ctx}");
                let (mean, cov) = match command {
                    "filter" => (
                        filtered.filtered_mean(k).as_slice().to_vec(),
                        filtered.filtered_covariance(k),
                    ),
                    _ => (smoothed.mean(k).as_slice().to_vec(), smoothed.covariance(k)),
                };
                let undetermined = match command {
                    "filter" => filtered.filtered_undetermined(k),
                    _ => vec![false; 8],
                };
                for i in 0..8 {
                    if undetermined[i] {
                        assert_eq!(values[8 + i], f64::INFINITY, "{ctx}");
                        continue;
                    }
                    assert!(
                        close(values[i], mean[i]),
                        "{ctx}: {} vs {}",
                        values[i],
                        mean[i]
                    );
                    let sd = cov[(i, i)].max(0.0).sqrt();
                    assert!(close(values[8 + i], sd), "{ctx}: {} vs {sd}", values[8 + i]);
                }
            }
        }
    }
}

#[test]
fn a_range_outside_a_streamed_file_writes_nothing() {
    let dir = scratch_dir();
    let (data, model, _) = long_data(&dir);
    for range in ["0:5", "9000:9500", "20:10", "9500:"] {
        let out = dir.join("f.csv");
        let result = sysid(&[
            "filter",
            "--model",
            s(&model),
            "--data",
            s(&data),
            "--out",
            s(&out),
            "--range",
            range,
        ]);
        assert_one_line_error(&result, &["--range", "9000"]);
        assert!(!out.exists(), "{range}");
    }
    // an error in the last block leaves no partial output
    let text = std::fs::read_to_string(&data).unwrap();
    let broken = dir.join("broken.csv");
    std::fs::write(&broken, format!("{text}s9001,1,x,1,1\n")).unwrap();
    let out = dir.join("g.csv");
    let result = sysid(&[
        "filter",
        "--model",
        s(&model),
        "--data",
        s(&broken),
        "--out",
        s(&out),
    ]);
    assert_one_line_error(&result, &["broken.csv", "line 9002", "u2"]);
    assert!(!out.exists());
    assert_eq!(
        entries(&dir),
        ["broken.csv", "d.csv", "raw.csv", "true.json"]
    );
}

/// On a measured record longer than one block (DaISy's evaporator, 6305 rows: two
/// blocks), the streamed filter and the checkpointed smoother equal statsmodels 0.15.0's
/// Kalman filter and smoother (`tests/data/evaporator_statsmodels.json`, rows either
/// side of the block boundary and the ends) with a 4-state model fitted to it by
/// `fit lti` (`tests/data/evaporator_order4.json`, a known initial state).
#[test]
fn on_a_measured_record_filter_and_smooth_equal_statsmodels() {
    let dir = scratch_dir();
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = here.join("tests/data/evaporator_order4.json");
    let data = here.join("../../tests/data/daisy/evaporator.csv");
    let reference: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(here.join("tests/data/evaporator_statsmodels.json")).unwrap(),
    )
    .unwrap();
    let rows: Vec<usize> = reference["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r.as_u64().unwrap() as usize)
        .collect();
    for (command, pass) in [("filter", "filtered"), ("smooth", "smoothed")] {
        let out = dir.join(format!("{command}.csv"));
        let summary = json_of(&sysid(&[
            command,
            "--model",
            s(&model),
            "--data",
            s(&data),
            "--out",
            s(&out),
            "--json",
        ]));
        let loglik = summary["loglik"].as_f64().unwrap();
        let theirs = reference["loglik"].as_f64().unwrap();
        assert!(
            (loglik - theirs).abs() < 1e-9 * theirs.abs(),
            "{command}: {loglik} against {theirs}"
        );
        let written = states(&out);
        assert_eq!(written.len(), 6305);
        for (k, &row) in rows.iter().enumerate() {
            for (what, offset) in [("mean", 0), ("sd", 4)] {
                let expected = &reference[format!("{pass}_{what}")][k];
                for i in 0..4 {
                    let (ours, theirs) =
                        (written[row].1[offset + i], expected[i].as_f64().unwrap());
                    assert!(
                        (ours - theirs).abs() <= 1e-9 * theirs.abs().max(1e-3),
                        "{command} row {row} {what} x{}: {ours} against {theirs}",
                        i + 1
                    );
                }
            }
        }
    }
}
