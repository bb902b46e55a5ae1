//! The trial's one exit path (issue 10, "One exit path"): every ending stops the robot through
//! the supervisor, finishes every log with its `finish_reason` and names the run folder; the
//! error says why and carries the documented exit code. Link loss is tested against the
//! in-process emulator, frozen ([`Emulator::pause`], as `kill -STOP`) or killed
//! ([`Emulator::shutdown`]) from the progress callback, so no test waits on the wall clock
//! beyond the configured (short) link-loss times.

use std::sync::atomic::AtomicBool;

use robot_io::RobotIoError;
use robot_io::emulator::Emulator;

use super::*;
use crate::trial::log::read_mcap_messages;

/// What a trial that did not end normally left: (reason, run folder, message, exit code).
fn ended(r: crate::Result<PathBuf>) -> (&'static str, PathBuf, String, u8) {
    let e = r.expect_err("the trial should not end normally");
    let message = e.with_causes().to_string();
    let t = e
        .trial_ended()
        .unwrap_or_else(|| panic!("not a TrialEnded: {message}"));
    let dir = t.dir.clone().expect("the logs were opened");
    // The binary takes the exit code from the error itself.
    assert_eq!(e.exit_code(), t.exit_code(), "{message}");
    (t.reason, dir, message, t.exit_code())
}

fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap()
}

/// Every message on `topic` in the run's trial.mcap, as JSON.
fn messages(dir: &Path, topic: &str) -> Vec<serde_json::Value> {
    let bytes = std::fs::read(dir.join("trial.mcap")).unwrap();
    let (all, damaged) = read_mcap_messages(&bytes).unwrap();
    assert!(!damaged, "trial.mcap was finished");
    all.iter()
        .filter(|m| m.topic == topic)
        .map(|m| serde_json::from_slice(&m.data).unwrap())
        .collect()
}

/// The `/task/events` event names.
fn events(dir: &Path) -> Vec<String> {
    messages(dir, "/task/events")
        .iter()
        .map(|e| e["event"].as_str().unwrap().to_owned())
        .collect()
}

/// A short L1 trial with a fast link-loss configuration.
fn spec(max_s: f64, resume: bool, resume_within_s: f64) -> TrialSpec {
    let mut s = test_spec(Level::L1, 3, max_s);
    s.config.link.lost_after_s = 0.2;
    s.config.link.resume = resume;
    s.config.link.resume_within_s = resume_within_s;
    s
}

/// Runs `spec` on the in-process emulator at speed-up 10 (as `--robot emulator`), with `hook`
/// called with the emulator at every progress update.
fn run_on_emulator(
    spec: &TrialSpec,
    out: &Path,
    stop: &AtomicBool,
    hook: &mut dyn FnMut(&Emulator, &Live),
) -> crate::Result<PathBuf> {
    let _one_at_a_time = EMULATOR_TESTS.lock().unwrap_or_else(|e| e.into_inner());
    let choice = RobotChoice::Emulator { speedup: 10 };
    let setup = load_setup(spec, &choice, &CueSource::Simulated, out)?;
    let (robot, guard) = super::super::backend::start_emulator(
        setup.ctl_cfg.task.home_q_rad,
        10,
        spec.config.realtime,
        spec.config.emulator,
    )?;
    let emu = guard.emulator().expect("in-process");
    let r = drive(
        spec,
        setup,
        robot,
        Clock::Controller(10.0),
        "emulator",
        out,
        stop,
        &mut |l| hook(&emu, l),
    );
    guard.close();
    r
}

/// The last `/robot/command` record: the supervisor's verdict on it says what was sent.
fn last_command(dir: &Path) -> serde_json::Value {
    messages(dir, "/robot/command")
        .pop()
        .expect("commands logged")
}

#[test]
fn saf_req_009_a_frozen_emulator_stops_the_robot_and_ends_the_trial_as_link_lost() {
    let dir = tempfile::tempdir().unwrap();
    let stop = AtomicBool::new(false);
    let mut frozen = false;
    let r = run_on_emulator(&spec(6.0, false, 10.0), dir.path(), &stop, &mut |emu, l| {
        if l.t_s >= 1.0 && !frozen {
            emu.pause();
            frozen = true;
        }
    });
    let (reason, out, message, code) = ended(r);
    assert_eq!(reason, "link_lost");
    assert_eq!(code, 3, "the documented exit code");
    assert!(
        message.contains("no robot state for") && message.contains(&out.display().to_string()),
        "{message}"
    );
    assert_trial_files(&out);
    assert_eq!(summary(&out)["finish_reason"], "link_lost");
    assert!(events(&out).contains(&"link_lost".to_owned()));
    // The supervisor stopped the robot for the stale robot state before the trial ended.
    let last = last_command(&out);
    assert_eq!(last["verdict"], "stopped", "{last}");
    assert_eq!(last["requirement"], "SAF-REQ-009", "{last}");
}

