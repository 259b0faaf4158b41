//! The `sysid` binary end to end: happy paths, and bad input giving one line on stderr
//! that names the place, with a non-zero exit code.

mod common;
use common::{assert_one_line_error, s, scratch_dir, sysid};
use std::process::Output;

const SCALAR_MODEL: &str =
    r#"{"a": [[0.9]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]], "p1": [[1.0]]}"#;

#[test]
fn simulate_then_loglik_matches_the_library() {
    let dir = scratch_dir();
    let (data, model) = (dir.join("d.csv"), dir.join("m.json"));
    let out = sysid(&[
        "simulate",
        "lti2x2",
        "--steps",
        "60",
        "--seed",
        "5",
        "--out",
        s(&data),
        "--model-out",
        s(&model),
        "--states",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&data).unwrap();
    assert_eq!(
        text.lines().next().unwrap(),
        "t,u1,u2,y1,y2,x1,x2,x3,x4,x5,x6,x7,x8"
    );
    assert_eq!(text.lines().count(), 61);
    let out = sysid(&["loglik", "--model", s(&model), "--data", s(&data), "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let sim = sysid::models::System::Lti2x2.simulate(60, 5).unwrap();
    let expected = sysid::kalman::KalmanWorkspace::new()
        .loglik(&sysid::models::lti2x2(), &sim.record)
        .unwrap();
    let got = v["loglik"].as_f64().unwrap();
    assert!(
        (got - expected).abs() <= 1e-12 * expected.abs(),
        "{got} vs {expected}"
    );
    // columns chosen by name, in another order, change nothing for a symmetric choice
    let out = sysid(&[
        "loglik",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--inputs",
        "u1,u2",
        "--outputs",
        "y1,y2",
    ]);
    let plain: f64 = String::from_utf8_lossy(&out.stdout).trim().parse().unwrap();
    assert_eq!(plain, got);
}

#[test]
fn smooth_writes_means_and_standard_deviations() {
    let dir = scratch_dir();
    let (data, model, out_csv) = (dir.join("d.csv"), dir.join("m.json"), dir.join("s.csv"));
    std::fs::write(&model, SCALAR_MODEL).unwrap();
    std::fs::write(&data, "t,y1\n1,0.5\n2,\n3,NaN\n4,-0.2\n").unwrap();
    let out = sysid(&[
        "smooth",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--out",
        s(&out_csv),
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&out_csv).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "t,x1,x1_sd");
    assert_eq!(lines.len(), 5);
    // the missing steps have larger smoothed standard deviations
    let sd = |l: &str| l.split(',').nth(2).unwrap().parse::<f64>().unwrap();
    assert!(sd(lines[2]) > sd(lines[1]) && sd(lines[3]) > sd(lines[4]));
}

#[test]
fn refuses_to_overwrite_without_force() {
    let dir = scratch_dir();
    let data = dir.join("d.csv");
    std::fs::write(&data, "precious").unwrap();
    let out = sysid(&["simulate", "lgss", "--steps", "10", "--out", s(&data)]);
    assert_one_line_error(&out, &["d.csv", "--force"]);
    assert_eq!(std::fs::read_to_string(&data).unwrap(), "precious");
    let out = sysid(&[
        "simulate",
        "lgss",
        "--steps",
        "10",
        "--out",
        s(&data),
        "--force",
    ]);
    assert!(out.status.success());
    assert!(std::fs::read_to_string(&data).unwrap().starts_with("t,y1"));
}

fn loglik_error(csv: &str, extra: &[&str]) -> Output {
    let dir = scratch_dir();
    let (data, model) = (dir.join("data.csv"), dir.join("m.json"));
    std::fs::write(&model, SCALAR_MODEL).unwrap();
    std::fs::write(&data, csv).unwrap();
    let mut args = vec!["loglik", "--model", s(&model), "--data", s(&data)];
    args.extend_from_slice(extra);
    sysid(
        &args
            .iter()
            .map(|a| a.to_string())
            .collect::<Vec<_>>()
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    )
}

#[test]
fn ragged_row_names_the_line() {
    let out = loglik_error("t,y1\n1,0.5\n2,0.1,7\n", &[]);
    assert_one_line_error(
        &out,
        &["data.csv", "line 3", "expected 2 fields", "found 3"],
    );
}

#[test]
fn non_numeric_field_names_line_and_column() {
    let out = loglik_error("t,y1\n1,0.5\n2,abc\n", &[]);
    assert_one_line_error(&out, &["data.csv", "line 3", "column y1", "\"abc\""]);
}

#[test]
fn empty_file_and_header_only() {
    assert_one_line_error(&loglik_error("", &[]), &["data.csv", "empty"]);
    assert_one_line_error(&loglik_error("t,y1\n", &[]), &["data.csv", "no data rows"]);
}

#[test]
fn unknown_column_lists_the_columns() {
    let out = loglik_error("t,y1\n1,0.5\n", &["--outputs", "y7"]);
    assert_one_line_error(&out, &["data.csv", "\"y7\"", "t, y1"]);
}

#[test]
fn infinite_output_names_line_and_column() {
    let out = loglik_error("t,y1\n1,0.5\n2,inf\n", &[]);
    assert_one_line_error(&out, &["data.csv", "line 3", "column y1", "inf"]);
}

#[test]
fn model_errors_name_the_matrix() {
    let dir = scratch_dir();
    let (data, model) = (dir.join("d.csv"), dir.join("bad.json"));
    std::fs::write(&data, "t,y1\n1,0.5\n").unwrap();
    for (json, needles) in [
        (
            r#"{"a": [[0.9, 1.0]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]]}"#,
            vec!["bad.json", "A must be 1x1"],
        ),
        (
            r#"{"a": [[0.9]], "c": [[1.0]], "q": [[-1.0]], "r": [[0.5]]}"#,
            vec!["bad.json", "Q is not positive semi-definite"],
        ),
        (
            r#"{"a": [[0.9, 0], [0, 0.5]], "c": [[1.0, 1.0]], "q": [[1, 0], [0, 1]], "r": [[0.5]], "p1": [[1, 2], [0, 1]]}"#,
            vec!["bad.json", "P1 is not symmetric"],
        ),
        (
            "{\"a\": [[0.9]],\n \"c\": [[NaN]]}",
            vec!["bad.json", "line 2"],
        ),
        (
            r#"{"a": [[0.9]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]], "zeta": 1}"#,
            vec!["bad.json", "zeta"],
        ),
        (
            r#"{"a": [[0.9]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]], "initial": "stationary", "p1": [[1.0]]}"#,
            vec!["bad.json", "\"p1\" conflicts with \"initial\""],
        ),
        (
            r#"{"a": [[1.01]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]], "initial": "stationary"}"#,
            vec![
                "bad.json",
                "cannot be stationary",
                "spectral radius 1.01",
                "diffuse",
            ],
        ),
        (
            r#"{"a": [[0.9]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]], "initial": "vague"}"#,
            vec!["bad.json", "unknown variant `vague`", "stationary"],
        ),
        (
            r#"{"a": [[0.9, 0], [0, 0.5]], "c": [[1.0, 1.0]], "q": [[1, 0], [0, 1]], "r": [[0.5]], "diffuse": [[1, 2], [1, 2]]}"#,
            vec!["bad.json", "diffuse directions", "linearly dependent"],
        ),
        (
            r#"{"a": [[0.9, 0], [0, 0.5]], "c": [[1.0, 0.0]], "q": [[1, 0], [0, 1]], "r": [[0.5]], "p1": [[0, 0], [0, 0]], "diffuse": [[0], [1]]}"#,
            vec![
                "d.csv",
                "do not determine the diffuse initial state",
                "rank 0 of 1",
            ],
        ),
    ] {
        std::fs::write(&model, json).unwrap();
        let out = sysid(&["loglik", "--model", s(&model), "--data", s(&data)]);
        assert_one_line_error(&out, &needles);
    }
}

#[test]
fn column_count_mismatch_and_unknown_system() {
    let out = loglik_error("t,y1,y2\n1,0.5,0.2\n", &[]);
    assert_one_line_error(&out, &["2 output columns", "model has 1"]);
    let dir = scratch_dir();
    let out = sysid(&["simulate", "pendulum", "--out", s(&dir.join("x.csv"))]);
    assert_one_line_error(&out, &["pendulum", "lgss, lti2x2"]);
}
