//! Several files at once: how the cores are shared between files ([`ThreadBudget`]) and the
//! runner that gives every file in flight its own compute pool ([`run_batch`]).
//!
//! One file already keeps every core busy: the pipeline's kernels (DVO, detector, pyramid) are
//! row-parallel on rayon. Running two files on the same pool then only adds fork/join and
//! spin-waiting between them. So each file in flight gets a rayon pool of its own with its
//! share of the cores: with as many files as cores each file runs sequentially inside (the
//! pool has one thread, so its parallel loops run inline) and the files scale across cores;
//! a single file still gets all of them.
//!
//! The outputs do not depend on the split: every parallel reduction in the pipeline combines
//! its parts in a fixed order (see `dvo::residuals::accumulate_normal_equations`), and the
//! row-parallel kernels write disjoint rows.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use crate::error::{Error, Result};

/// The number of cores this process may use (`std::thread::available_parallelism`, which
/// honours CPU affinity and cgroup quotas), at least 1.
pub fn available_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// How a batch of files shares the cores: how many files run at the same time and how many
/// compute threads each file's pipeline gets.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ThreadBudget {
    /// Compute threads of each file slot, one entry per file processed at the same time.
    threads_per_slot: Vec<usize>,
}

impl ThreadBudget {
    /// The budget for `inputs` files on `cores` cores.
    ///
    /// - `jobs`: files processed at the same time; `None` = one per core. Never more than
    ///   `inputs`; above `cores` it is honoured (the files then share the cores by time slicing,
    ///   which only helps when the files wait on a slow disk).
    /// - `threads_per_file`: compute threads of each file's pipeline; `None` = the cores split
    ///   evenly between the files in flight, at least one each (with 3 cores and 2 files, the
    ///   first slot gets 2 and the second 1, so no core idles).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] when `jobs` or `threads_per_file` is 0.
    pub fn new(
        cores: usize,
        inputs: usize,
        jobs: Option<usize>,
        threads_per_file: Option<usize>,
    ) -> Result<Self> {
        let positive = |name: &'static str, value: Option<usize>| match value {
            Some(0) => Err(Error::InvalidParameter {
                name,
                value: "0".into(),
                expected: "at least 1".into(),
            }),
            other => Ok(other),
        };
        let jobs = positive("jobs", jobs)?;
        let threads_per_file = positive("threads_per_file", threads_per_file)?;
        let cores = cores.max(1);
        let slots = jobs.unwrap_or(cores).min(inputs).max(1);
        let threads_per_slot = (0..slots)
            .map(|slot| match threads_per_file {
                Some(n) => n,
                // The remainder of the division goes to the first slots, one core each.
                None => (cores / slots + usize::from(slot < cores % slots)).max(1),
            })
            .collect();
        Ok(Self { threads_per_slot })
    }

    /// Files processed at the same time.
    pub fn files_in_flight(&self) -> usize {
        self.threads_per_slot.len()
    }

    /// Compute threads of file slot `slot` (`0..files_in_flight()`); 1 past the last slot.
    pub fn threads_for_slot(&self, slot: usize) -> usize {
        self.threads_per_slot.get(slot).copied().unwrap_or(1)
    }

    /// Compute threads of all slots together.
    pub fn total_threads(&self) -> usize {
        self.threads_per_slot.iter().sum()
    }

    /// Compute threads per file as one would say it: `"2"`, or `"1-2"` when the cores do not
    /// divide evenly.
    pub fn threads_per_file_text(&self) -> String {
        let lo = self.threads_per_slot.iter().min().copied().unwrap_or(1);
        let hi = self.threads_per_slot.iter().max().copied().unwrap_or(1);
        if lo == hi {
            lo.to_string()
        } else {
            format!("{lo}-{hi}")
        }
    }
}

