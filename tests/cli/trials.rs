//! Whole trials through the `hrc-adapt trial` command, as a user runs them: the closed loop
//! of every crate (simulated operator → assess → policies → adapt → safety → robot-io) on the
//! mock clock (`--robot sim`), over loopback RTDE to the in-process emulator
//! (`--robot emulator`), and driven by a recorded cue file (`--cues`). Each checks the run
//! folder the binary prints and what its files say.
//!
//! The emulator trial runs alone (the others wait for it), so the sim trials' CPU load does not
//! make its RTDE pacing depend on how the test harness scheduled them.

mod common;
use common::{run_folder, summary, trial, trial_config};

use std::path::Path;
use std::sync::RwLock;

/// Taken for writing by the emulator trial, for reading by the others.
static PACED: RwLock<()> = RwLock::new(());

fn shared() -> std::sync::RwLockReadGuard<'static, ()> {
    PACED.read().unwrap_or_else(|e| e.into_inner())
}

/// Runs a trial with `args` and the shipped config cut to `max_s` [s]; the run folder.
fn run(dir: &Path, max_s: f64, args: &[&str]) -> std::path::PathBuf {
    let cfg = trial_config(dir, &[("max_duration_s", &format!("{max_s:.1}"))]);
    let root = dir.join("runs");
    let mut all = vec![
        "--participant",
        "P01",
        "--config",
        cfg.to_str().unwrap(),
        "--out-root",
        root.to_str().unwrap(),
    ];
    all.extend_from_slice(args);
    let (status, stdout, stderr) = trial(&all);
    assert!(
        status.success(),
        "trial {args:?} failed: {status}\n{stderr}"
    );
    run_folder(&stdout, &stderr)
}

#[test]
fn emulator_trial_runs_over_loopback_rtde_and_writes_every_file() {
    let _alone = PACED.write().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let out = run(
        dir.path(),
        6.0,
        &["--robot", "emulator", "--speedup", "10", "--seed", "7"],
    );
    let json = summary(&out);
    assert_eq!(json["meta"]["robot"], "emulator", "{json}");
    // The emulator's own count of the servo commands: every command in one lateness bin,
    // at most one per control cycle (the loop sends one per cycle it runs; the program sees
    // fewer when two land within one of its cycles, or when the supervisor stopped the
    // robot: how many is load-dependent, so not judged here — CI once saw 603 of 1233
    // cycles in a loaded debug build).
    let servo = &json["motion"]["robot_servo"];
    let commands = servo["commands"]
        .as_u64()
        .expect("motion.robot_servo.commands");
    let late: u64 = servo["late_by_cycles"]
        .as_array()
        .expect("late_by_cycles")
        .iter()
        .map(|n| n.as_u64().unwrap())
        .sum();
    assert_eq!(late, commands, "{servo}");
    let cycles = json["motion"]["control_cycles"].as_u64().unwrap();
    assert!(
        commands > 0 && commands <= cycles,
        "{commands} of {cycles}: {}",
        json["motion"]["cycles"]
    );
    // The emulator's own clock: every cycle due is run, dropped, or still behind.
    let clock = &json["motion"]["emulator_clock"];
    let n = |k: &str| clock[k].as_u64().unwrap_or_else(|| panic!("{k}: {clock}"));
    assert!(n("cycles_run") > 0, "{clock}");
    assert!(
        n("cycles_run") + n("cycles_dropped") + n("cycles_waited") <= n("cycles_elapsed"),
        "{clock}"
    );
    assert!(n("holds_in_bursts") <= n("bursts"), "{clock}");
    // Sped up (speedup 10), the clock waits for late servo commands by default
    // ([emulator] wait_for_client_ms = 20): counted, each wait at most once timed out. How
    // often it waits is load-dependent, so not judged here.
    assert!(n("waits_timed_out") <= n("waits"), "{clock}");
    assert!(n("waits") <= n("cycles_waited"), "{clock}");
    // The shipped [realtime] asks for no priority (ur_rtde's default): every thread a cycle
    // waits on is reported at normal scheduling, never claimed real-time and never left out.
    let sched = &json["motion"]["scheduling"];
    for key in ["control", "rtde_io", "emulator_clock"] {
        let got = sched[key]
            .as_str()
            .unwrap_or_else(|| panic!("{key}: {sched}"));
        assert_eq!(got, "normal", "{key}: {sched}");
    }
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(report.contains("robot side (emulator): servo commands"));
    assert!(report.contains("emulator clock (its host, not the client)"));
    assert!(report.contains("thread scheduling ([realtime])"));
    // Paced on the controller clock: about 6 s of trial time were assessed at 30 Hz.
    let rows = std::fs::read_to_string(out.join("indicators.csv"))
        .unwrap()
        .lines()
        .count();
    assert!((150..=200).contains(&rows), "{rows} indicator rows");
}

