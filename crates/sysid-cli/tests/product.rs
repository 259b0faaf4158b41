//! The product commands: `demo`, `filter`, `plot`, `bench`, and the shared flags.

mod common;

use common::{assert_ok, assert_one_line_error, json_of, s, scratch_dir, simulate, sysid};
use std::path::Path;

const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];

/// A PNG's width and height from its IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(bytes[..8], PNG_SIGNATURE, "{} is not a PNG", path.display());
    let be = |i: usize| u32::from_be_bytes(bytes[i..i + 4].try_into().unwrap());
    (be(16), be(20))
}

/// Asserts that `<dir>/<stem>.svg` has every label and `<stem>.png` is a real image.
fn assert_figure(dir: &Path, stem: &str, labels: &[&str]) {
    let svg = std::fs::read_to_string(dir.join(format!("{stem}.svg"))).unwrap();
    for label in labels {
        assert!(svg.contains(label), "{stem}.svg lacks {label:?}");
    }
    let (w, h) = png_size(&dir.join(format!("{stem}.png")));
    assert!(w >= 400 && h >= 300, "{stem}.png is {w}x{h}");
}

#[test]
fn demo_prints_the_table_and_draws_the_five_figures() {
    let dir = scratch_dir();
    let figures = dir.join("figures");
    let out = sysid(&[
        "demo",
        "--runs",
        "2",
        "--iters",
        "3",
        "--out-dir",
        s(&figures),
        "--json",
    ]);
    let v = json_of(&out);
    let models = v["lti2x2"]["models"].as_array().unwrap();
    let row = |name: &str| models.iter().find(|m| m["model"] == name).unwrap();
    let truth = row("truth")["loglik"].as_f64().unwrap();
    // EM ends at or above the truth's likelihood (seed-004 criterion) and above N4SID
    let em = row("EM from N4SID")["loglik"].as_f64().unwrap();
    assert!(
        em >= truth && em >= row("N4SID (order 8)")["loglik"].as_f64().unwrap(),
        "{v}"
    );
    assert!(
        row("EM from N4SID")["response_error"].as_f64().unwrap() < 0.2,
        "{v}"
    );
    assert_eq!(v["nlbench_em"]["runs"], 2);
    assert_eq!(v["nlbench_em"]["iterations"], 3);
    assert_figure(
        &figures,
        "em-trajectories",
        &[
            "paper EM: a",
            "paper EM: d",
            "EM iteration",
            "true b = 25",
            "runs (one line each, 2)",
        ],
    );
    assert_figure(
        &figures,
        "em-trajectories-robust",
        &["robust EM: a", "refinement iteration", "true d = 0.05"],
    );
    let methods = v["nlbench_em"]["methods"].as_array().unwrap();
    assert_eq!(methods[0]["method"], "paper");
    assert_eq!(methods[1]["method"], "robust");
    assert!(
        v["nlbench_em"]["take_away"]
            .as_str()
            .unwrap()
            .contains("sysid fit nlbench")
    );
    assert_figure(
        &figures,
        "bode",
        &[
            "G11 (u1 to y1): magnitude",
            "G22 (u2 to y2): phase",
            "frequency (rad/sample)",
            "magnitude (dB)",
            "phase (degrees)",
            "truth",
            "N4SID (order 8)",
            "EM from N4SID",
        ],
    );
    assert_figure(
        &figures,
        "smoothed-state",
        &[
            "95 % smoothing band",
            "true state",
            "smoothed mean",
            "time step t",
            "steps 1-100 of 500",
        ],
    );
    assert_figure(
        &figures,
        "loglik-trace",
        &[
            "log-likelihood",
            "lti2x2: exact EM",
            "EM runs (one line each)",
        ],
    );
    // no round-off residue among the tick labels of the five figures
    assert_eq!(common::assert_clean_figures(&figures), 5);
    // the directory was given: a second run refuses to replace the figures
    let again = sysid(&[
        "demo",
        "--runs",
        "1",
        "--iters",
        "1",
        "--out-dir",
        s(&figures),
    ]);
    assert_one_line_error(&again, &["em-trajectories.svg", "--force"]);
    // the text table names every model
    let text = sysid(&[
        "demo",
        "--runs",
        "1",
        "--iters",
        "1",
        "--out-dir",
        s(&figures),
        "--force",
        "--quiet",
    ]);
    let table = String::from_utf8_lossy(&text.stdout);
    for needle in [
        "paper's initial model",
        "EM from N4SID",
        "within 10%",
        "take away: fit with the default `sysid fit nlbench` (robust)",
        "bode.png",
    ] {
        assert!(table.contains(needle), "{needle:?} missing from\n{table}");
    }
}

