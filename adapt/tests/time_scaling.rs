//! Time scaling along a jerk-limited path (`adapt::path`), the planner's admissible scale
//! (`adapt::envelope`) and the controller's catch-up after missed cycles: hand-computed worked
//! examples (the arithmetic is in the comments) and property tests.
//!
//! Nothing here is a measurement of a person: the hands are points placed by the tests, and the
//! closed-loop run uses `robot_io::sim::SimRobot` with nobody tracked.

use std::f64::consts::PI;

use adapt::controller::{Controller, ControllerConfig, MotionAdaptation, OperatorView};
use adapt::envelope::{
    Binding, Envelope, PlanningMargins, SafetyEnvelope, flange_speed_m_s, largest_root_below,
};
use adapt::otg::MotionLimits;
use adapt::path::{Path, PathSample, PathState, ScaleLimits, TimeScale, scale_limits_for};
use adapt::task::Phase;
use proptest::prelude::*;
use robot_io::geometry::{ARM_CAPSULES, ArmLink, BodyPart, Capsule, HumanBody, closest_approaches};
use robot_io::separation::protective_distance_m;
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Joints, Robot, RobotState};

const DT: f64 = 0.002;

// --- ScaleLimits and TimeScale: worked examples ---

#[test]
fn scale_limits_are_validated() {
    for (rate, accel) in [
        (0.0, 1.0),
        (1.0, 0.0),
        (-1.0, 1.0),
        (f64::NAN, 1.0),
        (1.0, f64::INFINITY),
    ] {
        assert!(ScaleLimits::new(rate, accel).is_err(), "{rate} {accel}");
    }
    let err = ScaleLimits::new(0.0, 1.0).unwrap_err().to_string();
    assert!(err.contains("scale_rate"), "{err}");
    let err = ScaleLimits::new(1.0, -2.0).unwrap_err().to_string();
    assert!(err.contains("scale_accel"), "{err}");
    let l = ScaleLimits::new(1.5, 12.0).unwrap();
    assert_eq!((l.rate(), l.accel()), (1.5, 12.0));
}

#[test]
fn reachable_drop_and_full_stop_worked_example() {
    // By hand: ṡ_max = 1 /s, s̈_max = 4 /s²: the rate builds up in 1/4 = 0.25 s.
    // h = 0.1 s: ½·4·0.1² = 0.02; h = 0.25 s: ½·4·0.25² = 0.125;
    // h = 1 s: 1·(1 − 0.25/2) = 0.875; a full stop 1 → 0 from ṡ = 0 takes 1/1 + 1/4 = 1.25 s
    // (the ramp-down of the rate at the end mirrors the ramp-up: 0.125 + 0.75 + 0.125 = 1).
    // reachable_drop(h) is how far s can have fallen by h with the rate still at −ṡ_max, not
    // a stop completed by then: at h = 1.25 s it is 1·(1.25 − 0.125) = 1.125, the completed
    // stop's 1 plus the ramp-down's ṡ_max²/(2 s̈_max) = 0.125.
    let l = ScaleLimits::new(1.0, 4.0).unwrap();
    assert!((l.reachable_drop(0.1) - 0.02).abs() < 1e-12);
    assert!((l.reachable_drop(0.25) - 0.125).abs() < 1e-12);
    assert!((l.reachable_drop(1.0) - 0.875).abs() < 1e-12);
    assert!((l.full_stop_s() - 1.25).abs() < 1e-12);
    assert!((l.reachable_drop(1.25) - 1.125).abs() < 1e-12);
    assert_eq!(l.reachable_drop(0.0), 0.0);
    assert_eq!(l.reachable_drop(f64::NAN), 0.0);
}

