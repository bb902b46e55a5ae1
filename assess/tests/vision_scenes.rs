//! Issue 13, point 2: tracking on three more SIMULATED moving-video scenes against mediapipe
//! 0.10.21's own video mode: a person entering and leaving, a hand leaving the frame, low light.
//!
//! The videos: `tests/support/scenes.rs`, SIMULATED motion of the real photos
//! `data/images/pose_sitting.jpg` and `data/images/hand_thumb_up.jpg` at 640 × 480, made here in
//! memory; every frame's checksum is checked against the one the reference was made from. The
//! references: `tests/fixtures/vision/mediapipe_scene_*.json`, mediapipe's Python solutions in
//! video mode on the same frames (`scripts/models/reference`, which writes the frames with
//! `moving_video make --scene …` and runs `scripts/bench/moving_video.py --fixture`).
//!
//! Per scene, on the frames where both find one: pose worst landmark and nose/shoulders/hips
//! over the shoulder width (11–12), face worst over the eye-corner distance (33–263), hands
//! worst over the wrist–middle-knuckle length (0–9), hands counted from the second frame of a
//! hand's track (a mediapipe hand near it on the frame before). And presence: the frames where
//! one finds a pose (face, as many hands) and the other does not.
//!
//! The bounds are in [`BOUNDS`]; each says whether it is the tolerance or, where that
//! does not hold, the measured value (the measurement quoted).
#![cfg(feature = "vision")]

use std::path::PathBuf;

use assess::vision::RgbImage;
use assess::vision::models::model_dir;
use assess::vision::pipeline::{Pipeline, PipelineConfig};
use serde_json::Value;

#[path = "support/compare.rs"]
mod compare;
#[allow(dead_code)] // `frame` is the pan/zoom/roll video of vision_moving.rs
#[path = "support/moving.rs"]
mod moving;
#[allow(dead_code)] // the descriptions are for the example's frames.json
#[path = "support/scenes.rs"]
mod scenes;

use compare::{SHIFT_PX, SelfShift, Stats, d, nearest_hand, px, worst, xy};
use scenes::Scene;

/// What one scene measured.
struct Measured {
    pose: Stats,
    core: Stats,
    face: Stats,
    hands: Stats,
    /// Frames where exactly one of ours and mediapipe's has a pose.
    pose_presence: Vec<usize>,
    /// Frames where exactly one has a face.
    face_presence: Vec<usize>,
    /// Frames where the numbers of hands differ: (frame, ours, mediapipe's).
    hands_presence: Vec<(usize, usize, usize)>,
    /// Our hands with no mediapipe hand within the hand's wrist–middle-knuckle length:
    /// (frame, wrist [px], length [px]).
    unmatched_hands: Vec<(usize, [f64; 2], f64)>,
    /// Our own pose worst, nose/shoulders/hips and hands against ours on the frames panned
    /// by `compare::SHIFT_PX`.
    shift: (Stats, Stats, Stats),
    /// The same per frame, to select frames.
    shift_at: SelfShift,
    /// Per frame (frame, value): pose worst, nose/shoulders/hips and hands (one entry per
    /// compared hand), the series `pose`, `core` and `hands` are the statistics of.
    pose_at: Vec<(usize, f64)>,
    core_at: Vec<(usize, f64)>,
    hands_at: Vec<(usize, f64)>,
}

