//! Ctrl-C through the binary, for every fit method and both samplers: the run stops
//! within 2 s of the signal (gradient EM: after the iteration it is in), exits with
//! 130, and writes the result so far, marked interrupted.

#![cfg(unix)]

mod common;

use common::{assert_ok, interrupted_after, s, scratch_dir, sysid};
use std::path::Path;
use std::time::Duration;

const OSCILLATOR: &str = include_str!("../../../examples/models/oscillator.toml");

#[test]
fn ctrl_c_stops_every_fit_method_and_sampler_within_two_seconds() {
    let dir = scratch_dir();
    let osc = dir.join("osc.toml");
    std::fs::write(&osc, OSCILLATOR).unwrap();
    let product = dir.join("product.toml");
    std::fs::write(&product, OSCILLATOR.replace("c*v", "k*c*v")).unwrap();
    let data = dir.join("osc.csv");
    assert_ok(&sysid(&[
        "simulate",
        "--model",
        s(&osc),
        "--steps",
        "400",
        "--out",
        s(&data),
    ]));
    let nl = dir.join("nl.csv");
    assert_ok(&sysid(&[
        "simulate",
        "nlbench",
        "--steps",
        "300",
        "--out",
        s(&nl),
    ]));
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let heating = root.join("tests/data/heating_system.csv");
    let tanks = root.join("../../examples/models/cascaded_tanks.toml");
    let tanks_data = root.join("../../examples/data/cascaded_tanks_est.csv");
    let fit_toml = dir.join("fit.toml");
    let fit_json = dir.join("fit.json");
    let chains = dir.join("chains.csv");
    let out = s(&fit_toml);
    let model = |m: &Path, data: &Path, extra: &[&'static str]| -> Vec<String> {
        let mut args = vec![
            "fit",
            "--model",
            s(m),
            "--data",
            s(data),
            "--force",
            "--out",
            out,
        ];
        args.extend_from_slice(extra);
        args.into_iter().map(String::from).collect()
    };
    let words = |args: &[&str]| -> Vec<String> { args.iter().map(|a| a.to_string()).collect() };
    let cases: Vec<(&str, Vec<String>, &Path)> = vec![
        (
            "robust particle EM",
            model(&osc, &data, &["--max-iter", "100000"]),
            &fit_toml,
        ),
        (
            "particle EM",
            model(&osc, &data, &["--method", "em", "--max-iter", "10000000"]),
            &fit_toml,
        ),
        (
            "particle SAEM",
            model(
                &osc,
                &data,
                &["--method", "psaem", "--max-iter", "10000000"],
            ),
            &fit_toml,
        ),
        (
            "direct likelihood search",
            model(&product, &data, &["--starts", "200"]),
            &fit_toml,
        ),
        (
            "gradient EM",
            model(
                &product,
                &data,
                &["--method", "em", "--max-iter", "10000000"],
            ),
            &fit_toml,
        ),
        (
            "simulation-error fit",
            model(
                &tanks,
                &tanks_data,
                &["--criterion", "simulation", "--starts", "100000"],
            ),
            &fit_toml,
        ),
        (
            "fit lti",
            words(&[
                "fit",
                "lti",
                "--data",
                s(&heating),
                "--order",
                "6",
                "--max-iter",
                "100000000",
                "--tol-nats",
                "0",
                "--polish",
                "off",
                "--force",
                "--out",
                s(&fit_json),
            ]),
            &fit_json,
        ),
        (
            "fit nlbench",
            words(&[
                "fit",
                "nlbench",
                "--data",
                s(&nl),
                "--max-iter",
                "10000000",
                "--force",
                "--out",
                s(&fit_json),
            ]),
            &fit_json,
        ),
        (
            "pmmh",
            words(&[
                "pmmh",
                "--model",
                s(&osc),
                "--data",
                s(&data),
                "--iters",
                "100000000",
                "--chains",
                "2",
                "--particles",
                "50",
                "--out",
                s(&chains),
            ]),
            &chains,
        ),
        (
            "pgas",
            words(&[
                "pgas",
                "--model",
                s(&osc),
                "--data",
                s(&data),
                "--iters",
                "100000000",
                "--particles",
                "20",
                "--out",
                s(&chains),
            ]),
            &chains,
        ),
    ];
    let mut failures = Vec::new();
    for (name, args, written) in cases {
        let _ = std::fs::remove_file(written);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (out, seconds) = interrupted_after(&args, Duration::from_millis(2500));
        let (code, stderr) = (out.status.code(), String::from_utf8_lossy(&out.stderr));
        let report = format!("{name}: {seconds:.2} s, exit {code:?}, {}", stderr.trim());
        eprintln!("{report}");
        // gradient EM checks the stop between iterations only, and one iteration's
        // M-step (BFGS over 100 smoothed paths) takes 2-5 s here: it stops after the
        // iteration it is in (issue 58's "one run" is to reach into the M-step)
        let limit = if name == "gradient EM" { 10.0 } else { 2.0 };
        if seconds > limit || code != Some(130) || !written.exists() {
            failures.push(report);
        } else if !stderr.contains("interrupted (Ctrl-C)") {
            failures.push(format!("{report}: not said interrupted"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
