//! What a policy sees ([`TaskContext`]) and what it returns ([`Adaptation`]).

use assess::Indicator;
use serde::{Serialize, Serializer};

use crate::{PolicyError, Result};

/// A scale factor in (0, 1] [-]: speed, acceleration or jerk relative to the controller's limits.
///
/// Valid by construction: [`Scale::new`] rejects 0, negative, above-1 and non-finite values.
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Serialize)]
#[serde(transparent)]
pub struct Scale(f64);

impl Scale {
    /// Full scale, 1.
    pub const ONE: Scale = Scale(1.0);

    /// A scale in (0, 1]; anything else is [`PolicyError::InvalidValue`] (key `scale`).
    pub fn new(x: f64) -> Result<Scale> {
        Self::named("scale", x)
    }

    /// As [`Scale::new`], naming `key` in the error.
    pub(crate) fn named(key: &str, x: f64) -> Result<Scale> {
        if x.is_finite() && x > 0.0 && x <= 1.0 {
            Ok(Scale(x))
        } else {
            Err(PolicyError::invalid(key, "must be in (0, 1]", x))
        }
    }

    /// The factor [-].
    pub fn get(self) -> f64 {
        self.0
    }

    /// Moves towards `target` by at most `max_step` (≥ 0); the result stays in (0, 1] because
    /// both ends are.
    pub(crate) fn slew_to(self, target: Scale, max_step: f64) -> Scale {
        Scale(slew(self.0, target.0, max_step))
    }
}

impl Default for Scale {
    fn default() -> Self {
        Scale::ONE
    }
}

/// `current` moved towards `target` by at most `max_step` (≥ 0); lands exactly on the target.
pub(crate) fn slew(current: f64, target: f64, max_step: f64) -> f64 {
    let d = target - current;
    if d.abs() <= max_step {
        target
    } else {
        current + max_step.copysign(d)
    }
}

/// The handover task's phase, mirroring `adapt::task::Phase` (this crate does not depend on
/// `adapt`; the binary maps one onto the other).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TaskPhase {
    /// Nothing to do yet.
    #[default]
    Idle,
    /// Moving to the pick pose and gripping the part (then the start delay).
    Fetch,
    /// Holding the part at the pick pose until the start gate ([`Gate`]) clears.
    WaitForAttention,
    /// Moving to the handover pose.
    Approach,
    /// Holding the part at the handover pose.
    Present,
    /// Opening the gripper.
    Release,
    /// Moving away.
    Retreat,
    /// Finished.
    Done,
}

impl TaskPhase {
    /// All phases, in task order.
    pub const ALL: [TaskPhase; 8] = [
        TaskPhase::Idle,
        TaskPhase::Fetch,
        TaskPhase::WaitForAttention,
        TaskPhase::Approach,
        TaskPhase::Present,
        TaskPhase::Release,
        TaskPhase::Retreat,
        TaskPhase::Done,
    ];
}

/// What the policy needs to know about the task; the binary fills it each decision from the
/// handover task and the workspace roles.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TaskContext {
    /// The current time \[s\] (injected, the same clock as the assessment's frame times).
    pub now_s: f64,
    /// The handover task's phase.
    pub phase: TaskPhase,
    /// The operator's confirmed area (the assessment's `confirmed`) is the collaboration area.
    pub in_collaboration_area: bool,
    /// The operator's confirmed area is the instruction area.
    pub in_instruction_area: bool,
    /// How long the operator's current dwell in the assembly area has lasted \[s\]; 0 when the
    /// confirmed area is not the assembly area.
    pub assembly_dwell_s: f64,
}

/// The longest start delay, minimum approach duration and assembly deferral a rule table may
/// give \[s\]: 600 s, the shipped trial's whole length (`config/trial.toml`'s `max_duration_s`).
/// A longer hold would never let a handover happen in a trial; the bound also keeps every timing
/// convertible to a `std::time::Duration` (issue 10: 1e20 s panicked the trial).
pub const MAX_TIMING_S: f64 = 600.0;

