//! Behaviour of the built-in policies and of the rule-table loader.

mod common;

use assess::Indicator;
use common::{assessment, only};
use policies::{
    Adaptation, AdaptivePolicy, FixedPolicy, Gate, HoldReason, Limits, Policy, PolicyKind,
    RuleTable, TaskContext, TaskPhase,
};

fn ctx(t: f64) -> TaskContext {
    TaskContext {
        now_s: t,
        phase: TaskPhase::Fetch,
        ..TaskContext::default()
    }
}

/// Runs `policy` at 30 Hz from `t0` for `duration_s` with a constant dominant indicator and
/// contributions; returns the last output and the time after it.
fn run(
    policy: &mut dyn Policy,
    t0: f64,
    duration_s: f64,
    dominant: Option<Indicator>,
    e: [f64; 5],
    c: impl Fn(f64) -> TaskContext,
) -> (Adaptation, f64) {
    let mut t = t0;
    let mut out = Adaptation::NOMINAL;
    while t < t0 + duration_s {
        out = policy.decide(&assessment(t, dominant, e), &c(t));
        t += 1.0 / 30.0;
    }
    (out, t)
}

#[test]
fn the_shipped_table_moves_each_parameter_the_way_its_rule_says() {
    let table = RuleTable::shipped();
    let none = table.rule(None).adaptation();
    let rule = |k| table.rule(Some(k)).adaptation();
    for r in table.rules() {
        assert!(!r.rationale().is_empty(), "{}", r.key());
    }
    // OHD: slower, smoother, longer approach, a longer hold before the part is returned.
    let ohd = rule(Indicator::Ohd);
    assert!(ohd.speed_scale < none.speed_scale);
    assert!(ohd.acceleration_scale < none.acceleration_scale);
    assert!(ohd.jerk_scale < none.jerk_scale);
    assert!(ohd.timing.min_approach_duration_s > none.timing.min_approach_duration_s);
    assert!(ohd.timing.present_timeout_s > none.timing.present_timeout_s);
    assert_eq!(none.timing.present_timeout_s, None, "the task's own");
    // Every rule presents only once the operator looks for the part (inherited from none).
    for r in table.rules() {
        assert!(r.adaptation().timing.wait_for_attention, "{}", r.key());
    }
    // ASD_ctx: the two gating flags.
    let asd = rule(Indicator::AsdCtx);
    assert!(asd.timing.present_requires_collaboration_attention);
    assert!(asd.timing.hold_while_in_instruction_area);
    // ICD: later start.
    assert!(rule(Indicator::Icd).timing.start_delay_s > none.timing.start_delay_s);
    // TID: earlier (shorter delay) and faster.
    let tid = rule(Indicator::Tid);
    assert!(tid.timing.start_delay_s < none.timing.start_delay_s);
    assert!(tid.speed_scale > none.speed_scale);
    // AED: a bounded deferral.
    let aed = rule(Indicator::Aed);
    assert!(aed.timing.max_assembly_deferral_s > 0.0);
    assert_eq!(none.timing.max_assembly_deferral_s, 0.0);
}

#[test]
fn fixed_ignores_the_assessment() {
    let mut p = FixedPolicy::default();
    for k in Indicator::ALL {
        let out = p.decide(&assessment(100.0, Some(k), only(k, 0.2)), &ctx(100.0));
        assert_eq!(out, Adaptation::NOMINAL);
    }
    assert_eq!(p.name(), "fixed");
    // Built by name, it uses the table's nominal rule.
    let table = RuleTable::shipped();
    let mut by_name = PolicyKind::Fixed.build(&table);
    let out = by_name.decide(
        &assessment(0.0, Some(Indicator::Ohd), only(Indicator::Ohd, 0.2)),
        &ctx(0.0),
    );
    assert_eq!(out.speed_scale, table.rule(None).adaptation().speed_scale);
    assert_eq!(out.reason.indicator, None);
    // ... without its gates on the operator: the shipped nominal waits for attention, the fixed
    // policy never does (the gate is clear whatever the operator's area).
    let nominal = table.rule(None).adaptation();
    assert!(nominal.timing.wait_for_attention);
    assert!(!out.timing.gates_start());
    assert_eq!(out.gate, Gate::CLEAR);
    assert_eq!(out.timing.start_delay_s, nominal.timing.start_delay_s);
    assert_eq!(
        "adaptive".parse::<PolicyKind>().unwrap(),
        PolicyKind::Adaptive
    );
    let e = "random".parse::<PolicyKind>().unwrap_err().to_string();
    assert!(e.contains("`random`"), "{e}");
}

