//! The determinism audit: every stochastic subcommand gives bit-identical outputs with
//! 1, 2 and 4 threads for the same seed (DESIGN.md section 3). One test per subcommand;
//! each compares the written files byte for byte and the JSON summary without its
//! timings.

mod common;

use common::{s, scratch_dir, simulate, sysid};
use std::path::{Path, PathBuf};

/// Summary fields that are wall-clock measurements.
const TIMINGS: &[&str] = &[
    "seconds",
    "ms_per_iteration",
    "seconds_per_run_median",
    "elapsed",
];

fn without_timings(mut v: serde_json::Value) -> serde_json::Value {
    if let Some(map) = v.as_object_mut() {
        map.retain(|k, _| !TIMINGS.contains(&k.as_str()));
        for value in map.values_mut() {
            *value = without_timings(value.take());
        }
    } else if let Some(items) = v.as_array_mut() {
        for value in items.iter_mut() {
            *value = without_timings(value.take());
        }
    }
    v
}

/// Runs `args` (`{out}` is a fresh per-run folder) with 1, 2 and 4 threads and asserts
/// that the files named `outputs` in that folder and the JSON summaries are identical.
fn assert_thread_independent(args: &[&str], outputs: &[&str]) {
    let dir = scratch_dir();
    let mut reference: Option<(Vec<Vec<u8>>, serde_json::Value)> = None;
    for threads in ["1", "2", "4"] {
        let out_dir: PathBuf = dir.join(format!("threads{threads}"));
        std::fs::create_dir_all(&out_dir).unwrap();
        let mut argv: Vec<String> = vec!["--threads".into(), threads.into()];
        argv.extend(args.iter().map(|a| a.replace("{out}", s(&out_dir))));
        argv.push("--json".into());
        let argv: Vec<&str> = argv.iter().map(String::as_str).collect();
        let out = sysid(&argv);
        assert!(
            out.status.success(),
            "{:?}: {}",
            args,
            String::from_utf8_lossy(&out.stderr)
        );
        // the summaries name the output folder, which differs between the runs
        let stdout = String::from_utf8_lossy(&out.stdout).replace(s(&out_dir), "{out}");
        let summary: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        let files: Vec<Vec<u8>> = outputs
            .iter()
            .map(|f| std::fs::read(out_dir.join(f)).unwrap())
            .collect();
        let now = (files, without_timings(summary));
        match &reference {
            None => reference = Some(now),
            Some(first) => {
                for (k, name) in outputs.iter().enumerate() {
                    assert!(
                        first.0[k] == now.0[k],
                        "{args:?}: {name} differs with {threads} threads"
                    );
                }
                assert_eq!(
                    first.1, now.1,
                    "{args:?}: summary differs with {threads} threads"
                );
            }
        }
    }
}

fn data(system: &str, steps: usize) -> (PathBuf, PathBuf) {
    let dir = scratch_dir();
    let file = simulate(&dir, system, steps, 7);
    (dir, file)
}

fn arg(p: &Path) -> String {
    s(p).to_string()
}

#[test]
fn simulate_is_thread_independent() {
    assert_thread_independent(
        &[
            "simulate",
            "nlbench",
            "--steps",
            "200",
            "--seed",
            "3",
            "--states",
            "--out",
            "{out}/d.csv",
        ],
        &["d.csv"],
    );
}

#[test]
fn pf_is_thread_independent() {
    let (_dir, d) = data("nlbench", 300);
    let d = arg(&d);
    assert_thread_independent(
        &[
            "pf",
            "--system",
            "nlbench",
            "--data",
            &d,
            "--particles",
            "3000",
            "--seed",
            "2",
            "--out",
            "{out}/f.csv",
        ],
        &["f.csv"],
    );
}

#[test]
fn psmooth_is_thread_independent() {
    let (_dir, d) = data("nlbench", 200);
    let d = arg(&d);
    for method in ["tanizaki", "ffbsi", "ffbsi-reject", "genealogy"] {
        // Tanizaki's smoother draws one path per particle
        let paths = if method == "tanizaki" { "300" } else { "50" };
        assert_thread_independent(
            &[
                "psmooth",
                "--system",
                "nlbench",
                "--data",
                &d,
                "--particles",
                "300",
                "--method",
                method,
                "--paths",
                paths,
                "--out",
                "{out}/s.csv",
            ],
            &["s.csv"],
        );
    }
}

#[test]
fn fit_nlbench_is_thread_independent() {
    let (_dir, d) = data("nlbench", 200);
    let d = arg(&d);
    assert_thread_independent(
        &[
            "fit",
            "nlbench",
            "--data",
            &d,
            "--particles",
            "30",
            "--max-iter",
            "5",
            "--init",
            "0.6,20,9,0.04",
            "--out",
            "{out}/fit.json",
            "--trace",
            "{out}/trace.csv",
        ],
        &["fit.json", "trace.csv"],
    );
    assert_thread_independent(
        &[
            "fit",
            "nlbench",
            "--method",
            "psaem",
            "--data",
            &d,
            "--particles",
            "10",
            "--max-iter",
            "5",
            "--init",
            "0.6,20,9,0.04",
            "--out",
            "{out}/fit.json",
        ],
        &["fit.json"],
    );
}

