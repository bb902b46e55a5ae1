//! Real-time scheduling of the threads a 2 ms control cycle waits on.
//!
//! A control cycle is only as punctual as the slowest thread on its path: the controller's
//! clock (the emulator's, when it stands in for one), the thread that receives RTDE samples
//! and writes commands, and the control thread itself. Under Linux's normal scheduler
//! (`SCHED_OTHER`) a thread that wakes can wait for another process's time slice. ur_rtde
//! therefore lets its receive and control threads run under `SCHED_FIFO` when given a priority
//! (its real-time examples: receive 90, control 85), and so does the trial (`[realtime]` in
//! `config/trial.toml`, off by default as in ur_rtde): [`set_current_thread`] puts the calling
//! thread under `SCHED_FIFO` at a [`RtPriority`]. A `SCHED_FIFO` thread that rarely sleeps
//! takes its core from every normal thread, so the threads given a priority must be the ones
//! that wait most of each cycle.
//!
//! This needs `CAP_SYS_NICE` or an `RLIMIT_RTPRIO` of at least the priority (on a lab PC:
//! `@realtime - rtprio 99` in `/etc/security/limits.conf`). Without it the call fails with the
//! OS error and the thread keeps its scheduling; the caller reports that
//! ([`Scheduling::Refused`]) instead of pretending. Linux's real-time throttling
//! (`kernel.sched_rt_runtime_us`, 95 % by default) leaves normal threads 5 % of the CPU:
//! enough to stop a runaway real-time thread, not to run a trial's cue cycle beside one.
//! Elsewhere than on Linux nothing is changed.
//!
//! # Example
//! ```
//! use robot_io::realtime::{RtPriority, Scheduling, current_thread, set_current_thread};
//!
//! let p = RtPriority::new(85)?;
//! let outcome = std::thread::spawn(move || (set_current_thread(p), current_thread()))
//!     .join()
//!     .expect("thread");
//! match outcome {
//!     (Scheduling::Fifo(got), Some(Scheduling::Fifo(now))) => assert_eq!((got, now), (p, p)),
//!     (Scheduling::Refused { .. }, now) => assert!(!matches!(now, Some(Scheduling::Fifo(_)))),
//!     other => panic!("{other:?}"),
//! }
//! # Ok::<(), robot_io::RobotIoError>(())
//! ```

use std::fmt;

use crate::{Result, RobotIoError};

/// A `SCHED_FIFO` priority [-], in [1, 99] (Linux's range for real-time threads).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct RtPriority(u8);

impl RtPriority {
    /// Lowest real-time priority [-].
    pub const MIN: u8 = 1;
    /// Highest real-time priority [-].
    pub const MAX: u8 = 99;

    /// `priority` [-] if it is in [`Self::MIN`, `Self::MAX`].
    pub fn new(priority: u8) -> Result<Self> {
        if (Self::MIN..=Self::MAX).contains(&priority) {
            Ok(Self(priority))
        } else {
            Err(RobotIoError::InvalidConfig {
                reason: format!(
                    "real-time priority {priority} must be in [{}, {}]",
                    Self::MIN,
                    Self::MAX
                ),
            })
        }
    }

    /// The priority [-].
    pub fn get(self) -> u8 {
        self.0
    }
}

/// How a thread is scheduled.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Scheduling {
    /// `SCHED_FIFO` at this priority.
    Fifo(RtPriority),
    /// The normal scheduler: real time was not asked for (or the thread is not `SCHED_FIFO`).
    Normal,
    /// `SCHED_FIFO` at `priority` was asked for and the OS refused: the normal scheduler.
    Refused {
        /// The priority asked for.
        priority: RtPriority,
        /// The OS error.
        reason: String,
    },
}

impl Scheduling {
    /// Whether the thread runs under `SCHED_FIFO`.
    pub fn is_realtime(&self) -> bool {
        matches!(self, Self::Fifo(_))
    }
}

impl fmt::Display for Scheduling {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Fifo(p) => write!(f, "SCHED_FIFO {}", p.get()),
            Self::Normal => write!(f, "normal"),
            Self::Refused { priority, reason } => {
                write!(
                    f,
                    "normal (SCHED_FIFO {} refused: {reason})",
                    priority.get()
                )
            }
        }
    }
}

/// Puts the calling thread under `SCHED_FIFO` at `priority`, or leaves it as it is and says
/// why ([`Scheduling::Refused`] with the OS error). Never panics.
pub fn set_current_thread(priority: RtPriority) -> Scheduling {
    match imp::set_fifo(priority.get()) {
        Ok(()) => Scheduling::Fifo(priority),
        Err(e) => Scheduling::Refused {
            priority,
            reason: e.to_string(),
        },
    }
}

