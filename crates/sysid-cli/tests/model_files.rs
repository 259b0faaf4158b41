//! Nonlinear model files through the binary: the whole loop (simulate -> fit -> pf ->
//! psmooth -> pmmh -> plot) on a file's model and its fitted copy, and the errors.

mod common;
use common::{assert_one_line_error, s, scratch_dir, sysid};
use std::path::{Path, PathBuf};

fn ok(args: &[&str]) -> String {
    let out = sysid(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn json(args: &[&str]) -> serde_json::Value {
    let text = ok(args);
    serde_json::from_str(text.lines().last().unwrap()).unwrap()
}

/// A model of the user's own (not a built-in): a Duffing-like oscillator observed
/// through a saturating sensor, affine in k and c.
const OSCILLATOR: &str = r#"format = 1
states = ["p", "v"]
outputs = ["y"]

[parameters]
k = { value = 0.8, prior = { family = "normal", mean = 0.0, sd = 10.0 } }
c = { value = 0.3, prior = { family = "normal", mean = 0.0, sd = 10.0 } }
dt = 0.1
r = { value = 0.01, fixed = true }

[transition]
p = "p + dt*v"
v = "v - dt*(k*p^3 + c*v) + dt*cos(0.3*t)"

[observation]
y = "tanh(p)"

[noise]
p = 1e-4
v = 1e-3
y = "r"

[initial]
p = { mean = 0.5, variance = 0.01 }
v = { mean = 0, variance = 0.01 }
"#;

/// The oscillator written as `osc.toml` in `dir` and a record of it, `osc.csv`, of
/// `steps` steps (with the true states when `states`).
fn oscillator_record(dir: &Path, steps: usize, states: bool) -> (PathBuf, PathBuf) {
    let model = dir.join("osc.toml");
    std::fs::write(&model, OSCILLATOR).unwrap();
    let data = dir.join("osc.csv");
    let steps = steps.to_string();
    let mut args = vec!["simulate", "--model", s(&model), "--steps", &steps];
    if states {
        args.push("--states");
    }
    args.extend(["--out", s(&data)]);
    ok(&args);
    (model, data)
}

#[test]
fn a_model_file_goes_through_every_nonlinear_command() {
    let dir = scratch_dir();
    let (model, data) = oscillator_record(&dir, 300, true);
    let header = std::fs::read_to_string(&data).unwrap();
    assert!(header.starts_with("t,y,p,v\n"), "{}", &header[..40]);

    // fit (affine in k, c: closed-form particle EM), written back as a model file
    let fitted = dir.join("fit.toml");
    let trace = dir.join("trace.csv");
    let report = json(&[
        "fit",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--method",
        "em",
        "--max-iter",
        "30",
        "--particles",
        "100",
        "--out",
        s(&fitted),
        "--trace",
        s(&trace),
        "--json",
    ]);
    assert!(report["likelihood_decreases"].as_u64().is_some());
    let text = std::fs::read_to_string(&fitted).unwrap();
    let back = sysid::modelfile::ModelFile::parse(&text, "fit.toml").unwrap();
    assert_eq!(back.free_names(), ["k", "c"]);
    let theta = back.free_values();
    // the data came from k = 0.8, c = 0.3 (started there: EM stays near)
    assert!(
        (theta[0] - 0.8).abs() < 0.2 && (theta[1] - 0.3).abs() < 0.2,
        "{theta:?}"
    );
    assert!(
        std::fs::read_to_string(&trace)
            .unwrap()
            .starts_with("iteration,loglik,k,c\n")
    );

    // the fitted file runs everywhere
    let pf = json(&[
        "pf",
        "--model",
        s(&fitted),
        "--data",
        s(&data),
        "--particles",
        "500",
        "--json",
    ]);
    assert!(pf["loglik"].as_f64().unwrap().is_finite());
    let states = dir.join("states.csv");
    ok(&[
        "psmooth",
        "--model",
        s(&fitted),
        "--data",
        s(&data),
        "--particles",
        "300",
        "--out",
        s(&states),
    ]);
    assert!(
        std::fs::read_to_string(&states)
            .unwrap()
            .starts_with("t,p,v,p_sd,v_sd\n")
    );
    let chains = dir.join("chains.csv");
    let pmmh = json(&[
        "pmmh",
        "--model",
        s(&fitted),
        "--data",
        s(&data),
        "--iters",
        "300",
        "--chains",
        "2",
        "--particles",
        "50",
        "--out",
        s(&chains),
        "--json",
    ]);
    assert_eq!(pmmh["summary"].as_array().unwrap().len(), 2);
    ok(&["plot", s(&states), "--out-dir", s(&dir.join("figs"))]);
}

/// `pgas --model` draws the parameters of a file affine in them exactly given the
/// states (the default where it applies), and says when it falls back to the
/// random-walk step.
#[test]
fn pgas_draws_an_affine_model_files_parameters_exactly() {
    let dir = scratch_dir();
    let (model, data) = oscillator_record(&dir, 200, false);
    let run = |model: &std::path::Path, step: Option<&str>| {
        let mut args = vec![
            "pgas",
            "--model",
            s(model),
            "--data",
            s(&data),
            "--iters",
            "300",
            "--particles",
            "20",
            "--chains",
            "2",
            "--json",
        ];
        if let Some(step) = step {
            args.extend(["--step", step]);
        }
        sysid(&args)
    };
    let summary = |out: &std::process::Output| -> serde_json::Value {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value =
            serde_json::from_str(String::from_utf8_lossy(&out.stdout).lines().last().unwrap())
                .unwrap();
        v["summary"].clone()
    };
    let default = summary(&run(&model, None));
    assert_eq!(default, summary(&run(&model, Some("conjugate"))));
    assert_ne!(default, summary(&run(&model, Some("mh"))));
    // k*c is not affine: the default falls back and says so; asking for it is an error
    let product = dir.join("product.toml");
    std::fs::write(&product, OSCILLATOR.replace("c*v", "k*c*v")).unwrap();
    let out = run(&product, None);
    summary(&out);
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("random-walk parameter step"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_one_line_error(&run(&product, Some("conjugate")), &["--step", "not affine"]);
    assert_one_line_error(&run(&model, Some("gibbs")), &["--step", "unknown step"]);
}

#[test]
fn a_non_affine_model_file_is_fitted_directly_or_by_gradient_em() {
    let dir = scratch_dir();
    let model = dir.join("osc.toml");
    // k*c: a product of parameters
    std::fs::write(&model, OSCILLATOR.replace("c*v", "k*c*v")).unwrap();
    let data = dir.join("osc.csv");
    ok(&[
        "simulate",
        "--model",
        s(&model),
        "--steps",
        "200",
        "--out",
        s(&data),
    ]);
    let fitted = dir.join("fit.toml");
    let fit = |extra: &[&str]| {
        let mut args = vec![
            "fit",
            "--model",
            s(&model),
            "--data",
            s(&data),
            "--out",
            s(&fitted),
            "--force",
            "--json",
        ];
        args.extend_from_slice(extra);
        json(&args)
    };
    // the default: the likelihood maximised from several starts, with standard errors
    let report = fit(&["--starts", "3"]);
    assert_eq!(report["method"], "direct");
    assert_eq!(report["starts"].as_array().unwrap().len(), 3);
    assert_eq!(report["starts"][1]["origin"], "simulation-error fit");
    let written = sysid::modelfile::ModelFile::read(&fitted).unwrap();
    let se = &report["standard_errors"];
    for (name, value) in written.free_names().iter().zip(written.free_values()) {
        assert_eq!(report["estimate"][name].as_f64(), Some(value));
        assert!(se[name].as_f64().is_some_and(|v| v > 0.0), "{report}");
    }
    // --method em: gradient EM from the file's values
    let report = fit(&["--method", "em", "--max-iter", "8", "--particles", "50"]);
    assert_eq!(report["method"], "gradient-em");
    assert!(sysid::modelfile::ModelFile::read(&fitted).is_ok());
}

#[test]
fn model_file_mistakes_are_one_line_errors_with_line_and_column() {
    let dir = scratch_dir();
    let data = dir.join("nl.csv");
    ok(&["simulate", "nlbench", "--steps", "50", "--out", s(&data)]);
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, OSCILLATOR.replace("k*p^3", "k*q^3")).unwrap();
    for command in ["pf", "psmooth", "pmmh"] {
        let out = sysid(&[command, "--model", s(&bad), "--data", s(&data)]);
        assert_one_line_error(&out, &["bad.toml:13:16:", "unknown name \"q\""]);
    }
    let out = sysid(&[
        "fit",
        "--model",
        s(&bad),
        "--data",
        s(&data),
        "--out",
        s(&dir.join("f.toml")),
    ]);
    assert_one_line_error(&out, &["bad.toml:13:16:"]);

    // a flag of linear fits
    let model = dir.join("osc.toml");
    std::fs::write(&model, OSCILLATOR).unwrap();
    let out = sysid(&[
        "fit",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--order",
        "2",
        "--out",
        s(&dir.join("f.toml")),
    ]);
    assert_one_line_error(&out, &["--order", "does not apply to a model file"]);

    // a free parameter without a prior
    let no_prior = dir.join("no_prior.toml");
    std::fs::write(
        &no_prior,
        OSCILLATOR.replace(
            ", prior = { family = \"normal\", mean = 0.0, sd = 10.0 }",
            "",
        ),
    )
    .unwrap();
    let out = sysid(&[
        "pmmh",
        "--model",
        s(&no_prior),
        "--data",
        s(&data),
        "--iters",
        "10",
    ]);
    assert_one_line_error(&out, &["--prior", "k has no prior"]);

    // an unknown built-in names the known ones
    let out = sysid(&["pf", "--system", "duffing", "--data", s(&data)]);
    assert_one_line_error(
        &out,
        &["unknown system \"duffing\"", "lgss, nlbench, pendulum"],
    );
}

/// `fit` refuses an option its model class does not use, naming the classes that do
/// (such options used to be ignored in silence).
#[test]
fn fit_refuses_the_options_of_other_model_classes() {
    let dir = scratch_dir();
    let data = dir.join("nl.csv");
    ok(&["simulate", "nlbench", "--steps", "50", "--out", s(&data)]);
    let out_file = dir.join("f.json");
    let cases: [(&[&str], &[&str]); 4] = [
        (
            &["lti", "--particles", "50"],
            &["--particles", "does not apply to fit lti", "fit nlbench"],
        ),
        (
            &["nlbench", "--order", "2"],
            &["--order", "does not apply to fit nlbench", "fit lti"],
        ),
        (
            &["wiener", "--method", "em"],
            &["--method", "does not apply to fit wiener"],
        ),
        (
            &["lti", "--estimate-noise"],
            &["--estimate-noise", "fit nlbench, fit affine"],
        ),
    ];
    for (args, needles) in cases {
        let mut all = vec!["fit"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["--data", s(&data), "--out", s(&out_file)]);
        assert_one_line_error(&sysid(&all), needles);
        assert!(!out_file.exists());
    }
}

/// Ctrl-C (SIGINT) during a long fit or chain: the result so far is written, marked
/// as interrupted, and the exit code is 130; a command that cannot keep a partial
/// result stops at once and leaves no output.
#[cfg(unix)]
#[test]
fn ctrl_c_keeps_what_a_long_run_has() {
    let dir = scratch_dir();
    let data = dir.join("nl.csv");
    ok(&["simulate", "nlbench", "--steps", "200", "--out", s(&data)]);
    let model = dir.join("nlbench.toml");
    std::fs::write(&model, sysid::modelfile::builtin::text("nlbench").unwrap()).unwrap();
    let interrupt =
        |args: &[&str]| common::interrupted_after(args, std::time::Duration::from_millis(1500)).0;
    let fitted = dir.join("fit.toml");
    let out = interrupt(&[
        "fit",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--method",
        "em",
        "--max-iter",
        "10000000",
        "--particles",
        "20",
        "--out",
        s(&fitted),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{stderr}");
    assert!(
        stderr.contains("interrupted (Ctrl-C) after iteration"),
        "{stderr}"
    );
    let text = std::fs::read_to_string(&fitted).unwrap();
    assert!(text.contains("interrupted = true"), "{text}");
    assert!(sysid::modelfile::ModelFile::parse(&text, "fit.toml").is_ok());

    let chains = dir.join("chains.csv");
    let out = interrupt(&[
        "pmmh",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--iters",
        "1000000",
        "--chains",
        "2",
        "--particles",
        "20",
        "--out",
        s(&chains),
    ]);
    assert_eq!(
        out.status.code(),
        Some(130),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(std::fs::read_to_string(&chains).unwrap().lines().count() > 10);

    // fit lti (plain EM, no tolerance to stop it) and robust particle EM keep their
    // estimate too
    let lti_data = dir.join("d.csv");
    ok(&[
        "simulate",
        "lti2x2",
        "--steps",
        "300",
        "--out",
        s(&lti_data),
    ]);
    let lti = dir.join("lti.json");
    let trace = dir.join("trace.csv");
    let out = interrupt(&[
        "fit",
        "lti",
        "--data",
        s(&lti_data),
        "--order",
        "8",
        "--accelerate",
        "none",
        "--polish",
        "off",
        "--tol",
        "0",
        "--max-iter",
        "100000000",
        "--out",
        s(&lti),
        "--trace",
        s(&trace),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{stderr}");
    let text = std::fs::read_to_string(&lti).unwrap();
    assert!(text.contains("\"termination\": \"interrupted\""), "{text}");
    assert!(std::fs::read_to_string(&trace).unwrap().lines().count() > 10);
    let robust = dir.join("robust.json");
    let out = interrupt(&[
        "fit",
        "nlbench",
        "--data",
        s(&data),
        "--max-iter",
        "100000000",
        "--out",
        s(&robust),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("interrupted after"), "{stderr}");
    let text = std::fs::read_to_string(&robust).unwrap();
    assert!(text.contains("\"interrupted\": true"), "{text}");

    let states = dir.join("states.csv");
    let out = interrupt(&[
        "pf",
        "--system",
        "nlbench",
        "--data",
        s(&data),
        "--particles",
        "2000000",
        "--out",
        s(&states),
    ]);
    assert_eq!(out.status.code(), Some(130));
    assert!(!states.exists());
}

/// `--extrapolate off` reaches the robust driver: its refinement tries no jump, where
/// the default tries one every 25 iterations from the second block on (in the first
/// three quarters).
#[test]
fn extrapolate_off_runs_plain_em_in_the_refinement() {
    let dir = scratch_dir();
    let (model, data) = oscillator_record(&dir, 150, false);
    let jumps = |extrapolate: Option<&str>| {
        let out = dir.join("fit.toml");
        let mut args = vec![
            "fit",
            "--model",
            s(&model),
            "--data",
            s(&data),
            "--starts",
            "1",
            "--max-iter",
            "80",
            "--particles",
            "50",
            "--out",
            s(&out),
            "--force",
            "--json",
        ];
        if let Some(x) = extrapolate {
            args.extend(["--extrapolate", x]);
        }
        let report = json(&args);
        report["refinement"]["jumps_tried"].as_u64().unwrap()
    };
    assert_eq!(jumps(Some("off")), 0);
    // the first drift is measured between the blocks ending at 25 and 50, so one jump
    // is due in the first 60 of 80 iterations
    assert_eq!(jumps(None), 1);
}

/// `sysid fit CLASS --help` lists the options that class takes, and no other class's.
#[test]
fn each_fit_class_help_lists_only_its_own_options() {
    let options = |args: &[&str]| -> Vec<String> {
        let out = sysid(args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter_map(|l| l.trim_start().strip_prefix("--"))
            .map(|l| l.split([' ', '[', '=']).next().unwrap().to_string())
            .collect()
    };
    let has = |list: &[String], flags: &[&str], yes: bool, class: &str| {
        for flag in flags {
            assert_eq!(list.iter().any(|f| f == flag), yes, "fit {class}: --{flag}");
        }
    };
    let particle = [
        "particles",
        "smoother",
        "method",
        "starts",
        "estimate-noise",
        "system",
        "extrapolate",
    ];
    let linear = [
        "order", "fix", "diag", "detrend", "split", "polish", "tol-nats", "full-r",
    ];
    let lti = options(&["fit", "lti", "--help"]);
    has(&lti, &linear, true, "lti");
    has(&lti, &particle, false, "lti");
    has(&lti, &["model", "seed"], false, "lti");
    let nlbench = options(&["fit", "nlbench", "--help"]);
    has(
        &nlbench,
        &[
            "particles",
            "smoother",
            "method",
            "starts",
            "estimate-noise",
            "init",
            "seed",
        ],
        true,
        "nlbench",
    );
    has(&nlbench, &linear, false, "nlbench");
    has(&nlbench, &["system", "model"], false, "nlbench");
    let affine = options(&["fit", "affine", "--help"]);
    has(&affine, &["system", "init", "particles"], true, "affine");
    has(&affine, &linear, false, "affine");
    let wiener = options(&["fit", "wiener", "--help"]);
    has(&wiener, &["particles", "seed", "max-iter"], true, "wiener");
    has(
        &wiener,
        &["method", "smoother", "starts", "init", "system"],
        false,
        "wiener",
    );
    has(&wiener, &linear, false, "wiener");
}

/// psmooth and pf name a model file's states as the file does (and as `simulate
/// --model --states` writes them), so `plot --truth` draws the true states.
#[test]
fn smoothed_states_keep_the_model_s_names_and_plot_draws_their_truth() {
    let dir = scratch_dir();
    let (model, data) = oscillator_record(&dir, 200, true);
    let (smoothed, filtered) = (dir.join("sm.csv"), dir.join("pf.csv"));
    let truth_header = std::fs::read_to_string(&data).unwrap();
    let truth_header = truth_header.lines().next().unwrap().to_string();
    ok(&[
        "psmooth",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--particles",
        "200",
        "--out",
        s(&smoothed),
    ]);
    ok(&[
        "pf",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--particles",
        "200",
        "--out",
        s(&filtered),
    ]);
    let header = |p: &std::path::Path| {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .next()
            .unwrap()
            .to_string()
    };
    let states: Vec<String> = truth_header.split(',').skip(2).map(String::from).collect();
    assert_eq!(states.len(), 2, "{truth_header}");
    assert_eq!(
        header(&smoothed),
        format!("t,{0},{1},{0}_sd,{1}_sd", states[0], states[1])
    );
    assert_eq!(header(&filtered), format!("t,{},{}", states[0], states[1]));
    let figures = dir.join("figs");
    ok(&[
        "plot",
        s(&smoothed),
        "--truth",
        s(&data),
        "--out-dir",
        s(&figures),
    ]);
    let svg = std::fs::read_to_string(figures.join("sm-states.svg")).unwrap();
    assert_eq!(
        svg.matches("true state").count(),
        2,
        "one truth per state panel"
    );
}

/// A bad cell in a column the model file names is reported as the cell it is (file,
/// line, column), not as a file without input or output columns.
#[test]
fn a_bad_cell_in_a_named_column_is_named() {
    let dir = scratch_dir();
    let (model, data) = oscillator_record(&dir, 20, false);
    let text = std::fs::read_to_string(&data).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let mut cells: Vec<&str> = lines[5].split(',').collect();
    *cells.last_mut().unwrap() = "abc";
    lines[5] = cells.join(",");
    std::fs::write(&data, lines.join("\n") + "\n").unwrap();
    for command in ["pf", "psmooth", "pmmh"] {
        let out = sysid(&[command, "--model", s(&model), "--data", s(&data)]);
        assert_one_line_error(&out, &["osc.csv, line 6, column y", "cannot read \"abc\""]);
    }
}

#[test]
fn long_fits_say_how_far_they_got_in_a_log() {
    // stderr is a pipe here, as in a batch job: no bar, plain lines at the interval
    // (SYSID_PROGRESS_SECONDS, 30 s by default; 0 here: a line at every tick)
    let dir = scratch_dir();
    let (model, data) = oscillator_record(&dir, 100, false);
    let fit = |method: &str, model_text: &str, interval: &str| {
        std::fs::write(&model, model_text).unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_sysid"))
            .args([
                "fit",
                "--model",
                s(&model),
                "--data",
                s(&data),
                "--method",
                method,
                "--max-iter",
                "4",
                "--particles",
                "20",
                "--force",
                "--out",
            ])
            .arg(dir.join("fit.toml"))
            // only the robust driver explores starts (the others refuse --starts)
            .args(if method == "robust" {
                &["--starts", "2"][..]
            } else {
                &[]
            })
            .env("SYSID_PROGRESS_SECONDS", interval)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let em = fit("em", OSCILLATOR, "0");
    assert!(em.contains("sysid: tanizaki: 1/4 loglik"), "{em}");
    assert!(em.contains("sysid: tanizaki: 4/4 loglik"), "{em}");
    let robust = fit("robust", OSCILLATOR, "0");
    assert!(
        robust.contains("sysid: robust particle EM: running ("),
        "{robust}"
    );
    let gradient = fit("em", &OSCILLATOR.replace("c*v", "k*c*v"), "0");
    assert!(gradient.contains("sysid: gradient EM: 1/4"), "{gradient}");
    // at the default interval a short fit prints no progress line
    let quiet = fit("em", OSCILLATOR, "30");
    assert!(!quiet.contains("tanizaki:"), "{quiet}");
}
