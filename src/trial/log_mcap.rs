//! The channels of `trial.mcap`: topics, JSON schemas and the JSON text of each message.
//!
//! Every channel follows the MCAP well-known encodings for JSON: the schema record has encoding
//! `jsonschema` and holds a JSON Schema (draft 2020-12) of the message object, and the channel's
//! message encoding is `json` (one UTF-8 JSON object per message). Foxglove reads these
//! natively. Message log and publish times are trial time in nanoseconds (the files therefore
//! start at the Unix epoch in Foxglove's clock; `/trial/meta`'s first message carries the
//! wall-clock start).
//!
//! The hot records (robot state, commands, separation) are formatted by hand into a reused
//! buffer; the 30 Hz records go through `serde_json`.

use std::io::Write;

use robot_io::{JointCommand, RobotState};
use safety::Verdict;

use crate::trial::events::TrialEvent;

/// One channel: topic, schema name and JSON Schema text.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ChannelSpec {
    /// Topic.
    pub(crate) topic: &'static str,
    /// Schema name.
    pub(crate) schema_name: &'static str,
    /// The JSON Schema of a message.
    pub(crate) schema: &'static str,
}

/// Index of each channel in [`CHANNELS`].
pub(crate) mod ch {
    /// `/trial/meta`.
    pub(crate) const META: usize = 0;
    /// `/operator/cues`.
    pub(crate) const CUES: usize = 1;
    /// `/assessment`.
    pub(crate) const ASSESSMENT: usize = 2;
    /// `/policy/adaptation`.
    pub(crate) const ADAPTATION: usize = 3;
    /// `/robot/state`.
    pub(crate) const ROBOT_STATE: usize = 4;
    /// `/robot/command`.
    pub(crate) const COMMAND: usize = 5;
    /// `/safety/events`.
    pub(crate) const SAFETY: usize = 6;
    /// `/task/events`.
    pub(crate) const TASK: usize = 7;
    /// `/safety/separation`.
    pub(crate) const SEPARATION: usize = 8;
    /// `/robot/cycle`.
    pub(crate) const CYCLE: usize = 9;
}

macro_rules! schema {
    ($title:literal, $props:literal) => {
        concat!(
            r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","type":"object","title":""#,
            $title,
            r#"","properties":"#,
            $props,
            "}"
        )
    };
}

