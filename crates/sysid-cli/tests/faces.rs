//! One library, every face: `sysid fit lti` and the library's `LinearFit::run` on the
//! same data and options give bit-identical numbers and the same warnings.
//!
//! The library side reads the CSV itself (a few lines here, not the command line's
//! reader), so that nothing of the command line stands between the data and the call.

mod common;

use common::signals::{data, read_csv};
use common::{assert_ok, json_of, s, scratch_dir, sysid};
use std::path::Path;
use sysid::em::linear::{
    Acceleration, Fix, FixValue, LinearFit, LinearFitOptions, Matrix, OrderChoice, Selection,
    Signals, Start, Switch,
};
use sysid::kalman::{InitialState, ModelSpec, TrendKind};

/// Runs `sysid fit lti ARGS --out DIR/fit.json --json`: the written model and the
/// JSON summary.
fn cli_fit(args: &[&str]) -> (ModelSpec, serde_json::Value) {
    let dir = scratch_dir();
    let out = dir.join("fit.json");
    let mut all = vec!["fit", "lti"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--out", s(&out), "--json"]);
    let run = sysid(&all);
    let summary = json_of(&run);
    let spec: ModelSpec = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    (spec, summary)
}

/// Asserts that the binary's model and summary are the library's, to the bit.
fn assert_same(cli: &(ModelSpec, serde_json::Value), fit: &LinearFit) {
    let (spec, summary) = cli;
    let library = fit.model_spec();
    let strip = |mut s: ModelSpec| {
        s.metadata = None;
        serde_json::to_value(s).unwrap()
    };
    assert_eq!(strip(spec.clone()), strip(library.clone()), "model entries");
    let (m, l) = (spec.metadata.clone().unwrap(), library.metadata.unwrap());
    assert_eq!(
        (
            m.loglik.map(f64::to_bits),
            m.aic.map(f64::to_bits),
            m.bic.map(f64::to_bits)
        ),
        (
            l.loglik.map(f64::to_bits),
            l.aic.map(f64::to_bits),
            l.bic.map(f64::to_bits)
        ),
        "log-likelihood and criteria"
    );
    assert_eq!(
        (
            m.order,
            m.parameters,
            &m.termination,
            &m.detrend,
            &m.covariance
        ),
        (
            l.order,
            l.parameters,
            &l.termination,
            &l.detrend,
            &l.covariance
        )
    );
    assert_eq!(summary["loglik"].as_f64(), fit.loglik);
    assert_eq!(summary["iterations"], fit.iterations);
    assert_eq!(summary["e_steps"], fit.e_steps);
    assert_eq!(summary["termination"], fit.status.name());
    let warnings: Vec<String> = fit.warnings.iter().map(ToString::to_string).collect();
    assert_eq!(summary["warnings"], serde_json::json!(warnings));
    match &fit.validation {
        Some(v) => {
            assert_eq!(summary["validation"]["rows"], v.rows);
            assert_eq!(
                summary["validation"]["simulation_fit_percent"].as_f64(),
                v.simulation_fit_percent
            );
            assert_eq!(
                summary["validation"]["prediction_fit_percent"].as_f64(),
                v.prediction_fit_percent
            );
        }
        None => assert!(summary["validation"].is_null()),
    }
    match &fit.uncertainty {
        Some(u) => {
            let errors: Vec<f64> = summary["parameters"]
                .as_array()
                .unwrap()
                .iter()
                .map(|p| p["std_error"].as_f64().unwrap())
                .collect();
            let library: Vec<f64> = u.parameters.iter().map(|p| p.std_error).collect();
            assert_eq!(errors, library, "standard errors");
        }
        None => assert!(summary["parameters"].is_null()),
    }
}

fn library_fit(data: &Signals, options: LinearFitOptions) -> LinearFit {
    LinearFit::run(data, &options.check().unwrap(), &mut ()).unwrap()
}

#[test]
fn fit_lti_with_mean_detrending_equals_the_library() {
    let path = data("heating_system.csv");
    let cli = cli_fit(&[
        "--data",
        s(&path),
        "--range",
        ":400",
        "--order",
        "3",
        "--detrend",
        "mean",
    ]);
    let mut options = LinearFitOptions::default();
    options.order = OrderChoice::Fixed(3);
    options.detrend = Some(TrendKind::Mean);
    let fit = library_fit(&read_csv(&path, Some((0, 400))), options);
    assert_same(&cli, &fit);
}

#[test]
fn an_order_range_with_a_split_equals_the_library_and_reads_the_data_once() {
    let path = data("heating_system.csv");
    let cli = cli_fit(&[
        "--data",
        s(&path),
        "--order",
        "1..4",
        "--detrend",
        "mean",
        "--split",
        "0.5",
        "--select",
        "validation",
    ]);
    let mut options = LinearFitOptions::default();
    options.order = OrderChoice::Range {
        from: 1,
        to: 4,
        select: Selection::Validation,
    };
    options.detrend = Some(TrendKind::Mean);
    options.split = Some(0.5);
    let fit = library_fit(&read_csv(&path, None), options);
    assert_same(&cli, &fit);
    let table = fit.order_table.as_ref().unwrap();
    let summary = &cli.1["order_table"];
    assert_eq!(summary["chosen"], table.chosen);
    assert_eq!(summary["select"], "validation");
    for (row, json) in table.rows.iter().zip(summary["orders"].as_array().unwrap()) {
        assert_eq!(json["order"], row.order);
        assert_eq!(json["loglik"].as_f64(), row.loglik);
        assert_eq!(
            json["validation_simulation_fit_percent"].as_f64(),
            row.validation
        );
    }
    assert_eq!(table.rows.len(), 4);
}

#[test]
fn linear_detrending_with_a_split_and_plain_em_equals_the_library() {
    let path = data("heating_system.csv");
    let cli = cli_fit(&[
        "--data",
        s(&path),
        "--order",
        "2",
        "--detrend",
        "linear",
        "--split",
        "0.7",
        "--accelerate",
        "none",
        "--max-iter",
        "40",
        "--polish",
        "off",
    ]);
    let mut options = LinearFitOptions::default();
    options.order = OrderChoice::Fixed(2);
    options.detrend = Some(TrendKind::Linear);
    options.split = Some(0.7);
    options.acceleration = Acceleration::None;
    options.max_iterations = 40;
    options.polish = Switch::Off;
    let fit = library_fit(&read_csv(&path, None), options);
    assert_same(&cli, &fit);
    // 40 plain EM iterations do not converge: the warning is the same on both faces
    assert!(!fit.warnings.is_empty());
}

#[test]
fn fixed_matrices_from_a_start_file_equal_the_library() {
    let path = data("heating_system.csv");
    let start = data("heating_first_order.json");
    let cli = cli_fit(&[
        "--data",
        s(&path),
        "--range",
        ":400",
        "--detrend",
        "mean",
        "--init",
        s(&start),
        "--fix",
        "C",
        "--fix",
        "D",
        "--fix",
        "R=0.01",
    ]);
    let spec: ModelSpec = serde_json::from_str(&std::fs::read_to_string(&start).unwrap()).unwrap();
    let mut options = LinearFitOptions::default();
    options.start = Start::of_file(&spec).unwrap();
    options.detrend = Some(TrendKind::Mean);
    options.fixes = vec![
        Fix::at_start(Matrix::C),
        Fix::at_start(Matrix::D),
        Fix::at(Matrix::R, FixValue::Scalar(0.01)),
    ];
    let fit = library_fit(&read_csv(&path, Some((0, 400))), options);
    assert_same(&cli, &fit);
    assert!(
        fit.uncertainty.is_some(),
        "a structural model gets standard errors"
    );
}

#[test]
fn the_nile_local_level_with_a_diffuse_start_equals_the_library() {
    let path = data("nile.csv");
    let start = data("nile_start.json");
    let cli = cli_fit(&[
        "--data",
        s(&path),
        "--init",
        s(&start),
        "--fix",
        "A",
        "--fix",
        "C",
        "--initial",
        "diffuse",
    ]);
    let spec: ModelSpec = serde_json::from_str(&std::fs::read_to_string(&start).unwrap()).unwrap();
    let mut options = LinearFitOptions::default();
    options.start = Start::of_file(&spec).unwrap();
    options.fixes = vec![Fix::at_start(Matrix::A), Fix::at_start(Matrix::C)];
    options.initial = InitialState::Diffuse;
    let fit = library_fit(&read_csv(&path, None), options);
    assert_same(&cli, &fit);
}

#[test]
fn two_outputs_get_a_diagonal_r_on_both_faces_unless_asked_for_a_full_one() {
    let dir = scratch_dir();
    let path = dir.join("d.csv");
    assert_ok(&sysid(&[
        "simulate",
        "lti2x2",
        "--steps",
        "300",
        "--seed",
        "4",
        "--out",
        s(&path),
    ]));
    let records = read_csv(&path, None);
    for full in [false, true] {
        let mut args = vec!["--data", s(&path), "--order", "2", "--max-iter", "60"];
        if full {
            args.push("--full-r");
        }
        let cli = cli_fit(&args);
        let mut options = LinearFitOptions::default();
        options.order = OrderChoice::Fixed(2);
        options.max_iterations = 60;
        options.full_r = full;
        let fit = library_fit(&records, options);
        assert_same(&cli, &fit);
        assert_eq!(fit.model.r()[(0, 1)] == 0.0, !full, "full R: {full}");
    }
}

/// The log-likelihood the guide's Rust example asserts (a hidden line of its block).
fn guide_constant() -> f64 {
    let guide =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/guide.md"))
            .unwrap();
    let line = guide
        .lines()
        .find(|l| l.contains("const GUIDE_HEAT_LOGLIK: f64 ="))
        .expect("the guide's library example states the command's log-likelihood");
    let value = line.split('=').nth(1).unwrap().split(';').next().unwrap();
    value.trim().parse().unwrap()
}

/// The guide's library example (run as a doctest of the `sysid` crate) asserts this
/// log-likelihood to the bit; here the command of section 3 gives it too.
#[test]
fn the_guide_library_example_gives_the_command_s_log_likelihood_to_the_bit() {
    let path = data("heating_system.csv");
    let (spec, summary) = cli_fit(&[
        "--data",
        s(&path),
        "--range",
        ":400",
        "--order",
        "3",
        "--detrend",
        "mean",
        "--initial",
        "diffuse",
    ]);
    let expected = guide_constant();
    assert_eq!(
        summary["loglik"].as_f64().map(f64::to_bits),
        Some(expected.to_bits())
    );
    assert_eq!(
        spec.metadata.and_then(|m| m.loglik).map(f64::to_bits),
        Some(expected.to_bits())
    );
}

/// `sysid pf` and the library's filter with `FilterDiagnostics` give the same
/// log-likelihood, repeats, sd and warnings, to the bit.
#[test]
fn pf_and_its_diagnostics_equal_the_library() {
    use sysid::smc::{FilterDiagnostics, FilterOptions, ParticleFilter, Resampling, Series};
    let dir = scratch_dir();
    let path = dir.join("d.csv");
    assert_ok(&sysid(&[
        "simulate",
        "nlbench",
        "--steps",
        "300",
        "--seed",
        "3",
        "--out",
        s(&path),
    ]));
    // the default (the single-run sd) and 9 repeats
    for repeats in [0usize, 9] {
        let repeats_text = repeats.to_string();
        let run = sysid(&[
            "pf",
            "--system",
            "nlbench",
            "--data",
            s(&path),
            "--particles",
            "300",
            "--seed",
            "5",
            "--repeats",
            &repeats_text,
            "--json",
        ]);
        let summary = json_of(&run);
        let data = read_csv(&path, None);
        let y: Vec<f64> = data.record.y.iter().copied().collect();
        let series = Series::new(&y, 1).unwrap();
        let mut pf = ParticleFilter::new(FilterOptions {
            particles: 300,
            resampling: Resampling::Systematic,
            ess_threshold: 1.0,
            variance_block: Some(sysid::smc::VARIANCE_SPAN),
            ..FilterOptions::default()
        })
        .unwrap();
        let model = sysid::models::Nlbench::truth();
        let filtered = pf.run(&model, &series, 5).unwrap();
        let checked =
            FilterDiagnostics::diagnose(&model, &series, &pf, &filtered, 5, repeats, || {});
        assert_eq!(
            summary["loglik"].as_f64().map(f64::to_bits),
            Some(filtered.loglik.to_bits())
        );
        let d = &summary["diagnostics"];
        assert_eq!(
            d["loglik_sd"].as_f64().map(f64::to_bits),
            checked.loglik_sd.map(f64::to_bits)
        );
        assert_eq!(
            d["loglik_sd_single_run"].as_f64().map(f64::to_bits),
            checked.loglik_sd_single_run.map(f64::to_bits)
        );
        let method = if repeats == 0 {
            "single-run"
        } else {
            "repeats"
        };
        assert_eq!(d["loglik_sd_method"], method);
        let logliks: Vec<f64> = d["repeat_logliks"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(logliks, checked.repeat_logliks);
        assert_eq!(logliks.len(), repeats);
        assert_eq!(d["min_ess"].as_f64(), checked.min_ess.map(|(e, _)| e));
        // the data file's times are the row numbers here, so the texts agree too
        let warnings: Vec<String> = checked.warnings.iter().map(ToString::to_string).collect();
        assert_eq!(summary["warnings"], serde_json::json!(warnings));
    }
}

/// `sysid pmmh`'s summary and warnings are the library's `ChainReport` of the chains
/// it wrote.
#[test]
fn pmmh_summary_and_warnings_are_the_library_report_of_its_chains() {
    use sysid::models::LgssFamily;
    use sysid::pmcmc::{
        Chain, ChainReport, ChainRun, IndependentPrior, ModelFamily, PmmhOptions, pmmh,
    };
    let dir = scratch_dir();
    let (data, chains_file) = (dir.join("d.csv"), dir.join("chains.json"));
    assert_ok(&sysid(&[
        "simulate",
        "lgss",
        "--steps",
        "100",
        "--seed",
        "2",
        "--out",
        s(&data),
    ]));
    let run = sysid(&[
        "pmmh",
        "--system",
        "lgss",
        "--data",
        s(&data),
        "--iters",
        "300",
        "--chains",
        "2",
        "--particles",
        "30",
        "--out",
        s(&chains_file),
        "--json",
    ]);
    let summary = json_of(&run);
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&chains_file).unwrap()).unwrap();
    let numbers = |v: &serde_json::Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap_or(f64::NAN))
            .collect()
    };
    let chains: Vec<Chain> = written["chains"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| Chain {
            names: serde_json::from_value(c["names"].clone()).unwrap(),
            burn_in: c["burn_in"].as_u64().unwrap() as usize,
            samples: numbers(&c["samples"]),
            log_likelihood: numbers(&c["log_likelihood"]),
            log_prior: numbers(&c["log_prior"]),
            accepted: serde_json::from_value(c["accepted"].clone()).unwrap(),
            state_update_rate: None,
            state_mean: None,
            interrupted: false,
        })
        .collect();
    let report = ChainReport::of(&chains);
    assert_eq!(summary["acceptance"], serde_json::json!(report.acceptance));
    let warnings: Vec<String> = report.warnings.iter().map(ToString::to_string).collect();
    assert_eq!(summary["warnings"], serde_json::json!(warnings));
    assert!(
        !warnings.is_empty(),
        "300 iterations of 2 chains leave few effective draws"
    );
    for (json, s) in summary["summary"]
        .as_array()
        .unwrap()
        .iter()
        .zip(&report.summary)
    {
        assert_eq!(json["name"], s.name.as_str());
        assert_eq!(json["mean"].as_f64(), Some(s.mean));
        assert_eq!(json["rhat"].as_f64(), Some(s.rhat));
        assert_eq!(json["ess_bulk"].as_f64(), Some(s.ess_bulk));
    }
    // the chains themselves are the library's pmmh with the command's options
    let (burn_in, seed) = (
        summary["burn_in"].as_u64().unwrap() as usize,
        summary["seed"].as_u64().unwrap(),
    );
    let y: Vec<f64> = read_csv(&data, None).record.y.iter().copied().collect();
    let family = LgssFamily::default();
    let prior = IndependentPrior::new(
        &family.parameter_names(),
        LgssFamily::DEFAULT_PRIORS.to_vec(),
    )
    .unwrap();
    let options = PmmhOptions {
        iterations: 300,
        burn_in,
        particles: 30,
        ..PmmhOptions::default()
    };
    let library = pmmh(
        &family,
        &prior,
        &sysid::smc::Series::new(&y, 1).unwrap(),
        &[0.5, 1.0, 1.0],
        &options,
        &ChainRun::new(2, seed),
    )
    .unwrap();
    assert_eq!(written["chains"], serde_json::to_value(&library).unwrap());
}

