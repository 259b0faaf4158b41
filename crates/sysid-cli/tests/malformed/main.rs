//! The malformed-input suite: every bad input, through the `sysid` binary and through
//! the library API, gets a typed error that names the place. Through the binary each
//! case must exit with code 2 and one line on stderr containing the expected words, no
//! panic, and no output file left behind (the case's folder holds only its inputs
//! afterwards).

#[path = "../common/mod.rs"]
mod common;

mod api;
mod awkward;

use common::{entries as names, s, scratch_dir, sysid};

/// A scalar model (lgss) and a 2-output data file that the cases can point at.
const MODEL: &str = r#"{"a": [[0.9]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]]}"#;
const DATA: &str = "t,y1\n1,0.5\n2,-0.25\n3,1.5\n4,0.75\n";
const DATA_U: &str = "t,u1,y1\n1,0.1,0.5\n2,-0.3,-0.25\n3,0.2,1.5\n4,0.0,0.75\n";

/// One bad input: files to create, the arguments (`{dir}` is the case's folder), and
/// words the one-line error must contain.
struct Case {
    name: &'static str,
    files: &'static [(&'static str, &'static str)],
    args: &'static [&'static str],
    needles: &'static [&'static str],
}

const fn case(
    name: &'static str,
    files: &'static [(&'static str, &'static str)],
    args: &'static [&'static str],
    needles: &'static [&'static str],
) -> Case {
    Case {
        name,
        files,
        args,
        needles,
    }
}

const LOGLIK: &[&str] = &["loglik", "--model", "{dir}/m.json", "--data", "{dir}/d.csv"];
const SMOOTH: &[&str] = &[
    "smooth",
    "--model",
    "{dir}/m.json",
    "--data",
    "{dir}/d.csv",
    "--out",
    "{dir}/out.csv",
];
const N4SID: &[&str] = &[
    "n4sid",
    "--data",
    "{dir}/d.csv",
    "--order",
    "1",
    "--out",
    "{dir}/out.json",
];

