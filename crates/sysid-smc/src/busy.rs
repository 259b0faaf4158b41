//! How many processors are free right now: a filter team needs a processor per member,
//! and a helper that has to share one with another process makes the team slower than
//! its leader alone.
//!
//! # Method
//! Linux counts the runnable threads of the whole machine in `/proc/stat`
//! (`procs_running`); less this process's own runnable threads (`/proc/self/task`),
//! the least of a few looks, that is what other processes keep busy. With `P`
//! processors, the rest are free for this thread and its helpers. Elsewhere, or when the file cannot be
//! read, every processor counts as free.

/// The processors free for the calling thread and its helpers (at least 1), or `None`
/// where the machine does not say.
pub(crate) fn free_processors() -> Option<usize> {
    // the least of a few looks: a process that runs for moments (a daemon, a shell)
    // is not a competitor, a CPU-bound one is in every look
    let others = (0..LOOKS).map(|_| others_running()).min()??;
    let processors = std::thread::available_parallelism().ok()?.get();
    Some(processors.saturating_sub(others).max(1))
}

/// Looks at `/proc/stat` this many times.
const LOOKS: usize = 3;

/// Runnable threads of other processes: the machine's, less this process's (its
/// thread pool's workers, just started or spinning before they sleep, are not
/// competitors).
fn others_running() -> Option<usize> {
    let all = running_threads()?;
    if all <= 1 {
        return Some(0);
    }
    Some(all.saturating_sub(own_running().unwrap_or(1)))
}

/// This process's runnable threads (the state field of each `/proc/self/task/*/stat`).
fn own_running() -> Option<usize> {
    let mut running = 0;
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let stat = std::fs::read_to_string(task.ok()?.path().join("stat")).ok()?;
        // `pid (comm) S ...`: the state follows the last parenthesis
        let state = stat.rsplit_once(')')?.1.trim_start().chars().next()?;
        if state == 'R' {
            running += 1;
        }
    }
    Some(running.max(1))
}

/// The machine's runnable threads now (`procs_running`).
fn running_threads() -> Option<usize> {
    let text = std::fs::read_to_string("/proc/stat").ok()?;
    text.lines()
        .find_map(|l| l.strip_prefix("procs_running "))?
        .trim()
        .parse()
        .ok()
}

#[cfg(test)]
mod tests {
    /// On Linux the count exists and lies between 1 and the processors.
    #[test]
    #[cfg(target_os = "linux")]
    fn free_processors_is_between_one_and_the_processors() {
        let free = super::free_processors().expect("/proc/stat on Linux");
        let processors = std::thread::available_parallelism().unwrap().get();
        assert!((1..=processors).contains(&free), "{free} of {processors}");
    }
}
