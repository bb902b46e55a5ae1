//! Tests of the trial log: a round trip through `trial.mcap`, and a run killed with SIGKILL.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use assess::{AssessConfig, Assessor, CueFrame, HeadCue, Vec3, Workspace};
use robot_io::{JointCommand, RobotState};
use safety::{Verdict, Violation};

use super::*;

const WORKSPACE: &str = r#"
    [[area]]
    name = "assembly"
    role = "assembly"
    min_m = [0.3, -0.2, 0.7]
    max_m = [0.7, 0.2, 0.9]
    [[area]]
    name = "handover"
    role = "collaboration"
    min_m = [0.3, 0.5, 0.9]
    max_m = [0.6, 0.8, 1.2]
"#;

fn meta() -> TrialMeta {
    TrialMeta {
        participant: "T01".into(),
        condition: "L2".into(),
        policy: "adaptive".into(),
        seed: 42,
        simulated: true,
        cue_source: None,
        started_utc: "2026-01-01T00:00:00Z".into(),
        robot: "synthetic".into(),
    }
}

/// How many records of each kind the synthetic writer produced.
#[derive(Debug, Default)]
struct Written {
    ticks: u64,
    camera: u64,
    events: u64,
    safety: u64,
}

/// A synthetic 500 Hz trial of `ticks` control cycles, labelled simulated: a camera frame every
/// 15 cycles (33.3 Hz), a handover cycle every 2 s, a speed reduction now and then. Calls
/// `after_camera(t)` after each camera frame.
fn synthetic(
    log: &mut TrialLog,
    ticks: u64,
    mut after_camera: impl FnMut(f64),
) -> crate::Result<Written> {
    let ws = Workspace::from_toml_str(WORKSPACE)?;
    let mut assessor = Assessor::new(ws.clone(), AssessConfig::default())?;
    let mut w = Written::default();
    let mut state = RobotState::default();
    let phases = ["Fetch", "Approach", "Present", "Release", "Retreat"];
    let mut adaptation = policies::Adaptation::NOMINAL;
    for k in 0..ticks {
        let t = k as f64 * 0.002;
        // Handover cycle: 2 s, phases at 0, 0.4, 0.8, 1.2, 1.6 s.
        if k % 200 == 0 {
            let phase = phases[((k / 200) % 5) as usize];
            log.event(t, &TrialEvent::TaskPhase { phase })?;
            w.events += 1;
            let h = (k / 1000) as u32;
            let extra = match phase {
                "Approach" => Some(TrialEvent::OperatorNeedsPart { handover: h }),
                "Present" => Some(TrialEvent::Presented { handover: h }),
                "Release" => Some(TrialEvent::Grasped { handover: h }),
                _ => None,
            };
            if let Some(e) = extra {
                log.event(t, &e)?;
                w.events += 1;
            }
        }
        // The simulated operator idles 0.2–0.5 s and hesitates 0.9–1.1 s of each cycle.
        for (at, e) in [
            (100, TrialEvent::OperatorIdle { idle: true }),
            (250, TrialEvent::OperatorIdle { idle: false }),
            (450, TrialEvent::Hesitation { active: true }),
            (550, TrialEvent::Hesitation { active: false }),
        ] {
            if k % 1000 == at {
                log.event(t, &e)?;
                w.events += 1;
            }
        }
        let s = (t * 1.3).sin();
        state.timestamp_s = t + 100.0;
        state.actual_q = [s, -1.2, 1.0, -1.4, -1.57, 0.0];
        state.actual_tcp_speed = [0.25 * s.abs(), 0.1, 0.0, 0.0, 0.0, 0.0];
        log.robot_state(t, &state)?;
        let cmd = JointCommand::Servo {
            q: state.actual_q,
            lookahead_s: 0.1,
            gain: 300.0,
        };
        let verdict = if k % 700 == 350 {
            log.event(
                t,
                &TrialEvent::Safety {
                    reaction: "reduced",
                    requirement: "SAF-REQ-005",
                },
            )?;
            w.events += 1;
            w.safety += 1;
            Verdict::Reduced {
                scale: 0.8,
                violation: Violation::TcpSpeed {
                    value_m_s: 0.31,
                    limit_m_s: 0.25,
                },
            }
        } else {
            Verdict::Passed
        };
        log.command(t, &cmd, &verdict)?;
        log.cycle(
            t,
            &CycleRecord {
                missed: u32::from(k % 1000 == 999),
                latency_s: None,
                wake_jitter_s: None,
                jerk_limit_rad_s3: 31.4,
                time_scale: 1.0,
            },
        )?;
        let d = (k % 1000 > 100).then_some(0.6 + 0.3 * s);
        log.human_distance(t, d)?;
        if k % 15 == 0 {
            let mut frame = CueFrame::empty(t);
            let facing = if (t as u64) % 4 < 2 {
                Vec3::new(0.5, 0.0, -0.4)
            } else {
                Vec3::new(0.45, 0.65, -0.1)
            };
            frame.head = Some(HeadCue {
                position: Vec3::new(0.0, 0.0, 1.2),
                facing,
                confidence: 0.9,
            });
            frame.robot.collaborating = (k % 1000) >= 200 && (k % 1000) < 600;
            frame.robot.incomplete = frame.robot.collaborating;
            log.cues(t, &frame)?;
            let a = assessor.update(&frame);
            log.assessment(t, a, &ws)?;
            if k % 1500 == 0 && k > 0 {
                adaptation.speed_scale = policies::Scale::new(0.6)?;
                adaptation.timing.start_delay_s = 1.5;
                adaptation.reason.indicator = Some(assess::Indicator::Icd);
                log.event(t, &TrialEvent::AdaptationChanged { indicator: "ICD" })?;
                w.events += 1;
            }
            log.adaptation(t, &adaptation)?;
            w.camera += 1;
            after_camera(t);
        }
        w.ticks += 1;
    }
    Ok(w)
}

