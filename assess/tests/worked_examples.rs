//! Worked examples: one or more per section of the spec (`assess::spec`), each checking numbers
//! computed by hand.
//!
//! The hand arithmetic is written out in each test's comments. Every expected value below was
//! computed on paper (to 6 significant digits) from the spec's formulas, not by running the
//! code. Changing any constant or formula of the model makes at least one of these fail.
//!
//! The test workspace (all tests): the operator stands at the origin; four 0.2 m cubes are
//! centred 1 m away on the horizontal plane, and D_ws is set to 2 m for round numbers:
//!
//! | area | role | centre r_i |
//! |---|---|---|
//! | `ass` | assembly | (1, 0, 0) |
//! | `id` | tool identification | (0, 1, 0) |
//! | `ins` | instruction | (0, −1, 0) |
//! | `col` | collaboration | (−1, 0, 0) |

use assess::{
    AreaId, AssessConfig, Assessor, BaselineMode, BodyCue, Category, ComponentValues, CueFrame,
    HandCue, HeadCue, Indicator, Vec3, Workspace,
};

const ASS: Option<AreaId> = Some(AreaId(0));
const ID: Option<AreaId> = Some(AreaId(1));
const INS: Option<AreaId> = Some(AreaId(2));
const COL: Option<AreaId> = Some(AreaId(3));

fn workspace() -> Workspace {
    Workspace::from_toml_str(
        r#"
        diagonal_m = 2.0
        [[area]]
        name = "ass"
        role = "assembly"
        centre_m = [1.0, 0.0, 0.0]
        size_m = [0.2, 0.2, 0.2]
        [[area]]
        name = "id"
        role = "tool_identification"
        centre_m = [0.0, 1.0, 0.0]
        size_m = [0.2, 0.2, 0.2]
        [[area]]
        name = "ins"
        role = "instruction"
        centre_m = [0.0, -1.0, 0.0]
        size_m = [0.2, 0.2, 0.2]
        [[area]]
        name = "col"
        role = "collaboration"
        centre_m = [-1.0, 0.0, 0.0]
        size_m = [0.2, 0.2, 0.2]
        "#,
    )
    .unwrap()
}

fn assessor(cfg: AssessConfig) -> Assessor {
    Assessor::new(workspace(), cfg).unwrap()
}

/// A unit vector in the horizontal plane at `deg` degrees from +x towards +y.
fn yaw(deg: f64) -> Vec3 {
    let r = deg.to_radians();
    Vec3::new(r.cos(), r.sin(), 0.0)
}

fn head(facing: Vec3, confidence: f64) -> Option<HeadCue> {
    Some(HeadCue {
        position: Vec3::zeros(),
        facing,
        confidence,
    })
}

fn body(facing: Vec3, confidence: f64) -> Option<BodyCue> {
    Some(BodyCue {
        position: Vec3::zeros(),
        facing,
        confidence,
    })
}

fn hand(x: f64, y: f64, z: f64) -> Option<HandCue> {
    Some(HandCue {
        position: Vec3::new(x, y, z),
        confidence: 1.0,
    })
}

/// A frame with only a head cue looking towards `target` (None: straight up, which is 90° from
/// every area, so S = 0.5 < τ and the raw state is ∅).
fn looking(t: f64, target: Option<AreaId>) -> CueFrame {
    let facing = match target {
        Some(AreaId(0)) => Vec3::new(1.0, 0.0, 0.0),
        Some(AreaId(1)) => Vec3::new(0.0, 1.0, 0.0),
        Some(AreaId(2)) => Vec3::new(0.0, -1.0, 0.0),
        Some(AreaId(3)) => Vec3::new(-1.0, 0.0, 0.0),
        _ => Vec3::new(0.0, 0.0, 1.0),
    };
    CueFrame {
        head: head(facing, 1.0),
        ..CueFrame::empty(t)
    }
}

fn close(actual: f64, expected: f64, tol: f64) {
    assert!(
        (actual - expected).abs() <= tol,
        "expected {expected}, got {actual} (tolerance {tol})"
    );
}

fn config_m(m: usize) -> AssessConfig {
    let mut cfg = AssessConfig::default();
    cfg.confirmation.window_frames = m;
    cfg
}

// ---------------------------------------------------------------------------------------------
// §1 Cue-to-area evidence
// ---------------------------------------------------------------------------------------------

#[test]
fn s1_head_evidence_against_four_area_centres() {
    // Head at the origin facing 30° (towards +x, turned 30° towards +y). Angles to the centres:
    //   ass (1,0,0): 30° = π/6    → S = 1 − 1/6 = 0.833333
    //   id  (0,1,0): 60° = π/3    → S = 1 − 1/3 = 0.666667
    //   ins (0,−1,0): 120° = 2π/3 → S = 1 − 2/3 = 0.333333
    //   col (−1,0,0): 150° = 5π/6 → S = 1 − 5/6 = 0.166667
    // Only the head is present, so ω_h = 1 and S_i = S_i^h; argmax = ass, 0.833333 ≥ τ = 0.7.
    let mut a = assessor(AssessConfig::default());
    let out = a.update(&CueFrame {
        head: head(yaw(30.0), 0.9),
        ..CueFrame::empty(0.0)
    });
    assert_eq!(out.raw, ASS);
    close(out.raw_score, 0.833333, 1e-6);
    let expected = [0.833333, 0.666667, 0.333333, 0.166667];
    for (ev, want) in a.cue_evidence().iter().zip(expected) {
        close(ev[0], want, 1e-6);
        assert_eq!(ev[1], 0.0, "no body cue, no body evidence");
    }
    for (s, want) in a.fused_scores().iter().zip(expected) {
        close(*s, want, 1e-6);
    }
}

#[test]
fn s1_head_evidence_out_of_plane() {
    // Head at the origin facing (1, 0, 1)/√2: 45° up from ass's centre direction (1,0,0).
    //   ass: 45° → S = 0.75. id: angle between (1,0,1)/√2 and (0,1,0) = 90° → S = 0.5.
    // So the raw state is ass with S = 0.75 ≥ 0.7.
    let mut a = assessor(AssessConfig::default());
    let out = a.update(&CueFrame {
        head: head(Vec3::new(1.0, 0.0, 1.0), 1.0),
        ..CueFrame::empty(0.0)
    });
    assert_eq!(out.raw, ASS);
    close(a.cue_evidence()[0][0], 0.75, 1e-12);
    close(a.cue_evidence()[1][0], 0.5, 1e-12);
}

