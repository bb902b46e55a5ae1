//! SAF-REQ-003/004 after missed cycles: a servo step is judged over the controller time since
//! the previous servo command (1 to `command_period_cycles`, 4 by default), not over one cycle. On `SimRobot` (2 ms mock
//! clock), the robot stepping several cycles between the supervisor's reads, as on a loaded
//! machine. Wrist 3 turns alone (it does not move the TCP, so SAF-REQ-005 stays out of it).
//! The figures are computed by hand in the comments.

mod common;

use std::cell::RefCell;
use std::f64::consts::PI;
use std::rc::Rc;

use common::{DT, Q_WORK, SharedSim, servo};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Joints, RobotState};
use safety::{
    CatchUpCycles, Requirement, Supervisor, SupervisorConfig, Verdict, Violation, WorldView,
};

/// The joint that turns: wrist 3.
const J: usize = 5;

struct Rig {
    sim: Rc<RefCell<SimRobot>>,
    sup: Supervisor<SharedSim>,
    state: RobotState,
}

impl Rig {
    fn with(cfg: SupervisorConfig) -> Rig {
        let sim = Rc::new(RefCell::new(
            SimRobot::new(SimConfig {
                initial_q_rad: Q_WORK,
                ..SimConfig::ur5e()
            })
            .unwrap(),
        ));
        let sup = Supervisor::new(SharedSim(sim.clone()), cfg).unwrap();
        Rig {
            sim,
            sup,
            state: RobotState::default(),
        }
    }

    /// Let the robot run `cycles` cycles, read its state, and judge the servo command `q`.
    fn command_after(&mut self, cycles: usize, q: Joints) -> Verdict {
        for _ in 0..cycles {
            self.sim.borrow_mut().step();
        }
        self.sup.read_state(&mut self.state).unwrap();
        self.sup
            .step(&servo(q), &WorldView::clear(self.state.timestamp_s))
    }

    fn sent(&self) -> Joints {
        match self.sup.last_sent().map(|c| *c.command()) {
            Some(JointCommand::Servo { q, .. }) => q,
            other => panic!("no servo command sent: {other:?}"),
        }
    }

    fn fired(&self, r: Requirement) -> u64 {
        self.sup.counters().fired(r)
    }
}

/// An upstream planner commanding every `period` cycles: wrist 3 accelerates at `acc`
/// [rad/s²] towards `speed` [rad/s]; `next` gives the positions of the next command.
struct Ramp {
    q: Joints,
    v: f64,
    speed: f64,
    acc: f64,
    period_s: f64,
}

impl Ramp {
    fn new(speed: f64, acc: f64, period: usize) -> Ramp {
        Ramp {
            q: Q_WORK,
            v: 0.0,
            speed,
            acc,
            period_s: DT * period as f64,
        }
    }

    fn next(&mut self) -> Joints {
        let dv = (self.speed - self.v).clamp(-self.acc * self.period_s, self.acc * self.period_s);
        self.v += dv;
        self.q[J] += self.v * self.period_s;
        self.q
    }
}

/// A hold at the start pose (the first servo command is judged from the robot's target state
/// over one cycle; it sets the reference for the elapsed-time rule).
fn started() -> Rig {
    started_with(SupervisorConfig::ur5e())
}

fn started_with(cfg: SupervisorConfig) -> Rig {
    let mut rig = Rig::with(cfg);
    assert_eq!(rig.command_after(0, Q_WORK), Verdict::Passed);
    rig
}

/// `command_period_cycles` = 8 (an emulator at speedup 2 extrapolates 7 cycles).
fn eight_cycles() -> SupervisorConfig {
    SupervisorConfig {
        command_period_cycles: CatchUpCycles::new(8).unwrap(),
        ..SupervisorConfig::ur5e()
    }
}

