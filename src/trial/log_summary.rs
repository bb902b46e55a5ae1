//! `summary.json`: the trial's outcome measures, every one derived from the logged assessments
//! and [`TrialEvent`]s (nothing is taken from the runtime's own counters).
//!
//! # Definitions
//! Times are trial time [s]. An assessed frame k stands for the interval
//! (t_k − Δt_k, t_k], with Δt_k its `dt_s` (the interval the assessor integrated), so the sums
//! below are the assessor's own integrals.
//! - `completion_time_s`: the time of the first `Finished` event, else of the last record.
//!   Intervals still open then (idle, hesitation, phase) are closed at it.
//! - `handovers[i]`: `robot_wait_s` = Σ over presentations of (Grasped or PartReturned − Presented);
//!   `operator_wait_s` = Grasped − the first OperatorNeedsPart of that handover (`null` when
//!   either is missing); `returned`: a PartReturned event occurred for it.
//! - `robot_idle_s`: time the task phase was `Idle`, `WaitForAttention` or `Present` (the robot
//!   holds still, waiting for the operator), from `TaskPhase` events.
//! - `operator_idle_s`: time between `OperatorIdle { idle: true }` and the next `idle: false`.
//! - `hesitation_share.assessed`: Σ Δt over frames with H = 1 / Σ Δt over frames with C = 1.
//!   `hesitation_share.ground_truth`: the time the simulated operator's `Hesitation` episodes
//!   overlap those C = 1 frames, over the same denominator. `null` when C was never 1.
//! - `hesitation_episodes`: assessed against simulated hesitation episode by episode (recall,
//!   precision, onset delay, every episode), defined in `hesitation_episodes.rs`.
//! - `hrc_cwl_mean` / `hrc_cwl_max`: the cumulative and windowed HRC-CWL; the mean is
//!   time-weighted by Δt (the plain mean if every Δt is 0).
//! - `dominant_time_s`: Σ Δt per reported dominant indicator (`AED`, `TID`, `ICD`, `ASD_ctx`,
//!   `OHD`, `none`).
//! - `adaptation_changes`: `AdaptationChanged` events, in total and by the new rule's indicator.
//! - `safety_events`: `Safety` events (debounced verdict changes, see the `log` module docs),
//!   in total, by reaction and by requirement.
//! - `motion`: motion quality from the raw per-cycle records (`motion_metrics.rs`, and
//!   README.md, "Motion quality metrics"): supervisor interventions per requirement, raw per
//!   command and as the debounced events above; stop windows; executed jerk and its limit;
//!   velocity reversals; stop-and-go events; missed cycles, latency and wake jitter.
//!
//! # Formatting
//! Keys come in the order of the structs below (maps in sorted order); every real number is
//! rounded to 6 decimals (−0 written as 0), so the same log gives the same bytes.

use std::collections::BTreeMap;

use assess::Indicator;
use serde::Serialize;

use super::TrialMeta;
use super::motion::{MotionMetrics, MotionSummary, requirement_index};
use crate::trial::events::TrialEvent;

#[path = "hesitation_episodes.rs"]
pub(crate) mod episodes;
pub(crate) use episodes::HesitationEpisodes;

/// What the summary needs of one assessed frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct FrameRecord {
    /// Frame time t_k [s].
    pub(crate) t_s: f64,
    /// Δt_k, the interval the frame stands for [s].
    pub(crate) dt_s: f64,
    /// C(t) = 1.
    pub(crate) collaborating: bool,
    /// C ∧ G ∧ v_h < v_th: a low-motion run continues or starts (MODEL.md §7).
    pub(crate) low_motion: bool,
    /// H(t) = 1.
    pub(crate) hesitating: bool,
    /// Cumulative HRC-CWL [-].
    pub(crate) hrc_cwl: f64,
    /// Windowed HRC-CWL [-].
    pub(crate) hrc_cwl_windowed: f64,
    /// The reported dominant indicator (`None` = "none").
    pub(crate) dominant: Option<Indicator>,
}