#[test]
fn a_dominant_indicator_is_adopted_after_the_hold_and_slewed_to() {
    let mut p = AdaptivePolicy::shipped();
    let hold = p.table().limits().min_hold_s();
    let ohd = Some(Indicator::Ohd);
    // At t = 0 the nominal rule is adopted; OHD from the start is adopted only at t = hold.
    let (out, t) = run(&mut p, 0.0, hold - 0.1, ohd, only(Indicator::Ohd, 0.1), ctx);
    assert_eq!(out.reason.indicator, None);
    assert_eq!(out.speed_scale.get(), 0.8);
    let (out, t) = run(&mut p, t, 0.2, ohd, only(Indicator::Ohd, 0.1), ctx);
    assert_eq!(out.reason.indicator, ohd);
    assert!((out.reason.strength - 0.1).abs() < 1e-12);
    assert_eq!(p.changes(), 1);
    // Slewing: 0.8 → 0.5 at 0.25 /s takes 1.2 s; 0 → 3 s of minimum approach at 1 s/s takes 3 s.
    assert!(out.speed_scale.get() > 0.75, "{}", out.speed_scale.get());
    let (out, t) = run(&mut p, t, 1.3, ohd, only(Indicator::Ohd, 0.1), ctx);
    assert_eq!(out.speed_scale.get(), 0.5);
    assert!(out.timing.min_approach_duration_s < 3.0);
    let (out, _) = run(&mut p, t, 2.0, ohd, only(Indicator::Ohd, 0.1), ctx);
    assert_eq!(out.timing.min_approach_duration_s, 3.0);
    assert_eq!(out.jerk_scale.get(), 0.25);
    assert!(out.timing.wait_for_attention);
    // Not on the collaboration area: the gate holds, and says why.
    assert_eq!(out.gate.hold, Some(HoldReason::AwaitingAttention));
    assert!(!out.gate.clear);
}

#[test]
fn calibration_reports_no_dominant_and_the_policy_stays_nominal() {
    let mut p = AdaptivePolicy::shipped();
    let mut a = assessment(0.0, Some(Indicator::Icd), only(Indicator::Icd, 0.2));
    a.dominant.calibrating = true;
    for k in 0..(30 * 30) {
        let t = k as f64 / 30.0;
        a.t = t;
        let out = p.decide(&a, &ctx(t));
        assert_eq!(out.reason.indicator, None);
    }
    assert_eq!(p.changes(), 0);
}

#[test]
fn hysteresis_keeps_the_active_rule_until_the_new_one_leads_by_the_margin() {
    let mut p = AdaptivePolicy::shipped();
    let margin = p.table().limits().switch_margin();
    let (_, t) = run(
        &mut p,
        0.0,
        10.0,
        Some(Indicator::Icd),
        only(Indicator::Icd, 0.1),
        ctx,
    );
    assert_eq!(p.active_rule().indicator(), Some(Indicator::Icd));
    // TID is reported dominant, but leads ICD by less than the margin: no change, however long.
    let mut e = [0.0; 5];
    e[Indicator::Icd as usize] = 0.1;
    e[Indicator::Tid as usize] = 0.1 + 0.5 * margin;
    let (out, t) = run(&mut p, t, 30.0, Some(Indicator::Tid), e, ctx);
    assert_eq!(out.reason.indicator, Some(Indicator::Icd));
    // Now it leads by more than the margin: adopted at once (the hold has long passed).
    e[Indicator::Tid as usize] = 0.1 + 1.5 * margin;
    let (out, _) = run(&mut p, t, 0.05, Some(Indicator::Tid), e, ctx);
    assert_eq!(out.reason.indicator, Some(Indicator::Tid));
    assert_eq!(p.changes(), 2);
}

