//! The `nlbench-em` study is deterministic: the same run lines and summary with 1 and 2
//! threads and as two merged shards.

use std::process::Command;

fn bench(args: &[&str], threads: &str) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_sysid-bench"))
        .args(args)
        .env("RAYON_NUM_THREADS", threads)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// The lines without the fields that legitimately differ (timings, threads, shard).
fn comparable(text: &str) -> Vec<serde_json::Value> {
    text.lines()
        .map(|l| {
            let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
            let o = v.as_object_mut().unwrap();
            for k in [
                "seconds",
                "wall_seconds",
                "threads",
                "seconds_per_run_median",
            ] {
                o.remove(k);
            }
            o["params"].as_object_mut().unwrap().remove("shard");
            v
        })
        .collect()
}

#[test]
fn study_is_identical_across_threads_and_shards() {
    let args = [
        "nlbench-em",
        "--runs",
        "4",
        "--iters",
        "3",
        "--steps",
        "60",
        "--particles",
        "30",
    ];
    let one = comparable(&bench(&args, "1"));
    let two = comparable(&bench(&args, "2"));
    assert_eq!(one.len(), 5);
    assert_eq!(one, two);
    let dir = std::env::temp_dir().join(format!("sysid-bench-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut files = Vec::new();
    for shard in ["0/2", "1/2"] {
        let mut a: Vec<&str> = args.to_vec();
        a.extend(["--shard", shard]);
        let path = dir.join(shard.replace('/', "of"));
        std::fs::write(&path, bench(&a, "2")).unwrap();
        files.push(path);
    }
    let mut merge_args = vec!["nlbench-em-merge"];
    merge_args.extend(files.iter().map(|p| p.to_str().unwrap()));
    let merged = comparable(&bench(&merge_args, "1"));
    assert_eq!(one, merged);
    let _ = std::fs::remove_dir_all(&dir);
}
