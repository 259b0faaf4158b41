//! A team of threads kept for a whole filter run: at every step the leader publishes
//! the step's work, a fixed set of chunks, and every member claims chunks from a shared
//! counter until none is left.
//!
//! # Why
//! A filter step at M = 10 000 is tens of microseconds of work. A rayon fork-join per
//! step wakes a sleeping worker through the kernel; on the 2-vCPU reference VM that
//! cost about 20 µs per step, more than the parallel half of the step saved. The
//! team's helpers instead wait for the next step by spinning. With a fixed split of
//! the chunks, though, the leader had to wait for a helper's share, and on a machine
//! busy with another process the helper is often not running: two threads took 1.4
//! times (spinning helpers) to 6 times (parked helpers) as long as one. Chunks are
//! therefore claimed: the leader works through whatever is left, and waits only for
//! a chunk a helper has started. A helper that waits longer than its spin yields a
//! few times and then parks, so it never burns a core that a busy machine needs;
//! whoever changes the team's state wakes the parked threads (a syscall only when one
//! is parked).
//!
//! Which thread runs a chunk does not matter: every chunk has its own random stream
//! and output slots, and the results are combined in chunk order, so the result is the
//! same on any number of threads.
//!
//! # Protocol
//! The leader resets the count of finished chunks, publishes the command with a new
//! generation and sets the claim ticket to `(generation, 0)` (release). A member claims
//! chunk `k` by moving the ticket from `(generation, k)` to `(generation, k + 1)`
//! (compare-and-swap): a helper still holding an older generation cannot claim. It
//! counts each finished chunk (release); the leader waits until the count reaches the
//! number of chunks (acquire) before it touches the shared buffers again. So between
//! the publication and that moment each chunk's buffers belong to the member that
//! claimed it, and outside it the leader owns all of them.
//!
//! A helper that panics marks the team failed and the leader panics at its next wait
//! instead of waiting forever; the leader stops the team when it returns or unwinds
//! ([`StopOnDrop`]), so the helpers always exit.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering, fence};
use std::sync::{Condvar, Mutex};
use std::time::Duration;

/// Spins before each yield while waiting.
const SPINS: u32 = 1 << 12;

/// Yields (each after a round of spins) before parking.
const YIELDS: u32 = 4;

/// A wait for the helpers' chunks longer than this is a stall: a helper was not
/// running (a chunk is a few microseconds of work).
const STALL: Duration = Duration::from_micros(500);

/// Consecutive commands in which the helpers claimed no chunk before the leader runs
/// alone for a while.
const IDLE_RUNS: usize = 8;

/// Commands the leader runs alone after its first stall (doubled after each further
/// stall).
const SOLO_RUNS: usize = 512;

/// The longest a parked thread sleeps before it looks again (a safety net: every
/// change of the team's state wakes the parked threads).
const PARK_TIMEOUT: Duration = Duration::from_millis(2);

/// The shared state of a team of threads (a leader and its helpers) that run
/// commands of type `C`, each split into chunks.
pub(crate) struct Team<C> {
    generation: AtomicUsize,
    /// `(generation mod 2^32) << 32 | next unclaimed chunk`.
    ticket: AtomicU64,
    /// Chunks finished in the current generation.
    done: AtomicUsize,
    stopped: AtomicBool,
    failed: AtomicBool,
    /// The current command: its generation, its chunk count and itself.
    command: Mutex<Option<(usize, usize, C)>>,
    /// Commands run so far, stalls met, and the run before which the leader works
    /// alone (see [`Team::run`]).
    runs: AtomicUsize,
    stalls: AtomicUsize,
    /// Consecutive commands whose every chunk the leader ran itself.
    idle_runs: AtomicUsize,
    solo_until: AtomicUsize,
    /// Threads parked (or about to park) in [`Team::wait_until`].
    sleepers: AtomicUsize,
    park: Mutex<()>,
    wake: Condvar,
}

impl<C: Copy> Team<C> {
    /// A team; its helpers are the threads that call [`Team::serve`].
    pub fn new() -> Self {
        Team {
            generation: AtomicUsize::new(0),
            ticket: AtomicU64::new(0),
            done: AtomicUsize::new(0),
            stopped: AtomicBool::new(false),
            failed: AtomicBool::new(false),
            command: Mutex::new(None),
            runs: AtomicUsize::new(0),
            stalls: AtomicUsize::new(0),
            idle_runs: AtomicUsize::new(0),
            solo_until: AtomicUsize::new(0),
            sleepers: AtomicUsize::new(0),
            park: Mutex::new(()),
            wake: Condvar::new(),
        }
    }

