//! # robot-io: the wire to the UR5e
//!
//! Everything between hrc-adapt and a Universal Robots controller, and the test bench that
//! stands in for one. It depends on no other crate of the project.
//!
//! - [`Robot`]: one control cycle's `read_state` and `send`, with three implementations:
//!   [`RtdeRobot`] (a real UR5e or URSim over RTDE), [`sim::SimRobot`] (an in-process UR5e
//!   model on a mock clock, with fault injection) and [`replay::ReplayRobot`] (a recorded trace).
//! - `UrRtdeRobot` (feature `ur-rtde`, module `ur_rtde_robot`): the same [`Robot`] over SDU's
//!   ur_rtde 1.6.5 (its RTDEReceiveInterface and RTDEControlInterface) through our C shim.
//! - [`codec`]: every RTDE package and field type, with recipes built once and decoding into
//!   caller-owned buffers; [`RtdeClient`]: the tokio client (protocol v2, recipes, a reader task
//!   that always drains the socket, link-loss detection and reconnect with backoff).
//! - [`Emulator`]: a UR controller on loopback (RTDE 30004, dashboard 29999, script
//!   30002/30003), backed by [`SimBackend`] or [`TraceBackend`].
//! - [`script`]: our URScript control program and its register protocol; [`DashboardClient`].
//! - [`realtime`]: `SCHED_FIFO` for the threads a control cycle waits on, reported when refused.
//! - [`trace`]: UR `record.py` and ur_rtde CSV readers and writers, de-duplication, gap reports.
//! - [`kinematics`]: UR5e forward kinematics and Jacobians, shared with `adapt` and `safety`.
//! - [`geometry`]: the arm, gripper and carried part as capsules ([`geometry::ArmModel`]),
//!   the operator's tracked body ([`geometry::HumanBody`], [`geometry::BodyModel`]) and exact
//!   segment and capsule distances; [`separation`]: ISO/TS 15066's protective separation
//!   distance. Both are shared by the planner (`adapt`) and the supervisor (`safety`), which
//!   share formulas, never code paths.
//!
//! # Example
//! A servoJ command on the simulated UR5e, one 2 ms cycle at a time:
//! ```
//! use robot_io::sim::{SimConfig, SimRobot};
//! use robot_io::{JointCommand, Robot, RobotState};
//!
//! let mut robot = SimRobot::new(SimConfig::ur5e())?;
//! let mut state = RobotState::default();
//! robot.read_state(&mut state)?;
//! let mut target = state.actual_q;
//! target[0] += 0.05; // 0.05 rad on the base joint
//! for _ in 0..500 {
//!     robot.send(&JointCommand::Servo { q: target, lookahead_s: 0.1, gain: 300.0 })?;
//!     robot.step();
//! }
//! robot.read_state(&mut state)?;
//! assert!((state.actual_q[0] - target[0]).abs() < 1e-3);
//! assert!(state.timestamp_s >= 1.0); // 500 cycles of 2 ms on the mock clock
//! # Ok::<(), robot_io::RobotIoError>(())
//! ```
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::indexing_slicing))]

mod cycle;
mod error;
mod types;

// --- RTDE side: codec, client, RtdeRobot, emulator, dashboard, script ---
pub mod client;
pub mod codec;
pub mod dashboard;
pub mod emulator;
pub mod realtime;
pub mod rtde_robot;
pub mod script;

pub use client::{ClientConfig, RtdeClient};
pub use dashboard::DashboardClient;
pub use emulator::{Emulator, EmulatorBackend, EmulatorConfig, SimBackend, TraceBackend};
pub use rtde_robot::{RtdeRobot, RtdeRobotConfig};
#[cfg(feature = "ur-rtde")]
pub mod ur_rtde_robot;
pub use script::{RegisterMap, ScriptSender};
#[cfg(feature = "ur-rtde")]
pub use ur_rtde_robot::{UrRtdeConfig, UrRtdeReceiver, UrRtdeRobot, UrRtdeSendStats};

// --- kinematics (UR5e FK and Jacobians; used by sim, adapt and safety) ---
pub mod kinematics;
pub use kinematics::{
    ControlPoint, ControlPointState, ControlPoints, flange_pose, link_frames, tcp_pose,
};

// --- separation monitoring: capsule geometry and ISO/TS 15066's S_p (used by adapt and safety) ---
pub mod geometry;
pub mod separation;

// --- simulation and traces: SimRobot, ReplayRobot, trace readers/writers ---
pub mod replay;
pub mod sim;
pub mod trace;
pub use replay::ReplayRobot;
pub use sim::{SimConfig, SimRobot};
pub use trace::{Trace, TraceReport};

pub use cycle::{CYCLE_TIME_TOLERANCE, cycle_time_s};
pub use error::{Result, RobotIoError};
pub use types::{
    JointCommand, Joints, Robot, RobotState, robot_mode, runtime_state, safety_mode,
    safety_status_bits,
};