/// Every channel, in the order of [`ch`].
pub(crate) const CHANNELS: [ChannelSpec; 10] = [
    ChannelSpec {
        topic: "/trial/meta",
        schema_name: "hrc_adapt.TrialMeta",
        schema: schema!(
            "Trial identity",
            r#"{"participant":{"type":"string"},"condition":{"type":"string"},"policy":{"type":"string"},"seed":{"type":"integer"},"simulated":{"type":"boolean"},"cue_source":{"type":"string"},"started_utc":{"type":"string"},"robot":{"type":"string"}}"#
        ),
    },
    ChannelSpec {
        topic: "/operator/cues",
        schema_name: "hrc_adapt.CueFrame",
        schema: schema!(
            "Operator cues (workspace frame, m; confidences 0..1)",
            r#"{"t_s":{"type":"number"},"head":{"type":["object","null"],"properties":{"position":{"type":"array","items":{"type":"number"}},"facing":{"type":"array","items":{"type":"number"}},"confidence":{"type":"number"}}},"body":{"type":["object","null"],"properties":{"position":{"type":"array","items":{"type":"number"}},"facing":{"type":"array","items":{"type":"number"}},"confidence":{"type":"number"}}},"left_hand":{"type":["object","null"],"properties":{"position":{"type":"array","items":{"type":"number"}},"confidence":{"type":"number"}}},"right_hand":{"type":["object","null"],"properties":{"position":{"type":"array","items":{"type":"number"}},"confidence":{"type":"number"}}},"collaborating":{"type":"boolean"},"incomplete":{"type":"boolean"}}"#
        ),
    },
    ChannelSpec {
        topic: "/assessment",
        schema_name: "hrc_adapt.Assessment",
        schema: schema!(
            "Assessment: area states, indicators (cumulative and windowed), dominant indicator",
            r##"{"t_s":{"type":"number"},"dt_s":{"type":"number"},"valid":{"type":"boolean"},"confirmed":{"type":"string"},"perceptual":{"type":"string"},"action":{"type":"string"},"collaborating":{"type":"boolean"},"hesitating":{"type":"boolean"},"hand_speed_m_s":{"type":["number","null"]},"v_th_m_s":{"type":"number"},"cumulative":{"$ref":"#/$defs/indicators"},"windowed":{"$ref":"#/$defs/indicators"},"dominant":{"type":"string"},"dominant_strength":{"type":"number"},"calibrating":{"type":"boolean"}},"$defs":{"indicators":{"type":"object","properties":{"aed":{"type":"number"},"tid":{"type":"number"},"icd":{"type":"number"},"col":{"type":"number"},"abi":{"type":"number"},"asd_ctx":{"type":"number"},"asd_norm":{"type":"number"},"ohd":{"type":"number"},"hrc_cwl":{"type":"number"},"category":{"type":"string"}}}}"##
        ),
    },
    ChannelSpec {
        topic: "/policy/adaptation",
        schema_name: "hrc_adapt.Adaptation",
        schema: schema!(
            "Adaptation: scales (0..1], timing (s), gate, reason",
            r#"{"t_s":{"type":"number"},"speed_scale":{"type":"number"},"acceleration_scale":{"type":"number"},"jerk_scale":{"type":"number"},"timing":{"type":"object","properties":{"start_delay_s":{"type":"number"},"min_approach_duration_s":{"type":"number"},"wait_for_attention":{"type":"boolean"},"present_requires_collaboration_attention":{"type":"boolean"},"hold_while_in_instruction_area":{"type":"boolean"},"max_assembly_deferral_s":{"type":"number"},"present_timeout_s":{"type":["number","null"]}}},"gate":{"type":"object","properties":{"clear":{"type":"boolean"},"hold":{"type":["string","null"]}}},"reason":{"type":"object","properties":{"indicator":{"type":"string"},"strength":{"type":"number"}}}}"#
        ),
    },
    ChannelSpec {
        topic: "/robot/state",
        schema_name: "hrc_adapt.RobotState",
        schema: schema!(
            "Robot state (rad, rad/s, m, m/s; base frame)",
            r#"{"t_s":{"type":"number"},"timestamp_s":{"type":"number"},"actual_q":{"type":"array","items":{"type":"number"}},"actual_qd":{"type":"array","items":{"type":"number"}},"target_q":{"type":"array","items":{"type":"number"}},"target_qd":{"type":"array","items":{"type":"number"}},"actual_tcp_pose":{"type":"array","items":{"type":"number"}},"actual_tcp_speed":{"type":"array","items":{"type":"number"}},"tcp_speed_m_s":{"type":"number"},"speed_scaling":{"type":"number"},"target_speed_fraction":{"type":"number"},"robot_mode":{"type":"integer"},"safety_mode":{"type":"integer"},"runtime_state":{"type":"integer"},"robot_status_bits":{"type":"integer"},"safety_status_bits":{"type":"integer"}}"#
        ),
    },
    ChannelSpec {
        topic: "/robot/command",
        schema_name: "hrc_adapt.Command",
        schema: schema!(
            "Joint command and the supervisor's verdict",
            r#"{"t_s":{"type":"number"},"kind":{"type":"string","enum":["servo","speed","stop"]},"q":{"type":["array","null"],"items":{"type":"number"}},"qd":{"type":["array","null"],"items":{"type":"number"}},"lookahead_s":{"type":["number","null"]},"gain":{"type":["number","null"]},"acc":{"type":["number","null"]},"decel":{"type":["number","null"]},"verdict":{"type":"string","enum":["passed","reduced","stopped","halted"]},"scale":{"type":["number","null"]},"requirement":{"type":["string","null"]}}"#
        ),
    },
    ChannelSpec {
        topic: "/safety/events",
        schema_name: "hrc_adapt.SafetyEvent",
        schema: schema!(
            "Safety event: the supervisor did not pass a command unchanged",
            r#"{"t_s":{"type":"number"},"reaction":{"type":"string"},"requirement":{"type":"string"}}"#
        ),
    },
    ChannelSpec {
        topic: "/task/events",
        schema_name: "hrc_adapt.TaskEvent",
        schema: schema!(
            "Task event",
            r#"{"t_s":{"type":"number"},"event":{"type":"string"},"phase":{"type":["string","null"]},"handover":{"type":["integer","null"]},"idle":{"type":["boolean","null"]},"active":{"type":["boolean","null"]},"indicator":{"type":["string","null"]},"reason":{"type":["string","null"]}}"#
        ),
    },
    ChannelSpec {
        topic: "/safety/separation",
        schema_name: "hrc_adapt.Separation",
        schema: schema!(
            "Minimum human-robot distance (m); null when no human point is tracked",
            r#"{"t_s":{"type":"number"},"min_distance_m":{"type":["number","null"]}}"#
        ),
    },
    ChannelSpec {
        topic: "/robot/cycle",
        schema_name: "hrc_adapt.Cycle",
        schema: schema!(
            "Control cycle: missed cycles, latency and wake jitter (s; null on the mock clock), planner jerk limit (rad/s^3), time scale (0..1), executed jerk max over joints (rad/s^3)",
            r#"{"t_s":{"type":"number"},"missed":{"type":"integer"},"latency_s":{"type":["number","null"]},"wake_jitter_s":{"type":["number","null"]},"jerk_limit_rad_s3":{"type":["number","null"]},"time_scale":{"type":["number","null"]},"jerk_abs_max_rad_s3":{"type":["number","null"]}}"#
        ),
    },
];