fn count_topics(msgs: &[ReadMessage]) -> BTreeMap<String, u64> {
    let mut m = BTreeMap::new();
    for msg in msgs {
        *m.entry(msg.topic.clone()).or_default() += 1;
    }
    m
}

#[test]
fn round_trip_through_mcap_with_every_channel_and_decimated_robot_state() {
    let dir = tempfile::tempdir().unwrap();
    // HRC_ADAPT_KEEP_LOG=<dir> keeps the files, to look at the report.
    let run = std::env::var_os("HRC_ADAPT_KEEP_LOG")
        .map_or_else(|| dir.path().join("run"), std::path::PathBuf::from);
    let mut log = TrialLog::create(&run, &meta(), LogOptions::default()).unwrap();
    // 6 s at 500 Hz.
    let w = synthetic(&mut log, 3000, |_| {}).unwrap();
    log.event(6.0, &TrialEvent::Finished { reason: "done" })
        .unwrap();
    let files = log.finish().unwrap();

    let bytes = std::fs::read(&files.mcap).unwrap();
    let (msgs, damaged) = read_mcap_messages(&bytes).unwrap();
    assert!(!damaged);
    // The finished file also opens with the strict reader and has a summary section.
    assert_eq!(
        mcap::MessageStream::new(&bytes).unwrap().count(),
        msgs.len()
    );
    assert!(mcap::Summary::read(&bytes).unwrap().is_some());

    let counts = count_topics(&msgs);
    let task_events = w.events + 1 - w.safety; // + Finished
    let want: BTreeMap<String, u64> = [
        ("/trial/meta", 1),
        ("/operator/cues", w.camera),
        ("/assessment", w.camera),
        ("/policy/adaptation", w.camera),
        // 500 Hz → 100 Hz: every 5th of 3000 cycles.
        ("/robot/state", 600),
        ("/robot/command", w.ticks),
        ("/safety/events", w.safety),
        ("/task/events", task_events),
        ("/safety/separation", 600),
        ("/robot/cycle", w.ticks),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    assert_eq!(counts, want);
    assert_eq!(
        files.message_counts, want,
        "the writer's own statistics agree"
    );
    assert_eq!(w.camera, 200);
    assert_eq!(files.synchronous_drains, 0);

    // Every channel carries its JSON schema; every message is JSON.
    for c in mcap_out::CHANNELS {
        let m = msgs.iter().find(|m| m.topic == c.topic).unwrap();
        let (name, encoding, text) = m.schema.clone().unwrap();
        assert_eq!(
            (name.as_str(), encoding.as_str()),
            (c.schema_name, "jsonschema")
        );
        assert_eq!(text, c.schema);
        assert_eq!(m.message_encoding, "json");
    }
    for m in &msgs {
        let v: serde_json::Value =
            serde_json::from_slice(&m.data).unwrap_or_else(|e| panic!("{}: {e}", m.topic));
        if m.topic != "/trial/meta" {
            let t = v["t_s"].as_f64().unwrap();
            assert_eq!(m.log_time_ns, (t * 1e9).round() as u64);
        }
    }
    let meta_msg = msgs.iter().find(|m| m.topic == "/trial/meta").unwrap();
    let v: serde_json::Value = serde_json::from_slice(&meta_msg.data).unwrap();
    assert_eq!(v["simulated"], true);
    // Robot state at 10 ms spacing.
    let ts: Vec<f64> = msgs
        .iter()
        .filter(|m| m.topic == "/robot/state")
        .map(|m| {
            serde_json::from_slice::<serde_json::Value>(&m.data).unwrap()["t_s"]
                .as_f64()
                .unwrap()
        })
        .collect();
    for (k, t) in ts.iter().enumerate() {
        assert!((t - k as f64 * 0.01).abs() < 1e-9, "{k}: {t}");
    }

    // robot.csv: the same 600 rows, ur_rtde-style, readable by robot-io.
    let trace = robot_io::trace::Trace::read(&files.robot_csv).unwrap();
    assert_eq!(trace.len(), 600);
    assert_eq!(trace.field_names().len(), STATE_FIELD_NAMES.len());
    // indicators.csv: the assess header and one row per assessment.
    let text = std::fs::read_to_string(&files.indicators_csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        crate::trial::report::assess_report::table::header().join(",")
    );
    assert_eq!(lines.count() as u64, w.camera);
    // summary.json: simulated, five handovers of 2 s cycles.
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&files.summary_json).unwrap()).unwrap();
    assert_eq!(s["meta"]["simulated"], true);
    assert_eq!(s["completion_time_s"], 6.0);
    assert_eq!(s["safety_events"]["total"], w.safety);
    assert_eq!(s["handovers"][0]["robot_wait_s"], 0.4);
    assert_eq!(s["handovers"][0]["operator_wait_s"], 0.8);
    // The report is labelled and embeds its plots.
    let html = std::fs::read_to_string(files.report_html.unwrap()).unwrap();
    assert!(html.contains("SIMULATED TRIAL"));
    assert!(html.matches("data:image/png;base64,").count() >= 5);
    for p in &files.plots {
        assert_eq!(&std::fs::read(p).unwrap()[..4], b"\x89PNG");
    }
}

