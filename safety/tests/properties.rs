//! Property tests over random commands, robot states and human positions (proptest; cases
//! from `PROPTEST_CASES`, 256 by default).
//!
//! An independent checker re-derives every limit from the configuration and checks each
//! command the robot received.

mod common;

use std::f64::consts::PI;

use common::{DT, MockRobot, Q_WORK, tcp_speed};
use proptest::prelude::*;
use robot_io::geometry::closest_approaches;
use robot_io::{JointCommand, Joints, RobotState, safety_mode};
use safety::points::arm_points;
use safety::separation::{RobotMotion, protective_distance_m};
use safety::{BodyPart, HumanBody, Supervisor, SupervisorConfig, Torso, Verdict, WorldView};

#[derive(Debug, Clone)]
struct Step {
    cmd: JointCommand,
    world: WorldView,
    safety_mode: i32,
    freeze: bool,
    reset: bool,
}

fn joints(range: f64) -> impl Strategy<Value = Joints> {
    prop::array::uniform6(-range..range)
}

fn command() -> impl Strategy<Value = JointCommand> {
    prop_oneof![
        // servo: a small random step, or a random absolute target
        (joints(0.02), 0.03..0.2f64, 100.0..2000.0f64).prop_map(|(dq, lookahead_s, gain)| {
            let mut q = Q_WORK;
            for (a, b) in q.iter_mut().zip(&dq) {
                *a += b;
            }
            JointCommand::Servo {
                q,
                lookahead_s,
                gain,
            }
        }),
        joints(7.0).prop_map(|q| JointCommand::Servo {
            q,
            lookahead_s: 0.1,
            gain: 300.0
        }),
        (joints(5.0), 0.1..10.0f64).prop_map(|(qd, acc)| JointCommand::Speed { qd, acc }),
        (joints(0.3), 0.1..10.0f64).prop_map(|(qd, acc)| JointCommand::Speed { qd, acc }),
        (0.0..10.0f64).prop_map(|decel| JointCommand::Stop { decel }),
        Just(JointCommand::Servo {
            q: [f64::NAN; 6],
            lookahead_s: 0.1,
            gain: 300.0
        }),
    ]
}

fn human() -> impl Strategy<Value = Option<[f64; 3]>> {
    prop_oneof![
        Just(None),
        prop::array::uniform3(-1.5..1.5f64).prop_map(Some),
    ]
}

fn torso() -> impl Strategy<Value = Option<Torso>> {
    prop_oneof![
        Just(None),
        (
            prop::array::uniform3(-1.5..1.5f64),
            prop::array::uniform3(-1.0..1.0f64)
        )
            .prop_map(|(shoulder_mid_m, normal)| Some(Torso {
                shoulder_mid_m,
                normal
            })),
    ]
}

fn step() -> impl Strategy<Value = Step> {
    (
        command(),
        (human(), human(), human(), torso()),
        prop_oneof![3 => 0.0..0.2f64, 1 => 0.0..1.5f64],
        any::<bool>(),
        prop_oneof![10 => Just(safety_mode::NORMAL), 1 => Just(safety_mode::PROTECTIVE_STOP)],
        prop_oneof![10 => Just(false), 1 => Just(true)],
        prop_oneof![5 => Just(false), 1 => Just(true)],
    )
        .prop_map(
            |(cmd, (h, l, r, t), age, collaborating, mode, freeze, reset)| Step {
                cmd,
                world: WorldView {
                    now_s: 0.0,
                    human: HumanBody {
                        head_m: h,
                        left_hand_m: l,
                        right_hand_m: r,
                        torso: t,
                    },
                    perception_age_s: age,
                    collaborating,
                },
                safety_mode: mode,
                freeze,
                reset,
            },
        )
}

/// The checker's own view of the previous servo target and its velocity.
#[derive(Debug, Clone, Copy)]
struct Reference {
    q: Joints,
    v: Joints,
}