#[test]
fn a_dominant_that_flips_every_frame_changes_the_rule_at_most_once_per_hold() {
    let mut p = AdaptivePolicy::shipped();
    let hold = p.table().limits().min_hold_s();
    let mut last_change = 0.0;
    let mut prev = None;
    for k in 0..(30 * 120) {
        let t = k as f64 / 30.0;
        let d = Indicator::ALL[k % 5];
        let out = p.decide(&assessment(t, Some(d), only(d, 0.2)), &ctx(t));
        if out.reason.indicator != prev {
            assert!(
                t - last_change >= hold - 1e-9,
                "changed at {t} after {last_change}"
            );
            last_change = t;
            prev = out.reason.indicator;
        }
    }
    // 120 s / 8 s: at most 15 changes, and the rule did change.
    assert!((1..=15).contains(&p.changes()), "{}", p.changes());
}

/// The shipped table without its nominal attention gate, which every rule inherits and which
/// would hold the start before any of the gates below is reached.
fn shipped_without_the_attention_gate() -> AdaptivePolicy {
    let toml =
        policies::SHIPPED_TOML.replace("wait_for_attention = true", "wait_for_attention = false");
    assert_ne!(toml, policies::SHIPPED_TOML);
    AdaptivePolicy::new(RuleTable::from_toml_str(&toml).unwrap())
}

#[test]
fn asd_gates_the_start_on_the_confirmed_area() {
    let mut p = shipped_without_the_attention_gate();
    let asd = Some(Indicator::AsdCtx);
    let (_, t) = run(&mut p, 0.0, 9.0, asd, only(Indicator::AsdCtx, 0.1), ctx);
    let mut c = ctx(t);
    let a = assessment(t, asd, only(Indicator::AsdCtx, 0.1));
    let out = p.decide(&a, &c);
    assert_eq!(
        out.gate.hold,
        Some(HoldReason::AwaitingCollaborationAttention)
    );
    assert!(out.timing.gates_start());
    c.in_collaboration_area = true;
    assert!(p.decide(&a, &c).gate.clear);
    c.in_collaboration_area = false;
    c.in_instruction_area = true;
    // Both flags hold here; the first in order is reported.
    assert_eq!(
        p.decide(&a, &c).gate.hold,
        Some(HoldReason::AwaitingCollaborationAttention)
    );
}

#[test]
fn aed_defers_the_start_during_the_dwell_up_to_the_limit() {
    let mut p = shipped_without_the_attention_gate();
    let aed = Some(Indicator::Aed);
    let e = only(Indicator::Aed, 0.1);
    let (_, t0) = run(&mut p, 0.0, 9.0, aed, e, ctx);
    let limit = p.active_rule().adaptation().timing.max_assembly_deferral_s;
    assert_eq!(limit, 10.0);
    let dwelling = |phase| {
        move |t: f64| TaskContext {
            now_s: t,
            phase,
            assembly_dwell_s: 5.0 + t,
            ..TaskContext::default()
        }
    };
    // Fetch with a dwell: held, the deferral clock not started.
    let (out, t) = run(&mut p, t0, 20.0, aed, e, dwelling(TaskPhase::Fetch));
    assert_eq!(out.gate.hold, Some(HoldReason::AssemblyDwell));
    // Waiting: held for the limit, then released although the dwell goes on.
    let (out, t) = run(
        &mut p,
        t,
        limit - 0.1,
        aed,
        e,
        dwelling(TaskPhase::WaitForAttention),
    );
    assert_eq!(out.gate.hold, Some(HoldReason::AssemblyDwell));
    let (out, t) = run(
        &mut p,
        t,
        0.2,
        aed,
        e,
        dwelling(TaskPhase::WaitForAttention),
    );
    assert!(out.gate.clear, "{:?}", out.gate);
    // The next handover gets its own limit.
    let (_, t) = run(&mut p, t, 1.0, aed, e, dwelling(TaskPhase::Approach));
    let (out, t) = run(
        &mut p,
        t,
        1.0,
        aed,
        e,
        dwelling(TaskPhase::WaitForAttention),
    );
    assert_eq!(out.gate.hold, Some(HoldReason::AssemblyDwell));
    // The dwell ends: clear at once.
    let (out, _) = run(&mut p, t, 0.1, aed, e, ctx);
    assert!(out.gate.clear);
}

