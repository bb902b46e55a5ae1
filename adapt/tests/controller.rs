//! Closed-loop tests of `Controller` against `robot_io::sim::SimRobot` (one 2 ms cycle per step,
//! mock clock). The operator's hand here is SIMULATED: a point that moves on a scripted path,
//! not a tracked person.

use std::f64::consts::PI;
use std::time::Duration;

use adapt::controller::{
    Controller, ControllerConfig, MotionAdaptation, OperatorView, RawHandoverFile, SmoothnessScale,
    SpeedScale,
};
use robot_io::geometry::HumanBody;
use adapt::task::{Phase, TaskEventKind};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Robot, RobotState};

const DT: f64 = 0.002;
const SHIPPED: &str = include_str!("../../config/handover.toml");

fn shipped_config() -> ControllerConfig {
    let file: RawHandoverFile = toml::from_str(SHIPPED).expect("config/handover.toml parses");
    ControllerConfig::try_from(&file.controller).expect("config/handover.toml validates")
}

/// The SIMULATED operator's right hand.
#[derive(Debug, Clone, Copy)]
enum HandScript {
    /// Rests at its home until Present, then reaches the TCP at `speed` m/s, holds it until
    /// the release is confirmed, then withdraws.
    ReachWhenPresented { speed_m_s: f64 },
    /// As `ReachWhenPresented`, and additionally, `after_s` into the Approach, reaches into the
    /// robot's path at `intrusion` for `hold_s`, then goes back home.
    IntrudeDuringApproach {
        after_s: f64,
        hold_s: f64,
        intrusion: [f64; 3],
    },
    /// Never comes.
    Absent,
}

/// Where the SIMULATED hand rests: in front of the operator, 0.55 m beyond the handover point.
const HAND_HOME: [f64; 3] = [-1.25, -0.13, 0.2];

struct Run {
    robot: SimRobot,
    ctl: Controller,
    state: RobotState,
    cmd: JointCommand,
    adaptation: MotionAdaptation,
    hand: [f64; 3],
    script: HandScript,
    approach_started_s: Option<f64>,
    released: bool,
    /// (phase, time) of every phase change.
    phases: Vec<(Phase, f64)>,
    all_events: Vec<(f64, TaskEventKind)>,
    max_cmd_speed: f64,
    max_cmd_acc: f64,
    prev_servo: bool,
    max_actual_speed: f64,
    max_actual_acc: f64,
    /// (t, TCP speed [m/s], hand distance [m], phase) per cycle.
    samples: Vec<(f64, f64, f64, Phase)>,
    /// The time scale's rate-limit fallbacks seen (must stay 0).
    scale_errors: u64,
}

impl Run {
    fn new(cfg: ControllerConfig, script: HandScript) -> Run {
        let robot = SimRobot::new(SimConfig {
            initial_q_rad: cfg.task.home_q_rad,
            ..SimConfig::ur5e()
        })
        .unwrap();
        let ctl = Controller::new(cfg).unwrap();
        Run {
            robot,
            ctl,
            state: RobotState::default(),
            cmd: JointCommand::Stop { decel: 1.0 },
            adaptation: MotionAdaptation::default(),
            hand: HAND_HOME,
            script,
            approach_started_s: None,
            released: false,
            phases: Vec::new(),
            all_events: Vec::new(),
            max_cmd_speed: 0.0,
            max_cmd_acc: 0.0,
            prev_servo: false,
            max_actual_speed: 0.0,
            max_actual_acc: 0.0,
            samples: Vec::new(),
            scale_errors: 0,
        }
    }

    fn tcp(&self) -> [f64; 3] {
        let p = self.state.actual_tcp_pose;
        [p[0], p[1], p[2]]
    }

    /// Move the SIMULATED hand one cycle towards `goal` at `speed` [m/s].
    fn move_hand(&mut self, goal: [f64; 3], speed: f64) {
        let d = dist(&self.hand, &goal);
        let step = speed * DT;
        if d <= step {
            self.hand = goal;
        } else {
            for (h, g) in self.hand.iter_mut().zip(goal) {
                *h += (g - *h) * step / d;
            }
        }
    }

