//! `report`: runs every runner at a chosen scale and writes `docs/benchmarks.md`
//! (medians, targets met or missed, each kernel's ratio to its floor estimate, the
//! accuracy of each reproduction) and a figure of the ratios beside it.
//!
//! The runners' JSON lines are captured in-process ([`crate::capture`]) and rendered
//! generically: a task measured once becomes a key/value table, a task measured several
//! times a table with one row per line. Nothing in the file is written by hand; the
//! analysis (floors derived, where the time goes) is `docs/performance.md`.

use crate::Runner;
use clap::Parser;
use serde_json::Value;
use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The report's settings.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// `quick` (a few minutes on 2 cores: fewer repetitions, small studies) or `full`
    /// (the papers' study sizes: hours).
    #[arg(long, default_value = "quick")]
    pub scale: String,
    /// The Markdown file to (re)write; the figure goes beside it. Regenerating this
    /// file is the command's purpose, so it is replaced without `--force`.
    #[arg(long, default_value = "docs/benchmarks.md")]
    pub out: PathBuf,
}

/// Parses a runner's command line (so the report runs exactly what a user would).
#[derive(Parser, Debug)]
struct RunnerLine {
    #[command(subcommand)]
    runner: Runner,
}

/// The runner command lines of a scale.
fn plan(scale: &str) -> Result<Vec<&'static str>, String> {
    Ok(match scale {
        "quick" => vec![
            "kalman --reps 11",
            "em --reps 11",
            "smc --reps 11",
            "pmcmc --reps 5",
            "lti2x2 --datasets 20",
            "nlbench-em --runs 8 --iters 200",
            "wiener --runs 2 --iters 20",
        ],
        "full" => vec![
            "kalman",
            "em",
            "smc",
            "pmcmc",
            "lti2x2",
            "nlbench-em",
            "wiener",
        ],
        other => return Err(format!("--scale {other:?}: use quick or full")),
    })
}

/// A kernel's physical floor: the time no implementation on this machine can beat,
/// from the arithmetic or the dependency chain it must execute (derivations in
/// docs/performance.md).
struct Floor {
    task: &'static str,
    /// `params` entries that select the measured line.
    select: &'static [(&'static str, &'static str)],
    /// The measured field and the floor in its unit.
    field: &'static str,
    floor: f64,
    why: &'static str,
}

const FLOORS: &[Floor] = &[
    Floor {
        task: "kalman_filter",
        select: &[("system", "lgss"), ("steady_state_reuse", "false")],
        field: "ns_per_step",
        floor: 13.0,
        why: "variance recursion: a 26-cycle dependency chain at 2 GHz",
    },
    Floor {
        task: "kalman_smooth_stats",
        select: &[
            ("system", "lti2x2"),
            ("full_noise", "true"),
            ("steady_state_reuse", "false"),
        ],
        field: "ns_per_step",
        floor: 625.0,
        why: "~10k flops per step at 16 Gflop/s (the passes are dispatched to AVX2: 4-wide, 2 FP ports, 2 GHz)",
    },
    Floor {
        task: "em_iteration",
        select: &[("T", "200")],
        field: "ms_median",
        floor: 0.125,
        why: "200 full square-root steps at the 0.625 us flop floor",
    },
    Floor {
        task: "pf_bootstrap",
        select: &[("M", "1000")],
        field: "ms_median",
        floor: 4.0,
        why: "1e6 particle-steps x ~4 ns: one vectorised normal (1.3 ns alone, bound by the divide and square-root unit), one vectorised exp (~1.2 ns) and the resampling prefix sum (~1.5 ns as one chain; now by groups of eight)",
    },
    Floor {
        task: "pf_bootstrap",
        select: &[("M", "10000"), ("threads", "1")],
        field: "ms_median",
        floor: 40.0,
        why: "1e7 particle-steps x ~4 ns on one core",
    },
    Floor {
        task: "pf_bootstrap",
        select: &[("M", "10000"), ("threads", "2")],
        field: "ms_median",
        floor: 20.0,
        why: "the one-core floor shared by two cores",
    },
    Floor {
        task: "tanizaki",
        select: &[("M", "50")],
        field: "ms_median",
        floor: 1.0,
        why: "5e4 draws x ~20 ns: about 2 rejection trials (a bulk uniform-exponential pair each) from a window of sorted means where they spread, the nearest-mean pass, 1-2 % fallbacks of 50 vectorised exps",
    },
    Floor {
        task: "ffbsi_reject",
        select: &[("M", "50")],
        field: "ms_median",
        floor: 0.6,
        why: "5e4 draws x ~2 trials x ~3 ns, plus 1000 steps x ~0.3 us for the transition means and either their bucket sort with the weights' running sums or an alias table",
    },
    Floor {
        task: "ffbsi_reject",
        select: &[("M", "1000")],
        field: "ms_median",
        floor: 6.0,
        why: "1.2e6 trials x ~3 ns (a bulk uniform-exponential pair, an alias lookup, one density), plus 1000 alias tables (a split pass with two running sums at the add latency, ~1.5 us each)",
    },
    Floor {
        task: "ffbsi",
        select: &[("M", "1000")],
        field: "ms_median",
        floor: 120.0,
        why: "1e8 transition densities at ~1.2 ns (vectorised exp)",
    },
];

