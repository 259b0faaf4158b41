//! `sysid pf` and `sysid psmooth`: runs, determinism across thread counts, the
//! linear model path against the exact log-likelihood, and one-line errors.

mod common;
use common::{assert_one_line_error, json_of, s, scratch_dir, sysid};

#[test]
fn pf_and_psmooth_on_nlbench_are_reproducible_across_thread_counts() {
    let dir = scratch_dir();
    let data = dir.join("nl.csv");
    assert!(
        sysid(&[
            "simulate",
            "nlbench",
            "--steps",
            "150",
            "--seed",
            "3",
            "--out",
            s(&data)
        ])
        .status
        .success()
    );
    let mut previous: Option<(serde_json::Value, String)> = None;
    for threads in ["1", "2", "4"] {
        let out = dir.join(format!("f{threads}.csv"));
        let run = json_of(&sysid(&[
            "pf",
            "--system",
            "nlbench",
            "--data",
            s(&data),
            "--particles",
            "3000",
            "--seed",
            "5",
            "--threads",
            threads,
            "--out",
            s(&out),
            "--json",
        ]));
        let text = std::fs::read_to_string(&out).unwrap();
        assert_eq!(text.lines().count(), 151);
        if let Some((first, first_text)) = &previous {
            assert_eq!(first["loglik"], run["loglik"]);
            assert_eq!(first_text, &text);
        }
        previous = Some((run, text));
    }
    for method in ["tanizaki", "ffbsi", "ffbsi-reject", "genealogy"] {
        // Tanizaki's smoother draws one path per particle
        let paths = if method == "tanizaki" { "100" } else { "70" };
        let mut outputs = Vec::new();
        for threads in ["1", "2"] {
            let out = dir.join(format!("{method}{threads}.csv"));
            let run = json_of(&sysid(&[
                "psmooth",
                "--system",
                "nlbench",
                "--data",
                s(&data),
                "--particles",
                "100",
                "--method",
                method,
                "--paths",
                paths,
                "--threads",
                threads,
                "--out",
                s(&out),
                "--json",
            ]));
            assert_eq!(run["method"], method);
            let text = std::fs::read_to_string(&out).unwrap();
            assert!(text.starts_with("t,x1,x1_sd\n"), "{method}");
            outputs.push(text);
        }
        assert_eq!(
            outputs[0], outputs[1],
            "{method}: thread count changed the result"
        );
    }
}

#[test]
fn pf_on_a_linear_model_file_is_close_to_the_exact_loglik() {
    let dir = scratch_dir();
    let (data, model) = (dir.join("l.csv"), dir.join("l.json"));
    assert!(
        sysid(&[
            "simulate",
            "lgss",
            "--steps",
            "200",
            "--out",
            s(&data),
            "--model-out",
            s(&model)
        ])
        .status
        .success()
    );
    let exact = json_of(&sysid(&[
        "loglik",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--json",
    ]));
    let pf = json_of(&sysid(&[
        "pf",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--particles",
        "20000",
        "--json",
    ]));
    let (a, b) = (
        exact["loglik"].as_f64().unwrap(),
        pf["loglik"].as_f64().unwrap(),
    );
    // M = 20000 on T = 200: the estimate's standard deviation is about 0.05.
    assert!((a - b).abs() < 0.3, "exact {a}, particle {b}");
}

#[test]
fn particle_commands_give_one_line_errors() {
    let dir = scratch_dir();
    let data = dir.join("nl.csv");
    assert!(
        sysid(&["simulate", "nlbench", "--steps", "20", "--out", s(&data)])
            .status
            .success()
    );
    let d = s(&data);
    assert_one_line_error(
        &sysid(&["pf", "--system", "nlbench", "--data", d, "--particles", "0"]),
        &["particles"],
    );
    assert_one_line_error(
        &sysid(&["pf", "--system", "nlbench", "--data", d, "--ess", "2"]),
        &["ess_threshold"],
    );
    assert_one_line_error(
        &sysid(&["pf", "--system", "foo", "--data", d]),
        &["unknown system", "foo"],
    );
    assert_one_line_error(
        &sysid(&["pf", "--system", "nlbench", "--data", d, "--resample", "x"]),
        &["--resample"],
    );
    assert_one_line_error(
        &sysid(&["pf", "--system", "nlbench", "--data", d, "--threads", "0"]),
        &["--threads"],
    );
    assert_one_line_error(
        &sysid(&[
            "psmooth", "--system", "nlbench", "--data", d, "--method", "y",
        ]),
        &["--method"],
    );
    assert_one_line_error(
        &sysid(&[
            "psmooth", "--system", "nlbench", "--data", d, "--paths", "0", "--method", "ffbsi",
        ]),
        &["paths"],
    );
    // lti2x2 has Q = 0: no transition density, so the adapter refuses it.
    let (lti_data, lti_model) = (dir.join("lti.csv"), dir.join("lti.json"));
    assert!(
        sysid(&[
            "simulate",
            "lti2x2",
            "--steps",
            "20",
            "--out",
            s(&lti_data),
            "--model-out",
            s(&lti_model)
        ])
        .status
        .success()
    );
    assert_one_line_error(
        &sysid(&["pf", "--model", s(&lti_model), "--data", s(&lti_data)]),
        &["--model", "positive definite"],
    );
    // An existing output is not replaced.
    let out = dir.join("f.csv");
    std::fs::write(&out, "keep").unwrap();
    assert_one_line_error(
        &sysid(&["pf", "--system", "nlbench", "--data", d, "--out", s(&out)]),
        &["--force"],
    );
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "keep");
}