    fn script_hand(&mut self, now: f64) {
        let phase = self.ctl.phase();
        if phase == Phase::Approach && self.approach_started_s.is_none() {
            self.approach_started_s = Some(now);
        }
        let speed = match self.script {
            HandScript::ReachWhenPresented { speed_m_s } => speed_m_s,
            HandScript::IntrudeDuringApproach { .. } => 0.5,
            HandScript::Absent => return,
        };
        if let HandScript::IntrudeDuringApproach {
            after_s,
            hold_s,
            intrusion,
        } = self.script
            && phase == Phase::Approach
        {
            let t = now - self.approach_started_s.unwrap_or(now);
            if t >= after_s && t < after_s + hold_s {
                self.move_hand(intrusion, 1.0);
            } else {
                self.move_hand(HAND_HOME, 1.0);
            }
            return;
        }
        match phase {
            Phase::Present | Phase::Release if !self.released => {
                // Grasp a little beside the flange centre.
                let tcp = self.tcp();
                self.move_hand([tcp[0] - 0.03, tcp[1], tcp[2]], speed);
            }
            _ => self.move_hand(HAND_HOME, speed),
        }
    }

    fn humans(&self) -> OperatorView {
        match self.script {
            HandScript::Absent => OperatorView::default(),
            _ => OperatorView {
                body: HumanBody {
                    head_m: Some([-1.45, -0.13, 0.75]),
                    left_hand_m: None,
                    right_hand_m: Some(self.hand),
                    torso: None,
                },
                perception_age_s: 0.0,
            },
        }
    }

    fn cycle(&mut self) {
        self.robot.read_state(&mut self.state).unwrap();
        let now = self.state.timestamp_s;
        self.script_hand(now);
        let before = self.ctl.phase();
        let prev_qd = *self.ctl.commanded_velocity();
        let humans = self.humans();
        self.ctl
            .step(now, &self.state, &self.adaptation, &humans, &mut self.cmd);
        for e in self.ctl.events() {
            self.all_events.push((e.t_s, e.kind));
            if e.kind == TaskEventKind::ReleaseConfirmed {
                self.released = true;
            }
        }
        if self.ctl.phase() != before {
            self.phases.push((self.ctl.phase(), now));
        }
        // Commanded limits, between consecutive servo commands (a Stop hands braking to the
        // robot, and the next servo command resumes from the measured state).
        let qd = self.ctl.commanded_velocity();
        if matches!(self.cmd, JointCommand::Servo { .. }) {
            for v in qd {
                self.max_cmd_speed = self.max_cmd_speed.max(v.abs());
            }
            if self.prev_servo {
                for (v, p) in qd.iter().zip(&prev_qd) {
                    self.max_cmd_acc = self.max_cmd_acc.max((v - p).abs() / DT);
                }
            }
        }
        self.prev_servo = matches!(self.cmd, JointCommand::Servo { .. });
        let prev_actual = self.state.actual_qd;
        self.robot.send(&self.cmd).unwrap();
        self.robot.step();
        let s = *self.robot.state();
        for (v, p) in s.actual_qd.iter().zip(&prev_actual) {
            self.max_actual_speed = self.max_actual_speed.max(v.abs());
            self.max_actual_acc = self.max_actual_acc.max((v - p).abs() / DT);
        }
        let v = s.actual_tcp_speed;
        let tcp_speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        self.samples.push((
            now,
            tcp_speed,
            dist(&self.hand, &self.tcp()),
            self.ctl.phase(),
        ));
        self.scale_errors = self.ctl.stats().fallback_steps;
    }

    fn run_until_done(&mut self, max_s: f64) {
        self.ctl.start_handover();
        let cycles = (max_s / DT) as usize;
        for _ in 0..cycles {
            self.cycle();
            if self.ctl.phase() == Phase::Done {
                return;
            }
        }
        panic!(
            "no Done within {max_s} s; phases {:?}, stats {:?}",
            self.phases,
            self.ctl.stats()
        );
    }

