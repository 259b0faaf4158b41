//! `sysid pmmh` and `sysid pgas` end to end: the draws equal the library's bit for bit
//! and do not depend on --threads; PGAS lands near lgss's truth; bad options, priors and
//! starts give one-line errors and leave no file; `fit nlbench --method psaem` runs.

mod common;
use common::{assert_one_line_error, json_of, s, scratch_dir, simulate, sysid};
use sysid::models::{LgssConjugate, LgssFamily, System};
use sysid::pmcmc::{
    ChainRun, CsmcKernel, GibbsOptions, IndependentPrior, ModelFamily, particle_gibbs,
};
use sysid::smc::Series;

fn lgss_data(dir: &std::path::Path, steps: usize) -> (std::path::PathBuf, Vec<f64>) {
    let data = simulate(dir, "lgss", steps, 3);
    let sim = System::Lgss.simulate(steps, 3).unwrap();
    (data, sim.record.y.as_slice().to_vec())
}

#[test]
fn pgas_equals_the_library_for_any_thread_count_and_finds_the_truth() {
    let dir = scratch_dir();
    let (data, y) = lgss_data(&dir, 300);
    let run = |threads: &str, out: &std::path::Path| {
        sysid(&[
            "pgas",
            "--system",
            "lgss",
            "--data",
            s(&data),
            "--iters",
            "1500",
            "--chains",
            "3",
            "--seed",
            "5",
            "--threads",
            threads,
            "--out",
            s(out),
            "--json",
        ])
    };
    let (one, two) = (dir.join("one.csv"), dir.join("two.csv"));
    let summary = json_of(&run("1", &one));
    json_of(&run("2", &two));
    let text = std::fs::read_to_string(&one).unwrap();
    assert_eq!(text, std::fs::read_to_string(&two).unwrap());
    // the library with the CLI's default prior gives the same draws
    let family = LgssFamily::default();
    let priors = LgssFamily::DEFAULT_PRIORS.to_vec();
    let prior = IndependentPrior::new(&family.parameter_names(), priors.clone()).unwrap();
    let step = LgssConjugate {
        phi: priors[0],
        q: priors[1],
        r: priors[2],
    };
    let chains = particle_gibbs(
        &family,
        &prior,
        &step,
        &Series::new(&y, 1).unwrap(),
        &[0.5, 1.0, 1.0],
        &GibbsOptions {
            iterations: 1500,
            burn_in: 300,
            particles: 10,
            kernel: CsmcKernel::AncestorSampling,
        },
        &ChainRun::new(3, 5),
    )
    .unwrap();
    let last = text.lines().last().unwrap();
    let fields: Vec<f64> = last.split(',').map(|v| v.parse().unwrap()).collect();
    assert_eq!(&fields[3..6], chains[2].sample(1499), "CSV row vs library");
    // posterior means near the truth (phi 0.9, q 1, r 0.5) on 300 steps
    let means: Vec<f64> = summary["summary"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["mean"].as_f64().unwrap())
        .collect();
    for (m, truth) in means.iter().zip([0.9, 1.0, 0.5]) {
        assert!(
            (m - truth).abs() < 0.35 * truth,
            "posterior mean {m} vs {truth}"
        );
    }
}

#[test]
fn guided_pgas_runs_and_reports_every_step_renewed() {
    let dir = scratch_dir();
    let (data, _) = lgss_data(&dir, 200);
    let summary = json_of(&sysid(&[
        "pgas",
        "--system",
        "lgss",
        "--data",
        s(&data),
        "--iters",
        "400",
        "--chains",
        "2",
        "--guided",
        "--json",
    ]));
    let rate = summary["min_state_update_rate"].as_f64().unwrap();
    assert!(rate > 0.5, "guided PGAS lowest update rate {rate}");
}

