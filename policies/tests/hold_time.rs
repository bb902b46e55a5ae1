//! Property tests: over random assessment streams the adaptive policy never changes its rule
//! (reason and gating flags) sooner than `min_hold_s` after the previous change, moves its
//! continuous parameters no faster than the slew limits, reverses a parameter's direction at
//! most once per `min_hold_s`, and always returns valid values.
//!
//! Two stream sources: assessments built directly (every field is public), covering arbitrary
//! dominant sequences, contributions and frame intervals; and a real `assess::Assessor` fed
//! random head cues over a four-area workspace. Cases: `PROPTEST_CASES` (default 256 and 24).

mod common;

use assess::{
    AssessConfig, Assessment, Assessor, BaselineMode, CueFrame, HeadCue, Indicator, Vec3, Workspace,
};
use common::assessment;
use policies::{Adaptation, AdaptivePolicy, Limits, Policy, RuleTable, TaskContext, TaskPhase};
use proptest::prelude::*;

fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

/// Watches a policy's outputs and checks the invariants step by step.
struct Monitor {
    limits: Limits,
    first_t: Option<f64>,
    last: Option<(f64, Adaptation)>,
    last_rule_change: Option<f64>,
    /// Per continuous parameter: the sign of its last non-zero change and when it last reversed.
    direction: [(f64, Option<f64>); 5],
    rule_changes: usize,
}

fn continuous(a: &Adaptation) -> [f64; 5] {
    [
        a.speed_scale.get(),
        a.acceleration_scale.get(),
        a.jerk_scale.get(),
        a.timing.start_delay_s,
        a.timing.min_approach_duration_s,
    ]
}

impl Monitor {
    fn new(limits: Limits) -> Monitor {
        Monitor {
            limits,
            first_t: None,
            last: None,
            last_rule_change: None,
            direction: [(0.0, None); 5],
            rule_changes: 0,
        }
    }

    fn observe(
        &mut self,
        t: f64,
        a: &Adaptation,
        dominant: Option<Indicator>,
    ) -> Result<(), TestCaseError> {
        let hold = self.limits.min_hold_s();
        let tol = 1e-9;
        // Valid values.
        for s in [a.speed_scale, a.acceleration_scale, a.jerk_scale] {
            prop_assert!(s.get() > 0.0 && s.get() <= 1.0, "scale {}", s.get());
        }
        for d in [
            a.timing.start_delay_s,
            a.timing.min_approach_duration_s,
            a.timing.max_assembly_deferral_s,
        ] {
            prop_assert!(d.is_finite() && d >= 0.0, "duration {d}");
        }
        prop_assert!(a.reason.strength.is_finite() && a.reason.strength >= 0.0);
        prop_assert!(
            a.timing.gates_start() || a.gate.clear,
            "held without a flag: {:?}",
            a.gate
        );
        let first = *self.first_t.get_or_insert(t);
        if let Some((t0, prev)) = self.last {
            let dt = t - t0;
            // Rule changes: no sooner than the hold after the previous one (or after the start),
            // and only to the indicator the assessment reports.
            if a.reason.indicator != prev.reason.indicator {
                let since = self.last_rule_change.unwrap_or(first);
                prop_assert!(
                    t - since >= hold - tol,
                    "rule changed at {t} s, {} s after the previous change (hold {hold} s)",
                    t - since
                );
                prop_assert_eq!(a.reason.indicator, dominant);
                self.last_rule_change = Some(t);
                self.rule_changes += 1;
            } else {
                // The flags change only with the rule.
                prop_assert_eq!(
                    a.timing.gating(),
                    prev.timing.gating(),
                    "flags changed without a rule change at {}",
                    t
                );
            }
            // Slew limits and direction reversals.
            let rates = [
                self.limits.max_scale_rate_per_s(),
                self.limits.max_scale_rate_per_s(),
                self.limits.max_scale_rate_per_s(),
                self.limits.max_timing_rate_s_per_s(),
                self.limits.max_timing_rate_s_per_s(),
            ];
            let (now, before) = (continuous(a), continuous(&prev));
            for i in 0..5 {
                let d = now[i] - before[i];
                prop_assert!(
                    d.abs() <= rates[i] * dt + tol,
                    "parameter {i} moved {d} in {dt} s"
                );
                if d != 0.0 {
                    let (sign, reversed_at) = self.direction[i];
                    if sign != 0.0 && sign != d.signum() {
                        if let Some(r) = reversed_at {
                            prop_assert!(
                                t - r >= hold - tol,
                                "parameter {i} reversed at {r} s and again at {t} s (hold {hold} s)"
                            );
                        }
                        self.direction[i].1 = Some(t);
                    }
                    self.direction[i].0 = d.signum();
                }
            }
        }
        self.last = Some((t, *a));
        Ok(())
    }
}

/// One segment of a synthetic stream: `frames` frames `dt_s` apart with the same dominant
/// indicator (index 5 = none) and contributions, calibrating or not, and a task context.
#[derive(Debug, Clone)]
struct Segment {
    dominant: usize,
    e: [f64; 5],
    frames: usize,
    dt_s: f64,
    calibrating: bool,
    phase: usize,
    in_collaboration_area: bool,
    in_instruction_area: bool,
    assembly_dwell: bool,
}