/// `sysid n4sid --order auto` and `sysid loglik` give the library's numbers and
/// warnings: the order, singular values, spectral radius and the subspace warnings;
/// the written model's log-likelihood under its stored initial state.
#[test]
fn n4sid_auto_and_loglik_equal_the_library() {
    use sysid::kalman::KalmanWorkspace;
    use sysid::subspace::{N4sidOptions, Order};
    let path = data("heating_system.csv");
    let dir = scratch_dir();
    let out = dir.join("n4.json");
    let run = sysid(&[
        "n4sid",
        "--data",
        s(&path),
        "--range",
        ":400",
        "--order",
        "auto",
        "--block-rows",
        "3",
        "--out",
        s(&out),
        "--json",
    ]);
    let summary = json_of(&run);
    let record = read_csv(&path, Some((0, 400))).record;
    let options = N4sidOptions {
        order: Order::Auto,
        block_rows: Some(3),
        ..Default::default()
    };
    // the command's default weighting is the data's choice
    let result =
        sysid::subspace::n4sid_weighted(&record, &options, sysid::subspace::WeightingChoice::Auto)
            .unwrap()
            .result;
    assert_eq!(summary["weighting"], result.weighting.name());
    assert_eq!(summary["order"], result.order);
    let singular: Vec<f64> = summary["singular_values"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(singular, result.singular_values);
    assert_eq!(
        summary["spectral_radius"].as_f64().map(f64::to_bits),
        Some(result.spectral_radius.to_bits())
    );
    let warnings: Vec<String> = result
        .warnings(&options)
        .iter()
        .map(ToString::to_string)
        .collect();
    assert_eq!(summary["warnings"], serde_json::json!(warnings));
    // three block rows of one output: candidates 1 and 2, the larger chosen and flagged
    assert_eq!(result.order, 2);
    assert!(
        warnings.iter().any(|w| w.contains("largest candidate")),
        "{warnings:?}"
    );
    // the written model (means in h, S kept) scored by loglik as by the library
    let written: ModelSpec = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let model = written.build().unwrap();
    let score = sysid(&[
        "loglik",
        "--model",
        s(&out),
        "--data",
        s(&path),
        "--range",
        ":400",
        "--json",
    ]);
    let score = json_of(&score);
    let library = KalmanWorkspace::new().loglik(&model, &record).unwrap();
    assert_eq!(
        score["loglik"].as_f64().map(f64::to_bits),
        Some(library.to_bits())
    );
}

/// The cascaded-tanks example's columns `u`, `y` (read here, not by the binary).
fn tanks_record(name: &str) -> (Vec<f64>, Vec<f64>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/data")
        .join(name);
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .map(|l| {
            let cells: Vec<f64> = l.split(',').map(|c| c.parse().unwrap()).collect();
            (cells[1], cells[2])
        })
        .unzip()
}

#[test]
fn compare_and_the_simulation_error_fit_of_a_model_file_equal_the_library() {
    use sysid::modelfile::{InitialState as Start0, ModelFile, SimulationFitOptions};
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let fitted = examples.join("models/cascaded_tanks_fitted.toml");
    let (u, y) = tanks_record("cascaded_tanks_val.csv");
    let series = sysid::smc::Series::new(&y, 1)
        .unwrap()
        .with_inputs(&u, 1)
        .unwrap();
    let library = ModelFile::read(&fitted)
        .unwrap()
        .compare_simulation(series, Start0::Estimate { samples: 5 }, 0)
        .unwrap();
    let run = sysid(&[
        "compare",
        "--model",
        s(&fitted),
        "--data",
        s(&examples.join("data/cascaded_tanks_val.csv")),
        "--initial-samples",
        "5",
        "--json",
    ]);
    let summary = json_of(&run);
    let model = &summary["models"][0];
    assert_eq!(model["rms"][0].as_f64(), Some(library.rms[0]));
    assert_eq!(
        model["fit_percent"][0].as_f64(),
        Some(library.fit_percent[0])
    );
    assert_eq!(
        model["initial_state"][1].as_f64(),
        Some(library.initial_state[1])
    );

    // a short simulation-error fit: the written file and the summary are the library's
    let start = examples.join("models/cascaded_tanks.toml");
    let (u, y) = tanks_record("cascaded_tanks_est.csv");
    let series = sysid::smc::Series::new(&y, 1)
        .unwrap()
        .with_inputs(&u, 1)
        .unwrap();
    let options = SimulationFitOptions {
        starts: 3,
        seed: 4,
        ..SimulationFitOptions::default()
    };
    let fit = ModelFile::read(&start)
        .unwrap()
        .fit_simulation_error(series, &options, &|| false)
        .unwrap();
    let dir = scratch_dir();
    let out = dir.join("tanks.toml");
    let run = sysid(&[
        "fit",
        "--model",
        s(&start),
        "--data",
        s(&examples.join("data/cascaded_tanks_est.csv")),
        "--criterion",
        "simulation",
        "--starts",
        "3",
        "--seed",
        "4",
        "--out",
        s(&out),
        "--json",
    ]);
    let summary = json_of(&run);
    assert_eq!(summary["rms"][0].as_f64(), Some(fit.rms[0]));
    let written = ModelFile::read(&out).unwrap();
    assert_eq!(written.free_values(), fit.estimate);
    assert_eq!(written.initial_means(), fit.initial_state);
    let warnings: Vec<String> = fit.warnings.iter().map(ToString::to_string).collect();
    assert_eq!(summary["warnings"], serde_json::json!(warnings));
}

#[test]
fn simulate_noise_free_of_a_model_file_equals_the_library() {
    use sysid::modelfile::ModelFile;
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let fitted = examples.join("models/cascaded_tanks_fitted.toml");
    let (u, _) = tanks_record("cascaded_tanks_val.csv");
    let library = ModelFile::read(&fitted)
        .unwrap()
        .simulate_noise_free(&u, u.len(), None)
        .unwrap();
    let dir = scratch_dir();
    let out = dir.join("sim.csv");
    let run = sysid(&[
        "simulate",
        "--model",
        s(&fitted),
        "--data",
        s(&examples.join("data/cascaded_tanks_val.csv")),
        "--noise-free",
        "--states",
        "--out",
        s(&out),
    ]);
    assert_ok(&run);
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("t,u,y,h1,h2"));
    for (t, line) in lines.enumerate() {
        let cells: Vec<f64> = line.split(',').map(|c| c.parse().unwrap()).collect();
        assert_eq!(cells[2], library.outputs[t], "y at row {t}");
        assert_eq!(cells[3], library.states[2 * t], "h1 at row {t}");
    }
}

