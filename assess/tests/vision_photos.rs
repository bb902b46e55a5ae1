//! Landmarks on the five real photos (`data/images/`, Apache-2.0, mediapipe-samples) against
//! the official mediapipe 0.10.21 Python output on the same photos
//! (`tests/fixtures/vision/mediapipe_reference.json`, written by
//! `scripts/models/reference_landmarks.py`), in MediaPipe's static-image mode.
//!
//! Tolerances (issue 6), per landmark, as a fraction of a length of the same person in the
//! reference:
//! - face: 2 % of the outer-eye-corner distance (landmarks 33–263);
//! - hands: 5 % of the wrist–middle-knuckle length (landmarks 0–9);
//! - pose: 8 % of the shoulder width (landmarks 11–12).
#![cfg(feature = "vision")]

use std::path::PathBuf;
use std::sync::Mutex;

use assess::vision::models::model_dir;
use assess::vision::pipeline::{Pipeline, PipelineConfig};
use assess::vision::{Landmark, Landmarks, RgbImage};
use serde_json::Value;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn reference() -> Value {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/vision/mediapipe_reference.json");
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

/// One pipeline for all tests (loading the models takes a moment).
fn pipeline() -> &'static Mutex<Pipeline> {
    static P: std::sync::OnceLock<Mutex<Pipeline>> = std::sync::OnceLock::new();
    P.get_or_init(|| {
        Mutex::new(Pipeline::load(&model_dir(), PipelineConfig::static_images()).unwrap())
    })
}

fn run(file: &str) -> (Landmarks, RgbImage) {
    let image = RgbImage::read(&repo().join("data/images").join(file)).unwrap();
    let lm = pipeline().lock().unwrap().process(&image, None).unwrap();
    (lm, image)
}

fn xy(v: &Value) -> [f64; 2] {
    [v[0].as_f64().unwrap(), v[1].as_f64().unwrap()]
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn lxy(l: &Landmark) -> [f64; 2] {
    [l.x, l.y]
}

/// The largest landmark error [px] and the tolerance [px]; prints the comparison.
fn compare(
    what: &str,
    ours: &[Landmark],
    reference: &[Value],
    scale: (usize, usize),
    frac: f64,
) -> (f64, f64) {
    assert_eq!(ours.len(), reference.len(), "{what}: landmark count");
    let tol = frac * dist(xy(&reference[scale.0]), xy(&reference[scale.1]));
    let (mut worst, mut at) = (0.0f64, 0);
    for (i, (o, r)) in ours.iter().zip(reference).enumerate() {
        let e = dist(lxy(o), xy(r));
        if e > worst {
            worst = e;
            at = i;
        }
    }
    println!("{what}: worst error {worst:.2} px at landmark {at}, tolerance {tol:.2} px");
    (worst, tol)
}

fn image_ref<'a>(reference: &'a Value, file: &str) -> &'a Value {
    reference["images"]
        .as_array()
        .unwrap()
        .iter()
        .find(|i| i["file"] == file)
        .unwrap()
}

const PHOTOS: [&str; 5] = [
    "business-person.png",
    "pose_sitting.jpg",
    "two_children.jpeg",
    "thumbs_up_two.jpg",
    "hand_thumb_up.jpg",
];

#[test]
fn reference_was_made_by_mediapipe_0_10_21_in_static_mode() {
    let r = reference();
    assert_eq!(r["mediapipe_version"], "0.10.21");
    assert_eq!(r["solutions"]["pose"]["options"]["static_image_mode"], true);
    assert_eq!(r["solutions"]["pose"]["options"]["model_complexity"], 1);
    assert_eq!(r["solutions"]["hands"]["options"]["model_complexity"], 1);
    assert_eq!(
        r["solutions"]["faces"]["options"]["refine_landmarks"],
        false
    );
    assert_eq!(r["images"].as_array().unwrap().len(), PHOTOS.len());
}

#[test]
fn pose_agrees_with_mediapipe_within_8_percent_of_shoulder_width() {
    let r = reference();
    let mut compared = 0;
    for file in PHOTOS {
        let want = &image_ref(&r, file)["pose"];
        let (got, _) = run(file);
        match (want.as_array().unwrap().first(), got.pose.as_ref()) {
            (Some(w), Some(g)) => {
                let (worst, tol) = compare(
                    &format!("{file} pose"),
                    &g.points,
                    w["landmarks"].as_array().unwrap(),
                    (11, 12),
                    0.08,
                );
                assert!(
                    worst <= tol,
                    "{file}: pose error {worst:.2} px > {tol:.2} px"
                );
                compared += 1;
            }
            (None, None) => {}
            (w, g) => panic!(
                "{file}: mediapipe found {} pose, we found {}",
                w.is_some() as u8,
                g.is_some() as u8
            ),
        }
    }
    assert!(compared >= 3, "only {compared} poses compared");
}

#[test]
fn face_mesh_agrees_with_mediapipe_within_2_percent_of_eye_corner_distance() {
    let r = reference();
    let mut compared = 0;
    for file in PHOTOS {
        let want = image_ref(&r, file)["faces"].as_array().unwrap().clone();
        let (got, _) = run(file);
        let Some(face) = got.face.as_ref() else {
            assert!(
                want.is_empty(),
                "{file}: mediapipe found a face, we found none"
            );
            continue;
        };
        assert!(!want.is_empty(), "{file}: we found a face, mediapipe none");
        // Single-person pipeline: compare with the reference face at the same place.
        let nose = lxy(&face.points[1]);
        let w = want
            .iter()
            .min_by(|a, b| {
                dist(xy(&a["landmarks"][1]), nose).total_cmp(&dist(xy(&b["landmarks"][1]), nose))
            })
            .unwrap();
        let (worst, tol) = compare(
            &format!("{file} face"),
            &face.points,
            w["landmarks"].as_array().unwrap(),
            (33, 263),
            0.02,
        );
        assert!(
            worst <= tol,
            "{file}: face error {worst:.2} px > {tol:.2} px"
        );
        compared += 1;
    }
    assert!(compared >= 3, "only {compared} faces compared");
}

#[test]
fn hands_agree_with_mediapipe_within_5_percent_of_wrist_knuckle_length() {
    let r = reference();
    let mut compared = 0;
    for file in PHOTOS {
        let want = image_ref(&r, file)["hands"].as_array().unwrap().clone();
        let (got, _) = run(file);
        for hand in &got.hands {
            let wrist = lxy(&hand.points[0]);
            let w = want
                .iter()
                .min_by(|a, b| {
                    dist(xy(&a["landmarks"][0]), wrist)
                        .total_cmp(&dist(xy(&b["landmarks"][0]), wrist))
                })
                .unwrap_or_else(|| panic!("{file}: we found a hand, mediapipe none"));
            let (worst, tol) = compare(
                &format!("{file} hand"),
                &hand.points,
                w["landmarks"].as_array().unwrap(),
                (0, 9),
                0.05,
            );
            assert!(
                worst <= tol,
                "{file}: hand error {worst:.2} px > {tol:.2} px"
            );
            compared += 1;
        }
    }
    assert!(compared >= 4, "only {compared} hands compared");
}