impl FrameRecord {
    /// The record of an assessment.
    pub(crate) fn of(a: &assess::Assessment) -> Self {
        Self {
            t_s: a.t,
            dt_s: a.dt_s,
            collaborating: a.collaborating,
            low_motion: a.low_motion,
            hesitating: a.hesitating,
            hrc_cwl: a.cumulative.hrc_cwl,
            hrc_cwl_windowed: a.windowed.hrc_cwl,
            dominant: a.dominant.indicator,
        }
    }
}

/// One handover's waits.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct HandoverSummary {
    /// The handover's index (as the events number it).
    pub(crate) index: u32,
    /// Robot wait: Presented → Grasped (or → PartReturned), summed over presentations [s].
    pub(crate) robot_wait_s: Option<f64>,
    /// Operator wait: OperatorNeedsPart → Grasped [s].
    pub(crate) operator_wait_s: Option<f64>,
    /// The part was returned at least once (presentation timed out).
    pub(crate) returned: bool,
}

/// Assessed and ground-truth hesitation shares.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct HesitationShare {
    /// Time with H = 1 over time with C = 1 [-].
    pub(crate) assessed: Option<f64>,
    /// Time in simulated hesitation episodes during C = 1, over time with C = 1 [-].
    pub(crate) ground_truth: Option<f64>,
    /// The denominator: time with C = 1 [s].
    pub(crate) collaboration_time_s: f64,
}

/// A statistic of the cumulative and the windowed HRC-CWL.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct CwlPair {
    /// Of the cumulative HRC-CWL [-].
    pub(crate) cumulative: Option<f64>,
    /// Of the windowed HRC-CWL [-].
    pub(crate) windowed: Option<f64>,
}

/// Adaptation changes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct AdaptationChanges {
    /// Number of changes.
    pub(crate) total: u64,
    /// By the new rule's indicator (`none` = back to nominal).
    pub(crate) by_indicator: BTreeMap<String, u64>,
}

/// Safety events.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct SafetyEvents {
    /// Number of events.
    pub(crate) total: u64,
    /// By reaction (`reduced`, `stopped`, `halted`).
    pub(crate) by_reaction: BTreeMap<String, u64>,
    /// By requirement (`SAF-REQ-nnn`).
    pub(crate) by_requirement: BTreeMap<String, u64>,
}

/// The trial's identity as `summary.json` writes it: [`TrialMeta`] without the wall-clock
/// start, so that a simulated trial's summary depends only on its seed and config (the start
/// time is in `trial.mcap`'s `/trial/meta` and in the report).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct SummaryMeta {
    /// Participant id.
    pub(crate) participant: String,
    /// Task condition.
    pub(crate) condition: String,
    /// Policy name.
    pub(crate) policy: String,
    /// Seed.
    pub(crate) seed: u64,
    /// The operator is simulated.
    pub(crate) simulated: bool,
    /// `recorded:<file name>` for a recorded cue file; absent for the simulated operator.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) cue_source: Option<String>,
    /// The robot backend.
    pub(crate) robot: String,
}

impl SummaryMeta {
    fn of(m: &TrialMeta) -> Self {
        Self {
            participant: m.participant.clone(),
            condition: m.condition.clone(),
            policy: m.policy.clone(),
            seed: m.seed,
            simulated: m.simulated,
            cue_source: m.cue_source.clone(),
            robot: m.robot.clone(),
        }
    }
}

