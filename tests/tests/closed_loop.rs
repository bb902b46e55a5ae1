//! Cross-crate closed loop, wired as the trial runtime wires it (`src/trial/runtime.rs`):
//! `adapt::Controller` → `safety::Supervisor` → `robot_io::sim::SimRobot`, every command judged,
//! and `Controller::command_overridden` after a verdict that changed the command. The operator
//! is SIMULATED: a scripted head and right hand, no person and no perception.
//!
//! The SIMULATED hand rests 0.79 m from the handover flange position (outside the supervisor's
//! protective separation distance at rest, S_p = v_h·T_r + C + Z_d + Z_r = 2.0·0.1 + 0.17 =
//! 0.37 m, and the planner's 0.52 m with its margins) and reaches for the part only once it is
//! presented, at 0.6 m/s, as the trial's simulated operator does.

use std::cell::RefCell;
use std::rc::Rc;

use adapt::controller::{Controller, ControllerConfig, MotionAdaptation, OperatorView};
use adapt::envelope::SafetyEnvelope;
use adapt::task::{Phase, TaskEventKind};
use robot_io::geometry::{ARM_CAPSULES, BodyPart, Capsule, HumanBody, closest_approaches};
use robot_io::separation::protective_distance_m;
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Robot, RobotState};
use safety::{Requirement, Supervisor, SupervisorConfig, Verdict, Violation, WorldView};

const DT: f64 = 0.002;
/// Where the SIMULATED right hand rests: 0.79 m from the handover flange position
/// (−0.725, −0.133, 0.243) m of the example task.
const HAND_REST: [f64; 3] = [-1.45, -0.45, 0.2];
/// The SIMULATED head, 1.05 m from the handover flange position.
const HEAD: [f64; 3] = [-1.6, -0.6, 0.6];
/// The SIMULATED hand's reaching speed [m/s].
const HAND_SPEED_M_S: f64 = 0.6;
/// Joint speed above which a sample takes part in a velocity reversal [rad/s], and the window
/// of a reversal [s] (the trial's motion metrics).
const REVERSAL_MIN_SPEED_RAD_S: f64 = 0.03;
const REVERSAL_WINDOW_S: f64 = 0.3;
/// A stop window runs from a stop verdict to this long after the last one [s] (as the trial's
/// motion metrics).
const STOP_TAIL_S: f64 = 1.0;

/// `SimRobot` behind a shared handle, so the test can step it while the supervisor owns the
/// `Robot`.
#[derive(Debug, Clone)]
struct SharedSim(Rc<RefCell<SimRobot>>);

impl Robot for SharedSim {
    fn read_state(&mut self, out: &mut RobotState) -> robot_io::Result<()> {
        self.0.borrow_mut().read_state(out)
    }

    fn send(&mut self, cmd: &JointCommand) -> robot_io::Result<()> {
        self.0.borrow_mut().send(cmd)
    }
}

/// The planner's envelope from the supervisor's configuration (what the runtime does).
fn envelope_from(cfg: &SupervisorConfig) -> SafetyEnvelope {
    SafetyEnvelope::new(
        cfg.joint_rates.max_speed_rad_s(),
        cfg.joint_rates.max_acc_rad_s2(),
        cfg.joint_rates.stop_decel_rad_s2(),
        cfg.tcp_speed.m_s(),
        cfg.collaboration_tcp_speed.m_s(),
        cfg.stale_perception_scale.get(),
        cfg.staleness.perception_reduce_after_s(),
        cfg.separation,
        cfg.arm,
        cfg.body,
    )
    .unwrap()
}

/// The SIMULATED right hand's script.
#[derive(Debug, Clone, Copy)]
enum Hand {
    /// Rests until Present, reaches beside the TCP until the release is confirmed, goes back.
    ReachWhenPresented,
    /// As `ReachWhenPresented`; `after_s` into the approach it moves at `speed_m_s` to
    /// `point`, stays `hold_s`, then goes back to rest at the reaching speed.
    Intrude {
        after_s: f64,
        hold_s: f64,
        point: [f64; 3],
        speed_m_s: f64,
    },
}

/// One judged cycle.
#[derive(Debug, Clone, Copy)]
struct Cycle {
    t: f64,
    phase: Phase,
    verdict: Verdict,
    /// The state the command was judged on.
    state: RobotState,
    hand: [f64; 3],
}

