//! One test per requirement, named after its ID, on a kinematic mock robot.

mod common;

use std::f64::consts::PI;

use common::{DT, MockRobot, Q_WORK, beyond_part, servo, tcp_speed};
use robot_io::{JointCommand, RobotState, safety_mode, safety_status_bits};
use safety::points::{ArmPoint, arm_points};
use safety::separation::{RobotMotion, protective_distance_m};
use safety::{
    ArmLink, BodyPart, HumanBody, MalformedInput, Requirement, SafetyError, Supervisor,
    SupervisorConfig, Torso, Verdict, Violation, WorkspaceBox, WorldView,
};

type Sup = Supervisor<MockRobot>;

fn rig(q: robot_io::Joints) -> (Sup, std::rc::Rc<std::cell::RefCell<common::MockInner>>) {
    rig_with(q, SupervisorConfig::ur5e())
}

fn rig_with(
    q: robot_io::Joints,
    config: SupervisorConfig,
) -> (Sup, std::rc::Rc<std::cell::RefCell<common::MockInner>>) {
    let (robot, inner) = MockRobot::at(q);
    (Supervisor::new(robot, config).unwrap(), inner)
}

/// Read the state and step once.
fn cycle(s: &mut Sup, cmd: &JointCommand, world: &WorldView) -> Verdict {
    let mut state = RobotState::default();
    s.read_state(&mut state).unwrap();
    s.step(cmd, world)
}

fn last_sent(s: &Sup) -> JointCommand {
    *s.last_sent().unwrap().command()
}

fn speed(qd: robot_io::Joints, acc: f64) -> JointCommand {
    JointCommand::Speed { qd, acc }
}

fn base_speed(v: f64) -> robot_io::Joints {
    [v, 0.0, 0.0, 0.0, 0.0, 0.0]
}

fn clear() -> WorldView {
    WorldView::clear(0.0)
}

#[test]
fn saf_req_001_non_finite_values_are_rejected() {
    let mut nan_q = Q_WORK;
    nan_q[2] = f64::NAN;
    let cases = [
        (servo(nan_q), clear(), MalformedInput::CommandValue),
        (
            speed([f64::INFINITY, 0.0, 0.0, 0.0, 0.0, 0.0], 1.0),
            clear(),
            MalformedInput::CommandValue,
        ),
        (
            speed(base_speed(0.1), f64::NAN),
            clear(),
            MalformedInput::CommandValue,
        ),
        (
            JointCommand::Stop { decel: f64::NAN },
            clear(),
            MalformedInput::CommandValue,
        ),
        (
            JointCommand::Servo {
                q: Q_WORK,
                lookahead_s: 0.01,
                gain: 300.0,
            },
            clear(),
            MalformedInput::ServoParameter,
        ),
        (
            JointCommand::Servo {
                q: Q_WORK,
                lookahead_s: 0.1,
                gain: 5000.0,
            },
            clear(),
            MalformedInput::ServoParameter,
        ),
        (
            servo(Q_WORK),
            WorldView {
                perception_age_s: f64::NAN,
                ..clear()
            },
            MalformedInput::WorldView,
        ),
        (
            servo(Q_WORK),
            WorldView {
                human: HumanBody {
                    left_hand_m: Some([f64::NAN, 0.0, 0.0]),
                    ..HumanBody::NONE
                },
                ..clear()
            },
            MalformedInput::WorldView,
        ),
        (
            servo(Q_WORK),
            WorldView {
                human: HumanBody {
                    torso: Some(Torso {
                        shoulder_mid_m: [-1.0, 0.0, 0.5],
                        normal: [f64::INFINITY, 0.0, 0.0],
                    }),
                    ..HumanBody::NONE
                },
                ..clear()
            },
            MalformedInput::WorldView,
        ),
    ];
    for (cmd, world, input) in cases {
        let (mut s, _) = rig(Q_WORK);
        let v = cycle(&mut s, &cmd, &world);
        assert_eq!(
            v,
            Verdict::Stopped {
                violation: Violation::Malformed { input }
            },
            "{cmd:?}"
        );
        assert!(matches!(last_sent(&s), JointCommand::Stop { decel } if decel == PI));
    }
    // A non-finite robot state.
    let (mut s, inner) = rig(Q_WORK);
    inner.borrow_mut().state.actual_qd[4] = f64::NAN;
    let v = cycle(&mut s, &servo(Q_WORK), &clear());
    assert_eq!(v.requirement(), Some(Requirement::Saf001Malformed));
    // A valid upstream stop passes, at no less than the configured deceleration.
    let (mut s, _) = rig(Q_WORK);
    assert_eq!(
        cycle(&mut s, &JointCommand::Stop { decel: 1.0 }, &clear()),
        Verdict::Passed
    );
    assert_eq!(last_sent(&s), JointCommand::Stop { decel: PI });
}