/// `params.key` of a line as text (strings unquoted).
fn param(line: &Value, key: &str) -> Option<String> {
    line.get("params")?.get(key).map(|v| match v {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    })
}

/// Four significant digits, scientific outside [1e-3, 1e6).
fn number(v: f64) -> String {
    let a = v.abs();
    if v.fract() == 0.0 && a < 1e15 {
        format!("{v:.0}")
    } else if !(1e-3..1e6).contains(&a) {
        format!("{v:.3e}")
    } else {
        let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
        format!("{v:.decimals$}")
    }
}

fn cell(v: &Value) -> String {
    match v {
        Value::Number(n) => n.as_f64().map(number).unwrap_or_else(|| n.to_string()),
        Value::String(s) => s.clone(),
        Value::Null => "-".into(),
        Value::Array(items) if items.iter().all(|i| !i.is_object()) => {
            items.iter().map(cell).collect::<Vec<_>>().join(", ")
        }
        other => other.to_string(),
    }
}

/// `(dotted key, value)` leaves of a JSON object; arrays of objects are indexed.
fn flatten(prefix: &str, v: &Value, out: &mut Vec<(String, Value)>) {
    let key = |k: &str| {
        if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}.{k}")
        }
    };
    match v {
        Value::Object(map) => {
            for (k, v) in map {
                flatten(&key(k), v, out);
            }
        }
        Value::Array(items) if items.iter().any(Value::is_object) => {
            for (i, item) in items.iter().enumerate() {
                flatten(&key(&i.to_string()), item, out);
            }
        }
        leaf => out.push((prefix.to_string(), leaf.clone())),
    }
}

fn leaves(line: &Value) -> Vec<(String, Value)> {
    let mut out = Vec::new();
    flatten("", line, &mut out);
    out.retain(|(k, _)| k != "task" && !k.starts_with("targets."));
    for (k, _) in &mut out {
        if let Some(rest) = k.strip_prefix("params.") {
            *k = rest.to_string();
        }
    }
    out
}