struct Loop {
    sim: Rc<RefCell<SimRobot>>,
    sup: Supervisor<SharedSim>,
    ctl: Controller,
    script: Hand,
    /// Robot cycles per controller step (1: every cycle; 3: two missed cycles per step).
    period: usize,
    /// Every this many steps, a late sample: one step on the held state, the next on the late
    /// sample (its time a hair late by rounding), the one after it on a sample two cycles on.
    hiccup_every: Option<usize>,
    state: RobotState,
    cmd: JointCommand,
    hand: [f64; 3],
    approach_started_s: Option<f64>,
    released: bool,
    steps: usize,
    cycles: Vec<Cycle>,
    phases: Vec<(Phase, f64)>,
}

impl Loop {
    fn new(script: Hand, period: usize, start_at_pick: bool) -> Loop {
        let sup_cfg = SupervisorConfig::ur5e();
        let mut cfg = ControllerConfig::example();
        cfg.envelope = envelope_from(&sup_cfg);
        let q0 = if start_at_pick {
            cfg.task.pick_q_rad
        } else {
            cfg.task.home_q_rad
        };
        let sim = Rc::new(RefCell::new(
            SimRobot::new(SimConfig {
                initial_q_rad: q0,
                ..SimConfig::ur5e()
            })
            .unwrap(),
        ));
        let sup = Supervisor::new(SharedSim(sim.clone()), sup_cfg).unwrap();
        let mut ctl = Controller::new(cfg).unwrap();
        ctl.start_handover();
        Loop {
            sim,
            sup,
            ctl,
            script,
            period,
            hiccup_every: None,
            state: RobotState::default(),
            cmd: JointCommand::Stop { decel: 1.0 },
            hand: HAND_REST,
            approach_started_s: None,
            released: false,
            steps: 0,
            cycles: Vec::with_capacity(8192),
            phases: Vec::new(),
        }
    }

    fn move_hand(&mut self, goal: [f64; 3], speed: f64, dt: f64) {
        let d = dist(&self.hand, &goal);
        let step = speed * dt;
        if d <= step {
            self.hand = goal;
        } else {
            for (h, g) in self.hand.iter_mut().zip(goal) {
                *h += (g - *h) * step / d;
            }
        }
    }

    fn script_hand(&mut self, now: f64, dt: f64) {
        let phase = self.ctl.phase();
        if phase == Phase::Approach && self.approach_started_s.is_none() {
            self.approach_started_s = Some(now);
        }
        if let Hand::Intrude {
            after_s,
            hold_s,
            point,
            speed_m_s,
        } = self.script
            && let Some(start) = self.approach_started_s
            && now - start >= after_s
            && now - start < after_s + hold_s
        {
            self.move_hand(point, speed_m_s, dt);
            return;
        }
        match phase {
            Phase::Present | Phase::Release if !self.released => {
                let p = self.state.actual_tcp_pose;
                self.move_hand([p[0] - 0.03, p[1], p[2]], HAND_SPEED_M_S, dt);
            }
            _ => self.move_hand(HAND_REST, HAND_SPEED_M_S, dt),
        }
    }

    fn body(&self) -> HumanBody {
        HumanBody {
            head_m: Some(HEAD),
            left_hand_m: None,
            right_hand_m: Some(self.hand),
            torso: None,
        }
    }