/// The content of `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct Summary {
    /// The trial's identity (with `simulated`).
    pub(crate) meta: SummaryMeta,
    /// Trial duration [s].
    pub(crate) completion_time_s: f64,
    /// Why the trial ended (the `Finished` event's reason), if it ended cleanly.
    pub(crate) finish_reason: Option<String>,
    /// Every handover, by index.
    pub(crate) handovers: Vec<HandoverSummary>,
    /// Robot idle time [s].
    pub(crate) robot_idle_s: f64,
    /// Operator idle time [s].
    pub(crate) operator_idle_s: f64,
    /// Hesitation shares.
    pub(crate) hesitation_share: HesitationShare,
    /// Assessed against simulated hesitation, episode by episode.
    pub(crate) hesitation_episodes: HesitationEpisodes,
    /// Time-weighted mean HRC-CWL [-].
    pub(crate) hrc_cwl_mean: CwlPair,
    /// Maximum HRC-CWL [-].
    pub(crate) hrc_cwl_max: CwlPair,
    /// Time each indicator was the reported dominant one [s].
    pub(crate) dominant_time_s: BTreeMap<String, f64>,
    /// Adaptation changes.
    pub(crate) adaptation_changes: AdaptationChanges,
    /// Safety events.
    pub(crate) safety_events: SafetyEvents,
    /// Assessed frames the summary was computed from.
    pub(crate) assessed_frames: u64,
    /// Motion quality (from the raw per-cycle records).
    pub(crate) motion: MotionSummary,
}

/// Rounds to 6 decimals; −0 becomes 0 and non-finite values stay as they are (JSON `null`).
pub(crate) fn r6(x: f64) -> f64 {
    if !x.is_finite() {
        return x;
    }
    let r = (x * 1e6).round() / 1e6;
    if r == 0.0 { 0.0 } else { r }
}

/// Phases in which the robot holds still waiting for the operator.
const ROBOT_IDLE_PHASES: [&str; 3] = ["Idle", "WaitForAttention", "Present"];

/// Length of the overlap of the union of `a` with the union of `b`; both lists must be sorted,
/// each made of disjoint [start, end] intervals [s].
fn overlap(a: &[(f64, f64)], b: &[(f64, f64)]) -> f64 {
    let (mut i, mut j, mut sum) = (0, 0, 0.0);
    while let (Some(&(a0, a1)), Some(&(b0, b1))) = (a.get(i), b.get(j)) {
        let lo = a0.max(b0);
        let hi = a1.min(b1);
        if hi > lo {
            sum += hi - lo;
        }
        if a1 < b1 { i += 1 } else { j += 1 }
    }
    sum
}