#[test]
fn scale_limits_for_worked_example() {
    // By hand: Q1 = 1.2 rad/s, Q2 = 2.5 rad/s², acceleration budget 1.2 rad/s², jerk budget
    // 12 rad/s³: ṡ_max = min(1.2/1.2, 12/(6·2.5)) = min(1.0, 0.8) = 0.8 /s;
    // s̈_max = 12/(2·1.2) = 5 /s². With the caps 0.5 /s and 3 /s² instead: 0.5 and 3.
    let l = scale_limits_for(1.2, 2.5, 1.2, 12.0, 4.0, 40.0);
    assert!((l.rate() - 0.8).abs() < 1e-12, "{}", l.rate());
    assert!((l.accel() - 5.0).abs() < 1e-12, "{}", l.accel());
    let l = scale_limits_for(1.2, 2.5, 1.2, 12.0, 0.5, 3.0);
    assert_eq!((l.rate(), l.accel()), (0.5, 3.0));
    // The executed bounds of the path module docs then stay within the budgets:
    // ṡ_max·Q1 = 0.8·1.2 = 0.96 ≤ 1.2 and s̈_max·Q1 + 3·ṡ_max·Q2 = 5·1.2 + 3·0.8·2.5 = 12.
    let l = scale_limits_for(1.2, 2.5, 1.2, 12.0, 4.0, 40.0);
    assert!(l.rate() * 1.2 <= 1.2 + 1e-12);
    assert!((l.accel() * 1.2 + 3.0 * l.rate() * 2.5 - 12.0).abs() < 1e-9);
    // Non-positive budgets never give a zero or negative limit (ScaleLimits stays valid).
    let l = scale_limits_for(1.0, 1.0, 0.0, -1.0, 4.0, 40.0);
    assert!(l.rate() > 0.0 && l.accel() > 0.0);
}

#[test]
fn time_scale_full_stop_worked_example() {
    // By hand: s = 1, ṡ = 0, target 0 under ṡ_max = 2 /s, s̈_max = 10 /s². The time-optimal
    // jerk-limited drop has three phases:
    //   0 ≤ t ≤ 0.2 s:   s̈ = −10, ṡ = −10 t (to −2), s = 1 − 5 t²  (to 0.8);
    //   0.2 ≤ t ≤ 0.5 s: ṡ = −2, s from 0.8 to 0.2;
    //   0.5 ≤ t ≤ 0.7 s: s̈ = +10, ṡ from −2 to 0, s from 0.2 to 0.
    // Path time τ = ∫ s dt: phase 1: 0.2 − 5·0.2³/3 = 0.186667; phase 2: 0.3·(0.8 + 0.2)/2 =
    // 0.15; phase 3: ∫₀^0.2 (0.2 − 2t + 5t²) dt = 0.04 − 0.04 + 5·0.2³/3 = 0.013333;
    // τ(0.7 s) = 0.35 s, and it stays there once s = 0.
    let mut ts = TimeScale::new(ScaleLimits::new(2.0, 10.0).unwrap());
    assert_eq!((ts.tau(), ts.s(), ts.s_dot()), (0.0, 1.0, 0.0));
    for k in 1..=400 {
        ts.step(0.0, DT);
        match k {
            100 => {
                assert!((ts.s() - 0.8).abs() < 1e-9, "s(0.2) = {}", ts.s());
                assert!((ts.s_dot() + 2.0).abs() < 1e-9, "ṡ(0.2) = {}", ts.s_dot());
                assert!(
                    (ts.tau() - 0.186_666_667).abs() < 1e-8,
                    "τ(0.2) = {}",
                    ts.tau()
                );
            }
            250 => {
                assert!((ts.s() - 0.2).abs() < 1e-9, "s(0.5) = {}", ts.s());
                assert!(
                    (ts.tau() - 0.336_666_667).abs() < 1e-8,
                    "τ(0.5) = {}",
                    ts.tau()
                );
            }
            350 => {
                assert!(ts.s().abs() < 1e-9, "s(0.7) = {}", ts.s());
                assert!(ts.s_dot().abs() < 1e-9);
                assert!((ts.tau() - 0.35).abs() < 1e-8, "τ(0.7) = {}", ts.tau());
            }
            _ => {}
        }
    }
    assert_eq!(ts.s(), 0.0);
    assert!((ts.tau() - 0.35).abs() < 1e-8);
    assert_eq!(ts.errors(), 0);
    // Steps that are not usable do nothing; targets outside [0, 1] are clamped.
    let before = (ts.tau(), ts.s());
    ts.step(1.0, 0.0);
    ts.step(1.0, f64::NAN);
    assert_eq!((ts.tau(), ts.s()), before);
    for _ in 0..1000 {
        ts.step(7.0, DT);
    }
    assert!((ts.s() - 1.0).abs() < 1e-9);
    ts.reset(2.0, -3.0);
    assert_eq!((ts.tau(), ts.s(), ts.s_dot()), (2.0, 0.0, 0.0));
    ts.reset(f64::NAN, 3.0);
    assert_eq!((ts.tau(), ts.s()), (0.0, 1.0));
}