fn segment() -> impl Strategy<Value = Segment> {
    (
        0usize..6,
        proptest::array::uniform5(0.0f64..0.3),
        1usize..90,
        0.005f64..0.3,
        proptest::bool::weighted(0.1),
        0usize..8,
        any::<bool>(),
        any::<bool>(),
        any::<bool>(),
    )
        .prop_map(
            |(dominant, e, frames, dt_s, calibrating, phase, col, ins, dwell)| Segment {
                dominant,
                e,
                frames,
                dt_s,
                calibrating,
                phase,
                in_collaboration_area: col,
                in_instruction_area: ins && !col,
                assembly_dwell: dwell,
            },
        )
}

fn limits() -> impl Strategy<Value = Limits> {
    (0.2f64..20.0, 0.0f64..0.05, 0.02f64..2.0, 0.05f64..3.0)
        .prop_map(|(h, m, s, t)| Limits::new(h, m, s, t).unwrap())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(256)))]

    #[test]
    fn synthetic_streams_never_change_faster_than_the_hold(
        limits in limits(),
        segments in proptest::collection::vec(segment(), 1..80),
    ) {
        let mut policy = AdaptivePolicy::new(RuleTable::shipped().with_limits(limits));
        let mut monitor = Monitor::new(limits);
        let mut t = 0.0;
        for s in &segments {
            for _ in 0..s.frames {
                let dominant = Indicator::from_index(s.dominant);
                let mut a: Assessment = assessment(t, dominant, s.e);
                a.dominant.calibrating = s.calibrating;
                let ctx = TaskContext {
                    now_s: t,
                    phase: TaskPhase::ALL[s.phase],
                    in_collaboration_area: s.in_collaboration_area,
                    in_instruction_area: s.in_instruction_area,
                    assembly_dwell_s: if s.assembly_dwell { t } else { 0.0 },
                };
                let out = policy.decide(&a, &ctx);
                let reported = if s.calibrating { None } else { dominant };
                monitor.observe(t, &out, reported)?;
                t += s.dt_s;
            }
        }
        prop_assert_eq!(monitor.rule_changes as u64, policy.changes());
    }
}

/// The four-area workspace of the real-assessor test, with the operator's head at the origin.
fn workspace() -> Workspace {
    Workspace::from_toml_str(
        r#"
        [[area]]
        name = "assembly"
        role = "assembly"
        min_m = [0.3, -0.2, 0.7]
        max_m = [0.7, 0.2, 0.9]
        [[area]]
        name = "storage"
        role = "tool_identification"
        min_m = [-0.2, -0.9, 0.7]
        max_m = [0.2, -0.6, 1.0]
        [[area]]
        name = "instruction"
        role = "instruction"
        min_m = [0.3, 0.6, 1.0]
        max_m = [0.5, 0.9, 1.4]
        [[area]]
        name = "handover"
        role = "collaboration"
        min_m = [0.6, -0.2, 1.0]
        max_m = [0.9, 0.2, 1.3]
        "#,
    )
    .unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(24)))]

    /// A real assessor (fixed baseline, so the dominant indicator is live from the start) on
    /// random gaze segments with noise and dropouts.
    #[test]
    fn real_assessor_streams_never_change_faster_than_the_hold(
        limits in limits(),
        gaze in proptest::collection::vec((0usize..5, 0.3f64..15.0), 4..30),
        noise in proptest::collection::vec((-0.2f64..0.2, -0.2f64..0.2, proptest::bool::weighted(0.1)), 64),
    ) {
        let ws = workspace();
        let centres: Vec<Vec3> = ws.areas().iter().map(|a| a.representative_centre).collect();
        let mut cfg = AssessConfig::default();
        cfg.dominant.baseline_mode = BaselineMode::Fixed;
        let mut assessor = Assessor::new(ws, cfg).unwrap();
        let mut policy = AdaptivePolicy::new(RuleTable::shipped().with_limits(limits));
        let mut monitor = Monitor::new(limits);
        let head = Vec3::new(0.0, 0.0, 1.2);
        let mut k = 0usize;
        for &(area, duration_s) in &gaze {
            let end = k as f64 / 30.0 + duration_s;
            while (k as f64 / 30.0) < end {
                let t = k as f64 / 30.0;
                let (nx, ny, dropped) = noise[k % noise.len()];
                let mut frame = CueFrame::empty(t);
                if !dropped {
                    // Area 4 is "away": looking up at nothing.
                    let target = centres.get(area).copied().unwrap_or(Vec3::new(0.0, 0.0, 3.0));
                    let facing = (target - head).normalize() + Vec3::new(nx, ny, 0.0) * 0.3;
                    frame.head = Some(HeadCue { position: head, facing, confidence: 0.9 });
                }
                let a = assessor.update(&frame);
                let ctx = TaskContext { now_s: t, phase: TaskPhase::Fetch, ..TaskContext::default() };
                let out = policy.decide(a, &ctx);
                let reported = if a.dominant.calibrating { None } else { a.dominant.indicator };
                monitor.observe(t, &out, reported)?;
                k += 1;
            }
        }
    }
}