#[test]
fn s1_hand_evidence_from_box_distance() {
    // Hand at (0.5, 0, 0), D_ws = 2 m.
    //   ass box x∈[0.9,1.1]: distance 0.4 → S = 1 − 0.4/2 = 0.8
    //   id box x∈[−0.1,0.1], y∈[0.9,1.1]: dx = 0.4, dy = 0.9 → √(0.16 + 0.81) = 0.984886
    //       → S = 1 − 0.492443 = 0.507557; ins is the mirror image: 0.507557
    //   col box x∈[−1.1,−0.9]: distance 1.4 → S = 1 − 0.7 = 0.3
    // Only the hand is present: ω_m = 1, S_ass = 0.8 ≥ 0.7 → raw = ass.
    let mut a = assessor(AssessConfig::default());
    let mut f = CueFrame::empty(0.0);
    f.hands[1] = hand(0.5, 0.0, 0.0);
    let out = a.update(&f);
    assert_eq!(out.raw, ASS);
    let expected = [0.8, 0.507557, 0.507557, 0.3];
    for (ev, want) in a.cue_evidence().iter().zip(expected) {
        close(ev[2], want, 1e-6);
    }
    // Inside a box the distance is 0, so S = 1.
    f.hands[1] = hand(1.05, 0.05, -0.05);
    a.update(&CueFrame { t: 0.1, ..f });
    close(a.cue_evidence()[0][2], 1.0, 0.0);
}

// ---------------------------------------------------------------------------------------------
// §2 Fusion and raw state
// ---------------------------------------------------------------------------------------------

#[test]
fn s2_fusion_with_head_missing_renormalises() {
    // Body facing 30° with confidence 0.8 and the hand at (0.5, 0, 0) with confidence 1; no head.
    //   raw weights: ω_b = 0.25 · 0.8 = 0.2, ω_m = 0.15 · 1 = 0.15; sum 0.35
    //   renormalised: ω_b = 0.2/0.35 = 4/7 = 0.571429, ω_m = 3/7 = 0.428571
    //   S_ass = 4/7 · 0.833333 + 3/7 · 0.8      = 0.476190 + 0.342857 = 0.819048
    //   S_id  = 4/7 · 0.666667 + 3/7 · 0.507557 = 0.380952 + 0.217525 = 0.598477
    //   S_ins = 4/7 · 0.333333 + 3/7 · 0.507557 = 0.190476 + 0.217525 = 0.408001
    //   S_col = 4/7 · 0.166667 + 3/7 · 0.3      = 0.095238 + 0.128571 = 0.223810
    //   raw = ass (0.819048 ≥ 0.7)
    let mut a = assessor(AssessConfig::default());
    let mut f = CueFrame {
        body: body(yaw(30.0), 0.8),
        ..CueFrame::empty(0.0)
    };
    f.hands[0] = hand(0.5, 0.0, 0.0);
    let out = a.update(&f).clone();
    close(out.weights[0], 0.0, 0.0);
    close(out.weights[1], 0.571429, 1e-6);
    close(out.weights[2], 0.428571, 1e-6);
    assert_eq!(out.raw, ASS);
    for (s, want) in a
        .fused_scores()
        .iter()
        .zip([0.819048, 0.598477, 0.408001, 0.223810])
    {
        close(*s, want, 1e-6);
    }

    // A head cue below c_min = 0.3, or with a NaN inside, is missing: the same weights result.
    for bad in [
        head(yaw(-90.0), 0.29),
        head(Vec3::new(f64::NAN, 0.0, 0.0), 1.0),
    ] {
        let mut a = assessor(AssessConfig::default());
        let out = a.update(&CueFrame { head: bad, ..f });
        assert!(!out.present[0]);
        close(out.weights[1], 0.571429, 1e-6);
        assert_eq!(out.raw, ASS);
    }
}

#[test]
fn s2_all_cues_present_uses_confidence_weighted_base_weights() {
    // Head facing ins (−90°, conf 1), body facing 30° (conf 1), hand at (0.5,0,0) (conf 1).
    //   ω = (0.6, 0.25, 0.15) (sum 1, all confidences 1).
    //   Head evidence (−90° facing): ass 90° → 0.5; id 180° → 0; ins 0° → 1; col 90° → 0.5.
    //   S_ass = 0.6·0.5 + 0.25·0.833333 + 0.15·0.8      = 0.3 + 0.208333 + 0.12     = 0.628333
    //   S_ins = 0.6·1   + 0.25·0.333333 + 0.15·0.507557 = 0.6 + 0.083333 + 0.076134 = 0.759467
    //   → raw = ins (0.759467 ≥ 0.7): the head cue dominates.
    let mut a = assessor(AssessConfig::default());
    let mut f = CueFrame {
        head: head(yaw(-90.0), 1.0),
        body: body(yaw(30.0), 1.0),
        ..CueFrame::empty(0.0)
    };
    f.hands[0] = hand(0.5, 0.0, 0.0);
    let out = a.update(&f);
    assert_eq!(out.raw, INS);
    close(out.raw_score, 0.759467, 1e-6);
    close(a.fused_scores()[0], 0.628333, 1e-6);
}

