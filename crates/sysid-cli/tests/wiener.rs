//! `sysid simulate wiener` and `sysid fit wiener` end to end: a short fit runs, writes
//! the estimate and trace, is reproducible, and bad input gives one-line errors.

mod common;
use common::{assert_one_line_error, json_of, s, scratch_dir, simulate, sysid};

#[test]
fn fit_wiener_runs_and_is_reproducible() {
    let dir = scratch_dir();
    let data = simulate(&dir, "wiener", 300, 2);
    let header = std::fs::read_to_string(&data).unwrap();
    assert!(header.starts_with("t,y1,y2\n"), "{}", &header[..20]);
    let fit = |name: &str| {
        let out = dir.join(name);
        let trace = dir.join(format!("{name}.trace.csv"));
        let summary = json_of(&sysid(&[
            "fit",
            "wiener",
            "--data",
            s(&data),
            "--iters",
            "3",
            "--particles",
            "20",
            "--seed",
            "4",
            "--out",
            s(&out),
            "--trace",
            s(&trace),
            "--json",
        ]));
        assert_eq!(summary["iterations"], 3);
        let model: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        let trace = std::fs::read_to_string(&trace).unwrap();
        assert_eq!(trace.lines().count(), 4, "{trace}");
        assert!(trace.starts_with("iteration,loglik,a11,"));
        (model, trace)
    };
    let (first, trace) = fit("a.json");
    let b = first["breakpoints"].as_array().unwrap();
    assert_eq!(b.len(), 4);
    assert!(b[0].as_f64().unwrap() < b[1].as_f64().unwrap());
    assert!(b[2].as_f64().unwrap() < b[3].as_f64().unwrap());
    let (second, trace2) = fit("b.json");
    assert_eq!(first, second);
    assert_eq!(trace, trace2);
}

#[test]
fn fit_wiener_refuses_bad_input() {
    let dir = scratch_dir();
    let lgss = simulate(&dir, "lgss", 100, 1);
    let out = dir.join("w.json");
    assert_one_line_error(
        &sysid(&["fit", "wiener", "--data", s(&lgss), "--out", s(&out)]),
        &["output columns", "2"],
    );
    let wiener = simulate(&dir, "wiener", 100, 1);
    assert_one_line_error(
        &sysid(&[
            "fit",
            "wiener",
            "--data",
            s(&wiener),
            "--particles",
            "1",
            "--out",
            s(&out),
        ]),
        &["--particles"],
    );
    assert!(!out.exists());
    // an existing output is refused before the (long) fit, not after it
    std::fs::write(&out, "keep").unwrap();
    let started = std::time::Instant::now();
    assert_one_line_error(
        &sysid(&[
            "fit",
            "wiener",
            "--data",
            s(&wiener),
            "--iters",
            "1000",
            "--out",
            s(&out),
        ]),
        &["w.json", "--force"],
    );
    assert!(
        started.elapsed().as_secs() < 5,
        "the refusal came after the fit"
    );
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "keep");
    assert_one_line_error(
        &sysid(&[
            "simulate",
            "wiener",
            "--out",
            s(&dir.join("x.csv")),
            "--model-out",
            s(&dir.join("m.json")),
        ]),
        &["--model-out"],
    );
}
