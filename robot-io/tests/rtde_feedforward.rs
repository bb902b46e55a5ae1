//! `RtdeRobot`'s servo feedforward against the emulator over loopback TCP, at speedup 4 (the
//! demo's setting): the velocity it derives from the servo targets and the controller
//! timestamps reaches the program, which extrapolates an unrefreshed target up to
//! `extrapolate_max_s` and holds it there. Simulated robot; no assertion depends on
//! scheduling (every wait is bounded by a sample count or a timeout, and the values checked
//! are the same whenever the command lands).

use std::time::Duration;

use robot_io::emulator::{Emulator, EmulatorConfig, SimBackend};
use robot_io::rtde_robot::{MAX_SERVO_LEAD_CYCLES, RtdeRobot, RtdeRobotConfig, servo_slot};
use robot_io::script::{INT_REGISTERS, RegisterMap, ScriptSender};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Joints, Robot, RobotState, runtime_state};

const TEST_TIMEOUT: Duration = Duration::from_secs(60);
const SAMPLE_TIMEOUT: Duration = Duration::from_secs(5);

/// The emulator at `speedup` with our program playing, and an RtdeRobot on it.
async fn setup(speedup: u32, map: RegisterMap) -> (Emulator, RtdeRobot) {
    setup_with(
        EmulatorConfig {
            speedup,
            ..EmulatorConfig::ephemeral()
        },
        map,
    )
    .await
}

/// The emulator with `cfg`, our program playing, and an RtdeRobot on it.
async fn setup_with(cfg: EmulatorConfig, map: RegisterMap) -> (Emulator, RtdeRobot) {
    let sim = SimRobot::new(SimConfig::ur5e()).unwrap();
    let emu = Emulator::start(cfg, Box::new(SimBackend::new(sim)))
        .await
        .unwrap();
    let mut cfg = RtdeRobotConfig::new("127.0.0.1");
    cfg.port = emu.rtde_addr().port();
    cfg.registers = map;
    cfg.link_loss_min = Duration::from_secs(3);
    let mut robot = RtdeRobot::connect(cfg).await.unwrap();
    ScriptSender::new("127.0.0.1", emu.secondary_addr().port())
        .send_control_program(&map)
        .await
        .unwrap();
    let mut s = RobotState::default();
    for _ in 0..5000 {
        robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        if s.runtime_state == runtime_state::PLAYING {
            return (emu, robot);
        }
    }
    panic!("the program never started");
}

fn servo(q: Joints) -> JointCommand {
    JointCommand::Servo {
        q,
        lookahead_s: 0.05,
        gain: 500.0,
    }
}

/// The servo target the emulator's SimRobot has latched [rad].
fn latched(emu: &Emulator) -> Option<Joints> {
    emu.with_sim(|b| match b.robot_mut().command() {
        Some(JointCommand::Servo { q, .. }) => Some(*q),
        _ => None,
    })
    .flatten()
}

/// A slow watchdog (1 s of virtual time) and the emulator's extrapolation bound at speedup 4
/// (24 ms, as the trial scales it): for tests that are not about stalls.
fn slow_watchdog_map() -> RegisterMap {
    RegisterMap {
        watchdog_hz: 1.0,
        extrapolate_max_s: 0.024,
        ..RegisterMap::default()
    }
}

/// Sends a ramp at `v` [rad/s] on joint 0 from the next sample's joints: three servo targets,
/// each for the cycle after the sample just read. Returns the joints it started from and the
/// last target [rad], and the last sample in `s`.
async fn send_ramp(robot: &mut RtdeRobot, s: &mut RobotState, v: f64) -> (Joints, Joints) {
    robot.wait_state(s, SAMPLE_TIMEOUT).await.unwrap();
    let (q0, t0) = (s.actual_q, s.timestamp_s);
    let mut last = q0;
    for _ in 0..3 {
        robot.wait_state(s, SAMPLE_TIMEOUT).await.unwrap();
        last = q0;
        last[0] += v * (s.timestamp_s + 0.002 - t0);
        robot.send(&servo(last)).unwrap();
    }
    (q0, last)
}