#[test]
fn s2_fusion_during_a_large_torso_turn() {
    // Head facing ass (0°) throughout, conf 1; no hand. The torso turns from 0° to 90° at
    // 6° per frame at 30 fps (180°/s), then stays at 90° (facing id).
    //   Nominal weights: (0.6, 0.25)/0.85 = (0.705882, 0.294118).
    //   Turn weights:    (0.3, 0.55)/0.85 = (0.352941, 0.647059).
    //   With torso at 90°: body evidence ass 90° → 0.5, id 0° → 1; head: ass 1, id 90° → 0.5.
    //     nominal: S_ass = 0.705882 + 0.294118·0.5 = 0.852941; S_id = 0.352941 + 0.294118 = 0.647059
    //     turn:    S_ass = 0.352941 + 0.647059·0.5 = 0.676471; S_id = 0.176471 + 0.647059 = 0.823529
    //   Frame 15 (yaw 90°) vs frame 12 (yaw 72°): 18° / (3/30 s) = 180°/s > 90°/s → turn → raw id.
    //   Frame 16 (90°) vs frame 13 (78°): 12° / 0.1 s = 120°/s → still a turn.
    //   Frame 17 (90°) vs frame 14 (84°): 6° / 0.1 s = 60°/s → not a turn → nominal → raw ass.
    //   Frames 0–2 have fewer than 3 earlier body frames, so no rate is defined: nominal.
    let mut a = assessor(AssessConfig::default());
    let mut raws = Vec::new();
    let mut turning = Vec::new();
    for k in 0..20 {
        let torso = (6.0 * k as f64).min(90.0);
        let out = a.update(&CueFrame {
            head: head(yaw(0.0), 1.0),
            body: body(yaw(torso), 1.0),
            ..CueFrame::empty(k as f64 / 30.0)
        });
        raws.push(out.raw);
        turning.push(out.turning);
        if k == 15 {
            close(out.weights[0], 0.352941, 1e-6);
            close(out.weights[1], 0.647059, 1e-6);
            close(out.raw_score, 0.823529, 1e-6);
        }
        if k == 17 {
            close(out.weights[0], 0.705882, 1e-6);
            close(out.raw_score, 0.852941, 1e-6);
        }
    }
    assert_eq!(&turning[0..3], &[false, false, false]);
    assert!(turning[3..=16].iter().all(|&t| t), "{turning:?}");
    assert!(turning[17..].iter().all(|&t| !t), "{turning:?}");
    assert_eq!(raws[15], ID, "during the turn the torso dominates");
    assert_eq!(raws[16], ID);
    assert_eq!(raws[17], ASS, "a static head–torso angle is not a turn");
    assert_eq!(raws[19], ASS);
}

#[test]
fn s2_ties_go_to_the_first_listed_area_and_tau_gates() {
    // Facing (1, 1, 0), exactly between ass and id: both at 45° → S = 0.75 each; the tie goes
    // to ass, listed first. Facing 60°: ass 60° → 0.666667, id 30° → 0.833333 → id.
    // Facing (−1, 1, 0) (between id and col): 45° from both → tie → id (listed before col).
    // Facing (−1, −1, 0): col and ins both at 45° → ins (listed before col).
    // (Exact ties need exactly symmetric facings: the components are equal in magnitude.)
    // With τ = 0.8 the 45° ties (0.75) are below τ → ∅.
    let cases = [
        (Vec3::new(1.0, 1.0, 0.0), ASS),
        (yaw(60.0), ID),
        (Vec3::new(-1.0, 1.0, 0.0), ID),
        (Vec3::new(-1.0, -1.0, 0.0), INS),
    ];
    for (facing, want) in cases {
        let mut a = assessor(AssessConfig::default());
        let out = a.update(&CueFrame {
            head: head(facing, 1.0),
            ..CueFrame::empty(0.0)
        });
        assert_eq!(out.raw, want, "facing {facing:?}");
        close(
            out.raw_score,
            if want == ID && facing.x > 0.0 {
                0.833333
            } else {
                0.75
            },
            1e-6,
        );
    }
    let mut cfg = AssessConfig::default();
    cfg.fusion.tau = 0.8;
    let mut a = assessor(cfg);
    let out = a.update(&CueFrame {
        head: head(Vec3::new(1.0, 1.0, 0.0), 1.0),
        ..CueFrame::empty(0.0)
    });
    assert_eq!(out.raw, None);
    assert!(out.valid, "∅ is still a valid state");
}

#[test]
fn s3_confirmation_with_m5_including_unassigned_and_invalid_frames() {
    // M = 5: a state needs more than 2.5, i.e. ≥ 3, of the last 5 valid frames.
    // frame raw  window (last 5 valid)  counts          F
    //  1    a    a                      a1              ∅ (before the first confirmation)
    //  2    a    a a                    a2              ∅
    //  3    a    a a a                  a3              a
    //  4    b    a a a b                a3 b1           a
    //  5    ∅    a a a b ∅              a3 b1 ∅1        a
    //  6    b    a a b ∅ b              a2 b2 ∅1        a (no majority: hold)
    //  7    b    a b ∅ b b              b3              b
    //  8    ∅    b ∅ b b ∅              b3 ∅2           b
    //  9    ∅    ∅ b b ∅ ∅              ∅3 b2           ∅ (∅ confirmed by majority)
    // 10    —    invalid: not pushed                     ∅ (= F(t−1))
    // 11    a    b b ∅ ∅ a              b2 ∅2 a1        ∅
    // 12    a    b ∅ ∅ a a              a2 ∅2 b1        ∅
    // 13    a    ∅ ∅ a a a              a3 ∅2           a
    // (a = ass, b = id)
    let script = [
        Some(ASS),
        Some(ASS),
        Some(ASS),
        Some(ID),
        Some(None),
        Some(ID),
        Some(ID),
        Some(None),
        Some(None),
        None, // invalid frame: no cue at all
        Some(ASS),
        Some(ASS),
        Some(ASS),
    ];
    let expected = [
        None, None, ASS, ASS, ASS, ASS, ID, ID, None, None, None, None, ASS,
    ];
    let mut a = assessor(config_m(5));
    for (k, (raw, want)) in script.iter().zip(expected).enumerate() {
        let t = k as f64 / 30.0;
        let frame = match raw {
            Some(target) => looking(t, *target),
            None => CueFrame::empty(t),
        };
        let out = a.update(&frame);
        assert_eq!(out.valid, raw.is_some(), "frame {}", k + 1);
        if let Some(target) = raw {
            assert_eq!(out.raw, *target, "frame {} raw", k + 1);
        }
        assert_eq!(out.confirmed, want, "frame {} confirmed", k + 1);
    }
}

