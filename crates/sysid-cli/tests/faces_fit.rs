//! One library, every face: the particle fits. `sysid fit --model` (affine: the robust
//! driver and plain particle EM; not affine: gradient EM), `sysid fit nlbench` and
//! `sysid fit wiener` give the numbers of `ModelFile::fit`, `fit_affine` and
//! `fit_wiener` with the same options and seed, to the bit, and the same warnings.

mod common;

use common::{assert_ok, json_of, s, scratch_dir, sysid};
use std::path::{Path, PathBuf};
use sysid::em::affine::{AffineFitOptions, AffineMethod, fit_affine};
use sysid::em::{FitRun, FitSettings};
use sysid::modelfile::{Criterion, ModelFile};
use sysid::models::{NlbenchAffine, NlbenchParams, WienerFitOptions, fit_wiener};
use sysid::smc::{PathSmoother, Series};

/// The guide's oscillator model file (affine in k and c).
fn oscillator() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/models/oscillator.toml")
}

/// A record simulated by the binary from a model file or a built-in system; its
/// outputs (time-major) and path.
fn simulated(dir: &Path, what: &[&str], steps: usize) -> (PathBuf, Vec<f64>, usize) {
    let path = dir.join("record.csv");
    let mut args = vec!["simulate"];
    args.extend_from_slice(what);
    let steps = steps.to_string();
    args.extend_from_slice(&["--steps", &steps, "--seed", "5", "--out", s(&path)]);
    assert_ok(&sysid(&args));
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let columns: Vec<usize> = (0..header.len())
        .filter(|&j| header[j] == "y" || header[j].starts_with("y1") || header[j] == "y2")
        .collect();
    let outputs = lines
        .flat_map(|l| {
            let fields: Vec<f64> = l.split(',').map(|v| v.parse().unwrap()).collect();
            columns.iter().map(move |&j| fields[j]).collect::<Vec<_>>()
        })
        .collect();
    (path, outputs, columns.len())
}

/// The options of the command line's defaults with these settings.
fn options(
    method: AffineMethod,
    particles: usize,
    iterations: usize,
    starts: usize,
) -> AffineFitOptions {
    let mut options = AffineFitOptions::default().with_method(method);
    options.particles = particles;
    options.iterations = iterations;
    options.starts = starts;
    options.smoother = PathSmoother::for_em("tanizaki", particles).unwrap();
    options
}

fn numbers(v: &serde_json::Value) -> Vec<u64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap().to_bits())
        .collect()
}

#[test]
fn fit_model_file_equals_the_library_for_each_method() {
    let dir = scratch_dir();
    let (data, y, p) = simulated(&dir, &["--model", s(&oscillator())], 150);
    let series = Series::new(&y, p).unwrap();
    let product = dir.join("product.toml");
    std::fs::write(
        &product,
        std::fs::read_to_string(oscillator())
            .unwrap()
            .replace("c*v", "k*c*v"),
    )
    .unwrap();
    // each method with the settings it reads (the others are refused: fit_method.rs)
    let read: [&[(&str, usize)]; 3] = [
        &[("particles", 40), ("max_iter", 6), ("starts", 3)],
        &[("particles", 40), ("max_iter", 6)],
        &[("starts", 3)],
    ];
    let cases = [
        (oscillator(), "robust", AffineMethod::Robust, read[0]),
        (oscillator(), "em", AffineMethod::Em, read[1]),
        (product.clone(), "em", AffineMethod::Em, read[1]),
        (product.clone(), "robust", AffineMethod::Robust, read[2]),
    ];
    for (path, method, chosen, given) in cases {
        let out = dir.join("fit.toml");
        let mut args = vec![
            "fit".to_string(),
            "--model".into(),
            s(&path).into(),
            "--data".into(),
            s(&data).into(),
            "--method".into(),
            method.into(),
            "--seed".into(),
            "9".into(),
            "--out".into(),
            s(&out).into(),
            "--force".into(),
            "--json".into(),
        ];
        let mut settings = FitSettings {
            method: Some(chosen),
            ..FitSettings::default()
        };
        for &(name, value) in given {
            args.extend([format!("--{}", name.replace('_', "-")), value.to_string()]);
            match name {
                "particles" => settings.particles = Some(value),
                "max_iter" => settings.max_iter = Some(value),
                _ => settings.starts = Some(value),
            }
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let run = sysid(&args);
        let summary = json_of(&run);
        let file = ModelFile::read(&path).unwrap();
        let fit = file
            .fit(
                series,
                &file.fit_method(Criterion::Likelihood, &settings).unwrap(),
                &FitRun::new(9),
                &mut (),
            )
            .unwrap();
        let written = ModelFile::read(&out).unwrap();
        let what = format!("{} --method {method}", path.display());
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&written.free_values()), bits(&fit.estimate), "{what}");
        let loglik = summary
            .get("loglik")
            .or_else(|| summary.get("loglik_estimate"))
            .and_then(|v| v.as_f64())
            .map(f64::to_bits);
        assert_eq!(loglik, fit.loglik().map(f64::to_bits), "{what}");
        let warnings: Vec<String> = fit.warnings.iter().map(ToString::to_string).collect();
        if let Some(cli) = summary.get("warnings") {
            assert_eq!(cli, &serde_json::json!(warnings), "{what}");
        }
        // a file that is not affine: gradient EM for em, the direct fit for robust
        let expected = match (path == product, method) {
            (true, "em") => "gradient-em",
            (true, _) => "direct",
            (false, _) => method,
        };
        assert_eq!(fit.method(), expected, "{what}");
    }
}