/// A ramp of three servo targets at 0.25 rad/s on joint 0, one per sample read, then
/// nothing: the robot extrapolates the last target at the ramp's velocity up to the bound
/// (24 ms at speedup 4, as the trial scales it) and holds q3 + 0.25·0.024 = q3 + 0.006 rad,
/// whenever the command arrived (its age only decides how soon).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unrefreshed_ramp_target_is_extrapolated_at_the_ramp_velocity_up_to_the_bound() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let map = slow_watchdog_map();
        let (emu, mut robot) = setup(4, map).await;
        const V: f64 = 0.25;
        let mut s = RobotState::default();
        let (q0, last) = send_ramp(&mut robot, &mut s, V).await;
        let held = last[0] + V * map.extrapolate_max_s;
        // Read samples until the program holds; an earlier target's hold is 0.0005 rad short.
        let mut reached = false;
        for _ in 0..5000 {
            robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
            if latched(&emu).is_some_and(|q| q[0] >= held - 1e-9) {
                reached = true;
                break;
            }
        }
        assert!(reached, "never extrapolated to {held}: {:?}", latched(&emu));
        let t = latched(&emu).unwrap();
        assert!((t[0] - held).abs() < 1e-9, "held {} vs {held}", t[0]);
        assert_eq!(t[1..], last[1..]);
        // And it stays there (no refresh, no further extrapolation), while the arm follows.
        for _ in 0..50 {
            robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        }
        assert_eq!(latched(&emu), Some(t));
        assert!(s.actual_q[0] > q0[0], "the arm did not follow");
        assert!(s.actual_q[0] <= held + 1e-9, "passed the held target");
        assert_eq!(emu.with_sim(|b| b.watchdog_trips()), Some(0));
    })
    .await
    .expect("test timed out");
}

/// A sped-up clock with `wait_for_client` waits for a late client instead of extrapolating
/// (`robot_io::emulator::ClientWait`): after one moving servo target and then silence,
/// virtual time stands still (cycles counted as waited, none run) for as long as the bound
/// allows, here 30 s; a new command lets it run on. With a short bound (50 ms) it runs on
/// after the bound, as a controller would, and counts the timed-out wait.
///
/// Nothing depends on how fast this machine is. Every snapshot is taken only after the
/// emulator has put the ramp's last command in force (`SimBackend::servo_target`), so a command
/// still in flight cannot end a wait the test is watching; each later condition is polled
/// for, bounded by [`SAMPLE_TIMEOUT`], never slept for. The long bound is never reached, the
/// short one always is.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sped_up_clock_waits_for_a_late_client_and_runs_on_after_the_bound() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let map = slow_watchdog_map();
        for (bound, times_out) in [
            (Duration::from_secs(30), false),
            (Duration::from_millis(50), true),
        ] {
            let cfg = EmulatorConfig {
                speedup: 4,
                wait_for_client: Some(bound),
                ..EmulatorConfig::ephemeral()
            };
            let (emu, mut robot) = setup_with(cfg, map).await;
            let in_force = |emu: &Emulator| emu.with_sim(|b| b.servo_target()).flatten();
            let mut s = RobotState::default();
            let (_, mut target) = send_ramp(&mut robot, &mut s, 0.25).await;
            // The ramp's last command is in force (a stalled test may have written two
            // commands between cycles; the emulator then executes the newer only).
            poll(|| in_force(&emu) == Some(target)).await;
            let executed = emu.clock_stats();
            // Silence: the clock waits at a wake after the last command's cycle.
            poll(|| emu.clock_stats().cycles_waited > executed.cycles_waited).await;
            let waiting = emu.clock_stats();
            assert!(waiting.waits > 0, "never waited: {waiting:?}");
            if times_out {
                // The wait started after `executed` reaches the bound; the clock runs on.
                poll(|| emu.clock_stats().waits_timed_out > executed.waits_timed_out).await;
                poll(|| emu.clock_stats().cycles_run > waiting.cycles_run).await;
            } else {
                // While it waits, cycles are counted as waited and none runs.
                poll(|| emu.clock_stats().cycles_waited > waiting.cycles_waited + 100).await;
                let later = emu.clock_stats();
                assert_eq!(later.waits_timed_out, 0, "{later:?}");
                assert_eq!(
                    later.cycles_run, waiting.cycles_run,
                    "a cycle ran while waiting: {later:?}"
                );
                assert_eq!(in_force(&emu), Some(target));
                // The next command, for the cycle after the newest sample: the clock runs on.
                robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
                target[0] += 0.0005;
                robot.send(&servo(target)).unwrap();
                poll(|| emu.clock_stats().cycles_run > later.cycles_run).await;
            }
        }
    })
    .await
    .expect("test timed out");
}

