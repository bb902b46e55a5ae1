//! Issue 13, point 2: tracking on moving video against mediapipe 0.10.21's own video mode.
//!
//! The video: 120 frames of `tests/support/moving.rs`, SIMULATED motion (pan ±60 px, zoom
//! 0.85–1.15, roll ±20°) of the real photo `data/images/pose_sitting.jpg` at 640 × 480, made
//! here in memory; every frame's checksum is checked against the one the reference was made
//! from. The reference: `tests/fixtures/vision/mediapipe_moving.json`, mediapipe's Python
//! solutions in video mode on the same frames (`scripts/models/reference`, which writes the
//! frames with the `moving_video` example and runs `scripts/bench/moving_video.py`).
//!
//! Measured at commit time (the test prints them): pose worst landmark median 10.5 % of the
//! shoulder width, max 50.8 % (the feet and ankles of a seated person, which the zoom and roll
//! push out of the frame); nose, shoulders and hips median 1.6 %, max 7.9 % (one frame, 99,
//! over 5 %); face max 0.4 % of the eye-corner distance; hands from frame 1 median 0.6 %, max
//! 11.6 % of the wrist–middle-knuckle length (4 of 238 hand-frames over 5 %, during the fastest
//! pan and roll; 24.6 % and 5 over when new hands came from the pose's wrists instead of palm
//! detection).
//!
//! The model's own sensitivity, measured the same way: ours against ours on the frames panned
//! 0.3 px (`compare::SelfShift`): pose worst median 11.3 %, max 33.7 %; nose/shoulders/hips
//! max 4.4 %; hands max 18.0 % (18 of 240 over 5 %). So the pose worst median and the hands
//! max are within what a 0.3 px change of the input moves the models by; the one
//! nose/shoulders/hips frame over 5 % is not.
//!
//! The tolerances are asserted where they hold (face ≤ 2 %; every landmark set found
//! wherever mediapipe finds it). Where they do not yet hold (pose worst ≤ 10 % by median,
//! nose/shoulders/hips ≤ 5 % max, hands ≤ 5 % from frame 1), the test bounds the median and
//! the number of frames over the tolerance near what is measured, so a regression fails; the
//! README and issue 13 say these tolerances are not met.
#![cfg(feature = "vision")]

use std::path::PathBuf;

use assess::vision::RgbImage;
use serde_json::Value;

#[allow(dead_code)] // the per-frame selections are vision_scenes.rs'
#[path = "support/compare.rs"]
mod compare;
#[path = "support/moving.rs"]
mod moving;

use compare::{SHIFT_PX, SelfShift, Stats, d, nearest_hand, worst, xy};

