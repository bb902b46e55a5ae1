//! QP speed scaling: boxes, separation clamping, slack and braking, closed-form and clarabel
//! cross-checks, and a property test over random inputs.
#![allow(clippy::needless_range_loop)]

use adapt::qp::{
    ClarabelSpeedScaler, ControlPointInput, HumanPoint, N_JOINTS, Problem, QpConfig, QpInput,
    QpStatus, SpeedScaler, braking_fallback, project_box_halfspace,
};
use adapt::ssm::HumanPointKind;
use proptest::prelude::*;

const DT: f64 = 0.002;

/// TCP at the origin whose velocity is (q̇0, q̇1, q̇2); wrist and elbow fixed far away.
fn base_input() -> QpInput {
    let mut tcp = ControlPointInput::default();
    tcp.jacobian[0][0] = 1.0;
    tcp.jacobian[1][1] = 1.0;
    tcp.jacobian[2][2] = 1.0;
    let far = ControlPointInput {
        position: [-5.0, 0.0, 0.0],
        jacobian: [[0.0; 6]; 3],
    };
    QpInput {
        qd_ref: [0.0; 6],
        qd_prev: [0.0; 6],
        dt_s: DT,
        max_velocity: [std::f64::consts::PI; 6],
        max_acceleration: [std::f64::consts::PI; 6],
        tcp_speed_cap_m_s: f64::INFINITY,
        control_points: [tcp, far, far],
        humans: [None; 3],
    }
}