#[test]
fn n4sid_says_when_stabilising_destroyed_the_model_as_the_library_measures_it() {
    use sysid::subspace::{N4sidOptions, Order, Weighting, n4sid, stabilised_fit};
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/daisy/CD_player_arm.csv");
    let dir = scratch_dir();
    let run = sysid(&[
        "n4sid",
        "--data",
        s(&path),
        "--order",
        "5",
        "--weighting",
        "n4sid",
        "--stable",
        "--out",
        s(&dir.join("m.json")),
        "--json",
    ]);
    let summary = json_of(&run);
    let record = read_csv(&path, None).record;
    let options = N4sidOptions {
        order: Order::Fixed(5),
        weighting: Weighting::N4sid,
        stable: true,
        ..Default::default()
    };
    let result = n4sid(&record, &options).unwrap();
    let fit = stabilised_fit(&record, &result, &options).expect("A needed stabilising");
    assert!(
        fit.destroyed() && fit.unstabilised_prediction_fit.unwrap() > 80.0,
        "{fit:?}"
    );
    let reported = &summary["stabilised_fit"];
    assert_eq!(
        reported["simulation_fit"].as_f64(),
        Some(fit.simulation_fit)
    );
    assert_eq!(reported["destroyed"], serde_json::json!(true));
    let warnings = summary["warnings"].as_array().unwrap();
    assert!(
        warnings
            .iter()
            .any(|w| w.as_str().unwrap().starts_with("stabilising destroyed"))
    );
    // the default weighting finds a stable model by itself at this order
    let auto = json_of(&sysid(&[
        "n4sid",
        "--data",
        s(&path),
        "--order",
        "5",
        "--out",
        s(&dir.join("a.json")),
        "--json",
    ]));
    assert_eq!(auto["stable"], serde_json::json!(true));
    assert_eq!(auto["stabilised"], serde_json::json!(false));
}

