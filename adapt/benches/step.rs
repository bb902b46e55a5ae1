//! Benchmark of one `Controller::step` (task + path + time scaling with its lookahead + bookkeeping) over a whole simulated
//! handover with a SIMULATED hand intruding during the approach (so the time scaling is active part of
//! the time) and reaching the presented TCP.
//!
//! Criterion measures the mean cost of a step; a second pass times every single step of whole
//! handovers with `Instant` and prints the median, p99 and worst against the 2 ms budget
//! (target: p99 < 200 µs). Run with `cargo bench -p adapt --bench step`.

use std::hint::black_box;
use std::time::Instant;

use adapt::controller::{Controller, ControllerConfig, MotionAdaptation, OperatorView};
use adapt::task::Phase;
use criterion::{Criterion, criterion_group, criterion_main};
use robot_io::geometry::HumanBody;
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Robot, RobotState};

const DT: f64 = 0.002;
const HAND_HOME: [f64; 3] = [-1.25, -0.13, 0.2];
const INTRUSION: [f64; 3] = [-0.97, -0.13, 0.25];

/// One closed-loop handover world: robot, controller and the SIMULATED hand.
struct World {
    robot: SimRobot,
    ctl: Controller,
    state: RobotState,
    cmd: JointCommand,
    adaptation: MotionAdaptation,
    hand: [f64; 3],
    approach_cycles: u32,
}

impl World {
    fn new() -> World {
        let cfg = ControllerConfig::example();
        let robot = SimRobot::new(SimConfig {
            initial_q_rad: cfg.task.home_q_rad,
            ..SimConfig::ur5e()
        })
        .expect("sim");
        let mut ctl = Controller::new(cfg).expect("controller");
        ctl.start_handover();
        World {
            robot,
            ctl,
            state: RobotState::default(),
            cmd: JointCommand::Stop { decel: 1.0 },
            adaptation: MotionAdaptation::default(),
            hand: HAND_HOME,
            approach_cycles: 0,
        }
    }

    fn move_hand(&mut self, goal: [f64; 3], speed: f64) {
        let d = ((self.hand[0] - goal[0]).powi(2)
            + (self.hand[1] - goal[1]).powi(2)
            + (self.hand[2] - goal[2]).powi(2))
        .sqrt();
        let step = speed * DT;
        if d <= step {
            self.hand = goal;
        } else {
            for (h, g) in self.hand.iter_mut().zip(goal) {
                *h += (g - *h) * step / d;
            }
        }
    }

    /// Everything around the step: read state, script the hand.
    fn prepare(&mut self) -> OperatorView {
        self.robot.read_state(&mut self.state).expect("read");
        let tcp = self.state.actual_tcp_pose;
        match self.ctl.phase() {
            Phase::Approach => {
                self.approach_cycles += 1;
                let t = f64::from(self.approach_cycles) * DT;
                if (0.4..1.9).contains(&t) {
                    self.move_hand(INTRUSION, 1.0);
                } else {
                    self.move_hand(HAND_HOME, 1.0);
                }
            }
            Phase::Present => self.move_hand([tcp[0] - 0.03, tcp[1], tcp[2]], 0.5),
            _ => self.move_hand(HAND_HOME, 0.5),
        }
        OperatorView {
            body: HumanBody {
                head_m: Some([-1.45, -0.13, 0.75]),
                left_hand_m: None,
                right_hand_m: Some(self.hand),
                torso: None,
            },
            perception_age_s: 0.0,
        }
    }

    fn step(&mut self, humans: &OperatorView) {
        self.ctl.step(
            self.state.timestamp_s,
            &self.state,
            &self.adaptation,
            humans,
            &mut self.cmd,
        );
    }

    fn finish(&mut self) -> bool {
        self.robot.send(&self.cmd).expect("send");
        self.robot.step();
        self.ctl.phase() == Phase::Done
    }
}

fn bench_step(c: &mut Criterion) {
    // Criterion: the step alone, cycling through whole handovers.
    let mut world = World::new();
    c.bench_function("controller_step_handover", |b| {
        b.iter_custom(|iters| {
            let mut total = std::time::Duration::ZERO;
            for _ in 0..iters {
                let humans = world.prepare();
                let t0 = Instant::now();
                world.step(black_box(&humans));
                total += t0.elapsed();
                if world.finish() {
                    world = World::new();
                }
            }
            total
        })
    });

    // Single steps timed over whole handovers: median, p99, worst.
    let runs: usize = std::env::var("STEP_BENCH_HANDOVERS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    let mut times_ns: Vec<u64> = Vec::with_capacity(runs * 10_000);
    let mut scaled = 0;
    for _ in 0..runs {
        let mut w = World::new();
        for _ in 0..20_000 {
            let humans = w.prepare();
            let t0 = Instant::now();
            w.step(black_box(&humans));
            times_ns.push(t0.elapsed().as_nanos() as u64);
            if w.finish() {
                break;
            }
        }
        scaled += w.ctl.stats().scaled_steps;
    }
    times_ns.sort_unstable();
    let pick = |q: f64| times_ns[((times_ns.len() - 1) as f64 * q).round() as usize] as f64 / 1e3;
    let over = times_ns.iter().filter(|&&t| t > 200_000).count();
    println!(
        "controller step over {runs} handovers ({} steps, {scaled} with speed scaling active): \
         median {:.1} µs, p99 {:.1} µs, p99.9 {:.1} µs, worst {:.1} µs, {over} steps > 200 µs \
         (budget 2000 µs, target p99 < 200 µs)",
        times_ns.len(),
        pick(0.5),
        pick(0.99),
        pick(0.999),
        pick(1.0),
    );
}

criterion_group!(benches, bench_step);
criterion_main!(benches);