/// Writes a JSON number (`null` when not finite).
fn num(out: &mut Vec<u8>, x: f64) {
    if x.is_finite() {
        // Writing into a Vec cannot fail.
        let _ = write!(out, "{x}");
    } else {
        out.extend_from_slice(b"null");
    }
}

fn arr(out: &mut Vec<u8>, xs: &[f64]) {
    out.push(b'[');
    for (i, &x) in xs.iter().enumerate() {
        if i > 0 {
            out.push(b',');
        }
        num(out, x);
    }
    out.push(b']');
}

fn key(out: &mut Vec<u8>, k: &str) {
    out.extend_from_slice(b",\"");
    out.extend_from_slice(k.as_bytes());
    out.extend_from_slice(b"\":");
}

/// Linear TCP speed |v| [m/s].
pub(crate) fn tcp_speed_m_s(s: &RobotState) -> f64 {
    let v = &s.actual_tcp_speed;
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// `/robot/state` message.
pub(crate) fn robot_state_json(out: &mut Vec<u8>, t_s: f64, s: &RobotState) {
    out.clear();
    out.extend_from_slice(b"{\"t_s\":");
    num(out, t_s);
    key(out, "timestamp_s");
    num(out, s.timestamp_s);
    for (k, v) in [
        ("actual_q", &s.actual_q),
        ("actual_qd", &s.actual_qd),
        ("target_q", &s.target_q),
        ("target_qd", &s.target_qd),
        ("actual_tcp_pose", &s.actual_tcp_pose),
        ("actual_tcp_speed", &s.actual_tcp_speed),
    ] {
        key(out, k);
        arr(out, v);
    }
    key(out, "tcp_speed_m_s");
    num(out, tcp_speed_m_s(s));
    key(out, "speed_scaling");
    num(out, s.speed_scaling);
    key(out, "target_speed_fraction");
    num(out, s.target_speed_fraction);
    for (k, v) in [
        ("robot_mode", i64::from(s.robot_mode)),
        ("safety_mode", i64::from(s.safety_mode)),
        ("runtime_state", i64::from(s.runtime_state)),
        ("robot_status_bits", i64::from(s.robot_status_bits)),
        ("safety_status_bits", i64::from(s.safety_status_bits)),
    ] {
        key(out, k);
        let _ = write!(out, "{v}");
    }
    out.push(b'}');
}

fn opt_num(out: &mut Vec<u8>, k: &str, x: Option<f64>) {
    key(out, k);
    match x {
        Some(x) => num(out, x),
        None => out.extend_from_slice(b"null"),
    }
}

fn opt_arr(out: &mut Vec<u8>, k: &str, xs: Option<&[f64]>) {
    key(out, k);
    match xs {
        Some(xs) => arr(out, xs),
        None => out.extend_from_slice(b"null"),
    }
}

/// `/robot/cycle` message: the cycle record and the cycle's executed jerk (max over the joints
/// of |j|, `null` before the third state).
pub(crate) fn cycle_json(
    out: &mut Vec<u8>,
    t_s: f64,
    r: &super::CycleRecord,
    jerk_abs_max_rad_s3: Option<f64>,
) {
    out.clear();
    out.extend_from_slice(b"{\"t_s\":");
    num(out, t_s);
    key(out, "missed");
    let _ = write!(out, "{}", r.missed);
    opt_num(out, "latency_s", r.latency_s);
    opt_num(out, "wake_jitter_s", r.wake_jitter_s);
    key(out, "jerk_limit_rad_s3");
    num(out, r.jerk_limit_rad_s3);
    key(out, "time_scale");
    num(out, r.time_scale);
    opt_num(out, "jerk_abs_max_rad_s3", jerk_abs_max_rad_s3);
    out.push(b'}');
}

/// The name of a verdict: `passed`, `reduced`, `stopped`, `halted`.
pub(crate) fn verdict_name(v: &Verdict) -> &'static str {
    match v {
        Verdict::Passed => "passed",
        Verdict::Reduced { .. } => "reduced",
        Verdict::Stopped { .. } => "stopped",
        Verdict::Halted { .. } => "halted",
    }
}

