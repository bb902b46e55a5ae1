//! `hrc-adapt trial --robot 127.0.0.1` against `hrc-adapt emulate --sim` running as a separate
//! process on ephemeral ports (real time, speed-up 1), the emulator stopped with SIGSTOP for
//! 5 s or killed with SIGKILL mid-trial (issue 10, Acceptance). Each case checks the exit code
//! (README, "Exit codes"), that the run folder is printed and that its logs are finished with
//! the reason.
//!
//! The trial is a short L1 trial whose first fetch starts at once; the emulator is stopped once
//! the trial has logged a second of robot state. The only fixed wait is the 5 s SIGSTOP the
//! acceptance asks for.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{BIN, Emulate, run_folder, summary};

/// Every wait of these tests is bounded by this.
const DEADLINE: Duration = Duration::from_secs(120);

/// `hrc-adapt emulate --sim` on ephemeral ports, in real time.
fn emulate_sim() -> Emulate {
    Emulate::start_on_port(&["--sim", "--speedup", "1"], 0)
}

/// The trial config of these tests: a 6 s L1 trial whose first fetch starts at once, and
/// `[link] resume = resume`.
fn link_config(dir: &Path, resume: bool) -> PathBuf {
    common::trial_config(
        dir,
        &[
            ("max_duration_s", "6.0"),
            ("lead_time_s", "60.0"),
            ("resume", if resume { "true" } else { "false" }),
            ("resume_within_s", "30.0"),
        ],
    )
}

/// A running `hrc-adapt trial` on the emulator process.
struct Trial {
    child: Child,
    out_root: PathBuf,
}

impl Trial {
    fn start(emu: &Emulate, dir: &Path, resume: bool) -> Trial {
        let out_root = dir.join("runs");
        let mut child = Command::new(BIN)
            .args(["trial", "--robot", "127.0.0.1", "--condition", "L1"])
            .args(["--participant", "P01", "--seed", "1"])
            .arg("--config")
            .arg(link_config(dir, resume))
            .arg("--out-root")
            .arg(&out_root)
            .args(["--rtde-port", &emu.port("rtde").to_string()])
            .args(["--dashboard-port", &emu.port("dashboard").to_string()])
            .args(["--script-port", &emu.port("script").to_string()])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start hrc-adapt trial");
        // The UR5e confirmation prompt.
        child.stdin.take().unwrap().write_all(b"yes\n").unwrap();
        Trial { child, out_root }
    }

    /// Waits until the trial has logged more than a second of robot state (robot.csv holds
    /// a first chunk: about 100 rows).
    fn wait_until_running(&mut self) {
        let start = Instant::now();
        loop {
            let rows = std::fs::read_dir(&self.out_root)
                .into_iter()
                .flatten()
                .flatten()
                .map(|e| e.path().join("robot.csv"))
                .find_map(|p| std::fs::read_to_string(p).ok())
                .map_or(0, |t| t.lines().count());
            if rows > 100 {
                return;
            }
            if let Some(status) = self.child.try_wait().unwrap() {
                panic!("the trial ended before it ran: {status}: {}", self.stderr());
            }
            assert!(start.elapsed() < DEADLINE, "the trial never got going");
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn stderr(&mut self) -> String {
        let mut s = String::new();
        if let Some(mut e) = self.child.stderr.take() {
            let _ = e.read_to_string(&mut s);
        }
        s
    }

    /// Waits for the trial's end: its exit status, its stdout and its stderr.
    fn wait(self) -> (ExitStatus, String, String) {
        common::wait(self.child)
    }
}

/// The `event` names on `/task/events`.
fn task_events(dir: &Path) -> Vec<String> {
    let bytes = std::fs::read(dir.join("trial.mcap")).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(Result::unwrap)
        .filter(|m| m.channel.topic == "/task/events")
        .map(|m| {
            let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            v["event"].as_str().unwrap().to_owned()
        })
        .collect()
}

#[test]
fn sigstop_5_s_with_resume_the_trial_resumes_and_completes() {
    let tmp = tempfile::tempdir().unwrap();
    let emu = emulate_sim();
    let mut trial = Trial::start(&emu, tmp.path(), true);
    trial.wait_until_running();
    emu.signal("-STOP");
    std::thread::sleep(Duration::from_secs(5));
    emu.signal("-CONT");
    let (status, stdout, stderr) = trial.wait();
    assert_eq!(status.code(), Some(0), "{stderr}");
    let dir = run_folder(&stdout, &stderr);
    assert_eq!(summary(&dir)["finish_reason"], "max_duration", "{stderr}");
    let ev = task_events(&dir);
    let lost = ev.iter().position(|e| e == "link_lost").expect("link lost");
    let back = ev
        .iter()
        .position(|e| e == "link_restored")
        .expect("link restored");
    assert!(lost < back, "{ev:?}");
}

#[test]
fn sigstop_without_resume_ends_as_link_lost_with_exit_code_3() {
    let tmp = tempfile::tempdir().unwrap();
    let emu = emulate_sim();
    let mut trial = Trial::start(&emu, tmp.path(), false);
    trial.wait_until_running();
    emu.signal("-STOP");
    // No resume: the trial ends while the emulator is still stopped (1 s without state).
    let (status, stdout, stderr) = trial.wait();
    emu.signal("-CONT");
    assert_eq!(status.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains("link_lost") && stderr.contains("no robot state"),
        "{stderr}"
    );
    let dir = run_folder(&stdout, &stderr);
    assert_eq!(summary(&dir)["finish_reason"], "link_lost");
    assert!(task_events(&dir).contains(&"link_lost".to_owned()));
}

#[test]
fn sigkill_ends_as_link_lost_with_exit_code_3() {
    let tmp = tempfile::tempdir().unwrap();
    let emu = emulate_sim();
    let mut trial = Trial::start(&emu, tmp.path(), false);
    trial.wait_until_running();
    emu.signal("-KILL");
    let (status, stdout, stderr) = trial.wait();
    assert_eq!(status.code(), Some(3), "{stderr}");
    let dir = run_folder(&stdout, &stderr);
    assert_eq!(summary(&dir)["finish_reason"], "link_lost");
}