/// One task's lines as Markdown: key/value when measured once, else a table.
fn render_task(md: &mut String, task: &str, lines: &[&Value]) {
    let _ = writeln!(md, "\n**{task}**\n");
    if lines.len() == 1 {
        let _ = writeln!(md, "| quantity | value |\n| --- | --- |");
        for (k, v) in leaves(lines[0]) {
            let _ = writeln!(md, "| {k} | {} |", cell(&v));
        }
        return;
    }
    if task.ends_with("_run") && lines.len() > 12 {
        let _ = writeln!(
            md,
            "{} run lines (see the runner's JSON output).",
            lines.len()
        );
        return;
    }
    let rows: Vec<Vec<(String, Value)>> = lines.iter().map(|l| leaves(l)).collect();
    let mut columns: Vec<String> = Vec::new();
    for row in &rows {
        for (k, _) in row {
            if !columns.contains(k) {
                columns.push(k.clone());
            }
        }
    }
    // drop columns with the same value on every row (shown once, below)
    let constant: BTreeSet<String> = columns
        .iter()
        .filter(|c| {
            let values: BTreeSet<String> = rows
                .iter()
                .map(|r| {
                    r.iter()
                        .find(|(k, _)| k == *c)
                        .map(|(_, v)| cell(v))
                        .unwrap_or_default()
                })
                .collect();
            values.len() == 1
        })
        .cloned()
        .collect();
    let shown: Vec<&String> = columns.iter().filter(|c| !constant.contains(*c)).collect();
    let _ = writeln!(
        md,
        "| {} |\n|{}",
        shown
            .iter()
            .map(|s| s.as_str())
            .collect::<Vec<_>>()
            .join(" | "),
        " --- |".repeat(shown.len())
    );
    for row in &rows {
        let cells: Vec<String> = shown
            .iter()
            .map(|c| {
                row.iter()
                    .find(|(k, _)| k == *c)
                    .map(|(_, v)| cell(v))
                    .unwrap_or_default()
            })
            .collect();
        let _ = writeln!(md, "| {} |", cells.join(" | "));
    }
    if !constant.is_empty() {
        let first = &rows[0];
        let fixed: Vec<String> = columns
            .iter()
            .filter(|c| constant.contains(*c))
            .map(|c| {
                let v = first
                    .iter()
                    .find(|(k, _)| k == c)
                    .map(|(_, v)| cell(v))
                    .unwrap_or_default();
                format!("{c} = {v}")
            })
            .collect();
        let _ = writeln!(md, "\nOn every row: {}.", fixed.join(", "));
    }
}

/// A target entry of a summary line as (what, measured, target, met).
fn target_row(runner: &str, t: &Value) -> Option<TargetRow> {
    let map = t.as_object()?;
    let target_key = map.keys().find(|k| k.starts_with("target_"))?;
    let unit = target_key.trim_start_matches("target_");
    let measured = map
        .iter()
        .find(|(k, v)| k.starts_with(unit) && v.is_number())
        .or_else(|| {
            map.iter()
                .find(|(k, v)| !k.starts_with("target") && v.is_number())
        })?
        .1
        .as_f64()?;
    let mut what = vec![format!(
        "{runner}: {}",
        map.get("task").map(cell).unwrap_or_default()
    )];
    let mut details = Vec::new();
    flatten("", map.get("params").unwrap_or(&Value::Null), &mut details);
    for (k, v) in map
        .iter()
        .filter(|(k, _)| ["system", "T"].contains(&k.as_str()))
    {
        details.push((k.clone(), v.clone()));
    }
    what.extend(
        details
            .iter()
            .filter(|(k, _)| !k.is_empty())
            .map(|(k, v)| format!("{k} {}", cell(v))),
    );
    Some((
        what.join(", "),
        measured,
        map.get(target_key)?.as_f64()?,
        map.get("met")
            .and_then(Value::as_bool)
            .unwrap_or(measured <= map.get(target_key)?.as_f64()?),
    ))
}

/// Machine facts for the header: CPU model, logical CPUs, memory.
fn machine() -> String {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = cpuinfo
        .lines()
        .find_map(|l| {
            l.strip_prefix("model name")
                .map(|r| r.trim_start_matches([' ', '\t', ':']).to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    let memory = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            m.lines()
                .find_map(|l| l.strip_prefix("MemTotal:"))
                .and_then(|kb| kb.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        })
        .map(|kb| format!(", {:.0} GiB", kb / 1024.0 / 1024.0))
        .unwrap_or_default();
    let cpus = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    format!("{model}, {cpus} logical CPUs{memory}")
}

/// Today's UTC date as YYYY-MM-DD (civil-from-days, no calendar crate needed).
fn today() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let z = (secs / 86_400) as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}")
}

