//! # adapt: turning an adaptation into safe, smooth UR5e joint commands
//!
//! This crate holds:
//! - UR5e inverse kinematics (8 branches, nearest to the current joint vector) on top of the
//!   forward kinematics in `robot_io::kinematics`;
//! - jerk-limited online trajectory generation with `rsruckig` ([`otg`]), and the jerk-limited
//!   path the controller runs at a jerk-limited time scale ([`path`]);
//! - the planner's speed envelope near the operator ([`envelope`]): the supervisor's caps and
//!   ISO/TS 15066 separation on `robot_io`'s capsule geometry, as the largest admissible scale;
//! - the handover task state machine, which also reports the robot context C(t), G(t);
//! - `Controller::step`, the 500 Hz cycle, which allocates nothing;
//! - ISO/TS 15066 SSM/PFL speed limits ([`ssm`]) and a per-cycle QP speed scaler ([`qp`], with
//!   `clarabel` as its cross-check): the controller's cycle used them before the time scaling
//!   (issue 10) and uses neither now.
//!
//! It depends on `robot-io` types only and never sees `assess` types.
//!
//! Main types: [`controller::Controller`] (with [`controller::MotionAdaptation`] and
//! [`controller::OperatorView`] as inputs), [`task::HandoverTask`], [`path::Path`] with
//! [`path::TimeScale`], [`envelope::Envelope`] with [`envelope::SafetyEnvelope`], [`otg::Otg`]
//! with [`otg::MotionLimits`], and [`ik::nearest`].
//!
//! # Example
//! Inverse kinematics back to a joint vector, then a jerk-limited move to it at half speed:
//! ```
//! use adapt::ik;
//! use adapt::otg::{LimitScale, MotionLimits, Otg, OtgState, PlanStatus};
//! use robot_io::kinematics::flange_pose;
//!
//! let start = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0];
//! let goal = [0.4, -1.2, 1.3, -1.6, -1.57, 0.3];
//! let q = ik::nearest(&start, &flange_pose(&goal))?;
//! assert!(q.iter().zip(&goal).all(|(a, b)| (a - b).abs() < 1e-9));
//!
//! let half = LimitScale::new(0.5)?;
//! let limits = MotionLimits::ur5e_nominal().scaled(half, half);
//! let mut otg = Otg::new(0.002, limits)?;
//! otg.set_current_state(&start, &[0.0; 6], &[0.0; 6]);
//! otg.set_target(&q, None)?;
//! let mut state = OtgState::default();
//! let mut cycles = 0;
//! while otg.step(&mut state)? == PlanStatus::Working {
//!     cycles += 1;
//! }
//! assert!(state.position.iter().zip(&q).all(|(a, b)| (a - b).abs() < 1e-6));
//! assert!(cycles > 100); // well over 0.2 s at half speed
//! # Ok::<(), adapt::AdaptError>(())
//! ```
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::indexing_slicing))]

mod error;

// --- kinematics and trajectory generation ---
pub mod ik;
pub mod otg;
pub mod path;

// --- the planner's speed envelope near the operator ---
pub mod envelope;

// --- separation monitoring and QP speed scaling ---
pub mod qp;
pub mod ssm;

// --- handover task and controller ---
pub mod controller;
pub mod task;

pub use error::{AdaptError, Result};