/// `/robot/command` message.
pub(crate) fn command_json(out: &mut Vec<u8>, t_s: f64, c: &JointCommand, v: &Verdict) {
    out.clear();
    out.extend_from_slice(b"{\"t_s\":");
    num(out, t_s);
    let (kind, q, qd, lookahead, gain, acc, decel) = match c {
        JointCommand::Servo {
            q,
            lookahead_s,
            gain,
        } => (
            "servo",
            Some(&q[..]),
            None,
            Some(*lookahead_s),
            Some(*gain),
            None,
            None,
        ),
        JointCommand::Speed { qd, acc } => {
            ("speed", None, Some(&qd[..]), None, None, Some(*acc), None)
        }
        JointCommand::Stop { decel } => ("stop", None, None, None, None, None, Some(*decel)),
    };
    key(out, "kind");
    let _ = write!(out, "\"{kind}\"");
    opt_arr(out, "q", q);
    opt_arr(out, "qd", qd);
    opt_num(out, "lookahead_s", lookahead);
    opt_num(out, "gain", gain);
    opt_num(out, "acc", acc);
    opt_num(out, "decel", decel);
    key(out, "verdict");
    let _ = write!(out, "\"{}\"", verdict_name(v));
    let scale = match v {
        Verdict::Reduced { scale, .. } => Some(*scale),
        _ => None,
    };
    opt_num(out, "scale", scale);
    key(out, "requirement");
    match v.requirement() {
        Some(r) => {
            let _ = write!(out, "\"{}\"", r.id());
        }
        None => out.extend_from_slice(b"null"),
    }
    out.push(b'}');
}

/// `/safety/separation` message.
pub(crate) fn separation_json(out: &mut Vec<u8>, t_s: f64, d: Option<f64>) {
    out.clear();
    out.extend_from_slice(b"{\"t_s\":");
    num(out, t_s);
    opt_num(out, "min_distance_m", d);
    out.push(b'}');
}