    /// Spins, then yields, then parks until `done()`.
    fn wait_until(&self, mut done: impl FnMut() -> bool) {
        for _ in 0..YIELDS {
            for _ in 0..SPINS {
                if done() {
                    return;
                }
                std::hint::spin_loop();
            }
            std::thread::yield_now();
        }
        let mut guard = self.park.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            // announce the sleep before the last look: a signaller that changes the
            // state after this look sees the sleeper and wakes it (both SeqCst)
            self.sleepers.fetch_add(1, Ordering::SeqCst);
            if done() {
                self.sleepers.fetch_sub(1, Ordering::SeqCst);
                return;
            }
            guard = self
                .wake
                .wait_timeout(guard, PARK_TIMEOUT)
                .unwrap_or_else(|e| e.into_inner())
                .0;
            self.sleepers.fetch_sub(1, Ordering::SeqCst);
            if done() {
                return;
            }
        }
    }

    /// Wakes the parked threads after a change of the team's state.
    fn signal(&self) {
        fence(Ordering::SeqCst);
        if self.sleepers.load(Ordering::SeqCst) > 0 {
            let _guard = self.park.lock().unwrap_or_else(|e| e.into_inner());
            self.wake.notify_all();
        }
    }

    /// Claims the next chunk of generation `generation` (of `chunks`), if any is left.
    #[inline(always)]
    fn claim(&self, generation: usize, chunks: usize) -> Option<usize> {
        let tag = (generation as u64 & 0xffff_ffff) << 32;
        let mut ticket = self.ticket.load(Ordering::Acquire);
        loop {
            if ticket & !0xffff_ffff != tag {
                return None; // a newer generation: this one is over
            }
            let next = (ticket & 0xffff_ffff) as usize;
            if next >= chunks {
                return None;
            }
            match self.ticket.compare_exchange_weak(
                ticket,
                ticket + 1,
                Ordering::AcqRel,
                Ordering::Acquire,
            ) {
                Ok(_) => return Some(next),
                Err(current) => ticket = current,
            }
        }
    }

    /// Runs the chunks this member can claim, counting each one finished.
    #[inline(always)] // the leader's chunks compile for its vector set (`simd::dispatch`)
    fn work_through(
        &self,
        generation: usize,
        chunks: usize,
        command: C,
        work: &mut impl FnMut(C, usize),
    ) -> usize {
        let mut ran = 0;
        while let Some(chunk) = self.claim(generation, chunks) {
            work(command, chunk);
            ran += 1;
            if self.done.fetch_add(1, Ordering::Release) + 1 == chunks {
                self.signal();
            }
        }
        ran
    }

    /// The leader runs alone for the next runs (twice as many after each time).
    fn go_solo(&self, runs: usize) {
        let times = self.stalls.fetch_add(1, Ordering::Relaxed).min(16);
        self.solo_until
            .store(runs + (SOLO_RUNS << times), Ordering::Relaxed);
    }

    /// Leader: runs `command`'s `chunks` chunks with the helpers (`work(command, k)`
    /// runs chunk `k`) and returns when every chunk is finished.
    ///
    /// After a stall (the leader waited more than [`STALL`] for a helper's chunk: the
    /// helper was descheduled by another process), or after [`IDLE_RUNS`] commands in
    /// a row that the helpers did not help with, the leader runs alone for a while,
    /// twice as long each time, then tries the team again.
    ///
    /// # Panics
    /// If a helper panicked (its panic is then reported when the team's scope ends).
    #[inline(always)] // the leader's chunks compile for its vector set (`simd::dispatch`)
    pub fn run(&self, command: C, chunks: usize, mut work: impl FnMut(C, usize)) {
        let runs = self.runs.fetch_add(1, Ordering::Relaxed);
        if runs < self.solo_until.load(Ordering::Relaxed) {
            for chunk in 0..chunks {
                work(command, chunk);
            }
            return;
        }
        let generation = self.generation.load(Ordering::Relaxed) + 1;
        // no chunk of the last generation is running: they all finished before the
        // last `run` returned, and a late helper's claim fails on the new tag
        self.done.store(0, Ordering::Relaxed);
        *self.command.lock().unwrap_or_else(|e| e.into_inner()) =
            Some((generation, chunks, command));
        self.ticket
            .store((generation as u64 & 0xffff_ffff) << 32, Ordering::Release);
        self.generation.store(generation, Ordering::Release);
        self.signal();
        let alone = self.work_through(generation, chunks, command, &mut work) == chunks;
        let waiting = std::time::Instant::now();
        self.wait_until(|| {
            assert!(
                !self.failed.load(Ordering::Relaxed),
                "a particle filter team thread panicked"
            );
            self.done.load(Ordering::Acquire) == chunks
        });
        // the helpers did nothing for a while (they are not getting a core): waking
        // them costs the leader a syscall per command for no help
        let idle = if alone {
            self.idle_runs.fetch_add(1, Ordering::Relaxed) + 1
        } else {
            self.idle_runs.store(0, Ordering::Relaxed);
            0
        };
        if waiting.elapsed() > STALL || idle >= IDLE_RUNS {
            self.idle_runs.store(0, Ordering::Relaxed);
            self.go_solo(runs);
        }
    }

    /// Helper: claims and runs chunks of every command until the team stops.
    pub fn serve(&self, mut work: impl FnMut(C, usize)) {
        let failure = MarkFailedOnUnwind(self);
        let mut seen = 0;
        loop {
            self.wait_until(|| {
                self.stopped.load(Ordering::Acquire)
                    || self.generation.load(Ordering::Acquire) > seen
            });
            if self.generation.load(Ordering::Acquire) == seen {
                break; // stopped, with no command pending
            }
            let current = *self.command.lock().unwrap_or_else(|e| e.into_inner());
            let (generation, chunks, command) =
                current.expect("a command is published before its generation");
            // a helper that slept through generations joins the latest
            seen = generation;
            self.work_through(generation, chunks, command, &mut work);
        }
        std::mem::forget(failure);
    }

    /// Leader: a guard that stops the helpers when dropped (also while unwinding).
    pub fn stop_on_drop(&self) -> StopOnDrop<'_, C> {
        StopOnDrop(self)
    }
}

