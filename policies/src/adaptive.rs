//! The `adaptive` policy: a rule table (dominant indicator → adaptation) with a minimum hold
//! time, hysteresis and slew-limited parameters.
//!
//! # Rule table (TOML)
//! ```toml
//! [limits]
//! min_hold_s = 8.0                 # an adopted rule stays at least this long \[s\]
//! switch_margin = 0.02             # a new indicator's e_k must exceed the active one's by this [-]
//! max_scale_rate_per_s = 0.25      # speed/acceleration/jerk scales change at most this fast [1/s]
//! max_timing_rate_s_per_s = 1.0    # start delay and min approach duration change at most this fast \[s/s\]
//!
//! [rules.none]                     # nominal; every field defaults to Adaptation::NOMINAL
//! rationale = "..."
//! [rules.OHD]                      # every field not given is inherited from rules.none
//! rationale = "..."
//! speed_scale = 0.5
//! ```
//! The six rules `none`, `AED`, `TID`, `ICD`, `ASD_ctx` and `OHD` must all be present; unknown
//! keys are errors that name the key. Fields: `rationale` (required, non-empty), `speed_scale`,
//! `acceleration_scale`, `jerk_scale` (in (0, 1]), `start_delay_s`, `min_approach_duration_s`,
//! `max_assembly_deferral_s` (in [0, [`MAX_TIMING_S`]] = [0, 600] s), `present_timeout_s` (in
//! (0, 600] s; not given anywhere: the handover task's own), and the flags
//! `wait_for_attention`, `present_requires_collaboration_attention`,
//! `hold_while_in_instruction_area`. The meaning of each is on [`HandoverTiming`].
//!
//! # Rate limiting
//! Let A be the active rule's indicator (initially "none", adopted at the first decision) and
//! B the assessment's dominant indicator ("none" while the assessor is calibrating). The policy
//! adopts B only when
//! - A has been active for at least `min_hold_s` (**minimum hold**), and
//! - B is "none", or B's contribution e_B exceeds A's current contribution e_A (0 for "none")
//!   by at least `switch_margin` (**hysteresis**; this is on top of the assessor's own 3 s
//!   hold and 0.02 lead).
//!
//! The flags and the deferral limit switch with the rule. The continuous parameters move towards
//! the active rule's values at no more than `max_scale_rate_per_s` (scales) and
//! `max_timing_rate_s_per_s` (durations) (**slew limiting**). So the reason and the flags change
//! at most once per `min_hold_s`, and a parameter can reverse its direction only when the rule
//! changes, hence also at most once per `min_hold_s`. The start [`Gate`] is the exception by
//! design: it follows the operator's confirmed area every frame (see [`Gate`]).

use std::collections::BTreeMap;
use std::path::Path;

use assess::{Assessment, Indicator};
use serde::Deserialize;

use crate::adaptation::slew;
use crate::{
    Adaptation, Gate, HandoverTiming, HoldReason, MAX_TIMING_S, Policy, PolicyError, Reason,
    Result, Scale, TaskContext, TaskPhase, indicator_from_key, indicator_key,
};

/// The shipped default rule table, `config/policy-adaptive.toml`, embedded at build time.
pub const SHIPPED_TOML: &str = include_str!("../../config/policy-adaptive.toml");

/// Rate limits of the adaptive policy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    min_hold_s: f64,
    switch_margin: f64,
    max_scale_rate_per_s: f64,
    max_timing_rate_s_per_s: f64,
}

impl Limits {
    /// Validated limits:
    /// - `min_hold_s` \[s\]: finite, > 0;
    /// - `switch_margin` [-]: finite, ≥ 0;
    /// - `max_scale_rate_per_s` [1/s] and `max_timing_rate_s_per_s` \[s/s\]: finite, > 0.
    pub fn new(
        min_hold_s: f64,
        switch_margin: f64,
        max_scale_rate_per_s: f64,
        max_timing_rate_s_per_s: f64,
    ) -> Result<Limits> {
        Self::checked(
            "limits.",
            min_hold_s,
            switch_margin,
            max_scale_rate_per_s,
            max_timing_rate_s_per_s,
        )
    }