#[test]
fn saf_req_003_ramp_commanded_every_third_cycle_is_judged_over_the_elapsed_time() {
    // Every 3rd cycle (6 ms), wrist 3 ramps at 0.5 π rad/s² to 0.9 π rad/s and cruises: each
    // step is at most 0.9 π · 0.006 = 0.016965 rad. Judged over the 6 ms that elapsed, that is
    // 0.9 π rad/s < π: every command passes. (Divided by one 2 ms cycle, as before issue 10,
    // the same step read 0.016965 / 0.002 = 8.48 rad/s = 2.7 π and was reduced to
    // π / 8.48 = 0.370 of itself, SAF-REQ-003.)
    let mut rig = started();
    let mut ramp = Ramp::new(0.9 * PI, 0.5 * PI, 3);
    for k in 0..400 {
        // 1.8 s of ramp (300 commands), then cruise.
        let q = ramp.next();
        let v = rig.command_after(3, q);
        assert_eq!(v, Verdict::Passed, "command {k} at {} rad/s", ramp.v);
        assert_eq!(rig.sent(), q, "sent unchanged");
    }
    assert!((ramp.v - 0.9 * PI).abs() < 1e-12);
    assert_eq!(rig.fired(Requirement::Saf003JointSpeed), 0);
    assert_eq!(rig.fired(Requirement::Saf004JointAcceleration), 0);
    // Above the limit it is the true speed that is judged: ramping on past π rad/s, the first
    // command over π is reduced to π, and the violation reports the speed over 6 ms.
    let mut rig = started();
    let mut ramp = Ramp::new(1.05 * PI, 0.5 * PI, 3);
    loop {
        let q = ramp.next();
        let v = rig.command_after(3, q);
        if ramp.v <= PI {
            assert_eq!(v, Verdict::Passed, "at {} rad/s", ramp.v);
            continue;
        }
        match v {
            Verdict::Reduced {
                scale,
                violation:
                    Violation::JointSpeed {
                        joint,
                        value_rad_s,
                        limit_rad_s,
                    },
            } => {
                assert_eq!(joint, J);
                assert!(
                    (value_rad_s - ramp.v).abs() < 1e-9,
                    "{value_rad_s} vs {}",
                    ramp.v
                );
                assert_eq!(limit_rad_s, PI);
                assert!((scale - PI / ramp.v).abs() < 1e-9, "{scale}");
            }
            other => panic!("at {} rad/s: {other:?}", ramp.v),
        }
        break;
    }
    assert_eq!(rig.fired(Requirement::Saf003JointSpeed), 1);
}

#[test]
fn saf_req_003_a_gap_longer_than_the_command_period_is_judged_as_that_period() {
    // With `command_period_cycles` = 8: wrist 3 cruises at 0.99 π rad/s, commanded every 3rd cycle. Then 9 cycles pass without a
    // command, and the next one continues the motion: a step of 0.99 π · 0.018 = 0.055984 rad.
    // Judged over 8 cycles (16 ms, the longest period the rule allows), that is
    // 0.055984 / 0.016 = 3.49895 rad/s = 1.11375 π > π: reduced (conservative) to
    // π / 3.49895 = 0.897868, a step of π · 0.016 = 0.050265 rad. The acceleration check
    // allows this scale: |s · 3.49895 − 3.11018| ≤ π · 0.016 = 0.050265 for s in
    // [0.874524, 0.903250].
    let mut rig = started_with(eight_cycles());
    let mut ramp = Ramp::new(0.99 * PI, 0.5 * PI, 3);
    for _ in 0..400 {
        let q = ramp.next();
        assert_eq!(rig.command_after(3, q), Verdict::Passed);
    }
    assert!((ramp.v - 0.99 * PI).abs() < 1e-12);
    let from = rig.sent();
    let mut late = ramp;
    late.period_s = 9.0 * DT;
    let q = late.next();
    assert!((q[J] - from[J] - 0.055_984).abs() < 1e-6);
    match rig.command_after(9, q) {
        Verdict::Reduced {
            scale,
            violation: Violation::JointSpeed { value_rad_s, .. },
        } => {
            assert!((scale - 0.897_868).abs() < 1e-6, "{scale}");
            assert!((value_rad_s - 3.498_95).abs() < 1e-5, "{value_rad_s}");
        }
        other => panic!("{other:?}"),
    }
    let step = rig.sent()[J] - from[J];
    assert!((step - 0.050_265).abs() < 1e-6, "{step}");
    assert!(step < q[J] - from[J], "the bigger step is reduced");

    // The same step after exactly 8 cycles (0.99 π · 0.016 = 0.049763 rad) passes.
    let mut rig = started_with(eight_cycles());
    let mut ramp = Ramp::new(0.99 * PI, 0.5 * PI, 3);
    for _ in 0..400 {
        let q = ramp.next();
        assert_eq!(rig.command_after(3, q), Verdict::Passed);
    }
    ramp.period_s = 8.0 * DT;
    let q = ramp.next();
    assert_eq!(rig.command_after(8, q), Verdict::Passed);
    assert_eq!(rig.sent(), q);
}

