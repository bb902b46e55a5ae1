//! # policies: from the dominant workload indicator to handover timing, speed and smoothness
//!
//! The assessor (`assess`) streams an [`assess::Assessment`] per camera frame; its `dominant`
//! field names the indicator that currently drives the operator's workload above their
//! baseline ([`assess::spec`] §8). A [`Policy`] turns it, with a [`TaskContext`] from the
//! handover task, into an [`Adaptation`]: plain parameters that the binary maps onto `adapt`'s
//! inputs.
//!
//! - [`Adaptation`]: speed, acceleration and jerk [`Scale`]s in (0, 1], [`HandoverTiming`]
//!   (start delay, minimum approach duration, attention and area gating, assembly deferral), the
//!   start [`Gate`] and the [`Reason`] (the dominant indicator and its strength).
//! - [`FixedPolicy`]: the nominal baseline, whatever the assessment.
//! - [`AdaptivePolicy`]: a [`RuleTable`] loaded from TOML (dominant indicator → adaptation), with
//!   a minimum hold time, hysteresis and slew-limited parameters ([`adaptive`] has the details).
//!   The shipped table is `config/policy-adaptive.toml` ([`SHIPPED_TOML`]).
//! - [`ExperimentDesign`] → [`Schedule`]: A/B schedules counterbalanced with a Williams design,
//!   reproducible from a seed ([`schedule`] has the details).
//!
//! Mapping onto `adapt` (done by the binary): `speed_scale` scales the velocity limits,
//! `acceleration_scale`/`jerk_scale` the OTG's limits, `timing.start_delay_s` is the task's
//! `start_delay_s`, `timing.gates_start()` sets the task's `wait_for_attention` and
//! `gate.clear` is fed as its "attention on the robot"; `min_approach_duration_s` caps the speed
//! of the approach segment.
//!
//! # Example
//! An operator looking at the instruction area for 70 s: after the assessor's 60 s baseline
//! calibration ICD stands out, and after the assessor's and the policy's holds the adaptive
//! policy delays the handover start.
//! ```
//! use assess::{Assessor, AssessConfig, CueFrame, HeadCue, Indicator, Vec3, Workspace};
//! use policies::{AdaptivePolicy, FixedPolicy, Policy, TaskContext, TaskPhase};
//!
//! let workspace = Workspace::from_toml_str(r#"
//!     [[area]]
//!     name = "assembly"
//!     role = "assembly"
//!     min_m = [0.3, -0.2, 0.7]
//!     max_m = [0.7, 0.2, 0.9]
//!     [[area]]
//!     name = "instruction"
//!     role = "instruction"
//!     min_m = [0.3, 0.6, 1.0]
//!     max_m = [0.5, 0.9, 1.4]
//! "#)?;
//! let mut assessor = Assessor::new(workspace, AssessConfig::default())?;
//! let mut adaptive = AdaptivePolicy::shipped();
//! let mut fixed = FixedPolicy::default();
//! let mut last = None;
//! for k in 0..(30 * 90) {
//!     let t = k as f64 / 30.0;
//!     let mut frame = CueFrame::empty(t);
//!     // First the assembly area for 60 s (the baseline), then the instruction area.
//!     let facing = if t < 60.0 { Vec3::new(0.5, 0.0, -0.4) } else { Vec3::new(0.4, 0.75, 0.0) };
//!     frame.head = Some(HeadCue { position: Vec3::new(0.0, 0.0, 1.2), facing, confidence: 0.9 });
//!     let assessment = assessor.update(&frame);
//!     let ctx = TaskContext { now_s: t, phase: TaskPhase::Fetch, ..TaskContext::default() };
//!     assert_eq!(fixed.decide(assessment, &ctx).speed_scale.get(), 1.0);
//!     last = Some(adaptive.decide(assessment, &ctx));
//! }
//! let a = last.unwrap();
//! assert_eq!(a.reason.indicator, Some(Indicator::Icd));
//! assert_eq!(a.timing.start_delay_s, 3.0);
//! println!("{}", adaptive.active_rule().rationale());
//! # Ok::<(), assess::AssessError>(())
//! ```

mod adaptation;
pub mod adaptive;
mod error;
mod policy;
pub mod schedule;

pub use adaptation::{
    Adaptation, Gate, HandoverTiming, HoldReason, MAX_TIMING_S, Reason, Scale, TaskContext,
    TaskPhase, indicator_from_key, indicator_key,
};
pub use adaptive::{AdaptivePolicy, Limits, Rule, RuleTable, SHIPPED_TOML};
pub use error::{PolicyError, Result};
pub use policy::{FixedPolicy, Policy, PolicyKind};
pub use schedule::{
    Condition, ExperimentDesign, MAX_PARTICIPANTS, Schedule, ScheduledTrial, Session, SplitMix64,
    Treatment, williams_square,
};