#[test]
fn fit_nlbench_equals_fit_affine_on_the_built_in_model() {
    let dir = scratch_dir();
    let (data, y, _) = simulated(&dir, &["nlbench"], 200);
    let out = dir.join("fit.json");
    let run = sysid(&[
        "fit",
        "nlbench",
        "--data",
        s(&data),
        "--init",
        "0.7,30,4.5,0.07",
        "--particles",
        "40",
        "--max-iter",
        "6",
        "--starts",
        "3",
        "--seed",
        "2",
        "--out",
        s(&out),
        "--json",
    ]);
    let summary = json_of(&run);
    let mut start = NlbenchParams::TRUE;
    (start.a, start.b, start.c, start.d) = (0.7, 30.0, 4.5, 0.07);
    let fit = fit_affine(
        &NlbenchAffine,
        Series::new(&y, 1).unwrap(),
        NlbenchAffine::params(&start),
        &options(AffineMethod::Robust, 40, 6, 3).check().unwrap(),
        &FitRun::new(2),
        &mut (),
    )
    .unwrap();
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let estimate = NlbenchAffine::nlbench_params(fit.estimate());
    for (name, value) in [
        ("a", estimate.a),
        ("b", estimate.b),
        ("q", estimate.q),
        ("r", estimate.r),
    ] {
        assert_eq!(
            written[name].as_f64().unwrap().to_bits(),
            value.to_bits(),
            "{name}"
        );
    }
    assert_eq!(
        summary["loglik"].as_f64().map(f64::to_bits),
        fit.loglik().map(f64::to_bits)
    );
}

#[test]
fn fit_wiener_equals_the_library() {
    let dir = scratch_dir();
    let (data, y, p) = simulated(&dir, &["wiener"], 150);
    assert_eq!(p, 2);
    let out = dir.join("w.json");
    let run = sysid(&[
        "fit",
        "wiener",
        "--data",
        s(&data),
        "--particles",
        "20",
        "--iters",
        "3",
        "--seed",
        "4",
        "--out",
        s(&out),
        "--json",
    ]);
    let summary = json_of(&run);
    let options = WienerFitOptions::new(20, 3).check().unwrap();
    let fit = fit_wiener(
        Series::new(&y, 2).unwrap(),
        &options,
        &FitRun::new(4),
        &mut (),
    )
    .unwrap();
    assert_eq!(
        numbers(&summary["r"]),
        fit.estimate
            .r
            .iter()
            .map(|v| v.to_bits())
            .collect::<Vec<_>>()
    );
    assert_eq!(
        summary["loglik_estimate"].as_f64().map(f64::to_bits),
        fit.result.loglik.map(f64::to_bits)
    );
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(
        written["gradient_em"]["normalised_magnitude_error_vs_reference_system"]
            .as_f64()
            .map(f64::to_bits),
        Some(fit.magnitude_error().to_bits())
    );
}