#[test]
fn a_frozen_emulator_back_within_the_limit_resumes_and_the_trial_completes() {
    let dir = tempfile::tempdir().unwrap();
    let stop = AtomicBool::new(false);
    let (mut frozen, mut thawed) = (false, false);
    let out = run_on_emulator(&spec(3.0, true, 20.0), dir.path(), &stop, &mut |emu, l| {
        if l.t_s >= 1.0 && !frozen {
            emu.pause();
            frozen = true;
        }
        // Called while the trial waits for the link: bring the controller back.
        if l.link_down_s.is_some() && !thawed {
            emu.resume();
            thawed = true;
        }
    })
    .expect("the trial resumes and runs to its end");
    assert!(frozen && thawed);
    assert_trial_files(&out);
    assert_eq!(summary(&out)["finish_reason"], "max_duration");
    let ev = events(&out);
    let lost = ev
        .iter()
        .position(|e| e == "link_lost")
        .expect("link_lost event");
    let back = ev
        .iter()
        .position(|e| e == "link_restored")
        .expect("link_restored event");
    assert!(lost < back, "{ev:?}");
    let commands = messages(&out, "/robot/command");
    assert!(
        commands.iter().any(|c| c["requirement"] == "SAF-REQ-009"),
        "the supervisor stopped the robot while the state was stale"
    );
    // After the resume the controller commands motion again (servo commands that pass).
    let t_back = messages(&out, "/task/events")[back]["t_s"]
        .as_f64()
        .unwrap();
    assert!(
        commands.iter().any(|c| c["t_s"].as_f64().unwrap() > t_back
            && c["kind"] == "servo"
            && c["verdict"] == "passed"),
        "no motion after the resume"
    );
}

#[test]
fn a_killed_emulator_not_back_within_the_limit_ends_as_link_lost() {
    let dir = tempfile::tempdir().unwrap();
    let stop = AtomicBool::new(false);
    let mut killed = false;
    let r = run_on_emulator(&spec(6.0, true, 0.3), dir.path(), &stop, &mut |emu, l| {
        if l.t_s >= 1.0 && !killed {
            emu.shutdown();
            killed = true;
        }
    });
    let (reason, out, message, code) = ended(r);
    assert_eq!((reason, code), ("link_lost", 3));
    assert!(message.contains("not back within"), "{message}");
    assert_trial_files(&out);
    assert_eq!(summary(&out)["finish_reason"], "link_lost");
    // A killed link fails the sends (SAF-REQ-012, latched) or goes stale (SAF-REQ-009): a
    // stop either way.
    let last = last_command(&out);
    assert!(
        matches!(last["verdict"].as_str(), Some("stopped" | "halted"))
            && matches!(
                last["requirement"].as_str(),
                Some("SAF-REQ-009" | "SAF-REQ-012")
            ),
        "{last}"
    );
}

/// A lockstep `SimRobot` whose reads fail (or panic) from the `fail_at`-th on.
#[derive(Debug)]
struct FailingRobot {
    inner: LockstepSim,
    reads: u64,
    fail_at: u64,
    panic: bool,
}

impl Robot for FailingRobot {
    fn read_state(&mut self, out: &mut RobotState) -> robot_io::Result<()> {
        self.reads += 1;
        if self.reads >= self.fail_at {
            assert!(!self.panic, "injected panic in read_state");
            return Err(RobotIoError::Malformed {
                reason: "injected fault",
            });
        }
        self.inner.read_state(out)
    }

    fn send(&mut self, cmd: &JointCommand) -> robot_io::Result<()> {
        self.inner.send(cmd)
    }
}

impl TrialRobot for FailingRobot {}