#[test]
fn s3_default_m15_and_even_m_need_a_strict_majority() {
    // Default M = 15: a strict majority is ≥ 8 frames (2·8 = 16 > 15; 2·7 = 14 is not).
    // Looking at ass from frame 0: F = ∅ for frames 0–6 (1..7 in the window), ass at frame 7.
    let mut a = assessor(AssessConfig::default());
    for k in 0..10usize {
        let out = a.update(&looking(k as f64 / 30.0, ASS));
        assert_eq!(out.confirmed, if k < 7 { None } else { ASS }, "frame {k}");
    }
    // M = 4: two of four is a tie, not a majority (2·2 = 4 is not > 4); three confirm.
    let mut a = assessor(config_m(4));
    let confirmed: Vec<_> = (0..3)
        .map(|k| a.update(&looking(k as f64 / 30.0, ID)).confirmed)
        .collect();
    assert_eq!(confirmed, vec![None, None, ID]);
}

// ---------------------------------------------------------------------------------------------
// §4 Area demand
// ---------------------------------------------------------------------------------------------

#[test]
fn s4_occupation_and_valid_time_with_irregular_dt_and_invalid_frames() {
    // M = 1, so F = F_raw on every valid frame. Backward rectangle: frame k contributes
    // Δt_k = t_k − t_{k−1} (capped at 0.2 s) with its own state and validity.
    // frame  t     state    Δt_k            T_ass  T_id  T_v
    //  0     0.00  ass      0 (first)       0      0     0
    //  1     0.10  ass      0.10            0.10   0     0.10
    //  2     0.25  ass      0.15            0.25   0     0.25
    //  3     0.30  invalid  0.05 (not counted; F stays ass)
    //  4     0.60  id       0.30 → 0.20     0.25   0.20  0.45
    //  5     0.65  ∅        0.05            0.25   0.20  0.50
    //  6     0.70  id       0.05            0.25   0.25  0.55
    // AED = 0.25/0.55 = 0.454545, TID = 0.25/0.55 = 0.454545, ICD = COL = 0,
    // ΣD = 0.909091 (the rest, 0.05/0.55, is ∅ time).
    let frames = [
        (0.00, Some(ASS)),
        (0.10, Some(ASS)),
        (0.25, Some(ASS)),
        (0.30, None),
        (0.60, Some(ID)),
        (0.65, Some(None)),
        (0.70, Some(ID)),
    ];
    let mut a = assessor(config_m(1));
    let mut dts = Vec::new();
    for (t, raw) in frames {
        let f = match raw {
            Some(target) => looking(t, target),
            None => CueFrame::empty(t),
        };
        let out = a.update(&f);
        dts.push(out.dt_s);
    }
    for (got, want) in dts.iter().zip([0.0, 0.1, 0.15, 0.05, 0.2, 0.05, 0.05]) {
        close(*got, want, 1e-9);
    }
    let out = a.assessment();
    let c = &out.cumulative;
    close(c.valid_time_s, 0.55, 1e-9);
    close(c.aed, 0.454545, 1e-6);
    close(c.tid, 0.454545, 1e-6);
    close(c.icd, 0.0, 0.0);
    close(c.col, 0.0, 0.0);
    close(out.area_demand.iter().sum::<f64>(), 0.909091, 1e-6);
    assert_eq!(out.confirmed, ID);
}

#[test]
fn s4_before_any_valid_time_demand_is_zero() {
    // A first frame contributes Δt = 0, so T_v = 0 and every D_i is 0 (an invalid assessment).
    let mut a = assessor(AssessConfig::default());
    let out = a.update(&looking(0.0, ASS));
    assert_eq!(out.cumulative.valid_time_s, 0.0);
    assert_eq!(out.cumulative.aed, 0.0);
    assert_eq!(out.cumulative.asd_ctx, 0.0);
}

// ---------------------------------------------------------------------------------------------
// §5 Attention–behaviour inconsistency
// ---------------------------------------------------------------------------------------------

#[test]
fn s5_abi_from_perceptual_and_action_states() {
    // M = 1, Δt = 0.1 s. The head looks at ins throughout (F^per = ins whenever the head is there).
    // frame  head  hand                            F^act              v_AB  I_AB
    //  0     ins   in the ass box (1,0,0)          ass                 (Δt = 0)
    //  1     ins   in the ass box                  ass                 1     1
    //  2     ins   (0, −0.85, 0): 0.05 m from ins  ins (≤ d_act 0.1)   1     0
    //  3     ins   (0.5, 0.5, 0): > 0.1 m from all ∅                   1     1
    //  4     —     in the ass box                  ass                 0     0
    //  5     ins   —                               —                   0     0
    // ∫v_AB = 0.3 s, ∫I_AB = 0.2 s → ABI = 0.2 / 0.3 = 0.666667.
    let ins = || head(Vec3::new(0.0, -1.0, 0.0), 1.0);
    let rows = [
        (ins(), hand(1.0, 0.0, 0.0)),
        (ins(), hand(1.0, 0.0, 0.0)),
        (ins(), hand(0.0, -0.85, 0.0)),
        (ins(), hand(0.5, 0.5, 0.0)),
        (None, hand(1.0, 0.0, 0.0)),
        (ins(), None),
    ];
    let expected_act = [ASS, ASS, INS, None, ASS, None];
    let mut a = assessor(config_m(1));
    for (k, (h, m)) in rows.into_iter().enumerate() {
        let mut f = CueFrame {
            head: h,
            ..CueFrame::empty(k as f64 * 0.1)
        };
        f.hands[1] = m;
        let out = a.update(&f);
        if out.action.1 {
            assert_eq!(out.action.0, expected_act[k], "frame {k}");
        }
        if out.perceptual.1 {
            assert_eq!(out.perceptual.0, INS, "frame {k}");
        }
    }
    let c = &a.assessment().cumulative;
    close(c.ab_valid_time_s, 0.3, 1e-9);
    close(c.ab_inconsistent_time_s, 0.2, 1e-9);
    close(c.abi, 0.666667, 1e-6);
}

// ---------------------------------------------------------------------------------------------
// §6 Context-aware switching
// ---------------------------------------------------------------------------------------------

/// The scripted sequence ins→ass→col→id→∅→ass, five frames each at Δt = 0.1 s, M = 1.
fn asd_script() -> Vec<CueFrame> {
    let states = [INS, ASS, COL, ID, None, ASS];
    (0..30)
        .map(|k| looking(k as f64 * 0.1, states[k / 5]))
        .collect()
}

