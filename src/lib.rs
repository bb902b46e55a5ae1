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
//! - [`stats`]: the experiments' statistics (Wilcoxon, Friedman, Holm, Spearman, NASA-TLX).
//! - [`report`]: the indicator table and plots of `hrc-adapt assess`.
//! - [`assess_cmd`], [`vision_cmd`], `calibrate_cmd` (feature `vision`): offline assessment,
//!   the camera front-end (landmarks → cues) and the camera calibration.
//! - [`robot_cmd`]: `hrc-adapt record` (an RTDE trace) and `hrc-adapt emulate`.
//! - [`Error`]: the library's one error type; a trial that did not end normally is
//!   [`Error::Trial`], whose [`Error::exit_code`] is the process exit code (README, "Exit
//!   codes").
//!
//! # Example
//!
//! One simulated trial of 1 s (trial time, on the mock clock) with the shipped configuration,
//! into a new folder; it ends at `max_duration_s`, a normal ending:
//!
//! ```
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
//! let tmp = tempfile::tempdir().expect("a temporary folder");
//! let dir = run_simulated(&spec, &tmp.path().join("run"), false)?;
//! let summary = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json");
//! assert!(summary.contains(r#""finish_reason": "max_duration""#));
//! # Ok::<(), hrc_adapt::Error>(())
//! ```

pub mod assess_cmd;
#[cfg(feature = "vision")]
pub mod calibrate_cmd;
mod error;
pub mod experiment;
pub mod report;
pub mod robot_cmd;
pub mod stats;
pub mod trial;
pub mod vision_cmd;

pub use error::{Error, Result};

/// The unit tests count the allocations of the control cycle (thread-local: only a counted
/// section of the test's own thread; see `trial::control`'s tests).
#[cfg(test)]
#[global_allocator]
static ALLOCATOR: hrc_adapt_tests::alloc_count::CountingAllocator =
    hrc_adapt_tests::alloc_count::CountingAllocator;