/// Runs the report.
pub fn run(a: &Args) -> Result<(), String> {
    let plan = plan(&a.scale)?;
    // the folder of the report and its figure, before the runners take their minutes
    let folder = a
        .out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if !folder.is_dir() {
        return Err(format!(
            "--out {}: the folder {} does not exist",
            a.out.display(),
            folder.display()
        ));
    }
    let started = Instant::now();
    let mut sections: Vec<Section> = Vec::new();
    for command in &plan {
        let words = std::iter::once("sysid-bench").chain(command.split_whitespace());
        let line = RunnerLine::try_parse_from(words).map_err(|e| e.to_string())?;
        eprintln!("report: {command}");
        let t0 = Instant::now();
        let lines = crate::capture(|| crate::run(line.runner))?;
        sections.push((command.to_string(), t0.elapsed().as_secs_f64(), lines));
    }
    let md = render(&a.scale, &sections, started.elapsed().as_secs_f64());
    let figure = ratio_figure(&sections);
    let dir = a
        .out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if let Some(figure) = figure {
        let svg = figure.to_svg().map_err(|e| e.to_string())?;
        sysid_output::write_atomically(&dir.join("benchmarks.svg"), true, |w| {
            std::io::Write::write_all(w, svg.as_bytes())
        })
        .map_err(|e| e.to_string())?;
    }
    sysid_output::write_atomically(&a.out, true, |w| {
        std::io::Write::write_all(w, md.as_bytes())
    })
    .map_err(|e| e.to_string())?;
    eprintln!(
        "report: wrote {} in {:.0} s",
        a.out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// A runner's command line, wall seconds and JSON lines.
type Section = (String, f64, Vec<Value>);
/// (what, measured, target, met).
type TargetRow = (String, f64, f64, bool);
/// (kernel, measured, floor, why).
type FloorRow = (String, f64, f64, &'static str);

/// Every target and every floor ratio found in the runners' lines.
fn ratios(sections: &[Section]) -> (Vec<TargetRow>, Vec<FloorRow>) {
    let mut targets = Vec::new();
    let mut floors = Vec::new();
    for (command, _, lines) in sections {
        let runner = command.split_whitespace().next().unwrap_or_default();
        for line in lines {
            if let Some(items) = line.get("targets").and_then(Value::as_array) {
                targets.extend(items.iter().filter_map(|t| target_row(runner, t)));
            } else if line.get("met").is_some() {
                targets.extend(target_row(runner, line));
            }
            let task = line.get("task").and_then(Value::as_str).unwrap_or_default();
            for f in FLOORS.iter().filter(|f| f.task == task) {
                let selected = f
                    .select
                    .iter()
                    .all(|(k, v)| param(line, k).as_deref() == Some(*v));
                if let (true, Some(measured)) =
                    (selected, line.get(f.field).and_then(Value::as_f64))
                {
                    let what = f
                        .select
                        .iter()
                        .map(|(k, v)| format!("{k} {v}"))
                        .collect::<Vec<_>>()
                        .join(", ");
                    floors.push((format!("{task} ({what})"), measured, f.floor, f.why));
                }
            }
        }
    }
    (targets, floors)
}

fn render(scale: &str, sections: &[Section], seconds: f64) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# Benchmarks\n\nGenerated by `cargo run --release -p sysid-bench -- report --scale {scale}` \
         on {} in {seconds:.0} s; do not edit by hand (the analysis is in \
         [performance.md](performance.md)).\n\nMachine: {}. Build: `--release`, baseline \
         x86-64 (no `target-cpu`). Timings are medians over the repetitions of one \
         process; this machine is a shared VM whose processes run in a fast or a slow \
         mode (up to 2x apart), so compare medians over several processes \
         (performance.md).",
        today(),
        machine()
    );
    let (targets, floors) = ratios(sections);
    let _ = writeln!(
        md,
        "\n## Targets\n\n| what | measured | target | met |\n| --- | --- | --- | --- |"
    );
    for (what, measured, target, met) in &targets {
        let _ = writeln!(
            md,
            "| {what} | {} | {} | {} |",
            number(*measured),
            number(*target),
            if *met { "yes" } else { "**no**" }
        );
    }
    let _ = writeln!(
        md,
        "\n## Ratios to the physical floors\n\nUnits: ns per time step for the Kalman kernels, ms per call otherwise.\n\n| kernel | measured | floor | ratio | floor from |\n| --- | --- | --- | --- | --- |"
    );
    for (what, measured, floor, why) in &floors {
        let _ = writeln!(
            md,
            "| {what} | {} | {} | {:.2} | {why} |",
            number(*measured),
            number(*floor),
            measured / floor
        );
    }
    let _ = writeln!(md, "\n![ratios to targets and floors](benchmarks.svg)");
    md.push_str(&reproductions(sections));
    for (command, seconds, lines) in sections {
        let runner = command.split_whitespace().next().unwrap_or_default();
        let _ = writeln!(
            md,
            "\n## `{runner}`\n\n    cargo run --release -p sysid-bench -- {command}    # {seconds:.0} s"
        );
        let mut tasks: Vec<&str> = Vec::new();
        for line in lines {
            let task = line.get("task").and_then(Value::as_str).unwrap_or("?");
            if !tasks.contains(&task) {
                tasks.push(task);
            }
        }
        for task in tasks {
            let group: Vec<&Value> = lines
                .iter()
                .filter(|l| l.get("task").and_then(Value::as_str).unwrap_or("?") == task)
                .collect();
            render_task(&mut md, task, &group);
        }
    }
    md
}

/// The first line of a task across the sections.
fn find<'a>(sections: &'a [Section], task: &str) -> Option<&'a Value> {
    sections
        .iter()
        .flat_map(|(_, _, lines)| lines)
        .find(|l| l.get("task").and_then(Value::as_str) == Some(task))
}

