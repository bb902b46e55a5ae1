//! Hardware-in-the-loop trials through the ur_rtde backend (`--robot-backend ur_rtde`,
//! feature `ur-rtde`; issue 11): SDU ur_rtde 1.6.5 drives the emulator, which runs ur_rtde's
//! own control script. Everything here is simulated (a simulated UR5e and operator).
//!
//! - a trial on the in-process emulator completes, and agrees with the same trial on the
//!   native backend in what the supervisor and the task did;
//! - `hrc-adapt emulate --sim` as a separate process, killed (SIGKILL) mid-trial: the trial
//!   ends as `link_lost` with exit code 3, through the supervisor;
//! - a protective stop injected in that emulator (SIGUSR1) ends the trial as
//!   `robot_program_stopped` (exit code 5), the robot stopped.
//!
//! ur_rtde's ports are fixed, so the tests run one at a time (`SERIAL`): the in-process
//! emulator takes 127.0.0.1's UR ports, the separate one 127.0.0.8's.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

mod common;
use common::{BIN, Emulate, run_folder, summary, trial, trial_config};

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// Every wait here is bounded by this.
const DEADLINE: Duration = Duration::from_secs(180);

/// A trial with `args` and the shipped config cut to `max_s` [s]; the run folder.
fn run(dir: &Path, max_s: f64, args: &[&str]) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let cfg = trial_config(dir, &[("max_duration_s", &format!("{max_s:.1}"))]);
    let root = dir.join("runs");
    let mut all = vec![
        "--participant",
        "P01",
        "--condition",
        "L1",
        "--seed",
        "1",
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

/// The requirements the supervisor intervened for, sorted.
fn requirements(json: &serde_json::Value) -> Vec<String> {
    let mut v: Vec<String> = json["safety_events"]["by_requirement"]
        .as_object()
        .map(|m| m.keys().cloned().collect())
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn ur_rtde_trial_completes_and_agrees_with_the_native_backend() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    let args = ["--robot", "emulator", "--speedup", "1"];
    let native = summary(&run(&dir.path().join("native"), 40.0, &args));
    let mut ur = args.to_vec();
    ur.extend_from_slice(&["--robot-backend", "ur_rtde"]);
    let ur = summary(&run(&dir.path().join("ur_rtde"), 40.0, &ur));
    assert_eq!(ur["meta"]["robot"], "emulator (ur_rtde)", "{ur}");
    assert_eq!(native["meta"]["robot"], "emulator", "{native}");
    // The same task outcome and the same supervisor story.
    assert_eq!(ur["finish_reason"], native["finish_reason"]);
    let handovers = |j: &serde_json::Value| {
        j["handovers"]
            .as_array()
            .map(|h| h.iter().map(|x| x["returned"].clone()).collect::<Vec<_>>())
    };
    assert_eq!(handovers(&ur), handovers(&native), "{ur}\n{native}");
    assert_eq!(requirements(&ur), requirements(&native));
    assert_eq!(
        ur["motion"]["stop_windows"]["count"],
        native["motion"]["stop_windows"]["count"]
    );
    // Smooth on both: no velocity reversal outside the stops, and no state repeated so often
    // that the supervisor's staleness check (SAF-REQ-009) fired.
    for j in [&ur, &native] {
        assert_eq!(
            j["motion"]["velocity_reversals"]["outside_stops"]["total"], 0,
            "{j}"
        );
        assert!(!requirements(j).contains(&"SAF-REQ-009".to_owned()), "{j}");
    }
}

#[test]
fn ur_rtde_backend_refuses_sim_and_a_speedup() {
    let _one = serial();
    let (status, _, stderr) = trial(&["--robot", "sim", "--robot-backend", "ur_rtde"]);
    assert!(!status.success(), "{stderr}");
    assert!(stderr.contains("--robot sim"), "{stderr}");
    let (status, _, stderr) = trial(&[
        "--robot",
        "emulator",
        "--speedup",
        "4",
        "--robot-backend",
        "ur_rtde",
    ]);
    assert!(!status.success(), "{stderr}");
    assert!(stderr.contains("real time"), "{stderr}");
}

/// `hrc-adapt emulate --sim` on 127.0.0.8 with UR's ports, in real time.
fn emulate_sim() -> Emulate {
    Emulate::start(&["--sim", "--speedup", "1", "--bind", "127.0.0.8"])
}

/// `hrc-adapt trial --robot 127.0.0.8 --robot-backend ur_rtde`, confirmed; a 20 s L1 trial
/// whose first fetch starts at once, with `[link] resume = resume`.
fn start_trial(dir: &Path, resume: bool) -> (Child, PathBuf) {
    let cfg = trial_config(
        dir,
        &[
            ("max_duration_s", "20.0"),
            ("lead_time_s", "60.0"),
            ("resume", if resume { "true" } else { "false" }),
            ("resume_within_s", "30.0"),
        ],
    );
    let out_root = dir.join("runs");
    let mut child = Command::new(BIN)
        .args([
            "trial",
            "--robot",
            "127.0.0.8",
            "--robot-backend",
            "ur_rtde",
        ])
        .args(["--condition", "L1", "--participant", "P01", "--seed", "1"])
        .arg("--config")
        .arg(&cfg)
        .arg("--out-root")
        .arg(&out_root)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start hrc-adapt trial");
    child.stdin.take().unwrap().write_all(b"yes\n").unwrap();
    (child, out_root)
}

/// Waits until the trial has logged more than a second of robot state.
fn wait_until_running(child: &mut Child, out_root: &Path) {
    let start = Instant::now();
    loop {
        let rows = std::fs::read_dir(out_root)
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.path().join("robot.csv"))
            .find_map(|p| std::fs::read_to_string(p).ok())
            .map_or(0, |t| t.lines().count());
        if rows > 100 {
            return;
        }
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the trial ended before it ran: {status}");
        }
        assert!(start.elapsed() < DEADLINE, "the trial never got going");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn sigkill_of_the_emulator_ends_the_ur_rtde_trial_as_link_lost() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    let emu = emulate_sim();
    let (mut child, out_root) = start_trial(dir.path(), false);
    wait_until_running(&mut child, &out_root);
    drop(emu); // SIGKILL
    let (status, stdout, stderr) = common::wait(child);
    assert_eq!(status.code(), Some(3), "{stderr}");
    let json = summary(&run_folder(&stdout, &stderr));
    assert_eq!(json["finish_reason"], "link_lost", "{json}");
}

