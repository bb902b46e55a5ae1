//! # safety: the supervisor every robot command passes
//!
//! **Skeleton.** This crate will hold, per `ARCHITECTURE.md` and issue 4, `Supervisor<R: Robot>`,
//! which owns the robot and is the only path to `Robot::send`. It will check non-finite values,
//! joint position, velocity and acceleration limits, TCP speed, a workspace box, the protective
//! separation distance (ISO/TS 15066), perception and robot-state staleness, and the robot's own
//! safety mode; it stops the robot and latches faults until an explicit `reset()`. Every check
//! will carry a requirement ID `SAF-REQ-nnn` with a test named after it.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::indexing_slicing))]