/// The event's name as `/task/events` writes it.
pub(crate) fn event_name(e: &TrialEvent) -> &'static str {
    match e {
        TrialEvent::TaskPhase { .. } => "task_phase",
        TrialEvent::Presented { .. } => "presented",
        TrialEvent::Grasped { .. } => "grasped",
        TrialEvent::PartReturned { .. } => "part_returned",
        TrialEvent::OperatorNeedsPart { .. } => "operator_needs_part",
        TrialEvent::OperatorIdle { .. } => "operator_idle",
        TrialEvent::Hesitation { .. } => "hesitation",
        TrialEvent::AdaptationChanged { .. } => "adaptation_changed",
        TrialEvent::Safety { .. } => "safety",
        TrialEvent::Link { up: false } => "link_lost",
        TrialEvent::Link { up: true } => "link_restored",
        TrialEvent::Finished { .. } => "finished",
    }
}

/// An event's message and channel index: `Safety` goes to `/safety/events`, the rest to
/// `/task/events`.
pub(crate) fn event_json(out: &mut Vec<u8>, t_s: f64, e: &TrialEvent) -> usize {
    out.clear();
    out.extend_from_slice(b"{\"t_s\":");
    num(out, t_s);
    if let TrialEvent::Safety {
        reaction,
        requirement,
    } = e
    {
        let _ = write!(
            out,
            ",\"reaction\":\"{reaction}\",\"requirement\":\"{requirement}\"}}"
        );
        return ch::SAFETY;
    }
    let _ = write!(out, ",\"event\":\"{}\"", event_name(e));
    let (mut phase, mut handover, mut idle, mut active, mut indicator, mut reason) =
        (None, None, None, None, None, None);
    match *e {
        TrialEvent::TaskPhase { phase: p } => phase = Some(p),
        TrialEvent::Presented { handover: h }
        | TrialEvent::Grasped { handover: h }
        | TrialEvent::PartReturned { handover: h }
        | TrialEvent::OperatorNeedsPart { handover: h } => handover = Some(h),
        TrialEvent::OperatorIdle { idle: i } => idle = Some(i),
        TrialEvent::Hesitation { active: a } => active = Some(a),
        TrialEvent::AdaptationChanged { indicator: i } => indicator = Some(i),
        TrialEvent::Finished { reason: r } => reason = Some(r),
        TrialEvent::Safety { .. } | TrialEvent::Link { .. } => {}
    }
    for (k, v) in [
        ("phase", phase),
        ("indicator", indicator),
        ("reason", reason),
    ] {
        key(out, k);
        match v {
            Some(s) => {
                let _ = write!(out, "\"{s}\"");
            }
            None => out.extend_from_slice(b"null"),
        }
    }
    key(out, "handover");
    match handover {
        Some(h) => {
            let _ = write!(out, "{h}");
        }
        None => out.extend_from_slice(b"null"),
    }
    for (k, v) in [("idle", idle), ("active", active)] {
        key(out, k);
        out.extend_from_slice(match v {
            Some(true) => b"true",
            Some(false) => b"false",
            None => b"null",
        });
    }
    out.push(b'}');
    ch::TASK
}