#[test]
fn time_scale_lower_limits_bring_the_rate_within_them_jerk_limited() {
    // Falling at the full rate of 4 /s, the limits drop to ṡ_max = 1 /s: the rate is brought
    // within the new limit at s̈_max = 40 /s² (3 /s take 3/40 = 0.075 s), never jumping.
    let mut ts = TimeScale::new(ScaleLimits::new(4.0, 40.0).unwrap());
    for _ in 0..60 {
        ts.step(0.0, DT);
    }
    assert!((ts.s_dot() + 4.0).abs() < 1e-9, "{}", ts.s_dot());
    ts.set_limits(ScaleLimits::new(1.0, 40.0).unwrap());
    let mut prev = ts.s_dot();
    let mut steps_above = 0;
    for _ in 0..100 {
        ts.step(0.0, DT);
        assert!(
            (ts.s_dot() - prev).abs() <= 40.0 * DT * (1.0 + 1e-6),
            "jump {prev} → {}",
            ts.s_dot()
        );
        if ts.s_dot().abs() > 1.0 + 1e-9 {
            steps_above += 1;
        }
        prev = ts.s_dot();
    }
    // 0.075 s / 2 ms = 37.5 steps.
    assert!((37..=39).contains(&steps_above), "{steps_above}");
    assert_eq!(ts.errors(), 0);
}

// --- TimeScale: properties ---

fn target_sequence() -> impl Strategy<Value = Vec<(f64, usize)>> {
    // Targets slightly outside [0, 1] too (they are clamped), each held 1..150 steps.
    prop::collection::vec((-0.2..1.2f64, 1..150usize), 1..25)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn time_scale_stays_within_its_limits(
        rate in 0.2..5.0f64,
        accel in 1.0..60.0f64,
        s0 in 0.0..=1.0f64,
        targets in target_sequence(),
        period in 1..=3usize,
    ) {
        let limits = ScaleLimits::new(rate, accel).unwrap();
        let mut ts = TimeScale::new(limits);
        ts.reset(0.0, s0);
        let dt = DT * period as f64;
        let eps = 1e-6;
        let (mut s_prev, mut sd_prev, mut tau_prev) = (ts.s(), ts.s_dot(), ts.tau());
        for (target, hold) in targets {
            for _ in 0..hold {
                ts.step(target, dt);
                let (s, sd, tau) = (ts.s(), ts.s_dot(), ts.tau());
                prop_assert!((0.0..=1.0).contains(&s), "s = {}", s);
                prop_assert!(tau >= tau_prev, "τ went back: {} → {}", tau_prev, tau);
                // τ advances by ∫ s dt with 0 ≤ s ≤ 1.
                prop_assert!(tau - tau_prev <= dt * (1.0 + eps), "Δτ = {}", tau - tau_prev);
                prop_assert!(sd.abs() <= rate * (1.0 + eps) + 1e-12, "ṡ = {} > {}", sd, rate);
                // Mean-value bounds on the differences (exact for the trajectory).
                prop_assert!((s - s_prev).abs() <= rate * dt * (1.0 + eps) + 1e-12);
                prop_assert!(
                    (sd - sd_prev).abs() <= accel * dt * (1.0 + eps) + 1e-9,
                    "s̈ = {} > {}", (sd - sd_prev) / dt, accel
                );
                s_prev = s;
                sd_prev = sd;
                tau_prev = tau;
            }
        }
        prop_assert_eq!(ts.errors(), 0);
    }
}

// --- Executed motion q(τ(t)): the bounds of the path module docs ---