/// [`set_current_thread`] for an optional priority: `None` leaves the thread as it is
/// ([`Scheduling::Normal`]).
pub fn set_current_thread_opt(priority: Option<RtPriority>) -> Scheduling {
    priority.map_or(Scheduling::Normal, set_current_thread)
}

/// How the calling thread is scheduled now (`None` where that cannot be read).
pub fn current_thread() -> Option<Scheduling> {
    imp::current().map(|(fifo, prio)| match RtPriority::new(prio) {
        Ok(p) if fifo => Scheduling::Fifo(p),
        _ => Scheduling::Normal,
    })
}

#[cfg(target_os = "linux")]
mod imp {
    /// `sched_setscheduler(0, SCHED_FIFO, priority)`: on Linux, pid 0 is the calling thread.
    pub(super) fn set_fifo(priority: u8) -> std::io::Result<()> {
        let param = libc::sched_param {
            sched_priority: libc::c_int::from(priority),
        };
        // SAFETY: `param` is a valid sched_param that outlives the call; pid 0 names the
        // calling thread, so no other thread is touched.
        if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } == 0 {
            Ok(())
        } else {
            Err(std::io::Error::last_os_error())
        }
    }

    /// (is SCHED_FIFO, priority) of the calling thread.
    pub(super) fn current() -> Option<(bool, u8)> {
        // SAFETY: plain integer argument; pid 0 is the calling thread.
        let policy = unsafe { libc::sched_getscheduler(0) };
        if policy < 0 {
            return None;
        }
        let mut param = libc::sched_param { sched_priority: 0 };
        // SAFETY: `param` is a valid, writable sched_param for the duration of the call.
        if unsafe { libc::sched_getparam(0, &mut param) } != 0 {
            return None;
        }
        let prio = u8::try_from(param.sched_priority).ok()?;
        Some((policy == libc::SCHED_FIFO, prio))
    }
}

#[cfg(not(target_os = "linux"))]
mod imp {
    pub(super) fn set_fifo(_priority: u8) -> std::io::Result<()> {
        Err(std::io::Error::new(
            std::io::ErrorKind::Unsupported,
            "real-time scheduling is implemented on Linux only",
        ))
    }

    pub(super) fn current() -> Option<(bool, u8)> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn priorities_outside_1_to_99_are_refused() {
        assert!(RtPriority::new(0).is_err());
        assert!(RtPriority::new(100).is_err());
        assert_eq!(RtPriority::new(1).map(RtPriority::get).ok(), Some(1));
        assert_eq!(RtPriority::new(99).map(RtPriority::get).ok(), Some(99));
    }

    /// Scheduling is per thread: a spawned thread that asks for SCHED_FIFO gets it or the OS
    /// error, and what it reports is what the OS then says of it; its parent is unchanged.
    /// Both outcomes are checked, because CI may run without CAP_SYS_NICE.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_thread_reports_the_scheduling_the_os_gives_it_and_only_it_changes() {
        let before = current_thread();
        let p = RtPriority::new(10).expect("valid");
        let (asked, now) = std::thread::spawn(move || (set_current_thread(p), current_thread()))
            .join()
            .expect("thread");
        match &asked {
            Scheduling::Fifo(got) => {
                assert_eq!(*got, p);
                assert_eq!(now, Some(Scheduling::Fifo(p)));
            }
            Scheduling::Refused { priority, reason } => {
                assert_eq!(*priority, p);
                assert!(!reason.is_empty());
                assert_eq!(now, Some(Scheduling::Normal), "refused means unchanged");
            }
            Scheduling::Normal => panic!("a priority was asked for: Fifo or Refused"),
        }
        assert_eq!(current_thread(), before, "the spawning thread is unchanged");
        assert_eq!(set_current_thread_opt(None), Scheduling::Normal);
    }

    #[test]
    fn display_names_the_policy() {
        let p = RtPriority::new(85).expect("valid");
        assert_eq!(Scheduling::Fifo(p).to_string(), "SCHED_FIFO 85");
        let n = Scheduling::Refused {
            priority: p,
            reason: "EPERM".into(),
        };
        assert_eq!(n.to_string(), "normal (SCHED_FIFO 85 refused: EPERM)");
        assert_eq!(Scheduling::Normal.to_string(), "normal");
    }
}
