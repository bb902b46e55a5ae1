//! # robot-io: the wire to the UR5e
//!
//! **Skeleton.** Issue 3 fills this crate: the RTDE codec and tokio client, the UR controller
//! emulator, the `Robot` trait with `RtdeRobot`, `SimRobot` and `ReplayRobot`, dashboard and
//! script senders, and trace readers and writers.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::indexing_slicing))]