fn vec3(v: &assess::Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// `/operator/cues` message.
pub(crate) fn cues_value(t_s: f64, f: &assess::CueFrame) -> serde_json::Value {
    use serde_json::json;
    let hand = |h: &Option<assess::HandCue>| {
        h.as_ref()
            .map(|h| json!({"position": vec3(&h.position), "confidence": h.confidence}))
    };
    json!({
        "t_s": t_s,
        "head": f.head.as_ref().map(|h| json!({
            "position": vec3(&h.position), "facing": vec3(&h.facing), "confidence": h.confidence
        })),
        "body": f.body.as_ref().map(|b| json!({
            "position": vec3(&b.position), "facing": vec3(&b.facing), "confidence": b.confidence
        })),
        "left_hand": hand(&f.hands[0]),
        "right_hand": hand(&f.hands[1]),
        "collaborating": f.robot.collaborating,
        "incomplete": f.robot.incomplete,
    })
}

fn indicators_value(i: &assess::Indicators) -> serde_json::Value {
    serde_json::json!({
        "aed": i.aed, "tid": i.tid, "icd": i.icd, "col": i.col, "abi": i.abi,
        "asd_ctx": i.asd_ctx, "asd_norm": i.asd_norm, "ohd": i.ohd, "hrc_cwl": i.hrc_cwl,
        "category": i.category.name(),
    })
}

/// `/assessment` message.
pub(crate) fn assessment_value(
    t_s: f64,
    a: &assess::Assessment,
    ws: &assess::Workspace,
) -> serde_json::Value {
    serde_json::json!({
        "t_s": t_s,
        "dt_s": a.dt_s,
        "valid": a.valid,
        "confirmed": ws.state_name(a.confirmed),
        "perceptual": ws.state_name(a.perceptual.0),
        "action": ws.state_name(a.action.0),
        "collaborating": a.collaborating,
        "hesitating": a.hesitating,
        "hand_speed_m_s": a.hand_speed_m_s,
        "v_th_m_s": a.speed_threshold_m_s,
        "cumulative": indicators_value(&a.cumulative),
        "windowed": indicators_value(&a.windowed),
        "dominant": a.dominant.indicator.map_or("none", assess::Indicator::name),
        "dominant_strength": a.dominant.strength,
        "calibrating": a.dominant.calibrating,
    })
}

/// `/policy/adaptation` message: the adaptation's serde form with `t_s` first.
pub(crate) fn adaptation_value(
    t_s: f64,
    a: &policies::Adaptation,
) -> serde_json::Result<serde_json::Value> {
    let mut map = serde_json::Map::new();
    map.insert("t_s".into(), t_s.into());
    if let serde_json::Value::Object(rest) = serde_json::to_value(a)? {
        map.extend(rest);
    }
    Ok(serde_json::Value::Object(map))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_schema_is_json_and_every_hot_message_parses() {
        for c in CHANNELS {
            let v: serde_json::Value = serde_json::from_str(c.schema).unwrap();
            assert_eq!(v["type"], "object", "{}", c.topic);
        }
        let mut buf = Vec::new();
        let mut s = RobotState::default();
        s.actual_tcp_speed[0] = 0.3;
        s.actual_tcp_speed[1] = 0.4;
        robot_state_json(&mut buf, 1.5, &s);
        let v: serde_json::Value = serde_json::from_slice(&buf).unwrap();
        assert_eq!(v["tcp_speed_m_s"], 0.5);
        command_json(
            &mut buf,
            1.0,
            &JointCommand::Stop { decel: f64::NAN },
            &Verdict::Passed,
        );
        let v: serde_json::Value = serde_json::from_slice(&buf).unwrap();
        assert_eq!(v["kind"], "stop");
        assert!(v["decel"].is_null() && v["q"].is_null());
        let e = TrialEvent::Grasped { handover: 3 };
        assert_eq!(event_json(&mut buf, 2.0, &e), ch::TASK);
        let v: serde_json::Value = serde_json::from_slice(&buf).unwrap();
        assert_eq!(v["handover"], 3);
        let e = TrialEvent::Safety {
            reaction: "reduced",
            requirement: "SAF-REQ-005",
        };
        assert_eq!(event_json(&mut buf, 2.0, &e), ch::SAFETY);
        let v: serde_json::Value = serde_json::from_slice(&buf).unwrap();
        assert_eq!(v["requirement"], "SAF-REQ-005");
        let r = super::super::CycleRecord {
            missed: 2,
            latency_s: None,
            wake_jitter_s: Some(1.5e-5),
            jerk_limit_rad_s3: 31.4,
            time_scale: 0.5,
        };
        cycle_json(&mut buf, 3.0, &r, Some(12.0));
        let v: serde_json::Value = serde_json::from_slice(&buf).unwrap();
        assert_eq!(v["missed"], 2);
        assert!(v["latency_s"].is_null());
        assert_eq!(v["wake_jitter_s"], 1.5e-5);
        assert_eq!(v["time_scale"], 0.5);
        assert_eq!(v["jerk_abs_max_rad_s3"], 12.0);
    }
}