/// Handover timing and gating parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HandoverTiming {
    /// Hold this long after the part is gripped before the approach may start \[s\], in
    /// [0, [`MAX_TIMING_S`]] (adapt's `start_delay_s`).
    pub start_delay_s: f64,
    /// The approach (pick pose → handover pose) takes at least this long \[s\], in
    /// [0, [`MAX_TIMING_S`]]; 0 means no
    /// lower bound (the motion generator's time-optimal duration). The binary maps it onto a
    /// speed cap for the approach segment.
    pub min_approach_duration_s: f64,
    /// Do not start the approach until the operator's confirmed area is the collaboration area
    /// (adapt's `wait_for_attention`, with "attention on the robot" = confirmed on the
    /// collaboration area).
    pub wait_for_attention: bool,
    /// Present only once the operator's attention is confirmed on the collaboration area.
    /// adapt's task has one gate (before the approach), so this is enforced there, like
    /// `wait_for_attention`; it is a separate flag so that the reason is logged and a later
    /// pre-present hold can use it.
    pub present_requires_collaboration_attention: bool,
    /// Do not start motion (the approach) while the operator's confirmed area is the
    /// instruction area.
    pub hold_while_in_instruction_area: bool,
    /// Defer the approach while the operator's assembly dwell lasts, for at most this long per
    /// handover \[s\], in [0, [`MAX_TIMING_S`]]; 0 disables the deferral.
    pub max_assembly_deferral_s: f64,
    /// Hold the part at the handover pose this long for the operator's grasp before returning
    /// it \[s\], in (0, [`MAX_TIMING_S`]]; `None`: the handover task's own `present_timeout_s`
    /// (`config/handover.toml`). Read when the presentation starts.
    pub present_timeout_s: Option<f64>,
}

impl HandoverTiming {
    /// Nominal timing: no delays, no gating.
    pub const NOMINAL: HandoverTiming = HandoverTiming {
        start_delay_s: 0.0,
        min_approach_duration_s: 0.0,
        wait_for_attention: false,
        present_requires_collaboration_attention: false,
        hold_while_in_instruction_area: false,
        max_assembly_deferral_s: 0.0,
        present_timeout_s: None,
    };

    /// These timings without the gates that watch the operator (attention, instruction area,
    /// assembly deferral): what a policy that does not look at the operator can use.
    pub fn without_gates(self) -> HandoverTiming {
        HandoverTiming {
            wait_for_attention: false,
            present_requires_collaboration_attention: false,
            hold_while_in_instruction_area: false,
            max_assembly_deferral_s: 0.0,
            ..self
        }
    }

    /// The discrete part (flags, the deferral limit and the present timeout), which changes
    /// only when the active rule changes.
    pub fn gating(&self) -> (bool, bool, bool, f64, Option<f64>) {
        (
            self.wait_for_attention,
            self.present_requires_collaboration_attention,
            self.hold_while_in_instruction_area,
            self.max_assembly_deferral_s,
            self.present_timeout_s,
        )
    }

    /// Whether any flag can hold the start of the approach (the binary then sets adapt's
    /// `wait_for_attention` and feeds [`Gate::clear`] as "attention on the robot").
    pub fn gates_start(&self) -> bool {
        self.wait_for_attention
            || self.present_requires_collaboration_attention
            || self.hold_while_in_instruction_area
            || self.max_assembly_deferral_s > 0.0
    }
}

impl Default for HandoverTiming {
    fn default() -> Self {
        HandoverTiming::NOMINAL
    }
}

/// Why the start of the approach is held (first match in this order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum HoldReason {
    /// `wait_for_attention` and the operator is not confirmed on the collaboration area.
    AwaitingAttention,
    /// `present_requires_collaboration_attention` and the operator is not confirmed on the
    /// collaboration area.
    AwaitingCollaborationAttention,
    /// `hold_while_in_instruction_area` and the operator is confirmed on the instruction area.
    OperatorInInstructionArea,
    /// The assembly dwell lasts and the deferral limit has not been reached.
    AssemblyDwell,
}

impl HoldReason {
    /// Snake-case name, as logs write it.
    pub fn as_str(self) -> &'static str {
        match self {
            HoldReason::AwaitingAttention => "awaiting_attention",
            HoldReason::AwaitingCollaborationAttention => "awaiting_collaboration_attention",
            HoldReason::OperatorInInstructionArea => "operator_in_instruction_area",
            HoldReason::AssemblyDwell => "assembly_dwell",
        }
    }
}

/// The start gate, evaluated on every decision from the timing flags and the [`TaskContext`].
///
/// Unlike the parameters it is **not** rate-limited: it follows the operator's confirmed area
/// (itself debounced by the assessor's temporal confirmation), which is what the flags ask for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Gate {
    /// The approach may start now.
    pub clear: bool,
    /// Why not, when it may not.
    pub hold: Option<HoldReason>,
}

