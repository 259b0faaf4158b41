//! The failing commands of the "no surprises" issue, through the binary: sizes beyond
//! the machine's memory, a plot that looped forever, a thread count in the
//! hundred-thousands, and outputs that clobbered each other, a device or a link.
//! Each refusal exits 2 with one line on stderr and leaves no file behind.

mod common;
use common::{assert_ok, assert_one_line_error, entries, s, scratch_dir, simulate, sysid};

#[test]
fn sizes_beyond_the_machines_memory_are_refused_before_allocating() {
    let dir = scratch_dir();
    let nl = simulate(&dir, "nlbench", 100, 1);
    let lg = simulate(&dir, "lgss", 100, 1);
    let before = entries(&dir);
    // a repeat count that would run for days is refused by name
    assert_one_line_error(
        &sysid(&[
            "pf",
            "--system",
            "nlbench",
            "--data",
            s(&nl),
            "--repeats",
            "1000000000",
        ]),
        &["--repeats", "at most 1000"],
    );
    let oscillator = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../examples/models/oscillator.toml"
    );
    let nile_model = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/nile_start.json");
    let nile = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/nile.csv");
    let cases: [(&[&str], &str); 6] = [
        // (a model file's simulation allocated its times first, and aborted)
        (
            &[
                "simulate",
                "--model",
                oscillator,
                "--steps",
                "100000000000",
                "--out",
                "m.csv",
            ],
            "--steps",
        ),
        // (a forecast allocated for a minute, then aborted)
        (
            &[
                "forecast",
                "--model",
                nile_model,
                "--data",
                nile,
                "--steps",
                "1000000000",
                "--out",
                "f.csv",
            ],
            "--steps",
        ),
        (
            &[
                "pf",
                "--system",
                "nlbench",
                "--data",
                s(&nl),
                "--particles",
                "10000000000",
            ],
            "--particles",
        ),
        (
            &[
                "simulate",
                "lgss",
                "--steps",
                "1000000000000",
                "--out",
                "s.csv",
            ],
            "--steps",
        ),
        (
            &[
                "psmooth",
                "--system",
                "nlbench",
                "--data",
                s(&nl),
                "--paths",
                "10000000000",
                "--out",
                "p.csv",
            ],
            "--paths",
        ),
        (
            &[
                "pmmh",
                "--system",
                "lgss",
                "--data",
                s(&lg),
                "--iters",
                "1000000000000",
                "--out",
                "c.csv",
            ],
            "--iters",
        ),
    ];
    for (args, option) in cases {
        let mut all: Vec<String> = args.iter().map(|a| a.to_string()).collect();
        // outputs in the scratch directory
        for a in all.iter_mut() {
            if a.ends_with(".csv") && !a.contains('/') {
                *a = dir.join(a.as_str()).display().to_string();
            }
        }
        let refs: Vec<&str> = all.iter().map(String::as_str).collect();
        assert_one_line_error(&sysid(&refs), &[option, "of memory", "available"]);
    }
    assert_eq!(entries(&dir), before, "no file left behind");
}

/// The guard counts the address-space limit (`ulimit -v`), not only the machine's
/// memory: 100 million steps of the oscillator (5.6 GB) under a 4 GB limit.
#[test]
fn the_memory_guard_honours_ulimit() {
    let dir = scratch_dir();
    let oscillator = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../examples/models/oscillator.toml"
    );
    let out = dir.join("m.csv");
    let run = std::process::Command::new("bash")
        .arg("-c")
        .arg(format!(
            "ulimit -v 4000000 && exec {} simulate --model {oscillator} --steps 100000000 --out {}",
            env!("CARGO_BIN_EXE_sysid"),
            out.display()
        ))
        .output()
        .unwrap();
    assert_one_line_error(&run, &["--steps", "of memory", "4.1 GB available"]);
    assert!(!out.exists());
}

#[test]
fn a_plot_of_values_near_the_largest_float_is_refused_not_looped() {
    let dir = scratch_dir();
    let data = dir.join("big.csv");
    std::fs::write(&data, "t,y1\n1,1.7e308\n2,0\n").unwrap();
    let figures = dir.join("figs");
    assert_one_line_error(
        &sysid(&["plot", s(&data), "--out-dir", s(&figures)]),
        &["y1", "too wide to draw"],
    );
    assert!(!figures.exists(), "the folder the command made is gone");
    // with a good file first, neither figure is left
    let good = dir.join("good.csv");
    std::fs::write(&good, "t,y1\n1,1\n2,0\n").unwrap();
    assert_one_line_error(
        &sysid(&["plot", s(&good), s(&data), "--out-dir", s(&figures)]),
        &["too wide to draw"],
    );
    assert!(!figures.exists(), "all or nothing");
}

