//! # policies: from the dominant workload indicator to handover timing, speed and smoothness
//!
//! **Skeleton.** This crate will hold, per `ARCHITECTURE.md` and issue 5, the `Policy` trait
//! (`decide(&Assessment, &TaskContext) -> Adaptation`), the built-in `fixed` and rule-table
//! `adaptive` policies with rate limiting and hysteresis, and the A/B schedule design
//! (balanced Latin square counterbalancing, reproducible from a seed).
