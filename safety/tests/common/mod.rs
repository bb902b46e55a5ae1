//! Test robots: a scripted kinematic mock and a shared handle on `SimRobot`.
#![allow(dead_code, unreachable_pub, missing_docs)]

use std::cell::RefCell;
use std::f64::consts::FRAC_PI_2;
use std::rc::Rc;

use robot_io::geometry::{ARM_CAPSULES, ArmModel, Capsule};
use robot_io::sim::SimRobot;
use robot_io::{JointCommand, Joints, Robot, RobotIoError, RobotState};
use safety::points::arm_points;

/// A work pose in front of the base: TCP about 0.5 m out, 0.4 m up.
pub const Q_WORK: Joints = [0.0, -1.2, 1.5, -1.87, -FRAC_PI_2, 0.0];
pub const DT: f64 = 0.002;

/// The mock's inner state, shared with the test.
#[derive(Debug)]
pub struct MockInner {
    pub state: RobotState,
    /// Do not advance the timestamp on reads.
    pub freeze: bool,
    /// Fail every send.
    pub fail_send: bool,
    pub sent: Vec<JointCommand>,
}

/// A kinematic robot: servo targets are reached in one cycle, speedj velocities are applied
/// at once, stops are instantaneous. Reads advance the timestamp by 2 ms.
#[derive(Debug, Clone)]
pub struct MockRobot(pub Rc<RefCell<MockInner>>);

impl MockRobot {
    pub fn at(q: Joints) -> (MockRobot, Rc<RefCell<MockInner>>) {
        let state = RobotState {
            actual_q: q,
            target_q: q,
            actual_tcp_pose: tcp_pose(&q),
            ..RobotState::default()
        };
        let inner = Rc::new(RefCell::new(MockInner {
            state,
            freeze: false,
            fail_send: false,
            sent: Vec::new(),
        }));
        (MockRobot(inner.clone()), inner)
    }
}

fn tcp_pose(q: &Joints) -> [f64; 6] {
    let p = arm_points(q).tcp;
    [p[0], p[1], p[2], 0.0, 0.0, 0.0]
}

impl Robot for MockRobot {
    fn read_state(&mut self, out: &mut RobotState) -> robot_io::Result<()> {
        let mut inner = self.0.borrow_mut();
        if !inner.freeze {
            inner.state.timestamp_s += DT;
        }
        *out = inner.state;
        Ok(())
    }

    fn send(&mut self, cmd: &JointCommand) -> robot_io::Result<()> {
        let mut inner = self.0.borrow_mut();
        if inner.fail_send {
            return Err(RobotIoError::InvalidCommand {
                reason: "mock refuses",
            });
        }
        inner.sent.push(*cmd);
        let s = &mut inner.state;
        let before = arm_points(&s.actual_q).tcp;
        match *cmd {
            JointCommand::Servo { q, .. } => {
                let mut qd = [0.0; 6];
                for ((v, a), b) in qd.iter_mut().zip(&q).zip(&s.actual_q) {
                    *v = (a - b) / DT;
                }
                s.actual_q = q;
                s.target_q = q;
                s.actual_qd = qd;
                s.target_qd = qd;
            }
            JointCommand::Speed { qd, .. } => {
                for (q, v) in s.actual_q.iter_mut().zip(&qd) {
                    *q += v * DT;
                }
                s.target_q = s.actual_q;
                s.actual_qd = qd;
                s.target_qd = qd;
            }
            JointCommand::Stop { .. } => {
                s.actual_qd = [0.0; 6];
                s.target_qd = [0.0; 6];
                s.target_q = s.actual_q;
            }
        }
        let after = arm_points(&s.actual_q).tcp;
        s.actual_tcp_pose = tcp_pose(&s.actual_q);
        for k in 0..3 {
            s.actual_tcp_speed[k] = (after[k] - before[k]) / DT;
        }
        Ok(())
    }
}

/// A `SimRobot` the test can still step and inject faults into.
#[derive(Debug, Clone)]
pub struct SharedSim(pub Rc<RefCell<SimRobot>>);

impl Robot for SharedSim {
    fn read_state(&mut self, out: &mut RobotState) -> robot_io::Result<()> {
        self.0.borrow_mut().read_state(out)
    }

    fn send(&mut self, cmd: &JointCommand) -> robot_io::Result<()> {
        self.0.borrow_mut().send(cmd)
    }
}

pub fn servo(q: Joints) -> JointCommand {
    JointCommand::Servo {
        q,
        lookahead_s: 0.05,
        gain: 500.0,
    }
}

/// The arm's capsules at `q` [rad] (base frame [m]).
pub fn capsules(arm: &ArmModel, q: &Joints) -> [Capsule; ARM_CAPSULES] {
    let mut out = [Capsule::point([0.0; 3], 0.0); ARM_CAPSULES];
    arm.capsules(q, &mut out);
    out
}

/// The point on the tool axis `clearance_m` [m] beyond the surface of the carried part's
/// capsule (past its far end), at joints `q` [rad].
pub fn beyond_part(arm: &ArmModel, q: &Joints, clearance_m: f64) -> [f64; 3] {
    let part = capsules(arm, q)[robot_io::geometry::ArmLink::Part.index()];
    let axis: Vec<f64> = (0..3).map(|k| part.b_m[k] - part.a_m[k]).collect();
    let len = norm3(&axis);
    let out = part.radius_m + clearance_m;
    std::array::from_fn(|k| part.b_m[k] + axis[k] / len * out)
}

pub fn norm3(v: &[f64]) -> f64 {
    v.iter().take(3).map(|x| x * x).sum::<f64>().sqrt()
}

/// Instantaneous TCP speed for joint velocity `v` at `q` [m/s] (finite difference).
pub fn tcp_speed(q: &Joints, v: &Joints) -> f64 {
    let h = 1e-7;
    let mut q2 = *q;
    for (a, b) in q2.iter_mut().zip(v) {
        *a += b * h;
    }
    let a = arm_points(q).tcp;
    let b = arm_points(&q2).tcp;
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt() / h
}

/// An upstream planner for the tests: drives the base joint towards `target_speed` [rad/s]
/// at `acc` [rad/s²] and integrates servo targets.
#[derive(Debug, Clone, Copy)]
pub struct BaseRamp {
    pub q: Joints,
    pub speed: f64,
    pub target_speed: f64,
    pub acc: f64,
}

impl BaseRamp {
    pub fn new(q: Joints, target_speed: f64, acc: f64) -> Self {
        Self {
            q,
            speed: 0.0,
            target_speed,
            acc,
        }
    }

    pub fn next(&mut self) -> JointCommand {
        let dv = (self.target_speed - self.speed).clamp(-self.acc * DT, self.acc * DT);
        self.speed += dv;
        self.q[0] += self.speed * DT;
        servo(self.q)
    }
}