/// Runs `work(0)`, …, `work(count - 1)` with [`ThreadBudget::files_in_flight`] of them at a
/// time, each inside its slot's own rayon pool (so the pipeline's parallel loops in `work` use
/// that slot's threads only), and returns the results in index order. Work is handed out in
/// index order as slots become free.
///
/// A slot is a plain thread that waits (blocked, not spinning) while its pool runs the work;
/// pool threads are named `occmask-file<slot>-<thread>`.
///
/// # Errors
/// [`Error::ThreadPool`] when the operating system refuses to start a pool's threads (nothing
/// has run then).
///
/// # Panics
/// Re-raises a panic of `work` after the other slots have finished.
pub fn run_batch<T, F>(count: usize, budget: &ThreadBudget, work: F) -> Result<Vec<T>>
where
    T: Send,
    F: Fn(usize) -> T + Sync,
{
    let slots = budget.files_in_flight().min(count);
    let pools = (0..slots)
        .map(|slot| {
            let threads = budget.threads_for_slot(slot);
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .thread_name(move |i| format!("occmask-file{slot}-{i}"))
                .build()
                .map_err(|cause| Error::ThreadPool { threads, cause })
        })
        .collect::<Result<Vec<_>>>()?;
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<T>>> = Mutex::new((0..count).map(|_| None).collect());
    std::thread::scope(|scope| {
        for pool in &pools {
            let (next, results, work) = (&next, &results, &work);
            scope.spawn(move || loop {
                let index = next.fetch_add(1, Ordering::Relaxed);
                if index >= count {
                    break;
                }
                let result = pool.install(|| work(index));
                // A poisoned lock means another slot panicked: the scope re-raises that panic.
                if let Ok(mut r) = results.lock() {
                    r[index] = Some(result);
                }
            });
        }
    });
    let results = results
        .into_inner()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    Ok(results.into_iter().flatten().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn slots(b: &ThreadBudget) -> Vec<usize> {
        (0..b.files_in_flight()).map(|s| b.threads_for_slot(s)).collect()
    }

    #[test]
    fn default_budget_splits_the_cores_between_the_files_in_flight() {
        // One file gets every core; as many files as cores run one thread each.
        assert_eq!(slots(&ThreadBudget::new(2, 1, None, None).unwrap()), [2]);
        assert_eq!(slots(&ThreadBudget::new(2, 2, None, None).unwrap()), [1, 1]);
        // More files than cores: one slot per core, the rest wait their turn.
        assert_eq!(slots(&ThreadBudget::new(2, 4, None, None).unwrap()), [1, 1]);
        assert_eq!(slots(&ThreadBudget::new(8, 2, None, None).unwrap()), [4, 4]);
        // Uneven: the first slots take the remainder, no core idles.
        assert_eq!(slots(&ThreadBudget::new(3, 2, None, None).unwrap()), [2, 1]);
        assert_eq!(slots(&ThreadBudget::new(8, 3, None, None).unwrap()), [3, 3, 2]);
        for cores in 1..=16 {
            for inputs in 1..=20 {
                let b = ThreadBudget::new(cores, inputs, None, None).unwrap();
                assert_eq!(b.files_in_flight(), cores.min(inputs));
                assert_eq!(b.total_threads(), cores, "{cores} cores, {inputs} inputs");
            }
        }
    }

    #[test]
    fn jobs_and_threads_per_file_override_the_split() {
        // --jobs 1: files one after the other, each with every core.
        assert_eq!(slots(&ThreadBudget::new(2, 4, Some(1), None).unwrap()), [2]);
        // --jobs above the core count is honoured (one thread each), never above the inputs.
        assert_eq!(
            slots(&ThreadBudget::new(2, 4, Some(4), None).unwrap()),
            [1, 1, 1, 1]
        );
        assert_eq!(slots(&ThreadBudget::new(2, 3, Some(8), None).unwrap()), [1, 1, 1]);
        // --threads-per-file as given, even oversubscribed.
        assert_eq!(slots(&ThreadBudget::new(2, 1, None, Some(1)).unwrap()), [1]);
        assert_eq!(slots(&ThreadBudget::new(2, 2, None, Some(2)).unwrap()), [2, 2]);
        // No cores reported and no inputs still give one slot of one thread.
        assert_eq!(slots(&ThreadBudget::new(0, 0, None, None).unwrap()), [1]);
        assert_eq!(
            ThreadBudget::new(3, 2, None, None)
                .unwrap()
                .threads_per_file_text(),
            "1-2"
        );
        assert_eq!(
            ThreadBudget::new(4, 2, None, None)
                .unwrap()
                .threads_per_file_text(),
            "2"
        );
        for (jobs, threads) in [(Some(0), None), (None, Some(0))] {
            let e = ThreadBudget::new(2, 2, jobs, threads).unwrap_err();
            assert!(matches!(e, Error::InvalidParameter { .. }), "{e}");
        }
    }

    #[test]
    fn each_slot_runs_in_its_own_pool_of_its_size() {
        let budget = ThreadBudget::new(3, 5, Some(2), None).unwrap();
        let seen = run_batch(5, &budget, |i| {
            let name = std::thread::current()
                .name()
                .map(str::to_owned)
                .unwrap_or_default();
            (i, rayon::current_num_threads(), name)
        })
        .unwrap();
        assert_eq!(seen.iter().map(|s| s.0).collect::<Vec<_>>(), [0, 1, 2, 3, 4]);
        for (i, threads, name) in &seen {
            let slot: usize = name
                .strip_prefix("occmask-file")
                .and_then(|r| r.split('-').next())
                .and_then(|s| s.parse().ok())
                .unwrap_or_else(|| panic!("item {i} ran on thread {name:?}"));
            assert_eq!(*threads, budget.threads_for_slot(slot), "item {i} on {name}");
        }
    }

    #[test]
    fn slots_run_at_the_same_time_and_no_more() {
        use std::sync::atomic::AtomicUsize;
        use std::time::Duration;
        for jobs in [1, 2, 3] {
            let budget = ThreadBudget::new(2, 6, Some(jobs), None).unwrap();
            let (running, peak) = (AtomicUsize::new(0), AtomicUsize::new(0));
            run_batch(6, &budget, |_| {
                let now = running.fetch_add(1, Ordering::SeqCst) + 1;
                peak.fetch_max(now, Ordering::SeqCst);
                // Wait (up to a generous 10 s, for a loaded machine) until `jobs` items run
                // at once: that fails only if the slots do not run side by side.
                let start = std::time::Instant::now();
                while peak.load(Ordering::SeqCst) < jobs && start.elapsed() < Duration::from_secs(10) {
                    std::thread::sleep(Duration::from_millis(1));
                }
                running.fetch_sub(1, Ordering::SeqCst);
            })
            .unwrap();
            assert_eq!(peak.load(Ordering::SeqCst), jobs);
        }
    }

    #[test]
    fn empty_batch_runs_nothing() {
        let budget = ThreadBudget::new(2, 0, None, None).unwrap();
        let out: Vec<usize> = run_batch(0, &budget, |i| i).unwrap();
        assert!(out.is_empty());
    }
}
