//! `Controller::step` allocates nothing: a counting global allocator (per thread) over a whole
//! closed-loop handover on `SimRobot`, with a SIMULATED hand that intrudes during the approach
//! (speed scaling active) and then reaches the presented TCP.

use adapt::controller::{Controller, ControllerConfig, MotionAdaptation, OperatorView};
use adapt::task::Phase;
use hrc_adapt_tests::alloc_count::{CountingAllocator, allocations_in};
use robot_io::geometry::HumanBody;
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Robot, RobotState};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn step_allocates_nothing_over_a_whole_handover() {
    let cfg = ControllerConfig::example();
    let mut robot = SimRobot::new(SimConfig {
        initial_q_rad: cfg.task.home_q_rad,
        ..SimConfig::ur5e()
    })
    .unwrap();
    let mut ctl = Controller::new(cfg).unwrap();
    let mut state = RobotState::default();
    let mut cmd = JointCommand::Stop { decel: 1.0 };
    let adaptation = MotionAdaptation {
        min_approach_duration: std::time::Duration::from_secs(2),
        ..MotionAdaptation::default()
    };
    // The SIMULATED hand rests 0.79 m from the handover pose (outside the planner's protective
    // distance at rest) and intrudes into the approach path for 1 s (tests/controller.rs).
    let (home, intrusion) = ([-1.45, -0.45, 0.2], [-1.15, -0.3, 0.25]);
    let mut hand: [f64; 3] = home;
    let mut approach_cycles = 0u32;
    ctl.start_handover();

    let (mut steps, mut step_allocs, mut phases) = (0u64, 0u64, vec![ctl.phase()]);
    phases.reserve(16);
    while ctl.phase() != Phase::Done {
        assert!(steps < 20_000, "no Done: {phases:?}");
        robot.read_state(&mut state).unwrap();
        let tcp = state.actual_tcp_pose;
        let goal = match ctl.phase() {
            Phase::Approach => {
                approach_cycles += 1;
                let t = f64::from(approach_cycles) * 0.002;
                if (0.3..1.3).contains(&t) {
                    intrusion
                } else {
                    home
                }
            }
            Phase::Present => [tcp[0] - 0.03, tcp[1], tcp[2]],
            _ => home,
        };
        for (h, g) in hand.iter_mut().zip(goal) {
            *h += (g - *h).clamp(-0.002, 0.002);
        }
        let humans = OperatorView {
            body: HumanBody {
                head_m: Some([-1.6, -0.6, 0.6]),
                left_hand_m: None,
                right_hand_m: Some(hand),
                torso: None,
            },
            perception_age_s: 0.0,
        };
        let ((), n) =
            allocations_in(|| ctl.step(state.timestamp_s, &state, &adaptation, &humans, &mut cmd));
        step_allocs += n;
        steps += 1;
        if phases.last() != Some(&ctl.phase()) {
            phases.push(ctl.phase());
        }
        robot.send(&cmd).unwrap();
        robot.step();
    }
    assert!(ctl.stats().scaled_steps > 0, "speed scaling was exercised");
    assert!(phases.contains(&Phase::Release));
    assert_eq!(step_allocs, 0, "allocations in {steps} steps");
    eprintln!("{steps} steps, 0 allocations; {:?}", ctl.stats());
}