/// Computes the summary (see the module docs for the definitions) from the assessed frames,
/// the events and the finished motion metrics.
pub(crate) fn compute(
    meta: &TrialMeta,
    frames: &[FrameRecord],
    events: &[(f64, TrialEvent)],
    motion: &MotionMetrics,
) -> Summary {
    let finished = events.iter().find_map(|&(t, e)| match e {
        TrialEvent::Finished { reason } => Some((t, reason)),
        _ => None,
    });
    let last_t = frames
        .iter()
        .map(|f| f.t_s)
        .chain(events.iter().map(|e| e.0))
        .fold(0.0_f64, f64::max);
    let end = finished.map_or(last_t, |f| f.0);

    // Handovers.
    #[derive(Default)]
    struct Open {
        presented: Option<f64>,
        robot_wait: Option<f64>,
        needs: Option<f64>,
        grasped: Option<f64>,
        returned: bool,
    }
    let mut handovers: BTreeMap<u32, Open> = BTreeMap::new();
    // Intervals driven by state events.
    let mut robot_idle = 0.0;
    let mut phase: Option<(&str, f64)> = None;
    let mut phase_changes: Vec<(f64, &str)> = Vec::new();
    let mut operator_idle = 0.0;
    let mut idle_since: Option<f64> = None;
    let mut hesitations: Vec<(f64, f64)> = Vec::new();
    let mut hesitating_since: Option<f64> = None;
    let mut adaptation = AdaptationChanges {
        total: 0,
        by_indicator: BTreeMap::new(),
    };
    let mut safety = SafetyEvents {
        total: 0,
        by_reaction: BTreeMap::new(),
        by_requirement: BTreeMap::new(),
    };
    let mut debounced = [0u64; safety::Requirement::COUNT];
    let close_presentation = |h: &mut Open, t: f64| {
        if let Some(p) = h.presented.take() {
            *h.robot_wait.get_or_insert(0.0) += t - p;
        }
    };
    for &(t, e) in events.iter().filter(|e| e.0 <= end) {
        match e {
            TrialEvent::TaskPhase { phase: p } => {
                if let Some((prev, since)) = phase
                    && ROBOT_IDLE_PHASES.contains(&prev)
                {
                    robot_idle += t - since;
                }
                phase = Some((p, t));
                phase_changes.push((t, p));
            }
            TrialEvent::Presented { handover } => {
                let h = handovers.entry(handover).or_default();
                h.presented.get_or_insert(t);
            }
            TrialEvent::Grasped { handover } => {
                let h = handovers.entry(handover).or_default();
                close_presentation(h, t);
                h.grasped.get_or_insert(t);
            }
            TrialEvent::PartReturned { handover } => {
                let h = handovers.entry(handover).or_default();
                close_presentation(h, t);
                h.returned = true;
            }
            TrialEvent::OperatorNeedsPart { handover } => {
                handovers
                    .entry(handover)
                    .or_default()
                    .needs
                    .get_or_insert(t);
            }
            TrialEvent::OperatorIdle { idle: true } => {
                idle_since.get_or_insert(t);
            }
            TrialEvent::OperatorIdle { idle: false } => {
                if let Some(s) = idle_since.take() {
                    operator_idle += t - s;
                }
            }
            TrialEvent::Hesitation { active: true } => {
                hesitating_since.get_or_insert(t);
            }
            TrialEvent::Hesitation { active: false } => {
                if let Some(s) = hesitating_since.take() {
                    hesitations.push((s, t));
                }
            }
            TrialEvent::AdaptationChanged { indicator } => {
                adaptation.total += 1;
                *adaptation.by_indicator.entry(indicator.into()).or_default() += 1;
            }
            TrialEvent::Safety {
                reaction,
                requirement,
            } => {
                safety.total += 1;
                *safety.by_reaction.entry(reaction.into()).or_default() += 1;
                *safety.by_requirement.entry(requirement.into()).or_default() += 1;
                if let Some(c) = requirement_index(requirement).and_then(|i| debounced.get_mut(i)) {
                    *c += 1;
                }
            }
            TrialEvent::Finished { .. } | TrialEvent::Link { .. } => {}
        }
    }
    // Close what is still open at the end.
    if let Some((p, since)) = phase
        && ROBOT_IDLE_PHASES.contains(&p)
    {
        robot_idle += end - since;
    }
    if let Some(s) = idle_since {
        operator_idle += end - s;
    }
    if let Some(s) = hesitating_since {
        hesitations.push((s, end));
    }
    let handovers = handovers
        .into_iter()
        .map(|(index, mut h)| {
            close_presentation(&mut h, end);
            HandoverSummary {
                index,
                robot_wait_s: h.robot_wait.map(r6),
                operator_wait_s: match (h.needs, h.grasped) {
                    (Some(n), Some(g)) => Some(r6(g - n)),
                    _ => None,
                },
                returned: h.returned,
            }
        })
        .collect();

    // Assessed streams.
    let frames: Vec<&FrameRecord> = frames.iter().filter(|f| f.t_s <= end).collect();
    let mut collab_time = 0.0;
    let mut hes_time = 0.0;
    let mut collab_intervals: Vec<(f64, f64)> = Vec::new();
    let mut dominant: BTreeMap<String, f64> = Indicator::ALL
        .iter()
        .map(|k| k.name())
        .chain(["none"])
        .map(|k| (k.to_string(), 0.0))
        .collect();
    let (mut sum_dt, mut sum_c, mut sum_w) = (0.0, 0.0, 0.0);
    let (mut max_c, mut max_w) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    for f in &frames {
        if f.collaborating {
            collab_time += f.dt_s;
            let iv = (f.t_s - f.dt_s, f.t_s);
            match collab_intervals.last_mut() {
                Some(last) if last.1 >= iv.0 => last.1 = iv.1,
                _ => collab_intervals.push(iv),
            }
        }
        if f.hesitating && f.collaborating {
            hes_time += f.dt_s;
        }
        *dominant
            .entry(f.dominant.map_or("none", Indicator::name).to_string())
            .or_default() += f.dt_s;
        sum_dt += f.dt_s;
        sum_c += f.dt_s * f.hrc_cwl;
        sum_w += f.dt_s * f.hrc_cwl_windowed;
        max_c = max_c.max(f.hrc_cwl);
        max_w = max_w.max(f.hrc_cwl_windowed);
    }
    let n = frames.len() as f64;
    let mean = |weighted: f64, plain: fn(&FrameRecord) -> f64| {
        if frames.is_empty() {
            None
        } else if sum_dt > 0.0 {
            Some(r6(weighted / sum_dt))
        } else {
            Some(r6(frames.iter().map(|f| plain(f)).sum::<f64>() / n))
        }
    };
    let some_max = |m: f64| (!frames.is_empty()).then(|| r6(m));
    let share = |x: f64| (collab_time > 0.0).then(|| r6(x / collab_time));

    Summary {
        meta: SummaryMeta::of(meta),
        completion_time_s: r6(end),
        finish_reason: finished.map(|f| f.1.to_string()),
        handovers,
        robot_idle_s: r6(robot_idle),
        operator_idle_s: r6(operator_idle),
        hesitation_share: HesitationShare {
            assessed: share(hes_time),
            ground_truth: share(overlap(&collab_intervals, &hesitations)),
            collaboration_time_s: r6(collab_time),
        },
        hesitation_episodes: episodes::compute(&frames, &hesitations, &phase_changes),
        hrc_cwl_mean: CwlPair {
            cumulative: mean(sum_c, |f| f.hrc_cwl),
            windowed: mean(sum_w, |f| f.hrc_cwl_windowed),
        },
        hrc_cwl_max: CwlPair {
            cumulative: some_max(max_c),
            windowed: some_max(max_w),
        },
        dominant_time_s: dominant.into_iter().map(|(k, v)| (k, r6(v))).collect(),
        adaptation_changes: adaptation,
        safety_events: safety,
        assessed_frames: frames.len() as u64,
        motion: motion.summary(&debounced),
    }
}