/// Largest |q'| and |q''| over the path, sampled densely (a finer grid than `Path`'s own
/// 65 samples) [rad/s], [rad/s²].
fn dense_maxima(path: &mut Path) -> (f64, f64) {
    let mut s = PathSample::default();
    let (mut q1, mut q2) = (path.max_velocity(), path.max_acceleration());
    let n = 4000;
    for k in 0..=n {
        path.sample(path.duration_s() * k as f64 / n as f64, &mut s);
        for i in 0..6 {
            q1 = q1.max(s.velocity[i].abs());
            q2 = q2.max(s.acceleration[i].abs());
        }
    }
    (q1, q2)
}

fn joints(range: f64) -> impl Strategy<Value = Joints> {
    prop::array::uniform6(-range..range)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn executed_motion_keeps_the_time_scaled_bounds(
        start in joints(2.0),
        target in joints(2.0),
        v in prop::array::uniform6(0.3..PI),
        a in prop::array::uniform6(0.5..PI),
        j in prop::array::uniform6(2.0..40.0f64),
        rate in 0.2..4.0f64,
        accel in 1.0..40.0f64,
        s0 in 0.0..=1.0f64,
        targets in prop::collection::vec((0.0..=1.0f64, 1..120usize), 1..30),
    ) {
        let limits = MotionLimits::new(v, a, j).unwrap();
        let mut path = Path::new(limits);
        let rest = PathState { position: start, velocity: [0.0; 6], acceleration: [0.0; 6] };
        path.plan(&rest, &target, &limits, None).unwrap();
        let (q1, q2) = dense_maxima(&mut path);
        let scale = ScaleLimits::new(rate, accel).unwrap();
        let mut ts = TimeScale::new(scale);
        ts.reset(0.0, s0);
        // Executed positions every 2 ms, the targets then held at their last value until the
        // path's end (at most 3000 steps more).
        let mut q: Vec<Joints> = Vec::with_capacity(4096);
        let mut sample = PathSample::default();
        path.sample(ts.tau(), &mut sample);
        q.push(sample.position);
        let mut last = 1.0;
        for (t, hold) in &targets {
            last = *t;
            for _ in 0..*hold {
                ts.step(*t, DT);
                path.sample(ts.tau(), &mut sample);
                q.push(sample.position);
            }
        }
        let mut extra = 0;
        while ts.tau() < path.duration_s() && extra < 3000 {
            ts.step(last.max(0.2), DT);
            path.sample(ts.tau(), &mut sample);
            q.push(sample.position);
            extra += 1;
        }
        prop_assert_eq!(ts.errors(), 0);
        // The bounds (path module docs), per joint i:
        //   |q̇| ≤ V_i,  |q̈| ≤ A_i + ṡ_max·Q1,  |q⃛| ≤ s̈_max·Q1 + 3·ṡ_max·Q2 + J_i.
        // The k-th difference over 2 ms is a weighted mean of the k-th derivative (q(τ(t)) is
        // C² with a piecewise-continuous third derivative), so each bounds it; the tolerance
        // covers rounding (≈ 1e-15 rad over 8e-9 s³ for the third difference).
        let tol = |bound: f64| bound * 1e-6 + 1e-6;
        for w in q.windows(4) {
            for i in 0..6 {
                let d1 = (w[1][i] - w[0][i]) / DT;
                let d2 = (w[2][i] - 2.0 * w[1][i] + w[0][i]) / (DT * DT);
                let d3 = (w[3][i] - 3.0 * w[2][i] + 3.0 * w[1][i] - w[0][i]) / (DT * DT * DT);
                let (vb, ab) = (v[i], a[i] + rate * q1);
                let jb = accel * q1 + 3.0 * rate * q2 + j[i];
                prop_assert!(d1.abs() <= vb + tol(vb), "joint {} q̇ {} > {}", i, d1, vb);
                prop_assert!(d2.abs() <= ab + tol(ab), "joint {} q̈ {} > {}", i, d2, ab);
                prop_assert!(d3.abs() <= jb + 1e-3 * jb + 0.05, "joint {} q⃛ {} > {}", i, d3, jb);
            }
        }
    }
}

// --- Envelope::admissible_scale ---