#[test]
fn tracking_on_moving_video_against_mediapipe_video_mode() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let reference: Value = serde_json::from_str(
        &std::fs::read_to_string(root.join("tests/fixtures/vision/mediapipe_moving.json")).unwrap(),
    )
    .unwrap();
    let refs = reference["frames"].as_array().unwrap();
    assert_eq!(refs.len(), 120);
    let photo = RgbImage::read(&root.join("../data/images/pose_sitting.jpg")).unwrap();
    let mut p = compare::tracking_pipeline();
    let (mut q, mut shift) = (compare::tracking_pipeline(), SelfShift::default());

    let (mut pose, mut core, mut face, mut hands) = (vec![], vec![], vec![], vec![]);
    for (k, r) in refs.iter().enumerate() {
        let frame = moving::frame(&photo, k);
        assert_eq!(
            format!("{:016x}", moving::fnv1a(&frame.data)),
            r["fnv1a"].as_str().unwrap(),
            "frame {k} differs from the frame the reference was made from"
        );
        let lm = p.process_at(k as f64 / moving::FPS, &frame, None).unwrap();
        let shifted = moving::frame_shifted(&photo, k, SHIFT_PX);
        shift.add(
            k,
            &lm,
            &q.process_at(k as f64 / moving::FPS, &shifted, None)
                .unwrap(),
        );

        let rp = r["pose"]
            .as_array()
            .expect("mediapipe has a pose on every frame");
        let ours = lm
            .pose
            .as_ref()
            .unwrap_or_else(|| panic!("frame {k}: no pose"));
        let shoulders = d(xy(&rp[11]), xy(&rp[12]));
        pose.push(worst(&ours.points, rp, 0..33) / shoulders);
        core.push(worst(&ours.points, rp, [0, 11, 12, 23, 24].into_iter()) / shoulders);

        let rf = r["face"]
            .as_array()
            .expect("mediapipe has a face on every frame");
        let ours = lm
            .face
            .as_ref()
            .unwrap_or_else(|| panic!("frame {k}: no face"));
        face.push(worst(&ours.points, rf, 0..468) / d(xy(&rf[33]), xy(&rf[263])));

        let rh = r["hands"].as_array().unwrap();
        assert_eq!(lm.hands.len(), rh.len(), "frame {k}: hands found");
        for h in rh {
            let h = h.as_array().unwrap();
            let wrist = xy(&h[0]);
            let ours = nearest_hand(&lm.hands, wrist).unwrap();
            if k >= 1 {
                hands.push(worst(&ours.points, h, 0..21) / d(wrist, xy(&h[9])));
            }
        }
    }
    let (pose, core, face, hands) = (
        Stats::of(&pose),
        Stats::of(&core),
        Stats::of(&face),
        Stats::of(&hands),
    );
    let n_hands = hands.n;
    let (shift_pose, shift_core, shift_hands) = shift.stats();
    println!(
        "ours against ours on the frames panned {SHIFT_PX} px: pose worst median {:.1} %, max \
         {:.1} %; nose/shoulders/hips median {:.1} %, max {:.1} %; hands median {:.1} %, max \
         {:.1} % ({} of {} over 5 %)",
        100.0 * shift_pose.median,
        100.0 * shift_pose.max,
        100.0 * shift_core.median,
        100.0 * shift_core.max,
        100.0 * shift_hands.median,
        100.0 * shift_hands.max,
        shift_hands.over_5pct,
        shift_hands.n,
    );
    println!(
        "pose worst: median {:.1} %, max {:.1} %; nose/shoulders/hips: median {:.1} %, max {:.1} % \
         ({} frames over 5 %); face: max {:.2} %; hands from frame 1: median {:.1} %, max {:.1} % \
         ({} of {n_hands} over 5 %)",
        100.0 * pose.median,
        100.0 * pose.max,
        100.0 * core.median,
        100.0 * core.max,
        core.over_5pct,
        100.0 * face.max,
        100.0 * hands.median,
        100.0 * hands.max,
        hands.over_5pct,
    );
    // The tolerance, met: face ≤ 2 % of the eye-corner distance on every frame.
    assert!(face.max <= 0.02, "face max {:.3}", face.max);
    // Not met (issue: pose worst ≤ 10 % by median), prevented by the model's own sensitivity:
    // a 0.3 px pan alone moves it by a median over 10 % (11.3 % measured), more than ours
    // differs from mediapipe's (10.5 %).
    assert!(shift_pose.median > 0.10, "shift {:.3}", shift_pose.median);
    assert!(
        pose.median <= shift_pose.median,
        "pose worst median {:.3}",
        pose.median
    );
    // Bounded near the measured 10.5 % as before.
    assert!(pose.median <= 0.12, "pose worst median {:.3}", pose.median);
    // Not yet met (issue: nose, shoulders, hips ≤ 5 % max): measured median 1.6 %, one frame
    // over 5 %.
    assert!(core.median <= 0.03, "core median {:.3}", core.median);
    assert!(
        core.over_5pct <= 3,
        "core frames over 5 %: {}",
        core.over_5pct
    );
    assert!(core.max <= 0.12, "core max {:.3}", core.max);
    // Not yet met (issue: hands ≤ 5 % from frame 1): measured median 0.6 %, max 11.6 %, 4 of
    // 238 over 5 %.
    assert_eq!(n_hands, 2 * 119);
    assert!(hands.median <= 0.02, "hands median {:.3}", hands.median);
    assert!(hands.over_5pct <= 8, "hands over 5 %: {}", hands.over_5pct);
    assert!(hands.max <= 0.20, "hands max {:.3}", hands.max);
    // Within the model's own sensitivity: a 0.3 px pan alone moves a hand by up to 18.0 %.
    assert!(shift_hands.max > 0.05, "shift {:.3}", shift_hands.max);
    assert!(hands.max <= shift_hands.max, "hands max {:.3}", hands.max);
}
