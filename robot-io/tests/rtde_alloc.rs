//! `RtdeRobot::read_state` and `send` allocate nothing, connected to the emulator over loopback
//! TCP and while the link is down; neither do `RtdeClient::try_recv`, `try_latest` and
//! `send_inputs` once the client is closed for good (the control thread's rule).
//!
//! A counting global allocator wraps `System`. The switch and the counter are thread-local:
//! only the test's own thread is counted, while the emulator and the client's reader, writer
//! and reconnect tasks run (and allocate as they please) on a tokio runtime's worker threads.
//! Each test is bounded in time (the loops are bounded, the awaits have timeouts).

mod common;

use std::time::{Duration, Instant};

use hrc_adapt_tests::alloc_count::{CountingAllocator, allocations_in};
use robot_io::client::{ClientConfig, LinkState, RtdeClient};
use robot_io::codec::Value;
use robot_io::emulator::{Emulator, EmulatorConfig};
use robot_io::rtde_robot::{RtdeRobot, RtdeRobotConfig};
use robot_io::{JointCommand, Robot, RobotIoError, RobotState};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

/// A runtime whose workers run the emulator and the client; the test thread only calls the
/// synchronous hot-path methods (and `block_on` outside the counted sections).
fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

async fn sim_emulator() -> Emulator {
    common::sim_emulator(EmulatorConfig::ephemeral()).await
}

/// Polls `cond` every millisecond for at most `limit`.
fn wait_until(limit: Duration, what: &str, mut cond: impl FnMut() -> bool) {
    let deadline = Instant::now() + limit;
    while !cond() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn the_counter_sees_allocations() {
    let (v, n) = allocations_in(|| Vec::<u64>::with_capacity(16));
    std::hint::black_box(v);
    assert_eq!(n, 1);
}

#[test]
fn rtde_robot_read_state_and_send_allocate_nothing_connected_and_link_down() {
    let rt = runtime();
    let emu = rt.block_on(sim_emulator());
    let mut cfg = RtdeRobotConfig::new("127.0.0.1");
    cfg.port = emu.rtde_addr().port();
    // Two shared cores: a generous link-loss floor so a scheduling hiccup is no link loss.
    cfg.link_loss_min = Duration::from_secs(3);
    let mut robot = rt.block_on(RtdeRobot::connect(cfg)).unwrap();
    let mut state = RobotState::default();
    rt.block_on(robot.wait_state(&mut state, Duration::from_secs(5)))
        .unwrap();
    let commands = [
        JointCommand::Speed {
            qd: [0.1, 0.0, 0.0, 0.0, 0.0, 0.0],
            acc: 1.0,
        },
        JointCommand::Servo {
            q: [0.0, -1.57, 1.57, -1.57, -1.57, 0.0],
            lookahead_s: 0.1,
            gain: 300.0,
        },
        JointCommand::Stop { decel: 2.0 },
    ];
    // Warm up (first uses of thread-locals and the like), outside the count.
    for cmd in &commands {
        robot.read_state(&mut state).unwrap();
        robot.send(cmd).unwrap();
    }

    // Connected: 500 cycles of 2 ms, the control thread's loop.
    let t0 = state.timestamp_s;
    let (ok_reads, n) = allocations_in(|| {
        let mut ok = 0u32;
        for cycle in 0..500_usize {
            if robot.read_state(&mut state).is_ok() {
                ok += 1;
            }
            if let Some(cmd) = commands.get(cycle / 100 % 3) {
                let _ = robot.send(cmd);
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        ok
    });
    assert_eq!(n, 0, "allocations over 500 connected cycles");
    assert_eq!(ok_reads, 500, "every read while connected succeeds");
    assert!(
        state.timestamp_s > t0 + 0.1,
        "no new samples while connected: {t0} -> {}",
        state.timestamp_s
    );

    // Link down: the emulator goes away; the client keeps trying to reconnect.
    emu.shutdown();
    drop(emu);
    wait_until(Duration::from_secs(10), "the link to go down", || {
        robot.client().link_state() != LinkState::Up
    });
    let ((down, other), n) = allocations_in(|| {
        let (mut down, mut other) = (0u32, 0u32);
        for cycle in 0..200_usize {
            match robot.read_state(&mut state) {
                Err(RobotIoError::LinkDown { .. }) => down += 1,
                _ => other += 1,
            }
            if let Some(cmd) = commands.get(cycle % 3) {
                let _ = robot.send(cmd);
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        (down, other)
    });
    assert_eq!(n, 0, "allocations over 200 cycles with the link down");
    assert_eq!((down, other), (200, 0), "read_state reports the link down");
    assert_eq!(robot.client().link_state(), LinkState::Reconnecting);
    drop(robot);
    rt.shutdown_timeout(Duration::from_secs(2));
}

#[test]
fn a_closed_client_reports_without_allocating() {
    let rt = runtime();
    let emu = rt.block_on(sim_emulator());
    let mut cfg = ClientConfig::new("127.0.0.1", &["timestamp", "actual_q"]);
    cfg.port = emu.rtde_addr().port();
    cfg.frequency_hz = 125.0;
    cfg.input_recipes = vec![vec!["input_int_register_24".to_owned()]];
    cfg.reconnect = false;
    let mut client = rt.block_on(RtdeClient::connect(cfg)).unwrap();
    let mut buf = client.output_buffer();
    rt.block_on(async {
        client.start().await.unwrap();
        client
            .recv_timeout(&mut buf, Duration::from_secs(5))
            .await
            .unwrap();
    });
    let values = [Value::Int32(7)];
    client.send_inputs(0, &values).unwrap();
    emu.cut_rtde_links();
    wait_until(Duration::from_secs(10), "the client to close", || {
        client.link_state() == LinkState::Closed
    });
    let (closed, n) = allocations_in(|| {
        let mut closed = 0u32;
        for _ in 0..100 {
            // Drain what was received before the cut, then the closed error.
            while let Ok(Some(_)) = client.try_recv(&mut buf) {}
            if matches!(
                client.try_recv(&mut buf),
                Err(RobotIoError::LinkClosed { .. })
            ) {
                closed += 1;
            }
            if matches!(
                client.try_latest(&mut buf),
                Err(RobotIoError::LinkClosed { .. })
            ) {
                closed += 1;
            }
            if matches!(
                client.send_inputs(0, &values),
                Err(RobotIoError::LinkClosed { .. })
            ) {
                closed += 1;
            }
        }
        closed
    });
    assert_eq!(n, 0, "allocations reporting a closed client");
    assert_eq!(closed, 300);
    let e = client.try_recv(&mut buf).unwrap_err();
    assert!(
        e.to_string().contains("reconnecting disabled"),
        "the reason names the cause: {e}"
    );
    drop(client);
    drop(emu);
    rt.shutdown_timeout(Duration::from_secs(2));
}
