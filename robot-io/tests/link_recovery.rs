//! Hardware-in-the-loop tests of what a trial needs after a link loss (issue 10, "One exit
//! path"): the emulator's freeze hook (`pause`/`resume`, as `kill -STOP`/`-CONT`), its kill
//! (`shutdown`), `RtdeRobot::send` failing while the link is down, and
//! `RtdeRobot::restart_program` bringing our stopped control program back without blocking.
//! Real client, emulator on ephemeral loopback ports; every wait is bounded and generous.

use std::time::Duration;

use robot_io::client::LinkState;
use robot_io::dashboard::DashboardClient;
use robot_io::emulator::{Emulator, EmulatorConfig, SimBackend};
use robot_io::rtde_robot::{RtdeRobot, RtdeRobotConfig};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Robot, RobotIoError, RobotState, runtime_state};

const TEST_TIMEOUT: Duration = Duration::from_secs(60);
const SAMPLE_TIMEOUT: Duration = Duration::from_secs(5);

/// The emulator and a robot whose control program plays (sent through `start_program`).
async fn setup() -> (Emulator, RtdeRobot) {
    let emu = Emulator::start(
        EmulatorConfig::ephemeral(),
        Box::new(SimBackend::new(SimRobot::new(SimConfig::ur5e()).unwrap())),
    )
    .await
    .unwrap();
    let mut cfg = RtdeRobotConfig::new("127.0.0.1");
    cfg.port = emu.rtde_addr().port();
    cfg.link_loss_min = Duration::from_secs(3);
    cfg.program_port = Some(emu.secondary_addr().port());
    // A slow watchdog: these tests stop writing on purpose.
    cfg.registers.watchdog_hz = 0.5;
    let mut robot = RtdeRobot::connect(cfg).await.unwrap();
    robot.start_program().await.unwrap();
    wait_for(&mut robot, "the program playing", |s| {
        s.runtime_state == runtime_state::PLAYING
    })
    .await;
    (emu, robot)
}

async fn wait_for(
    robot: &mut RtdeRobot,
    what: &str,
    ok: impl Fn(&RobotState) -> bool,
) -> RobotState {
    let mut s = RobotState::default();
    for _ in 0..5000 {
        robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        if ok(&s) {
            return s;
        }
    }
    panic!("never saw {what}; last state {s:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_paused_emulator_sends_nothing_and_its_clock_stands_still_until_resumed() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let (emu, mut robot) = setup().await;
        let mut s = RobotState::default();
        robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        emu.pause();
        assert!(emu.is_paused());
        // Drain what was on the way, then nothing comes.
        while robot
            .wait_state(&mut s, Duration::from_millis(100))
            .await
            .is_ok()
        {}
        let frozen_at = emu.cycle();
        let r = robot.wait_state(&mut s, Duration::from_millis(300)).await;
        assert!(matches!(r, Err(RobotIoError::Timeout { .. })), "{r:?}");
        assert_eq!(emu.cycle(), frozen_at, "the virtual clock ran while paused");
        // A frozen controller is still connected: the client does not see a loss yet.
        assert_eq!(robot.client().link_state(), LinkState::Up);
        let before = s.timestamp_s;
        emu.resume();
        let mut after = RobotState::default();
        robot.wait_state(&mut after, SAMPLE_TIMEOUT).await.unwrap();
        // The clock goes on from where it stopped (no jump by the pause's length).
        let step = after.timestamp_s - before;
        assert!(step > 0.0 && step < 0.1, "timestamp step {step} s");
        assert_eq!(after.runtime_state, runtime_state::PLAYING);
    })
    .await
    .expect("test timed out");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn send_fails_while_the_link_is_down_and_works_again_once_reconnected() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let (emu, mut robot) = setup().await;
        let stop = JointCommand::Stop { decel: 2.0 };
        robot.send(&stop).unwrap();
        emu.cut_rtde_links();
        // The client sees the cut socket and reconnects; meanwhile a send did not reach the
        // robot and says so.
        let mut saw_down = false;
        for _ in 0..2000 {
            match robot.send(&stop) {
                Err(RobotIoError::LinkDown { .. }) => {
                    saw_down = true;
                    break;
                }
                Ok(()) => tokio::time::sleep(Duration::from_millis(1)).await,
                Err(e) => panic!("unexpected {e}"),
            }
        }
        assert!(saw_down, "send never reported the link down");
        let mut s = RobotState::default();
        // Reconnected: sends go through again and fresh states arrive.
        for _ in 0..5000 {
            if robot.client().link_state() == LinkState::Up {
                break;
            }
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
        assert_eq!(robot.client().link_state(), LinkState::Up);
        robot.send(&stop).unwrap();
        robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        assert!(robot.client().reconnects() >= 1);
    })
    .await
    .expect("test timed out");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn restart_program_brings_a_stopped_program_back_without_blocking() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let (emu, mut robot) = setup().await;
        let mut d = DashboardClient::connect(
            "127.0.0.1",
            emu.dashboard_addr().port(),
            Duration::from_secs(5),
        )
        .await
        .unwrap();
        // As the controller's watchdog would: the program stops.
        d.stop().await.unwrap();
        wait_for(&mut robot, "the program stopped", |s| {
            s.runtime_state == runtime_state::STOPPED
        })
        .await;
        assert_eq!(robot.program_restarts(), 0);
        // Returns at once; the send runs on the runtime.
        assert!(robot.restart_program(), "a restart was started");
        wait_for(&mut robot, "the program playing again", |s| {
            s.runtime_state == runtime_state::PLAYING
        })
        .await;
        assert_eq!(robot.program_restarts(), 1);
        assert_eq!(emu.with_sim(|b| b.program_running()), Some(true));
        // Without a program port there is nothing to restart.
        let mut cfg = RtdeRobotConfig::new("127.0.0.1");
        cfg.port = emu.rtde_addr().port();
        cfg.registers.int_base = 30;
        cfg.registers.double_base = 0;
        let other = RtdeRobot::connect(cfg).await.unwrap();
        assert!(!other.restart_program());
        assert!(matches!(
            other.start_program().await,
            Err(RobotIoError::InvalidConfig { .. })
        ));
    })
    .await
    .expect("test timed out");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_shut_down_emulator_refuses_the_reconnection() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let (emu, mut robot) = setup().await;
        let mut s = RobotState::default();
        robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        emu.shutdown();
        emu.shutdown(); // idempotent
        // The link goes down and stays down: reads fail, nothing arrives.
        for _ in 0..5000 {
            if robot.client().link_state() != LinkState::Up {
                break;
            }
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
        assert_eq!(robot.client().link_state(), LinkState::Reconnecting);
        assert!(matches!(
            robot.read_state(&mut s),
            Err(RobotIoError::LinkDown { .. })
        ));
        tokio::time::sleep(Duration::from_millis(300)).await;
        assert_eq!(robot.client().link_state(), LinkState::Reconnecting);
        assert_eq!(robot.client().reconnects(), 0);
    })
    .await
    .expect("test timed out");
}
