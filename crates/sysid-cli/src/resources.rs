//! Resource guards: a command that would need more memory than the machine has is
//! refused before it allocates (an allocation failure aborts the process with exit
//! 134 and no message), and `--threads` is capped.

use crate::error::CliError;

/// The memory available to this process, in bytes: the least of Linux's
/// `MemAvailable`, the room left under the process's control group limit (cgroup v2
/// `memory.max` less `memory.current`, or v1's `memory.limit_in_bytes` less its usage)
/// and its address-space limit (`ulimit -v`); `None` where none can be read (the guard
/// is then skipped).
pub fn available_memory() -> Option<f64> {
    [machine_available(), cgroup_room(), address_space_limit()]
        .into_iter()
        .flatten()
        .reduce(f64::min)
}

fn machine_available() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}

/// A number in a file (`max` and unreadable files: none).
fn number_in(path: &str) -> Option<f64> {
    std::fs::read_to_string(path).ok()?.trim().parse().ok()
}

/// The room under the control group's memory limit.
fn cgroup_room() -> Option<f64> {
    let v2 = number_in("/sys/fs/cgroup/memory.max")
        .map(|limit| limit - number_in("/sys/fs/cgroup/memory.current").unwrap_or(0.0));
    v2.or_else(|| {
        let limit = number_in("/sys/fs/cgroup/memory/memory.limit_in_bytes")?;
        // v1 reports "no limit" as a huge number
        (limit < 1e18).then(|| {
            limit - number_in("/sys/fs/cgroup/memory/memory.usage_in_bytes").unwrap_or(0.0)
        })
    })
}

/// `ulimit -v`, the soft limit of the address space (`/proc/self/limits`).
fn address_space_limit() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = text.lines().find(|l| l.starts_with("Max address space"))?;
    line.split_whitespace().nth(3)?.parse().ok()
}

/// Bytes in a human unit (`1.2 GB`, `80 TB`).
pub fn human_bytes(bytes: f64) -> String {
    let units = ["bytes", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut value = bytes;
    let mut unit = 0;
    while value >= 1000.0 && unit + 1 < units.len() {
        value /= 1000.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{value:.0} {}", units[unit])
    } else {
        format!("{value:.1} {}", units[unit])
    }
}

/// Refuses a command whose sizes need about `bytes` of memory (a lower bound from its
/// largest arrays, `what` says which) when that exceeds what the machine has
/// available. The error names `option`.
pub fn check_memory(option: &'static str, what: &str, bytes: f64) -> Result<(), CliError> {
    check_memory_against(option, what, bytes, available_memory())
}

/// [`check_memory`] against a given amount of available memory (`None`: no check).
pub fn check_memory_against(
    option: &'static str,
    what: &str,
    bytes: f64,
    available: Option<f64>,
) -> Result<(), CliError> {
    match available {
        Some(limit) if bytes > limit || !bytes.is_finite() => Err(CliError::BadOption {
            option,
            message: format!(
                "{what} need about {} of memory; this machine has {} available",
                human_bytes(bytes),
                human_bytes(limit)
            ),
        }),
        _ => Ok(()),
    }
}

/// Threads beyond this multiple of the cores only add scheduling overhead.
pub const THREADS_PER_CORE: usize = 4;

/// The thread count to use for `--threads requested`: at most [`THREADS_PER_CORE`]
/// times the cores, with a note when capped.
pub fn capped_threads(requested: usize) -> (usize, Option<String>) {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    let limit = THREADS_PER_CORE * cores;
    if requested > limit {
        (
            limit,
            Some(format!(
                "--threads {requested} capped at {limit} ({THREADS_PER_CORE} per core on this \
                 {cores}-core machine; results do not depend on it)"
            )),
        )
    } else {
        (requested, None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_size_beyond_the_available_memory_is_refused_with_both_figures() {
        let err = check_memory_against("--particles", "1e10 particles", 8e10, Some(2.4e10))
            .unwrap_err()
            .to_string();
        assert!(err.contains("--particles"), "{err}");
        assert!(err.contains("80.0 GB") && err.contains("24.0 GB"), "{err}");
        assert!(check_memory_against("--particles", "x", 1e9, Some(2.4e10)).is_ok());
        assert!(check_memory_against("--particles", "x", f64::INFINITY, Some(1.0)).is_err());
        assert!(check_memory_against("--particles", "x", 1e30, None).is_ok());
        assert_eq!(human_bytes(512.0), "512 bytes");
        assert_eq!(human_bytes(8e12), "8.0 TB");
    }
}