#[test]
fn filter_ends_where_the_smoother_ends_and_both_plot() {
    let dir = scratch_dir();
    let (data, model) = (dir.join("lgss.csv"), dir.join("lgss.json"));
    let out = sysid(&[
        "simulate",
        "lgss",
        "--steps",
        "60",
        "--seed",
        "3",
        "--states",
        "--out",
        s(&data),
        "--model-out",
        s(&model),
    ]);
    assert_ok(&out);
    let (filtered, smoothed) = (dir.join("f.csv"), dir.join("s.csv"));
    let f = json_of(&sysid(&[
        "filter",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--out",
        s(&filtered),
        "--json",
    ]));
    let sm = json_of(&sysid(&[
        "smooth",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--out",
        s(&smoothed),
        "--json",
    ]));
    assert_eq!(f["loglik"], sm["loglik"]);
    let read = |p: &Path| std::fs::read_to_string(p).unwrap();
    let (ft, st) = (read(&filtered), read(&smoothed));
    assert_eq!(ft.lines().next(), Some("t,x1,x1_sd"));
    // at the last step the filter and the smoother condition on the same data
    let last = |text: &str| -> Vec<f64> {
        text.lines()
            .last()
            .unwrap()
            .split(',')
            .map(|v| v.parse().unwrap())
            .collect()
    };
    let (fl, sl) = (last(&ft), last(&st));
    assert!(
        (fl[1] - sl[1]).abs() < 1e-12 && (fl[2] - sl[2]).abs() < 1e-12,
        "{fl:?} {sl:?}"
    );
    // earlier, smoothing uses more data: smaller standard deviations on average
    let mean_sd = |text: &str| -> f64 {
        let v: Vec<f64> = text
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    assert!(mean_sd(&st) < mean_sd(&ft));
    let figures = dir.join("fig");
    let p = json_of(&sysid(&[
        "plot",
        s(&smoothed),
        "--truth",
        s(&data),
        "--out-dir",
        s(&figures),
        "--json",
    ]));
    assert_eq!(p["figures"].as_array().unwrap().len(), 2);
    assert_figure(
        &figures,
        "s-states",
        &["state x1", "95 % band", "estimate", "true state"],
    );
}

#[test]
fn plot_draws_traces_models_and_data() {
    let dir = scratch_dir();
    let data = simulate(&dir, "lti2x2", 300, 5);
    let (fit, trace, n4) = (
        dir.join("fit.json"),
        dir.join("trace.csv"),
        dir.join("n4sid.json"),
    );
    let out = sysid(&["n4sid", "--data", s(&data), "--order", "4", "--out", s(&n4)]);
    assert_ok(&out);
    let out = sysid(&[
        "fit",
        "lti",
        "--data",
        s(&data),
        "--order",
        "4",
        "--max-iter",
        "5",
        "--out",
        s(&fit),
        "--trace",
        s(&trace),
    ]);
    assert_ok(&out);
    let figures = dir.join("fig");
    let v = json_of(&sysid(&[
        "plot",
        s(&trace),
        s(&n4),
        s(&fit),
        s(&data),
        "--out-dir",
        s(&figures),
        "--json",
    ]));
    assert_eq!(v["figures"].as_array().unwrap().len(), 6, "{v}");
    assert_figure(&figures, "trace-trace", &["log-likelihood", "EM iteration"]);
    assert_figure(
        &figures,
        "bode",
        &[
            "G12 (u2 to y1): magnitude",
            "G12 (u2 to y1): phase",
            "phase (degrees)",
            "n4sid",
            "fit",
            "magnitude (dB)",
        ],
    );
    assert_figure(&figures, "lti2x2-data", &["u1", "y2"]);
    // existing figures are refused, then replaced with --force
    let again = sysid(&["plot", s(&trace), "--out-dir", s(&figures)]);
    assert_one_line_error(&again, &["trace-trace.svg", "--force"]);
    assert!(
        sysid(&["plot", s(&trace), "--out-dir", s(&figures), "--force"])
            .status
            .success()
    );
    // a file that is not numeric names its line and column
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, "t,y1\n1,0.5\n2,oops\n").unwrap();
    assert_one_line_error(
        &sysid(&["plot", s(&bad), "--out-dir", s(&figures)]),
        &["bad.csv", "line 3", "y1", "oops"],
    );
    assert_one_line_error(
        &sysid(&["plot", s(&trace), "--kind", "pie"]),
        &["--kind", "pie"],
    );
    // nothing half-written was left behind
    let leftovers: Vec<String> = std::fs::read_dir(&figures)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp-"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn bench_runs_a_runner_through_the_command_line() {
    let out = sysid(&["bench", "em", "--reps", "1"]);
    assert_ok(&out);
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let iteration = lines.iter().find(|l| l["task"] == "em_iteration").unwrap();
    assert!(iteration["ms_median"].as_f64().unwrap() > 0.0);
    assert!(lines.iter().any(|l| l["task"] == "em_summary"));
    assert_one_line_error(
        &sysid(&["bench", "report", "--scale", "huge"]),
        &["--scale", "huge"],
    );
}