#[test]
fn pmmh_runs_and_reports_acceptance_and_diagnostics() {
    let dir = scratch_dir();
    let (data, _) = lgss_data(&dir, 100);
    let summary = json_of(&sysid(&[
        "pmmh",
        "--system",
        "lgss",
        "--data",
        s(&data),
        "--iters",
        "600",
        "--chains",
        "2",
        "--particles",
        "50",
        "--json",
    ]));
    assert_eq!(summary["acceptance"].as_array().unwrap().len(), 2);
    // JSON draws, and no overwrite without --force (refused before running)
    let out = dir.join("chains.json");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "pmmh",
            "--system",
            "lgss",
            "--data",
            s(&data),
            "--iters",
            "50",
            "--chains",
            "2",
            "--particles",
            "20",
            "--out",
            s(&out),
        ];
        args.extend(extra);
        sysid(&args)
    };
    assert!(run(&[]).status.success());
    let chains: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let first = &chains["chains"][0];
    assert_eq!(first["samples"].as_array().unwrap().len(), 50 * 3);
    assert_eq!(first["names"][0], "phi");
    assert_one_line_error(&run(&[]), &["chains.json", "--force"]);
    assert!(run(&["--force"]).status.success());
    for p in summary["summary"].as_array().unwrap() {
        assert!(p["ess"].as_f64().unwrap() > 1.0 && p["rhat"].as_f64().unwrap().is_finite());
    }
}

#[test]
fn bad_pmcmc_input_gives_one_line_errors_and_no_file() {
    let dir = scratch_dir();
    let (data, _) = lgss_data(&dir, 50);
    let out = dir.join("chains.csv");
    let prior = dir.join("prior.json");
    let base = ["--system", "lgss", "--data", s(&data), "--out", s(&out)];
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (
            vec!["pmmh", "--iters", "10", "--burn-in", "10"],
            vec!["--burn-in", "leaves no draws"],
        ),
        (vec!["pmmh", "--chains", "0"], vec!["--chains"]),
        (
            vec!["pmmh", "--start", "0.5,1"],
            vec!["--start", "3 parameters"],
        ),
        (
            vec!["pmmh", "--start", "0.5,-1,1", "--iters", "10"],
            vec!["q = -1"],
        ),
        (
            vec!["pmmh", "--proposal-sd", "0.1,0,0.1", "--iters", "10"],
            vec!["proposal_sd"],
        ),
        (
            vec!["pgas", "--kernel", "xx"],
            vec!["--kernel", "as, bs, plain"],
        ),
        (
            vec!["pgas", "--particles", "1", "--iters", "10"],
            vec!["at least 2 particles"],
        ),
        (vec!["pgas", "--step", "gibbs"], vec!["--step"]),
        (
            vec!["pmmh", "--prior", s(&prior), "--iters", "10"],
            vec!["prior.json", "line 1"],
        ),
    ];
    std::fs::write(&prior, r#"{"q": {"family": "gamma", "shape": 1}}"#).unwrap();
    for (head, needles) in cases {
        let mut args = head.clone();
        args.extend(base);
        assert_one_line_error(&sysid(&args), &needles);
        assert!(!out.exists(), "{head:?} left a file");
    }
    let nl = simulate(&dir, "nlbench", 50, 1);
    assert_one_line_error(
        &sysid(&[
            "pgas",
            "--guided",
            "--system",
            "nlbench",
            "--data",
            s(&nl),
            "--out",
            s(&out),
        ]),
        &["--guided", "nlbench"],
    );
    std::fs::write(&prior, r#"{"sigma": {"family": "flat"}}"#).unwrap();
    let mut args = vec!["pmmh", "--prior", s(&prior)];
    args.extend(base);
    assert_one_line_error(&sysid(&args), &["unknown parameter \"sigma\"", "phi, q, r"]);
    std::fs::write(
        &prior,
        r#"{"q": {"family": "gamma", "shape": -1, "rate": 1}}"#,
    )
    .unwrap();
    assert_one_line_error(&sysid(&args), &["prior of `q`"]);
    let mut args = vec![
        "pgas",
        "--system",
        "lgss",
        "--data",
        s(&data),
        "--prior",
        s(&prior),
    ];
    std::fs::write(
        &prior,
        r#"{"q": {"family": "gamma", "shape": 2, "rate": 1}}"#,
    )
    .unwrap();
    args.extend(["--iters", "10"]);
    assert_one_line_error(&sysid(&args), &["conjugate", "--step mh"]);
}

#[test]
fn fit_nlbench_by_psaem_runs() {
    let dir = scratch_dir();
    let data = simulate(&dir, "nlbench", 200, 2);
    // `fit nlbench --method psaem` on the data with `extra` flags, writing `out`
    let psaem = |iters: &str, extra: &[&str], out: &std::path::Path| {
        let mut args = vec![
            "fit",
            "nlbench",
            "--method",
            "psaem",
            "--data",
            s(&data),
            "--iters",
            iters,
            "--particles",
            "15",
            "--out",
            s(out),
        ];
        args.extend(extra);
        sysid(&args)
    };
    let fit = dir.join("fit.json");
    let summary = json_of(&psaem("30", &["--json"], &fit));
    assert_eq!(summary["iterations"], 30);
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&fit).unwrap()).unwrap();
    assert_eq!(model["particle_em"]["method"], "psaem");
    // --estimate-noise=q frees q only, =r r only, bare both
    for (which, q_free, r_free) in [("=q", true, false), ("=r", false, true), ("", true, true)] {
        let out = dir.join(format!("noise{which}.json"));
        let flag = format!("--estimate-noise{which}");
        let result = psaem("5", &[&flag], &out);
        assert!(
            result.status.success(),
            "{}",
            String::from_utf8_lossy(&result.stderr)
        );
        let model: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        let (q, r) = (model["q"].as_f64(), model["r"].as_f64());
        assert_eq!(q != Some(0.01), q_free, "{flag}: q {q:?}");
        assert_eq!(r != Some(0.1), r_free, "{flag}: r {r:?}");
    }
    assert_one_line_error(
        &sysid(&[
            "fit",
            "nlbench",
            "--method",
            "mcmc",
            "--data",
            s(&data),
            "--out",
            s(&dir.join("x.json")),
        ]),
        &["--method", "em, psaem"],
    );
}

