//! The [`Policy`] trait, the `fixed` baseline and the policy names.

use std::fmt;
use std::str::FromStr;

use assess::Assessment;

use crate::adaptive::{AdaptivePolicy, GateEvaluator, RuleTable};
use crate::{Adaptation, PolicyError, TaskContext};

/// Something that turns the assessment stream into an adaptation.
///
/// # Implementation
/// - Called once per assessment frame (30 Hz) on the perception thread, with non-decreasing
///   `ctx.now_s`; it must not block and should not allocate.
/// - Returns a complete [`Adaptation`] every time (the binary publishes the latest one to the
///   control thread); a frame with a non-finite or decreasing time returns the previous output.
pub trait Policy: fmt::Debug {
    /// The adaptation for this frame.
    fn decide(&mut self, assessment: &Assessment, ctx: &TaskContext) -> Adaptation;

    /// The policy's name, as logs and run directories write it (`fixed`, `adaptive`).
    fn name(&self) -> &'static str;
}

/// The nominal baseline: returns the same adaptation whatever the assessment.
///
/// [`FixedPolicy::default`] is [`Adaptation::NOMINAL`] (speed, acceleration and jerk scale 1,
/// no delays, no gating). For an A/B comparison in which the two policies differ *only* by the
/// adaptation, build it with [`FixedPolicy::from_table`], which uses the adaptive table's
/// `none` rule without its gates on the operator's state.
#[derive(Debug, Clone, PartialEq)]
pub struct FixedPolicy {
    output: Adaptation,
    gate: GateEvaluator,
}

impl FixedPolicy {
    /// A fixed policy returning `output`'s parameters. Its reason is always "none" with
    /// strength 0; its gate is evaluated from `output.timing` each frame, exactly as the
    /// adaptive policy evaluates it (so a fixed policy with gating flags gates too).
    pub fn new(mut output: Adaptation) -> FixedPolicy {
        output.reason.indicator = None;
        output.reason.strength = 0.0;
        output.gate = crate::Gate::CLEAR;
        FixedPolicy {
            output,
            gate: GateEvaluator::default(),
        }
    }

    /// The `none` rule of an adaptive rule table, held fixed, without its gates on the
    /// operator's state ([`crate::HandoverTiming::without_gates`]): a fixed policy does not
    /// watch the operator, so it shares the nominal rule's speeds, smoothness, delays and
    /// present timeout, and starts each handover on the trial's schedule alone.
    pub fn from_table(table: &RuleTable) -> FixedPolicy {
        let mut a = table.rule(None).adaptation();
        a.timing = a.timing.without_gates();
        FixedPolicy::new(a)
    }

    /// The adaptation it returns.
    pub fn output(&self) -> &Adaptation {
        &self.output
    }
}

impl Default for FixedPolicy {
    fn default() -> Self {
        FixedPolicy::new(Adaptation::NOMINAL)
    }
}

impl Policy for FixedPolicy {
    fn decide(&mut self, _assessment: &Assessment, ctx: &TaskContext) -> Adaptation {
        let mut out = self.output;
        out.gate = self.gate.evaluate(&out.timing, ctx);
        out
    }

    fn name(&self) -> &'static str {
        "fixed"
    }
}

/// The built-in policies by name, for `--policy` and the A/B design.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PolicyKind {
    /// [`FixedPolicy`].
    Fixed,
    /// [`AdaptivePolicy`].
    Adaptive,
}

impl PolicyKind {
    /// Both, in this order.
    pub const ALL: [PolicyKind; 2] = [PolicyKind::Fixed, PolicyKind::Adaptive];

    /// `fixed` or `adaptive`.
    pub fn as_str(self) -> &'static str {
        match self {
            PolicyKind::Fixed => "fixed",
            PolicyKind::Adaptive => "adaptive",
        }
    }

    /// Builds the policy. `fixed` uses the table's `none` rule ([`FixedPolicy::from_table`],
    /// without its gates on the operator), so that fixed and adaptive share one nominal motion.
    pub fn build(self, table: &RuleTable) -> Box<dyn Policy + Send> {
        match self {
            PolicyKind::Fixed => Box::new(FixedPolicy::from_table(table)),
            PolicyKind::Adaptive => Box::new(AdaptivePolicy::new(table.clone())),
        }
    }
}

impl FromStr for PolicyKind {
    type Err = PolicyError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        PolicyKind::ALL
            .into_iter()
            .find(|k| k.as_str() == s)
            .ok_or_else(|| PolicyError::UnknownPolicy { name: s.into() })
    }
}

impl fmt::Display for PolicyKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}
