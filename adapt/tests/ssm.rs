//! Worked examples for speed and separation monitoring and the PFL contact limits, with the
//! arithmetic done by hand in the comments.

use adapt::ssm::{HumanPointKind, SpeedLimit, SsmConfig, SsmParams};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn separation_limit_worked_example_hand() {
    // Defaults: v_h = 2.0 m/s (hand, arm reach), T_r = 0.1 s, a_b = 2.5 m/s²,
    // C = 0.1 m, Z_d = 0.05 m, Z_r = 0.01 m; hand at d = 0.8 m.
    //   α = 1/(2·2.5) = 0.2 s²/m
    //   β = T_r + v_h/a_b = 0.1 + 2.0/2.5 = 0.9 s
    //   γ = v_h T_r + C + Z_d + Z_r − d = 0.2 + 0.1 + 0.05 + 0.01 − 0.8 = −0.44 m
    //   β² − 4αγ = 0.81 + 0.352 = 1.162, √ = 1.0779610
    //   v* = −2γ/(β + √…) = 0.88 / 1.9779610 = 0.4449027 m/s
    // Check S_p(v*): T_s = 0.4449027/2.5 = 0.1779611 s
    //   S_h = 2.0·(0.1 + 0.1779611) = 0.5559222
    //   S_r = 0.4449027·0.1 = 0.0444903
    //   S_s = 0.4449027²/(2·2.5) = 0.1979384/5 = 0.0395877
    //   S_p = 0.5559222 + 0.0444903 + 0.0395877 + 0.16 = 0.8000002 ≈ d ✓
    let cfg = SsmConfig::default();
    let v = cfg.separation_speed_limit_m_s(HumanPointKind::Hand, 0.8);
    assert!(close(v, 0.444_902_7, 1e-6), "v = {v}");
    let sp = cfg.protective_distance_m(HumanPointKind::Hand, v);
    assert!(close(sp, 0.8, 1e-12), "S_p = {sp}");
    assert!(close(cfg.stopping_distance_m(v), 0.039_587_7, 1e-6));
}

#[test]
fn separation_limit_worked_example_head() {
    // Head: v_h = 1.6 m/s (walking), d = 1.5 m.
    //   β = 0.1 + 1.6/2.5 = 0.74 s;  γ = 0.16 + 0.16 − 1.5 = −1.18 m
    //   β² − 4αγ = 0.5476 + 0.944 = 1.4916, √ = 1.2213108
    //   v* = 2.36 / (0.74 + 1.2213108) = 2.36 / 1.9613108 = 1.2032774 m/s
    let cfg = SsmConfig::default();
    let v = cfg.separation_speed_limit_m_s(HumanPointKind::Head, 1.5);
    assert!(close(v, 1.203_277_4, 1e-6), "v = {v}");
}

#[test]
fn inside_protective_distance_at_rest_gives_zero() {
    // Hand: S_p(0) = v_h T_r + C + Z_d + Z_r = 0.2 + 0.16 = 0.36 m > 0.3 m → must stop.
    let cfg = SsmConfig::default();
    assert!(close(
        cfg.protective_distance_m(HumanPointKind::Hand, 0.0),
        0.36,
        1e-12
    ));
    assert_eq!(
        cfg.separation_speed_limit_m_s(HumanPointKind::Hand, 0.3),
        0.0
    );
    assert_eq!(
        cfg.separation_speed_limit_m_s(HumanPointKind::Hand, 0.36),
        0.0
    );
    assert_eq!(
        cfg.separation_speed_limit_m_s(HumanPointKind::Head, f64::NAN),
        0.0
    );
}

#[test]
fn separation_limit_is_the_root_and_monotone() {
    let cfg = SsmConfig::default();
    let mut last = 0.0;
    for i in 0..400 {
        let d = 0.37 + i as f64 * 0.01;
        for kind in [HumanPointKind::Hand, HumanPointKind::Head] {
            let v = cfg.separation_speed_limit_m_s(kind, d);
            assert!(v > 0.0);
            assert!(close(cfg.protective_distance_m(kind, v), d, 1e-12));
        }
        let v = cfg.separation_speed_limit_m_s(HumanPointKind::Hand, d);
        assert!(v > last);
        last = v;
    }
}