#[test]
fn predict_of_a_model_file_equals_the_library_s_particle_predictions() {
    use sysid::modelfile::ModelFile;
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let fitted = examples.join("models/cascaded_tanks_fitted.toml");
    let (u, y) = tanks_record("cascaded_tanks_val.csv");
    let series = sysid::smc::Series::new(&y, 1)
        .unwrap()
        .with_inputs(&u, 1)
        .unwrap();
    let library = ModelFile::read(&fitted)
        .unwrap()
        .predict_particles(series, 3, 500, 9)
        .unwrap();
    let dir = scratch_dir();
    let out = dir.join("p.csv");
    let run = sysid(&[
        "predict",
        "--model",
        s(&fitted),
        "--data",
        s(&examples.join("data/cascaded_tanks_val.csv")),
        "--horizon",
        "3",
        "--particles",
        "500",
        "--seed",
        "9",
        "--out",
        s(&out),
    ]);
    assert_ok(&run);
    let text = std::fs::read_to_string(&out).unwrap();
    for (t, line) in text.lines().skip(1).enumerate() {
        let cells: Vec<f64> = line.split(',').map(|c| c.parse().unwrap()).collect();
        assert_eq!(cells[1], library.mean[t], "mean at row {t}");
        assert_eq!(cells[2], library.sd[t], "sd at row {t}");
    }
}