fn measure(scene: Scene) -> Measured {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let path = root.join("tests/fixtures/vision").join(scene.fixture());
    let reference: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert!(
        reference["simulated"]
            .as_str()
            .unwrap()
            .starts_with("SIMULATED")
    );
    let refs = reference["frames"].as_array().unwrap();
    assert_eq!(refs.len(), scene.frames());
    let photo = RgbImage::read(&root.join("../data/images").join(scene.photo())).unwrap();
    let mut p = compare::tracking_pipeline();
    let (mut q, mut shift) = (compare::tracking_pipeline(), SelfShift::default());

    let (mut pose, mut core, mut face, mut hands) = (vec![], vec![], vec![], vec![]);
    let (mut pose_presence, mut face_presence, mut hands_presence) = (vec![], vec![], vec![]);
    let mut unmatched_hands = vec![];
    let mut previous_hands: &[Value] = &[];
    for (k, r) in refs.iter().enumerate() {
        let frame = scene.frame(&photo, k);
        assert_eq!(
            format!("{:016x}", moving::fnv1a(&frame.data)),
            r["fnv1a"].as_str().unwrap(),
            "{}: frame {k} differs from the frame the reference was made from",
            scene.name()
        );
        let lm = p.process_at(k as f64 / moving::FPS, &frame, None).unwrap();
        let shifted = scene.frame_shifted(&photo, k, SHIFT_PX);
        shift.add(
            k,
            &lm,
            &q.process_at(k as f64 / moving::FPS, &shifted, None)
                .unwrap(),
        );

        match (r["pose"].as_array(), lm.pose.as_ref()) {
            (Some(rp), Some(ours)) => {
                let shoulders = d(xy(&rp[11]), xy(&rp[12]));
                pose.push((k, worst(&ours.points, rp, 0..33) / shoulders));
                core.push((
                    k,
                    worst(&ours.points, rp, [0, 11, 12, 23, 24].into_iter()) / shoulders,
                ));
            }
            (None, None) => {}
            _ => pose_presence.push(k),
        }
        match (r["face"].as_array(), lm.face.as_ref()) {
            (Some(rf), Some(ours)) => {
                face.push(worst(&ours.points, rf, 0..468) / d(xy(&rf[33]), xy(&rf[263])));
            }
            (None, None) => {}
            _ => face_presence.push(k),
        }

        let rh = r["hands"].as_array().unwrap();
        if lm.hands.len() != rh.len() {
            hands_presence.push((k, lm.hands.len(), rh.len()));
        }
        for h in &lm.hands {
            let wrist = px(&h.points[0]);
            let length = d(wrist, px(&h.points[9]));
            if !rh.iter().any(|q| d(xy(&q[0]), wrist) < length) {
                unmatched_hands.push((k, wrist, length));
            }
        }
        for h in rh {
            let h = h.as_array().unwrap();
            let (wrist, length) = (xy(&h[0]), d(xy(&h[0]), xy(&h[9])));
            // From the second frame of the hand's track: mediapipe had a hand near this one on
            // the frame before (the hand moves at most about 23 px a frame here).
            let tracked = previous_hands
                .iter()
                .any(|q| d(xy(&q[0]), wrist) < 2.0 * length);
            if let Some(ours) = nearest_hand(&lm.hands, wrist).filter(|_| tracked) {
                hands.push((k, worst(&ours.points, h, 0..21) / length));
            }
        }
        previous_hands = rh;
    }
    let all = |_| true;
    Measured {
        pose: Stats::at(&pose, all),
        core: Stats::at(&core, all),
        face: Stats::of(&face),
        hands: Stats::at(&hands, all),
        pose_presence,
        face_presence,
        hands_presence,
        unmatched_hands,
        shift: shift.stats(),
        shift_at: shift,
        pose_at: pose,
        core_at: core,
        hands_at: hands,
    }
}

fn report(scene: Scene, m: &Measured) {
    let pct = |s: &Stats| {
        format!(
            "median {:.1} %, max {:.1} % ({} of {} over 5 %)",
            100.0 * s.median,
            100.0 * s.max,
            s.over_5pct,
            s.n
        )
    };
    println!(
        "[{}] pose worst: {}; nose/shoulders/hips: {}; face: max {:.2} % of {}; hands from the \
         track's second frame: {}; presence disagreements: pose {:?}, face {:?}, hands {:?}",
        scene.name(),
        pct(&m.pose),
        pct(&m.core),
        100.0 * m.face.max,
        m.face.n,
        pct(&m.hands),
        m.pose_presence,
        m.face_presence,
        m.hands_presence,
    );
    println!(
        "[{}] ours against ours on the frames panned {SHIFT_PX} px: pose worst: {}; \
         nose/shoulders/hips: {}; hands: {}",
        scene.name(),
        pct(&m.shift.0),
        pct(&m.shift.1),
        pct(&m.shift.2),
    );
}