/// The summary as pretty-printed JSON with a final newline.
pub(crate) fn to_json(summary: &Summary) -> serde_json::Result<String> {
    let mut s = serde_json::to_string_pretty(summary)?;
    s.push('\n');
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta() -> TrialMeta {
        TrialMeta {
            participant: "P01".into(),
            condition: "L2".into(),
            policy: "adaptive".into(),
            seed: 7,
            simulated: true,
            cue_source: None,
            started_utc: "2026-01-01T00:00:00Z".into(),
            robot: "sim".into(),
        }
    }

    fn frame(
        t_s: f64,
        c: bool,
        h: bool,
        cwl: f64,
        win: f64,
        dom: Option<Indicator>,
    ) -> FrameRecord {
        FrameRecord {
            t_s,
            dt_s: 1.0,
            collaborating: c,
            low_motion: h,
            hesitating: h,
            hrc_cwl: cwl,
            hrc_cwl_windowed: win,
            dominant: dom,
        }
    }

    /// A hand-made 10 s trial with two handovers; every expected value is computed by hand in
    /// the comments.
    #[test]
    fn summary_of_a_hand_made_trial() {
        use Indicator::*;
        use TrialEvent as E;
        // Ten frames at t = 1..10, each standing for 1 s: frame t covers (t − 1, t].
        // C = 1 on frames 3..=6 (interval (2, 6]) → collaboration time 4 s.
        // H = 1 on frames 5 and 6 → 2 s; assessed share 2/4 = 0.5.
        // Dominant: none on 1–2 (2 s), OHD on 3–6 (4 s), ICD on 7–10 (4 s).
        // Cumulative CWL 0.1·t → mean (0.1+…+1.0)/10 = 0.55, max 1.0.
        // Windowed CWL 0.2 on frames 1–5, 0.6 on 6–10 → mean 0.4, max 0.6.
        let frames: Vec<FrameRecord> = (1..=10)
            .map(|k| {
                let t = k as f64;
                let dom = match k {
                    1..=2 => None,
                    3..=6 => Some(Ohd),
                    _ => Some(Icd),
                };
                let win = if k <= 5 { 0.2 } else { 0.6 };
                frame(
                    t,
                    (3..=6).contains(&k),
                    (5..=6).contains(&k),
                    0.1 * t,
                    win,
                    dom,
                )
            })
            .collect();
        let events = vec![
            (0.0, E::TaskPhase { phase: "Idle" }),
            (0.5, E::OperatorIdle { idle: true }),
            (1.0, E::TaskPhase { phase: "Fetch" }), // robot idle 0–1: 1 s
            (1.0, E::OperatorNeedsPart { handover: 0 }),
            (2.0, E::OperatorIdle { idle: false }), // operator idle 0.5–2: 1.5 s
            (2.0, E::TaskPhase { phase: "Approach" }),
            (3.0, E::TaskPhase { phase: "Present" }),
            (3.0, E::Presented { handover: 0 }),
            (3.5, E::Hesitation { active: true }),
            (4.5, E::Hesitation { active: false }), // 1 s, all inside C = (2, 6]
            (4.0, E::AdaptationChanged { indicator: "OHD" }),
            (4.5, E::Grasped { handover: 0 }), // robot wait 1.5, operator wait 3.5
            (4.5, E::TaskPhase { phase: "Retreat" }), // robot idle 3–4.5: 1.5 s
            (
                5.0,
                E::Safety {
                    reaction: "reduced",
                    requirement: "SAF-REQ-007",
                },
            ),
            (
                5.2,
                E::Safety {
                    reaction: "stopped",
                    requirement: "SAF-REQ-007",
                },
            ),
            (5.5, E::Hesitation { active: true }), // until 9; overlap with C: 5.5–6 = 0.5 s
            (6.0, E::TaskPhase { phase: "Present" }),
            (6.0, E::Presented { handover: 1 }),
            (
                6.5,
                E::Safety {
                    reaction: "reduced",
                    requirement: "SAF-REQ-005",
                },
            ),
            (7.0, E::PartReturned { handover: 1 }), // robot wait 1 s so far
            (7.0, E::TaskPhase { phase: "Retreat" }), // robot idle 6–7: 1 s
            (7.0, E::AdaptationChanged { indicator: "ICD" }),
            (7.5, E::OperatorNeedsPart { handover: 1 }),
            (8.0, E::TaskPhase { phase: "Present" }),
            (8.0, E::Presented { handover: 1 }),
            (8.5, E::OperatorIdle { idle: true }), // open until the end at 10: 1.5 s
            (9.0, E::Hesitation { active: false }),
            (9.0, E::AdaptationChanged { indicator: "none" }),
            (10.0, E::Finished { reason: "stopped" }), // Present 8–10 open: robot idle 2 s,
            // handover 1's second presentation 8–10: robot wait 1 + 2 = 3 s, never grasped.
            (
                11.0,
                E::Safety {
                    reaction: "halted",
                    requirement: "SAF-REQ-011",
                },
            ), // after the end
        ];
        let mut motion = MotionMetrics::new();
        motion.finish();
        let s = compute(&meta(), &frames, &events, &motion);
        let mut got: serde_json::Value = serde_json::from_str(&to_json(&s).unwrap()).unwrap();
        // The debounced events reach `motion` per requirement (SAF-REQ-011's comes after the
        // end); the rest of `motion` has its own tests (motion_metrics.rs).
        let m = got.as_object_mut().unwrap().remove("motion").unwrap();
        let by = &m["interventions"]["by_requirement"];
        assert_eq!(by["SAF-REQ-007"]["debounced_events"], 2);
        assert_eq!(by["SAF-REQ-005"]["debounced_events"], 1);
        assert_eq!(by["SAF-REQ-011"]["debounced_events"], 0);
        assert_eq!(m["interventions"]["total"]["debounced_events"], 3);
        let want = serde_json::json!({
            "meta": {
                "participant": "P01", "condition": "L2", "policy": "adaptive", "seed": 7,
                "simulated": true, "robot": "sim"
            },
            "completion_time_s": 10.0,
            "finish_reason": "stopped",
            "handovers": [
                {"index": 0, "robot_wait_s": 1.5, "operator_wait_s": 3.5, "returned": false},
                {"index": 1, "robot_wait_s": 3.0, "operator_wait_s": null, "returned": true}
            ],
            // 1 (Idle 0–1) + 1.5 (Present 3–4.5) + 1 (Present 6–7) + 2 (Present 8–10).
            "robot_idle_s": 5.5,
            // 1.5 (0.5–2) + 1.5 (8.5–10).
            "operator_idle_s": 3.0,
            // Ground truth: (1 + 0.5) / 4 = 0.375.
            "hesitation_share": {"assessed": 0.5, "ground_truth": 0.375, "collaboration_time_s": 4.0},
            // Episodes: truth [3.5, 4.5] (no H frame in it: missed) and [5.5, 9] (first H
            // frame t = 6: delay 0.5; its run starts at 5 − 1 = 4: attributed 4 − 5.5 = −1.5).
            // One assessed run, frames 5–6: start 4, detected 5, end 6; it overlaps
            // [3.5, 4.5] (matched); the phase at 5 is Retreat (from 4.5).
            "hesitation_episodes": {
                "ground_truth": 2, "detected": 1, "recall": 0.5,
                "assessed": 1, "matched": 1, "precision": 1.0,
                "onset_delay_median_s": 0.5,
                "truth_episodes": [
                    {"start_s": 3.5, "end_s": 4.5, "detected_s": null, "delay_s": null,
                     "attributed_onset_s": null},
                    {"start_s": 5.5, "end_s": 9.0, "detected_s": 6.0, "delay_s": 0.5,
                     "attributed_onset_s": -1.5}
                ],
                "assessed_episodes": [
                    {"start_s": 4.0, "detected_s": 5.0, "end_s": 6.0, "matched": true,
                     "phase": "Retreat"}
                ]
            },
            "hrc_cwl_mean": {"cumulative": 0.55, "windowed": 0.4},
            "hrc_cwl_max": {"cumulative": 1.0, "windowed": 0.6},
            "dominant_time_s": {"AED": 0.0, "ASD_ctx": 0.0, "ICD": 4.0, "OHD": 4.0, "TID": 0.0, "none": 2.0},
            "adaptation_changes": {"total": 3, "by_indicator": {"ICD": 1, "OHD": 1, "none": 1}},
            "safety_events": {
                "total": 3,
                "by_reaction": {"reduced": 2, "stopped": 1},
                "by_requirement": {"SAF-REQ-005": 1, "SAF-REQ-007": 2}
            },
            "assessed_frames": 10
        });
        assert_eq!(got, want, "{}", to_json(&s).unwrap());
    }

    #[test]
    fn key_order_and_number_format_are_fixed() {
        let s = compute(
            &meta(),
            &[frame(1.0 / 3.0, false, false, -1e-9, 0.0, None)],
            &[],
            &MotionMetrics::new(),
        );
        let text = to_json(&s).unwrap();
        // Struct order, not alphabetical; 6 decimals; −0 as 0.
        let meta_at = text.find("\"meta\"").unwrap();
        let completion_at = text.find("\"completion_time_s\"").unwrap();
        assert!(meta_at < completion_at);
        // `motion` comes last, after every key the summary had before it.
        assert!(text.find("\"assessed_frames\"").unwrap() < text.find("\"motion\"").unwrap());
        assert!(text.contains("\"completion_time_s\": 0.333333,"), "{text}");
        assert!(text.contains("\"cumulative\": 0.0"), "{text}");
        assert!(text.contains("\"assessed\": null"), "{text}");
        assert_eq!(text, to_json(&s.clone()).unwrap());
    }

    #[test]
    fn overlap_of_interval_lists() {
        assert_eq!(overlap(&[(0.0, 2.0), (3.0, 5.0)], &[(1.0, 4.0)]), 2.0);
        assert_eq!(overlap(&[], &[(1.0, 4.0)]), 0.0);
    }
}