#[test]
fn s6_asd_ctx_on_scripted_sequence_with_default_costs() {
    // Switch events (default costs c_high 3, c_int 2, c_base 1):
    //   frame  5: ins → ass   {ins, ass} → c_high = 3   C_sw = 3
    //   frame 10: ass → col   other      → c_base = 1   C_sw = 4
    //   frame 15: col → id    {col, id}  → c_int  = 2   C_sw = 6
    //   frame 20: id → ∅      not a switch              C_sw = 6
    //   frame 25: ∅ → ass     counts as id → ass, c_base = 1, C_sw = 7
    // T_v at frame k = 0.1·k (frame 0 contributes 0). ASD_ctx = C_sw / T_v:
    //   frame  5: 3/0.5 = 6.0     frame  9: 3/0.9 = 3.333333
    //   frame 10: 4/1.0 = 4.0     frame 15: 6/1.5 = 4.0
    //   frame 20: 6/2.0 = 3.0     frame 25: 7/2.5 = 2.8     frame 29: 7/2.9 = 2.413793
    let mut a = assessor(config_m(1));
    let mut asd = Vec::new();
    let mut costs = Vec::new();
    for f in asd_script() {
        let out = a.update(&f);
        asd.push(out.cumulative.asd_ctx);
        costs.push(out.switch_cost);
    }
    let events: Vec<(usize, f64)> = costs
        .iter()
        .enumerate()
        .filter_map(|(k, c)| c.map(|c| (k, c)))
        .collect();
    assert_eq!(events, vec![(5, 3.0), (10, 1.0), (15, 2.0), (25, 1.0)]);
    for (k, want) in [
        (4, 0.0),
        (5, 6.0),
        (9, 3.333333),
        (10, 4.0),
        (15, 4.0),
        (20, 3.0),
        (25, 2.8),
        (29, 2.413793),
    ] {
        close(asd[k], want, 1e-6);
    }
    assert_eq!(a.assessment().switches, 4);
    close(a.assessment().cumulative.switch_cost, 7.0, 0.0);
    // Between events ASD_ctx only decays: frames 6..9 strictly decrease.
    assert!(asd[6..10].windows(2).all(|w| w[1] < w[0]));
}

#[test]
fn s6_custom_costs_change_the_sum() {
    // With c_high 5, c_int 4, c_base 0.5 the same script gives C_sw = 5 + 0.5 + 4 + 0.5 = 10,
    // ASD_ctx at frame 29 = 10/2.9 = 3.448276.
    let mut cfg = config_m(1);
    cfg.switching.cost_high = 5.0;
    cfg.switching.cost_int = 4.0;
    cfg.switching.cost_base = 0.5;
    let mut a = assessor(cfg);
    for f in asd_script() {
        a.update(&f);
    }
    close(a.assessment().cumulative.asd_ctx, 3.448276, 1e-6);
}

// ---------------------------------------------------------------------------------------------
// §7 Operation hesitation
// ---------------------------------------------------------------------------------------------

/// A hand-only frame with the robot context.
fn hand_frame(t: f64, x: Option<f64>, c: bool, g: bool) -> CueFrame {
    let mut f = CueFrame::empty(t);
    f.hands[0] = x.map(|x| HandCue {
        position: Vec3::new(x, 0.0, 0.0),
        confidence: 1.0,
    });
    f.robot.collaborating = c;
    f.robot.incomplete = g;
    f
}

/// The One-Euro filter made transparent (cutoff 1 MHz: α = 1/(1 + 1.6e−6) at Δt = 0.1 s), so
/// hand speeds are |Δx|/Δt to ~1e−6 and can be computed by hand. The filter itself has its
/// own worked example in `assess/src/filter.rs`.
fn transparent_filter() -> AssessConfig {
    let mut cfg = AssessConfig::default();
    cfg.hesitation.one_euro.min_cutoff_hz = 1e6;
    cfg
}

#[test]
fn s7_ohd_with_gates_t_min_and_adaptive_threshold() {
    // Δt = 0.1 s. Hand x per frame and context:
    //  frames  0–19: moving +0.02 m/frame (0.2 m/s), C = 1, G = 1
    //  frames 20–24: still, C = 1, G = 1            → low motion
    //  frames 25–29: still, C = 1, G = 0            → gated out by G
    //  frames 30–34: still, C = 0, G = 1            → gated out by C
    //  frames 35–36: still, C = 1, G = 1            → a 0.2 s run < t_min: not hesitation
    //  frame  37:    hand missing, C = 1, G = 1     → v_h undefined, H = 0, C accumulates
    //  frame  38:    hand back, C = 1, G = 1        → only re-initialises the filter
    //  frame  39:    still, C = 1, G = 1            → a 0.1 s run
    // Threshold: samples are v_h of earlier C = 1 frames. v_h is undefined on frame 0, so
    // frames 1..10 give ten 0.2 m/s samples worth 1.0 s. Up to frame 10 the samples add up to
    // < 1 s → v_th = v_max = 0.10. From frame 11: median 0.2 → v_th = clamp(0.35·0.2 = 0.07,
    // 0.03, 0.10) = 0.07. During 20–24 the zero samples are a minority: median stays 0.2.
    // Run 20–24: lengths 0.1, 0.2, 0.3 → t_min = 0.3 reached on frame 22: T_hes += 0.3 at once
    // (frames 20–22 retroactively); frames 23, 24 add 0.1 each → T_hes = 0.5.
    // T_collab = Σ Δt over C = 1 frames = frames 1–29 (2.9 s) + 35–39 (0.5 s) = 3.4 s.
    // OHD = 0.5 / (3.4 + 0.001) = 0.147016. At frame 22: 0.3 / (2.2 + 0.001) = 0.136302.
    let mut a = assessor(transparent_filter());
    let mut x = 0.0;
    let mut log = Vec::new();
    for k in 0..40usize {
        if (1..=19).contains(&k) {
            x += 0.02;
        }
        let (c, g) = match k {
            25..=29 => (true, false),
            30..=34 => (false, true),
            _ => (true, true),
        };
        let pos = if k == 37 { None } else { Some(x) };
        let out = a.update(&hand_frame(k as f64 * 0.1, pos, c, g)).clone();
        log.push(out);
    }
    close(log[5].speed_threshold_m_s, 0.10, 0.0);
    close(log[10].speed_threshold_m_s, 0.10, 0.0);
    close(log[11].speed_threshold_m_s, 0.07, 1e-5);
    close(log[24].speed_threshold_m_s, 0.07, 1e-5);
    close(log[15].hand_speed_m_s.unwrap(), 0.2, 1e-4);
    assert!(!log[15].low_motion, "0.2 m/s is above v_th");
    assert_eq!(
        log[0].hand_speed_m_s, None,
        "the first hand frame only initialises the filter"
    );
    assert_eq!(
        log[38].hand_speed_m_s, None,
        "the reappearing hand only re-initialises"
    );
    assert!(log[39].hand_speed_m_s.is_some());

    let hes: Vec<bool> = log.iter().map(|o| o.hesitating).collect();
    let low: Vec<bool> = log.iter().map(|o| o.low_motion).collect();
    assert!(low[20] && low[21] && low[22] && low[23] && low[24]);
    assert!(!hes[20] && !hes[21], "the run is shorter than t_min");
    assert!(hes[22] && hes[23] && hes[24]);
    assert!(!low[25] && !low[30], "the G and C gates");
    assert!(low[35] && low[36] && !hes[35] && !hes[36], "0.2 s < t_min");
    assert!(!low[37], "hand missing: H = 0");
    assert!(hes.iter().filter(|&&h| h).count() == 3);

    close(log[21].cumulative.hesitation_time_s, 0.0, 0.0);
    close(log[22].cumulative.hesitation_time_s, 0.3, 1e-9);
    close(log[22].cumulative.ohd, 0.136302, 1e-6);
    let end = &log[39].cumulative;
    close(end.hesitation_time_s, 0.5, 1e-9);
    close(end.collaboration_time_s, 3.4, 1e-9);
    close(end.ohd, 0.147016, 1e-6);
}