/// The tolerances: pose worst landmark ≤ 10 % of the shoulder width by median;
/// nose, shoulders and hips ≤ 5 % max; hands ≤ 5 % max; face ≤ 2 % max.
const HANDS_MAX: f64 = 0.05;
const FACE_MAX: f64 = 0.02;

/// `value` ≤ `bound`, named in the failure.
fn at_most(what: &str, value: f64, bound: f64) {
    assert!(value <= bound, "{what}: {value:.4} > {bound}");
}

/// `n` ≤ `bound`, naming `what` and showing `items` in the failure.
fn at_most_n<T: std::fmt::Debug>(what: &str, items: &[T], bound: usize) {
    assert!(
        items.len() <= bound,
        "{what}: {} > {bound}: {items:?}",
        items.len()
    );
}

/// A person entering and leaving: empty frames (0–7, 92–99), the person sliding in (8–35),
/// sitting still in full view (36–63) and sliding out (64–91).
///
/// Where the person is in full view, the model is stable (ours against ours on the frames
/// panned 0.3 px moves nose/shoulders/hips by at most 2.4 %), and the test holds the issue's
/// tolerances there. Measured on the CI machine (AMD EPYC, AVX-512; the test prints them):
/// nose/shoulders/hips max 4.9 %, hands max 3.9 % on 27 hand-frames, pose worst median 11.8 %
/// (issue: 10 %, not met; the 0.3 px pan alone moves it by a median 10.5 %).
///
/// Where the person is partly in the frame, the model is not stable: the 0.3 px pan alone
/// moves nose/shoulders/hips by up to 70.1 % while sliding in. There no per-frame tolerance is
/// meaningful, and the figures differ between machines: the whole scene's nose/shoulders/hips
/// max was 589.5 % when this test was written and is 136.3 % on the CI machine, 8 and 9
/// frames over 5 %. Those frames are measured and printed, and held only by the whole
/// scene's medians, with room for that difference.
/// Sliding out is not explained so (the pan moves nose/shoulders/hips by at most 3.9 % there;
/// ours differs from mediapipe's by up to 33.2 % on 2 frames): issue 13 keeps it open.
///
/// Presence: every disagreement is on a frame where the person slides in or out, where
/// mediapipe's own pose, face and hands flicker on and off; both agree on every still and
/// every empty frame.
#[test]
fn person_entering_and_leaving_against_mediapipe_video_mode() {
    let m = measure(Scene::EnterLeave);
    report(Scene::EnterLeave, &m);
    assert!(m.pose.n >= 60 && m.face.n >= 39 && m.hands.n >= 37);
    let still = |k: usize| (36..64).contains(&k);
    let sliding_in = |k: usize| (8..36).contains(&k);
    let moving = |k: usize| sliding_in(k) || (64..92).contains(&k);
    let (pose, core, hands) = (
        Stats::at(&m.pose_at, still),
        Stats::at(&m.core_at, still),
        Stats::at(&m.hands_at, still),
    );
    let (shift_pose, shift_core, _) = m.shift_at.stats_where(still);
    println!(
        "[enter-leave] still frames 36–63: pose worst median {:.1} % ({} frames), \
         nose/shoulders/hips max {:.1} %, hands max {:.1} % ({} hand-frames); the 0.3 px pan: \
         pose worst median {:.1} %, nose/shoulders/hips max {:.1} %",
        100.0 * pose.median,
        pose.n,
        100.0 * core.max,
        100.0 * hands.max,
        hands.n,
        100.0 * shift_pose.median,
        100.0 * shift_core.max,
    );
    assert_eq!(pose.n, 28, "a pose on every still frame");
    assert!(hands.n >= 27, "{} still hand-frames", hands.n);
    // The tolerances, met: face ≤ 2 % (every frame with a face), and on the still
    // frames nose/shoulders/hips ≤ 5 % and hands ≤ 5 %.
    at_most("face max", m.face.max, FACE_MAX);
    at_most("still core max", core.max, 0.05);
    at_most("still hands max", hands.max, HANDS_MAX);
    // Not met (issue: pose worst ≤ 10 % by median): bounded at the measured 11.8 %; the
    // model's own sensitivity there is 10.5 %.
    at_most("still pose median", pose.median, 0.12);
    // The model's own sensitivity while the person slides in exceeds the tolerance many times
    // over (measured 70.1 %), so no per-frame tolerance is asserted on those frames.
    let (_, shift_in, _) = m.shift_at.stats_where(sliding_in);
    assert!(shift_in.max > 0.20, "shift sliding in {:.3}", shift_in.max);
    // The whole scene, medians only (measured 13.4–15.3 % and 2.4–2.7 %, hands 0.5 %).
    at_most("pose median", m.pose.median, 0.17);
    at_most("core median", m.core.median, 0.035);
    at_most("hands median", m.hands.median, 0.01);
    for (what, frames) in [
        ("pose", m.pose_presence.clone()),
        ("face", m.face_presence.clone()),
        (
            "hands",
            m.hands_presence.iter().map(|h| h.0).collect::<Vec<_>>(),
        ),
    ] {
        assert!(
            frames.iter().all(|&k| moving(k)),
            "{what} presence off the moving frames: {frames:?}"
        );
    }
}