#[test]
fn saf_req_002_joint_position_limits() {
    // Wrist 3 near +2π (it does not move the flange position).
    let mut q = Q_WORK;
    q[5] = 2.0 * PI - 0.06;
    let (mut s, _) = rig(q);
    // 0.5 rad/s: the next target is inside the margin, but the stop would end beyond it.
    let v = cycle(&mut s, &speed([0.0, 0.0, 0.0, 0.0, 0.0, 0.5], PI), &clear());
    assert!(v.is_stop(), "{v:?}");
    assert_eq!(v.requirement(), Some(Requirement::Saf002JointPosition));
    // Slowly, the same direction passes until the margin.
    let (mut s, _) = rig(q);
    let mut target = q;
    target[5] += 1e-6;
    assert_eq!(cycle(&mut s, &servo(target), &clear()), Verdict::Passed);
    // A target beyond the margin is refused outright.
    let (mut s, _) = rig(q);
    let v = cycle(
        &mut s,
        &speed([0.0, 0.0, 0.0, 0.0, 0.0, 3.0], 1.0),
        &clear(),
    );
    assert!(matches!(
        v,
        Verdict::Stopped {
            violation: Violation::JointOutOfLimit { joint: 5, .. }
        }
    ));
}

#[test]
fn saf_req_003_joint_speed_limit() {
    let (mut s, _) = rig(Q_WORK);
    // Wrist 3 at 2π rad/s: scaled to π rad/s (the TCP does not move).
    let v = cycle(
        &mut s,
        &speed([0.0, 0.0, 0.0, 0.0, 0.0, 2.0 * PI], 1.0),
        &clear(),
    );
    match v {
        Verdict::Reduced { scale, violation } => {
            assert!((scale - 0.5).abs() < 1e-12);
            assert!(matches!(violation, Violation::JointSpeed { joint: 5, .. }));
        }
        other => panic!("{other:?}"),
    }
    let JointCommand::Speed { qd, .. } = last_sent(&s) else {
        panic!()
    };
    assert!((qd[5] - PI).abs() < 1e-12);
    assert!(s.counters().fired(Requirement::Saf003JointSpeed) == 1);
}

#[test]
fn saf_req_004_joint_acceleration_limit() {
    // speedj acceleration above π rad/s² is clamped.
    let (mut s, _) = rig(Q_WORK);
    let v = cycle(
        &mut s,
        &speed([0.0, 0.0, 0.0, 0.0, 0.0, 0.1], 10.0),
        &clear(),
    );
    assert_eq!(v.requirement(), Some(Requirement::Saf004JointAcceleration));
    assert!(matches!(last_sent(&s), JointCommand::Speed { acc, .. } if acc == PI));

    // A servo jump from rest (5 rad/s in one cycle) is scaled to the acceleration limit.
    let (mut s, inner) = rig(Q_WORK);
    let mut target = Q_WORK;
    target[5] += 0.01;
    let v = cycle(&mut s, &servo(target), &clear());
    assert_eq!(v.requirement(), Some(Requirement::Saf004JointAcceleration));
    let JointCommand::Servo { q, .. } = last_sent(&s) else {
        panic!()
    };
    let implied_acc = (q[5] - Q_WORK[5]) / DT / DT;
    assert!(implied_acc <= PI * (1.0 + 1e-9), "{implied_acc}");
    assert!(implied_acc > PI * 0.99, "{implied_acc}");

    // Reversing a moving joint within one cycle is impossible: stop.
    let (mut s, inner2) = rig(Q_WORK);
    let mut q = Q_WORK;
    let mut cmd_speed = 0.0;
    for _ in 0..100 {
        cmd_speed += 3.0 * DT;
        q[5] += cmd_speed * DT;
        assert!(!cycle(&mut s, &servo(q), &clear()).is_stop());
    }
    q[5] -= cmd_speed * DT; // back where it came from
    let mut other = q;
    other[4] += 0.001;
    let v = cycle(&mut s, &servo(other), &clear());
    assert!(v.is_stop(), "{v:?}");
    assert_eq!(v.requirement(), Some(Requirement::Saf004JointAcceleration));
    drop((inner, inner2));
}