#[rustfmt::skip]
const CASES: &[Case] = &[
    // CSV data files
    case("ragged row", &[("m.json", MODEL), ("d.csv", "t,y1\n1,0.5\n2\n3,0.1\n")], SMOOTH, &["d.csv", "line 3", "expected 2 fields", "found 1"]),
    case("extra field", &[("m.json", MODEL), ("d.csv", "t,y1\n1,0.5,9\n")], SMOOTH, &["d.csv", "line 2", "found 3"]),
    case("non-numeric field", &[("m.json", MODEL), ("d.csv", "t,y1\n1,0.5\n2,abc\n")], SMOOTH, &["d.csv", "line 3", "y1", "\"abc\""]),
    // a non-numeric time column ("monday", "1959Q1") is a label, not bad input: see
    // real_data.rs, delimiters_time_labels_and_the_sample_time
    case("empty file", &[("m.json", MODEL), ("d.csv", "")], SMOOTH, &["d.csv", "empty"]),
    case("blank lines only", &[("m.json", MODEL), ("d.csv", "\n\n")], LOGLIK, &["d.csv", "empty"]),
    case("header only", &[("m.json", MODEL), ("d.csv", "t,y1\n")], SMOOTH, &["d.csv", "no data rows"]),
    case("no signal columns", &[("m.json", MODEL), ("d.csv", "time,pressure\n1,2\n")], LOGLIK, &["d.csv", "no input or output column", "time, pressure"]),
    case("no output column", &[("d.csv", "t,u1\n1,2\n2,3\n3,1\n")], N4SID, &["d.csv", "no output column", "--outputs", "t, u1"]),
    case("duplicate column names", &[("m.json", MODEL), ("d.csv", "t,y1,y1\n1,0.5,0.5\n")], SMOOTH, &["d.csv", "line 1", "\"y1\""]),
    case("NaN in an input", &[("d.csv", "t,u1,y1\n1,0.1,0.5\n2,NaN,0.1\n3,0.2,0.3\n")], N4SID, &["d.csv", "line 3", "u1", "input"]),
    case("empty input cell", &[("d.csv", "t,u1,y1\n1,,0.5\n")], N4SID, &["d.csv", "line 2", "u1"]),
    case("Inf in an input", &[("d.csv", "t,u1,y1\n1,inf,0.5\n")], N4SID, &["d.csv", "line 2", "u1", "inf"]),
    case("Inf in an output", &[("m.json", MODEL), ("d.csv", "t,y1\n1,0.5\n2,inf\n")], SMOOTH, &["d.csv", "line 3", "y1", "output"]),
    case("-Inf in an output", &[("m.json", MODEL), ("d.csv", "t,y1\n1,-inf\n")], LOGLIK, &["d.csv", "line 2", "-inf"]),
    case("1e309 overflows to Inf", &[("m.json", MODEL), ("d.csv", "t,y1\n1,0.5\n2,1e309\n")], SMOOTH, &["d.csv", "line 3", "1e309"]),
    case("1e308 outputs overflow the likelihood", &[("m.json", MODEL), ("d.csv", "t,y1\n1,1e308\n2,-1e308\n")], LOGLIK, &["d.csv", "time 1", "overflows"]),
    case("unknown output column", &[("m.json", MODEL), ("d.csv", DATA)], &["loglik", "--model", "{dir}/m.json", "--data", "{dir}/d.csv", "--outputs", "y9"], &["d.csv", "\"y9\"", "t, y1"]),
    case("more outputs than the model", &[("m.json", MODEL), ("d.csv", "t,y1,y2\n1,0.5,0.1\n")], SMOOTH, &["output", "2", "1"]),
    case("invalid UTF-8", &[("m.json", MODEL), ("d.csv", "(written as bytes)")], LOGLIK, &["d.csv", "line 2"]),
    // model files
    case("model: missing matrix", &[("m.json", r#"{"a": [[0.9]], "c": [[1.0]], "r": [[0.5]]}"#), ("d.csv", DATA)], LOGLIK, &["m.json", "line 1", "`q`"]),
    case("model: wrong shape", &[("m.json", r#"{"a": [[0.9, 0.1]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]]}"#), ("d.csv", DATA)], SMOOTH, &["m.json", "matrix"]),
    case("model: ragged rows", &[("m.json", r#"{"a": [[0.9, 0.0], [0.1]], "c": [[1.0, 0.0]], "q": [[1.0, 0], [0, 1]], "r": [[0.5]]}"#), ("d.csv", DATA)], LOGLIK, &["m.json", "a"]),
    case("model: non-symmetric Q", &[("m.json", r#"{"a": [[0.9, 0], [0, 0.5]], "c": [[1.0, 1.0]], "q": [[1.0, 0.5], [0.2, 1.0]], "r": [[0.5]]}"#), ("d.csv", DATA)], SMOOTH, &["m.json", "Q", "not symmetric"]),
    case("model: indefinite R", &[("m.json", r#"{"a": [[0.9]], "c": [[1.0], [1.0]], "q": [[1.0]], "r": [[1.0, 2.0], [2.0, 1.0]]}"#), ("d.csv", "t,y1,y2\n1,0.5,0.5\n")], LOGLIK, &["m.json", "R", "not positive semi-definite"]),
    case("model: negative variance", &[("m.json", r#"{"a": [[0.9]], "c": [[1.0]], "q": [[-1.0]], "r": [[0.5]]}"#), ("d.csv", DATA)], LOGLIK, &["m.json", "Q"]),
    case("model: NaN entry", &[("m.json", r#"{"a": [[NaN]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]]}"#), ("d.csv", DATA)], SMOOTH, &["m.json", "line 1", "column"]),
    case("model: null entry", &[("m.json", r#"{"a": [[null]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]]}"#), ("d.csv", DATA)], LOGLIK, &["m.json", "line 1"]),
    case("model: 1e400 entry", &[("m.json", r#"{"a": [[1e400]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]]}"#), ("d.csv", DATA)], LOGLIK, &["m.json"]),
    case("model: unknown field", &[("m.json", r#"{"a": [[0.9]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]], "gain": 2}"#), ("d.csv", DATA)], LOGLIK, &["m.json", "unknown field", "gain"]),
    case("model: empty file", &[("m.json", ""), ("d.csv", DATA)], SMOOTH, &["m.json", "line 1"]),
    case("model: an array", &[("m.json", "[1, 2, 3]"), ("d.csv", DATA)], LOGLIK, &["m.json", "line 1"]),
    case("model: truncated", &[("m.json", r#"{"a": [[0.9]], "c": [[1.0]]"#), ("d.csv", DATA)], LOGLIK, &["m.json", "line 1"]),
    case("model: inputs but data without", &[("m.json", r#"{"a": [[0.9]], "b": [[1.0]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]]}"#), ("d.csv", DATA)], LOGLIK, &["input", "1", "0"]),
    // options
    case("particles 0", &[("d.csv", DATA)], &["pf", "--system", "lgss", "--data", "{dir}/d.csv", "--particles", "0", "--out", "{dir}/out.csv"], &["particles"]),
    case("particles negative", &[("d.csv", DATA)], &["pf", "--system", "lgss", "--data", "{dir}/d.csv", "--particles", "-5"], &["-5"]),
    case("ESS threshold above 1", &[("d.csv", DATA)], &["pf", "--system", "lgss", "--data", "{dir}/d.csv", "--ess", "1.5"], &["ess"]),
    case("unknown resampling scheme", &[("d.csv", DATA)], &["pf", "--system", "lgss", "--data", "{dir}/d.csv", "--resample", "lottery"], &["--resample", "lottery", "systematic"]),
    case("smoothed paths 0", &[("d.csv", DATA)], &["psmooth", "--system", "lgss", "--data", "{dir}/d.csv", "--paths", "0", "--out", "{dir}/out.csv"], &["paths"]),
    case("tanizaki with another path count", &[("d.csv", DATA)], &["psmooth", "--system", "lgss", "--data", "{dir}/d.csv", "--method", "tanizaki", "--particles", "50", "--paths", "10", "--out", "{dir}/out.csv"], &["--paths", "one path per particle (50)"]),
    case("steps 0", &[], &["simulate", "lgss", "--steps", "0", "--out", "{dir}/out.csv"], &["steps"]),
    case("steps negative", &[], &["simulate", "lgss", "--steps", "-3", "--out", "{dir}/out.csv"], &["-3"]),
    case("iterations 0", &[("d.csv", DATA_U)], &["fit", "lti", "--data", "{dir}/d.csv", "--order", "1", "--max-iter", "0", "--out", "{dir}/out.json"], &["--max-iter: must be at least 1"]),
    case("negative tolerance", &[("d.csv", DATA_U)], &["fit", "lti", "--data", "{dir}/d.csv", "--order", "1", "--tol=-1", "--out", "{dir}/out.json"], &["--tol:", "-1"]),
    case("NaN tolerance", &[("d.csv", DATA_U)], &["fit", "lti", "--data", "{dir}/d.csv", "--order", "1", "--tol", "NaN", "--out", "{dir}/out.json"], &["--tol:", "NaN"]),
    case("negative variance floor", &[("d.csv", DATA_U)], &["fit", "lti", "--data", "{dir}/d.csv", "--order", "1", "--min-variance=-1", "--out", "{dir}/out.json"], &["min-variance", "-1"]),
    case("order 0", &[("d.csv", DATA_U)], &["n4sid", "--data", "{dir}/d.csv", "--order", "0", "--out", "{dir}/out.json"], &["order"]),
    case("more block rows than data", &[("d.csv", DATA_U)], &["n4sid", "--data", "{dir}/d.csv", "--order", "1", "--block-rows", "50", "--out", "{dir}/out.json"], &["50 block rows", "samples"]),
    case("unknown matrix to fix", &[("d.csv", DATA_U)], &["fit", "lti", "--data", "{dir}/d.csv", "--order", "1", "--fix", "Z", "--out", "{dir}/out.json"], &["--fix", "Z"]),
    case("particle EM with 0 particles", &[("d.csv", DATA)], &["fit", "nlbench", "--data", "{dir}/d.csv", "--particles", "0", "--out", "{dir}/out.json"], &["particles"]),
    case("chains 0", &[("d.csv", DATA)], &["pmmh", "--system", "lgss", "--data", "{dir}/d.csv", "--chains", "0", "--out", "{dir}/out.csv"], &["--chains"]),
    case("burn-in longer than the chain", &[("d.csv", DATA)], &["pgas", "--system", "lgss", "--data", "{dir}/d.csv", "--iters", "10", "--burn-in", "20", "--out", "{dir}/out.csv"], &["burn"]),
    case("threads 0", &[("d.csv", DATA)], &["--threads", "0", "pf", "--system", "lgss", "--data", "{dir}/d.csv"], &["--threads"]),
    case("demo with 0 runs", &[], &["demo", "--runs", "0", "--out-dir", "{dir}/figures"], &["--runs"]),
    case("unknown plot kind", &[("d.csv", DATA)], &["plot", "{dir}/d.csv", "--kind", "pie", "--out-dir", "{dir}"], &["--kind", "pie"]),
    case("unknown subcommand", &[], &["identify", "--data", "x.csv"], &["identify"]),
    case("missing required option", &[], &["loglik", "--model", "{dir}/m.json"], &["--data"]),
    case("Wiener fit on one output", &[("d.csv", DATA)], &["fit", "wiener", "--data", "{dir}/d.csv", "--out", "{dir}/out.json"], &["output"]),
    case("one column as input and output", &[("d.csv", DATA_U), ("m.json", MODEL)], &["loglik", "--model", "{dir}/m.json", "--data", "{dir}/d.csv", "--inputs", "y1", "--outputs", "y1"], &["y1", "both an input and an output"]),
    case("one output twice", &[("d.csv", DATA), ("m.json", MODEL)], &["loglik", "--model", "{dir}/m.json", "--data", "{dir}/d.csv", "--outputs", "y1,y1"], &["y1", "chosen twice"]),
    case("the time column as an output", &[("d.csv", DATA), ("m.json", MODEL)], &["loglik", "--model", "{dir}/m.json", "--data", "{dir}/d.csv", "--outputs", "t"], &["time column"]),
    case("time that does not increase", &[("d.csv", "t,y1\n1,0.5\n3,1\n2,0.1\n4,0\n"), ("m.json", MODEL)], LOGLIK, &["line 4", "does not increase"]),
    case("a matrix fixed twice", &[("d.csv", DATA)], &["fit", "lti", "--data", "{dir}/d.csv", "--order", "1", "--fix", "A=0.5", "--fix", "A=0.9", "--out", "{dir}/out.json"], &["--fix", "A is fixed twice"]),
];

#[test]
fn every_bad_input_gets_a_one_line_error_that_names_the_place() {
    assert!(CASES.len() >= 40, "the suite has {} cases", CASES.len());
    let mut failures = Vec::new();
    for c in CASES {
        let dir = scratch_dir();
        for (name, contents) in c.files {
            // the one case whose bytes a &str cannot hold
            let bytes: &[u8] = if c.name == "invalid UTF-8" && *name == "d.csv" {
                b"t,y1\n1,\xff0.5\n"
            } else {
                contents.as_bytes()
            };
            std::fs::write(dir.join(name), bytes).unwrap();
        }
        let before = names(&dir);
        let args: Vec<String> = c.args.iter().map(|a| a.replace("{dir}", s(&dir))).collect();
        let argv: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = sysid(&argv);
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        let mut problems = Vec::new();
        if out.status.code() != Some(2) {
            problems.push(format!("exit code {:?}", out.status.code()));
        }
        if err.lines().count() != 1 {
            problems.push("stderr is not one line".to_string());
        }
        if err.contains("panicked") {
            problems.push("panicked".to_string());
        }
        for n in c.needles {
            if !err.contains(n) {
                problems.push(format!("no {n:?}"));
            }
        }
        if names(&dir) != before {
            problems.push(format!("files left: {:?}", names(&dir)));
        }
        if !problems.is_empty() {
            failures.push(format!(
                "{}: {} -- stderr: {}",
                c.name,
                problems.join(", "),
                err.trim()
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        CASES.len(),
        failures.join("\n")
    );
}
