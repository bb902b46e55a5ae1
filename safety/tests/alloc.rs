//! `Supervisor::read_state` and `Supervisor::step` allocate nothing (the control thread's
//! rule), whatever the verdict: pass, reduce, stop, halt.
//!
//! A counting global allocator wraps `System`; the switch and the counter are thread-local,
//! so tests running in parallel do not disturb each other.

mod common;

use std::cell::RefCell;
use std::rc::Rc;

use common::{BaseRamp, Q_WORK, SharedSim, servo};
use hrc_adapt_tests::alloc_count::{CountingAllocator, allocations_in};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, RobotState};
use safety::{Supervisor, SupervisorConfig, WorldView};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn step_allocates_nothing() {
    let mut config = SimConfig::ur5e();
    config.initial_q_rad = Q_WORK;
    let sim = Rc::new(RefCell::new(SimRobot::new(config).unwrap()));
    let mut sup = Supervisor::new(SharedSim(sim.clone()), SupervisorConfig::ur5e()).unwrap();
    let mut state = RobotState::default();
    let mut plan = BaseRamp::new(Q_WORK, 0.8, 3.0);
    let hand = robot_io::sim::ur5e_tcp_pose(&Q_WORK);
    let mut nan = Q_WORK;
    nan[0] = f64::NAN;
    let cycles = 10_000;
    let mut verdicts = [0u64; 4];
    let ((), n) = allocations_in(|| {
        for k in 0..cycles {
            let t = k as f64 * 0.002;
            let mut world = WorldView::clear(t);
            let cmd = match k {
                // Pass, reduce (stale perception), stop (NaN, separation, stale perception),
                // halt (protective stop) and reset.
                0..2000 => plan.next(),
                2000..2500 => {
                    world.perception_age_s = 0.5;
                    plan.next()
                }
                2500..2600 => servo(nan),
                2600..2700 => {
                    world.human.left_hand_m = Some([hand[0], hand[1], hand[2]]);
                    world.human.torso = Some(safety::Torso {
                        shoulder_mid_m: [hand[0], hand[1], hand[2] + 0.5],
                        normal: [1.0, 0.0, 0.0],
                    });
                    plan.next()
                }
                2700..2800 => {
                    world.perception_age_s = 2.0;
                    plan.next()
                }
                _ => JointCommand::Stop { decel: 3.0 },
            };
            if k == 3000 {
                sim.borrow_mut().inject_protective_stop();
            }
            if k == 4000 {
                sim.borrow_mut().clear_protective_stop();
            }
            if k == 4100 {
                let _ = sup.reset();
            }
            let _ = sup.read_state(&mut state);
            let v = sup.step(&cmd, &world);
            let slot = match v {
                safety::Verdict::Passed => 0,
                safety::Verdict::Reduced { .. } => 1,
                safety::Verdict::Stopped { .. } => 2,
                safety::Verdict::Halted { .. } => 3,
            };
            if let Some(c) = verdicts.get_mut(slot) {
                *c += 1;
            }
            sim.borrow_mut().step();
        }
    });
    println!("allocations over {cycles} cycles: {n}; verdicts pass/reduce/stop/halt: {verdicts:?}");
    assert_eq!(n, 0);
    assert!(verdicts.iter().all(|&c| c > 0), "{verdicts:?}");
}