/// All joints at zero: the arm stretches along −x at the shoulder height d1 = 0.1625 m.
const Q_ZERO: Joints = [0.0; 6];
/// A point on the base's z axis 1 m above the shoulder axis: rotating joint 1 does not change
/// its distance to any capsule, so the distance at the stopping configuration equals the
/// distance now.
const ABOVE_BASE: [f64; 3] = [0.0, 0.0, 1.1625];

fn hand(p: [f64; 3]) -> HumanBody {
    HumanBody {
        right_hand_m: Some(p),
        ..HumanBody::default()
    }
}

fn envelope() -> Envelope {
    Envelope::new(SafetyEnvelope::ur5e(), PlanningMargins::default())
}

#[test]
fn admissible_scale_worked_example_one_hand_above_the_shoulder() {
    // Geometry by hand (robot_io::geometry's table): at q = 0 the shoulder drum is the segment
    // from (0, ±0.038, 0.1625) to (0, ±0.158, 0.1625) with radius 0.075 m, and the hand on
    // the z axis 1 m above the shoulder axis is √(0.038² + 1²) − 0.075 = 0.925722 m from its
    // surface (the upper arm, offset 0.138 m: √(0.138² + 1) − 0.065 = 0.944477 m; every other
    // capsule is further out along −x).
    let mut caps = [Capsule::point([0.0; 3], 0.0); ARM_CAPSULES];
    robot_io::geometry::ArmModel::ur5e_gripper().capsules(&Q_ZERO, &mut caps);
    let near = closest_approaches(
        &caps,
        &hand(ABOVE_BASE),
        &robot_io::geometry::BodyModel::default_adult(),
    );
    let right = near[BodyPart::RightHand.index()].unwrap();
    assert_eq!(right.link, ArmLink::Shoulder);
    let d = (0.038f64 * 0.038 + 1.0).sqrt() - 0.075;
    assert!((right.distance_m - d).abs() < 1e-9 && (d - 0.925_722).abs() < 1e-6);

    // Motion: joint 1 at q' = 1 rad/s. The flange at q = 0 is at (a2 + a3, −(d4 + d6),
    // d1 − d5) = (−0.8172, −0.2329, 0.0628) m, r = √(0.8172² + 0.2329²) = 0.849740 m from the
    // z axis, so u = |J q'| = 0.849740 m/s and w = max|q'| = 1 rad/s.
    let qd = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let u = flange_speed_m_s(&Q_ZERO, &qd);
    assert!((u - 0.849_740).abs() < 1e-6, "{u}");
    // Caps (not binding here): joint 0.9·π/1 = 2.8274, TCP 0.9·1 m/s / 0.849740 = 1.0591.
    //
    // S_p(s) with the planner's margins (ε = 0.1 measured-speed allowance, perception age at
    // least 0.05 s, δ = 0.05 m): v_r = ε' s u, T_s = ε' s w / a_stop with ε' = 1.1, a_stop =
    // π rad/s², hand v_h = 2.0 m/s, T_r = 0.1 s, C + Z_d + Z_r = 0.17 m:
    //   S_p(s) = v_h (T_age + T_r + T_s) + v_r T_r + v_r T_s / 2 + 0.17
    //          = c0 + c1 s + c2 s²,
    //   c0 = 2.0·(0.05 + 0.1) + 0.17                      = 0.47
    //   c1 = 1.1·(2.0·1/π + 0.849740·0.1) = 1.1·0.721594   = 0.793753
    //   c2 = 1.1²·0.849740·1/(2π)         = 1.21·0.135240  = 0.163641
    // S_p(s) + δ ≤ d ⇔ 0.163641 s² + 0.793753 s + (0.47 − 0.875722) ≤ 0, γ = −0.405722:
    //   s* = −2γ / (c1 + √(c1² − 4 c2 γ)) = 0.811444 / (0.793753 + √(0.630044 + 0.265570))
    //      = 0.811444 / (0.793753 + 0.946369) = 0.466314.
    let mut env = envelope();
    let a = env.admissible_scale(&Q_ZERO, &qd, &hand(ABOVE_BASE), 0.0, false);
    assert!((a.scale - 0.466_314).abs() < 1e-5, "{a:?}");
    assert_eq!(a.binding, Binding::Separation(BodyPart::RightHand));
    assert!((a.min_distance_m - d).abs() < 1e-9);
    // Cross-check with the shared formula: at s*, S_p + δ is exactly the distance.
    let sp = protective_distance_m(
        SafetyEnvelope::ur5e().separation(),
        BodyPart::RightHand,
        1.1 * a.scale * u,
        1.1 * a.scale * 1.0 / PI,
        0.05,
    );
    assert!((sp + 0.05 - d).abs() < 1e-9, "S_p(s*) = {sp}");
    // And the quadratic's root by itself.
    let s = largest_root_below(0.47, 0.793_753, 0.163_641, 0.875_722);
    assert!((s - 0.466_314).abs() < 2e-6, "{s}");
    // Perception 0.3 s old (stale): T_age = 0.3, c0 = 2.0·0.4 + 0.17 = 0.97 > 0.875722: the
    // hand is inside S_p even at rest, so the scale is 0.
    let a = env.admissible_scale(&Q_ZERO, &qd, &hand(ABOVE_BASE), 0.3, false);
    assert_eq!(a.scale, 0.0, "{a:?}");
}