#[test]
fn s7_threshold_clamps_to_v_min() {
    // The hand moves at 0.05 m/s (0.005 m per 0.1 s) with C = G = 1 for 2 s. After 1 s of
    // samples, v_th = clamp(0.35·0.05 = 0.0175, 0.03, 0.10) = 0.03 < 0.05, so this slow but
    // steady motion is not low motion. Under the initial v_max = 0.10 it was: frames 1..10
    // (v_h 0.05 < 0.10) form a run that reaches t_min = 0.3 on frame 3 → 0.3 s at once, then
    // frames 4..10 add 0.7 s → T_hes = 1.0 s; from frame 11 on, v_th = 0.03 and the run ends.
    let mut a = assessor(transparent_filter());
    let mut last = None;
    for k in 0..20usize {
        let out = a.update(&hand_frame(
            k as f64 * 0.1,
            Some(0.005 * k as f64),
            true,
            true,
        ));
        if k == 10 {
            close(out.speed_threshold_m_s, 0.10, 0.0);
            assert!(out.hesitating);
        }
        if k == 11 {
            close(out.speed_threshold_m_s, 0.03, 0.0);
            assert!(!out.low_motion);
        }
        last = Some(out.clone());
    }
    close(last.unwrap().cumulative.hesitation_time_s, 1.0, 1e-9);
}

#[test]
fn s7_t_min_counts_the_run_length() {
    // Δt = 0.05 s, a still hand with C = G = 1 from frame 0. Frame 0 initialises the filter
    // (v_h undefined); from frame 1, v_h = 0 < v_th, so the run length at frame k is 0.05·k.
    // t_min = 0.3 s is reached at frame 6 (0.30), not at frame 5 (0.25): T_hes jumps from 0
    // to 0.30 s on frame 6, and frame 7 adds 0.05 → 0.35 s.
    let mut a = assessor(transparent_filter());
    let mut hes = Vec::new();
    for k in 0..8usize {
        let out = a.update(&hand_frame(k as f64 * 0.05, Some(0.4), true, true));
        hes.push((out.hesitating, out.cumulative.hesitation_time_s));
    }
    assert_eq!(hes[5], (false, 0.0));
    assert!(hes[6].0);
    close(hes[6].1, 0.30, 1e-9);
    close(hes[7].1, 0.35, 1e-9);
}

#[test]
fn s7_threshold_median_covers_the_last_10_s() {
    // Δt = 0.1 s. Frames 0–50: C = 1, the hand moves at 0.2 m/s (samples 0.2 from frame 1).
    // Frames 51–130: C = 0, the hand still (no samples are taken while C = 0).
    // Frames 131–151: C = 1, the hand still (samples ≈ 0).
    // Frame 131 (t = 13.1): samples with 13.1 − t_k < 10 s are frames 32–50 (≈ 1.9 s, all 0.2)
    //   → v_th = 0.35·0.2 = 0.07.
    // Frame 151 (t = 15.1): every sample of frames ≤ 50 (t ≤ 5.0) is ≥ 10 s old; the samples
    //   are frames 131–150 (2.0 s, all ≈ 0) → v_th = clamp(0, 0.03, 0.10) = 0.03.
    let mut a = assessor(transparent_filter());
    let mut vth = Vec::new();
    for k in 0..152usize {
        let x = 0.02 * k.min(50) as f64;
        let c = !(51..=130).contains(&k);
        vth.push(
            a.update(&hand_frame(k as f64 * 0.1, Some(x), c, true))
                .speed_threshold_m_s,
        );
    }
    close(vth[131], 0.07, 1e-5);
    close(vth[151], 0.03, 0.0);
}

#[test]
fn s7_ohd_is_zero_without_collaboration() {
    // Without C, nothing can hesitate and T_collab = 0: OHD = 0 / (0 + ε) = 0.
    let mut a = assessor(transparent_filter());
    for k in 0..30usize {
        a.update(&hand_frame(k as f64 * 0.1, Some(0.0), false, true));
    }
    assert_eq!(a.assessment().cumulative.ohd, 0.0);
    assert_eq!(a.assessment().cumulative.collaboration_time_s, 0.0);
}

// ---------------------------------------------------------------------------------------------
// §8 Composite, category, windowed values, dominant indicator
// ---------------------------------------------------------------------------------------------

