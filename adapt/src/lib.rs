//! # adapt: turning an adaptation into safe, smooth UR5e joint commands
//!
//! **In progress (issue 4).** This crate holds:
//! - UR5e inverse kinematics (8 branches, nearest to the current joint vector) on top of the
//!   forward kinematics in `robot_io::kinematics`;
//! - jerk-limited online trajectory generation with `rsruckig`;
//! - speed and separation monitoring (ISO/TS 15066) and per-cycle QP speed scaling with `clarabel`;
//! - the handover task state machine, which also reports the robot context C(t), G(t);
//! - `Controller::step`, the 500 Hz cycle, which allocates nothing.
//!
//! It depends on `robot-io` types only and never sees `assess` types.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::indexing_slicing))]

mod error;

// --- kinematics and trajectory generation ---
pub mod ik;
pub mod otg;

// --- separation monitoring and QP speed scaling ---
pub mod qp;
pub mod ssm;

// --- handover task and controller ---
pub mod controller;
pub mod task;

pub use error::{AdaptError, Result};