#[test]
fn full_rate_option_keeps_every_robot_state() {
    let dir = tempfile::tempdir().unwrap();
    let options = LogOptions {
        robot_full_rate: true,
        write_report: false,
        ..LogOptions::default()
    };
    let mut log = TrialLog::create(dir.path(), &meta(), options).unwrap();
    synthetic(&mut log, 500, |_| {}).unwrap();
    let files = log.finish().unwrap();
    assert_eq!(files.message_counts["/robot/state"], 500);
    assert!(files.report_html.is_none());
}

/// Where the SIGKILL child writes (set by the parent test; the child test does nothing without).
const CHILD_ENV: &str = "HRC_ADAPT_LOG_SIGKILL_DIR";
/// The child's progress file: the trial time up to which everything was handed to the log.
const PROGRESS_FILE: &str = "progress";

/// The child half of [`sigkill_leaves_a_log_readable_up_to_its_last_chunk`]: writes a trial at
/// about 10× real time until it is killed (or 200 s of trial time pass).
#[test]
#[ignore = "run by sigkill_leaves_a_log_readable_up_to_its_last_chunk"]
fn sigkill_child() {
    let Some(dir) = std::env::var_os(CHILD_ENV) else {
        return;
    };
    let dir = Path::new(&dir);
    let options = LogOptions {
        write_report: false,
        ..LogOptions::default()
    };
    let mut log = TrialLog::create(&dir.join("run"), &meta(), options).unwrap();
    let progress = dir.join(PROGRESS_FILE);
    let mut next = 0.0;
    synthetic(&mut log, 100_000, |t| {
        if t >= next {
            // Written after every record up to t went to the log (and was drained).
            std::fs::write(&progress, format!("{t}")).unwrap();
            next += 0.25;
            std::thread::sleep(Duration::from_millis(25));
        }
    })
    .unwrap();
    std::mem::forget(log); // never finished: the file is as a crash leaves it
}