#[test]
fn a_huge_thread_count_is_capped_with_a_note() {
    let dir = scratch_dir();
    let nl = simulate(&dir, "nlbench", 50, 1);
    let out = sysid(&[
        "--threads",
        "100000",
        "pf",
        "--system",
        "nlbench",
        "--data",
        s(&nl),
        "--particles",
        "200",
    ]);
    assert_ok(&out);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--threads 100000 capped at"), "{err}");
}

#[test]
fn outputs_never_clobber_each_other_a_device_or_a_link() {
    let dir = scratch_dir();
    let (data, model) = (dir.join("d.csv"), dir.join("m.json"));
    assert_ok(&sysid(&[
        "simulate",
        "lgss",
        "--steps",
        "80",
        "--out",
        s(&data),
        "--model-out",
        s(&model),
    ]));
    let before = entries(&dir);
    // one file for two outputs, with and without --force, spelled two ways
    let same = dir.join("f.json");
    let other_spelling = dir.join(".").join("f.json");
    for force in [true, false] {
        let mut args = vec![
            "fit",
            "lti",
            "--data",
            s(&data),
            "--order",
            "1",
            "--out",
            s(&same),
            "--trace",
            s(&other_spelling),
        ];
        if force {
            args.push("--force");
        }
        assert_one_line_error(&sysid(&args), &["f.json", "two outputs"]);
    }
    let x = dir.join("x");
    assert_one_line_error(
        &sysid(&[
            "simulate",
            "lgss",
            "--steps",
            "10",
            "--out",
            s(&x),
            "--model-out",
            s(&x),
            "--force",
        ]),
        &["two outputs"],
    );
    assert_eq!(entries(&dir), before, "no file left behind");
    // an existing second output refuses the command before the first is written
    let existing = dir.join("trace.csv");
    std::fs::write(&existing, "keep").unwrap();
    let new = dir.join("new.json");
    assert_one_line_error(
        &sysid(&[
            "fit",
            "lti",
            "--data",
            s(&data),
            "--order",
            "1",
            "--out",
            s(&new),
            "--trace",
            s(&existing),
        ]),
        &["trace.csv", "--force"],
    );
    assert!(!new.exists(), "half the outputs written");
    assert_eq!(std::fs::read_to_string(&existing).unwrap(), "keep");
    // a symbolic link (as /dev/stdout is) and a directory are never replaced
    let target = dir.join("target.csv");
    std::fs::write(&target, "kept").unwrap();
    let link = dir.join("link.csv");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    for out in [&link, &dir] {
        assert_one_line_error(
            &sysid(&[
                "smooth",
                "--model",
                s(&model),
                "--data",
                s(&data),
                "--out",
                s(out),
                "--force",
            ]),
            &["not a regular file"],
        );
    }
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "kept");
}

#[test]
fn two_inputs_with_one_name_get_two_figures() {
    let dir = scratch_dir();
    let data = simulate(&dir, "lgss", 80, 2);
    let mut traces = Vec::new();
    for sub in ["a", "b"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
        let trace = dir.join(sub).join("trace.csv");
        assert_ok(&sysid(&[
            "fit",
            "lti",
            "--data",
            s(&data),
            "--order",
            "1",
            "--max-iter",
            if sub == "a" { "5" } else { "20" },
            "--out",
            s(&dir.join(sub).join("f.json")),
            "--trace",
            s(&trace),
        ]));
        traces.push(trace);
    }
    let figures = dir.join("figs");
    assert_ok(&sysid(&[
        "plot",
        s(&traces[0]),
        s(&traces[1]),
        "--out-dir",
        s(&figures),
        "--force",
    ]));
    assert_eq!(
        entries(&figures),
        [
            "trace-trace-2.png",
            "trace-trace-2.svg",
            "trace-trace.png",
            "trace-trace.svg"
        ]
    );
    let read = |name: &str| std::fs::read_to_string(figures.join(name)).unwrap();
    assert_ne!(
        read("trace-trace.svg"),
        read("trace-trace-2.svg"),
        "two different figures"
    );
}