/// A hand leaving the frame. The photo shows a hand and no person, yet mediapipe's video-mode
/// Pose (as ours) reports a "pose" on it on 46 of 90 frames: the pose errors (worst median
/// 180.9 %) and the frames where only one of the two has that pose compare two
/// hallucinations and are not asserted. That pose sees neither of its
/// wrists, so it does not rule the hand out (`pipeline::belongs_to`). Measured at commit
/// time: hands (where both have one, from the track's second frame) median 0.1 %, max 4.1 %
/// on 46 hand-frames, the tolerance; the number of hands differs on 2 frames, 67 and
/// 68, where the hand comes back and mediapipe finds it 2 frames before ours. Ours runs palm
/// detection every `palm_every` = 3 frames while a hand is missing (mediapipe on every frame):
/// with `palm_every` = 1 ours finds it on frame 67 too, which the test checks.
#[test]
fn hand_leaving_the_frame_against_mediapipe_video_mode() {
    let m = measure(Scene::HandExit);
    report(Scene::HandExit, &m);
    assert!(m.hands.n >= 46, "{} hand-frames compared", m.hands.n);
    at_most("hands max", m.hands.max, HANDS_MAX);
    // Both find no hand while the hand is out of the frame (26–66 in mediapipe's fixture).
    for k in 26..67 {
        assert!(m.hands_presence.iter().all(|h| h.0 != k), "frame {k}");
    }
    // The pose's presence is not asserted: it is a hallucination on a photo of a hand, and it
    // flickers differently between machines (frames 28, 70 and 72 on the CI machine, two of
    // them when this test was written).
    at_most_n("face presence", &m.face_presence, 0);
    at_most_n("hands presence", &m.hands_presence, 2);
    assert!(
        m.hands_presence.iter().all(|h| (67..69).contains(&h.0)),
        "{:?}",
        m.hands_presence
    );

    // With palm detection on every frame, ours finds the returning hand on frame 67 as
    // mediapipe does.
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let photo = RgbImage::read(&root.join("../data/images").join(Scene::HandExit.photo())).unwrap();
    let mut p = Pipeline::load(
        &model_dir(),
        PipelineConfig {
            palm_every: 1,
            ..PipelineConfig::default()
        },
    )
    .unwrap();
    let found: Vec<usize> = (60..70)
        .map(|k| {
            let frame = Scene::HandExit.frame(&photo, k);
            let lm = p.process_at(k as f64 / moving::FPS, &frame, None).unwrap();
            lm.hands.len()
        })
        .collect();
    let reference: Value = serde_json::from_str(
        &std::fs::read_to_string(
            root.join("tests/fixtures/vision")
                .join(Scene::HandExit.fixture()),
        )
        .unwrap(),
    )
    .unwrap();
    let theirs: Vec<usize> = reference["frames"].as_array().unwrap()[60..70]
        .iter()
        .map(|r| r["hands"].as_array().unwrap().len())
        .collect();
    assert_eq!(theirs, [0, 0, 0, 0, 0, 0, 0, 1, 1, 1]);
    assert_eq!(found, theirs, "hands on frames 60–69, ours and mediapipe's");
}