#[test]
fn threads_zero_is_refused_and_help_has_examples() {
    assert_one_line_error(
        &sysid(&[
            "--threads",
            "0",
            "pf",
            "--system",
            "lgss",
            "--data",
            "x.csv",
        ]),
        &["--threads"],
    );
    for command in [
        "demo", "simulate", "n4sid", "fit", "loglik", "filter", "smooth", "pf", "psmooth", "pmmh",
        "pgas", "plot", "bench",
    ] {
        let out = sysid(&[command, "--help"]);
        let help = String::from_utf8_lossy(&out.stdout);
        assert!(
            help.contains("Examples:") && help.contains(&format!("sysid {command}")),
            "{command} --help:\n{help}"
        );
    }
}

/// A chain file of `pmmh` is plotted as chains: one panel per parameter and the
/// log-likelihood, one line per chain, not `chain`, `iteration` and `burn_in` as data.
#[test]
fn plot_recognises_a_chain_file() {
    let dir = scratch_dir();
    let data = simulate(&dir, "lgss", 200, 3);
    let chains = dir.join("chains.csv");
    assert_ok(&sysid(&[
        "pmmh",
        "--system",
        "lgss",
        "--data",
        s(&data),
        "--iters",
        "300",
        "--particles",
        "30",
        "--chains",
        "2",
        "--out",
        s(&chains),
        "--quiet",
    ]));
    let figures = dir.join("figures");
    assert_ok(&sysid(&["plot", s(&chains), "--out-dir", s(&figures)]));
    let svg = std::fs::read_to_string(figures.join("chains-chains.svg")).unwrap();
    let texts = common::svg_texts(&svg);
    for expected in [
        "phi (burn-in before iteration 60, faint)",
        "q (burn-in before iteration 60, faint)",
        "loglik (burn-in before iteration 60, faint)",
        "chain 0",
        "chain 1",
        "iteration",
    ] {
        assert!(
            texts.iter().any(|t| t == expected),
            "{expected:?} in {texts:?}"
        );
    }
    for absent in ["burn_in", "chain", "accepted", "log_prior"] {
        assert!(
            !texts
                .iter()
                .any(|t| t.starts_with(absent) && !t.starts_with("chain ")),
            "{absent:?} in {texts:?}"
        );
    }
    assert_eq!(common::assert_clean_figures(&figures), 1);
}