#[test]
fn admissible_scale_at_rest_is_zero_inside_and_one_outside_the_protective_distance() {
    // At rest (q' = 0) S_p does not grow with s: S_p = c0 = 0.47 m, so the scale is 0 for a
    // hand closer than 0.47 + 0.05 = 0.52 m and 1 (nothing binds) beyond.
    let mut env = envelope();
    let rest = [0.0; 6];
    // √(0.038² + Δz²) − 0.075 = d ⇒ Δz = √((d + 0.075)² − 0.038²): 0.573743 m for 0.50 m,
    // 0.613825 m for 0.54 m.
    let at = |d: f64| {
        [
            0.0,
            0.0,
            0.1625 + ((d + 0.075f64).powi(2) - 0.038f64.powi(2)).sqrt(),
        ]
    };
    let inside = env.admissible_scale(&Q_ZERO, &rest, &hand(at(0.50)), 0.0, true);
    assert!((inside.min_distance_m - 0.50).abs() < 1e-6, "{inside:?}");
    assert_eq!(inside.scale, 0.0);
    assert_eq!(inside.binding, Binding::Separation(BodyPart::RightHand));
    let outside = env.admissible_scale(&Q_ZERO, &rest, &hand(at(0.54)), 0.0, true);
    assert!((outside.min_distance_m - 0.54).abs() < 1e-6, "{outside:?}");
    assert_eq!(outside.scale, 1.0);
    assert_eq!(outside.binding, Binding::None);
    // Moving, the same hand 0.3 m from the surface is inside S_p as well: 0.
    let qd = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let a = env.admissible_scale(&Q_ZERO, &qd, &hand(at(0.3)), 0.0, false);
    assert!((a.min_distance_m - 0.3).abs() < 1e-6, "{a:?}");
    assert_eq!(a.scale, 0.0, "{a:?}");
}