fn check_motion(
    cfg: &SupervisorConfig,
    state: &RobotState,
    world: &WorldView,
    reference: Option<Reference>,
    sent: &JointCommand,
) -> Result<Option<Reference>, TestCaseError> {
    let stale = world.perception_age_s > 0.2;
    let scale = if stale { 0.25 } else { 1.0 };
    let tcp_cap = if world.collaborating { 0.25 } else { 1.0 } * scale;
    let tol = 1e-6;
    let (q_from, v, v_prev, next) = match *sent {
        JointCommand::Stop { decel } => {
            prop_assert!(decel.is_finite() && decel >= PI);
            return Ok(None);
        }
        JointCommand::Servo {
            q,
            lookahead_s,
            gain,
        } => {
            prop_assert!((0.03..=0.2).contains(&lookahead_s) && (100.0..=2000.0).contains(&gain));
            let (from, v_prev) = match reference {
                Some(r) => (r.q, r.v),
                None => (state.target_q, state.target_qd),
            };
            let v: Joints = std::array::from_fn(|j| (q[j] - from[j]) / DT);
            for j in 0..6 {
                let acc = (v[j] - v_prev[j]).abs() / DT;
                prop_assert!(acc <= PI * (1.0 + tol), "joint {j} acceleration {acc}");
            }
            (from, v, v_prev, Some(Reference { q, v }))
        }
        JointCommand::Speed { qd, acc } => {
            prop_assert!(acc <= PI + 1e-12 && acc > 0.0);
            (state.actual_q, qd, state.actual_qd, None)
        }
    };
    prop_assert!(v.iter().all(|x| x.is_finite()));
    // Speeds: within the caps, or (servo) decelerating on every joint under the hard limits.
    let decelerating = matches!(sent, JointCommand::Servo { .. })
        && v.iter().zip(&v_prev).all(|(a, b)| a.abs() <= b.abs());
    let (joint_cap, tcp_cap) = if decelerating {
        (PI, 1.0)
    } else {
        (PI * scale, tcp_cap)
    };
    for x in &v {
        prop_assert!(
            x.abs() <= joint_cap * (1.0 + tol),
            "joint speed {x} > {joint_cap}"
        );
    }
    let tcp = tcp_speed(&q_from, &v);
    prop_assert!(tcp <= tcp_cap * (1.0 + 1e-4), "tcp {tcp} > {tcp_cap}");
    // Positions and workspace at the target.
    let q_next: Joints = std::array::from_fn(|j| q_from[j] + v[j] * DT);
    for (j, q) in q_next.iter().enumerate() {
        let (lo, hi) = cfg.joint_limits.allowed(j).unwrap();
        prop_assert!(*q >= lo - 1e-12 && *q <= hi + 1e-12, "joint {j} at {q}");
    }
    for (point, p) in arm_points(&q_next).as_array() {
        prop_assert!(cfg.workspace.contains(&p), "{point:?} at {p:?}");
    }
    // Separation: no tracked body part within the smallest S_p (robot at rest) of any arm
    // capsule now (surface to surface).
    let arm = common::capsules(&cfg.arm, &state.actual_q);
    let near = closest_approaches(&arm, &world.human, &cfg.body);
    for (part, approach) in BodyPart::ALL.iter().zip(near) {
        let Some(a) = approach else { continue };
        let s_min = protective_distance_m(
            &cfg.separation,
            *part,
            RobotMotion::REST,
            world.perception_age_s,
        );
        prop_assert!(
            a.distance_m >= s_min,
            "{} too close to the {}: {:?}",
            part,
            a.link,
            a
        );
    }
    Ok(next)
}

proptest! {
    /// SAF-REQ-001..010 and 012: no command that reaches the robot breaks a limit; while a
    /// stop condition holds, only stops reach it.
    #[test]
    fn saf_req_all_no_command_breaks_a_limit(steps in prop::collection::vec(step(), 1..40)) {
        let cfg = SupervisorConfig::ur5e();
        let (robot, inner) = MockRobot::at(Q_WORK);
        let mut sup = Supervisor::new(robot, cfg).unwrap();
        let mut reference: Option<Reference> = None;
        let mut frozen_cycles = 0u32;
        for s in &steps {
            {
                let mut i = inner.borrow_mut();
                i.state.safety_mode = s.safety_mode;
                i.freeze = s.freeze;
            }
            let mut state = RobotState::default();
            sup.read_state(&mut state).unwrap();
            frozen_cycles = if s.freeze { frozen_cycles + 1 } else { 0 };
            if s.reset {
                let _ = sup.reset();
            }
            let sent_before = inner.borrow().sent.len();
            let verdict = sup.step(&s.cmd, &s.world);
            let sent = *inner.borrow().sent.last().unwrap();
            prop_assert_eq!(inner.borrow().sent.len(), sent_before + 1);
            let must_stop = s.safety_mode != safety_mode::NORMAL
                || s.world.perception_age_s > 1.0
                || frozen_cycles > 3
                || sup.latched().is_some();
            if must_stop {
                prop_assert!(verdict.is_stop(), "{:?}", verdict);
            }
            if verdict.is_stop() {
                prop_assert!(matches!(sent, JointCommand::Stop { .. }), "{:?}", sent);
            }
            reference = check_motion(&cfg, &state, &s.world, reference, &sent)?;
        }
    }

    /// SAF-REQ-011: once latched, every cycle halts until a reset succeeds, and a reset
    /// succeeds only after a state without the cause has been read.
    #[test]
    fn saf_req_011_latched_fault_stays_latched(
        before in prop::collection::vec(step(), 0..10),
        fault_cycles in 1usize..20,
        after in prop::collection::vec(step(), 1..30),
        reset_at in 0usize..30,
    ) {
        let (robot, inner) = MockRobot::at(Q_WORK);
        let mut sup = Supervisor::new(robot, SupervisorConfig::ur5e()).unwrap();
        let mut state = RobotState::default();
        for s in &before {
            sup.read_state(&mut state).unwrap();
            sup.step(&s.cmd, &s.world);
        }
        inner.borrow_mut().state.safety_mode = safety_mode::PROTECTIVE_STOP;
        for s in after.iter().cycle().take(fault_cycles) {
            sup.read_state(&mut state).unwrap();
            let v = sup.step(&s.cmd, &s.world);
            prop_assert!(matches!(v, Verdict::Halted { .. }), "{:?}", v);
            prop_assert!(sup.reset().is_err());
        }
        inner.borrow_mut().state.safety_mode = safety_mode::NORMAL;
        for (k, s) in after.iter().enumerate() {
            sup.read_state(&mut state).unwrap();
            if k == reset_at {
                prop_assert!(sup.reset().is_ok());
            }
            let v = sup.step(&s.cmd, &s.world);
            if k < reset_at {
                prop_assert!(matches!(v, Verdict::Halted { .. }), "{:?}", v);
                let last = inner.borrow().sent.last().copied();
                prop_assert!(matches!(last, Some(JointCommand::Stop { .. })), "{:?}", last);
            } else {
                prop_assert!(!matches!(v, Verdict::Halted { .. }), "{:?}", v);
            }
        }
    }
}