#[test]
fn a_protective_stop_stops_the_ur_rtde_trial_through_the_supervisor() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    let emu = emulate_sim();
    let (mut child, out_root) = start_trial(dir.path(), false);
    wait_until_running(&mut child, &out_root);
    // A protective stop in the emulator (SIGUSR1: its fault injection, as a collision).
    emu.signal("-USR1");
    let (status, stdout, stderr) = common::wait(child);
    let json = summary(&run_folder(&stdout, &stderr));
    // A protective stop ends any program on a controller, ur_rtde's script too: the trial
    // ends as robot_program_stopped (exit code 5) through the exit path, which stops the
    // robot through the supervisor. The sample that shows the stopped program (it arrives
    // with the protective stop) is judged by the supervisor first: SAF-REQ-010 halts, in
    // the raw per-cycle counts.
    assert_eq!(status.code(), Some(5), "{stderr}");
    assert_eq!(json["finish_reason"], "robot_program_stopped", "{json}");
    assert!(stderr.contains("runtime state"), "{stderr}");
    assert!(
        json["completion_time_s"].as_f64().unwrap() < 19.0,
        "the trial ran on to its end: {json}"
    );
    let saf010 = &json["motion"]["interventions"]["by_requirement"]["SAF-REQ-010"];
    assert!(
        saf010["halted"].as_u64().unwrap() >= 1,
        "the supervisor never judged the protective stop (SAF-REQ-010): {json}"
    );
}

#[test]
fn sigstop_of_the_emulator_ends_the_ur_rtde_trial_as_link_lost_without_blocking() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    let emu = emulate_sim();
    let (mut child, out_root) = start_trial(dir.path(), false);
    wait_until_running(&mut child, &out_root);
    // A silent controller (as a pulled cable): the sockets stay open, nothing arrives.
    emu.signal("-STOP");
    let (status, stdout, stderr) = common::wait(child);
    emu.signal("-CONT");
    assert_eq!(status.code(), Some(3), "{stderr}");
    let json = summary(&run_folder(&stdout, &stderr));
    assert_eq!(json["finish_reason"], "link_lost", "{json}");
    // The supervisor saw the silence (SAF-REQ-009) and no cycle was held in ur_rtde longer
    // than the link-loss declaration (1 s): ur_rtde's stopJ waits up to 300 s on a silent
    // link, which a Stop once did here (a 301 s cycle).
    let saf009 = &json["motion"]["interventions"]["by_requirement"]["SAF-REQ-009"];
    assert!(saf009["stopped"].as_u64().unwrap() >= 1, "{json}");
    let worst_us = json["motion"]["cycles"]["latency_us"]["max"]
        .as_f64()
        .unwrap();
    assert!(worst_us < 1e6, "a cycle blocked for {worst_us} us: {json}");
}

/// `[link] resume = true` with the ur_rtde backend on a robot address is refused before
/// anything connects: ur_rtde 1.6.5 crashes the process 2.5 s into a silent link (its
/// control interface's own reconnect; `src/trial/backend_ur_rtde.rs` module docs), so a
/// resume could never happen. No emulator is needed: nothing is contacted.
#[test]
fn resume_with_the_ur_rtde_backend_is_refused_before_connecting() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    let (child, _) = start_trial(dir.path(), true);
    let (status, _, stderr) = common::wait(child);
    assert!(!status.success(), "{stderr}");
    assert!(stderr.contains("link.resume"), "{stderr}");
    assert!(stderr.contains("ur_rtde"), "{stderr}");
    assert!(
        !stderr.contains("robot mode"),
        "the dashboard was contacted: {stderr}"
    );
}