#[test]
fn sigkill_leaves_a_log_readable_up_to_its_last_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let exe = std::env::current_exe().unwrap();
    let mut child = Command::new(exe)
        .args([
            "--exact",
            "trial::log::tests::sigkill_child",
            "--ignored",
            "--nocapture",
        ])
        .env(CHILD_ENV, dir.path())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let progress = dir.path().join(PROGRESS_FILE);
    let read_progress = || {
        std::fs::read_to_string(&progress)
            .ok()
            .and_then(|s| s.trim().parse::<f64>().ok())
    };
    // Wait for at least 3.5 s of trial time (three closed chunks), at most 60 s.
    let deadline = Instant::now() + Duration::from_secs(60);
    while read_progress().is_none_or(|t| t < 3.5) {
        assert!(Instant::now() < deadline, "the child made no progress");
        assert!(
            child.try_wait().unwrap().is_none(),
            "the child exited early"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL on Unix
    child.wait().unwrap();
    let reached = read_progress().unwrap();

    let bytes = std::fs::read(dir.path().join("run").join(MCAP_FILE)).unwrap();
    // No footer: the strict reader fails at the end, the lenient one reads to the last chunk.
    assert!(mcap::Summary::read(&bytes).is_err() || mcap::Summary::read(&bytes).unwrap().is_none());
    let (msgs, damaged) = read_mcap_messages(&bytes).unwrap();
    eprintln!(
        "killed at {reached} s: {} bytes, {} messages readable, damaged tail: {damaged}",
        bytes.len(),
        msgs.len()
    );
    let counts = count_topics(&msgs);
    for c in mcap_out::CHANNELS {
        assert!(
            counts.contains_key(c.topic),
            "{} missing: {counts:?}",
            c.topic
        );
    }
    // Robot states form an unbroken 100 Hz prefix from t = 0 ...
    let ts: Vec<f64> = msgs
        .iter()
        .filter(|m| m.topic == "/robot/state")
        .map(|m| {
            serde_json::from_slice::<serde_json::Value>(&m.data).unwrap()["t_s"]
                .as_f64()
                .unwrap()
        })
        .collect();
    for (k, t) in ts.iter().enumerate() {
        assert!((t - k as f64 * 0.01).abs() < 1e-9, "{k}: {t}");
    }
    // ... reaching the last chunk closed before the kill: chunks close every 1 s of trial
    // time, so at most 1 s (plus one camera period) before the progress the child reported.
    let last = *ts.last().unwrap();
    assert!(
        last >= reached - 1.0 - 0.05,
        "read up to {last} s, the child had reached {reached} s"
    );
}