#[test]
fn resid_of_a_model_file_equals_the_library() {
    use sysid::modelfile::ModelFile;
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let fitted = examples.join("models/cascaded_tanks_fitted.toml");
    let (u, y) = tanks_record("cascaded_tanks_val.csv");
    let series = sysid::smc::Series::new(&y, 1)
        .unwrap()
        .with_inputs(&u, 1)
        .unwrap();
    let library = ModelFile::read(&fitted)
        .unwrap()
        .residual_tests(series, 10, 500, 3)
        .unwrap();
    let summary = json_of(&sysid(&[
        "resid",
        "--model",
        s(&fitted),
        "--data",
        s(&examples.join("data/cascaded_tanks_val.csv")),
        "--lags",
        "10",
        "--particles",
        "500",
        "--seed",
        "3",
        "--json",
    ]));
    let text = summary.to_string();
    let q = library.outputs[0].ljung_box.statistic;
    assert!(text.contains(&format!("{q}")), "Q = {q} not in {text}");
    // the tanks' errors are correlated (the file's process noise is held small): the
    // advice is about the equations and the noise, not a linear model's order
    let warnings = summary["warnings"].to_string();
    assert!(
        warnings.contains("revise the equations") && !warnings.contains("higher order"),
        "{warnings}"
    );
}
