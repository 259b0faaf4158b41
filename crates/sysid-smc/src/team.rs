//! A team of threads kept for a whole filter run, woken at every step by spinning.
//!
//! # Why
//! A filter step at M = 10 000 is tens of microseconds of work. A rayon fork-join per
//! step wakes a sleeping worker through the kernel; on the 2-vCPU reference VM that
//! cost about 20 µs per step, more than the parallel half of the step saved (the
//! 2-thread filter was slower than the 1-thread one). The team's helpers instead
//! wait for the next step by spinning (then yielding, so that an oversubscribed
//! machine still makes progress), and the step's start and end are two atomic
//! counters.
//!
//! # Protocol
//! The leader (the thread running the filter) publishes a command and bumps the
//! generation (release); each helper sees the new generation (acquire), runs its part
//! and counts itself finished (release); the leader waits until every helper has
//! finished the generation (acquire) before it touches the shared buffers again. So
//! between `start` and `wait` the helpers own their parts of the buffers, and outside
//! that window the leader owns all of them.
//!
//! A helper that panics marks the team failed and the leader panics at its next wait
//! instead of waiting forever; the leader stops the team when it returns or unwinds
//! ([`StopOnDrop`]), so the helpers always exit.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Spins before each yield while waiting.
const SPINS: u32 = 1 << 12;

/// The shared state of a team of `members` threads (the leader and `members - 1`
/// helpers) that run commands of type `C`.
pub(crate) struct Team<C> {
    members: usize,
    generation: AtomicUsize,
    finished: AtomicUsize,
    stopped: AtomicBool,
    failed: AtomicBool,
    command: Mutex<Option<C>>,
}

impl<C: Copy> Team<C> {
    /// A team of `members >= 1` threads.
    pub fn new(members: usize) -> Self {
        Team {
            members,
            generation: AtomicUsize::new(0),
            finished: AtomicUsize::new(0),
            stopped: AtomicBool::new(false),
            failed: AtomicBool::new(false),
            command: Mutex::new(None),
        }
    }

    /// The number of threads, the leader included.
    pub fn members(&self) -> usize {
        self.members
    }

    /// Leader: publishes `command` and starts the helpers on it.
    pub fn start(&self, command: C) {
        *self.command.lock().unwrap_or_else(|e| e.into_inner()) = Some(command);
        self.generation.fetch_add(1, Ordering::Release);
    }

    /// Leader: waits until every helper has finished the last command.
    ///
    /// # Panics
    /// If a helper panicked (its panic is then reported when the team's scope ends).
    pub fn wait(&self) {
        let target = (self.members - 1) * self.generation.load(Ordering::Relaxed);
        spin_until(|| {
            assert!(
                !self.failed.load(Ordering::Relaxed),
                "a particle filter team thread panicked"
            );
            self.finished.load(Ordering::Acquire) == target
        });
    }

    /// Helper: runs `work` on every command until the team stops.
    pub fn serve(&self, mut work: impl FnMut(C)) {
        let failure = MarkFailedOnUnwind(&self.failed);
        let mut seen = 0;
        loop {
            spin_until(|| {
                self.stopped.load(Ordering::Acquire)
                    || self.generation.load(Ordering::Acquire) > seen
            });
            if self.generation.load(Ordering::Acquire) == seen {
                break; // stopped, with no command pending
            }
            seen += 1;
            let command = self.command.lock().unwrap_or_else(|e| e.into_inner());
            let command = command.expect("a command is published before its generation");
            work(command);
            self.finished.fetch_add(1, Ordering::Release);
        }
        std::mem::forget(failure);
    }

    /// Leader: a guard that stops the helpers when dropped (also while unwinding).
    pub fn stop_on_drop(&self) -> StopOnDrop<'_> {
        StopOnDrop(&self.stopped)
    }
}

/// Stops a team's helpers when dropped.
pub(crate) struct StopOnDrop<'a>(&'a AtomicBool);

impl Drop for StopOnDrop<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
    }
}

/// Marks a team failed when a helper unwinds.
struct MarkFailedOnUnwind<'a>(&'a AtomicBool);

impl Drop for MarkFailedOnUnwind<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// Spins (then yields) until `done()`.
fn spin_until(mut done: impl FnMut() -> bool) {
    loop {
        for _ in 0..SPINS {
            if done() {
                return;
            }
            std::hint::spin_loop();
        }
        std::thread::yield_now();
    }
}

/// The chunks `[first, last)` of `member` when `chunks` are split into `members`
/// contiguous ranges as equal as possible.
pub(crate) fn member_chunks(member: usize, members: usize, chunks: usize) -> (usize, usize) {
    (member * chunks / members, (member + 1) * chunks / members)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn members_split_the_chunks_exactly() {
        for members in 1..6 {
            for chunks in members..40 {
                let mut next = 0;
                for member in 0..members {
                    let (first, last) = member_chunks(member, members, chunks);
                    assert_eq!(first, next);
                    assert!(last > first, "every member has a chunk");
                    next = last;
                }
                assert_eq!(next, chunks);
            }
        }
    }

    /// Every helper runs every command once, in order, between `start` and `wait`.
    #[test]
    fn helpers_run_each_command_between_start_and_wait() {
        let team = Team::<usize>::new(3);
        let runs: Vec<AtomicUsize> = (0..3).map(|_| AtomicUsize::new(0)).collect();
        std::thread::scope(|scope| {
            for member in 1..3 {
                let (team, runs) = (&team, &runs);
                scope.spawn(move || {
                    team.serve(|command| {
                        // commands arrive in order, one at a time
                        assert_eq!(runs[member].load(Ordering::Relaxed), command);
                        runs[member].fetch_add(1, Ordering::Relaxed);
                    })
                });
            }
            let _stop = team.stop_on_drop();
            for command in 0..500 {
                team.start(command);
                team.wait();
                for runs in &runs[1..] {
                    assert_eq!(runs.load(Ordering::Relaxed), command + 1);
                }
            }
        });
    }

    #[test]
    fn a_panicking_helper_fails_the_leader_instead_of_hanging() {
        let result = std::panic::catch_unwind(|| {
            let team = Team::<usize>::new(2);
            std::thread::scope(|scope| {
                scope.spawn(|| team.serve(|_| panic!("model failure")));
                let _stop = team.stop_on_drop();
                team.start(0);
                team.wait();
            });
        });
        assert!(result.is_err());
    }
}