/// Polls `cond` every millisecond until it holds; panics after [`SAMPLE_TIMEOUT`].
async fn poll(mut cond: impl FnMut() -> bool) {
    let start = std::time::Instant::now();
    while !cond() {
        assert!(
            start.elapsed() < SAMPLE_TIMEOUT,
            "condition not met within {SAMPLE_TIMEOUT:?}"
        );
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
}

/// A real-time clock (speedup 1) never waits: `wait_for_client` there is refused.
#[tokio::test]
async fn waiting_for_the_client_is_refused_at_speedup_1() {
    let sim = SimRobot::new(SimConfig::ur5e()).unwrap();
    let e = Emulator::start(
        EmulatorConfig {
            speedup: 1,
            wait_for_client: Some(Duration::from_millis(20)),
            ..EmulatorConfig::ephemeral()
        },
        Box::new(SimBackend::new(sim)),
    )
    .await
    .expect_err("refused");
    assert!(e.to_string().contains("speedup > 1"), "{e}");
}

/// `send` only peeks at the newest sample for the age: a client reading every sample in
/// order (`wait_state`) still gets every one after sending (in real time, so the client's
/// 1024-sample ring holds 2 s: far more than any stall of this loop).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn send_does_not_consume_samples() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let (_emu, mut robot) = setup(1, RegisterMap::default()).await;
        let mut s = RobotState::default();
        robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        let q = s.actual_q;
        let mut prev = s.timestamp_s;
        // Let samples queue up unread (a taking send would skip them).
        tokio::time::sleep(Duration::from_millis(20)).await;
        for _ in 0..100 {
            robot.send(&servo(q)).unwrap();
            robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
            // 500 Hz output: consecutive samples are one cycle apart.
            assert!(
                (s.timestamp_s - prev - 0.002).abs() < 1e-9,
                "skipped from {prev} to {}",
                s.timestamp_s
            );
            prev = s.timestamp_s;
        }
    })
    .await
    .expect("test timed out");
}

/// The stamp of a servo command, worked by hand (2 ms cycles): after a state of tick 100 at
/// 1.000 s the command is for tick 101 at 1.002 s; read again with no newer state, the next
/// command is for 102 at 1.004 s, and one more for 103; a newer state (tick 104) takes over
/// again. A state that comes late, after the caller has already predicted past it (tick 101
/// when the last command was for 102), gives 103: never two commands for one tick. A lead of
/// more than MAX_SERVO_LEAD_CYCLES (a restarted program counts from 0 again) falls back to
/// the state's tick + 1; ticks wrap as the program's i32 counter does.
#[test]
fn servo_commands_are_stamped_with_consecutive_ticks_when_no_newer_state_arrived() {
    let close = |(a, t): (i32, f64), (b, u): (i32, f64)| a == b && (t - u).abs() < 1e-12;
    let first = servo_slot(100, 1.000, None);
    assert!(close(first, (101, 1.002)), "{first:?}");
    let again = servo_slot(100, 1.000, Some(first));
    assert!(close(again, (102, 1.004)), "{again:?}");
    let third = servo_slot(100, 1.000, Some(again));
    assert!(close(third, (103, 1.006)), "{third:?}");
    let newer = servo_slot(104, 1.008, Some(third));
    assert!(close(newer, (105, 1.010)), "{newer:?}");
    let late = servo_slot(101, 1.002, Some(again));
    assert!(close(late, (103, 1.006)), "{late:?}");
    let lead = MAX_SERVO_LEAD_CYCLES;
    let far = servo_slot(100, 1.000, Some((101 + lead, 9.0)));
    assert!(close(far, (101, 1.002)), "{far:?}");
    let restarted = servo_slot(3, 0.006, Some((5_000, 10.0)));
    assert!(close(restarted, (4, 0.008)), "{restarted:?}");
    let wrapped = servo_slot(i32::MAX, 1.0, Some((i32::MAX.wrapping_add(1), 1.002)));
    assert_eq!(wrapped.0, i32::MIN.wrapping_add(1));
}

/// Over RTDE: with the emulator's samples held back (`set_rtde_silent`, the program runs on),
/// `read_state` returns the same state again, and each servo command sent after it reaches the
/// program's registers with the next tick (before, both carried the state's tick + 1, so a
/// controller predicting through a late sample had its target applied a cycle early: a step).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn commands_sent_while_no_new_state_arrives_carry_consecutive_valid_ticks() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let map = RegisterMap {
            watchdog_hz: 1.0,
            ..RegisterMap::default()
        };
        let (emu, mut robot) = setup(1, map).await;
        let mut s = RobotState::default();
        robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        emu.set_rtde_silent(true);
        // Whatever was in flight arrives; then nothing new does.
        tokio::time::sleep(Duration::from_millis(50)).await;
        robot.read_state(&mut s).unwrap();
        let q = s.actual_q;
        let ib = usize::from(map.int_base);
        let seq0 = emu.inputs().int[ib + 1];
        let mut ticks = Vec::new();
        for k in 0..3 {
            let mut again = RobotState::default();
            robot.read_state(&mut again).unwrap();
            assert_eq!(again.timestamp_s, s.timestamp_s, "a new state arrived");
            robot.send(&servo(q)).unwrap();
            // Wait until the emulator holds this command (its sequence number).
            let written = loop {
                let inputs = emu.inputs();
                let regs = &inputs.int[ib..ib + INT_REGISTERS];
                if regs[1] == seq0 + k + 1 {
                    break regs[2];
                }
                tokio::time::sleep(Duration::from_millis(1)).await;
            };
            ticks.push(written);
        }
        assert_eq!(
            ticks,
            [ticks[0], ticks[0] + 1, ticks[0] + 2],
            "valid ticks of three commands after one state"
        );
        emu.set_rtde_silent(false);
    })
    .await
    .expect("test timed out");
}