#[test]
fn fit_affine_is_thread_independent() {
    let (_dir, d) = data("nlbench", 200);
    let d = arg(&d);
    assert_thread_independent(
        &[
            "fit",
            "affine",
            "--system",
            "nlbench",
            "--data",
            &d,
            "--particles",
            "30",
            "--max-iter",
            "4",
            "--smoother",
            "ffbsi-reject",
            "--out",
            "{out}/fit.json",
        ],
        &["fit.json"],
    );
}

#[test]
fn fit_wiener_is_thread_independent() {
    let (_dir, d) = data("wiener", 200);
    let d = arg(&d);
    assert_thread_independent(
        &[
            "fit",
            "wiener",
            "--data",
            &d,
            "--particles",
            "15",
            "--max-iter",
            "2",
            "--seed",
            "5",
            "--out",
            "{out}/w.json",
            "--trace",
            "{out}/t.csv",
        ],
        &["w.json", "t.csv"],
    );
}

#[test]
fn pmmh_is_thread_independent() {
    let (_dir, d) = data("lgss", 100);
    let d = arg(&d);
    assert_thread_independent(
        &[
            "pmmh",
            "--system",
            "lgss",
            "--data",
            &d,
            "--iters",
            "200",
            "--particles",
            "50",
            "--chains",
            "3",
            "--out",
            "{out}/c.csv",
        ],
        &["c.csv"],
    );
}

#[test]
fn pgas_is_thread_independent() {
    let (_dir, d) = data("lgss", 100);
    let d = arg(&d);
    for kernel in ["as", "bs"] {
        assert_thread_independent(
            &[
                "pgas",
                "--system",
                "lgss",
                "--data",
                &d,
                "--iters",
                "200",
                "--particles",
                "10",
                "--chains",
                "3",
                "--kernel",
                kernel,
                "--out",
                "{out}/c.json",
            ],
            &["c.json"],
        );
    }
}

#[test]
fn demo_is_thread_independent() {
    assert_thread_independent(
        &[
            "demo",
            "--runs",
            "2",
            "--iters",
            "2",
            "--out-dir",
            "{out}/fig",
            "--force",
        ],
        &[
            "fig/em-trajectories.svg",
            "fig/bode.svg",
            "fig/smoothed-state.svg",
            "fig/loglik-trace.svg",
        ],
    );
}

/// `sysid bench` runs the studies: their result lines (not their timings) are the same
/// for any thread count.
#[test]
fn bench_studies_are_thread_independent() {
    // timings and thread counts differ; everything else must not, at any depth
    fn strip(v: &mut serde_json::Value) {
        if let Some(map) = v.as_object_mut() {
            map.retain(|k, _| !(k.contains("seconds") || k == "threads" || k == "shard"));
            map.values_mut().for_each(strip);
        } else if let Some(list) = v.as_array_mut() {
            list.iter_mut().for_each(strip);
        }
    }
    let parse = |out: &std::process::Output| -> Vec<serde_json::Value> {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(|l| {
                let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
                strip(&mut v);
                v
            })
            .collect()
    };
    let dir = scratch_dir();
    for method in ["paper", "robust"] {
        let study = |threads: &str, shard: &str| {
            sysid(&[
                "--threads",
                threads,
                "bench",
                "nlbench-em",
                "--method",
                method,
                "--runs",
                "3",
                "--iters",
                "3",
                "--steps",
                "200",
                "--particles",
                "20",
                "--starts",
                "4",
                "--explore-iters",
                "3",
                "--refine-iters",
                "3",
                "--refine-particles",
                "20",
                "--select-particles",
                "100",
                "--shard",
                shard,
            ])
        };
        let reference = parse(&study("1", "0/1"));
        assert_eq!(reference.len(), 4, "3 runs and a summary");
        for threads in ["2", "4"] {
            assert_eq!(
                reference,
                parse(&study(threads, "0/1")),
                "{method} differs with {threads} threads"
            );
        }
        // two shards, merged
        let shards: Vec<std::path::PathBuf> = (0..2)
            .map(|i| {
                let out = study("2", &format!("{i}/2"));
                let path = dir.join(format!("{method}-{i}.jsonl"));
                std::fs::write(&path, &out.stdout).unwrap();
                path
            })
            .collect();
        let merged = parse(&sysid(&[
            "bench",
            "nlbench-em-merge",
            s(&shards[0]),
            s(&shards[1]),
        ]));
        assert_eq!(reference, merged, "{method}: merged shards differ");
    }
}
