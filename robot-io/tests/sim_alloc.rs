//! `SimRobot::read_state`, `send` and `step`, and `ReplayRobot::read_state` and `send`, allocate
//! nothing (the control thread's rule).
//!
//! A counting global allocator wraps `System`. The switch and the counter are thread-local, so
//! only the thread under test is counted and tests running in parallel do not disturb it.

use hrc_adapt_tests::alloc_count::{CountingAllocator, allocations_in};
use robot_io::replay::{Pacing, ReplayRobot};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::trace::Trace;
use robot_io::{JointCommand, Robot, RobotState};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn the_counter_sees_allocations() {
    let ((), n) = allocations_in(|| {
        let v: Vec<u64> = Vec::with_capacity(16);
        std::hint::black_box(v);
    });
    assert_eq!(n, 1);
}

#[test]
fn sim_robot_cycles_allocate_nothing() {
    let mut robot = SimRobot::new(SimConfig::ur5e()).unwrap();
    let mut state = RobotState::default();
    let commands = [
        JointCommand::Speed {
            qd: [0.4, -0.3, 0.2, 0.1, -0.1, 0.2],
            acc: 1.5,
        },
        JointCommand::Stop { decel: 2.0 },
        JointCommand::Servo {
            q: [0.3, -1.2, 0.4, -1.5, 0.2, 0.1],
            lookahead_s: 0.1,
            gain: 300.0,
        },
    ];
    let ((), n) = allocations_in(|| {
        for cycle in 0..10_000_usize {
            robot.read_state(&mut state).unwrap();
            let cmd = commands.get(cycle / 1000 % 3).unwrap();
            robot.send(cmd).unwrap();
            match cycle {
                2_500 => robot.inject_dropped_cycles(5),
                4_000 => robot.inject_protective_stop(),
                4_500 => {
                    robot.clear_protective_stop();
                    robot.play();
                }
                6_000 => robot.set_speed_scaling(0.5).unwrap(),
                _ => {}
            }
            robot.step();
        }
    });
    assert_eq!(n, 0, "allocations over 10 000 cycles");
    // The loop really ran the model (simulated data).
    assert!((state.timestamp_s - 19.998).abs() < 1e-9);
    assert!(robot.ignored_commands() > 0);
}

#[test]
fn replay_robot_reads_and_sends_allocate_nothing() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../data/rtde-traces/ur3e_25hz_rad_segment_L1L2.csv"
    );
    let trace = Trace::read(path).unwrap();
    let rows = trace.len();
    let mut per_read = ReplayRobot::with_pacing(trace.clone(), Pacing::PerRead, 16).unwrap();
    let mut clocked =
        ReplayRobot::with_pacing(trace, Pacing::Clocked { period_s: 0.002 }, 16).unwrap();
    let mut state = RobotState::default();
    let cmd = JointCommand::Stop { decel: 1.0 };
    let mut clocked_reads = 0;
    let ((), n) = allocations_in(|| {
        for _ in 0..rows {
            per_read.read_state(&mut state).unwrap();
            per_read.send(&cmd).unwrap();
        }
        while clocked.read_state(&mut state).is_ok() {
            clocked.send(&cmd).unwrap();
            clocked_reads += 1;
        }
    });
    assert_eq!(n, 0);
    assert!(clocked_reads > 20 * (rows - 1), "{clocked_reads}");
    assert_eq!(per_read.commands().len(), 16);
}