    /// One controller step: the robot runs `period` cycles, then read → controller →
    /// supervisor → send.
    fn step(&mut self) {
        // (robot cycles to run, rounding on the sample's time [s])
        let (robot_cycles, rounding) = match self.hiccup_every.map(|n| self.steps % n) {
            _ if self.steps == 0 => (0, 0.0),
            // No new sample in time: this step runs on the held state.
            Some(1) => (0, 0.0),
            // The late sample, as the runtime's `timestamp − t0` can give it: 1e-13 s late.
            Some(2) => (1, 1e-13),
            // Caught up: the newest sample is two cycles on.
            Some(3) => (2, 0.0),
            _ => (self.period, 0.0),
        };
        for _ in 0..robot_cycles {
            self.sim.borrow_mut().step();
        }
        self.steps += 1;
        self.sup.read_state(&mut self.state).unwrap();
        let now = self.state.timestamp_s + rounding;
        self.script_hand(now, DT * self.period as f64);
        let before = self.ctl.phase();
        let body = self.body();
        let view = OperatorView {
            body,
            perception_age_s: 0.0,
        };
        self.ctl.step(
            now,
            &self.state,
            &MotionAdaptation::default(),
            &view,
            &mut self.cmd,
        );
        for e in self.ctl.events() {
            if e.kind == TaskEventKind::ReleaseConfirmed {
                self.released = true;
            }
        }
        if self.ctl.phase() != before {
            self.phases.push((self.ctl.phase(), now));
        }
        let world = WorldView {
            now_s: now,
            human: body,
            perception_age_s: 0.0,
            collaborating: self.ctl.collaborating(),
        };
        let verdict = self.sup.step(&self.cmd, &world);
        // As the runtime: a reduction by rounding alone does not count; a stop brakes first.
        match verdict {
            Verdict::Passed => {}
            Verdict::Reduced { scale, .. } => {
                if (scale - 1.0).abs() > 1e-6 {
                    self.ctl.command_reduced(scale);
                }
            }
            Verdict::Stopped { .. } | Verdict::Halted { .. } => self.ctl.command_overridden(),
        }
        self.cycles.push(Cycle {
            t: now,
            phase: self.ctl.phase(),
            verdict,
            state: self.state,
            hand: self.hand,
        });
    }

    fn run_until_done(&mut self, max_s: f64) {
        let steps = (max_s / (DT * self.period as f64)) as usize;
        for _ in 0..steps {
            self.step();
            if self.ctl.phase() == Phase::Done {
                return;
            }
        }
        panic!(
            "no Done within {max_s} s: phases {:?}, {:?}, counters {:?}",
            self.phases,
            self.ctl.stats(),
            self.sup.counters()
        );
    }

    /// Verdicts per requirement over every judged cycle.
    fn count(&self, r: Requirement) -> usize {
        self.cycles
            .iter()
            .filter(|c| c.verdict.requirement() == Some(r))
            .count()
    }

    /// Stop windows: from each stop verdict to STOP_TAIL_S after it, merged [s].
    fn stop_windows(&self) -> Vec<(f64, f64)> {
        let mut out: Vec<(f64, f64)> = Vec::new();
        for c in self.cycles.iter().filter(|c| c.verdict.is_stop()) {
            match out.last_mut() {
                Some(w) if c.t <= w.1 => w.1 = c.t + STOP_TAIL_S,
                _ => out.push((c.t, c.t + STOP_TAIL_S)),
            }
        }
        out
    }

    /// Velocity reversals of the measured joint speeds (a sample above 0.03 rad/s whose sign is
    /// opposite to the previous such sample at most 0.3 s earlier), at the completing sample's
    /// time, with the joint.
    fn reversals(&self) -> Vec<(f64, usize)> {
        let mut last: [Option<(f64, bool)>; 6] = [None; 6];
        let mut out = Vec::new();
        for c in &self.cycles {
            for (j, (l, qd)) in last.iter_mut().zip(c.state.actual_qd).enumerate() {
                if qd.abs() <= REVERSAL_MIN_SPEED_RAD_S {
                    continue;
                }
                let positive = qd > 0.0;
                if let Some((t, p)) = *l
                    && p != positive
                    && c.t - t <= REVERSAL_WINDOW_S + 1e-9
                {
                    out.push((c.t, j));
                }
                *l = Some((c.t, positive));
            }
        }
        out
    }

    /// Each SAF-REQ-007 verdict's body part, and that part's surface distance to the arm at the
    /// judged state's measured joints, with S_p at rest (v_r = 0, T_s = 0, fresh perception).
    fn separation_stops(&self) -> Vec<(f64, BodyPart, f64, f64)> {
        let cfg = SupervisorConfig::ur5e();
        let mut caps = [Capsule::point([0.0; 3], 0.0); ARM_CAPSULES];
        let mut out = Vec::new();
        for c in &self.cycles {
            let Some(Violation::Separation { part, .. }) = c.verdict.violation() else {
                continue;
            };
            cfg.arm.capsules(&c.state.actual_q, &mut caps);
            let body = HumanBody {
                right_hand_m: Some(c.hand),
                head_m: Some(HEAD),
                ..HumanBody::default()
            };
            let near = closest_approaches(&caps, &body, &cfg.body);
            let d = near[part.index()].unwrap().distance_m;
            let rest = protective_distance_m(&cfg.separation, part, 0.0, 0.0, 0.0);
            out.push((c.t, part, d, rest));
        }
        out
    }