/// Particle Gibbs on nlbench moves every parameter (its conjugate step draws them
/// exactly given the states; the random-walk step was rejected at every iteration and
/// the draws never changed), and lands near the truth; `--step mh` still runs, and a
/// sampler that did not move a parameter says so.
#[test]
fn pgas_on_nlbench_moves_every_parameter() {
    let dir = scratch_dir();
    let data = simulate(&dir, "nlbench", 500, 4);
    let run = |step: &str| {
        json_of(&sysid(&[
            "pgas",
            "--system",
            "nlbench",
            "--data",
            s(&data),
            "--iters",
            "600",
            "--particles",
            "30",
            "--chains",
            "2",
            "--step",
            step,
            "--json",
        ]))
    };
    let v = run("conjugate");
    let truth = [0.5, 25.0, 8.0, 0.05];
    for (k, p) in v["summary"].as_array().unwrap().iter().enumerate() {
        let (mean, sd) = (p["mean"].as_f64().unwrap(), p["sd"].as_f64().unwrap());
        assert!(
            sd > 0.0 && p["ess_bulk"].as_f64().is_some_and(f64::is_finite),
            "{p}"
        );
        // the chains start at the truth; the posterior stays within a few percent
        assert!((mean / truth[k] - 1.0).abs() < 0.05, "{p}");
    }
    let mh = run("mh");
    assert!(
        mh["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("never changed")),
        "{mh}"
    );
}

/// Ctrl-C inside the burn-in: the chains made so far are written, the report says how
/// many iterations ran and that there are no draws to summarise (no table of NaN).
#[test]
fn a_sampler_interrupted_in_its_burn_in_says_so_instead_of_a_table_of_nan() {
    let dir = scratch_dir();
    let data = simulate(&dir, "lgss", 200, 1);
    let chains = dir.join("chains.csv");
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args([
            "pmmh",
            "--system",
            "lgss",
            "--data",
            s(&data),
            "--iters",
            "1000000",
            "--chains",
            "2",
            "--out",
            s(&chains),
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let killed = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let out = child.wait_with_output().unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert_eq!(out.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("no draws to summarise"), "{stderr}");
    assert!(
        stdout.contains("of 1000000 iterations (interrupted)"),
        "{stdout}"
    );
    assert!(!stdout.contains("NaN"), "{stdout}");
    assert!(chains.exists());
}