#[test]
fn admissible_scale_binding_names_the_limit() {
    let mut env = envelope();
    let nobody = HumanBody::default();
    // Wrist 3 alone at 5 rad/s turns the flange about its own axis (u ≈ 0): the joint cap
    // binds, s = 0.9·π/5 = 0.565487.
    let wrist = [0.0, 0.0, 0.0, 0.0, 0.0, 5.0];
    assert!(flange_speed_m_s(&Q_ZERO, &wrist) < 1e-6);
    let a = env.admissible_scale(&Q_ZERO, &wrist, &nobody, 0.0, false);
    assert_eq!(a.binding, Binding::JointSpeed);
    assert!((a.scale - 0.9 * PI / 5.0).abs() < 1e-12, "{a:?}");
    assert_eq!(a.min_distance_m, f64::INFINITY);
    // Joint 1 at 1 rad/s moves the flange at 0.849740 m/s: not collaborating, the TCP cap
    // allows 0.9·1/0.849740 = 1.0591 > 1, so nothing binds; while collaborating the cap is
    // 0.9·0.25 m/s: s = 0.225/0.849740 = 0.264787.
    let base = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let a = env.admissible_scale(&Q_ZERO, &base, &nobody, 0.0, false);
    assert_eq!((a.scale, a.binding), (1.0, Binding::None));
    let a = env.admissible_scale(&Q_ZERO, &base, &nobody, 0.0, true);
    assert_eq!(a.binding, Binding::TcpSpeed);
    assert!((a.scale - 0.264_787).abs() < 1e-6, "{a:?}");
    // Stale perception (0.3 s > 0.2 s) multiplies the caps by 0.25: joint 0.9·π·0.25 = 0.7069,
    // TCP 0.9·1·0.25/0.849740 = 0.264787, which binds.
    let a = env.admissible_scale(&Q_ZERO, &base, &nobody, 0.3, false);
    assert_eq!(a.binding, Binding::TcpSpeed);
    assert!((a.scale - 0.264_787).abs() < 1e-6, "{a:?}");
    let a = env.admissible_scale(&Q_ZERO, &wrist, &nobody, 0.3, false);
    assert_eq!(a.binding, Binding::JointSpeed);
    assert!((a.scale - 0.9 * PI * 0.25 / 5.0).abs() < 1e-12, "{a:?}");
    // The planned TCP caps themselves.
    assert!((env.planned_tcp_cap_m_s(true) - 0.225).abs() < 1e-12);
    assert!((env.planned_tcp_cap_m_s(false) - 0.9).abs() < 1e-12);
    // Unusable input: 0, Invalid.
    let mut bad = Q_ZERO;
    bad[1] = f64::NAN;
    let a = env.admissible_scale(&bad, &base, &nobody, 0.0, false);
    assert_eq!((a.scale, a.binding), (0.0, Binding::Invalid));
    let a = env.admissible_scale(&Q_ZERO, &base, &nobody, f64::INFINITY, false);
    assert_eq!((a.scale, a.binding), (0.0, Binding::Invalid));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn admissible_scale_is_one_with_nobody_and_slow_paths(
        q in joints(PI),
        qd in prop::array::uniform6(-0.1..0.1f64),
        age in 0.0..0.2f64,
        collaborating in any::<bool>(),
    ) {
        // |q'| ≤ 0.1 rad/s: the joint cap allows 0.9·π/0.1 = 28 ≫ 1; the flange is at most
        // about 1 m from any joint axis, so u ≤ 6·0.1·1 = 0.6 m/s < 0.9 m/s outside
        // collaboration; while collaborating (0.225 m/s) only paths with u ≤ 0.225 m/s count.
        let mut env = envelope();
        let a = env.admissible_scale(&q, &qd, &HumanBody::default(), age, collaborating);
        let u = flange_speed_m_s(&q, &qd);
        prop_assume!(!collaborating || u <= 0.225);
        prop_assert_eq!(a.scale, 1.0);
        prop_assert_eq!(a.binding, Binding::None);
        prop_assert_eq!(a.min_distance_m, f64::INFINITY);
    }

    #[test]
    fn admissible_scale_is_monotone_in_the_distance(
        q in joints(PI),
        qd in prop::array::uniform6(-1.5..1.5f64),
        p1 in prop::array::uniform3(-1.5..1.5f64),
        p2 in prop::array::uniform3(-1.5..1.5f64),
        age in 0.0..0.3f64,
        collaborating in any::<bool>(),
    ) {
        // The scale depends on the hand only through its distance to the arm (now and at the
        // stopping configuration): a farther hand never allows less.
        let mut env = envelope();
        let a1 = env.admissible_scale(&q, &qd, &hand(p1), age, collaborating);
        let a2 = env.admissible_scale(&q, &qd, &hand(p2), age, collaborating);
        prop_assert!((0.0..=1.0).contains(&a1.scale) && (0.0..=1.0).contains(&a2.scale));
        let (near, far) = if a1.min_distance_m <= a2.min_distance_m { (a1, a2) } else { (a2, a1) };
        prop_assert!(
            near.scale <= far.scale + 1e-12,
            "d {} → s {}, d {} → s {}", near.min_distance_m, near.scale, far.min_distance_m, far.scale
        );
        // And never more than with nobody there.
        let free = env.admissible_scale(&q, &qd, &HumanBody::default(), age, collaborating);
        prop_assert!(far.scale <= free.scale + 1e-12);
    }
}