#[test]
fn time_going_backwards_or_nan_repeats_the_last_output() {
    let mut p = AdaptivePolicy::shipped();
    let (out, _) = run(
        &mut p,
        0.0,
        9.0,
        Some(Indicator::Tid),
        only(Indicator::Tid, 0.1),
        ctx,
    );
    let a = assessment(1.0, None, [0.0; 5]);
    assert_eq!(p.decide(&a, &ctx(1.0)), out);
    assert_eq!(p.decide(&a, &ctx(f64::NAN)), out);
    p.reset();
    assert_eq!(p.changes(), 0);
    assert_eq!(p.active_rule().indicator(), None);
}

const SMALL: &str = r#"
[limits]
min_hold_s = 5.0
switch_margin = 0.0
max_scale_rate_per_s = 1.0
max_timing_rate_s_per_s = 1.0
[rules.none]
rationale = "nominal"
[rules.AED]
rationale = "a"
[rules.TID]
rationale = "t"
[rules.ICD]
rationale = "i"
start_delay_s = 2.0
[rules.ASD_ctx]
rationale = "s"
[rules.OHD]
rationale = "o"
speed_scale = 0.4
"#;

#[test]
fn a_table_inherits_from_none_and_none_from_the_nominal() {
    let t = RuleTable::from_toml_str(SMALL).unwrap();
    assert_eq!(t.rule(None).adaptation(), Adaptation::NOMINAL);
    assert_eq!(
        t.rule(Some(Indicator::Ohd)).adaptation().speed_scale.get(),
        0.4
    );
    assert_eq!(t.rule(Some(Indicator::Icd)).rationale(), "i");
    assert_eq!(t.limits().min_hold_s(), 5.0);
}

#[test]
fn loader_errors_name_the_key() {
    let cases = [
        (
            SMALL.replace("speed_scale = 0.4", "speed_scale = 1.4"),
            "rules.OHD.speed_scale",
        ),
        (
            SMALL.replace("start_delay_s = 2.0", "start_delay_s = -1.0"),
            "rules.ICD.start_delay_s",
        ),
        (
            SMALL.replace("min_hold_s = 5.0", "min_hold_s = 0.0"),
            "limits.min_hold_s",
        ),
        (SMALL.replace("[rules.TID]", "[rules.TIDX]"), "rules.TIDX"),
        (
            SMALL.replace("[rules.TID]\nrationale = \"t\"\n", ""),
            "rules.TID",
        ),
        (
            SMALL.replace("rationale = \"s\"", "rationale = \" \""),
            "rules.ASD_ctx.rationale",
        ),
        (
            SMALL.replace("speed_scale = 0.4", "sped_scale = 0.4"),
            "sped_scale",
        ),
        (
            SMALL.replace("switch_margin = 0.0", "switch_margin = 0.0\nhold_s = 1"),
            "hold_s",
        ),
    ];
    for (text, key) in cases {
        let e = RuleTable::from_toml_str(&text).unwrap_err().to_string();
        assert!(e.contains(key), "`{key}` not in: {e}");
    }
    let e = RuleTable::from_toml_file("/nonexistent/policy.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("/nonexistent/policy.toml"), "{e}");
}

#[test]
fn limits_are_validated_and_replaceable() {
    assert!(Limits::new(1.0, 0.0, 0.1, 0.1).is_ok());
    let e = Limits::new(1.0, -0.1, 0.1, 0.1).unwrap_err().to_string();
    assert!(e.contains("limits.switch_margin"), "{e}");
    let table = RuleTable::shipped().with_limits(Limits::new(2.0, 0.0, 0.1, 0.1).unwrap());
    assert_eq!(table.limits().min_hold_s(), 2.0);
}