/// Stops a team's helpers when dropped.
pub(crate) struct StopOnDrop<'a, C: Copy>(&'a Team<C>);

impl<C: Copy> Drop for StopOnDrop<'_, C> {
    fn drop(&mut self) {
        self.0.stopped.store(true, Ordering::Release);
        self.0.signal();
    }
}

/// Marks a team failed when a helper unwinds (and wakes a parked leader).
struct MarkFailedOnUnwind<'a, C: Copy>(&'a Team<C>);

impl<C: Copy> Drop for MarkFailedOnUnwind<'_, C> {
    fn drop(&mut self) {
        self.0.failed.store(true, Ordering::Relaxed);
        self.0.signal();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every chunk of every command runs exactly once, before `run` returns, whichever
    /// member claims it.
    #[test]
    fn every_chunk_of_every_command_runs_once() {
        const CHUNKS: usize = 7;
        let team = Team::<usize>::new();
        let counts: Vec<AtomicUsize> = (0..500 * CHUNKS).map(|_| AtomicUsize::new(0)).collect();
        let tally = |command: usize, chunk: usize| {
            counts[command * CHUNKS + chunk].fetch_add(1, Ordering::Relaxed);
        };
        std::thread::scope(|scope| {
            for _ in 1..3 {
                let (team, tally) = (&team, &tally);
                scope.spawn(move || team.serve(tally));
            }
            let _stop = team.stop_on_drop();
            for command in 0..500 {
                team.run(command, CHUNKS, &tally);
                for chunk in 0..CHUNKS {
                    assert_eq!(counts[command * CHUNKS + chunk].load(Ordering::Relaxed), 1);
                }
            }
        });
    }

    /// A helper that waits long parks instead of spinning (the leader sees it among
    /// the sleepers), is woken, and takes part again: with the leader's chunks slow,
    /// the helper claims some of them.
    #[test]
    fn a_long_wait_parks_the_helper_and_it_still_claims_chunks() {
        let team = Team::<usize>::new();
        let by_helper = AtomicUsize::new(0);
        std::thread::scope(|scope| {
            let (team_ref, by_helper_ref) = (&team, &by_helper);
            scope.spawn(move || {
                team_ref.serve(|_, _| {
                    by_helper_ref.fetch_add(1, Ordering::Relaxed);
                    std::thread::sleep(Duration::from_millis(2));
                })
            });
            let _stop = team.stop_on_drop();
            for command in 0..3 {
                // long enough for the helper to spin, yield and park (between two timed
                // waits the count drops for a moment: look again)
                std::thread::sleep(Duration::from_millis(30));
                let parked = (0..200).any(|_| {
                    let seen = team.sleepers.load(Ordering::SeqCst) == 1;
                    if !seen {
                        std::thread::sleep(Duration::from_micros(100));
                    }
                    seen
                });
                assert!(parked, "helper parked");
                team.run(command, 20, |_, _| {
                    std::thread::sleep(Duration::from_millis(2))
                });
            }
        });
        assert!(
            by_helper.load(Ordering::Relaxed) > 0,
            "the helper woke and worked"
        );
    }

    #[test]
    fn a_panicking_helper_fails_the_leader_instead_of_hanging() {
        let result = std::panic::catch_unwind(|| {
            let team = Team::<usize>::new();
            std::thread::scope(|scope| {
                scope.spawn(|| team.serve(|_, _| panic!("model failure")));
                let _stop = team.stop_on_drop();
                // slow chunks, so that the helper claims one
                team.run(0, 50, |_, _| std::thread::sleep(Duration::from_millis(5)));
            });
        });
        assert!(result.is_err());
    }
}
