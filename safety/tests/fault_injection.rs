//! Fault injection on `SimRobot` (2 ms mock clock). Each test prints its measured figure
//! (run with `--nocapture` to see them).

mod common;

use std::cell::RefCell;
use std::io::Write;
use std::rc::Rc;
use std::sync::{Arc, Mutex};

use common::{BaseRamp, DT, Q_WORK, SharedSim, capsules, norm3, servo, tcp_speed};
use robot_io::geometry::{BodyModel, closest_approaches};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, RobotState};
use safety::points::{arm_points, distance};
use safety::{HumanBody, Requirement, Supervisor, SupervisorConfig, Verdict, Violation, WorldView};

struct Rig {
    sim: Rc<RefCell<SimRobot>>,
    sup: Supervisor<SharedSim>,
    state: RobotState,
    t: f64,
}

impl Rig {
    fn new() -> Rig {
        let mut config = SimConfig::ur5e();
        config.initial_q_rad = Q_WORK;
        let sim = Rc::new(RefCell::new(SimRobot::new(config).unwrap()));
        let sup = Supervisor::new(SharedSim(sim.clone()), SupervisorConfig::ur5e()).unwrap();
        let mut rig = Rig {
            sim,
            sup,
            state: RobotState::default(),
            t: 0.0,
        };
        rig.read();
        rig
    }

    fn read(&mut self) {
        self.sup.read_state(&mut self.state).unwrap();
    }

    /// One control cycle: judge and send `cmd`, advance the robot 2 ms, read the new state.
    fn cycle(&mut self, cmd: &JointCommand, world: &WorldView) -> Verdict {
        let v = self.sup.step(cmd, world);
        self.sim.borrow_mut().step();
        self.t += DT;
        self.read();
        v
    }

    fn tcp_speed(&self) -> f64 {
        norm3(&self.state.actual_tcp_speed)
    }

    fn at_rest(&self) -> bool {
        self.state.actual_qd.iter().all(|v| *v == 0.0)
    }
}

fn world(t: f64, collaborating: bool) -> WorldView {
    WorldView {
        collaborating,
        ..WorldView::clear(t)
    }
}