    /// Largest executed jerk outside the stop windows [rad/s³], with its time [s]: from the
    /// measured joint speeds of three successive judged states with their real time steps,
    /// j = ((q̇₂ − q̇₁)/(t₂ − t₁) − (q̇₁ − q̇₀)/(t₁ − t₀)) / ((t₂ − t₀)/2), as the trial's motion
    /// metrics.
    fn max_jerk_outside_stops(&self) -> (f64, f64) {
        let windows = self.stop_windows();
        let mut worst = (0.0, 0.0);
        for w in self.cycles.windows(3) {
            let (a, b, c) = (&w[0], &w[1], &w[2]);
            if inside(&windows, a.t) || inside(&windows, c.t) {
                continue;
            }
            for j in 0..6 {
                let d1 = (b.state.actual_qd[j] - a.state.actual_qd[j]) / (b.t - a.t);
                let d2 = (c.state.actual_qd[j] - b.state.actual_qd[j]) / (c.t - b.t);
                let jerk = ((d2 - d1) / ((c.t - a.t) / 2.0)).abs();
                if jerk > worst.0 {
                    worst = (jerk, c.t);
                }
            }
        }
        worst
    }

    /// Velocity reversals outside the stop windows.
    fn reversals_outside_stops(&self) -> Vec<(f64, usize)> {
        let windows = self.stop_windows();
        self.reversals()
            .into_iter()
            .filter(|(t, _)| !inside(&windows, *t))
            .collect()
    }

