//! The ur_rtde backend (feature `ur-rtde`) against the emulator over loopback.
//!
//! ur_rtde's ports are fixed (RTDE 30004, dashboard 29999, script 30002/30003), so each test
//! binds its emulator to its own loopback address (127.0.0.0/8 all reaches this host on
//! Linux). Timeouts only bound a wait; no assertion depends on wall-clock speed.

use std::net::{IpAddr, Ipv4Addr};
use std::time::{Duration, Instant};

use hrc_adapt_tests::alloc_count::{CountingAllocator, allocations_in};
use robot_io::emulator::{Emulator, EmulatorConfig, SimBackend};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{
    JointCommand, Robot, RobotIoError, RobotState, UrRtdeConfig, UrRtdeReceiver, UrRtdeRobot,
    robot_mode, safety_mode,
};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

/// Every wait is bounded by this.
const WAIT: Duration = Duration::from_secs(20);

/// An emulator with ur_rtde's fixed ports on 127.0.0.`last`, over a simulated UR5e.
fn emulator(rt: &tokio::runtime::Runtime, last: u8) -> Emulator {
    let cfg = EmulatorConfig {
        bind: IpAddr::V4(Ipv4Addr::new(127, 0, 0, last)),
        rtde_port: 30004,
        dashboard_port: 29999,
        secondary_port: 30002,
        realtime_port: 30003,
        ..EmulatorConfig::default()
    };
    let robot = SimRobot::new(SimConfig::ur5e()).unwrap();
    rt.block_on(Emulator::start(cfg, Box::new(SimBackend::new(robot))))
        .unwrap()
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

/// Reads until `pred` holds for a state, or `WAIT` passes (then panics with the last state).
fn read_until(
    rx: &mut UrRtdeReceiver,
    what: &str,
    mut pred: impl FnMut(&RobotState) -> bool,
) -> RobotState {
    let mut s = RobotState::default();
    let end = Instant::now() + WAIT;
    loop {
        rx.read(&mut s).unwrap();
        if pred(&s) {
            return s;
        }
        assert!(
            Instant::now() < end,
            "{what}: not seen in {WAIT:?}; last {s:?}"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn receive_reads_the_emulated_state() {
    let rt = runtime();
    let emu = emulator(&rt, 2);
    let mut rx = UrRtdeReceiver::connect(&UrRtdeConfig::new("127.0.0.2")).unwrap();
    assert!(rx.is_connected());
    let first = read_until(&mut rx, "a sample", |s| s.timestamp_s > 0.0);
    let later = read_until(&mut rx, "a later sample", |s| {
        s.timestamp_s > first.timestamp_s
    });
    assert!(later.timestamp_s > first.timestamp_s);
    // The simulated arm rests at its home pose: ur_rtde reads what the emulator publishes.
    let published = emu.with_backend(|b| {
        b.as_any_mut()
            .downcast_mut::<SimBackend>()
            .map(|sb| *sb.published())
    });
    let home = SimConfig::ur5e().initial_q_rad;
    for (j, (got, want)) in later.actual_q.iter().zip(home).enumerate() {
        assert!((got - want).abs() < 1e-9, "joint {j}: {got} vs home {want}");
    }
    let published = published.expect("the backend is a SimBackend");
    assert_eq!(published.actual_q, later.actual_q);
    assert_eq!(later.robot_mode, robot_mode::RUNNING);
    assert_eq!(later.safety_mode, safety_mode::NORMAL);
    assert!(!later.is_safety_stopped());
    drop(rx);
    emu.shutdown();
}

#[test]
fn nothing_listening_is_connection_refused() {
    // 127.0.0.9 has no emulator (no other test uses it).
    match UrRtdeReceiver::connect(&UrRtdeConfig::new("127.0.0.9")) {
        Err(RobotIoError::ConnectionRefused { addr }) => assert!(addr.contains("127.0.0.9")),
        Err(e) => panic!("expected ConnectionRefused, got {e}"),
        Ok(_) => panic!("connected to nothing"),
    }
}

#[test]
fn bad_config_is_an_error_not_a_crash() {
    let mut cfg = UrRtdeConfig::new("127.0.0.9");
    cfg.frequency_hz = f64::NAN;
    assert!(matches!(
        UrRtdeReceiver::connect(&cfg),
        Err(RobotIoError::InvalidConfig { .. })
    ));
    let cfg = UrRtdeConfig::new("127.0.0.9\0x");
    assert!(matches!(
        UrRtdeReceiver::connect(&cfg),
        Err(RobotIoError::InvalidConfig { .. })
    ));
}

#[test]
fn link_loss_is_an_error() {
    let rt = runtime();
    let emu = emulator(&rt, 3);
    let mut rx = UrRtdeReceiver::connect(&UrRtdeConfig::new("127.0.0.3")).unwrap();
    read_until(&mut rx, "a sample", |s| s.timestamp_s > 0.0);
    emu.shutdown();
    drop(emu);
    drop(rt);
    let mut s = RobotState::default();
    let end = Instant::now() + WAIT;
    let err = loop {
        match rx.read(&mut s) {
            Ok(()) => {
                assert!(
                    Instant::now() < end,
                    "the link loss was not reported in {WAIT:?}"
                );
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(e) => break e,
        }
    };
    assert!(
        matches!(
            err,
            RobotIoError::LinkDown { .. } | RobotIoError::UrRtde { .. }
        ),
        "{err}"
    );
    assert!(!rx.is_connected());
}

#[test]
fn protective_stop_is_seen() {
    let rt = runtime();
    let emu = emulator(&rt, 4);
    let mut rx = UrRtdeReceiver::connect(&UrRtdeConfig::new("127.0.0.4")).unwrap();
    let s = read_until(&mut rx, "a sample", |s| s.timestamp_s > 0.0);
    assert!(!s.is_safety_stopped());
    let injected = emu.with_backend(|b| {
        b.as_any_mut()
            .downcast_mut::<SimBackend>()
            .map(|sb| sb.robot_mut().inject_protective_stop())
            .is_some()
    });
    assert!(injected, "the backend is a SimBackend");
    let s = read_until(
        &mut rx,
        "the protective stop",
        RobotState::is_safety_stopped,
    );
    assert_eq!(s.safety_mode, safety_mode::PROTECTIVE_STOP);
    drop(rx);
    emu.shutdown();
}

/// The emulator runs ur_rtde's control script (`robot_io::emulator::ur_rtde_control`):
/// RTDEControlInterface uploads it, and servoJ through our shim moves the simulated arm.
#[test]
fn servo_j_moves_the_emulated_arm() {
    let rt = runtime();
    let emu = emulator(&rt, 5);
    let mut robot = UrRtdeRobot::connect(&UrRtdeConfig::new("127.0.0.5")).unwrap();
    assert!(robot.is_connected());
    let mut s = RobotState::default();
    robot.read_state(&mut s).unwrap();
    let mut target = s.actual_q;
    target[0] += 0.05;
    let end = Instant::now() + WAIT;
    loop {
        let t = robot.init_period().unwrap();
        robot
            .send(&JointCommand::Servo {
                q: target,
                lookahead_s: 0.1,
                gain: 300.0,
            })
            .unwrap();
        robot.read_state(&mut s).unwrap();
        if (s.actual_q[0] - target[0]).abs() < 1e-3 {
            break;
        }
        assert!(
            Instant::now() < end,
            "servoJ did not reach the target: {s:?}"
        );
        robot.wait_period(t).unwrap();
    }
    robot.send(&JointCommand::Stop { decel: 2.0 }).unwrap();
    drop(robot);
    emu.shutdown();
}

/// The trial's control thread owns its robot: both types move between threads.
#[test]
fn handles_are_send() {
    fn send<T: Send>() {}
    send::<UrRtdeReceiver>();
    send::<UrRtdeRobot>();
}

/// Polls `robot`'s send statistics until every command handed over is accounted for (sent,
/// failed or superseded; none pending), or `WAIT` passes.
fn settled(robot: &UrRtdeRobot) -> robot_io::UrRtdeSendStats {
    let end = Instant::now() + WAIT;
    loop {
        let st = robot.send_stats();
        if st.sent + st.failed + st.superseded == st.handed {
            return st;
        }
        assert!(Instant::now() < end, "commands still pending: {st:?}");
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// The control cycle's part of the ur_rtde backend, `read_state` and `send`, allocates nothing
/// on the control thread (the counting allocator counts this thread only): `send` hands the
/// command to the sender thread, which makes the ur_rtde call (and its 31 C++ allocations).
/// 500 cycles of a servo ramp, paced by ur_rtde's initPeriod/waitPeriod (outside the counted
/// closure); then every command handed over is accounted for, none failed, and the arm
/// followed the ramp. Superseded commands (the sender thread had no time for them) are
/// counted and printed, not judged: they depend on this machine's load.
#[test]
fn the_control_cycle_allocates_nothing_through_the_ur_rtde_backend() {
    let rt = runtime();
    let emu = emulator(&rt, 11);
    let mut robot = UrRtdeRobot::connect(&UrRtdeConfig::new("127.0.0.11")).unwrap();
    let mut s = RobotState::default();
    robot.read_state(&mut s).unwrap();
    let start = s.actual_q;
    let mut target = start;
    let mut allocations = 0;
    for k in 0..500 {
        let t = robot.init_period().unwrap();
        target[0] = start[0] + 0.05 * f64::from(k) / 500.0;
        let cmd = JointCommand::Servo {
            q: target,
            lookahead_s: 0.1,
            gain: 300.0,
        };
        let (r, n) = allocations_in(|| {
            let read = robot.read_state(&mut s);
            (read, robot.send(&cmd))
        });
        r.0.unwrap();
        r.1.unwrap();
        allocations += n;
        robot.wait_period(t).unwrap();
    }
    assert_eq!(allocations, 0, "allocations on the control thread");
    let st = settled(&robot);
    eprintln!("ur_rtde sender over 500 cycles: {st:?}");
    assert_eq!(st.handed, 500);
    assert_eq!(st.failed, 0, "{st:?}");
    assert!(st.sent > 0, "{st:?}");
    // The arm follows the ramp (its last target is 0.05 rad on).
    let s = read_until(robot.receiver(), "the arm following the ramp", |s| {
        (s.actual_q[0] - target[0]).abs() < 1e-3
    });
    assert!(s.actual_q[0] > start[0] + 0.04);
    drop(robot);
    emu.shutdown();
}

/// A ur_rtde call that fails on the sender thread is reported by the next `send` (once, as
/// a structured error), and counted. Here the emulator goes away: the shim refuses commands
/// on a link that is down, or ur_rtde throws on the closed socket.
#[test]
fn a_failed_ur_rtde_call_is_reported_by_the_next_send() {
    let rt = runtime();
    let emu = emulator(&rt, 12);
    let mut robot = UrRtdeRobot::connect(&UrRtdeConfig::new("127.0.0.12")).unwrap();
    let mut s = RobotState::default();
    robot.read_state(&mut s).unwrap();
    let hold = JointCommand::Servo {
        q: s.actual_q,
        lookahead_s: 0.1,
        gain: 300.0,
    };
    robot.send(&hold).unwrap();
    assert_eq!(settled(&robot).failed, 0);
    emu.shutdown();
    drop(emu);
    drop(rt);
    let end = Instant::now() + WAIT;
    let err = loop {
        match robot.send(&hold) {
            Ok(()) => {
                assert!(Instant::now() < end, "no failure reported in {WAIT:?}");
                std::thread::sleep(Duration::from_millis(2));
            }
            Err(e) => break e,
        }
    };
    assert!(
        matches!(
            err,
            RobotIoError::LinkDown { .. } | RobotIoError::UrRtde { .. }
        ),
        "{err}"
    );
    let st = settled(&robot);
    assert!(st.failed >= 1, "{st:?}");
    assert!(!robot.is_connected());
}