/// The accuracy of each reproduction, from the runners' summaries.
fn reproductions(sections: &[Section]) -> String {
    let mut md = String::from(
        "\n## Accuracy of the reproductions\n\n| experiment | quantity | value |\n| --- | --- | --- |\n",
    );
    let mut row = |experiment: &str, quantity: &str, value: Option<&Value>| {
        if let Some(v) = value {
            let _ = writeln!(md, "| {experiment} | {quantity} | {} |", cell(v));
        }
    };
    if let Some(l) = find(sections, "lti2x2_summary") {
        let e = "seed 004, lti2x2 (T = 200)";
        row(e, "data sets", l.get("n4sid_runs"));
        row(
            e,
            "median response error: paper's initial model",
            l.get("median_response_error_paper_initial"),
        );
        row(
            e,
            "median response error: N4SID",
            l.get("median_response_error_n4sid"),
        );
        row(
            e,
            "median response error: EM from N4SID",
            l.get("median_response_error_em_from_n4sid"),
        );
        row(
            e,
            "median response error: EM from the paper's model",
            l.get("median_response_error_em_from_paper"),
        );
        row(
            e,
            "EM from N4SID at or above the truth's log-likelihood",
            l.get("n4sid_start_final_loglik_at_least_true"),
        );
    }
    if let Some(l) = find(sections, "nlbench_em_summary") {
        let e = "seed 000, nlbench particle EM";
        row(
            e,
            "runs x iterations",
            Some(&Value::String(format!(
                "{} x {}",
                cell(&l["params"]["runs"]),
                cell(&l["params"]["iters"])
            ))),
        );
        row(
            e,
            "fraction of runs with a, b, c, d within 10 % (paper: most)",
            l.get("fraction_converged"),
        );
        for p in ["a", "b", "c", "d"] {
            row(
                e,
                &format!("median {p}"),
                l.get(p).and_then(|v| v.get("median")),
            );
        }
    }
    if let Some(l) = find(sections, "wiener_summary") {
        let e = "seed 001, blind Wiener";
        row(
            e,
            "realisations x iterations",
            Some(&Value::String(format!(
                "{} x {}",
                cell(&l["params"]["runs"]),
                cell(&l["params"]["iterations"])
            ))),
        );
        row(
            e,
            "median relative breakpoint errors (target 0.1)",
            l.get("breakpoint_median_abs_error_relative"),
        );
        row(
            e,
            "median normalised magnitude error (target 0.1)",
            l.get("magnitude_error_median"),
        );
        row(
            e,
            "median largest error of r1, r2",
            l.get("r_median_max_abs_error"),
        );
    }
    if let Some(l) = find(sections, "pmcmc_lgss_posterior") {
        let e = "seed 001, lgss posterior (T = 100)";
        let names = ["phi", "q", "r"];
        for (i, name) in names.iter().enumerate() {
            let mean = |sampler: &str| {
                l.get(sampler)
                    .and_then(|s| s.get(i))
                    .and_then(|s| s.get("mean"))
                    .cloned()
            };
            if let (Some(exact), Some(pmmh), Some(pgas)) =
                (mean("exact"), mean("pmmh"), mean("pgas"))
            {
                row(
                    e,
                    &format!("posterior mean of {name}: exact / PMMH / PGAS"),
                    Some(&Value::String(format!(
                        "{} / {} / {}",
                        cell(&exact),
                        cell(&pmmh),
                        cell(&pgas)
                    ))),
                );
            }
        }
    }
    md
}

