//! Closed-loop tests of `Controller` against `robot_io::sim::SimRobot` (one 2 ms cycle per step,
//! mock clock). The operator here is SIMULATED: a head and a right hand that move on scripted
//! paths, not a tracked person.
//!
//! # The SIMULATED operator's geometry (robot base frame [m])
//! The operator sits on the robot's −x side, as in `config/trial.toml`'s station. The right
//! hand rests at [`HAND_REST`], 0.79 m from the handover flange position (−0.73, −0.13, 0.24)
//! of `config/handover.toml`: outside the protective separation distance the planner keeps at
//! rest (S_p = v_h·(T_age + T_r) + C + Z_d + Z_r = 2.0·(0.05 + 0.1) + 0.17 = 0.47 m with its
//! 0.05 s perception-age margin, plus its 0.05 m distance margin: 0.52 m). Like the trial's
//! simulated operator it reaches for the part only once it is presented (reaching earlier
//! would put it inside S_p and the robot would — correctly — wait), at [`HAND_SPEED_M_S`].
//!
//! Each closed-loop run costs about 2 ms of CPU per simulated cycle in a debug build, so the
//! scenarios are kept short: the nominal handover is run once and shared ([`nominal`]), and
//! scenarios about the approach start at the pick pose and end when the part is presented.

use std::f64::consts::PI;
use std::sync::OnceLock;
use std::time::Duration;

use adapt::controller::{
    Controller, ControllerConfig, MotionAdaptation, OperatorView, RawHandoverFile, SmoothnessScale,
    SpeedScale,
};
use adapt::envelope::flange_speed_m_s;
use adapt::task::{Phase, TaskEventKind};
use robot_io::geometry::HumanBody;
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Joints, Robot, RobotState};

const DT: f64 = 0.002;
const SHIPPED: &str = include_str!("../../config/handover.toml");

fn shipped_config() -> ControllerConfig {
    let file: RawHandoverFile = toml::from_str(SHIPPED).expect("config/handover.toml parses");
    ControllerConfig::try_from(&file.controller).expect("config/handover.toml validates")
}

/// Where the SIMULATED right hand rests (at the operator's fixture): 0.79 m from the handover
/// flange position (−0.73, −0.13, 0.24) m.
const HAND_REST: [f64; 3] = [-1.45, -0.45, 0.2];
/// The SIMULATED head: 1.05 m from the handover flange position.
const HEAD: [f64; 3] = [-1.6, -0.6, 0.6];
/// The SIMULATED hand's speed, as the trial's simulated operator (an unhurried reach) [m/s].
const HAND_SPEED_M_S: f64 = 0.6;

/// The SIMULATED operator's right hand.
#[derive(Debug, Clone, Copy)]
enum HandScript {
    /// Rests at [`HAND_REST`] until Present, then reaches beside the TCP, holds it until the
    /// release is confirmed, then goes back to rest.
    ReachWhenPresented,
    /// As `ReachWhenPresented`, and additionally, `after_s` into the Approach, reaches towards
    /// `intrusion` for `hold_s`, then goes back to rest.
    IntrudeDuringApproach {
        after_s: f64,
        hold_s: f64,
        intrusion: [f64; 3],
    },
    /// Nobody is tracked.
    Absent,
}

/// Where a run starts.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Start {
    /// At the task's home pose (the full task).
    Home,
    /// At the task's pick pose (the fetch is a zero-length move plus the grip dwell).
    Pick,
}

/// One cycle's record.
#[derive(Debug, Clone, Copy)]
struct Sample {
    t: f64,
    phase: Phase,
    /// Time scale after the step [-].
    s: f64,
    /// Measured TCP speed after the robot's cycle [m/s].
    tcp_speed: f64,
    /// Distance from the SIMULATED hand to the TCP [m].
    hand_to_tcp: f64,
}

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
    samples: Vec<Sample>,
    /// Largest commanded |q̇| [rad/s] and |q̈| [rad/s²] (the controller's own figures).
    max_cmd_speed: f64,
    max_cmd_acc: f64,
    /// Largest |second difference| / dt² of consecutive servo positions [rad/s²]: what the
    /// supervisor reads as the commanded acceleration.
    max_servo_acc: f64,
    /// Largest commanded TCP speed |J(q) q̇_cmd| during the approach [m/s].
    max_cmd_tcp_approach: f64,
    /// Servo positions of the last two cycles (None across a Stop).
    prev_servo: [Option<Joints>; 2],
    max_actual_speed: f64,
    /// Executed jerk from second differences of actual_qd [rad/s³], largest over the run.
    max_jerk: f64,
    qd_hist: [Option<Joints>; 2],
    /// The time scale's rate-limit fallbacks seen (must stay 0).
    scale_errors: u64,
}

