//! The settings of a particle fit on the command line: their defaults are the
//! library's (`sysid::modelfile::fit_defaults`), a flag the method that runs does not
//! read is refused with one line naming the method (nothing written), and a flag it
//! reads changes the result. The library's own test (sysid-modelfile
//! tests/fit_method.rs) covers every setting against every method.

mod common;

use common::{assert_ok, assert_one_line_error, s, scratch_dir, sysid};
use std::path::{Path, PathBuf};

const OSCILLATOR: &str = include_str!("../../../examples/models/oscillator.toml");
const TANKS: &str = "../../examples/models/cascaded_tanks.toml";

/// The `[default: V]` that `--help` shows for `--flag`.
fn help_default(help: &str, flag: &str) -> Option<String> {
    let line = help
        .lines()
        .find(|l| l.trim_start().starts_with(&format!("{flag} ")))?;
    let at = line.find("[default: ")? + "[default: ".len();
    Some(line[at..].split(']').next()?.to_string())
}

fn help(args: &[&str]) -> String {
    let out = sysid(args);
    assert_ok(&out);
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn the_help_shows_the_library_defaults() {
    let d = sysid::modelfile::fit_defaults();
    let expected = [
        ("--method", d.method.map(|m| m.name().to_string())),
        ("--particles", d.particles.map(|v| v.to_string())),
        ("--smoother", d.smoother.clone()),
        ("--max-iter", d.max_iter.map(|v| v.to_string())),
        ("--starts", d.starts.map(|v| v.to_string())),
        (
            "--polish",
            d.polish.map(|on| if on { "on" } else { "off" }.to_string()),
        ),
        (
            "--extrapolate",
            d.extrapolate
                .map(|on| if on { "on" } else { "off" }.to_string()),
        ),
        ("--patience", d.patience.map(|v| v.to_string())),
        ("--spread", d.spread.map(|v| v.to_string())),
        (
            "--criterion",
            Some(sysid::modelfile::Criterion::default().to_string()),
        ),
    ];
    let model = help(&["fit", "--help"]);
    for (flag, value) in &expected {
        assert_eq!(&help_default(&model, flag), value, "fit --model {flag}");
    }
    // the affine classes share particle EM's flags and their defaults
    for class in ["nlbench", "affine"] {
        let text = help(&["fit", class, "--help"]);
        for (flag, value) in &expected[..7] {
            if *flag == "--polish" {
                continue;
            }
            assert_eq!(&help_default(&text, flag), value, "fit {class} {flag}");
        }
    }
}

#[test]
fn fit_lti_help_shows_the_library_defaults() {
    use sysid::em::linear::{LinearFitOptions, Selection, Start};
    let d = LinearFitOptions::default();
    let Start::N4sid { weighting, .. } = d.start else {
        panic!("the default start is N4SID")
    };
    let text = help(&["fit", "lti", "--help"]);
    let expected = [
        ("--weighting", weighting.name().to_string()),
        ("--initial", d.initial.name().to_string()),
        ("--accelerate", d.acceleration.name().to_string()),
        ("--polish", d.polish.name().to_string()),
        ("--std-errors", d.std_errors.name().to_string()),
        (
            "--detrend",
            d.detrend.map_or("none", |k| k.name()).to_string(),
        ),
        ("--select", Selection::default().name().to_string()),
        ("--max-iter", d.max_iterations.to_string()),
        ("--tol-nats", d.tol_nats.to_string()),
        ("--min-variance", d.min_variance.to_string()),
        ("--min-output-noise", d.min_output_noise.to_string()),
    ];
    for (flag, value) in expected {
        assert_eq!(help_default(&text, flag), Some(value), "fit lti {flag}");
    }
    let wiener = sysid::models::WienerFitOptions::default();
    let text = help(&["fit", "wiener", "--help"]);
    assert_eq!(
        help_default(&text, "--particles"),
        Some(wiener.particles.to_string())
    );
    assert_eq!(
        help_default(&text, "--max-iter"),
        Some(wiener.iterations.to_string())
    );
    for class in ["lti", "nlbench", "affine", "wiener"] {
        let text = help(&["fit", class, "--help"]);
        let seed = help_default(&text, "--seed");
        assert!(
            class == "lti" || seed == Some(sysid::smc::DEFAULT_SEED.to_string()),
            "{class}"
        );
    }
    // a value outside the library's names is refused by the parser, listing them
    let out = sysid(&[
        "fit", "lti", "--data", "x.csv", "--select", "bicc", "--out", "x.json",
    ]);
    assert_one_line_error(&out, &["bicc", "bic, aic, validation"]);
}

#[test]
fn fit_lti_refuses_the_start_s_settings_with_a_start_model_and_select_without_a_range() {
    let dir = scratch_dir();
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/ar1.csv");
    let start = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/ar1_start.json");
    let out = dir.join("fit.json");
    for (extra, setting, what) in [
        (
            &["--init", s(&start), "--weighting", "cva"][..],
            "--weighting",
            "EM from the given start model",
        ),
        (
            &["--init", s(&start), "--stable"][..],
            "--stable",
            "EM from the given start model",
        ),
        (
            &["--order", "1", "--select", "aic"][..],
            "--select",
            "a fit of one order",
        ),
    ] {
        let mut args = vec!["fit", "lti", "--data", s(&data), "--out", s(&out)];
        args.extend_from_slice(extra);
        assert_one_line_error(
            &sysid(&args),
            &[&format!("{setting} does not apply to {what}")],
        );
        assert!(!out.exists());
    }
    // at their defaults they are not given, and the fit runs
    assert_ok(&sysid(&[
        "fit",
        "lti",
        "--data",
        s(&data),
        "--init",
        s(&start),
        "--out",
        s(&out),
    ]));
}

/// A record of the guide's oscillator, and the file itself, in `dir`.
fn oscillator(dir: &Path) -> (PathBuf, PathBuf) {
    let model = dir.join("osc.toml");
    std::fs::write(&model, OSCILLATOR).unwrap();
    let data = dir.join("osc.csv");
    assert_ok(&sysid(&[
        "simulate",
        "--model",
        s(&model),
        "--steps",
        "60",
        "--out",
        s(&data),
    ]));
    (model, data)
}

#[test]
fn a_flag_the_method_does_not_read_is_refused_naming_the_method() {
    let dir = scratch_dir();
    let (osc, data) = oscillator(&dir);
    let product = dir.join("product.toml");
    std::fs::write(&product, OSCILLATOR.replace("c*v", "k*c*v")).unwrap();
    let out = dir.join("fit.toml");
    let cases: [(&Path, &[&str], &str); 8] = [
        (
            &product,
            &["--particles", "50"],
            "the direct likelihood search",
        ),
        (
            &product,
            &["--max-iter", "5"],
            "the direct likelihood search",
        ),
        (
            &product,
            &["--extrapolate", "off"],
            "the direct likelihood search",
        ),
        (
            &product,
            &["--method", "em", "--starts", "2"],
            "gradient EM",
        ),
        (
            &osc,
            &["--method", "em", "--polish", "off"],
            "plain particle EM (method em)",
        ),
        (
            &osc,
            &["--method", "psaem", "--smoother", "ffbsi-reject"],
            "particle SAEM",
        ),
        (&osc, &["--patience", "5"], "the robust particle EM driver"),
        (
            &osc,
            &["--criterion", "simulation", "--particles", "50"],
            "the simulation-error fit",
        ),
    ];
    for (model, extra, method) in cases {
        let mut args = vec![
            "fit",
            "--model",
            s(model),
            "--data",
            s(&data),
            "--out",
            s(&out),
        ];
        args.extend_from_slice(extra);
        let flag = extra.iter().rev().nth(1).unwrap();
        let run = sysid(&args);
        assert_one_line_error(
            &run,
            &[
                &format!("{flag} does not apply to {method}"),
                "leave it out",
            ],
        );
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
    // the built-in classes refuse alike
    let nl = dir.join("nl.csv");
    assert_ok(&sysid(&[
        "simulate",
        "nlbench",
        "--steps",
        "30",
        "--out",
        s(&nl),
    ]));
    let run = sysid(&[
        "fit",
        "nlbench",
        "--data",
        s(&nl),
        "--method",
        "em",
        "--starts",
        "3",
        "--out",
        s(&dir.join("nl.json")),
    ]);
    assert_one_line_error(&run, &["--starts does not apply to plain particle EM"]);
}

#[test]
fn a_flag_the_method_reads_changes_its_result() {
    let dir = scratch_dir();
    let (osc, data) = oscillator(&dir);
    let fit = |extra: &[&str]| -> String {
        let out = dir.join("fit.toml");
        let mut args = vec![
            "fit",
            "--model",
            s(&osc),
            "--data",
            s(&data),
            "--out",
            s(&out),
            "--force",
            "--method",
            "em",
            "--max-iter",
            "3",
            "--particles",
            "20",
        ];
        args.extend_from_slice(extra);
        assert_ok(&sysid(&args));
        std::fs::read_to_string(&out).unwrap()
    };
    let base = fit(&[]);
    assert_ne!(base, fit(&["--smoother", "ffbsi-reject"]), "--smoother");
    assert_ne!(base, fit(&["--seed", "2"]), "--seed");
    // the simulation-error fit reads --spread and --patience
    let tanks = Path::new(env!("CARGO_MANIFEST_DIR")).join(TANKS);
    let est =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data/cascaded_tanks_est.csv");
    // every run's end (the best may be the file's own start whatever the spread)
    let simulation = |extra: &[&str]| -> serde_json::Value {
        let out = dir.join("tanks.toml");
        let mut args = vec![
            "fit",
            "--model",
            s(&tanks),
            "--data",
            s(&est),
            "--criterion",
            "simulation",
            "--starts",
            "2",
            "--out",
            s(&out),
            "--force",
            "--json",
        ];
        args.extend_from_slice(extra);
        common::json_of(&sysid(&args))["runs"].clone()
    };
    let base = simulation(&[]);
    assert_ne!(base, simulation(&["--spread", "0.9"]), "--spread");
    assert_ne!(base, simulation(&["--patience", "2"]), "--patience");
}
