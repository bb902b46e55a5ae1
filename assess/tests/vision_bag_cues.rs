//! The whole camera chain on a synthetic `.bag` of a known scene (`data/bag/`, made by
//! `scripts/fixtures/make_synthetic_bag.py`; simulated): a photo of a person on a plane 1 m
//! ahead, turned 25° about the camera's vertical axis, recorded through librealsense's software
//! device. The bag is played with `RealSenseSource`, landmarks found, lifted with the depth
//! and turned into cues. Known answers, from the scene file (`synthetic_plane.json`):
//! - every lifted landmark lies on the plane;
//! - the head and chest face along the plane's normal (a flat photo of a person facing the
//!   photographer faces where the plane faces).
#![cfg(all(feature = "vision", feature = "realsense"))]

use std::path::PathBuf;

use assess::vision::cues::{CueConfig, CueExtractor, CueQuality, load_canonical_face};
use assess::vision::models::model_dir;
use assess::vision::pipeline::{Pipeline, PipelineConfig};
use assess::vision::source::realsense::RealSenseSource;
use assess::vision::{Extrinsics, FrameSource, lift};
use nalgebra::{Point3, Vector3};
use serde_json::Value;

fn bag_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/bag")
}

fn v3(v: &Value) -> Vector3<f64> {
    Vector3::new(
        v[0].as_f64().unwrap(),
        v[1].as_f64().unwrap(),
        v[2].as_f64().unwrap(),
    )
}

#[test]
fn synthetic_bag_gives_points_on_the_plane_and_the_planes_facing() {
    let scene: Value = serde_json::from_str(
        &std::fs::read_to_string(bag_dir().join("synthetic_plane.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(scene["simulated"], true);
    let centre = Point3::from(v3(&scene["plane"]["centre_m"]));
    let normal = v3(&scene["plane"]["normal"]).normalize();
    let on_plane = |p: &Point3<f64>| (p - centre).dot(&normal).abs();

    let mut source = RealSenseSource::open_bag(bag_dir().join("synthetic_plane.bag")).unwrap();
    let mut pipeline = Pipeline::load(&model_dir(), PipelineConfig::default()).unwrap();
    let canonical = load_canonical_face(&model_dir().join("canonical_face_model.csv")).unwrap();
    let mut cues =
        CueExtractor::new(CueConfig::default(), Extrinsics::identity(), canonical).unwrap();
    let mut frames = 0;
    let mut scratch = Vec::new();
    while let Some(frame) = source.next_frame().unwrap() {
        frames += 1;
        let depth = frame.depth.as_ref().expect("the bag has depth");
        let lm = pipeline
            .process_at(frame.t, &frame.color, Some(depth))
            .unwrap();
        let face = lm.face.as_ref().expect("a face");
        let pose = lm.pose.as_ref().expect("a pose");

        // Lifted face and upper-body landmarks lie on the plane (depth quantised to 1 mm,
        // 3 × 3 median patches, bilinear texture).
        let mut worst = 0.0f64;
        let mut lifted = 0;
        for p in face.points.iter().chain(&pose.points[..13]) {
            if let Some(q) = lift(
                depth,
                &frame.intrinsics,
                p.x,
                p.y,
                1,
                (0.2, 4.0),
                &mut scratch,
            ) {
                worst = worst.max(on_plane(&q));
                lifted += 1;
            }
        }
        assert!(
            lifted > 400,
            "frame {}: only {lifted} landmarks lifted",
            frame.index
        );
        assert!(
            worst < 0.01,
            "frame {}: a point is {worst:.4} m off the plane",
            frame.index
        );

        let c = cues.extract(frame.t, &lm, Some(depth), &frame.intrinsics);
        assert_eq!(c.quality, CueQuality::Depth3d);
        let head = c.frame.head.expect("a head cue");
        assert!(
            on_plane(&Point3::from(head.position)) < 0.15,
            "head centre behind the face"
        );
        let head_angle = head.facing.normalize().angle(&normal).to_degrees();
        let body = c.frame.body.expect("a body cue");
        assert!(on_plane(&Point3::from(body.position)) < 0.01);
        let body_angle = body.facing.normalize().angle(&normal).to_degrees();
        println!(
            "frame {}: head {head_angle:.1}° and chest {body_angle:.1}° from the plane normal; \
             worst landmark {:.1} mm off the plane",
            frame.index,
            worst * 1000.0
        );
        // A flat photo is not a 3-D head: the canonical face's relief fits it only roughly.
        assert!(
            head_angle < 15.0,
            "head facing {head_angle:.1}° from the plane normal"
        );
        assert!(
            body_angle < 15.0,
            "chest facing {body_angle:.1}° from the plane normal"
        );
    }
    assert_eq!(frames, scene["frames"].as_u64().unwrap() as usize);
}