/// The default, the UR5e's: `command_period_cycles` = 4 (our program extrapolates 3 cycles,
/// plus 1). At 0.99 π rad/s commanded every 3rd cycle, the motion continued after exactly 4
/// cycles passes; continued after 5 (a step of 0.99 π · 0.010 = 0.031102 rad) it is judged
/// over 4 cycles: 0.031102 / 0.008 = 3.88772 rad/s > π. Cut to π (scale 0.808081) the change
/// from the cruise's 3.11018 rad/s, π − 3.11018 = 0.031416 rad/s over the 7 ms between the
/// periods' middles ((6 + 8) / 2 ms), is 4.48799 rad/s² > π rad/s²: reduced to the largest
/// scale the acceleration limit allows, (3.11018 + π · 0.007) / 3.88772 = 0.805661 (by hand;
/// the supervisor keeps a small margin under it). Judged over 8 cycles it would have passed.
#[test]
fn saf_req_003_the_default_command_period_is_the_ur5e_extrapolation_bound_plus_one() {
    assert_eq!(SupervisorConfig::ur5e().command_period_cycles.get(), 4);
    let cruise = || {
        let mut ramp = Ramp::new(0.99 * PI, 0.5 * PI, 3);
        let mut rig = started();
        for _ in 0..400 {
            let q = ramp.next();
            assert_eq!(rig.command_after(3, q), Verdict::Passed);
        }
        (rig, ramp)
    };
    let (mut rig, mut ramp) = cruise();
    ramp.period_s = 4.0 * DT;
    let q = ramp.next();
    assert_eq!(rig.command_after(4, q), Verdict::Passed);
    let (mut rig, mut ramp) = cruise();
    ramp.period_s = 5.0 * DT;
    let q = ramp.next();
    match rig.command_after(5, q) {
        Verdict::Reduced {
            scale,
            violation:
                Violation::JointAcceleration {
                    joint,
                    value_rad_s2,
                    ..
                },
        } => {
            assert_eq!(joint, J);
            assert!((value_rad_s2 - 4.487_99).abs() < 1e-4, "{value_rad_s2}");
            assert!(scale <= 0.805_661 && scale > 0.805_6, "{scale}");
        }
        other => panic!("a 5-cycle step judged over 4 cycles: {other:?}"),
    }
}