/// Two panels: measured / target and measured / floor, one point per kernel.
fn ratio_figure(sections: &[Section]) -> Option<sysid_plot::Figure> {
    use sysid_plot::{Figure, Panel, Scale, Series, Stroke};
    let (targets, floors) = ratios(sections);
    let panel = |title: &str, points: Vec<(f64, f64)>| {
        let n = points.len() as f64;
        Panel::new(
            title,
            "kernel (row of the table above)",
            "measured / reference",
        )
        .scales(Scale::Linear, Scale::Log)
        .with_series(
            Series::line("measured / reference", points)
                .stroke(Stroke::Points)
                .colour(0),
        )
        .with_series(
            Series::line("1 (met / at the floor)", vec![(0.5, 1.0), (n + 0.5, 1.0)])
                .stroke(Stroke::Dashed)
                .colour(6),
        )
    };
    let to_target: Vec<(f64, f64)> = targets
        .iter()
        .enumerate()
        .map(|(i, t)| ((i + 1) as f64, t.1 / t.2))
        .collect();
    let to_floor: Vec<(f64, f64)> = floors
        .iter()
        .enumerate()
        .map(|(i, f)| ((i + 1) as f64, f.1 / f.2))
        .collect();
    if to_target.is_empty() || to_floor.is_empty() {
        return None;
    }
    Some(Figure::grid(
        vec![
            panel("Time / target", to_target),
            panel("Time / physical floor", to_floor),
        ],
        2,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn numbers_have_four_significant_digits() {
        assert_eq!(number(16.82213), "16.82");
        assert_eq!(number(0.7312), "0.7312");
        assert_eq!(number(1375.27), "1375");
        assert_eq!(number(2.5e-5), "2.500e-5");
    }

    #[test]
    fn the_date_is_a_calendar_date() {
        let d = today();
        assert_eq!(d.len(), 10);
        assert!(d.starts_with("20"), "{d}");
    }

    #[test]
    fn targets_and_floors_are_read_from_the_runner_lines() {
        let lines = vec![
            json!({"task": "tanizaki", "params": {"M": 50, "T": 1000}, "ms_median": 6.0}),
            json!({"task": "smc_summary", "targets": [{"task": "tanizaki", "ms_median": 6.0, "target_ms": 2.5, "met": false, "params": {"M": 50}}]}),
        ];
        let sections = vec![("smc --reps 5".to_string(), 1.0, lines)];
        let (targets, floors) = ratios(&sections);
        assert_eq!(targets.len(), 1);
        assert_eq!(
            (targets[0].1, targets[0].2, targets[0].3),
            (6.0, 2.5, false)
        );
        assert_eq!(floors.len(), 1);
        assert!((floors[0].1 / floors[0].2 - 6.0).abs() < 1e-12);
        let md = render("quick", &sections, 1.0);
        assert!(
            md.contains("| smc: tanizaki, M 50 | 6 | 2.500 | **no** |"),
            "{md}"
        );
        assert!(md.contains("| tanizaki (M 50) | 6 | 1 | 6.00 |"), "{md}");
        assert!(ratio_figure(&sections).is_some());
    }
}