    fn checked(
        prefix: &str,
        min_hold_s: f64,
        switch_margin: f64,
        max_scale_rate_per_s: f64,
        max_timing_rate_s_per_s: f64,
    ) -> Result<Limits> {
        positive(&format!("{prefix}min_hold_s"), min_hold_s)?;
        non_negative(&format!("{prefix}switch_margin"), switch_margin)?;
        positive(
            &format!("{prefix}max_scale_rate_per_s"),
            max_scale_rate_per_s,
        )?;
        positive(
            &format!("{prefix}max_timing_rate_s_per_s"),
            max_timing_rate_s_per_s,
        )?;
        Ok(Limits {
            min_hold_s,
            switch_margin,
            max_scale_rate_per_s,
            max_timing_rate_s_per_s,
        })
    }

    /// Minimum time an adopted rule stays active \[s\].
    pub fn min_hold_s(&self) -> f64 {
        self.min_hold_s
    }

    /// How much a new indicator's contribution must exceed the active one's [-].
    pub fn switch_margin(&self) -> f64 {
        self.switch_margin
    }

    /// Maximum rate of change of the speed, acceleration and jerk scales [1/s].
    pub fn max_scale_rate_per_s(&self) -> f64 {
        self.max_scale_rate_per_s
    }

    /// Maximum rate of change of the start delay and the minimum approach duration \[s/s\].
    pub fn max_timing_rate_s_per_s(&self) -> f64 {
        self.max_timing_rate_s_per_s
    }
}

fn positive(key: &str, x: f64) -> Result<()> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(PolicyError::invalid(key, "must be finite and > 0", x))
    }
}

fn non_negative(key: &str, x: f64) -> Result<()> {
    if x.is_finite() && x >= 0.0 {
        Ok(())
    } else {
        Err(PolicyError::invalid(key, "must be finite and >= 0", x))
    }
}

/// One rule: the adaptation for one dominant indicator, with its rationale.
#[derive(Debug, Clone, PartialEq)]
pub struct Rule {
    indicator: Option<Indicator>,
    rationale: String,
    speed_scale: Scale,
    acceleration_scale: Scale,
    jerk_scale: Scale,
    timing: HandoverTiming,
}

impl Rule {
    /// The indicator it applies to; `None` for the nominal rule.
    pub fn indicator(&self) -> Option<Indicator> {
        self.indicator
    }