impl Run {
    fn new(cfg: ControllerConfig, script: HandScript, start: Start) -> Run {
        let q0 = match start {
            Start::Home => cfg.task.home_q_rad,
            Start::Pick => cfg.task.pick_q_rad,
        };
        let robot = SimRobot::new(SimConfig {
            initial_q_rad: q0,
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
            hand: HAND_REST,
            script,
            approach_started_s: None,
            released: false,
            phases: Vec::new(),
            all_events: Vec::new(),
            samples: Vec::with_capacity(8192),
            max_cmd_speed: 0.0,
            max_cmd_acc: 0.0,
            max_servo_acc: 0.0,
            max_cmd_tcp_approach: 0.0,
            prev_servo: [None, None],
            max_actual_speed: 0.0,
            max_jerk: 0.0,
            qd_hist: [None, None],
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
        if let HandScript::Absent = self.script {
            return;
        }
        if let HandScript::IntrudeDuringApproach {
            after_s,
            hold_s,
            intrusion,
        } = self.script
            && phase == Phase::Approach
        {
            let t = now - self.approach_started_s.unwrap_or(now);
            let goal = if t >= after_s && t < after_s + hold_s {
                intrusion
            } else {
                HAND_REST
            };
            self.move_hand(goal, HAND_SPEED_M_S);
            return;
        }
        match phase {
            Phase::Present | Phase::Release if !self.released => {
                // Grasp a little beside the flange centre.
                let tcp = self.tcp();
                self.move_hand([tcp[0] - 0.03, tcp[1], tcp[2]], HAND_SPEED_M_S);
            }
            _ => self.move_hand(HAND_REST, HAND_SPEED_M_S),
        }
    }

    fn view(&self) -> OperatorView {
        match self.script {
            HandScript::Absent => OperatorView::default(),
            _ => OperatorView {
                body: HumanBody {
                    head_m: Some(HEAD),
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
        let view = self.view();
        self.ctl
            .step(now, &self.state, &self.adaptation, &view, &mut self.cmd);
        for e in self.ctl.events() {
            self.all_events.push((e.t_s, e.kind));
            if e.kind == TaskEventKind::ReleaseConfirmed {
                self.released = true;
            }
        }
        if self.ctl.phase() != before {
            self.phases.push((self.ctl.phase(), now));
        }
        // Commanded limits (a Stop hands braking to the robot; the next servo command resumes
        // from the robot's target state).
        let qd = *self.ctl.commanded_velocity();
        let qdd = *self.ctl.commanded_acceleration();
        if let JointCommand::Servo { q, .. } = self.cmd {
            for (v, a) in qd.iter().zip(&qdd) {
                self.max_cmd_speed = self.max_cmd_speed.max(v.abs());
                self.max_cmd_acc = self.max_cmd_acc.max(a.abs());
            }
            if let [Some(a), Some(b)] = self.prev_servo {
                for k in 0..6 {
                    let acc = (q[k] - 2.0 * b[k] + a[k]) / (DT * DT);
                    self.max_servo_acc = self.max_servo_acc.max(acc.abs());
                }
            }
            self.prev_servo = [self.prev_servo[1], Some(q)];
            if self.ctl.phase() == Phase::Approach {
                let tcp = flange_speed_m_s(&q, &qd);
                self.max_cmd_tcp_approach = self.max_cmd_tcp_approach.max(tcp);
            }
        } else {
            self.prev_servo = [None, None];
        }
        self.robot.send(&self.cmd).unwrap();
        self.robot.step();
        let s = *self.robot.state();
        for v in s.actual_qd {
            self.max_actual_speed = self.max_actual_speed.max(v.abs());
        }
        if let [Some(a), Some(b)] = self.qd_hist {
            for k in 0..6 {
                let j = (s.actual_qd[k] - 2.0 * b[k] + a[k]) / (DT * DT);
                self.max_jerk = self.max_jerk.max(j.abs());
            }
        }
        self.qd_hist = [self.qd_hist[1], Some(s.actual_qd)];
        let v = s.actual_tcp_speed;
        let tcp_speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        self.samples.push(Sample {
            t: now,
            phase: self.ctl.phase(),
            s: self.ctl.scale_report().scale,
            tcp_speed,
            hand_to_tcp: dist(&self.hand, &self.tcp()),
        });
        self.scale_errors = self.ctl.stats().fallback_steps;
    }

    /// Cycle until `done` holds after a cycle (panics after `max_s` of simulated time).
    fn run_until(&mut self, max_s: f64, mut done: impl FnMut(&Run) -> bool) {
        let cycles = (max_s / DT) as usize;
        for _ in 0..cycles {
            self.cycle();
            if done(self) {
                return;
            }
        }
        panic!(
            "not done within {max_s} s; phases {:?}, stats {:?}, scale {:?}",
            self.phases,
            self.ctl.stats(),
            self.ctl.scale_report()
        );
    }

    /// A run of `cfg` from home, 300 cycles into the handover (moving at speed), and the last
    /// servo position sent.
    fn moving(cfg: ControllerConfig, script: HandScript) -> (Run, Joints) {
        let mut run = Run::new(cfg, script, Start::Home);
        run.ctl.start_handover();
        run.run_until(1.0, |r| r.samples.len() == 300);
        assert!(run.state.actual_qd.iter().any(|v| v.abs() > 0.3), "moving");
        let Some(prev) = run.prev_servo[1] else {
            panic!("servoing")
        };
        (run, prev)
    }

    /// One controller step by hand at `now` [s] on a fresh state (not sent to the robot).
    fn step_at(&mut self, now: f64) {
        self.robot.read_state(&mut self.state).unwrap();
        let view = self.view();
        self.ctl
            .step(now, &self.state, &self.adaptation, &view, &mut self.cmd);
    }

    fn run_until_phase(&mut self, phase: Phase, max_s: f64) {
        self.ctl.start_handover();
        self.run_until(max_s, |r| r.ctl.phase() == phase);
    }

    fn phase_time(&self, phase: Phase) -> f64 {
        self.phases
            .iter()
            .find(|(p, _)| *p == phase)
            .unwrap_or_else(|| panic!("{phase} never entered: {:?}", self.phases))
            .1
    }

    fn approach_duration(&self) -> f64 {
        self.phase_time(Phase::Present) - self.phase_time(Phase::Approach)
    }

    /// Mean measured TCP speed over [from, to) [m/s].
    fn mean_tcp_speed(&self, from: f64, to: f64) -> f64 {
        let v: Vec<f64> = self
            .samples
            .iter()
            .filter(|s| s.t >= from && s.t < to)
            .map(|s| s.tcp_speed)
            .collect();
        assert!(!v.is_empty(), "no samples in [{from}, {to})");
        v.iter().sum::<f64>() / v.len() as f64
    }
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn at(q: &Joints, target: &Joints, tol: f64) -> bool {
    q.iter().zip(target).all(|(a, b)| (a - b).abs() < tol)
}

/// The nominal handover with the shipped config, from home, run once and shared by the tests
/// that need it (a debug build pays about 2 ms per simulated cycle).
fn nominal() -> &'static Run {
    static NOMINAL: OnceLock<Run> = OnceLock::new();
    NOMINAL.get_or_init(|| {
        let mut run = Run::new(
            shipped_config(),
            HandScript::ReachWhenPresented,
            Start::Home,
        );
        run.ctl.start_handover();
        run.run_until(30.0, |r| {
            // C(t) and G(t) follow the phase in every cycle (asserted again by the test).
            assert_eq!(r.ctl.collaborating(), r.ctl.phase().is_collaborating());
            r.ctl.phase() == Phase::Done
        });
        run
    })
}

// `Run` holds a `SimRobot` and a `Controller`; sharing it read-only across test threads
// needs both to be `Sync`, which the compiler checks here.
const _: fn() = || {
    fn sync<T: Sync>() {}
    sync::<Run>();
};

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
    // The SIMULATED operator's geometry of the module docs.
    let handover = robot_io::kinematics::flange_pose(&cfg.task.handover_q_rad)
        .translation
        .vector;
    let handover = [handover.x, handover.y, handover.z];
    assert!((dist(&HAND_REST, &handover) - 0.792).abs() < 1e-3);
    assert!((dist(&HEAD, &handover) - 1.054).abs() < 1e-3);
}

#[test]
fn full_handover_closed_loop_reaches_done_within_limits() {
    let run = nominal();
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
    assert!(
        at(&run.state.actual_q, &home, 0.01),
        "{:?}",
        run.state.actual_q
    );
    // Commanded limits: |q̇| ≤ π rad/s, |q̈| ≤ 0.95 π rad/s² (the planner keeps 5 % under the
    // supervisor's π rad/s²), and the servo positions' second differences (what the supervisor
    // judges) within π rad/s².
    let tol = 1e-6;
    assert!(
        run.max_cmd_speed <= PI + tol,
        "cmd speed {}",
        run.max_cmd_speed
    );
    assert!(
        run.max_cmd_acc <= 0.95 * PI + tol,
        "cmd acc {}",
        run.max_cmd_acc
    );
    assert!(run.max_servo_acc <= PI, "servo acc {}", run.max_servo_acc);
    assert!(
        run.max_actual_speed <= PI + tol,
        "speed {}",
        run.max_actual_speed
    );
    // The TCP stays under the planning fraction of the collaboration cap during the approach:
    // 0.9 × 0.25 m/s.
    assert!(
        run.max_cmd_tcp_approach <= 0.225 + 1e-3,
        "approach TCP {}",
        run.max_cmd_tcp_approach
    );
    // Executed jerk (second differences of the robot's actual_qd) within 1.1 × the planner's
    // jerk limit (shipped config: 29.85 rad/s³).
    let limit = run.ctl.jerk_limit_rad_s3();
    assert!((limit - 29.84513).abs() < 1e-9, "{limit}");
    assert!(
        run.max_jerk <= 1.1 * limit,
        "jerk {} vs {limit}",
        run.max_jerk
    );
    // The grasp came from the SIMULATED hand at the presented TCP.
    assert!(
        run.all_events
            .iter()
            .any(|(_, k)| *k == TaskEventKind::GraspDetected { hand: 1 })
    );
    let stats = run.ctl.stats();
    assert_eq!(stats.otg_errors, 0, "{stats:?}");
    assert_eq!(stats.fallback_steps, 0, "{stats:?}");
    assert_eq!(stats.missed_cycles, 0, "{stats:?}");
    assert_eq!(
        stats.resyncs, 1,
        "only the initial synchronisation: {stats:?}"
    );
    eprintln!(
        "handover: phases {:?}; max cmd speed {:.3} rad/s, acc {:.3} rad/s² (servo {:.3}); \
         approach TCP {:.3} m/s; actual speed {:.3}; jerk {:.2} rad/s³ (limit {limit:.2}); {stats:?}",
        run.phases,
        run.max_cmd_speed,
        run.max_cmd_acc,
        run.max_servo_acc,
        run.max_cmd_tcp_approach,
        run.max_actual_speed,
        run.max_jerk,
    );
}

#[test]
fn context_c_and_g_follow_the_phase_in_closed_loop() {
    let run = nominal();
    // C(t) was checked against the phase in every cycle while running; G(t) is the
    // incompleteness: true until the release is confirmed, false from then on.
    let confirmed = run
        .all_events
        .iter()
        .find(|(_, k)| *k == TaskEventKind::ReleaseConfirmed)
        .expect("release confirmed")
        .0;
    let retreat = run.phase_time(Phase::Retreat);
    assert_eq!(confirmed, retreat, "Release → Retreat on the confirmation");
    let (approach, release) = (
        run.phase_time(Phase::Approach),
        run.phase_time(Phase::Release),
    );
    for s in &run.samples {
        let collaborating = s.t >= approach && s.t < retreat;
        assert_eq!(s.phase.is_collaborating(), collaborating, "t = {}", s.t);
        if s.t >= release && s.t < retreat {
            assert_eq!(s.phase, Phase::Release);
        }
    }
    assert!(!run.ctl.incomplete() && !run.ctl.collaborating());
    // A fresh task is incomplete and not collaborating.
    let ctl = Controller::new(ControllerConfig::example()).unwrap();
    assert!(ctl.incomplete() && !ctl.collaborating());
}

#[test]
fn the_hand_rests_outside_the_protective_distance_and_the_approach_runs_unscaled() {
    // With the hand at rest 0.79 m away, the approach is not slowed by separation until the
    // arm comes within reach of it: the time scale is 1 for the first 2 s of the approach and
    // the part is presented within 5 s; the robot waits for the hand only while it grasps and
    // withdraws.
    let run = nominal();
    let approach = run.phase_time(Phase::Approach);
    let early: Vec<&Sample> = run
        .samples
        .iter()
        .filter(|s| s.t >= approach && s.t < approach + 2.0)
        .collect();
    assert!(
        early.iter().all(|s| s.s > 1.0 - 1e-9),
        "scaled early in the approach"
    );
    let t = run.approach_duration();
    assert!(t < 5.0, "approach {t} s");
    // While presenting, the hand came to the TCP (within r_grasp = 0.08 m).
    let closest = run
        .samples
        .iter()
        .filter(|s| s.phase == Phase::Present)
        .map(|s| s.hand_to_tcp)
        .fold(f64::INFINITY, f64::min);
    assert!(closest < 0.08, "{closest}");
}

#[test]
fn the_robot_slows_when_a_hand_approaches_during_approach() {
    // The approach twice from the pick pose, without and with a SIMULATED hand that, 0.4 s into
    // the approach, reaches 0.45 m short of the handover flange position (well inside the
    // distance the planner keeps from a moving arm) for 1.5 s, then withdraws.
    let cfg = ControllerConfig::example();
    let mut free = Run::new(cfg.clone(), HandScript::ReachWhenPresented, Start::Pick);
    free.run_until_phase(Phase::Present, 15.0);
    let intrusion = [-1.15, -0.3, 0.25];
    let mut blocked = Run::new(
        cfg,
        HandScript::IntrudeDuringApproach {
            after_s: 0.4,
            hold_s: 1.5,
            intrusion,
        },
        Start::Pick,
    );
    blocked.run_until_phase(Phase::Present, 25.0);

    let (t_free, t_blocked) = (free.approach_duration(), blocked.approach_duration());
    assert!(
        t_blocked > t_free + 0.3,
        "approach {t_free:.3} s free vs {t_blocked:.3} s with the hand"
    );
    // While the hand is in the path, the TCP is slower than at the same time without it, and
    // the time scale is below 1.
    let start_free = free.phase_time(Phase::Approach);
    let start_blocked = blocked.phase_time(Phase::Approach);
    let (from, to) = (0.9, 1.6);
    let v_free = free.mean_tcp_speed(start_free + from, start_free + to);
    let v_blocked = blocked.mean_tcp_speed(start_blocked + from, start_blocked + to);
    assert!(
        v_blocked < 0.5 * v_free,
        "mean TCP speed {v_free:.3} m/s free vs {v_blocked:.3} m/s with the hand"
    );
    let min_scale = |r: &Run| {
        r.samples
            .iter()
            .filter(|s| s.phase == Phase::Approach)
            .map(|s| s.s)
            .fold(f64::INFINITY, f64::min)
    };
    let (s_free, s_min) = (min_scale(&free), min_scale(&blocked));
    assert!(s_min < 0.5, "time scale {s_min}");
    assert!(blocked.ctl.stats().scaled_steps > 0);
    // Without the intrusion only the hand at rest 0.79 m from the handover pose slows the last
    // few centimetres a little.
    assert!(s_free > 0.8, "free approach scaled to {s_free}");
    // It resumes: after the hand has withdrawn, the scale is back at 1 before the arrival.
    let withdrawn = start_blocked + 0.4 + 1.5 + 1.5;
    let resumed = blocked
        .samples
        .iter()
        .filter(|s| s.phase == Phase::Approach && s.t > withdrawn)
        .any(|s| s.s > 1.0 - 1e-9);
    assert!(resumed, "the scale never came back to 1");
    assert_eq!(
        blocked.scale_errors, 0,
        "the time scale's trajectory never failed"
    );
    // Within the limits throughout.
    assert!(
        blocked.max_cmd_acc <= 0.95 * PI + 1e-6,
        "{}",
        blocked.max_cmd_acc
    );
    assert!(blocked.max_servo_acc <= PI, "{}", blocked.max_servo_acc);
    assert!(blocked.max_cmd_speed <= PI + 1e-6);
    assert!(blocked.max_cmd_tcp_approach <= 0.225 + 1e-3);
    let limit = blocked.ctl.jerk_limit_rad_s3();
    assert!(
        blocked.max_jerk <= 1.1 * limit,
        "jerk {} vs {limit}",
        blocked.max_jerk
    );
    eprintln!(
        "approach {t_free:.3} s free vs {t_blocked:.3} s with the hand; TCP {v_free:.3} vs \
         {v_blocked:.3} m/s; min scale {s_free:.3} vs {s_min:.3}; jerk {:.2}; {:?}",
        blocked.max_jerk,
        blocked.ctl.stats()
    );
}

#[test]
fn timeout_returns_the_part_to_the_pick_pose() {
    // Nobody comes: after present_timeout_s (shortened to 1 s here) the part goes back to the
    // pick pose, and G(t) stays true.
    let mut cfg = ControllerConfig::example();
    cfg.task.present_timeout_s = 1.0;
    let mut run = Run::new(cfg, HandScript::Absent, Start::Pick);
    run.run_until_phase(Phase::Done, 20.0);
    let timeout = run
        .all_events
        .iter()
        .find(|(_, k)| *k == TaskEventKind::PresentTimeout)
        .expect("a timeout")
        .0;
    assert!((timeout - run.phase_time(Phase::Present) - 1.0).abs() < 1e-9);
    assert_eq!(run.phase_time(Phase::Retreat), timeout);
    assert!(run.ctl.incomplete());
    assert!(run.ctl.task().part_returned());
    let pick = run.ctl.config().task.pick_q_rad;
    assert!(
        at(&run.state.actual_q, &pick, 0.01),
        "{:?}",
        run.state.actual_q
    );
}

#[test]
fn adaptation_speed_scale_and_minimum_approach_duration_stretch_the_approach() {
    // The approach is planned under the planning fraction of the collaboration cap, 0.9 ×
    // 0.25 = 0.225 m/s at the TCP, so a speed scale only stretches it once scale × 1 m/s is
    // below that: 0.15 caps the TCP at 0.15 m/s and the joints at 0.15 π rad/s, and the
    // cruise takes 0.225/0.15 = 1.5 × as long. A smoothness of 0.5 halves the acceleration and
    // quarters the jerk. (The nominal approach is the shared run's, with the shipped config;
    // the example's approach path is the same and also planned under 0.225 m/s.)
    let cfg = ControllerConfig::example();
    let nominal = nominal().approach_duration();
    let mut slow = Run::new(cfg.clone(), HandScript::ReachWhenPresented, Start::Pick);
    slow.adaptation.speed_scale = SpeedScale::new(0.15).unwrap();
    slow.adaptation.smoothness_scale = SmoothnessScale::new(0.5).unwrap();
    slow.run_until_phase(Phase::Present, 20.0);
    let mut timed = Run::new(cfg, HandScript::ReachWhenPresented, Start::Pick);
    timed.adaptation.min_approach_duration = Duration::from_secs_f64(4.5);
    timed.adaptation.start_delay = Duration::from_secs_f64(1.0);
    timed.run_until_phase(Phase::Present, 20.0);

    let t_slow = slow.approach_duration();
    assert!(t_slow > 1.3 * nominal, "approach {t_slow} s vs {nominal} s");
    assert!(
        slow.max_cmd_speed <= 0.15 * PI + 1e-6,
        "{}",
        slow.max_cmd_speed
    );
    assert!(
        slow.max_cmd_tcp_approach <= 0.15 + 1e-3,
        "{}",
        slow.max_cmd_tcp_approach
    );
    // Smoothness 0.5 (by hand): the path gets 0.6 × min(0.5 π, 0.95 π) = 0.3 π rad/s² and the
    // time scale 0.4 × 0.5 π = 0.2 π, together 0.5 π; the jerk limit is 10 π × 0.5².
    assert!(slow.max_cmd_acc <= 0.5 * PI + 1e-6, "{}", slow.max_cmd_acc);
    let limit = slow.ctl.jerk_limit_rad_s3();
    assert!((limit - 10.0 * PI * 0.25).abs() < 1e-9, "{limit}");
    assert!(
        slow.max_jerk <= 1.1 * limit,
        "jerk {} vs {limit}",
        slow.max_jerk
    );
    // The minimum duration: the approach takes 4.5 s (+ the 0.25 s settle dwell and the servo
    // lag), and starts 1 s after the part is gripped.
    let t = timed.approach_duration();
    assert!(
        (4.5..5.0).contains(&t),
        "approach took {t} s with a 4.5 s minimum"
    );
    let gripped = timed
        .all_events
        .iter()
        .find(|(_, k)| *k == TaskEventKind::PartGripped)
        .unwrap()
        .0;
    assert!((timed.phase_time(Phase::Approach) - gripped - 1.0).abs() < 0.01);
    eprintln!(
        "approach: nominal {nominal:.3} s, speed 0.15/smooth 0.5 {t_slow:.3} s, min 4.5 s {t:.3} s"
    );
}

#[test]
fn wait_for_attention_holds_at_the_pick_pose_in_closed_loop() {
    let mut run = Run::new(
        ControllerConfig::example(),
        HandScript::ReachWhenPresented,
        Start::Pick,
    );
    run.adaptation.wait_for_attention = true;
    run.adaptation.attention_on_robot = false;
    run.run_until_phase(Phase::WaitForAttention, 3.0);
    // Held for 1 s at the pick pose, at rest.
    let entered = run.state.timestamp_s;
    run.run_until(1.0 + DT, |r| r.state.timestamp_s >= entered + 1.0);
    assert_eq!(run.ctl.phase(), Phase::WaitForAttention);
    let pick = run.ctl.config().task.pick_q_rad;
    assert!(
        at(&run.state.actual_q, &pick, 1e-3),
        "{:?}",
        run.state.actual_q
    );
    assert!(run.state.actual_qd.iter().all(|v| v.abs() < 1e-6));
    // Attention on the robot: the approach starts and the arm leaves the pick pose.
    run.adaptation.attention_on_robot = true;
    run.run_until(2.0, |r| r.ctl.phase() == Phase::Approach);
    run.run_until(2.0, |r| !at(&r.state.actual_q, &pick, 0.05));
    assert_eq!(run.ctl.phase(), Phase::Approach);
}

#[test]
fn a_safety_stop_outputs_stop_and_resumes_after_recovery() {
    let mut run = Run::new(
        ControllerConfig::example(),
        HandScript::ReachWhenPresented,
        Start::Home,
    );
    run.ctl.start_handover();
    // 0.6 s into the fetch (moving), a protective stop for 0.4 s.
    run.run_until(1.0, |r| r.samples.len() == 300);
    assert!(run.state.actual_qd.iter().any(|v| v.abs() > 0.3), "moving");
    run.robot.inject_protective_stop();
    run.run_until(1.0, |r| r.samples.len() == 500);
    assert!(matches!(run.cmd, JointCommand::Stop { .. }));
    assert!(run.ctl.stats().stop_steps >= 199, "{:?}", run.ctl.stats());
    assert!(
        run.state.actual_qd.iter().all(|v| *v == 0.0),
        "braked to rest"
    );
    assert!(run.robot.clear_protective_stop());
    run.robot.play();
    let resyncs = run.ctl.stats().resyncs;
    // It resumes from where it stopped and completes the fetch within the limits.
    run.run_until(6.0, |r| r.ctl.phase() == Phase::Approach);
    assert!(run.ctl.stats().resyncs > resyncs);
    assert!(run.max_cmd_acc <= 0.95 * PI + 1e-6, "{}", run.max_cmd_acc);
    assert!(run.max_servo_acc <= PI, "{}", run.max_servo_acc);
    let pick = run.ctl.config().task.pick_q_rad;
    assert!(at(&run.state.actual_q, &pick, 0.01));
}

#[test]
fn non_finite_inputs_do_not_panic() {
    let mut ctl = Controller::new(ControllerConfig::example()).unwrap();
    ctl.start_handover();
    let mut state = RobotState {
        actual_q: ctl.config().task.home_q_rad,
        target_q: ctl.config().task.home_q_rad,
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
    match cmd {
        JointCommand::Servo { q, .. } => {
            assert!(q.iter().all(|v| v.is_finite()));
            // Nothing usable about the operator: the time scale brakes to (stays at) 0.
            assert_eq!(ctl.scale_report().scale, 0.0, "{:?}", ctl.scale_report());
            assert!(ctl.commanded_velocity().iter().all(|v| *v == 0.0));
        }
        other => panic!("a servo hold expected, got {other:?}"),
    }
    state.actual_q[2] = f64::NAN;
    ctl.step(0.002, &state, &MotionAdaptation::default(), &nan, &mut cmd);
    assert!(matches!(cmd, JointCommand::Stop { .. }));
    assert_eq!(ctl.stats().stop_steps, 1);
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
    // Unknown keys are refused, in the planning table too.
    let bad = SHIPPED.replace("servo_gain = 500.0", "servo_gain = 500.0\nservo_gian = 1.0");
    assert!(toml::from_str::<RawHandoverFile>(&bad).is_err());
    let bad = SHIPPED.replace(
        "speed_fraction = 0.9",
        "speed_fraction = 0.9\nspeed_fractoin = 0.8",
    );
    assert!(toml::from_str::<RawHandoverFile>(&bad).is_err());
    // The planning fraction must be in (0, 1): using the supervisor's caps exactly is refused.
    let file: RawHandoverFile =
        toml::from_str(&SHIPPED.replace("speed_fraction = 0.9 ", "speed_fraction = 1.0 ")).unwrap();
    let err = ControllerConfig::try_from(&file.controller).unwrap_err();
    assert!(err.to_string().contains("planning.speed_fraction"), "{err}");
    let file: RawHandoverFile = toml::from_str(
        &SHIPPED.replace("max_scale_rate_per_s = 4.0", "max_scale_rate_per_s = 0.0"),
    )
    .unwrap();
    let err = ControllerConfig::try_from(&file.controller).unwrap_err();
    assert!(
        err.to_string().contains("planning.max_scale_rate_per_s"),
        "{err}"
    );
}

#[test]
fn after_a_reduction_it_continues_from_the_sent_command_not_a_step_back() {
    // A supervisor reduction while moving (here: half the step, as SAF-REQ-004 or -005 would
    // send it). The robot's reported target lags the servo command by the servo's smoothing
    // (about v·lookahead); re-planning from it commanded a step back of that lag — 0.0185 rad
    // in one cycle on the emulator, which the supervisor then stopped (SAF-REQ-004). The next
    // command must continue from what was sent, within one ordinary step.
    let (mut run, prev) = Run::moving(ControllerConfig::example(), HandScript::ReachWhenPresented);
    // One cycle by hand: the controller's command, sent with its step halved.
    let now = run.robot.state().timestamp_s;
    run.step_at(now);
    let JointCommand::Servo {
        q: asked,
        lookahead_s,
        gain,
    } = run.cmd
    else {
        panic!("a servo command")
    };
    let step: Joints = std::array::from_fn(|k| asked[k] - prev[k]);
    let normal = step.iter().fold(0.0f64, |m, d| m.max(d.abs()));
    let sent: Joints = std::array::from_fn(|k| prev[k] + 0.5 * step[k]);
    run.robot
        .send(&JointCommand::Servo {
            q: sent,
            lookahead_s,
            gain,
        })
        .unwrap();
    run.ctl.command_reduced(0.5);
    run.prev_servo = [Some(prev), Some(sent)];
    // The next command: within an ordinary step of what was sent, and onwards, not back.
    run.cycle();
    let JointCommand::Servo { q: next, .. } = run.cmd else {
        panic!("a servo command after the reduction: {:?}", run.cmd)
    };
    let lag: f64 = (0..6)
        .map(|k| (run.state.target_q[k] - sent[k]).abs())
        .fold(0.0, f64::max);
    assert!(
        lag > 5.0 * normal,
        "the robot's target lags the command: {lag} vs step {normal}"
    );
    for k in 0..6 {
        let d = next[k] - sent[k];
        assert!(
            d.abs() <= 1.5 * normal,
            "joint {k}: {d} rad after the reduction, an ordinary step is {normal}"
        );
        if step[k].abs() > 0.2 * normal {
            assert!(
                d * step[k] > 0.0,
                "joint {k} turned back: {d} after {}",
                step[k]
            );
        }
    }
    // And the fetch completes within the limits.
    run.run_until(6.0, |r| r.ctl.phase() == Phase::Approach);
    assert!(run.max_servo_acc <= PI, "{}", run.max_servo_acc);
}

/// After missed cycles the plan advances by the elapsed controller time, up to the envelope's
/// catch-up bound (the robot's servo extrapolation bound + 1; `safety::CatchUpCycles`). Moving
/// at speed, one step taken 10 cycles after the previous one commands, with the bound at 4,
/// exactly what a step taken 4 cycles after it commands (the robot held its target after its
/// extrapolation: the plan waits instead of jumping); with the bound at 16 the same 10-cycle
/// step goes further, as far as a 10-cycle step does there. The controller's stats count all
/// 9 missed cycles either way. SIMULATED robot.
#[test]
fn missed_cycles_advance_the_plan_by_at_most_the_catch_up_bound() {
    let command_after = |bound: u32, gap: u32| -> (Joints, Joints) {
        let mut cfg = ControllerConfig::example();
        cfg.envelope = cfg.envelope.with_catch_up_cycles(bound).unwrap();
        let (mut run, prev) = Run::moving(cfg, HandScript::Absent);
        let now = run.robot.state().timestamp_s + f64::from(gap - 1) * DT;
        run.step_at(now);
        let JointCommand::Servo { q, .. } = run.cmd else {
            panic!("a servo command")
        };
        // Every missed cycle is counted, also those the plan did not catch up.
        assert_eq!(run.ctl.stats().missed_cycles, u64::from(gap - 1));
        (prev, q)
    };
    let (prev, late) = command_after(4, 10);
    let (prev4, at_bound) = command_after(4, 4);
    assert_eq!(prev, prev4, "the runs are identical up to the gap");
    // Equal to rounding: the plan advances by the elapsed time as the supervisor judges it,
    // (3·DT added to a timestamp) / DT = 4 cycles to within 1e-12.
    let diff = (0..6).fold(0.0f64, |m, k| m.max((late[k] - at_bound[k]).abs()));
    assert!(
        diff < 1e-12,
        "a 10-cycle gap advances the plan 4 cycles: {late:?} vs {at_bound:?}"
    );
    let (prev16, wide) = command_after(16, 10);
    assert_eq!(prev16, prev);
    let step = |q: &Joints| (0..6).fold(0.0f64, |m, k| m.max((q[k] - prev[k]).abs()));
    assert!(
        step(&wide) > 2.0 * step(&late),
        "10 cycles of plan {} vs 4 cycles {}",
        step(&wide),
        step(&late)
    );
}