    fn tcp_speed(c: &Cycle) -> f64 {
        let v = c.state.actual_tcp_speed;
        (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
    }
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn inside(windows: &[(f64, f64)], t: f64) -> bool {
    windows.iter().any(|(a, b)| t >= *a && t <= *b)
}

#[test]
fn planner_envelope_equals_the_supervisor_configuration() {
    let sup = SupervisorConfig::ur5e();
    let env = SafetyEnvelope::ur5e();
    assert_eq!(env, envelope_from(&sup));
    // Number by number, so a mismatch names itself.
    assert_eq!(env.joint_speed_rad_s(), sup.joint_rates.max_speed_rad_s());
    assert_eq!(
        env.joint_acceleration_rad_s2(),
        sup.joint_rates.max_acc_rad_s2()
    );
    assert_eq!(
        env.stop_deceleration_rad_s2(),
        sup.joint_rates.stop_decel_rad_s2()
    );
    assert_eq!(env.tcp_speed_m_s(), sup.tcp_speed.m_s());
    assert_eq!(
        env.collaboration_tcp_speed_m_s(),
        sup.collaboration_tcp_speed.m_s()
    );
    assert_eq!(
        env.stale_perception_scale(),
        sup.stale_perception_scale.get()
    );
    assert_eq!(
        env.perception_reduce_after_s(),
        sup.staleness.perception_reduce_after_s()
    );
    assert_eq!(env.separation(), &sup.separation);
    assert_eq!(env.arm(), &sup.arm);
    assert_eq!(env.body(), &sup.body);
    // And the values the crate docs state: π rad/s, π rad/s², π rad/s², 1 and 0.25 m/s, ×0.25
    // after 0.2 s.
    let pi = std::f64::consts::PI;
    assert_eq!(
        (
            env.joint_speed_rad_s(),
            env.joint_acceleration_rad_s2(),
            env.stop_deceleration_rad_s2()
        ),
        (pi, pi, pi)
    );
    assert_eq!(
        (env.tcp_speed_m_s(), env.collaboration_tcp_speed_m_s()),
        (1.0, 0.25)
    );
    assert_eq!(
        (
            env.stale_perception_scale(),
            env.perception_reduce_after_s()
        ),
        (0.25, 0.2)
    );
    // The example controller config plans inside the same envelope.
    assert_eq!(ControllerConfig::example().envelope, env);
}

#[test]
fn whole_handover_has_no_saf_req_003_004_005_and_saf_req_007_only_within_s_p_at_rest() {
    let mut run = Loop::new(Hand::ReachWhenPresented, 1, false);
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
    // Every cycle's verdict: no joint speed, acceleration or TCP speed correction at all.
    let n = run.cycles.len();
    for r in [
        Requirement::Saf003JointSpeed,
        Requirement::Saf004JointAcceleration,
        Requirement::Saf005TcpSpeed,
    ] {
        assert_eq!(run.count(r), 0, "{} in {n} cycles", r.id());
        assert_eq!(run.sup.counters().fired(r), 0, "{}", r.id());
    }
    // SAF-REQ-007 only while the hand is within S_p of the arm at rest (0.37 m for a hand):
    // while it grasps the presented part and until it has withdrawn.
    let stops = run.separation_stops();
    for (t, part, d, rest) in &stops {
        assert!(
            d < rest,
            "SAF-REQ-007 at {t:.3} s: {part} {d:.3} m from the arm, S_p at rest {rest:.3} m"
        );
    }
    let others: Vec<&Cycle> = run
        .cycles
        .iter()
        .filter(|c| {
            !matches!(c.verdict, Verdict::Passed)
                && c.verdict.requirement() != Some(Requirement::Saf007Separation)
        })
        .collect();
    assert!(
        others.is_empty(),
        "other interventions: {:?}",
        others.first()
    );
    // No velocity reversal, and the executed jerk within 1.1 × the planner's limit, outside
    // the stop windows.
    let windows = run.stop_windows();
    let reversals = run.reversals_outside_stops();
    assert!(
        reversals.is_empty(),
        "reversals {reversals:?} (stops {windows:?})"
    );
    let (jerk, at) = run.max_jerk_outside_stops();
    let limit = run.ctl.jerk_limit_rad_s3();
    assert!(
        jerk <= 1.1 * limit,
        "jerk {jerk:.1} rad/s³ at {at:.3} s, limit {limit:.1}"
    );
    eprintln!(
        "handover in {n} cycles: phases {:?}; {} SAF-REQ-007 stops in {:?}; jerk {jerk:.2} \
         rad/s³ (limit {limit:.2}); {:?}",
        run.phases,
        stops.len(),
        windows,
        run.ctl.stats()
    );
}

#[test]
fn saf_req_007_stops_a_fast_intrusion_and_the_motion_resumes_without_saf_req_004() {
    // 1.5 s into the approach the SIMULATED hand darts at 2.0 m/s (the standard's hand speed)
    // from rest to a point 0.3 m beside the approach path, faster than the planner can slow
    // the arm, stays 0.5 s and goes back to rest.
    let mut run = Loop::new(
        Hand::Intrude {
            after_s: 1.5,
            hold_s: 0.9,
            point: [-0.85, 0.05, 0.25],
            speed_m_s: 2.0,
        },
        1,
        true,
    );
    run.run_until_done(40.0);
    assert_eq!(run.count(Requirement::Saf004JointAcceleration), 0);
    assert_eq!(run.count(Requirement::Saf003JointSpeed), 0);
    assert_eq!(run.count(Requirement::Saf005TcpSpeed), 0);
    // The supervisor stopped the arm for the hand during the approach, while it was moving.
    let first = run
        .cycles
        .iter()
        .find(|c| {
            c.phase == Phase::Approach
                && matches!(
                    c.verdict,
                    Verdict::Stopped {
                        violation: Violation::Separation { .. }
                    }
                )
        })
        .expect("a SAF-REQ-007 stop during the approach");
    let moving = Loop::tcp_speed(first);
    assert!(moving > 0.02, "TCP at {moving} m/s when stopped");
    // The controller braked to rest (without fighting the stop) before it moved on.
    let rested = run
        .cycles
        .iter()
        .filter(|c| c.t > first.t && c.phase == Phase::Approach)
        .find(|c| c.state.actual_qd.iter().all(|v| v.abs() < 1e-3))
        .expect("at rest after the stop");
    let resumed = run
        .cycles
        .iter()
        .filter(|c| c.t > rested.t && c.phase == Phase::Approach)
        .any(|c| Loop::tcp_speed(c) > 0.1);
    assert!(resumed, "the approach resumed");
    assert!(run.ctl.stats().resyncs > 1, "{:?}", run.ctl.stats());
    // It finished the handover, smoothly outside the stops.
    assert!(!run.ctl.incomplete());
    let reversals = run.reversals_outside_stops();
    assert!(reversals.is_empty(), "reversals {reversals:?}");
    let (jerk, at) = run.max_jerk_outside_stops();
    let limit = run.ctl.jerk_limit_rad_s3();
    assert!(
        jerk <= 1.1 * limit,
        "jerk {jerk:.1} rad/s³ at {at:.3} s, limit {limit:.1}"
    );
    eprintln!(
        "intrusion: stopped at {:.3} s at {moving:.3} m/s, at rest at {:.3} s; {} SAF-REQ-007 \
         verdicts; phases {:?}; {:?}",
        first.t,
        rested.t,
        run.count(Requirement::Saf007Separation),
        run.phases,
        run.ctl.stats()
    );
}

#[test]
fn missed_cycles_cause_no_saf_req_003_004_005() {
    // The robot runs 3 cycles between the loop's reads (two missed control cycles per step):
    // every command is judged over the 6 ms since the previous one.
    let mut run = Loop::new(Hand::ReachWhenPresented, 3, false);
    run.run_until_done(40.0);
    assert!(run.ctl.stats().missed_cycles >= 2 * (run.steps as u64 - 1));
    for r in [
        Requirement::Saf003JointSpeed,
        Requirement::Saf004JointAcceleration,
        Requirement::Saf005TcpSpeed,
    ] {
        assert_eq!(run.count(r), 0, "{} in {} steps", r.id(), run.steps);
    }
    for (t, part, d, rest) in run.separation_stops() {
        assert!(
            d < rest,
            "SAF-REQ-007 at {t:.3} s: {part} {d:.3} m, S_p at rest {rest:.3} m"
        );
    }
    assert!(!run.ctl.incomplete());
    eprintln!(
        "missed cycles: {} steps, phases {:?}; {:?}",
        run.steps,
        run.phases,
        run.ctl.stats()
    );
}

#[test]
fn saf_req_004_a_late_sample_after_a_held_cycle_is_judged_over_the_time_the_plan_advanced() {
    // A sample that arrives late (the cycle that expected it ran on the held state), then a
    // skip: the controller and the supervisor must advance by the same time. When the
    // controller took a late sample a hair after its last step as "now", its plan ran one cycle
    // ahead of the supervisor's clock, and the next skip implied double the speed: SAF-REQ-004
    // reductions on the emulator at `--speedup 4`, every time a missed cycle followed a late
    // sample (`robot_io::cycle_time_s` is now the rule of both).
    let mut run = Loop::new(Hand::ReachWhenPresented, 1, false);
    run.hiccup_every = Some(7);
    run.run_until_done(40.0);
    let held = run
        .cycles
        .windows(2)
        .filter(|w| w[1].state.timestamp_s == w[0].state.timestamp_s)
        .count();
    assert!(held > 100, "{held} steps on a held state in {}", run.steps);
    for r in [
        Requirement::Saf003JointSpeed,
        Requirement::Saf004JointAcceleration,
        Requirement::Saf005TcpSpeed,
    ] {
        assert_eq!(run.count(r), 0, "{} in {} steps", r.id(), run.steps);
    }
    assert!(!run.ctl.incomplete());
}

#[test]
#[ignore = "open (issue 10): SimRobot commanded only every 3rd cycle sees a staircase of \
            targets, which its lookahead filter turns into velocity ripple (executed jerk 323 \
            rad/s³, limit 31.4, after the held-target fix in sim.rs; 1047 before). On the RTDE \
            path the robot-side program extrapolates late targets (robot_io::script); this \
            direct SimRobot loop has no such extrapolation"]
fn missed_cycles_keep_the_executed_motion_smooth() {
    // The motion-quality half of the missed-cycles acceptance, on SimRobot: with a command every
    // 3rd cycle, no velocity reversal and the executed jerk within 1.1 × the planner's limit
    // outside the stop windows (as with a command every cycle).
    let mut run = Loop::new(Hand::ReachWhenPresented, 3, false);
    run.run_until_done(40.0);
    let reversals = run.reversals_outside_stops();
    assert!(reversals.is_empty(), "reversals {reversals:?}");
    let (jerk, at) = run.max_jerk_outside_stops();
    let limit = run.ctl.jerk_limit_rad_s3();
    assert!(
        jerk <= 1.1 * limit,
        "jerk {jerk:.1} rad/s³ at {at:.3} s, limit {limit:.1}"
    );
}