// --- Controller: missed cycles are caught up ---

/// One step's record: time [s], phase, commanded positions [rad].
type Record = (f64, Phase, Joints);

/// A handover from home with nobody tracked, until the part is presented, the controller
/// seeing every `period`-th state (the sim steps `period` times between reads).
fn run_with_period(period: usize) -> (Vec<Record>, Controller) {
    let cfg = ControllerConfig::example();
    let mut robot = SimRobot::new(SimConfig {
        initial_q_rad: cfg.task.home_q_rad,
        ..SimConfig::ur5e()
    })
    .unwrap();
    let mut ctl = Controller::new(cfg).unwrap();
    let mut state = RobotState::default();
    let mut cmd = JointCommand::Stop { decel: 1.0 };
    let mut out = Vec::with_capacity(4096);
    ctl.start_handover();
    for _ in 0..(12.0 / (DT * period as f64)) as usize {
        robot.read_state(&mut state).unwrap();
        ctl.step(
            state.timestamp_s,
            &state,
            &MotionAdaptation::default(),
            &OperatorView::default(),
            &mut cmd,
        );
        assert!(matches!(cmd, JointCommand::Servo { .. }), "{cmd:?}");
        out.push((state.timestamp_s, ctl.phase(), *ctl.commanded_position()));
        if ctl.phase() == Phase::Present {
            return (out, ctl);
        }
        robot.send(&cmd).unwrap();
        for _ in 0..period {
            robot.step();
        }
    }
    panic!("not presented: {:?}", ctl.stats());
}

#[test]
fn missed_cycles_are_caught_up_along_the_same_path() {
    let (every, ctl1) = run_with_period(1);
    let (third, ctl3) = run_with_period(3);
    // Every 3rd state: 2 cycles missed per step after the first.
    assert_eq!(ctl1.stats().missed_cycles, 0);
    assert_eq!(ctl3.stats().missed_cycles, 2 * (third.len() as u64 - 1));
    assert_eq!(ctl3.stats().steps, third.len() as u64);
    // Each motion (the fetch from t = 0, the approach from its start) is planned from rest at
    // the same state in both runs, and with nobody tracked it runs at s = 1. Each step advances
    // the path by the time elapsed since the previous step, so a step commands the path at
    // τ = (time since the motion's first step) + (the first step's elapsed time): 2 ms for the
    // fetch in both runs (the very first step counts one cycle); for the approach 2 ms every
    // cycle, 6 ms every 3rd. At equal τ the commanded positions are equal.
    for (phase, first_elapsed_3) in [(Phase::Fetch, DT), (Phase::Approach, 3.0 * DT)] {
        let start = |r: &[Record]| r.iter().find(|x| x.1 == phase).unwrap().0;
        let (s1, s3) = (start(&every), start(&third));
        let mut compared = 0;
        for (t3, _, q3) in third.iter().filter(|x| x.1 == phase) {
            let tau = t3 - s3 + first_elapsed_3;
            let t = s1 + tau - DT;
            let k = (t / DT).round() as usize;
            let (t1, p1, q1) = every[k];
            assert!((t1 - t).abs() < 1e-9);
            if p1 != phase {
                // The every-cycle run left the phase earlier (it sees the arrival up to 2
                // cycles sooner); by then both stand at the target.
                continue;
            }
            for i in 0..6 {
                assert!(
                    (q1[i] - q3[i]).abs() < 1e-6,
                    "{phase} at τ = {tau:.3} s, joint {i}: {} vs {}",
                    q1[i],
                    q3[i]
                );
            }
            compared += 1;
        }
        assert!(compared > 300, "{phase}: {compared} steps compared");
    }
    // The motions did move (the comparison is not of two robots standing still).
    let moved = |r: &[Record]| {
        r.windows(2)
            .map(|w| {
                (0..6)
                    .map(|i| (w[1].2[i] - w[0].2[i]).abs())
                    .fold(0.0, f64::max)
            })
            .fold(0.0, f64::max)
    };
    assert!(moved(&third) > 1e-3);
    eprintln!(
        "every cycle: {} steps; every 3rd: {} steps, {:?}",
        every.len(),
        third.len(),
        ctl3.stats()
    );
}