impl Gate {
    /// A clear gate.
    pub const CLEAR: Gate = Gate {
        clear: true,
        hold: None,
    };
}

/// Why the adaptation is what it is.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Reason {
    /// The dominant indicator whose rule is active; `None` is the nominal rule ("none").
    #[serde(serialize_with = "serialize_indicator")]
    pub indicator: Option<Indicator>,
    /// Its contribution e_k on this frame [-] (0 for "none"), from the assessment.
    pub strength: f64,
}

fn serialize_indicator<S: Serializer>(k: &Option<Indicator>, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(indicator_key(*k))
}

/// The rule-table key of an indicator: `AED`, `TID`, `ICD`, `ASD_ctx`, `OHD`, or `none`.
pub fn indicator_key(k: Option<Indicator>) -> &'static str {
    k.map_or("none", Indicator::name)
}

/// The indicator of a rule-table key; `Some(None)` for `none`, `None` for an unknown key.
pub fn indicator_from_key(key: &str) -> Option<Option<Indicator>> {
    if key == "none" {
        return Some(None);
    }
    Indicator::ALL
        .into_iter()
        .find(|k| k.name() == key)
        .map(Some)
}

/// A policy's output: plain parameters the binary maps onto `adapt`'s inputs. `Copy`, so it
/// passes through a single-slot handoff to the control thread.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Adaptation {
    /// Speed relative to the controller's limits [-], (0, 1].
    pub speed_scale: Scale,
    /// Acceleration relative to the controller's limit [-], (0, 1] (smoothness).
    pub acceleration_scale: Scale,
    /// Jerk relative to the controller's limit [-], (0, 1] (smoothness).
    pub jerk_scale: Scale,
    /// Handover timing and gating.
    pub timing: HandoverTiming,
    /// The start gate now.
    pub gate: Gate,
    /// The active rule's indicator and its strength.
    pub reason: Reason,
}

impl Adaptation {
    /// The nominal baseline: speed, acceleration and jerk scale 1, no delays, no gating, clear
    /// gate, reason "none".
    pub const NOMINAL: Adaptation = Adaptation {
        speed_scale: Scale::ONE,
        acceleration_scale: Scale::ONE,
        jerk_scale: Scale::ONE,
        timing: HandoverTiming::NOMINAL,
        gate: Gate::CLEAR,
        reason: Reason {
            indicator: None,
            strength: 0.0,
        },
    };
}

impl Default for Adaptation {
    fn default() -> Self {
        Adaptation::NOMINAL
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_accepts_only_the_half_open_unit_interval() {
        assert_eq!(Scale::new(1.0).unwrap().get(), 1.0);
        assert_eq!(Scale::new(1e-9).unwrap().get(), 1e-9);
        for bad in [0.0, -0.5, 1.0 + 1e-12, f64::NAN, f64::INFINITY] {
            let e = Scale::new(bad).unwrap_err().to_string();
            assert!(e.contains("`scale`") && e.contains("(0, 1]"), "{e}");
        }
    }

    #[test]
    fn slew_is_bounded_and_lands_on_the_target() {
        assert_eq!(slew(0.0, 1.0, 0.25), 0.25);
        assert_eq!(slew(1.0, 0.0, 0.25), 0.75);
        assert_eq!(slew(0.9, 1.0, 0.25), 1.0);
        assert_eq!(slew(0.5, 0.5, 0.0), 0.5);
    }

    #[test]
    fn indicator_keys_round_trip() {
        assert_eq!(indicator_from_key("none"), Some(None));
        for k in Indicator::ALL {
            assert_eq!(indicator_from_key(indicator_key(Some(k))), Some(Some(k)));
        }
        assert_eq!(indicator_from_key("ohd"), None);
    }

    #[test]
    fn adaptation_serialises_with_the_indicator_name() {
        let mut a = Adaptation::NOMINAL;
        a.reason.indicator = Some(Indicator::AsdCtx);
        let v = toml::Value::try_from(a).unwrap();
        assert_eq!(v["reason"]["indicator"].as_str(), Some("ASD_ctx"));
        assert_eq!(v["speed_scale"].as_float(), Some(1.0));
    }
}