fn run_failing(out: &Path, panic: bool) -> crate::Result<PathBuf> {
    let spec = test_spec(Level::L1, 1, 10.0);
    let setup = load_setup(&spec, &RobotChoice::Sim, &CueSource::Simulated, out).unwrap();
    let sim = SimRobot::new(SimConfig {
        initial_q_rad: setup.ctl_cfg.task.home_q_rad,
        ..SimConfig::ur5e()
    })
    .unwrap();
    let robot = FailingRobot {
        inner: LockstepSim { sim, first: true },
        reads: 0,
        fail_at: 1000, // 2 s into the trial
        panic,
    };
    let stop = AtomicBool::new(false);
    drive(
        &spec,
        setup,
        robot,
        Clock::Mock,
        "sim",
        out,
        &stop,
        &mut |_| {},
    )
}

#[test]
fn an_error_inside_the_loop_finishes_every_log_as_error() {
    let dir = tempfile::tempdir().unwrap();
    let (reason, out, message, code) = ended(run_failing(dir.path(), false));
    assert_eq!((reason, code), ("error", 1));
    assert!(message.contains("injected fault"), "{message}");
    assert_trial_files(&out);
    let s = summary(&out);
    assert_eq!(s["finish_reason"], "error");
    assert!(s["completion_time_s"].as_f64().unwrap() > 1.9, "{s}");
}

#[test]
fn a_panic_inside_the_loop_finishes_every_log_as_error() {
    let dir = tempfile::tempdir().unwrap();
    let (reason, out, message, code) = ended(run_failing(dir.path(), true));
    assert_eq!((reason, code), ("error", 1));
    assert!(message.contains("panicked: injected panic"), "{message}");
    assert_trial_files(&out);
    assert_eq!(summary(&out)["finish_reason"], "error");
}

#[test]
fn ctrl_c_mid_trial_finishes_every_log_as_interrupted() {
    let dir = tempfile::tempdir().unwrap();
    let stop = AtomicBool::new(false);
    let r = run_simulated_with(
        &test_spec(Level::L2, 1, 60.0),
        dir.path(),
        &stop,
        &mut |l| {
            if l.t_s >= 5.0 {
                stop.store(true, Ordering::Relaxed); // what the Ctrl-C handler does
            }
        },
    );
    let (reason, out, _, code) = ended(r);
    assert_eq!((reason, code), ("interrupted", 130));
    assert_trial_files(&out);
    let s = summary(&out);
    assert_eq!(s["finish_reason"], "interrupted");
    let t = s["completion_time_s"].as_f64().unwrap();
    assert!((5.0..5.1).contains(&t), "stopped at the next cycle: {t}");
}

/// A recorded operator who holds the right hand still at the handover pose, next to the
/// robot's way to the pick pose: the robot cannot get past it (its protective separation
/// distance is never met, SAF-REQ-007 stops it again and again), and the trial ends as
/// `task_impossible` naming the requirement, instead of running to `max_duration`.
#[test]
fn saf_req_007_a_hand_held_at_the_handover_pose_ends_the_trial_as_task_impossible() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("hand-at-handover.csv");
    let mut text = String::from(
        "t,head_x,head_y,head_z,head_fx,head_fy,head_fz,head_conf,\
         rhand_x,rhand_y,rhand_z,rhand_conf\n",
    );
    // 20 s at 30 Hz: the head looks at the collaboration area, whose centre (0.90, 0.60,
    // 0.99) m is where config/trial.toml puts the handover flange pose; the hand is there.
    for n in 0..=600 {
        let t = f64::from(n) / 30.0;
        text.push_str(&format!(
            "{t:.6},0,0,1.2,0.9,0.6,-0.2,0.9,0.90,0.60,0.99,0.9\n"
        ));
    }
    std::fs::write(&csv, text).unwrap();
    let mut s = test_spec(Level::L1, 1, 20.0);
    s.policy = PolicyKind::Fixed;
    s.config.progress.stuck_after_s = 1.5;
    s.config.lead_time_s = 60.0; // the first fetch starts at once
    let out_root = dir.path().join("run");
    let stop = AtomicBool::new(false);
    let r = run_trial_with_cues(
        &s,
        &RobotChoice::Sim,
        &CueSource::Recorded(csv),
        &out_root,
        &stop,
        &mut |_| {},
    );
    let (reason, out, message, code) = ended(r);
    assert_eq!((reason, code), ("task_impossible", 4), "{message}");
    assert!(
        message.contains("in Fetch") && message.contains("SAF-REQ-007"),
        "{message}"
    );
    assert_trial_files(&out);
    let sm = summary(&out);
    assert_eq!(sm["finish_reason"], "task_impossible");
    let t = sm["completion_time_s"].as_f64().unwrap();
    assert!(
        (1.5..8.0).contains(&t),
        "ended {t} s into the trial, not at the 20 s the cues last: {sm}"
    );
}