#[test]
fn s8_composite_and_category() {
    // After the §6 script (frame 29, T_v = 2.9 s):
    //   T_ins = frames 1–4 = 0.4; T_ass = frames 5–9 + 25–29 = 1.0; T_col = 0.5; T_id = 0.5
    //   AED = 1.0/2.9 = 0.344828, TID = 0.5/2.9 = 0.172414, ICD = 0.4/2.9 = 0.137931
    //   ASD_ctx = 2.413793 → ASD̃ = min(1, 2.413793/0.5) = 1; OHD = 0 (C never set)
    //   HRC-CWL = 0.2·(0.344828 + 0.172414 + 0.137931 + 1 + 0) = 0.2·1.655172 = 0.331034
    //   → medium (0.33 ≤ 0.331034 < 0.66).
    // With w = (0.4, 0.1, 0.1, 0.2, 0.2): 0.137931 + 0.017241 + 0.013793 + 0.2 = 0.368966.
    // With medium_from = 0.34 the default-weight composite 0.331034 is low.
    let run = |cfg: AssessConfig| {
        let mut a = assessor(cfg);
        for f in asd_script() {
            a.update(&f);
        }
        a.assessment().clone()
    };
    let out = run(config_m(1));
    let c = &out.cumulative;
    close(c.aed, 0.344828, 1e-6);
    close(c.tid, 0.172414, 1e-6);
    close(c.icd, 0.137931, 1e-6);
    close(c.asd_norm, 1.0, 0.0);
    close(c.ohd, 0.0, 0.0);
    close(c.hrc_cwl, 0.331034, 1e-6);
    assert_eq!(c.category, Category::Medium);

    let mut cfg = config_m(1);
    cfg.composite.weights = ComponentValues::from_array([0.4, 0.1, 0.1, 0.2, 0.2]);
    close(run(cfg).cumulative.hrc_cwl, 0.368966, 1e-6);

    let mut cfg = config_m(1);
    cfg.composite.medium_from = 0.34;
    assert_eq!(run(cfg).cumulative.category, Category::Low);

    // Around the default high bound 0.66:
    //   w = (0, 0, 0.4, 0.6, 0):   0.4·0.137931 + 0.6·1 = 0.655172 → medium
    //   w = (0.2, 0, 0, 0.6, 0.2): 0.2·0.344828 + 0.6·1 = 0.668966 → high
    let mut cfg = config_m(1);
    cfg.composite.weights = ComponentValues::from_array([0.0, 0.0, 0.4, 0.6, 0.0]);
    let c = run(cfg).cumulative;
    close(c.hrc_cwl, 0.655172, 1e-6);
    assert_eq!(c.category, Category::Medium);
    let mut cfg = config_m(1);
    cfg.composite.weights = ComponentValues::from_array([0.2, 0.0, 0.0, 0.6, 0.2]);
    let c = run(cfg).cumulative;
    close(c.hrc_cwl, 0.668966, 1e-6);
    assert_eq!(c.category, Category::High);
}

#[test]
fn s8_asd_normalisation_below_the_reference() {
    // ass for frames 0–49, ins for frames 50–99 at Δt = 0.1 s, M = 1: one switch ass → ins
    // (c_high = 3) at frame 50. At frame 99: T_v = 9.9 s, ASD_ctx = 3/9.9 = 0.303030 /s,
    // ASD̃ = 0.303030/0.5 = 0.606061. AED = 4.9/9.9 = 0.494949 (frames 1–49),
    // ICD = 5.0/9.9 = 0.505051. HRC-CWL = 0.2·(0.494949 + 0 + 0.505051 + 0.606061 + 0)
    // = 0.2·1.606061 = 0.321212 → low.
    let mut a = assessor(config_m(1));
    for k in 0..100usize {
        a.update(&looking(k as f64 * 0.1, if k < 50 { ASS } else { INS }));
    }
    let c = &a.assessment().cumulative;
    close(c.asd_ctx, 0.303030, 1e-6);
    close(c.asd_norm, 0.606061, 1e-6);
    close(c.aed, 0.494949, 1e-6);
    close(c.icd, 0.505051, 1e-6);
    close(c.hrc_cwl, 0.321212, 1e-6);
    assert_eq!(c.category, Category::Low);
}

#[test]
fn s8_windowed_indicators_cover_the_horizon_only() {
    // Same script, horizon H = 0.95 s: at frame 29 (t = 2.9) the window holds frames with
    // 2.9 − t_k < 0.95, i.e. frames 20–29: ∅ ×5 (0.5 s) and ass ×5 (0.5 s), and the switch
    // event of frame 25 (id → ass, cost 1).
    //   T_v^win = 1.0, AED^win = 0.5, TID^win = ICD^win = 0, ASD^win = 1/1.0 = 1.0 /s.
    let mut cfg = config_m(1);
    cfg.window.horizon_s = 0.95;
    let mut a = assessor(cfg);
    for f in asd_script() {
        a.update(&f);
    }
    let w = &a.assessment().windowed;
    close(w.valid_time_s, 1.0, 1e-9);
    close(w.aed, 0.5, 1e-9);
    close(w.tid, 0.0, 0.0);
    close(w.icd, 0.0, 0.0);
    close(w.asd_ctx, 1.0, 1e-9);
    // The cumulative values are untouched by the horizon.
    close(a.assessment().cumulative.asd_ctx, 2.413793, 1e-6);
}

/// Config for the dominant-indicator examples: fixed baseline, H = 2 s, M = 1.
fn dominant_config(baseline: [f64; 5]) -> AssessConfig {
    let mut cfg = config_m(1);
    cfg.window.horizon_s = 2.0;
    cfg.dominant.baseline_mode = BaselineMode::Fixed;
    cfg.dominant.baseline = ComponentValues::from_array(baseline);
    cfg
}

