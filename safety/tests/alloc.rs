//! `Supervisor::read_state` and `Supervisor::step` allocate nothing (the control thread's
//! rule), whatever the verdict: pass, reduce, stop, halt.
//!
//! A counting global allocator wraps `System`; the switch and the counter are thread-local,
//! so tests running in parallel do not disturb each other.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::{Cell, RefCell};
use std::rc::Rc;

use common::{BaseRamp, Q_WORK, SharedSim, servo};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, RobotState};
use safety::{Supervisor, SupervisorConfig, WorldView};

struct CountingAllocator;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn note_allocation() {
    if COUNTING.try_with(Cell::get).unwrap_or(false) {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
    }
}

// SAFETY: defers every operation to `System`; only counts.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_allocation();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

fn allocations_in(f: impl FnOnce()) -> u64 {
    let before = ALLOCATIONS.with(Cell::get);
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCATIONS.with(Cell::get) - before
}

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
    let n = allocations_in(|| {
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
                    world.human_points = [None, Some([hand[0], hand[1], hand[2]]), None];
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