/// Low light. Measured at commit time (the test prints them): pose worst median 21.5 %, max
/// 81.8 %; nose/shoulders/hips median 1.8 %, max 6.7 % (3 of 90 frames over 5 %); face max
/// 1.09 %; hands median 0.8 %, max 93.8 % (14 of 100 hand-frames over 5 %).
///
/// Where the model's own sensitivity prevents a tolerance, measured: ours against ours on the
/// same dark frames panned 0.3 px moves the worst pose landmark by a median 33.6 % (the seated
/// person's right knee, ankle, heel and foot in the dark) and nose/shoulders/hips by up to
/// 7.5 %, more than ours differs from mediapipe's (21.5 %, 6.7 %). The hands (max 93.8 %
/// against 59.8 % for the shift) are not explained so.
///
/// Presence: pose and face agree on every frame; the number of hands differs on 63 frames,
/// mostly ours 2 and mediapipe's 1. Mediapipe's palm detector misses the second hand in the
/// dark; ours finds it from the pose's wrist. It is a real hand: mediapipe finds it on the same
/// frames lit (`mediapipe_moving.json`, the pan/zoom/roll of `vision_moving.rs` before the
/// darkening), which the test checks for each of our hands mediapipe does not have.
#[test]
fn low_light_against_mediapipe_video_mode() {
    let m = measure(Scene::LowLight);
    report(Scene::LowLight, &m);
    let (shift_pose, shift_core, _) = &m.shift;
    assert!(m.pose.n == 90 && m.face.n == 90 && m.hands.n >= 100);
    // The tolerances, met: face ≤ 2 %; pose and face found wherever mediapipe finds
    // them and nowhere else.
    at_most("face max", m.face.max, FACE_MAX);
    at_most_n("pose presence", &m.pose_presence, 0);
    at_most_n("face presence", &m.face_presence, 0);
    // Not met (issue: pose worst ≤ 10 % by median), prevented by the model's own sensitivity:
    // a 0.3 px pan alone moves it by more than 10 %, and by more than ours differs from
    // mediapipe's. Bounded at the measured 21.5 %.
    assert!(shift_pose.median > 0.10, "shift {:.3}", shift_pose.median);
    at_most("pose median", m.pose.median, shift_pose.median);
    at_most("pose median", m.pose.median, 0.216);
    // Not met (issue: nose, shoulders, hips ≤ 5 % max), within the model's own sensitivity
    // (a 0.3 px pan alone: 7.5 %). Bounded at the measured 6.7 %, 3 over.
    assert!(shift_core.max > 0.05, "shift {:.3}", shift_core.max);
    at_most("core max", m.core.max, shift_core.max);
    at_most("core max", m.core.max, 0.068);
    assert!(m.core.over_5pct <= 3, "core over 5 %: {}", m.core.over_5pct);
    // Not met (issue: hands ≤ 5 %): bounded at the measured 93.8 %, 14 of 100 over 5 %.
    at_most("hands max", m.hands.max, 0.939);
    at_most("hands median", m.hands.median, 0.01);
    assert!(
        m.hands.over_5pct <= 14,
        "hands over 5 %: {}",
        m.hands.over_5pct
    );
    at_most_n("hands presence", &m.hands_presence, 63);

    // Every hand of ours that mediapipe does not find in the dark, mediapipe finds lit.
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let lit: Value = serde_json::from_str(
        &std::fs::read_to_string(root.join("tests/fixtures/vision/mediapipe_moving.json")).unwrap(),
    )
    .unwrap();
    let lit = lit["frames"].as_array().unwrap();
    assert!(m.unmatched_hands.len() >= 60, "{}", m.unmatched_hands.len());
    for (k, wrist, _) in &m.unmatched_hands {
        let hands = lit[*k]["hands"].as_array().unwrap();
        assert!(
            hands
                .iter()
                .any(|h| d(xy(&h[0]), *wrist) < d(xy(&h[0]), xy(&h[9]))),
            "frame {k}: our hand at {wrist:?} is not one mediapipe finds lit"
        );
    }
}