/// `-` is standard output: the data alone on stdout, the summary on stderr; `-` for
/// two outputs is refused.
#[test]
fn a_dash_writes_standard_output() {
    let dir = scratch_dir();
    let out = sysid(&[
        "simulate", "lgss", "--steps", "5", "--seed", "2", "--out", "-",
    ]);
    assert_ok(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 6, "header and 5 rows only: {stdout}");
    assert_eq!(lines[0], "t,y1");
    assert!(String::from_utf8_lossy(&out.stderr).contains("wrote 5 steps"));
    // the same rows as a file
    let file = dir.join("s.csv");
    assert_ok(&sysid(&[
        "simulate",
        "lgss",
        "--steps",
        "5",
        "--seed",
        "2",
        "--out",
        s(&file),
    ]));
    assert_eq!(std::fs::read_to_string(&file).unwrap(), stdout);
    assert!(!dir.join("-").exists());
    assert_one_line_error(
        &sysid(&[
            "fit",
            "lti",
            "--data",
            s(&file),
            "--order",
            "1",
            "--out",
            "-",
            "--trace",
            "-",
        ]),
        &["two outputs"],
    );
}

/// A PMMH run too short to mix says so on stderr and in --json (R-hat, ESS).
#[test]
fn chains_that_have_not_mixed_are_flagged() {
    let dir = scratch_dir();
    let data = simulate(&dir, "lgss", 100, 3);
    let out = sysid(&[
        "pmmh",
        "--system",
        "lgss",
        "--data",
        s(&data),
        "--iters",
        "200",
        "--chains",
        "2",
        "--json",
    ]);
    assert_ok(&out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("few effective draws"), "{stderr}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let warnings = v["warnings"].as_array().unwrap();
    assert!(
        warnings
            .iter()
            .any(|w| w.as_str().unwrap().contains("ESS below 400")),
        "{v}"
    );
}

/// A model file with a diffuse initial state is refused by the particle commands (a
/// flat prior cannot be sampled; fit affine used to start from x_0 = 0 exactly).
#[test]
fn particle_methods_refuse_a_diffuse_initial_state() {
    let dir = scratch_dir();
    let data = simulate(&dir, "lgss", 50, 1);
    let model = dir.join("diffuse.json");
    std::fs::write(
        &model,
        r#"{"a": [[1.0]], "c": [[1.0]], "q": [[1.0]], "r": [[1.0]], "initial": "diffuse"}"#,
    )
    .unwrap();
    let out = dir.join("out.json");
    assert_one_line_error(
        &sysid(&["pf", "--model", s(&model), "--data", s(&data)]),
        &["diffuse", "proper initial law"],
    );
    assert_one_line_error(
        &sysid(&[
            "fit",
            "affine",
            "--init",
            s(&model),
            "--data",
            s(&data),
            "--out",
            s(&out),
        ]),
        &["diffuse", "mu and P1"],
    );
    assert!(!out.exists());
}

/// Input the user named but that is not there, or a filter option out of range, is bad
/// input (exit 2) and the message names the file or the flag: a missing `--init` file
/// used to exit 1, and `--particles 0` was blamed on "options: invalid option
/// `particles`".
#[test]
fn missing_inputs_and_bad_filter_flags_are_bad_input_named_as_typed() {
    let dir = scratch_dir();
    let data = simulate(&dir, "lgss", 50, 1);
    let missing = dir.join("nonexistent.json");
    assert_one_line_error(
        &sysid(&[
            "fit",
            "lti",
            "--data",
            s(&data),
            "--order",
            "1",
            "--init",
            s(&missing),
            "--out",
            s(&dir.join("f.json")),
        ]),
        &["nonexistent.json", "No such file"],
    );
    assert_one_line_error(
        &sysid(&["loglik", "--model", s(&dir), "--data", s(&data)]),
        &["Is a directory"],
    );
    for (flag, value) in [("--particles", "0"), ("--ess", "2")] {
        assert_one_line_error(
            &sysid(&["pf", "--system", "lgss", "--data", s(&data), flag, value]),
            &[&format!("error: {flag}:")],
        );
    }
    assert!(!dir.join("f.json").exists());
}

/// A file with 100 000 columns: its column list in a message is cut to a readable
/// line (it was 789 kB), a name repeated at the far end is found in one pass (the
/// pairwise search took seconds), and `plot` refuses a figure of 100 000 panels
/// (plotters panicked asking for a 12 GB bitmap) with exit 2 and no file.
#[test]
fn a_file_with_a_hundred_thousand_columns_gets_short_messages_and_no_panic() {
    let dir = scratch_dir();
    let columns = 100_000;
    let names: Vec<String> = (0..columns).map(|i| format!("c{i}")).collect();
    let wide = dir.join("wide.csv");
    let ones = vec!["1"; columns + 1].join(",");
    std::fs::write(&wide, format!("t,{}\n{ones}\n{ones}\n", names.join(","))).unwrap();
    let model = dir.join("m.json");
    let out = sysid(&[
        "n4sid",
        "--data",
        s(&wide),
        "--order",
        "1",
        "--out",
        s(&model),
    ]);
    assert_one_line_error(&out, &["the file has t, c0, c1", "(100001 columns)"]);
    assert!(out.stderr.len() < 600, "{} bytes", out.stderr.len());
    let repeated = dir.join("repeated.csv");
    std::fs::write(
        &repeated,
        format!("t,y1,{},y1\n1,1,{ones}\n", names[..columns - 2].join(",")),
    )
    .unwrap();
    assert_one_line_error(
        &sysid(&[
            "n4sid",
            "--data",
            s(&repeated),
            "--order",
            "1",
            "--out",
            s(&model),
        ]),
        &["column 100001 repeats the name \"y1\""],
    );
    let figures = dir.join("figs");
    assert_one_line_error(
        &sysid(&["plot", s(&wide), "--out-dir", s(&figures)]),
        &["100000 panels", "at most 64"],
    );
    assert!(!figures.exists() || entries(&figures).is_empty());
}

/// `plot --truth` with a record that does not cover the states' times is an error
/// naming both spans (it was drawn over part of the window in silence); the record the
/// states came from is accepted.
#[test]
fn a_truth_that_does_not_cover_the_states_is_refused() {
    let dir = scratch_dir();
    let long = dir.join("long.csv");
    let short = dir.join("short.csv");
    for (path, steps) in [(&long, "100"), (&short, "50")] {
        assert_ok(&sysid(&[
            "simulate",
            "nlbench",
            "--steps",
            steps,
            "--states",
            "--out",
            s(path),
        ]));
    }
    let figures = dir.join("figs");
    let plot = |truth: &std::path::Path| {
        sysid(&[
            "plot",
            s(&long),
            "--kind",
            "states",
            "--truth",
            s(truth),
            "--out-dir",
            s(&figures),
            "--force",
        ])
    };
    assert_one_line_error(&plot(&short), &["--truth", "from 1 to 50", "from 1 to 100"]);
    assert!(!figures.exists() || entries(&figures).is_empty());
    assert_ok(&plot(&long));
}

/// An output in a folder that does not exist is refused before any work, and the other
/// outputs are not written (fit lti wrote its model, then failed on the trace).
#[test]
fn an_output_in_a_missing_folder_is_refused_before_any_work() {
    let dir = scratch_dir();
    let data = dir.join("d.csv");
    assert_ok(&sysid(&[
        "simulate",
        "lti2x2",
        "--steps",
        "200",
        "--out",
        s(&data),
    ]));
    let model = dir.join("f.json");
    let out = sysid(&[
        "fit",
        "lti",
        "--data",
        s(&data),
        "--order",
        "2",
        "--out",
        s(&model),
        "--trace",
        s(&dir.join("no/dir/tr.csv")),
    ]);
    assert_one_line_error(&out, &["no/dir", "does not exist"]);
    assert!(
        !model.exists(),
        "the model was written before the trace failed"
    );
    let out = sysid(&[
        "n4sid",
        "--data",
        s(&data),
        "--order",
        "2",
        "--out",
        s(&dir.join("missing/n4.json")),
    ]);
    assert_one_line_error(&out, &["missing", "does not exist"]);
}

/// Outputs get the mode the user's umask gives any new file, and `--force` keeps the
/// mode of the file it replaces.
#[cfg(unix)]
#[test]
fn outputs_get_the_umask_s_mode_and_force_keeps_the_replaced_mode() {
    use std::os::unix::fs::PermissionsExt;
    let dir = scratch_dir();
    let mode = |p: &std::path::Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    let plain = dir.join("plain.txt");
    std::fs::write(&plain, "x").unwrap();
    let data = dir.join("d.csv");
    assert_ok(&sysid(&[
        "simulate",
        "lgss",
        "--steps",
        "50",
        "--out",
        s(&data),
    ]));
    assert_eq!(mode(&data), mode(&plain));
    std::fs::set_permissions(&data, std::fs::Permissions::from_mode(0o640)).unwrap();
    assert_ok(&sysid(&[
        "simulate",
        "lgss",
        "--steps",
        "50",
        "--out",
        s(&data),
        "--force",
    ]));
    assert_eq!(mode(&data), 0o640);
}

/// A transition that is one long sum (70 000 terms) overflowed the stack (exit 134):
/// the nesting check counted parentheses, not the chain of `+`. It is one line naming
/// the place now.
#[test]
fn a_model_file_with_an_endless_sum_is_refused_with_its_place() {
    let dir = scratch_dir();
    let model = dir.join("long.toml");
    let sum = vec!["a*x"; 70_000].join(" + ");
    std::fs::write(
        &model,
        format!(
            "format = 1\nstates = [\"x\"]\noutputs = [\"y\"]\n[parameters]\na = 0.5\n\
             [transition]\nx = \"{sum}\"\n[observation]\ny = \"x\"\n[noise]\nx = 0.1\ny = 0.1\n\
             [initial]\nx = {{ mean = 0, variance = 1 }}\n"
        ),
    )
    .unwrap();
    let out = dir.join("s.csv");
    assert_one_line_error(
        &sysid(&[
            "simulate",
            "--model",
            s(&model),
            "--steps",
            "10",
            "--out",
            s(&out),
        ]),
        &["long.toml:7:", "more than 1000 operations"],
    );
    assert!(!out.exists());
}

/// Work that would run for hours without a word is refused at once with what to do
/// instead: a million PMMH chains, an O(M K T) FFBSi of 10^13 densities, a demo of
/// 10^9 runs.
#[test]
fn work_that_would_run_for_hours_is_refused_at_once() {
    let dir = scratch_dir();
    let nl = simulate(&dir, "nlbench", 1000, 1);
    let lg = simulate(&dir, "lgss", 100, 1);
    let before = entries(&dir);
    let started = std::time::Instant::now();
    assert_one_line_error(
        &sysid(&[
            "pmmh",
            "--system",
            "lgss",
            "--data",
            s(&lg),
            "--chains",
            "1000000",
            "--iters",
            "100",
        ]),
        &["--chains", "at most 1024"],
    );
    let out = dir.join("p.csv");
    assert_one_line_error(
        &sysid(&[
            "psmooth",
            "--system",
            "nlbench",
            "--data",
            s(&nl),
            "--method",
            "ffbsi",
            "--particles",
            "100000",
            "--paths",
            "100000",
            "--out",
            s(&out),
        ]),
        &["--paths", "1.0e13 transition densities", "ffbsi-reject"],
    );
    let figures = dir.join("demo");
    assert_one_line_error(
        &sysid(&["demo", "--runs", "1000000000", "--out-dir", s(&figures)]),
        &["--runs", "at most 1000 runs", "--shard"],
    );
    assert!(started.elapsed().as_secs_f64() < 30.0);
    assert_eq!(entries(&dir), before, "no file left behind");
}

/// A model fitted with `--detrend linear` on a record timed in seconds (step 2), run
/// on a record numbered by rows (step 1), removed its trend at the wrong times and
/// scored -2 088 199 775 % with exit 0. The time bases are compared now; the same
/// record with its time column passes.
#[test]
fn a_linear_trend_on_another_time_base_is_refused() {
    let dir = scratch_dir();
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/heating_system.csv");
    let model = dir.join("fit.json");
    assert_ok(&sysid(&[
        "fit",
        "lti",
        "--data",
        data,
        "--order",
        "2",
        "--detrend",
        "linear",
        "--out",
        s(&model),
    ]));
    // the same signals without their time column: the rows number the steps
    let text = std::fs::read_to_string(data).unwrap();
    let rows: Vec<String> = text
        .lines()
        .map(|l| l.split_once(',').unwrap().1.to_string())
        .collect();
    let untimed = dir.join("untimed.csv");
    std::fs::write(&untimed, rows.join("\n") + "\n").unwrap();
    assert_one_line_error(
        &sysid(&["compare", "--model", s(&model), "--data", s(&untimed)]),
        &["--data", "untimed.csv", "time step is 1", "was 2"],
    );
    assert_ok(&sysid(&["compare", "--model", s(&model), "--data", data]));
}
