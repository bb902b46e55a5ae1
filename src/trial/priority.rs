//! Scheduling priority of the log-writer thread, the control thread's timer slack, and the
//! report of which threads run under `SCHED_FIFO` (`robot_io::realtime`, `[realtime]`).
//!
//! The control thread and (on `--robot emulator`) the emulator's clock must wake within a
//! fraction of a 2 ms cycle. The log writer works in bursts: it formats what the control
//! thread recorded and, after each second of trial time, may close and compress a trial.mcap
//! chunk. It therefore runs at nice [`BACKGROUND_NICE`] ([`lower_this_thread`]): a smaller
//! share of CPU against threads of normal priority, so a waking control thread or emulator
//! clock is preferred to it, while it still keeps up under load (the log ring holds 8 s).
//! Lowering its own priority needs no privilege.
//!
//! Not lowered, on measurement (issue 10's note, session 8): the cue cycle. Its gaps in the
//! control loop's samples (15–25 ms of controller time after each 30 Hz cue tick at speedup
//! 4) went away with the cue cycle at `SCHED_IDLE`, but at nice 10 already a debug build at
//! speedup 10 starved it: the trial's mean time scale fell to 0.09 and the emulator trial test
//! failed. The assessment is part of the trial, not a background job.
//!
//! The control thread waits for a controller sample by napping `backend::POLL_NAP` (50 µs)
//! between polls. Linux lets a sleep run late by the thread's *timer slack* (50 µs by
//! default), which would double each nap; [`tighten_timer_slack`] lowers it to
//! [`CONTROL_TIMER_SLACK_NS`] for that thread.

/// Warns (once per call) that `what` asked for real-time scheduling and the OS refused it.
pub(crate) fn warn_if_refused(what: &str, got: &Scheduling) {
    if let Scheduling::Refused { .. } = got {
        tracing::warn!(
            "{what}: {got}; the control cycle may then miss samples under load (README, \"Real-time priorities\")"
        );
    }
}

/// How the threads of an RTDE trial were scheduled: `summary.json`'s `motion.scheduling`.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub(crate) struct SchedulingSummary {
    /// The control thread.
    pub(crate) control: String,
    /// The RTDE client's I/O threads.
    pub(crate) rtde_io: Option<String>,
    /// The in-process emulator's clock thread (`None`: no emulator, or a tokio-task clock).
    pub(crate) emulator_clock: Option<String>,
}

use robot_io::realtime::Scheduling;

/// The control thread's timer slack [ns]: 10 µs.
pub(crate) const CONTROL_TIMER_SLACK_NS: u64 = 10_000;

/// Lowers the calling thread's timer slack to [`CONTROL_TIMER_SLACK_NS`] (no privilege
/// needed). On an error (logged at debug level) the thread keeps its slack.
pub(crate) fn tighten_timer_slack() {
    if let Err(e) = imp::set_timer_slack_ns(CONTROL_TIMER_SLACK_NS) {
        tracing::debug!("the control thread keeps its timer slack: {e}");
    }
}

/// The nice value of the log-writer thread [-]: 10 (CFS weight 110 against 1024 at nice 0).
pub(crate) const BACKGROUND_NICE: i32 = 10;

/// Lowers the calling thread to nice [`BACKGROUND_NICE`] (never raising it if it is already
/// lower in priority), for good: meant for a spawned thread that ends with its background
/// work (the threads it would spawn inherit the value, and raising it back needs
/// `CAP_SYS_NICE`). On an error (logged at debug level) the thread goes on at its priority.
pub(crate) fn lower_this_thread() {
    match imp::nice() {
        Some(n) if n < BACKGROUND_NICE => {
            if let Err(e) = imp::set_nice(BACKGROUND_NICE) {
                tracing::debug!("thread stays at nice {n}: {e}");
            }
        }
        _ => {}
    }
}

#[cfg(target_os = "linux")]
mod imp {
    fn tid() -> libc::id_t {
        // SAFETY: gettid has no preconditions; a thread id is positive.
        unsafe { libc::gettid() as libc::id_t }
    }

    /// The calling thread's nice value (`None` if unknown).
    pub(super) fn nice() -> Option<i32> {
        // SAFETY: getpriority takes and returns plain integers; errno is thread-local and
        // tells an error from the value −1.
        unsafe {
            *libc::__errno_location() = 0;
            let n = libc::getpriority(libc::PRIO_PROCESS, tid());
            (*libc::__errno_location() == 0).then_some(n)
        }
    }

    /// Sets the calling thread's timer slack [ns].
    pub(super) fn set_timer_slack_ns(ns: u64) -> std::io::Result<()> {
        let ns = libc::c_ulong::try_from(ns).map_err(std::io::Error::other)?;
        // SAFETY: PR_SET_TIMERSLACK takes one integer argument; no memory is touched.
        if unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, ns, 0, 0, 0) } == 0 {
            Ok(())
        } else {
            Err(std::io::Error::last_os_error())
        }
    }

    /// The calling thread's timer slack [ns] (`None` on an error).
    #[cfg(test)]
    pub(super) fn timer_slack_ns() -> Option<u64> {
        // SAFETY: PR_GET_TIMERSLACK takes no argument and returns the slack.
        let r = unsafe { libc::prctl(libc::PR_GET_TIMERSLACK, 0, 0, 0, 0) };
        u64::try_from(r).ok()
    }

    /// Sets the calling thread's nice value (on Linux a nice value belongs to one thread).
    pub(super) fn set_nice(n: i32) -> std::io::Result<()> {
        // SAFETY: plain integers; no memory of ours is touched.
        if unsafe { libc::setpriority(libc::PRIO_PROCESS, tid(), n) } == 0 {
            Ok(())
        } else {
            Err(std::io::Error::last_os_error())
        }
    }
}

/// Elsewhere threads keep their priority and timer slack.
#[cfg(not(target_os = "linux"))]
mod imp {
    pub(super) fn set_timer_slack_ns(_ns: u64) -> std::io::Result<()> {
        Ok(())
    }

    pub(super) fn nice() -> Option<i32> {
        None
    }

    pub(super) fn set_nice(_n: i32) -> std::io::Result<()> {
        Ok(())
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    /// A nice value is per thread: a thread that lowers itself has BACKGROUND_NICE, and the
    /// thread that spawned it keeps its own.
    #[test]
    fn lowering_a_thread_changes_only_that_thread() {
        let before = imp::nice().expect("nice value");
        let (start, lowered) = std::thread::spawn(|| {
            let start = imp::nice();
            lower_this_thread();
            (start, imp::nice())
        })
        .join()
        .expect("thread");
        assert_eq!(
            start,
            Some(before),
            "a thread starts at its creator's value"
        );
        assert_eq!(lowered, Some(BACKGROUND_NICE.max(before)));
        assert_eq!(
            imp::nice(),
            Some(before),
            "the spawning thread is unchanged"
        );
    }

    /// The timer slack is per thread too: a thread that tightens it has
    /// CONTROL_TIMER_SLACK_NS, and the thread that spawned it keeps its own.
    #[test]
    fn tightening_the_timer_slack_changes_only_that_thread() {
        let before = imp::timer_slack_ns().expect("timer slack");
        let tightened = std::thread::spawn(|| {
            tighten_timer_slack();
            imp::timer_slack_ns()
        })
        .join()
        .expect("thread");
        assert_eq!(tightened, Some(CONTROL_TIMER_SLACK_NS));
        assert_eq!(imp::timer_slack_ns(), Some(before));
    }
}