#[test]
fn saf_req_004_ramp_commanded_every_third_cycle_is_judged_over_the_elapsed_time() {
    // The ramp at 0.5 π rad/s² commanded every 3rd cycle: the implied velocity grows by
    // 0.5 π · 0.006 = 0.009425 rad/s per command, over the 6 ms elapsed 0.5 π rad/s² < π.
    // (Over one 2 ms cycle, as before issue 10, both the steps and their change were divided
    // by 2 ms instead of 6 ms: (Δq_k − Δq_k−1) / 0.002² = a · 0.006² / 0.002² = 9 a =
    // 4.5 π rad/s², SAF-REQ-004 on every ramp command.)
    let mut rig = started();
    let mut ramp = Ramp::new(0.9 * PI, 0.5 * PI, 3);
    for _ in 0..320 {
        let q = ramp.next();
        assert_eq!(
            rig.command_after(3, q),
            Verdict::Passed,
            "at {} rad/s",
            ramp.v
        );
    }
    assert_eq!(rig.fired(Requirement::Saf004JointAcceleration), 0);

    // The same first ramp step one cycle after the hold: 0.009425 rad/s · 0.006 s =
    // 5.655e-5 rad read over 2 ms as 0.028274 rad/s from rest, 14.14 rad/s² = 4.5 π: reduced
    // to the acceleration limit, scale π · 0.002 / 0.028274 = 2/9 = 0.222222.
    let mut rig = started();
    let mut ramp = Ramp::new(0.9 * PI, 0.5 * PI, 3);
    let q = ramp.next();
    match rig.command_after(1, q) {
        Verdict::Reduced {
            scale,
            violation: Violation::JointAcceleration { value_rad_s2, .. },
        } => {
            assert!((scale - 2.0 / 9.0).abs() < 1e-6, "{scale}");
            assert!((value_rad_s2 - 4.5 * PI).abs() < 1e-6, "{value_rad_s2}");
        }
        other => panic!("{other:?}"),
    }
    // After 3 cycles it passes.
    let mut rig = started();
    let mut ramp = Ramp::new(0.9 * PI, 0.5 * PI, 3);
    assert_eq!(rig.command_after(3, ramp.next()), Verdict::Passed);

    // Above the limit the true acceleration is judged: a ramp at 1.2 π rad/s² every 3rd cycle
    // is reduced. Its first step changes the mean velocity from 0 (over the 2 ms of the start
    // command) to 1.2 π · 0.006 = 0.022619 rad/s (over the next 6 ms): the two means are
    // (2 + 6) / 2 = 4 ms apart, so the change reads 0.022619 / 0.004 = 5.655 rad/s² = 1.8 π
    // (not 9 × 1.2 π as over one cycle).
    let mut rig = started();
    let mut ramp = Ramp::new(0.9 * PI, 1.2 * PI, 3);
    match rig.command_after(3, ramp.next()) {
        Verdict::Reduced {
            violation: Violation::JointAcceleration { value_rad_s2, .. },
            ..
        } => assert!((value_rad_s2 - 1.8 * PI).abs() < 1e-6, "{value_rad_s2}"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn saf_req_004_a_gap_longer_than_the_command_period_is_judged_as_that_period() {
    // With `command_period_cycles` = 8: wrist 3 cruises at 0.5 π rad/s (every 3rd cycle), then 12 cycles pass and the next
    // command continues the motion: a step of 0.5 π · 0.024 = 0.037699 rad. Judged over 8
    // cycles (16 ms) it implies 2.35619 rad/s = 0.75 π, a change of 0.25 π rad/s from the
    // previous 1.570796 rad/s between the middles of the two periods, (6 + 16) / 2 = 11 ms
    // apart (71.4 rad/s²): reduced to the largest scale the acceleration limit allows,
    // s = (1.570796 + π · 0.011) / 2.35619 = 0.681333, a step of
    // 0.681333 · 2.35619 · 0.016 = 0.025686 rad. Judged over the real 24 ms it would have
    // passed (0.5 π rad/s, no change): a longer gap is judged conservatively.
    let mut rig = started_with(eight_cycles());
    let mut ramp = Ramp::new(0.5 * PI, 0.5 * PI, 3);
    for _ in 0..200 {
        let q = ramp.next();
        assert_eq!(rig.command_after(3, q), Verdict::Passed);
    }
    assert!((ramp.v - 0.5 * PI).abs() < 1e-12);
    let from = rig.sent();
    ramp.period_s = 12.0 * DT;
    let q = ramp.next();
    assert!((q[J] - from[J] - 0.037_699).abs() < 1e-6);
    match rig.command_after(12, q) {
        Verdict::Reduced {
            scale,
            violation: Violation::JointAcceleration { joint, .. },
        } => {
            assert_eq!(joint, J);
            assert!((scale - 0.681_333).abs() < 1e-6, "{scale}");
        }
        other => panic!("{other:?}"),
    }
    let step = rig.sent()[J] - from[J];
    assert!((step - 0.025_686).abs() < 1e-6, "{step}");
    assert_eq!(rig.fired(Requirement::Saf004JointAcceleration), 1);
    assert_eq!(rig.fired(Requirement::Saf003JointSpeed), 0);
}

#[test]
fn saf_req_004_a_cycle_run_on_a_held_state_still_counts_as_a_cycle() {
    // Wrist 3 ramps at 0.5 π rad/s² to 0.9 π rad/s, one command per cycle. Once, the state
    // is not renewed (the RTDE sample is late): the runtime runs that cycle on the held state
    // and commands the next 2 ms step; the state after it is 2 cycles newer than the one
    // before. Each command stands for one cycle: the held one for the held timestamp + 2 ms,
    // the next for the new timestamp, 2 ms later — steps of one cycle each, no acceleration
    // jump. (Timing the held one at the held timestamp, as before, read the next step as one
    // cycle of motion over 4 ms: its mean velocity halved, a change of ≈ 0.45 π rad/s within
    // 2 ms ≈ 700 rad/s², which the supervisor met by stretching that step.)
    let mut rig = started();
    let mut ramp = Ramp::new(0.9 * PI, 0.5 * PI, 1);
    for _ in 0..1000 {
        assert_eq!(rig.command_after(1, ramp.next()), Verdict::Passed);
    }
    assert!((ramp.v - 0.9 * PI).abs() < 1e-12, "cruising: {}", ramp.v);
    // Each command goes out exactly as asked (no verdict, and no silent change either: the
    // old timing made the supervisor stretch the next step by ≈ 2 to keep its deceleration
    // within π rad/s², which it reports as Passed).
    for (cycles, what) in [(0, "held state"), (2, "after it"), (1, "next"), (1, "next")] {
        let q = ramp.next();
        assert_eq!(rig.command_after(cycles, q), Verdict::Passed, "{what}");
        assert!(
            (rig.sent()[J] - q[J]).abs() < 1e-12,
            "{what}: sent {:?}, asked {q:?}",
            rig.sent()
        );
    }
    assert_eq!(rig.fired(Requirement::Saf004JointAcceleration), 0);
}

#[test]
fn saf_req_004_a_stop_harder_than_the_limit_is_slowed_at_the_limit_and_reported() {
    // Wrist 3 cruises at 0.9 π rad/s; then the planner commands 0.1 π rad/s at once. Stopping
    // that fast needs ≈ 0.8 π rad/s in one cycle (≈ 1250 rad/s²). The supervisor slows the joint
    // at its acceleration limit instead, along the commanded direction — so it sends *more*
    // speed than asked (scale > 1). That changes the command, so it must be reported: a
    // reduction citing SAF-REQ-004, never `Passed` (it used to pass silently).
    let mut rig = started();
    let mut ramp = Ramp::new(0.9 * PI, 0.5 * PI, 1);
    for _ in 0..1000 {
        assert_eq!(rig.command_after(1, ramp.next()), Verdict::Passed);
    }
    let before = rig.sent();
    let mut abrupt = before;
    abrupt[J] += 0.1 * PI * 0.002;
    let verdict = rig.command_after(1, abrupt);
    let Verdict::Reduced { scale, violation } = verdict else {
        panic!("an abrupt stop passed as {verdict:?}")
    };
    assert!(scale > 1.0, "scale {scale}");
    assert_eq!(
        violation.requirement(),
        Requirement::Saf004JointAcceleration,
        "{violation:?}"
    );
    assert_eq!(rig.fired(Requirement::Saf004JointAcceleration), 1);
    // What went out: slower than before, faster than asked, and within the acceleration limit.
    let step = rig.sent()[J] - before[J];
    assert!(
        step < 0.9 * PI * 0.002 && step > 0.1 * PI * 0.002,
        "step {step}"
    );
}