    /// Its table key (`none`, `AED`, ...).
    pub fn key(&self) -> &'static str {
        indicator_key(self.indicator)
    }

    /// The one-line rationale from the table, for logs.
    pub fn rationale(&self) -> &str {
        &self.rationale
    }

    /// Its target adaptation, with a clear gate and strength 0.
    pub fn adaptation(&self) -> Adaptation {
        Adaptation {
            speed_scale: self.speed_scale,
            acceleration_scale: self.acceleration_scale,
            jerk_scale: self.jerk_scale,
            timing: self.timing,
            gate: Gate::CLEAR,
            reason: Reason {
                indicator: self.indicator,
                strength: 0.0,
            },
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTable {
    limits: RawLimits,
    rules: BTreeMap<String, RawRule>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLimits {
    min_hold_s: f64,
    switch_margin: f64,
    max_scale_rate_per_s: f64,
    max_timing_rate_s_per_s: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRule {
    rationale: String,
    speed_scale: Option<f64>,
    acceleration_scale: Option<f64>,
    jerk_scale: Option<f64>,
    start_delay_s: Option<f64>,
    min_approach_duration_s: Option<f64>,
    wait_for_attention: Option<bool>,
    present_requires_collaboration_attention: Option<bool>,
    hold_while_in_instruction_area: Option<bool>,
    max_assembly_deferral_s: Option<f64>,
    present_timeout_s: Option<f64>,
}

impl RawRule {
    /// The rule for `indicator`, with fields not given taken from `base`.
    fn resolve(self, indicator: Option<Indicator>, base: &Rule) -> Result<Rule> {
        let key = indicator_key(indicator);
        if self.rationale.trim().is_empty() {
            return Err(PolicyError::EmptyRationale { key: key.into() });
        }
        let k = |field: &str| format!("rules.{key}.{field}");
        let scale = |field: &str, v: Option<f64>, d: Scale| match v {
            Some(x) => Scale::named(&k(field), x),
            None => Ok(d),
        };
        let duration = |field: &str, v: Option<f64>, d: f64| match v {
            Some(x) if (0.0..=MAX_TIMING_S).contains(&x) => Ok(x),
            Some(x) => Err(PolicyError::invalid(k(field), "must be in [0, 600] s", x)),
            None => Ok(d),
        };
        let b = &base.timing;
        Ok(Rule {
            indicator,
            rationale: self.rationale.trim().to_owned(),
            speed_scale: scale("speed_scale", self.speed_scale, base.speed_scale)?,
            acceleration_scale: scale(
                "acceleration_scale",
                self.acceleration_scale,
                base.acceleration_scale,
            )?,
            jerk_scale: scale("jerk_scale", self.jerk_scale, base.jerk_scale)?,
            timing: HandoverTiming {
                start_delay_s: duration("start_delay_s", self.start_delay_s, b.start_delay_s)?,
                min_approach_duration_s: duration(
                    "min_approach_duration_s",
                    self.min_approach_duration_s,
                    b.min_approach_duration_s,
                )?,
                wait_for_attention: self.wait_for_attention.unwrap_or(b.wait_for_attention),
                present_requires_collaboration_attention: self
                    .present_requires_collaboration_attention
                    .unwrap_or(b.present_requires_collaboration_attention),
                hold_while_in_instruction_area: self
                    .hold_while_in_instruction_area
                    .unwrap_or(b.hold_while_in_instruction_area),
                max_assembly_deferral_s: duration(
                    "max_assembly_deferral_s",
                    self.max_assembly_deferral_s,
                    b.max_assembly_deferral_s,
                )?,
                present_timeout_s: match self.present_timeout_s {
                    Some(x) if x > 0.0 && x <= MAX_TIMING_S => Some(x),
                    Some(x) => {
                        return Err(PolicyError::invalid(
                            k("present_timeout_s"),
                            "must be in (0, 600] s",
                            x,
                        ));
                    }
                    None => b.present_timeout_s,
                },
            },
        })
    }
}

/// A validated rule table: the limits and one rule per dominant indicator and for "none".
#[derive(Debug, Clone, PartialEq)]
pub struct RuleTable {
    limits: Limits,
    /// Index 0 is "none", index k + 1 is indicator k.
    rules: [Rule; 6],
}

impl RuleTable {
    /// The shipped default table ([`SHIPPED_TOML`]).
    pub fn shipped() -> RuleTable {
        // The shipped file is parsed by a unit test, so this cannot fail in a tested build.
        Self::parse(SHIPPED_TOML, "config/policy-adaptive.toml")
            .unwrap_or_else(|e| panic!("the shipped policy table is invalid: {e}"))
    }

    /// Parses and validates a table.
    pub fn from_toml_str(s: &str) -> Result<RuleTable> {
        Self::parse(s, "<string>")
    }

    /// Reads, parses and validates a table file.
    pub fn from_toml_file(path: impl AsRef<Path>) -> Result<RuleTable> {
        let path = path.as_ref();
        let s = std::fs::read_to_string(path).map_err(|source| PolicyError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::parse(&s, &path.display().to_string())
    }

    fn parse(s: &str, origin: &str) -> Result<RuleTable> {
        let raw: RawTable = toml::from_str(s).map_err(|e| PolicyError::Parse {
            origin: origin.to_owned(),
            message: e.to_string(),
        })?;
        let l = raw.limits;
        let limits = Limits::checked(
            "limits.",
            l.min_hold_s,
            l.switch_margin,
            l.max_scale_rate_per_s,
            l.max_timing_rate_s_per_s,
        )?;
        let mut raw_rules: [Option<RawRule>; 6] = Default::default();
        for (key, rule) in raw.rules {
            let indicator =
                indicator_from_key(&key).ok_or(PolicyError::UnknownRule { key: key.clone() })?;
            raw_rules[slot(indicator)] = Some(rule);
        }
        let nominal = Rule {
            indicator: None,
            rationale: String::new(),
            speed_scale: Scale::ONE,
            acceleration_scale: Scale::ONE,
            jerk_scale: Scale::ONE,
            timing: HandoverTiming::NOMINAL,
        };
        let take = |raw_rules: &mut [Option<RawRule>; 6], k: Option<Indicator>| {
            raw_rules[slot(k)].take().ok_or(PolicyError::MissingRule {
                key: indicator_key(k),
            })
        };
        let none = take(&mut raw_rules, None)?.resolve(None, &nominal)?;
        let mut rule_for = |k: Indicator| -> Result<Rule> {
            take(&mut raw_rules, Some(k))?.resolve(Some(k), &none)
        };
        let rules = [
            rule_for(Indicator::Aed)?,
            rule_for(Indicator::Tid)?,
            rule_for(Indicator::Icd)?,
            rule_for(Indicator::AsdCtx)?,
            rule_for(Indicator::Ohd)?,
        ];
        let [aed, tid, icd, asd, ohd] = rules;
        Ok(RuleTable {
            limits,
            rules: [none, aed, tid, icd, asd, ohd],
        })
    }

    /// The limits.
    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// The same rules with other limits.
    pub fn with_limits(mut self, limits: Limits) -> RuleTable {
        self.limits = limits;
        self
    }

    /// The rule for a dominant indicator (`None`: the nominal rule).
    pub fn rule(&self, indicator: Option<Indicator>) -> &Rule {
        &self.rules[slot(indicator)]
    }

    /// All six rules: "none", then AED, TID, ICD, ASD_ctx, OHD.
    pub fn rules(&self) -> &[Rule; 6] {
        &self.rules
    }
}

fn slot(k: Option<Indicator>) -> usize {
    k.map_or(0, |k| k as usize + 1)
}

/// Evaluates the start [`Gate`] from the timing flags and the task context. Holds the only
/// state the gate needs: when the assembly deferral of the current handover began.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct GateEvaluator {
    deferral_started_s: Option<f64>,
}

impl GateEvaluator {
    /// The gate now. The assembly-deferral clock starts on the first `WaitForAttention` frame
    /// with an assembly dwell, and is reset whenever the phase is neither `Fetch` nor
    /// `WaitForAttention` (the next handover gets its own limit).
    pub(crate) fn evaluate(&mut self, timing: &HandoverTiming, ctx: &TaskContext) -> Gate {
        if !matches!(ctx.phase, TaskPhase::Fetch | TaskPhase::WaitForAttention) {
            self.deferral_started_s = None;
        }
        let dwelling = ctx.assembly_dwell_s.is_finite() && ctx.assembly_dwell_s > 0.0;
        let deferring = timing.max_assembly_deferral_s > 0.0 && dwelling && {
            if ctx.phase == TaskPhase::WaitForAttention && ctx.now_s.is_finite() {
                self.deferral_started_s.get_or_insert(ctx.now_s);
            }
            self.deferral_started_s
                .is_none_or(|t0| ctx.now_s - t0 < timing.max_assembly_deferral_s)
        };
        let hold = if timing.wait_for_attention && !ctx.in_collaboration_area {
            Some(HoldReason::AwaitingAttention)
        } else if timing.present_requires_collaboration_attention && !ctx.in_collaboration_area {
            Some(HoldReason::AwaitingCollaborationAttention)
        } else if timing.hold_while_in_instruction_area && ctx.in_instruction_area {
            Some(HoldReason::OperatorInInstructionArea)
        } else if deferring {
            Some(HoldReason::AssemblyDwell)
        } else {
            None
        };
        Gate {
            clear: hold.is_none(),
            hold,
        }
    }
}

/// The rule-table policy (see the module docs for the table and the rate limiting).
#[derive(Debug, Clone)]
pub struct AdaptivePolicy {
    table: RuleTable,
    active: Option<Indicator>,
    adopted_at_s: Option<f64>,
    last_t_s: Option<f64>,
    changes: u64,
    output: Adaptation,
    gate: GateEvaluator,
}

impl AdaptivePolicy {
    /// A policy with this table, starting on the nominal rule.
    pub fn new(table: RuleTable) -> AdaptivePolicy {
        let output = table.rule(None).adaptation();
        AdaptivePolicy {
            table,
            active: None,
            adopted_at_s: None,
            last_t_s: None,
            changes: 0,
            output,
            gate: GateEvaluator::default(),
        }
    }

    /// A policy with the shipped table.
    pub fn shipped() -> AdaptivePolicy {
        AdaptivePolicy::new(RuleTable::shipped())
    }

    /// Back to the state of [`AdaptivePolicy::new`] (for a new trial).
    pub fn reset(&mut self) {
        *self = AdaptivePolicy::new(self.table.clone());
    }

    /// The table.
    pub fn table(&self) -> &RuleTable {
        &self.table
    }

    /// The active rule (its rationale is what logs show as the reason).
    pub fn active_rule(&self) -> &Rule {
        self.table.rule(self.active)
    }

    /// When the active rule was adopted \[s\]; `None` before the first decision.
    pub fn adopted_at_s(&self) -> Option<f64> {
        self.adopted_at_s
    }

    /// How many times the active rule has changed.
    pub fn changes(&self) -> u64 {
        self.changes
    }

    /// The latest output.
    pub fn output(&self) -> &Adaptation {
        &self.output
    }
}

/// e_k of `k` in the assessment, 0 for "none" and for non-finite or negative values.
fn contribution(a: &Assessment, k: Option<Indicator>) -> f64 {
    match k {
        Some(k) => {
            let e = a.dominant.contributions[k as usize];
            if e.is_finite() { e.max(0.0) } else { 0.0 }
        }
        None => 0.0,
    }
}

impl Policy for AdaptivePolicy {
    fn decide(&mut self, assessment: &Assessment, ctx: &TaskContext) -> Adaptation {
        let now = ctx.now_s;
        if !now.is_finite() || self.last_t_s.is_some_and(|t| now < t) {
            return self.output;
        }
        let dt = self.last_t_s.map_or(0.0, |t| now - t);
        self.last_t_s = Some(now);
        let adopted_at = *self.adopted_at_s.get_or_insert(now);

        let limits = self.table.limits;
        let proposed = if assessment.dominant.calibrating {
            None
        } else {
            assessment.dominant.indicator
        };
        if proposed != self.active {
            let held = now - adopted_at >= limits.min_hold_s;
            let leads = proposed.is_none()
                || contribution(assessment, proposed)
                    >= contribution(assessment, self.active) + limits.switch_margin;
            if held && leads {
                self.active = proposed;
                self.adopted_at_s = Some(now);
                self.changes += 1;
            }
        }

        let rule = self.table.rule(self.active);
        let out = &mut self.output;
        let ds = limits.max_scale_rate_per_s * dt;
        let dtm = limits.max_timing_rate_s_per_s * dt;
        out.speed_scale = out.speed_scale.slew_to(rule.speed_scale, ds);
        out.acceleration_scale = out.acceleration_scale.slew_to(rule.acceleration_scale, ds);
        out.jerk_scale = out.jerk_scale.slew_to(rule.jerk_scale, ds);
        out.timing = HandoverTiming {
            start_delay_s: slew(out.timing.start_delay_s, rule.timing.start_delay_s, dtm),
            min_approach_duration_s: slew(
                out.timing.min_approach_duration_s,
                rule.timing.min_approach_duration_s,
                dtm,
            ),
            ..rule.timing
        };
        out.reason = Reason {
            indicator: self.active,
            strength: contribution(assessment, self.active),
        };
        out.gate = self.gate.evaluate(&out.timing, ctx);
        *out
    }

    fn name(&self) -> &'static str {
        "adaptive"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A table whose six rules only have rationales, plus `none_fields` in `rules.none`.
    fn table_with(none_fields: &str) -> String {
        let mut t = String::from(
            "[limits]\nmin_hold_s = 5.0\nswitch_margin = 0.0\nmax_scale_rate_per_s = 1.0\n\
             max_timing_rate_s_per_s = 1.0\n[rules.none]\nrationale = \"n\"\n",
        );
        t.push_str(none_fields);
        for k in ["AED", "TID", "ICD", "ASD_ctx", "OHD"] {
            t.push_str(&format!("\n[rules.{k}]\nrationale = \"{k}\"\n"));
        }
        t
    }

    #[test]
    fn timings_are_bounded_at_600_s_and_the_error_names_the_key() {
        // 1e20 s passed validation and then panicked the trial when it became a Duration
        // (issue 10); the bound is 600 s, inclusive.
        for field in [
            "start_delay_s",
            "min_approach_duration_s",
            "max_assembly_deferral_s",
        ] {
            let ok = RuleTable::from_toml_str(&table_with(&format!("{field} = 600.0\n")));
            assert!(ok.is_ok(), "{field} = 600: {ok:?}");
            for bad in ["600.001", "1e20"] {
                let e = RuleTable::from_toml_str(&table_with(&format!("{field} = {bad}\n")))
                    .unwrap_err()
                    .to_string();
                assert!(e.contains(&format!("`rules.none.{field}`")), "{e}");
                assert!(e.contains("600"), "{e}");
            }
        }
    }

    #[test]
    fn the_present_timeout_is_inherited_bounded_and_optional() {
        let t = |f: &str| RuleTable::from_toml_str(&table_with(f));
        // Not given: the task's own (None), in every rule.
        let none = t("").unwrap();
        assert_eq!(none.rule(None).adaptation().timing.present_timeout_s, None);
        // Given in rules.none: inherited by the other rules.
        let given = t("present_timeout_s = 12.5\n").unwrap();
        for k in Indicator::ALL {
            assert_eq!(
                given.rule(Some(k)).adaptation().timing.present_timeout_s,
                Some(12.5)
            );
        }
        assert!(t("present_timeout_s = 600.0\n").is_ok());
        for bad in ["0.0", "-1.0", "600.5", "nan"] {
            let e = t(&format!("present_timeout_s = {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("`rules.none.present_timeout_s`"), "{bad}: {e}");
        }
    }
}
