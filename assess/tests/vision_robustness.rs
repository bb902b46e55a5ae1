//! The landmark pipeline and cue extraction on bad input: empty, black, tiny, malformed and
//! truncated frames give empty results or clear errors, never a panic. And operator selection
//! on `two_children.jpeg` (two people in view).
#![cfg(feature = "vision")]

use std::path::PathBuf;

use assess::vision::cues::{CueConfig, CueExtractor, load_canonical_face};
use assess::vision::models::model_dir;
use assess::vision::pipeline::{Mode, Pipeline, PipelineConfig, choose_operator};
use assess::vision::{DepthImage, Extrinsics, Intrinsics, RgbImage};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn tracking() -> Pipeline {
    Pipeline::load(
        &model_dir(),
        PipelineConfig {
            mode: Mode::Tracking,
            ..PipelineConfig::default()
        },
    )
    .unwrap()
}

#[test]
fn bad_frames_give_empty_landmarks_not_panics() {
    let mut p = tracking();
    let frames = [
        RgbImage::black(0, 0),
        RgbImage::black(640, 480),
        RgbImage::black(1, 1),
        RgbImage::black(3, 2000),
        RgbImage {
            width: 640,
            height: 480,
            data: vec![255; 100], // malformed: too short
        },
        RgbImage {
            width: 64,
            height: 48,
            data: (0..64 * 48 * 3).map(|i| (i * 7919 % 251) as u8).collect(), // noise
        },
    ];
    for (i, f) in frames.iter().enumerate() {
        let lm = p.process(f, None).unwrap();
        assert!(
            lm.pose.is_none() && lm.face.is_none() && lm.hands.is_empty(),
            "frame {i}"
        );
    }
    // A real frame after bad ones still works (tracking state was reset, not corrupted).
    let img = RgbImage::read(&repo().join("data/images/pose_sitting.jpg")).unwrap();
    let lm = p.process(&img, None).unwrap();
    assert!(lm.pose.is_some() && lm.face.is_some());
    // A depth image of the wrong size is ignored for operator selection, not an error.
    let depth = DepthImage {
        width: 2,
        height: 2,
        data: vec![1000; 4],
        scale_m: 0.001,
    };
    assert!(p.process(&img, Some(&depth)).unwrap().pose.is_some());
}

#[test]
fn truncated_and_empty_image_files_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read(repo().join("data/images/hand_thumb_up.jpg")).unwrap();
    let cases = [
        ("empty.jpg", Vec::new()),
        ("text.png", b"not an image".to_vec()),
        ("truncated.jpg", good[..200].to_vec()),
    ];
    for (name, bytes) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let err = RgbImage::read(&path).unwrap_err().to_string();
        assert!(err.contains(name), "{err}");
    }
    let missing = RgbImage::read(&dir.path().join("missing.png")).unwrap_err();
    assert!(missing.to_string().contains("missing.png"));
}

#[test]
fn cues_from_empty_landmarks_are_empty() {
    let canonical = load_canonical_face(&model_dir().join("canonical_face_model.csv")).unwrap();
    let mut x = CueExtractor::new(CueConfig::default(), Extrinsics::identity(), canonical).unwrap();
    let intr = Intrinsics::from_hfov(640, 480, 69.0);
    let c = x.extract(0.0, &Default::default(), None, &intr);
    assert!(c.frame.head.is_none() && c.frame.body.is_none());
    assert!(c.frame.hands.iter().all(Option::is_none));
}

/// `two_children.jpeg`: a boy in front (left, larger face) and a girl behind him (right),
/// whose hand rests on his shoulder.
#[test]
fn the_operator_is_the_nearest_person_on_two_children() {
    let img = RgbImage::read(&repo().join("data/images/two_children.jpeg")).unwrap();
    let mut p = Pipeline::load(&model_dir(), PipelineConfig::static_images()).unwrap();
    let half = img.width as f64 / 2.0;

    // Without depth: the largest person, the boy on the left: pose, face and the nose agree.
    let lm = p.process(&img, None).unwrap();
    let face = lm.face.as_ref().expect("a face");
    assert!(
        face.points[1].x < half,
        "face nose at x = {}",
        face.points[1].x
    );
    let pose = lm.pose.as_ref().expect("a pose");
    assert!(
        pose.points[0].x < half,
        "pose nose at x = {}",
        pose.points[0].x
    );
    // The girl's hand on his shoulder is not the operator's hand: mediapipe's Hands (not
    // person-aware) reports it, our operator pipeline drops it.
    let reference: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("tests/fixtures/vision/mediapipe_reference.json"),
        )
        .unwrap(),
    )
    .unwrap();
    let theirs = reference["images"]
        .as_array()
        .unwrap()
        .iter()
        .find(|i| i["file"] == "two_children.jpeg")
        .unwrap()["hands"]
        .as_array()
        .unwrap()
        .len();
    assert_eq!(theirs, 1, "mediapipe reports the girl's hand");
    assert!(lm.hands.is_empty(), "kept {} hand(s)", lm.hands.len());

    // With depth, the nearer face is chosen, whichever side it is on.
    let faces = p.detect_faces(&img).unwrap();
    assert_eq!(faces.len(), 2, "two faces detected");
    let depth_with_near_side = |left_near: bool| {
        let mut data = vec![0u16; (img.width * img.height) as usize];
        for (i, d) in data.iter_mut().enumerate() {
            let left = ((i as u32 % img.width) as f64) < half;
            *d = if left == left_near { 800 } else { 1500 };
        }
        DepthImage {
            width: img.width,
            height: img.height,
            data,
            scale_m: 0.001,
        }
    };
    let size = (img.width, img.height);
    for left_near in [true, false] {
        let depth = depth_with_near_side(left_near);
        let chosen = choose_operator(&faces, size, Some(&depth)).unwrap();
        let cx = f64::from(chosen.xmin + chosen.width / 2.0) * f64::from(img.width);
        assert_eq!(cx < half, left_near, "chose the face at x = {cx}");
    }
    // Without depth: the larger face box (the boy's).
    let chosen = choose_operator(&faces, size, None).unwrap();
    assert!(f64::from(chosen.xmin + chosen.width / 2.0) * f64::from(img.width) < half);
}