#[test]
fn saf_req_005_tcp_speed_limit() {
    // Base at 3 rad/s moves the TCP at well over 1 m/s.
    let (mut s, inner) = rig(Q_WORK);
    let v = cycle(&mut s, &speed(base_speed(3.0), PI), &clear());
    assert_eq!(v.requirement(), Some(Requirement::Saf005TcpSpeed), "{v:?}");
    let JointCommand::Speed { qd, .. } = last_sent(&s) else {
        panic!()
    };
    let q = inner.borrow().state.actual_q;
    let sent = tcp_speed(&q, &qd);
    assert!(sent <= 1.0 && sent > 0.99, "{sent}");
    // While collaborating: 0.25 m/s.
    let (mut s, inner) = rig(Q_WORK);
    let world = WorldView {
        collaborating: true,
        ..clear()
    };
    let v = cycle(&mut s, &speed(base_speed(1.0), PI), &world);
    assert!(matches!(v, Verdict::Reduced { .. }), "{v:?}");
    let JointCommand::Speed { qd, .. } = last_sent(&s) else {
        panic!()
    };
    let sent = tcp_speed(&inner.borrow().state.actual_q, &qd);
    assert!(sent <= 0.25 && sent > 0.24, "{sent}");
}

#[test]
fn saf_req_006_workspace_box() {
    let p = arm_points(&Q_WORK);
    // A box whose −y face is just beyond the TCP: turning the base moves the TCP out
    // through it (the stopping configuration is outside).
    let mut config = SupervisorConfig::ur5e();
    config.workspace = WorkspaceBox::new([-1.0, p.tcp[1] - 0.002, 0.02], [1.0, 1.0, 1.3]).unwrap();
    let (mut s, _) = rig_with(Q_WORK, config);
    let v = cycle(&mut s, &speed(base_speed(0.5), PI), &clear());
    assert_eq!(v.requirement(), Some(Requirement::Saf006Workspace), "{v:?}");
    // A box the elbow is not in.
    let mut config = SupervisorConfig::ur5e();
    config.workspace =
        WorkspaceBox::new([-1.0, -1.0, 0.02], [1.0, 1.0, p.elbow[2] - 0.01]).unwrap();
    let (mut s, _) = rig_with(Q_WORK, config);
    let v = cycle(&mut s, &servo(Q_WORK), &clear());
    assert!(
        matches!(
            v,
            Verdict::Stopped {
                violation: Violation::OutsideWorkspace {
                    point: ArmPoint::Elbow,
                    ..
                }
            }
        ),
        "{v:?} {p:?}"
    );
}