    fn phase_time(&self, phase: Phase) -> f64 {
        self.phases
            .iter()
            .find(|(p, _)| *p == phase)
            .unwrap_or_else(|| panic!("{phase} never entered: {:?}", self.phases))
            .1
    }
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[test]
fn shipped_config_parses_and_solves_the_cartesian_pick() {
    let cfg = shipped_config();
    let pose = robot_io::kinematics::flange_pose(&cfg.task.pick_q_rad);
    let p = pose.translation.vector;
    assert!(
        (p - nalgebra::Vector3::new(-0.38, 0.35, 0.15)).norm() < 1e-6,
        "{p}"
    );
    // The branch chosen is the one nearest home: elbow up, wrist down, like the example.
    let example = adapt::task::TaskConfig::example();
    for (a, b) in cfg.task.pick_q_rad.iter().zip(&example.pick_q_rad) {
        assert!((a - b).abs() < 0.05, "{:?}", cfg.task.pick_q_rad);
    }
    assert_eq!(
        cfg.task.home_q_rad,
        example.home_q_rad.map(|q| (q * 1e6).round() / 1e6)
    );
}

#[test]
fn full_handover_closed_loop_reaches_done_within_limits() {
    let mut run = Run::new(
        shipped_config(),
        HandScript::ReachWhenPresented { speed_m_s: 0.4 },
    );
    run.run_until_done(30.0);
    let order: Vec<Phase> = run.phases.iter().map(|(p, _)| *p).collect();
    assert_eq!(
        order,
        [
            Phase::Fetch,
            Phase::Approach,
            Phase::Present,
            Phase::Release,
            Phase::Retreat,
            Phase::Done
        ]
    );
    assert!(!run.ctl.incomplete(), "release confirmed");
    assert!(!run.ctl.collaborating());
    // Ends at home.
    let home = run.ctl.config().task.home_q_rad;
    for (q, h) in run.state.actual_q.iter().zip(&home) {
        assert!((q - h).abs() < 0.01, "{:?}", run.state.actual_q);
    }
    // Joint limits hold throughout: commanded and actual (π rad/s, π rad/s²).
    let tol = 1e-6;
    assert!(
        run.max_cmd_speed <= PI + tol,
        "cmd speed {}",
        run.max_cmd_speed
    );
    assert!(run.max_cmd_acc <= PI + tol, "cmd acc {}", run.max_cmd_acc);
    assert!(
        run.max_actual_speed <= PI + tol,
        "speed {}",
        run.max_actual_speed
    );
    assert!(
        run.max_actual_acc <= PI + 1e-3,
        "acc {}",
        run.max_actual_acc
    );
    // The grasp came from the SIMULATED hand at the presented TCP.
    assert!(
        run.all_events
            .iter()
            .any(|(_, k)| *k == TaskEventKind::GraspDetected { hand: 1 })
    );
    assert!(run.ctl.stats().otg_errors == 0, "{:?}", run.ctl.stats());
    eprintln!(
        "handover: phases {:?}; max cmd speed {:.3} rad/s, acc {:.3} rad/s²; actual {:.3} / {:.3}; {:?}",
        run.phases,
        run.max_cmd_speed,
        run.max_cmd_acc,
        run.max_actual_speed,
        run.max_actual_acc,
        run.ctl.stats()
    );
}

#[test]
fn context_c_and_g_follow_the_phase_in_closed_loop() {
    let mut run = Run::new(
        ControllerConfig::example(),
        HandScript::ReachWhenPresented { speed_m_s: 0.4 },
    );
    run.ctl.start_handover();
    for _ in 0..(30.0 / DT) as usize {
        run.cycle();
        let phase = run.ctl.phase();
        assert_eq!(run.ctl.collaborating(), phase.is_collaborating());
        let confirmed = run
            .all_events
            .iter()
            .any(|(_, k)| *k == TaskEventKind::ReleaseConfirmed);
        assert_eq!(run.ctl.incomplete(), !confirmed, "{phase}");
        if phase == Phase::Done {
            return;
        }
    }
    panic!("not done");
}

#[test]
fn the_robot_slows_when_a_hand_approaches_during_approach() {
    // Same handover twice; in the second, 0.4 s into the approach the SIMULATED hand reaches
    // into the path 0.25 m short of the handover point for 1.5 s, then withdraws.
    let cfg = ControllerConfig::example();
    let mut free = Run::new(
        cfg.clone(),
        HandScript::ReachWhenPresented { speed_m_s: 0.4 },
    );
    free.run_until_done(30.0);
    let intrusion = [-0.97, -0.13, 0.25];
    let mut blocked = Run::new(
        cfg,
        HandScript::IntrudeDuringApproach {
            after_s: 0.4,
            hold_s: 1.5,
            intrusion,
        },
    );
    blocked.run_until_done(40.0);

    let approach = |r: &Run| r.phase_time(Phase::Present) - r.phase_time(Phase::Approach);
    let (t_free, t_blocked) = (approach(&free), approach(&blocked));
    assert!(
        t_blocked > t_free + 0.3,
        "approach {t_free:.3} s free vs {t_blocked:.3} s with the hand"
    );
    // While the hand is in the path, the TCP is slower than at the same time without it.
    let start_free = free.phase_time(Phase::Approach);
    let start_blocked = blocked.phase_time(Phase::Approach);
    let window = |r: &Run, start: f64| -> f64 {
        let s: Vec<f64> = r
            .samples
            .iter()
            .filter(|(t, ..)| *t >= start + 0.9 && *t < start + 1.6)
            .map(|(_, v, ..)| *v)
            .collect();
        s.iter().sum::<f64>() / s.len() as f64
    };
    let (v_free, v_blocked) = (window(&free, start_free), window(&blocked, start_blocked));
    assert!(
        v_blocked < 0.5 * v_free,
        "mean TCP speed {v_free:.3} m/s free vs {v_blocked:.3} m/s with the hand"
    );
    assert!(blocked.ctl.stats().scaled_steps > 0);
    assert_eq!(blocked.scale_errors, 0, "the time scale's trajectory never failed");
    // The hand never came closer to the TCP than the SSM limit lets the robot move at.
    let closest = blocked
        .samples
        .iter()
        .filter(|s| s.3 == Phase::Approach)
        .map(|s| s.2)
        .fold(f64::INFINITY, f64::min);
    eprintln!(
        "approach {t_free:.3} s free vs {t_blocked:.3} s with the hand; TCP {v_free:.3} vs {v_blocked:.3} m/s; closest TCP–hand {closest:.3} m; {:?}",
        blocked.ctl.stats()
    );
    // Both arrived and finished the handover within limits.
    assert!(blocked.max_cmd_acc <= PI + 1e-6 && blocked.max_cmd_speed <= PI + 1e-6);
}

#[test]
fn timeout_returns_the_part_to_the_pick_pose() {
    let mut run = Run::new(ControllerConfig::example(), HandScript::Absent);
    run.run_until_done(40.0);
    assert!(
        run.all_events
            .iter()
            .any(|(_, k)| *k == TaskEventKind::PresentTimeout)
    );
    assert!(run.ctl.incomplete());
    let pick = run.ctl.config().task.pick_q_rad;
    for (q, p) in run.state.actual_q.iter().zip(&pick) {
        assert!((q - p).abs() < 0.01);
    }
}

#[test]
fn adaptation_speed_scale_and_minimum_approach_duration_stretch_the_approach() {
    let cfg = ControllerConfig::example();
    let mut nominal = Run::new(
        cfg.clone(),
        HandScript::ReachWhenPresented { speed_m_s: 0.4 },
    );
    nominal.run_until_done(30.0);
    let mut slow = Run::new(
        cfg.clone(),
        HandScript::ReachWhenPresented { speed_m_s: 0.4 },
    );
    slow.adaptation.speed_scale = SpeedScale::new(0.25).unwrap();
    slow.adaptation.smoothness_scale = SmoothnessScale::new(0.5).unwrap();
    slow.run_until_done(40.0);
    let mut timed = Run::new(cfg, HandScript::ReachWhenPresented { speed_m_s: 0.4 });
    timed.adaptation.min_approach_duration = Duration::from_secs_f64(4.0);
    timed.adaptation.start_delay = Duration::from_secs_f64(1.0);
    timed.run_until_done(40.0);

    let approach = |r: &Run| r.phase_time(Phase::Present) - r.phase_time(Phase::Approach);
    eprintln!(
        "approach nominal {:.3} s, slow {:.3} s",
        approach(&nominal),
        approach(&slow)
    );
    assert!(approach(&slow) > 1.3 * approach(&nominal));
    assert!(
        slow.max_cmd_speed <= 0.25 * PI + 1e-6,
        "{}",
        slow.max_cmd_speed
    );
    let t = approach(&timed);
    assert!(
        (4.0..4.5).contains(&t),
        "approach took {t} s with a 4 s minimum"
    );
    let gripped = timed
        .all_events
        .iter()
        .find(|(_, k)| *k == TaskEventKind::PartGripped)
        .unwrap()
        .0;
    assert!((timed.phase_time(Phase::Approach) - gripped - 1.0).abs() < 0.01);
    eprintln!(
        "approach: nominal {:.3} s, speed 0.25/smooth 0.5 {:.3} s, min 4 s {:.3} s",
        approach(&nominal),
        approach(&slow),
        t
    );
}

#[test]
fn wait_for_attention_holds_at_the_pick_pose_in_closed_loop() {
    let mut run = Run::new(
        ControllerConfig::example(),
        HandScript::ReachWhenPresented { speed_m_s: 0.4 },
    );
    run.adaptation.wait_for_attention = true;
    run.adaptation.attention_on_robot = false;
    run.ctl.start_handover();
    for _ in 0..(8.0 / DT) as usize {
        run.cycle();
    }
    assert_eq!(run.ctl.phase(), Phase::WaitForAttention);
    let pick = run.ctl.config().task.pick_q_rad;
    assert!(
        run.state
            .actual_q
            .iter()
            .zip(&pick)
            .all(|(q, p)| (q - p).abs() < 0.01)
    );
    run.adaptation.attention_on_robot = true;
    for _ in 0..(20.0 / DT) as usize {
        run.cycle();
        if run.ctl.phase() == Phase::Done {
            return;
        }
    }
    panic!("not done: {:?}", run.phases);
}

#[test]
fn a_safety_stop_outputs_stop_and_resumes_after_recovery() {
    let mut run = Run::new(
        ControllerConfig::example(),
        HandScript::ReachWhenPresented { speed_m_s: 0.4 },
    );
    run.ctl.start_handover();
    for _ in 0..300 {
        run.cycle();
    }
    run.robot.inject_protective_stop();
    for _ in 0..200 {
        run.cycle();
    }
    assert!(matches!(run.cmd, JointCommand::Stop { .. }));
    assert!(run.robot.clear_protective_stop());
    run.robot.play();
    for _ in 0..(30.0 / DT) as usize {
        run.cycle();
        if run.ctl.phase() == Phase::Done {
            assert!(run.max_cmd_acc <= PI + 1e-6, "{}", run.max_cmd_acc);
            return;
        }
    }
    panic!("not done after recovery: {:?}", run.phases);
}

#[test]
fn non_finite_inputs_do_not_panic() {
    let mut ctl = Controller::new(ControllerConfig::example()).unwrap();
    ctl.start_handover();
    let mut state = RobotState {
        actual_q: ctl.config().task.home_q_rad,
        ..RobotState::default()
    };
    let mut cmd = JointCommand::Stop { decel: 1.0 };
    let nan = OperatorView {
        body: HumanBody {
            head_m: Some([f64::NAN; 3]),
            left_hand_m: Some([f64::INFINITY, 0.0, 0.0]),
            right_hand_m: None,
            torso: None,
        },
        perception_age_s: f64::NAN,
    };
    ctl.step(
        f64::NAN,
        &state,
        &MotionAdaptation::default(),
        &nan,
        &mut cmd,
    );
    if let JointCommand::Servo { q, .. } = cmd {
        assert!(q.iter().all(|v| v.is_finite()));
    }
    state.actual_q[2] = f64::NAN;
    ctl.step(0.002, &state, &MotionAdaptation::default(), &nan, &mut cmd);
    assert!(matches!(cmd, JointCommand::Stop { .. }));
}

#[test]
fn config_rules() {
    assert!(SpeedScale::new(0.0).is_err());
    assert!(SpeedScale::new(1.01).is_err());
    assert!(SmoothnessScale::new(f64::NAN).is_err());
    assert_eq!(SpeedScale::new(0.5).unwrap().get(), 0.5);
    let mut c = ControllerConfig::example();
    c.servo_gain = 50.0;
    let err = Controller::new(c).unwrap_err();
    assert!(
        err.to_string()
            .starts_with("invalid value for `servo_gain`"),
        "{err}"
    );
    let mut c = ControllerConfig::example();
    c.servo_lookahead_s = 0.5;
    assert!(Controller::new(c).is_err());
    // Unknown keys are refused.
    let bad = SHIPPED.replace("servo_gain = 500.0", "servo_gain = 500.0\nservo_gian = 1.0");
    assert!(toml::from_str::<RawHandoverFile>(&bad).is_err());
}