#[test]
fn recorded_cue_file_drives_a_sim_trial_until_the_file_ends() {
    let _shared = shared();
    // 6 s at 30 Hz of an operator seated at the origin who looks at and works in the
    // assembly area (centre (0.55, 0, 0.8) m); the collaborating/incomplete columns say 1
    // and must be ignored (the robot context comes from the live task).
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("assembly-gaze.csv");
    let mut text = String::from(
        "# recorded operator looking at the assembly fixture\n\
         t,head_x,head_y,head_z,head_fx,head_fy,head_fz,head_conf,\
         body_x,body_y,body_z,body_fx,body_fy,body_fz,body_conf,\
         rhand_x,rhand_y,rhand_z,rhand_conf,collaborating,incomplete\n",
    );
    for n in 0..=180 {
        let t = 100.0 + f64::from(n) / 30.0; // file times need not start at 0
        let wiggle = 0.01 * (f64::from(n) * 0.7).sin();
        text.push_str(&format!(
            "{t:.6},0,0,1.2,0.55,{wiggle:.4},-0.4,0.9,0,0,1.0,1,0,0,0.9,0.5,{:.4},0.8,0.9,1,1\n",
            0.05 + wiggle
        ));
    }
    std::fs::write(&csv, text).unwrap();
    let out = run(
        dir.path(),
        60.0,
        &[
            "--robot",
            "sim",
            "--condition",
            "L1",
            "--seed",
            "5",
            "--cues",
            csv.to_str().unwrap(),
        ],
    );
    let summary = summary(&out);
    assert_eq!(summary["meta"]["cue_source"], "recorded:assembly-gaze.csv");
    assert_eq!(summary["meta"]["simulated"], false);
    assert_eq!(summary["meta"]["robot"], "sim");
    assert_eq!(summary["finish_reason"], "cues_ended", "{summary}");
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(report.contains("RECORDED CUES"), "report not labelled");
    assert!(report.contains("does not react to the robot"));
    // The assessment saw the recorded gaze: after the confirmation delay, the confirmed
    // area is the assembly area on (nearly) every frame.
    let ind = std::fs::read_to_string(out.join("indicators.csv")).unwrap();
    let mut lines = ind.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "F").unwrap(); // the confirmed area
    let confirmed: Vec<String> = lines
        .map(|l| l.split(',').nth(col).unwrap().to_owned())
        .collect();
    assert!(
        (170..=185).contains(&confirmed.len()),
        "{} assessments for a 6 s file",
        confirmed.len()
    );
    let late = &confirmed[confirmed.len() / 2..];
    assert!(
        late.iter().all(|c| c == "assembly"),
        "confirmed areas: {late:?}"
    );
}

#[test]
fn same_seed_and_config_give_byte_identical_indicators_and_summary() {
    let _shared = shared();
    let dir = tempfile::tempdir().unwrap();
    let (a, b, c) = (
        dir.path().join("a"),
        dir.path().join("b"),
        dir.path().join("c"),
    );
    for d in [&a, &b, &c] {
        std::fs::create_dir(d).unwrap();
    }
    let sim = |d: &Path, seed: &str| run(d, 45.0, &["--robot", "sim", "--seed", seed]);
    let (da, db) = (sim(&a, "42"), sim(&b, "42"));
    for f in ["indicators.csv", "summary.json"] {
        let x = std::fs::read(da.join(f)).unwrap();
        let y = std::fs::read(db.join(f)).unwrap();
        assert!(x.len() > 100, "{f} is too short");
        assert!(x == y, "{f} differs between two runs of the same seed");
    }
    // No RTDE link on the mock clock: no robot-side servo statistics (emulator only).
    let text = std::fs::read_to_string(da.join("summary.json")).unwrap();
    assert!(!text.contains("robot_servo"), "{text}");
    assert!(!text.contains("emulator_clock"), "{text}");
    assert!(
        !text.contains("scheduling"),
        "no thread on the mock clock: {text}"
    );
    let report = std::fs::read_to_string(da.join("report.html")).unwrap();
    assert!(!report.contains("robot side (emulator)"));
    let dc = sim(&c, "43");
    assert_ne!(
        std::fs::read(da.join("indicators.csv")).unwrap(),
        std::fs::read(dc.join("indicators.csv")).unwrap()
    );
}

