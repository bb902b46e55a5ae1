//! # robot-io: the wire to the UR5e
//!
//! **In progress (issue 3).** This crate will hold the RTDE codec and tokio client, the UR
//! controller emulator, the [`Robot`] trait with `RtdeRobot`, `SimRobot` and `ReplayRobot`,
//! dashboard and script senders, and trace readers and writers. It depends on no other crate of
//! the project.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::indexing_slicing))]

mod error;
mod types;

// --- RTDE side: codec, client, RtdeRobot, emulator, dashboard, script ---
pub mod client;
pub mod codec;
pub mod dashboard;
pub mod emulator;
pub mod rtde_robot;
pub mod script;

pub use client::{ClientConfig, RtdeClient};
pub use dashboard::DashboardClient;
pub use emulator::{Emulator, EmulatorBackend, EmulatorConfig, SimBackend, TraceBackend};
pub use rtde_robot::{RtdeRobot, RtdeRobotConfig};
pub use script::{RegisterMap, ScriptSender};

// --- kinematics (UR5e FK and Jacobians; used by sim, adapt and safety) ---
pub mod kinematics;
pub use kinematics::{
    ControlPoint, ControlPointState, ControlPoints, flange_pose, link_frames, tcp_pose,
};

// --- simulation and traces: SimRobot, ReplayRobot, trace readers/writers ---
pub mod replay;
pub mod sim;
pub mod trace;
pub use replay::ReplayRobot;
pub use sim::{SimConfig, SimRobot};
pub use trace::{Trace, TraceReport};

pub use error::{Result, RobotIoError};
pub use types::{
    JointCommand, Joints, Robot, RobotState, robot_mode, runtime_state, safety_mode,
    safety_status_bits,
};