#[test]
fn saf_req_007_protective_separation() {
    let config = SupervisorConfig::ur5e();
    let params = config.separation;
    // A hand on the tool axis `d` beyond the carried part's surface: its nearest link is the
    // part, `d` away (surface to surface).
    let at = |d: f64| Some(beyond_part(&config.arm, &Q_WORK, d));
    let hand = |d: f64| HumanBody {
        left_hand_m: at(d),
        ..HumanBody::NONE
    };
    // By hand: at rest with fresh perception S_p = v_h·T_r + C + Z_d + Z_r
    // = 2.0·0.1 + 0.1 + 0.05 + 0.02 = 0.37 m for a hand.
    let s_rest = protective_distance_m(&params, BodyPart::LeftHand, RobotMotion::REST, 0.0);
    assert!((s_rest - 0.37).abs() < 1e-12);

    // A hand 0.3 m from the part: stop, even at rest, naming the hand and the part.
    let (mut s, _) = rig(Q_WORK);
    let world = WorldView {
        human: hand(0.3),
        ..clear()
    };
    let v = cycle(&mut s, &servo(Q_WORK), &world);
    match v {
        Verdict::Stopped {
            violation:
                Violation::Separation {
                    part,
                    link,
                    distance_m,
                    required_m,
                },
        } => {
            assert_eq!(part, BodyPart::LeftHand);
            assert_eq!(link, ArmLink::Part);
            assert!((distance_m - 0.3).abs() < 1e-9, "{distance_m}");
            assert!((required_m - s_rest).abs() < 1e-9);
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(
        v.violation().unwrap().to_string(),
        "SAF-REQ-007: left_hand 0.300 m from the part, needs 0.370 m"
    );
    // 0.45 m: fine at rest, not at speed (S_p grows with v_r and T_s).
    let (mut s, _) = rig(Q_WORK);
    let world = WorldView {
        human: HumanBody {
            right_hand_m: at(0.45),
            ..HumanBody::NONE
        },
        ..clear()
    };
    assert_eq!(cycle(&mut s, &servo(Q_WORK), &world), Verdict::Passed);
    let v = cycle(&mut s, &speed(base_speed(1.5), PI), &world);
    assert_eq!(
        v.requirement(),
        Some(Requirement::Saf007Separation),
        "{v:?}"
    );
    // The head 1.5 m beyond the part does not stop a 1 rad/s base motion.
    let (mut s, _) = rig(Q_WORK);
    let world = WorldView {
        human: HumanBody {
            head_m: at(1.5),
            ..HumanBody::NONE
        },
        ..clear()
    };
    let v = cycle(&mut s, &speed(base_speed(1.0), PI), &world);
    assert!(!v.is_stop(), "{v:?}");
    // Old perception widens S_p by v_h·age: 0.37 + 2.0·0.15 = 0.67 > 0.45.
    let world = WorldView {
        human: hand(0.45),
        perception_age_s: 0.15,
        ..clear()
    };
    let (mut s, _) = rig(Q_WORK);
    assert_eq!(
        cycle(&mut s, &servo(Q_WORK), &world).requirement(),
        Some(Requirement::Saf007Separation)
    );
}

#[test]
fn saf_req_008_perception_staleness() {
    let world = |age| WorldView {
        perception_age_s: age,
        ..clear()
    };
    // Fresh enough: 0.6 m/s passes.
    let (mut s, inner) = rig(Q_WORK);
    let q = inner.borrow().state.actual_q;
    let v06 = 0.6 / tcp_speed(&q, &base_speed(1.0));
    assert_eq!(
        cycle(&mut s, &speed(base_speed(v06), PI), &world(0.19)),
        Verdict::Passed
    );
    // Older than 0.2 s: reduced to 0.25 m/s.
    let v = cycle(&mut s, &speed(base_speed(v06), PI), &world(0.3));
    assert!(
        matches!(
            v,
            Verdict::Reduced {
                violation: Violation::PerceptionStale { .. },
                ..
            }
        ),
        "{v:?}"
    );
    let JointCommand::Speed { qd, .. } = last_sent(&s) else {
        panic!()
    };
    let sent = tcp_speed(&inner.borrow().state.actual_q, &qd);
    assert!(sent <= 0.25, "{sent}");
    // Older than 1 s: stop.
    let v = cycle(&mut s, &speed(base_speed(v06), PI), &world(1.01));
    assert_eq!(
        v,
        Verdict::Stopped {
            violation: Violation::PerceptionStale {
                age_s: 1.01,
                limit_s: 1.0
            }
        }
    );
}

#[test]
fn saf_req_009_robot_state_staleness() {
    let (mut s, inner) = rig(Q_WORK);
    let hold = servo(Q_WORK);
    assert_eq!(cycle(&mut s, &hold, &clear()), Verdict::Passed);
    inner.borrow_mut().freeze = true;
    for _ in 0..3 {
        assert_eq!(cycle(&mut s, &hold, &clear()), Verdict::Passed);
    }
    let v = cycle(&mut s, &hold, &clear());
    assert_eq!(
        v,
        Verdict::Stopped {
            violation: Violation::RobotStateStale {
                cycles: 4,
                limit_cycles: 3
            }
        }
    );
    // A reset does not clear the staleness of a state that is still frozen (a latched fault
    // from before the freeze may be reset once a newer state was read, but the state has
    // stopped coming since): the next commands still stop.
    let (mut s2, inner2) = rig(Q_WORK);
    assert_eq!(cycle(&mut s2, &hold, &clear()), Verdict::Passed);
    inner2.borrow_mut().state.safety_mode = safety_mode::PROTECTIVE_STOP;
    assert!(cycle(&mut s2, &hold, &clear()).is_stop());
    inner2.borrow_mut().state.safety_mode = safety_mode::NORMAL;
    assert!(cycle(&mut s2, &hold, &clear()).is_stop()); // latched; a newer state without it
    inner2.borrow_mut().freeze = true;
    for _ in 0..4 {
        assert!(cycle(&mut s2, &hold, &clear()).is_stop());
    }
    assert!(s2.latched().is_some());
    s2.reset()
        .expect("a newer state without the cause was read");
    assert_eq!(
        cycle(&mut s2, &hold, &clear()),
        Verdict::Stopped {
            violation: Violation::RobotStateStale {
                cycles: 5,
                limit_cycles: 3
            }
        }
    );
    // Stepping without reading counts too.
    inner.borrow_mut().freeze = false;
    assert_eq!(cycle(&mut s, &hold, &clear()), Verdict::Passed);
    for _ in 0..3 {
        assert!(!s.step(&hold, &clear()).is_stop());
    }
    assert!(s.step(&hold, &clear()).is_stop());
}

#[test]
fn saf_req_010_robot_safety_stop_halts_and_latches() {
    let faults: [(i32, u32); 4] = [
        (
            safety_mode::PROTECTIVE_STOP,
            safety_status_bits::PROTECTIVE_STOP,
        ),
        (safety_mode::NORMAL, safety_status_bits::EMERGENCY_STOP),
        (safety_mode::ROBOT_EMERGENCY_STOP, 0),
        (safety_mode::REDUCED, 0),
    ];
    for (mode, bits) in faults {
        let (mut s, inner) = rig(Q_WORK);
        {
            let mut i = inner.borrow_mut();
            i.state.safety_mode = mode;
            i.state.safety_status_bits = bits;
        }
        let v = cycle(&mut s, &servo(Q_WORK), &clear());
        assert!(
            matches!(
                v,
                Verdict::Halted {
                    violation: Violation::RobotSafetyStop { .. }
                }
            ),
            "{v:?}"
        );
        assert!(s.latched().is_some());
        assert!(matches!(last_sent(&s), JointCommand::Stop { .. }));
    }
}

#[test]
fn saf_req_011_latch_clears_only_by_reset_with_cause_gone() {
    let (mut s, inner) = rig(Q_WORK);
    let hold = servo(Q_WORK);
    inner.borrow_mut().state.safety_mode = safety_mode::PROTECTIVE_STOP;
    assert!(matches!(
        cycle(&mut s, &hold, &clear()),
        Verdict::Halted { .. }
    ));
    // Cause present: reset refused.
    assert!(matches!(s.reset(), Err(SafetyError::ResetRefused { .. })));
    // Cause gone, but no reset: still halted.
    inner.borrow_mut().state.safety_mode = safety_mode::NORMAL;
    for _ in 0..10 {
        assert!(matches!(
            cycle(&mut s, &hold, &clear()),
            Verdict::Halted { .. }
        ));
    }
    // Reset now succeeds; commands pass again.
    s.reset().unwrap();
    assert_eq!(cycle(&mut s, &hold, &clear()), Verdict::Passed);
    assert_eq!(s.counters().resets, 1);
    assert_eq!(s.counters().resets_refused, 1);
    assert_eq!(s.counters().fired(Requirement::Saf011Latch), 1);
    assert_eq!(s.counters().fired(Requirement::Saf010RobotSafetyStop), 11);
}

#[test]
fn saf_req_012_send_failure_latches() {
    let (mut s, inner) = rig(Q_WORK);
    inner.borrow_mut().fail_send = true;
    let v = cycle(&mut s, &servo(Q_WORK), &clear());
    assert_eq!(
        v,
        Verdict::Halted {
            violation: Violation::SendFailed
        }
    );
    assert!(s.reset().is_err());
    inner.borrow_mut().fail_send = false;
    // The next cycle delivers a stop; then the cause is gone.
    assert!(matches!(
        cycle(&mut s, &servo(Q_WORK), &clear()),
        Verdict::Halted { .. }
    ));
    assert!(matches!(
        inner.borrow().sent.last(),
        Some(JointCommand::Stop { .. })
    ));
    s.reset().unwrap();
    assert_eq!(cycle(&mut s, &servo(Q_WORK), &clear()), Verdict::Passed);
}

#[test]
fn verdicts_are_counted_per_reaction() {
    let (mut s, _) = rig(Q_WORK);
    cycle(&mut s, &servo(Q_WORK), &clear());
    let mut nan = Q_WORK;
    nan[0] = f64::NAN;
    cycle(&mut s, &servo(nan), &clear());
    let c = s.counters();
    assert_eq!((c.steps, c.passed, c.stopped), (2, 1, 1));
    assert_eq!(c.fired(Requirement::Saf001Malformed), 1);
    assert_eq!(Requirement::ALL.len(), Requirement::COUNT);
    for (i, r) in Requirement::ALL.iter().enumerate() {
        assert_eq!(r.index(), i);
        assert_eq!(r.id(), format!("SAF-REQ-{:03}", i + 1));
    }
}