/// Issue 10's motion acceptance on whole simulated trials, judged on the raw per-cycle
/// signals (summary.json's `motion`, never the debounced events): the planner keeps the
/// robot inside the supervisor's limits, so
/// - no command is reduced or stopped for joint speed, joint acceleration or TCP speed
///   (SAF-REQ-003/004/005) — the demo had 234 SAF-REQ-004 stops at a077dd5;
/// - every stop window is a separation stop (SAF-REQ-007, the simulated hand inside S_p);
/// - outside those windows there is no velocity reversal, no stop-and-go event and no
///   executed jerk above 1.1 × the planner's jerk limit.
///
/// Six trials: every condition with both policies, different seeds (one of them a trial of
/// `config/experiment-ab.toml`, P04's L3/fixed); all 48 of that schedule were checked the
/// same way in a release build (issue 10's note).
#[test]
fn saf_req_003_004_005_never_act_and_the_motion_is_smooth_in_simulated_trials() {
    let _shared = shared();
    for (condition, seed, policy) in [
        ("L1", "3", "fixed"),
        ("L1", "4", "adaptive"),
        ("L2", "1", "adaptive"),
        ("L2", "2", "fixed"),
        ("L3", "5338130435519176286", "fixed"),
        ("L3", "6", "adaptive"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let out = run(
            dir.path(),
            400.0,
            &[
                "--robot",
                "sim",
                "--condition",
                condition,
                "--seed",
                seed,
                "--policy",
                policy,
            ],
        );
        let summary = summary(&out);
        let label = format!("{condition} seed {seed} {policy}");
        assert_eq!(summary["finish_reason"], "completed", "{label}");
        let m = &summary["motion"];
        for id in ["SAF-REQ-003", "SAF-REQ-004", "SAF-REQ-005"] {
            let r = &m["interventions"]["by_requirement"][id];
            for reaction in ["reduced", "stopped", "halted"] {
                assert_eq!(r[reaction], 0, "{label}: {id} {reaction}: {r}");
            }
        }
        assert_eq!(
            m["stop_windows"]["other"], 0,
            "{label}: {}",
            m["stop_windows"]
        );
        assert_eq!(
            m["velocity_reversals"]["outside_stops"]["total"], 0,
            "{label}: {}",
            m["velocity_reversals"]
        );
        assert_eq!(
            m["stop_and_go"]["outside_stops"], 0,
            "{label}: {}",
            m["stop_and_go"]
        );
        assert_eq!(
            m["jerk_limit"]["outside_stops"]["exceeding"], 0,
            "{label}: {}",
            m["jerk_limit"]
        );
        // The judged signals are really there (a run of 500 Hz samples, a real hand).
        assert!(m["jerk"]["outside_stops"]["samples"].as_u64().unwrap() > 10_000);
        assert!(
            m["stop_windows"]["separation"].as_u64().unwrap() > 0,
            "{label}"
        );
    }
}

/// Issue 14, handover timing: in the demo trial (P01, L2, seed 1) the adaptive policy holds each
/// part at the staging pose until the operator's attention is confirmed on the collaboration
/// area, so no part is presented to an operator still assembling and none goes back: on the
/// mock clock and over loopback RTDE to the emulator at speedups 4 (the demo's) and 1 (real
/// time). The fixed policy, which presents on the schedule alone, returns parts in the same
/// trial on the mock clock (so the check can fail). Judged per handover (`summary.json`'s
/// `handovers[].returned`: a `part_returned` task event for that handover), not from a rate.
#[test]
fn the_demo_trial_with_the_adaptive_policy_returns_no_part() {
    let returned = |out: &Path| -> Vec<bool> {
        let s = summary(out);
        assert_eq!(s["finish_reason"], "completed", "{s}");
        let h = s["handovers"].as_array().expect("handovers");
        assert_eq!(h.len(), 3, "L2 has three handovers: {s}");
        h.iter()
            .map(|h| h["returned"].as_bool().expect("returned"))
            .collect()
    };
    let demo = ["--condition", "L2", "--seed", "1"];
    {
        let _shared = shared();
        let dir = tempfile::tempdir().unwrap();
        let sim = [&demo[..], &["--robot", "sim", "--policy"]].concat();
        let adaptive = run(dir.path(), 400.0, &[&sim[..], &["adaptive"]].concat());
        assert_eq!(returned(&adaptive), [false; 3], "adaptive, sim");
        let fixed = run(dir.path(), 400.0, &[&sim[..], &["fixed"]].concat());
        assert!(
            returned(&fixed).contains(&true),
            "the fixed policy returned no part either: the check cannot tell them apart"
        );
    }
    let _alone = PACED.write().unwrap_or_else(|e| e.into_inner());
    for speedup in ["4", "1"] {
        let dir = tempfile::tempdir().unwrap();
        let args = [
            &demo[..],
            &[
                "--robot",
                "emulator",
                "--speedup",
                speedup,
                "--policy",
                "adaptive",
            ],
        ]
        .concat();
        let out = run(dir.path(), 400.0, &args);
        assert_eq!(
            returned(&out),
            [false; 3],
            "adaptive, emulator at speedup {speedup}"
        );
    }
}