#[test]
fn saf_req_007_fault_injection_hand_during_approach() {
    let mut rig = Rig::new();
    // Approach: the base turns so the TCP moves at about 0.2 m/s (the collaboration cap is
    // 0.25 m/s), ramping at 2 rad/s².
    let base = 0.2 / tcp_speed(&Q_WORK, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let mut plan = BaseRamp::new(Q_WORK, base, 2.0);
    for _ in 0..500 {
        let v = rig.cycle(&plan.next(), &world(rig.t, true));
        assert_eq!(v, Verdict::Passed);
    }
    let speed_at_appearance = rig.tcp_speed();
    // A hand appears 0.3 m from the TCP, ahead of it on its path.
    let p = arm_points(&rig.state.actual_q).tcp;
    let dir: Vec<f64> = rig.state.actual_tcp_speed[..3]
        .iter()
        .map(|x| x / speed_at_appearance)
        .collect();
    let hand = [
        p[0] + 0.3 * dir[0],
        p[1] + 0.3 * dir[1],
        p[2] + 0.3 * dir[2],
    ];
    let body = HumanBody {
        right_hand_m: Some(hand),
        ..HumanBody::NONE
    };
    let config = SupervisorConfig::ur5e();
    let surface_distance = |q: &robot_io::Joints| {
        let near = closest_approaches(&capsules(&config.arm, q), &body, &BodyModel::default());
        near[2].unwrap().distance_m
    };
    let initial_distance = surface_distance(&rig.state.actual_q);
    let seen = WorldView {
        human: body,
        perception_age_s: 0.033,
        ..world(rig.t, true)
    };
    let tcp_at_appearance = p;
    let mut min_distance = f64::INFINITY;
    let mut first_stop = None;
    let mut rest_after = None;
    let mut required = 0.0;
    for k in 0..1000 {
        let v = rig.cycle(&plan.next(), &seen);
        assert!(v.is_stop(), "cycle {k}: {v:?}");
        if let Verdict::Stopped {
            violation: Violation::Separation { required_m, .. },
        } = v
            && first_stop.is_none()
        {
            first_stop = Some(k);
            required = required_m;
        }
        min_distance = min_distance.min(surface_distance(&rig.state.actual_q));
        if rest_after.is_none() && rig.at_rest() {
            rest_after = Some(k + 1);
        }
    }
    let travel = distance(&tcp_at_appearance, &arm_points(&rig.state.actual_q).tcp);
    let rest_s = rest_after.unwrap() as f64 * DT;
    println!(
        "SAF-REQ-007 hand 0.300 m ahead of the TCP at {speed_at_appearance:.3} m/s \
         ({initial_distance:.4} m from the arm's surface): S_p = {required:.3} m, \
         stop sent in cycle {}, at rest after {rest_s:.3} s, TCP travelled {travel:.4} m, \
         minimum surface distance {min_distance:.4} m",
        first_stop.unwrap()
    );
    assert_eq!(first_stop, Some(0));
    let params = SupervisorConfig::ur5e().separation;
    let floor = params.intrusion_m() + params.human_uncertainty_m() + params.robot_uncertainty_m();
    assert!(
        min_distance >= floor,
        "{min_distance} < C + Z_d + Z_r = {floor}"
    );
    assert!(initial_distance < 0.3 && initial_distance > 0.3 - 0.1);
    assert!(min_distance > initial_distance - 0.02, "{min_distance}");
    assert!(rest_s < 0.2);
}

#[test]
fn saf_req_008_fault_injection_perception_freeze() {
    let mut rig = Rig::new();
    // 0.6 m/s outside collaboration (the cap is 1 m/s; stale perception cuts it to 0.25 m/s).
    let base = 0.6 / tcp_speed(&Q_WORK, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let mut plan = BaseRamp::new(Q_WORK, base, 3.0);
    for _ in 0..500 {
        assert_eq!(
            rig.cycle(&plan.next(), &world(rig.t, false)),
            Verdict::Passed
        );
    }
    let cruise = rig.tcp_speed();
    // The camera freezes: the last frame was 33 ms old and ages from now on.
    let frozen_at = rig.t;
    let mut first_reduced = None;
    let mut under_cap = None;
    let mut actual_under_cap = None;
    let mut sent_q = rig.state.target_q;
    let mut first_stop = None;
    let mut rest = None;
    for _ in 0..1000 {
        let age = 0.033 + (rig.t - frozen_at);
        let w = WorldView {
            perception_age_s: age,
            ..world(rig.t, false)
        };
        let since = rig.t - frozen_at;
        let v = rig.cycle(&plan.next(), &w);
        if std::env::var("SAFETY_DEBUG").is_ok() {
            println!("{since:.3} {:.4} {v:?}", rig.tcp_speed());
        }
        match v {
            Verdict::Passed => assert!(age <= 0.2 + 1e-9, "passed at age {age}"),
            Verdict::Reduced { violation, .. } => {
                // The first reduction is the staleness; afterwards the planner runs ahead of
                // the slowed robot and its steps also break the unreduced TCP cap.
                if first_reduced.is_none() {
                    assert_eq!(violation.requirement(), Requirement::Saf008PerceptionStale);
                } else {
                    assert!(matches!(
                        violation.requirement(),
                        Requirement::Saf008PerceptionStale | Requirement::Saf005TcpSpeed
                    ));
                }
                first_reduced.get_or_insert(since);
                if let JointCommand::Servo { q, .. } = rig.sup.last_sent().unwrap().command() {
                    let v = q
                        .iter()
                        .zip(&sent_q)
                        .map(|(a, b)| (a - b) / DT)
                        .collect::<Vec<_>>();
                    let v: [f64; 6] = v.try_into().unwrap();
                    if tcp_speed(&sent_q, &v) <= 0.25 + 1e-9 {
                        under_cap.get_or_insert(since);
                    }
                }
                if rig.tcp_speed() <= 0.25 * 1.05 {
                    actual_under_cap.get_or_insert(since);
                }
            }
            Verdict::Stopped { violation } => {
                assert!(
                    matches!(violation, Violation::PerceptionStale { limit_s, .. } if limit_s == 1.0)
                );
                first_stop.get_or_insert(since);
            }
            Verdict::Halted { .. } => panic!("{v:?}"),
        }
        if let JointCommand::Servo { q, .. } = rig.sup.last_sent().unwrap().command() {
            sent_q = *q;
        }
        if first_stop.is_some() && rest.is_none() && rig.at_rest() {
            rest = Some(rig.t - frozen_at);
        }
    }
    let (r, u, a, s, z) = (
        first_reduced.unwrap(),
        under_cap.unwrap(),
        actual_under_cap.unwrap(),
        first_stop.unwrap(),
        rest.unwrap(),
    );
    println!(
        "SAF-REQ-008 perception frozen at {cruise:.3} m/s (frame 33 ms old): reduced after {r:.3} s, \
         commanded TCP speed under 0.25 m/s after {u:.3} s (measured under 0.2625 m/s after {a:.3} s; \
         SimRobot's servo filter lags), stop after {s:.3} s, at rest after {z:.3} s"
    );
    assert!((r - 0.167).abs() < 0.003, "{r}");
    assert!(u < r + 0.3);
    assert!(a < s);
    assert!((s - 0.967).abs() < 0.003, "{s}");
    assert!(z < s + 0.2);
}

#[test]
fn saf_req_010_fault_injection_protective_stop() {
    let mut rig = Rig::new();
    let base = 0.4 / tcp_speed(&Q_WORK, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let mut plan = BaseRamp::new(Q_WORK, base, 3.0);
    for _ in 0..300 {
        assert_eq!(
            rig.cycle(&plan.next(), &world(rig.t, false)),
            Verdict::Passed
        );
    }
    rig.sim.borrow_mut().inject_protective_stop();
    // The supervisor sees the stop in the first state read after it (cycle 0 is judged on
    // the state read before the injection).
    let mut latched_after = None;
    let mut motion_sent = 0;
    for k in 0..500 {
        let v = rig.cycle(&plan.next(), &world(rig.t, false));
        if matches!(v, Verdict::Halted { .. }) {
            latched_after.get_or_insert(k);
        } else if k > 0 {
            panic!("cycle {k}: {v:?}");
        }
        let stop = matches!(
            rig.sup.last_sent().unwrap().command(),
            JointCommand::Stop { .. }
        );
        if latched_after.is_some() && !stop {
            motion_sent += 1;
        }
    }
    assert!(rig.sup.reset().is_err(), "the stop is still active");
    // The operator unlocks the protective stop; without a reset nothing moves.
    assert!(rig.sim.borrow_mut().clear_protective_stop());
    rig.sim.borrow_mut().play();
    let mut replaced_after_clear = 0;
    for _ in 0..100 {
        let v = rig.cycle(&plan.next(), &world(rig.t, false));
        assert!(matches!(v, Verdict::Halted { .. }), "{v:?}");
        replaced_after_clear += 1;
    }
    assert!(rig.at_rest());
    rig.sup.reset().unwrap();
    // The planner restarts from where the robot stands.
    let mut plan = BaseRamp::new(rig.state.target_q, base, 3.0);
    for _ in 0..100 {
        assert_eq!(
            rig.cycle(&plan.next(), &world(rig.t, false)),
            Verdict::Passed
        );
    }
    assert!(rig.tcp_speed() > 0.0);
    println!(
        "SAF-REQ-010 protective stop: latched in cycle {} after injection (the first state showing it), \
         {} motion commands sent while latched ({} + {replaced_after_clear} after the unlock replaced by stops), \
         motion resumes only after reset",
        latched_after.unwrap(),
        motion_sent,
        500 - latched_after.unwrap()
    );
    assert_eq!(latched_after, Some(1));
    assert_eq!(motion_sent, 0);
}

/// Collects formatted log output.
#[derive(Clone, Default)]
struct LogBuffer(Arc<Mutex<Vec<u8>>>);

impl Write for LogBuffer {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[test]
fn saf_req_001_fault_injection_nan_target() {
    let logs = LogBuffer::default();
    let writer = logs.clone();
    let subscriber = tracing_subscriber::fmt()
        .with_writer(move || writer.clone())
        .with_ansi(false)
        .with_max_level(tracing::Level::INFO)
        .finish();
    tracing::subscriber::with_default(subscriber, || {
        // At rest, holding: a NaN target arrives for 50 cycles.
        let mut rig = Rig::new();
        let hold = servo(rig.state.target_q);
        for _ in 0..50 {
            assert_eq!(rig.cycle(&hold, &world(rig.t, false)), Verdict::Passed);
        }
        let before = rig.state.actual_q;
        let mut nan = rig.state.target_q;
        nan[1] = f64::NAN;
        for _ in 0..50 {
            let v = rig.cycle(&servo(nan), &world(rig.t, false));
            assert_eq!(v.requirement(), Some(Requirement::Saf001Malformed));
            assert!(v.is_stop());
        }
        let moved = before
            .iter()
            .zip(&rig.state.actual_q)
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        assert_eq!(rig.sim.borrow().ignored_commands(), 0);
        assert_eq!(rig.sup.counters().fired(Requirement::Saf001Malformed), 50);

        // While moving at 0.4 m/s: the NaN stops the arm.
        let mut rig = Rig::new();
        let base = 0.4 / tcp_speed(&Q_WORK, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let mut plan = BaseRamp::new(Q_WORK, base, 3.0);
        for _ in 0..300 {
            rig.cycle(&plan.next(), &world(rig.t, false));
        }
        let tcp0 = arm_points(&rig.state.actual_q).tcp;
        let mut rest = None;
        for k in 0..300 {
            let v = rig.cycle(&servo(nan), &world(rig.t, false));
            assert!(v.is_stop());
            if rest.is_none() && rig.at_rest() {
                rest = Some((k + 1) as f64 * DT);
            }
        }
        let travel = distance(&tcp0, &arm_points(&rig.state.actual_q).tcp);
        println!(
            "SAF-REQ-001 NaN target: at rest the arm moved {moved:.1e} rad over 50 NaN cycles; \
             at 0.4 m/s it stopped in {:.3} s after {travel:.4} m of TCP travel",
            rest.unwrap()
        );
        assert!(moved < 1e-12);
    });
    let text = String::from_utf8(logs.0.lock().unwrap().clone()).unwrap();
    assert!(
        text.contains("SAF-REQ-001") && text.contains("command replaced by a stop"),
        "{text}"
    );
}