fn dot(a: &[f64; 6], b: &[f64; 6]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn approach_speed(input: &QpInput, cp: usize, h: &HumanPoint, qd: &[f64; 6]) -> (f64, f64) {
    let c = &input.control_points[cp];
    let d: [f64; 3] = std::array::from_fn(|k| h.position[k] - c.position[k]);
    let dist = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let v: [f64; 3] = std::array::from_fn(|k| dot(&c.jacobian[k], qd));
    ((v[0] * d[0] + v[1] * d[1] + v[2] * d[2]) / dist, dist)
}

#[test]
fn unconstrained_returns_the_reference() {
    let mut s = SpeedScaler::new(QpConfig::default()).unwrap();
    let mut input = base_input();
    input.qd_ref = [0.001, -0.002, 0.003, 0.0, 0.005, -0.006];
    let mut out = [9.0; 6];
    assert_eq!(s.solve(&input, &mut out), QpStatus::Solved);
    assert_eq!(out, input.qd_ref);
}

#[test]
fn velocity_and_acceleration_boxes_hold() {
    let mut s = SpeedScaler::new(QpConfig::default()).unwrap();
    let mut input = base_input();
    input.qd_prev = [3.139, 0.0, -1.0, 0.5, 0.0, 0.0];
    input.qd_ref = [10.0, 1.0, -1.0, 0.5, -10.0, 0.0];
    let mut out = [0.0; 6];
    assert_eq!(s.solve(&input, &mut out), QpStatus::Solved);
    let step = std::f64::consts::PI * DT;
    // joint 0: velocity limit π binds before the acceleration step (3.139 + 0.00628 > π)
    assert_eq!(out[0], std::f64::consts::PI);
    // joint 1 and 4: one acceleration step
    assert!((out[1] - step).abs() < 1e-15);
    assert!((out[4] + step).abs() < 1e-15);
    assert_eq!(out[2], -1.0);
    // a previous velocity beyond the limit is pinned at the limit (velocity wins)
    input.qd_prev[0] = 5.0;
    s.solve(&input, &mut out);
    assert_eq!(out[0], std::f64::consts::PI);
}

#[test]
fn head_on_approach_is_clamped_at_the_separation_limit() {
    let cfg = QpConfig::default();
    let mut s = SpeedScaler::new(cfg).unwrap();
    let mut input = base_input();
    let hand = HumanPoint {
        position: [0.8, 0.0, 0.0],
        kind: HumanPointKind::Hand,
    };
    input.humans[1] = Some(hand);
    // Moving straight at the hand at 1 m/s (and sideways at 0.2), already at that speed.
    input.qd_ref = [1.0, 0.2, 0.0, 0.3, 0.0, 0.0];
    input.qd_prev = [0.5, 0.2, 0.0, 0.3, 0.0, 0.0];
    input.max_acceleration = [1e3; 6];
    let mut out = [0.0; 6];
    assert_eq!(s.solve(&input, &mut out), QpStatus::Solved);
    // limit at 0.8 m for a hand = 0.4449027 m/s (worked example in tests/ssm.rs)
    let limit = cfg
        .ssm()
        .separation_speed_limit_m_s(HumanPointKind::Hand, 0.8);
    assert!((out[0] - limit).abs() < 1e-9, "{out:?}");
    // the projection moves only along the row: the sideways motion and other joints stay
    assert!((out[1] - 0.2).abs() < 1e-12 && (out[3] - 0.3).abs() < 1e-12);
    let (v, _) = approach_speed(&input, 0, &hand, &out);
    assert!(v <= limit + 1e-9);
}

#[test]
fn infeasible_step_uses_slack_and_brakes_within_limits() {
    let mut s = SpeedScaler::new(QpConfig::default()).unwrap();
    let mut input = base_input();
    let hand = HumanPoint {
        position: [0.8, 0.0, 0.0],
        kind: HumanPointKind::Hand,
    };
    input.humans[2] = Some(hand);
    input.qd_ref = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    input.qd_prev = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    input.max_acceleration = [5.0; 6]; // 0.01 rad/s per cycle: cannot reach 0.445 m/s in one step
    let mut out = [0.0; 6];
    let status = s.solve(&input, &mut out);
    assert_eq!(status, QpStatus::SolvedWithSlack);
    // brakes as hard as the box allows along the approach direction
    assert!((out[0] - 0.99).abs() < 1e-9, "{out:?}");
    for j in 0..6 {
        assert!(out[j].abs() <= input.max_velocity[j]);
        assert!((out[j] - input.qd_prev[j]).abs() <= 5.0 * DT + 1e-12);
    }
    // and keeps braking cycle after cycle until the limit holds
    let mut cycles = 0;
    loop {
        input.qd_prev = out;
        let st = s.solve(&input, &mut out);
        cycles += 1;
        if st == QpStatus::Solved {
            break;
        }
        assert_eq!(st, QpStatus::SolvedWithSlack);
        assert!(out[0] < input.qd_prev[0]);
    }
    // (1.0 − 0.4449) / 0.01 ≈ 55.5 cycles
    assert!((54..=57).contains(&cycles), "{cycles}");
}

#[test]
fn invalid_input_falls_back_without_panicking() {
    let mut s = SpeedScaler::new(QpConfig::default()).unwrap();
    let mut out = [0.0; 6];
    let mut input = base_input();
    input.qd_prev = [1.0, -1.0, 0.0, 0.0, 0.0, 0.0];
    input.qd_ref = [f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(s.solve(&input, &mut out), QpStatus::InvalidInput);
    // braking fallback: scaled toward 0 by one acceleration step
    let step = std::f64::consts::PI * DT;
    assert!((out[0] - (1.0 - step)).abs() < 1e-12 && (out[1] + (1.0 - step)).abs() < 1e-12);
    input.qd_ref = [0.0; 6];
    input.humans[0] = Some(HumanPoint {
        position: [f64::INFINITY, 0.0, 0.0],
        kind: HumanPointKind::Head,
    });
    assert_eq!(s.solve(&input, &mut out), QpStatus::InvalidInput);
    input.humans[0] = None;
    input.dt_s = f64::NAN;
    assert_eq!(s.solve(&input, &mut out), QpStatus::InvalidInput);
    assert_eq!(out, [0.0; 6]);
    input.dt_s = DT;
    input.max_velocity[3] = -1.0;
    assert_eq!(s.solve(&input, &mut out), QpStatus::InvalidInput);
    assert!(out.iter().all(|v| v.is_finite()));
    input.max_velocity[3] = 1.0;
    input.tcp_speed_cap_m_s = f64::NAN;
    assert_eq!(s.solve(&input, &mut out), QpStatus::InvalidInput);
}

#[test]
fn tcp_speed_cap_scales_the_reference_along_its_path() {
    let mut s = SpeedScaler::new(QpConfig::default()).unwrap();
    let mut input = base_input();
    input.qd_ref = [0.6, 0.8, 0.0, 0.4, 0.0, 0.0]; // TCP speed 1.0 m/s
    input.qd_prev = input.qd_ref;
    input.tcp_speed_cap_m_s = 0.25;
    input.max_acceleration = [1e3; 6];
    let mut out = [0.0; 6];
    assert_eq!(s.solve(&input, &mut out), QpStatus::Solved);
    let expect = [0.15, 0.2, 0.0, 0.1, 0.0, 0.0];
    for j in 0..6 {
        assert!((out[j] - expect[j]).abs() < 1e-12, "{out:?}");
    }
}

fn rand_problem(rng: &mut u64, rows: usize) -> Problem {
    let mut next = || {
        *rng ^= *rng << 13;
        *rng ^= *rng >> 7;
        *rng ^= *rng << 17;
        (*rng >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut p = Problem::default();
    for j in 0..N_JOINTS {
        let prev = 2.0 * next();
        p.lo[j] = (prev - 0.5).max(-3.0);
        p.hi[j] = (prev + 0.5).min(3.0);
        p.r[j] = 3.0 * next();
    }
    for i in 0..rows {
        let mut a = [0.0; 6];
        a.iter_mut().for_each(|x| *x = next());
        let n = dot(&a, &a).sqrt();
        a.iter_mut().for_each(|x| *x /= n);
        p.a[i] = a;
        p.b[i] = next().abs();
    }
    p.m = rows;
    p
}

#[test]
fn closed_form_agrees_with_clarabel_on_single_row_problems() {
    // Pose single-row problems through QpInput so that both solvers see them: one hand point,
    // TCP Jacobian = one random unit row along x, accelerations large enough to make it feasible.
    let cfg = QpConfig::default();
    let mut ours = SpeedScaler::new(cfg).unwrap();
    let mut cla = ClarabelSpeedScaler::new(cfg).unwrap();
    let mut rng = 0x9e37_79b9_7f4a_7c15u64;
    let mut worst: f64 = 0.0;
    for _ in 0..300 {
        let p = rand_problem(&mut rng, 1);
        let mut input = base_input();
        input.control_points[0].jacobian = [p.a[0], [0.0; 6], [0.0; 6]];
        input.humans[0] = Some(HumanPoint {
            position: [1.0, 0.0, 0.0],
            kind: HumanPointKind::Head,
        });
        input.qd_ref = p.r;
        input.qd_prev = std::array::from_fn(|j| 0.5 * (p.lo[j] + p.hi[j]));
        input.max_acceleration = [250.0; 6]; // ±0.5 rad/s per step
        let mut a = [0.0; 6];
        let mut b = [0.0; 6];
        let sa = ours.solve(&input, &mut a);
        let sb = cla.solve(&input, &mut b);
        assert!(!sa.is_fallback() && !sb.is_fallback(), "{sa:?} {sb:?}");
        // and our path is the closed form itself when there is one row
        let pr = ours.problem();
        if pr.m == 1 {
            let mut c = [0.0; 6];
            project_box_halfspace(&pr.r, &pr.lo, &pr.hi, &pr.a[0], pr.b[0], 1e3, &mut c);
            for j in 0..6 {
                assert!((a[j] - c[j]).abs() < 1e-12);
            }
        }
        for j in 0..6 {
            worst = worst.max((a[j] - b[j]).abs());
        }
    }
    assert!(worst < 1e-5, "closed form vs clarabel: {worst}");
}

#[test]
fn active_set_matches_clarabel_on_multi_row_problems() {
    let cfg = QpConfig::default();
    let mut ours = SpeedScaler::new(cfg).unwrap();
    let mut cla = ClarabelSpeedScaler::new(cfg).unwrap();
    let mut rng = 0x2545_f491_4f6c_dd1du64;
    let (mut worst, mut max_sweeps, mut statuses) = (0.0f64, 0u32, [0usize; 5]);
    for _ in 0..300 {
        let input = random_input(&mut rng);
        let mut a = [0.0; 6];
        let mut b = [0.0; 6];
        let sa = ours.solve(&input, &mut a);
        let sb = cla.solve(&input, &mut b);
        statuses[sa as usize] += 1;
        max_sweeps = max_sweeps.max(ours.report().sweeps);
        if matches!(sa, QpStatus::Solved | QpStatus::SolvedWithSlack)
            && matches!(sb, QpStatus::Solved | QpStatus::SolvedWithSlack)
        {
            for j in 0..6 {
                worst = worst.max((a[j] - b[j]).abs());
            }
        }
    }
    eprintln!("statuses {statuses:?}, max sweeps {max_sweeps}, worst |Δq̇| {worst:e}");
    assert!(worst < 1e-4, "ours vs clarabel: {worst}");
}

#[test]
fn braking_fallback_is_uniform_and_acceleration_limited() {
    let mut input = base_input();
    input.qd_prev = [1.0, -0.5, 0.25, 0.0, 0.0, 0.0];
    input.max_acceleration = [1.0, 10.0, 10.0, 10.0, 10.0, 10.0];
    let mut out = [0.0; 6];
    braking_fallback(&input, &mut out);
    // joint 0 limits: s = 1 − 1.0·0.002/1.0 = 0.998
    let expect = [0.998, -0.499, 0.2495, 0.0, 0.0, 0.0];
    for j in 0..6 {
        assert!((out[j] - expect[j]).abs() < 1e-12);
    }
}

/// A random but plausible input: three control points with random Jacobians (|J| ≤ 1 m/rad),
/// up to three human points within 0–1.5 m, random references and previous velocities.
fn random_input(rng: &mut u64) -> QpInput {
    let mut next = || {
        *rng ^= *rng << 13;
        *rng ^= *rng >> 7;
        *rng ^= *rng << 17;
        (*rng >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut input = base_input();
    for cp in input.control_points.iter_mut() {
        cp.position = std::array::from_fn(|_| next() * 0.6 - 0.3);
        cp.jacobian = std::array::from_fn(|_| std::array::from_fn(|_| next() * 2.0 - 1.0));
    }
    for (i, h) in input.humans.iter_mut().enumerate() {
        if next() < 0.8 {
            *h = Some(HumanPoint {
                position: std::array::from_fn(|_| next() * 2.0 - 1.0),
                kind: if i == 0 {
                    HumanPointKind::Head
                } else {
                    HumanPointKind::Hand
                },
            });
        }
    }
    input.qd_ref = std::array::from_fn(|_| next() * 6.0 - 3.0);
    input.qd_prev = std::array::from_fn(|_| (next() * 2.0 - 1.0) * std::f64::consts::PI);
    input.max_acceleration = std::array::from_fn(|_| next() * 400.0);
    input.tcp_speed_cap_m_s = if next() < 0.5 { next() } else { f64::INFINITY };
    input
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: std::env::var("QP_PROPTEST_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(512),
        ..ProptestConfig::default()
    })]

    #[test]
    fn output_is_safe_for_random_inputs(seed in any::<u64>()) {
        let mut rng = seed | 1;
        let input = random_input(&mut rng);
        let cfg = QpConfig::default();
        let mut s = SpeedScaler::new(cfg).unwrap();
        let mut out = [0.0; 6];
        let status = s.solve(&input, &mut out);
        let mut brake = [0.0; 6];
        braking_fallback(&input, &mut brake);
        for j in 0..6 {
            prop_assert!(out[j].is_finite());
            prop_assert!(out[j].abs() <= input.max_velocity[j]);
            // acceleration-limited (qd_prev is within the velocity limits here)
            prop_assert!((out[j] - input.qd_prev[j]).abs() <= input.max_acceleration[j] * DT + 1e-12);
        }
        if status.is_fallback() {
            prop_assert_eq!(out, brake);
        }
        for (cp, _) in input.control_points.iter().enumerate() {
            for h in input.humans.iter().flatten() {
                let (v_out, d) = approach_speed(&input, cp, h, &out);
                let limit = cfg.ssm().approach_speed_limit_m_s(h.kind, d);
                let (v_prev, _) = approach_speed(&input, cp, h, &input.qd_prev);
                match status {
                    // feasible: within the limit
                    QpStatus::Solved => prop_assert!(v_out <= limit + 1e-6, "{} > {}", v_out, limit),
                    // infeasible: never approaches faster than the limit or than before
                    _ => prop_assert!(v_out <= limit.max(v_prev) + 1e-6, "{} > max({}, {})", v_out, limit, v_prev),
                }
            }
        }
    }

    #[test]
    fn never_panics_on_arbitrary_floats(vals in proptest::collection::vec(
        prop_oneof![any::<f64>(), -10.0..10.0f64, Just(f64::NAN), Just(f64::INFINITY)], 80)) {
        let mut input = base_input();
        let mut it = vals.into_iter();
        let mut next = move || it.next().unwrap_or(0.0);
        input.qd_ref = std::array::from_fn(|_| next());
        input.qd_prev = std::array::from_fn(|_| next());
        input.dt_s = next();
        input.max_velocity = std::array::from_fn(|_| next());
        input.max_acceleration = std::array::from_fn(|_| next());
        input.tcp_speed_cap_m_s = next();
        for cp in input.control_points.iter_mut() {
            cp.position = std::array::from_fn(|_| next());
            cp.jacobian[0] = std::array::from_fn(|_| next());
        }
        input.humans[1] = Some(HumanPoint { position: [next(), next(), next()], kind: HumanPointKind::Hand });
        let mut s = SpeedScaler::new(QpConfig::default()).unwrap();
        let mut out = [0.0; 6];
        let _ = s.solve(&input, &mut out);
        prop_assert!(out.iter().all(|v| v.is_finite()));
    }
}

#[test]
#[ignore]
fn sweep_budget_report() {
    use adapt::qp::QpParams;
    for sweeps in [500u32, 5000, 50000] {
        let cfg = QpConfig::new(
            adapt::ssm::SsmConfig::default(),
            QpParams {
                max_sweeps: sweeps,
                ..QpParams::default()
            },
        )
        .unwrap();
        let mut ours = SpeedScaler::new(cfg).unwrap();
        let mut rng = 0x2545_f491_4f6c_dd1du64;
        let mut st = [0usize; 5];
        let mut worst_v: f64 = 0.0;
        for _ in 0..300 {
            let input = random_input(&mut rng);
            let mut a = [0.0; 6];
            let s = ours.solve(&input, &mut a);
            st[s as usize] += 1;
            if s == QpStatus::TimeLimit || s == QpStatus::Infeasible {
                worst_v = worst_v.max(ours.report().max_violation_rad_s);
            }
        }
        eprintln!("sweeps {sweeps}: {st:?} worst viol of unconverged {worst_v:e}");
    }
}
