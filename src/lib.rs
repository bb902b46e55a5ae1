//! # hrc-adapt: the trial runtime, its logs and reports, and the experiment runner
//!
//! The library behind the `hrc-adapt` binary (`src/main.rs`, the CLI). It wires the workspace's
//! crates (`assess`, `policies`, `adapt`, `safety`, `robot-io`) into closed-loop handover
//! trials and experiments. The data flow of a trial, module by module:
//!
//! ```text
//!  cue cycle (30 Hz)     trial::operator (simulated) │ recorded cue CSV │ live camera (vision_cmd)
//!                          │ CueFrame
//!                          ▼
//!                        assess::Assessor ──► policies::Policy ──► MotionAdaptation
//!                                                                     │ (trial::runtime)
//!  control cycle (500 Hz)  ▼
//!                        adapt::Controller ──► safety::Supervisor ──► robot_io::Robot
//!                          │ (trial::control: SimRobot on a mock clock, or RTDE: trial::backend)
//!                          ▼
//!  logs                  trial::log (trial.mcap, indicators.csv, robot.csv, summary.json)
//!                          ──► trial::report (report.html)
//!  experiments           experiment (A/B schedule → trials → aggregate) ──► stats ──► report
//! ```
//!
//! - [`trial`]: one trial (`hrc-adapt trial`): the runtime ([`trial::runtime`]), the simulated
//!   operator ([`trial::operator`]), the configuration ([`trial::config`]), the logs and the
//!   report; [`trial::run_simulated`] runs one trial on the simulated robot.
//! - [`experiment`]: policy A/B experiments (`hrc-adapt experiment`) and the guided session.
//!   Its statistics are the crate-private `stats` (Wilcoxon, Friedman, Holm, Spearman, NASA-TLX).
//! - [`assess_cmd`] (offline assessment, with its indicator table and plots in the
//!   crate-private `report`), `calibrate_cmd` (feature `vision`: the camera calibration), and
//!   the crate-private `vision_cmd`, the camera front-end (landmarks → cues) of both and of
//!   live trials.
//! - [`robot_cmd`]: `hrc-adapt record` (an RTDE trace) and `hrc-adapt emulate`.
//! - [`Error`]: the library's one error type; a trial that did not end normally is
//!   [`Error::Trial`], whose [`Error::exit_code`] is the process exit code (README, "Exit
//!   codes").
//!
//! # Examples
//!
//! The shipped trial configuration, a value out of its range refused with the key named, and
//! the exit code a trial's ending maps onto:
//!
//! ```
//! use hrc_adapt::trial::config::{SHIPPED_TOML, TrialConfig};
//! use hrc_adapt::trial::runtime::{exit_code, reason};
//!
//! let config = TrialConfig::shipped()?;
//! assert_eq!(config.cue_rate_hz, 30.0);
//! let bad = SHIPPED_TOML.replace("max_duration_s = 600.0", "max_duration_s = 1e20");
//! let e = TrialConfig::from_toml_str(&bad, std::path::Path::new("config")).unwrap_err();
//! assert!(e.to_string().starts_with("`max_duration_s` must be in (0, 3600] s"), "{e}");
//! assert_eq!(exit_code(reason::COMPLETED), 0);
//! assert_eq!(exit_code(reason::LINK_LOST), 3);
//! # Ok::<(), hrc_adapt::Error>(())
//! ```
//!
//! One simulated trial (simulated operator, `SimRobot` on the mock clock) of 1 s of trial time
//! into a new run folder; it ends at `max_duration_s`, a normal ending (compiled only: the
//! setup, the trial and its report take seconds in a debug build):
//!
//! ```no_run
//! use hrc_adapt::trial::{TrialSpec, config::TrialConfig, operator::Level, run_simulated};
//!
//! let mut config = TrialConfig::shipped()?;
//! config.max_duration_s = 1.0;
//! let spec = TrialSpec {
//!     participant: "P01".into(),
//!     condition: Level::L1,
//!     policy: policies::PolicyKind::Adaptive,
//!     seed: 7,
//!     config,
//! };
//! let dir = run_simulated(&spec, std::path::Path::new("runs/example"), false)?;
//! let summary = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json");
//! assert!(summary.contains(r#""finish_reason": "max_duration""#));
//! # Ok::<(), hrc_adapt::Error>(())
//! ```

// The module docs describe their modules' internals too: those links resolve with
// `cargo doc --document-private-items`, and are plain text in the public docs.
#![allow(rustdoc::private_intra_doc_links)]

#[macro_use]
mod error;
pub mod assess_cmd;
#[cfg(feature = "vision")]
pub mod calibrate_cmd;
pub mod episodes_cmd;
pub mod experiment;
mod report;
pub mod robot_cmd;
mod stats;
pub mod trial;
mod vision_cmd;

pub use error::{Error, Result};

/// Held by every unit test that plays a RealSense `.bag`: two librealsense 2.56 playback
/// devices in one process, one being destroyed while the other streams, crashed this test
/// binary about once in 20 runs (SIGSEGV in `librealsense::playback_sensor::~playback_sensor`
/// on a librealsense thread, seen under gdb, 2026-12-07). `hrc-adapt` opens one source per
/// process; the tests serialise theirs.
#[cfg(all(test, feature = "realsense"))]
pub(crate) static REALSENSE_PLAYBACK: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// The unit tests count the allocations of the control cycle (thread-local: only a counted
/// section of the test's own thread; see `trial::control`'s tests).
#[cfg(test)]
#[global_allocator]
static ALLOCATOR: hrc_adapt_tests::alloc_count::CountingAllocator =
    hrc_adapt_tests::alloc_count::CountingAllocator;
