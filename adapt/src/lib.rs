//! # adapt: turning an adaptation into safe, smooth UR5e joint commands
//!
//! **Skeleton.** This crate will hold, per `ARCHITECTURE.md` and issue 4:
//! - UR5e kinematics: forward kinematics of every link frame, the geometric Jacobian and the
//!   analytic inverse kinematics (8 branches, nearest to the current joint vector);
//! - the handover task state machine (Idle → Fetch → WaitForAttention → Approach → Present →
//!   Release → Retreat → Done), which also reports the robot context C(t), G(t) for assessment;
//! - jerk-limited online trajectory generation with `rsruckig`;
//! - per-cycle QP speed scaling with `clarabel` under joint limits and human-distance limits;
//! - `Controller::step`, the 500 Hz cycle, which allocates nothing.
//!
//! It depends on `robot-io` types only and never sees `assess` types.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::indexing_slicing))]