/// Worked example (by hand): limit 2 s, the Approach target 1 rad away on joint 0.
/// - t = 0: phase change → timer starts, best 1.0;
/// - t = 0.5: q0 = 0.5 → distance 0.5, progress → timer restarts at 0.5;
/// - t = 0.5 … 2.5: no progress (0.5 stays), 3 SAF-REQ-007 stops and 1 SAF-REQ-004
///   reduction: at t = 2.5, 2.0 s without progress → stuck, cause SAF-REQ-007 (3 times);
/// - a phase change restarts it; at the target (≤ 0.01 rad) it is never stuck.
#[test]
fn stuck_watch_worked_example() {
    let target = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let at = |q0: f64| [q0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut w = StuckWatch::new(2.0);
    assert_eq!(
        w.update(0.0, Phase::Approach, Some(&target), &at(0.0), None, 0),
        None
    );
    assert_eq!(
        w.update(0.5, Phase::Approach, Some(&target), &at(0.5), None, 0),
        None
    );
    for (t, r) in [
        (1.0, Some("SAF-REQ-007")),
        (1.5, Some("SAF-REQ-004")),
        (2.0, Some("SAF-REQ-007")),
        (2.4, Some("SAF-REQ-007")),
    ] {
        assert_eq!(
            w.update(t, Phase::Approach, Some(&target), &at(0.5), r, 0),
            None
        );
    }
    let s = w
        .update(2.5, Phase::Approach, Some(&target), &at(0.5), None, 0)
        .expect("stuck after 2 s");
    assert_eq!(
        (s.cause, s.interventions, s.phase),
        ("SAF-REQ-007", 3, Phase::Approach)
    );
    assert!((s.for_s - 2.0).abs() < 1e-12);
    // A phase change restarts the timer.
    assert_eq!(
        w.update(2.6, Phase::Retreat, Some(&target), &at(0.5), None, 0),
        None
    );
    assert_eq!(
        w.update(4.5, Phase::Retreat, Some(&target), &at(0.5), None, 0),
        None
    );
    // At the target (gripping at the pick pose, settling): never stuck.
    let mut w = StuckWatch::new(2.0);
    for k in 0..100 {
        let t = f64::from(k) * 0.1;
        assert_eq!(
            w.update(t, Phase::Fetch, Some(&target), &at(0.995), None, 0),
            None
        );
    }
    // No intervention, but trajectory errors: the trajectory is named; neither: no_progress.
    let mut w = StuckWatch::new(1.0);
    w.update(0.0, Phase::Fetch, Some(&target), &at(0.0), None, 5);
    let s = w
        .update(1.0, Phase::Fetch, Some(&target), &at(0.0), None, 9)
        .unwrap();
    assert_eq!(s.cause, "trajectory");
    let mut w = StuckWatch::new(1.0);
    w.update(0.0, Phase::Fetch, Some(&target), &at(0.0), None, 0);
    assert_eq!(
        w.update(1.0, Phase::Fetch, Some(&target), &at(0.0), None, 0)
            .unwrap()
            .cause,
        "no_progress"
    );
    // Idle and Present are not motion phases.
    let mut w = StuckWatch::new(1.0);
    for k in 0..30 {
        let t = f64::from(k) * 0.1;
        assert_eq!(
            w.update(
                t,
                Phase::Present,
                Some(&target),
                &at(0.0),
                Some("SAF-REQ-007"),
                0
            ),
            None
        );
    }
}

#[test]
fn every_abnormal_ending_has_its_own_documented_exit_code() {
    for normal in ["completed", "max_duration", "cues_ended"] {
        assert_eq!(exit_code(normal), 0, "{normal}");
    }
    let codes: Vec<u8> = [
        "error",
        "link_lost",
        "task_impossible",
        "robot_program_stopped",
        "interrupted",
    ]
    .iter()
    .map(|r| exit_code(r))
    .collect();
    assert_eq!(codes, [1, 3, 4, 5, 130]);
    // The README's table says the same.
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap();
    for row in [
        "| 0 | `completed`",
        "| 1 | `error`",
        "| 3 | `link_lost`",
        "| 4 | `task_impossible`",
        "| 5 | `robot_program_stopped`",
        "| 130 | `interrupted`",
    ] {
        assert!(readme.contains(row), "README exit-code table lacks {row:?}");
    }
}