#[test]
fn pfl_hand_limits_worked_example_ur5e() {
    // k = 75 N/mm = 75 000 N/m, √k = 273.86128 √(N/m)
    // m_R = M/2 + m_L = 17.7/2 + 5 = 8.85 + 5 = 13.85 kg
    // 1/m_H + 1/m_R = 1/0.6 + 1/13.85 = 1.6666667 + 0.0722022 = 1.7388689 1/kg, √ = 1.3186618
    // transient:    F = 280 N: 280/273.86128 = 1.0224154;  v = 1.0224154·1.3186618 = 1.3482207 m/s
    // quasi-static: F = 140 N: half of that = 0.6741104 m/s
    let cfg = SsmConfig::default();
    assert!(close(cfg.effective_robot_mass_kg(), 13.85, 1e-12));
    let vt = cfg.hand_transient_speed_m_s();
    let vq = cfg.hand_quasi_static_speed_m_s();
    assert!(close(vt, 1.348_220_7, 1e-6), "transient {vt}");
    assert!(close(vq, 0.674_110_4, 1e-6), "quasi-static {vq}");
    // Issue 4 quotes ≈ 1.36 and ≈ 0.68 m/s. Those are the figures *without* the payload:
    // m_R = 8.85 kg: 1/0.6 + 1/8.85 = 1.6666667 + 0.1129944 = 1.7796610, √ = 1.3340394
    // transient: 1.0224154·1.3340394 = 1.3639426 m/s; quasi-static: 0.6819713 m/s.
    let no_payload = SsmConfig::try_from(SsmParams {
        payload_kg: 0.0,
        ..SsmParams::default()
    })
    .unwrap();
    assert!(close(
        no_payload.hand_transient_speed_m_s(),
        1.363_942_6,
        1e-6
    ));
    assert!(close(
        no_payload.hand_quasi_static_speed_m_s(),
        0.681_971_3,
        1e-6
    ));
    // With the payload they round to 1.35 and 0.67 m/s: within 0.02 m/s of the figures.
    assert!(close(vt, 1.36, 0.02) && close(vq, 0.68, 0.01));
}

#[test]
fn approach_limit_uses_pfl_for_hands_in_contact_zone_only() {
    let cfg = SsmConfig::default();
    let vt = cfg.hand_transient_speed_m_s();
    assert_eq!(cfg.approach_speed_limit_m_s(HumanPointKind::Hand, 0.1), vt);
    assert_eq!(cfg.approach_speed_limit_m_s(HumanPointKind::Hand, 0.15), vt);
    // The head never gets the contact allowance.
    assert_eq!(cfg.approach_speed_limit_m_s(HumanPointKind::Head, 0.1), 0.0);
    // Outside the contact zone: SSM.
    assert_eq!(
        cfg.approach_speed_limit_m_s(HumanPointKind::Hand, 0.8),
        cfg.separation_speed_limit_m_s(HumanPointKind::Hand, 0.8)
    );
}

#[test]
fn config_validation_rejects_bad_values() {
    let bad = [
        SsmParams {
            reaction_time_s: 0.0,
            ..SsmParams::default()
        },
        SsmParams {
            braking_deceleration_m_s2: f64::NAN,
            ..SsmParams::default()
        },
        SsmParams {
            intrusion_distance_m: -0.1,
            ..SsmParams::default()
        },
        SsmParams {
            hand_mass_kg: f64::INFINITY,
            ..SsmParams::default()
        },
        SsmParams {
            payload_kg: -1.0,
            ..SsmParams::default()
        },
    ];
    for p in bad {
        let err = SsmConfig::try_from(p).unwrap_err().to_string();
        assert!(err.starts_with("invalid separation"), "{err}");
    }
    assert!(SsmConfig::try_from(SsmParams::default()).is_ok());
    assert!(SpeedLimit::new(-1.0).is_err());
    assert!(SpeedLimit::new(f64::NAN).is_err());
    assert_eq!(SpeedLimit::new(0.5).unwrap().m_s(), 0.5);
}