#[test]
fn s8_dominant_switches_only_after_t_dom() {
    // Δt = 0.125 s (exact in binary), H = 2 s → a full window holds 16 frames (2.0 s).
    // b = (0.50, 0.15, 0.15, 0.20, 0.10), w = 0.2 each, T_dom = 3 s, margin 0.02.
    // Frames 0–39 (t 0–4.875): looking at ass. Frame 0 has T_v = 0 → every e = 0 → "none".
    //   From frame 1: AED^win = 1 → e_AED = 0.2·(1 − 0.5) = 0.1; the rest 0 → candidate AED
    //   since t = 0.125 → reported AED at t − 0.125 ≥ 3, i.e. t = 3.125 (frame 25).
    // Frames 40–: looking at ins. Frame 40 (t = 5): window = frames 25–40 → ICD = 1/16,
    //   AED = 15/16, switch ass→ins (c_high 3) → ASD^win = 3/2.0 = 1.5 /s → ASD̃ = 1 →
    //   e_ASD = 0.2·(1 − 0.2) = 0.16 > e_AED = 0.2·(0.9375 − 0.5) = 0.0875 → candidate ASD_ctx.
    //   Frame n (41..55): ICD = (n − 39)/16, e_ICD = 0.2·(ICD − 0.15): frame 54 → 0.1575 < 0.16,
    //   frame 55 → ICD = 1 → 0.17 > 0.16 → candidate ICD since t = 6.875.
    //   ASD_ctx was candidate for only 1.875 s < T_dom: never reported.
    //   Frame 56 (t = 7): the switch (t = 5) leaves the window (7 − 5 ≥ 2) → e_ASD = 0.
    //   ICD reported at t − 6.875 ≥ 3 → t = 9.875 (frame 79), lead 0.17 − e_AED(0) ≥ 0.02.
    let mut a = assessor(dominant_config([0.50, 0.15, 0.15, 0.20, 0.10]));
    let mut reported = Vec::new();
    let mut candidate = Vec::new();
    for k in 0..90usize {
        let target = if k < 40 { ASS } else { INS };
        let out = a.update(&looking(k as f64 * 0.125, target));
        reported.push(out.dominant.indicator);
        candidate.push(out.dominant.candidate);
        if k == 25 {
            close(out.dominant.strength, 0.1, 1e-12);
            close(out.dominant.held_for_s, 0.0, 0.0);
        }
        if k == 40 {
            close(out.dominant.contributions[3], 0.16, 1e-12);
            close(out.dominant.contributions[0], 0.0875, 1e-12);
        }
        if k == 79 {
            close(out.dominant.strength, 0.17, 1e-12);
        }
    }
    assert_eq!(candidate[0], None);
    assert!(reported[..25].iter().all(|r| r.is_none()));
    assert!(reported[25..79].iter().all(|r| *r == Some(Indicator::Aed)));
    assert!(reported[79..].iter().all(|r| *r == Some(Indicator::Icd)));
    assert_eq!(candidate[40], Some(Indicator::AsdCtx));
    assert_eq!(candidate[54], Some(Indicator::AsdCtx));
    assert_eq!(candidate[55], Some(Indicator::Icd));
    assert!(!reported.contains(&Some(Indicator::AsdCtx)));
}

#[test]
fn s8_dominant_needs_the_margin() {
    // b = (0.40, 0.15, 0.35, 1.0, 1.0) (ASD and OHD can never contribute), H = 2 s, Δt = 0.125.
    // Frames 0–39 look at ass → AED reported from frame 25 (as above), e_AED = 0.2·0.6 = 0.12.
    // From frame 40 the gaze alternates ins/ass every frame. Once the window holds only
    // alternating frames (8 ins, 8 ass): AED = ICD = 0.5 →
    //   e_AED = 0.2·(0.5 − 0.40) = 0.02, e_ICD = 0.2·(0.5 − 0.35) = 0.03.
    // ICD is the candidate for longer than T_dom but leads by only 0.01 < 0.02: AED stays.
    let mut a = assessor(dominant_config([0.40, 0.15, 0.35, 1.0, 1.0]));
    for k in 0..160usize {
        let target = if k < 40 || k % 2 == 1 { ASS } else { INS };
        a.update(&looking(k as f64 * 0.125, target));
    }
    let d = &a.assessment().dominant;
    assert_eq!(d.candidate, Some(Indicator::Icd));
    assert_eq!(d.indicator, Some(Indicator::Aed));
    close(d.contributions[0], 0.02, 1e-12);
    close(d.contributions[2], 0.03, 1e-12);
}

#[test]
fn s8_dominant_baseline_from_the_calibration_period() {
    // Calibrate mode with a 1 s period, looking at ass, Δt = 0.125: frames 0–7 are inside
    // (t − t0 < 1). Frame 0 has windowed AED = 0 (T_v = 0), frames 1–7 have AED = 1, so the
    // baseline is b_AED = 7/8 = 0.875 and 0 for the others. No dominant is reported while
    // calibrating. From frame 8 on: e_AED = 0.2·(1 − 0.875) = 0.025 > 0.01 → candidate AED.
    let mut cfg = config_m(1);
    cfg.dominant.calibration_s = 1.0;
    let mut a = assessor(cfg);
    for k in 0..8usize {
        let out = a.update(&looking(k as f64 * 0.125, ASS));
        assert!(out.dominant.calibrating);
        assert_eq!(out.dominant.indicator, None);
    }
    let out = a.update(&looking(1.0, ASS));
    assert!(!out.dominant.calibrating);
    let b = out.dominant.baseline.unwrap();
    close(b[0], 0.875, 1e-12);
    assert_eq!(&b[1..], &[0.0; 4]);
    assert_eq!(out.dominant.candidate, Some(Indicator::Aed));
    close(out.dominant.contributions[0], 0.025, 1e-12);
}

#[test]
fn s8_default_calibration_period_and_fallback_baseline() {
    // Defaults: baseline from the first 60 s. Frames every 0.5 s with no cue at all (invalid):
    // at t = 59.5 the period is still running (59.5 − 0 < 60); at t = 60 it ends. With no
    // valid frame in it, the baseline falls back to the configured default
    // b = (0.50, 0.15, 0.15, 0.20, 0.10).
    let mut a = assessor(AssessConfig::default());
    for k in 0..120usize {
        let out = a.update(&CueFrame::empty(k as f64 * 0.5));
        assert!(out.dominant.calibrating, "t = {}", k as f64 * 0.5);
    }
    let out = a.update(&CueFrame::empty(60.0));
    assert!(!out.dominant.calibrating);
    assert_eq!(out.dominant.baseline, Some([0.50, 0.15, 0.15, 0.20, 0.10]));
}
