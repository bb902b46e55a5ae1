//! `RtdeRobot`'s servo feedforward against the emulator over loopback TCP, at speedup 4 (the
//! demo's setting): the velocity it derives from the servo targets and the controller
//! timestamps reaches the program, which extrapolates an unrefreshed target up to
//! `extrapolate_max_s` and holds it there. Simulated robot; no assertion depends on
//! scheduling (every wait is bounded by a sample count or a timeout, and the values checked
//! are the same whenever the command lands).

use std::time::Duration;

use robot_io::emulator::{Emulator, EmulatorConfig, SimBackend};
use robot_io::rtde_robot::{RtdeRobot, RtdeRobotConfig};
use robot_io::script::{RegisterMap, ScriptSender};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Joints, Robot, RobotState, runtime_state};

const TEST_TIMEOUT: Duration = Duration::from_secs(60);
const SAMPLE_TIMEOUT: Duration = Duration::from_secs(5);

/// The emulator at `speedup` with our program playing, and an RtdeRobot on it.
async fn setup(speedup: u32, map: RegisterMap) -> (Emulator, RtdeRobot) {
    let sim = SimRobot::new(SimConfig::ur5e()).unwrap();
    let emu = Emulator::start(
        EmulatorConfig {
            speedup,
            ..EmulatorConfig::ephemeral()
        },
        Box::new(SimBackend::new(sim)),
    )
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

/// A ramp of three servo targets at 0.25 rad/s on joint 0, one per sample read, then
/// nothing: the robot extrapolates the last target at the ramp's velocity up to the bound
/// (24 ms at speedup 4, as the trial scales it) and holds q3 + 0.25·0.024 = q3 + 0.006 rad,
/// whenever the command arrived (its age only decides how soon).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unrefreshed_ramp_target_is_extrapolated_at_the_ramp_velocity_up_to_the_bound() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        // A slow watchdog (1 s of virtual time): this test is not about stalls.
        let map = RegisterMap {
            watchdog_hz: 1.0,
            extrapolate_max_s: 0.024,
            ..RegisterMap::default()
        };
        let (emu, mut robot) = setup(4, map).await;
        const V: f64 = 0.25;
        let mut s = RobotState::default();
        robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        let (q0, t0) = (s.actual_q, s.timestamp_s);
        let mut last = q0;
        for _ in 0..3 {
            robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
            // The target for the cycle after this sample.
            last = q0;
            last[0] += V * (s.timestamp_s + 0.002 - t0);
            robot.send(&servo(last)).unwrap();
        }
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
