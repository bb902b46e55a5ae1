//! `robot_io::geometry`: worked examples computed by hand (in the comments), the UR5e capsules
//! against the DH geometry and against MuJoCo Menagerie's UR5e collision model, and property
//! tests (proptest; cases from `PROPTEST_CASES`, 256 by default).

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{Isometry3, Point3 as NaPoint3, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;
use robot_io::geometry::{
    ARM_CAPSULES, ArmLink, ArmModel, BodyModel, BodyPart, Capsule, HumanBody, Point3, RawArmModel,
    RawBodyModel, Torso, capsule_distance, centre_line_distance, closest_approaches,
    point_segment_distance, segment_segment_distance,
};
use robot_io::kinematics::{FRAME_COUNT, UR5E_DH_D, link_frames};

const TOL: f64 = 1e-12;

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

fn lerp(a: &Point3, b: &Point3, s: f64) -> Point3 {
    [
        a[0] + (b[0] - a[0]) * s,
        a[1] + (b[1] - a[1]) * s,
        a[2] + (b[2] - a[2]) * s,
    ]
}

fn dist(a: &Point3, b: &Point3) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn capsules_at(arm: &ArmModel, q: &[f64; 6]) -> [Capsule; ARM_CAPSULES] {
    let mut out = [Capsule::point([0.0; 3], 0.0); ARM_CAPSULES];
    arm.capsules(q, &mut out);
    out
}

fn assert_point(p: &Point3, expected: &Point3, what: &str) {
    assert!(dist(p, expected) < 1e-12, "{what}: {p:?} != {expected:?}");
}

// --- worked examples ---

#[test]
fn point_segment_worked_examples() {
    let a = [0.0, 0.0, 0.0];
    let b = [2.0, 0.0, 0.0];
    // Projection inside the segment: (1, 1, 0) is 1 above its foot (1, 0, 0).
    assert!(close(
        point_segment_distance(&[1.0, 1.0, 0.0], &a, &b),
        1.0,
        TOL
    ));
    // Beyond a: (−3, 4, 0) is nearest to a, at |(−3, 4)| = 5.
    assert!(close(
        point_segment_distance(&[-3.0, 4.0, 0.0], &a, &b),
        5.0,
        TOL
    ));
    // Beyond b: (5, 0, 4) is nearest to b = (2, 0, 0), at |(3, 0, 4)| = 5.
    assert!(close(
        point_segment_distance(&[5.0, 0.0, 4.0], &a, &b),
        5.0,
        TOL
    ));
    // On the segment: 0.
    assert_eq!(point_segment_distance(&[0.5, 0.0, 0.0], &a, &b), 0.0);
    // A diagonal segment (0,0,0)→(1,1,1) and p = (1,0,0): the foot is t = 1/3, at
    // (1/3, 1/3, 1/3); the offset (2/3, −1/3, −1/3) has length √(6/9) = 0.81650.
    let d = point_segment_distance(&[1.0, 0.0, 0.0], &a, &[1.0, 1.0, 1.0]);
    assert!(close(d, (6.0f64 / 9.0).sqrt(), TOL), "{d}");
    // A degenerate segment (a == b) is a point: |(3, 4, 0)| = 5.
    assert!(close(
        point_segment_distance(&[3.0, 4.0, 0.0], &a, &a),
        5.0,
        TOL
    ));
    // NaN anywhere gives NaN.
    assert!(point_segment_distance(&[f64::NAN, 0.0, 0.0], &a, &b).is_nan());
    assert!(point_segment_distance(&[1.0, 0.0, 0.0], &a, &[f64::NAN, 0.0, 0.0]).is_nan());
}

#[test]
fn segment_segment_worked_examples() {
    let o = [0.0, 0.0, 0.0];
    let x1 = [1.0, 0.0, 0.0];
    // Crossing (skew, perpendicular): the x axis from −1 to 1 and a y-parallel segment 1 above
    // it; the closest points are both midpoints, 1 apart.
    let d = segment_segment_distance(&[-1.0, 0.0, 0.0], &x1, &[0.0, -1.0, 1.0], &[0.0, 1.0, 1.0]);
    assert!(close(d, 1.0, TOL), "{d}");
    // Intersecting: 0.
    let d = segment_segment_distance(&[-1.0, 0.0, 0.0], &x1, &[0.0, -1.0, 0.0], &[0.0, 1.0, 0.0]);
    assert!(close(d, 0.0, TOL), "{d}");
    // Skew with clamping: (0,0,0)→(1,0,0) and (2,−1,1)→(2,1,1); nearest are the end (1,0,0)
    // and (2,0,1): √2.
    let d = segment_segment_distance(&o, &x1, &[2.0, -1.0, 1.0], &[2.0, 1.0, 1.0]);
    assert!(close(d, 2.0f64.sqrt(), TOL), "{d}");
    // Parallel and overlapping along x, 1 apart in y: 1.
    let d = segment_segment_distance(&o, &[2.0, 0.0, 0.0], &[1.0, 1.0, 0.0], &[3.0, 1.0, 0.0]);
    assert!(close(d, 1.0, TOL), "{d}");
    // The same, one of them reversed (anti-parallel): 1.
    let d = segment_segment_distance(&o, &[2.0, 0.0, 0.0], &[3.0, 1.0, 0.0], &[1.0, 1.0, 0.0]);
    assert!(close(d, 1.0, TOL), "{d}");
    // Parallel, not overlapping: (1,0,0) to (2,1,0): √2.
    let d = segment_segment_distance(&o, &x1, &[2.0, 1.0, 0.0], &[3.0, 1.0, 0.0]);
    assert!(close(d, 2.0f64.sqrt(), TOL), "{d}");
    // Collinear, apart: 3 − 1 = 2.
    let d = segment_segment_distance(&o, &x1, &[3.0, 0.0, 0.0], &[4.0, 0.0, 0.0]);
    assert!(close(d, 2.0, TOL), "{d}");
    // Collinear, overlapping: 0.
    let d = segment_segment_distance(&o, &[2.0, 0.0, 0.0], &[1.0, 0.0, 0.0], &[4.0, 0.0, 0.0]);
    assert!(close(d, 0.0, TOL), "{d}");
    // Both degenerate: two points 3-4-5 apart.
    let d = segment_segment_distance(&o, &o, &[3.0, 4.0, 0.0], &[3.0, 4.0, 0.0]);
    assert!(close(d, 5.0, TOL), "{d}");
    // One degenerate: the point (1, 1, 0) against (0,0,0)→(2,0,0), either way round: 1.
    let p = [1.0, 1.0, 0.0];
    let d = segment_segment_distance(&p, &p, &o, &[2.0, 0.0, 0.0]);
    assert!(close(d, 1.0, TOL), "{d}");
    let d = segment_segment_distance(&o, &[2.0, 0.0, 0.0], &p, &p);
    assert!(close(d, 1.0, TOL), "{d}");
    // NaN gives NaN.
    assert!(segment_segment_distance(&o, &x1, &[f64::NAN; 3], &x1).is_nan());
}

#[test]
fn capsule_worked_examples() {
    // Two parallel capsules 1 m apart (centre lines), radii 0.1 and 0.2: surfaces 0.7 apart.
    let a = Capsule {
        a_m: [0.0, 0.0, 0.0],
        b_m: [1.0, 0.0, 0.0],
        radius_m: 0.1,
    };
    let b = Capsule {
        a_m: [0.0, 1.0, 0.0],
        b_m: [1.0, 1.0, 0.0],
        radius_m: 0.2,
    };
    assert!(close(capsule_distance(&a, &b), 0.7, TOL));
    assert!(close(centre_line_distance(&a, &b), 1.0, TOL));
    // Radii 0.6 and 0.5 overlap: 0, not −0.1.
    let fat = Capsule { radius_m: 0.6, ..a };
    let fat_b = Capsule { radius_m: 0.5, ..b };
    assert_eq!(capsule_distance(&fat, &fat_b), 0.0);
    // A sphere of 0.12 about (0.5, 0, 0.5) and the first capsule: 0.5 − 0.1 − 0.12 = 0.28.
    let head = Capsule::point([0.5, 0.0, 0.5], 0.12);
    assert!(close(capsule_distance(&a, &head), 0.28, TOL));
    // NaN gives NaN, never 0.
    let nan = Capsule::point([f64::NAN; 3], 0.0);
    assert!(capsule_distance(&a, &nan).is_nan());
    let nan_r = Capsule {
        radius_m: f64::NAN,
        ..a
    };
    assert!(capsule_distance(&nan_r, &head).is_nan());
}

/// The default UR5e capsules at q = 0, by hand. All joints at zero: frames 1–3 have x along
/// base +x, z along base −y (the joint axes), at the shoulder height d1 = 0.1625; the elbow
/// axis is at x = a2 = −0.425, the wrist-1 axis at a2 + a3 = −0.8172; frame 4 sits d4 = 0.1333
/// along −y with z down; frame 5 d5 = 0.0997 lower (z = 0.0628) with z along −y; the flange
/// d6 = 0.0996 further along −y (y = −0.2329).
#[test]
fn ur5e_capsules_at_zero_match_the_dh_geometry() {
    let c = capsules_at(&ArmModel::ur5e_gripper(), &[0.0; 6]);
    let h = 0.1625;
    let expected: [(ArmLink, Point3, Point3, f64); ARM_CAPSULES] = [
        // Shoulder drum on the shoulder axis (−y), 0.038 … 0.158 out.
        (ArmLink::Shoulder, [0.0, -0.038, h], [0.0, -0.158, h], 0.075),
        // Upper arm 0.138 along the shoulder axis from the DH line, base axis to elbow axis.
        (
            ArmLink::UpperArm,
            [0.0, -0.138, h],
            [-0.425, -0.138, h],
            0.065,
        ),
        // Elbow drum on the elbow axis, 0.027 … 0.147 out.
        (
            ArmLink::Elbow,
            [-0.425, -0.027, h],
            [-0.425, -0.147, h],
            0.070,
        ),
        // Forearm 0.007 off the DH line, elbow axis to wrist-1 axis.
        (
            ArmLink::Forearm,
            [-0.425, -0.007, h],
            [-0.8172, -0.007, h],
            0.053,
        ),
        // Wrist-1 housing on its axis, −0.013 … 0.127.
        (
            ArmLink::Wrist1,
            [-0.8172, 0.013, h],
            [-0.8172, -0.127, h],
            0.055,
        ),
        // Wrist-2 housing on its (downward) axis, 0.02 above frame 4 down to frame 5.
        (
            ArmLink::Wrist2,
            [-0.8172, -0.1333, h + 0.02],
            [-0.8172, -0.1333, 0.0628],
            0.055,
        ),
        // Wrist-3 housing on its axis (−y), 0.02 behind frame 5 to the flange.
        (
            ArmLink::Wrist3,
            [-0.8172, -0.1133, 0.0628],
            [-0.8172, -0.2329, 0.0628],
            0.055,
        ),
        // Gripper 0.12 along the tool axis (−y) from the flange.
        (
            ArmLink::Gripper,
            [-0.8172, -0.2329, 0.0628],
            [-0.8172, -0.3529, 0.0628],
            0.06,
        ),
        // Part 0.03 beyond the fingertips.
        (
            ArmLink::Part,
            [-0.8172, -0.3529, 0.0628],
            [-0.8172, -0.3829, 0.0628],
            0.04,
        ),
    ];
    for (k, (link, a, b, r)) in expected.iter().enumerate() {
        assert_eq!(ArmLink::ALL[k], *link);
        assert_eq!(link.index(), k);
        assert_point(&c[k].a_m, a, link.name());
        assert_point(&c[k].b_m, b, link.name());
        assert_eq!(c[k].radius_m, *r, "{link}");
    }
    // The flange is the end of Wrist3, as in `kinematics::flange_pose`.
    let f = robot_io::flange_pose(&[0.0; 6]).translation.vector;
    assert_point(&c[ArmLink::Wrist3.index()].b_m, &[f.x, f.y, f.z], "flange");
}

/// At any q the capsules sit where the link frames say: the upper arm and forearm run between
/// the joint axes at their offsets, the wrist housings on their axes, the gripper and part
/// along the flange's z axis.
#[test]
fn capsules_follow_the_link_frames() {
    let arm = ArmModel::ur5e_gripper();
    let qs = [
        [0.3, -1.2, 0.9, -1.1, -1.6, 0.4],
        [-2.0, -0.5, 2.1, 0.3, 1.0, -3.0],
        [0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, 0.0],
    ];
    for q in qs {
        let c = capsules_at(&arm, &q);
        let mut frames = [Isometry3::identity(); FRAME_COUNT];
        link_frames(&q, &mut frames);
        let at = |i: usize, z: f64| -> Point3 {
            let t = frames[i];
            let p = t.translation.vector + t.rotation * Vector3::new(0.0, 0.0, z);
            [p.x, p.y, p.z]
        };
        // Frame i's z axis is joint i+1's axis; frames 1 and 2 share it (parallel axes).
        assert_point(
            &c[ArmLink::UpperArm.index()].a_m,
            &at(1, 0.138),
            "upper arm a",
        );
        assert_point(
            &c[ArmLink::UpperArm.index()].b_m,
            &at(2, 0.138),
            "upper arm b",
        );
        assert_point(&c[ArmLink::Forearm.index()].a_m, &at(2, 0.007), "forearm a");
        assert_point(&c[ArmLink::Forearm.index()].b_m, &at(3, 0.007), "forearm b");
        assert_point(&c[ArmLink::Elbow.index()].a_m, &at(2, 0.027), "elbow");
        assert_point(
            &c[ArmLink::Wrist2.index()].b_m,
            &at(5, 0.0),
            "wrist 2 ends at frame 5",
        );
        assert_point(
            &c[ArmLink::Wrist3.index()].b_m,
            &at(6, 0.0),
            "wrist 3 ends at the flange",
        );
        assert_point(&c[ArmLink::Gripper.index()].b_m, &at(6, 0.12), "fingertips");
        assert_point(&c[ArmLink::Part.index()].b_m, &at(6, 0.15), "part end");
        // Lengths are rigid: the upper arm is a2 long, the forearm a3.
        let len = |l: ArmLink| dist(&c[l.index()].a_m, &c[l.index()].b_m);
        assert!(close(len(ArmLink::UpperArm), 0.425, 1e-12));
        assert!(close(len(ArmLink::Forearm), 0.3922, 1e-12));
        assert!(close(len(ArmLink::Wrist2), 0.02 + UR5E_DH_D[4], 1e-12));
    }
    // Non-finite joints give non-finite capsules.
    let c = capsules_at(&arm, &[f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0]);
    assert!(c.iter().any(|c| !c.is_finite()));
}

/// MuJoCo Menagerie's UR5e collision geometry (`universal_robots_ur5e/ur5e.xml`: capsules and
/// one flange cylinder), restated in our DH frames, lies inside the default capsules with at
/// least 14 mm to spare, at many joint configurations. Menagerie's frames differ from the
/// DH frames by ≤ 0.7 mm (its a3 = 0.392, wrist offsets 0.127/0.1), which this ignores. Not
/// compared: Menagerie's vertical joint-1 column below the shoulder axis (not covered, see the
/// module docs).
#[test]
fn menagerie_collision_geometry_lies_inside_the_capsules() {
    // (frame, a, b, radius, is_cylinder)
    let reference: [(usize, Point3, Point3, f64, bool); 8] = [
        (1, [0.0, 0.0, 0.038], [0.0, 0.0, 0.158], 0.06, false), // shoulder drum
        (2, [0.425, 0.0, 0.138], [0.025, 0.0, 0.138], 0.05, false), // upper arm tube
        (2, [0.0, 0.0, 0.027], [0.0, 0.0, 0.147], 0.055, false), // elbow drum
        (3, [0.3822, 0.0, 0.007], [0.0022, 0.0, 0.007], 0.038, false), // forearm tube
        (3, [0.0, 0.0, -0.013], [0.0, 0.0, 0.127], 0.04, false), // wrist 1
        (4, [0.0, 0.0, -0.02], [0.0, 0.0, 0.10], 0.04, false),  // wrist 2
        (5, [0.0, 0.0, -0.02], [0.0, 0.0, 0.06], 0.04, false),  // wrist 2, on the wrist-3 axis
        (5, [0.0, 0.0, 0.06], [0.0, 0.0, 0.10], 0.04, true),    // wrist 3 flange (cylinder)
    ];
    let arm = ArmModel::ur5e_gripper();
    let qs = [
        [0.0; 6],
        [0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, 0.0],
        [0.3, -1.2, 2.4, -1.1, -1.6, 0.4],
        [-2.0, -0.5, -2.1, 0.3, 1.0, -3.0],
        [1.0, -2.5, 1.0, 2.5, 0.2, 1.0],
    ];
    let mut worst = f64::NEG_INFINITY;
    for q in qs {
        let c = capsules_at(&arm, &q);
        let mut frames = [Isometry3::identity(); FRAME_COUNT];
        link_frames(&q, &mut frames);
        for (k, (frame, a, b, r, cylinder)) in reference.iter().enumerate() {
            let t = frames[*frame];
            let place = |p: Vector3<f64>| -> Point3 {
                let w = t.transform_point(&NaPoint3::from(p));
                [w.x, w.y, w.z]
            };
            let (a, b) = (Vector3::from(*a), Vector3::from(*b));
            let axis = (b - a).normalize();
            let u = axis
                .cross(&Vector3::x())
                .try_normalize(1e-9)
                .unwrap_or_else(|| axis.cross(&Vector3::y()).normalize());
            let v = axis.cross(&u);
            let mut samples = Vec::new();
            for i in 0..=40 {
                let s = i as f64 / 40.0;
                for j in 0..36 {
                    let phi = j as f64 * PI / 18.0;
                    let radial = (u * phi.cos() + v * phi.sin()) * *r;
                    samples.push(a + (b - a) * s + radial);
                    if *cylinder && (i == 0 || i == 40) {
                        // The flat end discs.
                        for k in 1..4 {
                            samples.push(a + (b - a) * s + radial * (k as f64 / 4.0));
                        }
                    }
                    if !*cylinder && (i == 0 || i == 40) {
                        // The hemispherical caps.
                        let out = if i == 0 { -axis } else { axis };
                        for k in 1..=6 {
                            let theta = k as f64 * FRAC_PI_2 / 6.0;
                            samples.push(
                                a + (b - a) * s
                                    + (u * phi.cos() + v * phi.sin()) * (*r * theta.cos())
                                    + out * (*r * theta.sin()),
                            );
                        }
                    }
                }
            }
            for p in samples {
                let p = place(p);
                // Signed distance to the union: < 0 inside.
                let inside = c
                    .iter()
                    .map(|cap| point_segment_distance(&p, &cap.a_m, &cap.b_m) - cap.radius_m)
                    .fold(f64::INFINITY, f64::min);
                worst = worst.max(inside);
                assert!(
                    inside <= -0.014,
                    "reference shape {k} at q = {q:?}: point {p:?} is {inside} m from the surface"
                );
            }
        }
    }
    println!(
        "Menagerie UR5e collision geometry: deepest-outside point {worst:.4} m (negative = inside)"
    );
}

// --- models, validation, config ---

#[test]
fn models_validate_and_parse_from_toml() {
    let raw: RawArmModel = toml::from_str(
        r#"
        shoulder_radius_m = 0.075
        upper_arm_radius_m = 0.065
        elbow_radius_m = 0.07
        forearm_radius_m = 0.053
        wrist_1_radius_m = 0.055
        wrist_2_radius_m = 0.055
        wrist_3_radius_m = 0.055
        gripper_length_m = 0.12
        gripper_radius_m = 0.06
        part_length_m = 0.03
        part_radius_m = 0.04
        "#,
    )
    .unwrap();
    assert_eq!(ArmModel::new(raw).unwrap(), ArmModel::ur5e_gripper());
    assert_eq!(ArmModel::ur5e_gripper().raw(), raw);
    // Unknown keys are refused.
    let bad = toml::from_str::<RawArmModel>("shoulder_radius_mm = 75.0");
    assert!(bad.is_err());
    // Radii must be finite and > 0; lengths finite and >= 0.
    for (field, f) in [
        (
            "arm.forearm_radius_m",
            (|r: &mut RawArmModel| r.forearm_radius_m = 0.0) as fn(&mut RawArmModel),
        ),
        ("arm.part_radius_m", |r| r.part_radius_m = f64::NAN),
        ("arm.gripper_length_m", |r| r.gripper_length_m = -0.01),
        ("arm.part_length_m", |r| r.part_length_m = f64::INFINITY),
    ] {
        let mut r = raw;
        f(&mut r);
        let e = ArmModel::new(r).unwrap_err().to_string();
        assert!(e.contains(field), "{e}");
    }
    let mut r = raw;
    r.part_length_m = 0.0;
    assert!(ArmModel::new(r).is_ok());

    let body: RawBodyModel =
        toml::from_str("head_radius_m = 0.12\ntorso_radius_m = 0.22\ntorso_length_m = 0.5")
            .unwrap();
    assert_eq!(BodyModel::new(body).unwrap(), BodyModel::default_adult());
    assert!(toml::from_str::<RawBodyModel>("head_radius_m = 0.12\nneck_m = 1.0").is_err());
    let e = BodyModel::new(RawBodyModel {
        head_radius_m: -1.0,
        ..body
    })
    .unwrap_err()
    .to_string();
    assert_eq!(
        e,
        "invalid geometry setting `body.head_radius_m`: must be finite and > 0"
    );
}

#[test]
fn body_capsules_worked_examples() {
    let m = BodyModel::default_adult();
    let body = HumanBody {
        head_m: Some([1.0, 0.0, 1.5]),
        left_hand_m: Some([0.5, 0.2, 1.0]),
        right_hand_m: None,
        torso: Some(Torso {
            shoulder_mid_m: [1.0, 0.0, 1.3],
            normal: [-2.0, 0.0, 0.0], // facing −x, any length
        }),
    };
    assert_eq!(
        m.capsule(&body, BodyPart::Head),
        Some(Capsule::point([1.0, 0.0, 1.5], 0.12))
    );
    assert_eq!(
        m.capsule(&body, BodyPart::LeftHand),
        Some(Capsule::point([0.5, 0.2, 1.0], 0.0))
    );
    assert_eq!(m.capsule(&body, BodyPart::RightHand), None);
    // Upright: from the shoulders straight down 0.5 m.
    let t = m.capsule(&body, BodyPart::Torso).unwrap();
    assert_point(&t.a_m, &[1.0, 0.0, 1.3], "shoulders");
    assert_point(&t.b_m, &[1.0, 0.0, 0.8], "hips");
    assert_eq!(t.radius_m, 0.22);
    // Leaning 30° forward (towards −x): the chest normal tilts 30° down,
    // n = (−cos 30°, 0, −sin 30°). The spine is −z minus its component along n:
    // (−z)·n = sin 30°, d = −z − sin 30°·n = (sin 30° cos 30°, 0, −cos² 30°)
    // ∝ (sin 30°, 0, −cos 30°): the hips lie 0.5·sin 30° = 0.25 m behind (+x) and
    // 0.5·cos 30° = 0.433 m below the shoulders.
    let (s, c) = (30f64.to_radians().sin(), 30f64.to_radians().cos());
    let leaning = HumanBody {
        torso: Some(Torso {
            shoulder_mid_m: [1.0, 0.0, 1.3],
            normal: [-c, 0.0, -s],
        }),
        ..body
    };
    let t = m.capsule(&leaning, BodyPart::Torso).unwrap();
    assert_point(&t.b_m, &[1.0 + 0.5 * s, 0.0, 1.3 - 0.5 * c], "leaning hips");
    // A vertical or zero normal: straight down.
    for normal in [[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.01, 0.0, -1.0]] {
        let b = HumanBody {
            torso: Some(Torso {
                shoulder_mid_m: [0.0; 3],
                normal,
            }),
            ..HumanBody::NONE
        };
        assert_point(
            &m.capsule(&b, BodyPart::Torso).unwrap().b_m,
            &[0.0, 0.0, -0.5],
            "down",
        );
    }
    // Non-finite values give no capsule, and `is_finite` says so.
    assert!(body.is_finite());
    let bad = HumanBody {
        torso: Some(Torso {
            shoulder_mid_m: [0.0; 3],
            normal: [f64::NAN, 0.0, 1.0],
        }),
        ..body
    };
    assert!(!bad.is_finite());
    assert_eq!(m.capsule(&bad, BodyPart::Torso), None);
    let bad = HumanBody {
        right_hand_m: Some([0.0, f64::INFINITY, 0.0]),
        ..body
    };
    assert!(!bad.is_finite());
    assert_eq!(m.capsule(&bad, BodyPart::RightHand), None);
    assert!(HumanBody::default().is_finite());
    assert_eq!(
        BodyPart::ALL.map(BodyPart::name),
        ["head", "left_hand", "right_hand", "torso"]
    );
    assert!(BodyPart::LeftHand.is_hand() && !BodyPart::Torso.is_hand());
}

#[test]
fn closest_approaches_worked_example() {
    let c = capsules_at(&ArmModel::ur5e_gripper(), &[0.0; 6]);
    let m = BodyModel::default_adult();
    // q = 0 (see `ur5e_capsules_at_zero_match_the_dh_geometry`). A left hand 0.3 beyond the
    // part's end along −y: the part's segment ends at y = −0.3829, so the hand at
    // y = −0.6829 is 0.3 − 0.04 = 0.26 from its surface. The head 1 m above the shoulder drum's
    // outer end (0, −0.158, 0.1625): 1 − 0.075 − 0.12 = 0.805. The right hand is not tracked.
    let body = HumanBody {
        head_m: Some([0.0, -0.158, 1.1625]),
        left_hand_m: Some([-0.8172, -0.6829, 0.0628]),
        right_hand_m: None,
        torso: None,
    };
    let a = closest_approaches(&c, &body, &m);
    let head = a[0].unwrap();
    assert_eq!((head.part, head.link), (BodyPart::Head, ArmLink::Shoulder));
    assert!(close(head.distance_m, 0.805, 1e-12), "{head:?}");
    let hand = a[1].unwrap();
    assert_eq!((hand.part, hand.link), (BodyPart::LeftHand, ArmLink::Part));
    assert!(close(hand.distance_m, 0.26, 1e-12), "{hand:?}");
    assert_eq!((a[2], a[3]), (None, None));
    // A tracked NaN gives NaN, never "not tracked" and never a finite distance.
    let nan = HumanBody {
        right_hand_m: Some([f64::NAN, 0.0, 0.0]),
        ..body
    };
    let a = closest_approaches(&c, &nan, &m);
    assert!(a[2].unwrap().distance_m.is_nan());
    // So does a NaN arm.
    let c = capsules_at(
        &ArmModel::ur5e_gripper(),
        &[0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0],
    );
    let a = closest_approaches(&c, &body, &m);
    assert!(a[1].unwrap().distance_m.is_nan());
}

// --- property tests ---

/// The exact distance from `p` to the segment by ternary search on the convex function
/// `s ↦ |p − (a + s(b − a))|`: an independent reference.
fn point_segment_reference(p: &Point3, a: &Point3, b: &Point3) -> f64 {
    let f = |s: f64| dist(p, &lerp(a, b, s));
    minimise_convex(f)
}

/// Minimum of a convex function on [0, 1] by ternary search.
fn minimise_convex(f: impl Fn(f64) -> f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..200 {
        let m1 = lo + (hi - lo) / 3.0;
        let m2 = hi - (hi - lo) / 3.0;
        if f(m1) <= f(m2) {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    f(0.0).min(f(1.0)).min(f((lo + hi) / 2.0))
}

/// The segment–segment distance as the minimum over `s` of the (exact) point–segment
/// distance from `a(s)`: convex in `s`, so ternary search finds it.
fn segment_segment_reference(a0: &Point3, a1: &Point3, b0: &Point3, b1: &Point3) -> f64 {
    minimise_convex(|s| point_segment_distance(&lerp(a0, a1, s), b0, b1))
}

fn point() -> impl Strategy<Value = Point3> {
    prop::array::uniform3(-2.0..2.0f64)
}

/// Segment pairs, with parallel, collinear, degenerate and touching cases over-represented.
fn segment_pair() -> impl Strategy<Value = (Point3, Point3, Point3, Point3)> {
    prop_oneof![
        4 => (point(), point(), point(), point()),
        // b parallel to a (same or opposite direction, any length).
        2 => (point(), point(), point(), -2.0..2.0f64).prop_map(|(a0, a1, b0, k)| {
            let b1 = [b0[0] + k * (a1[0] - a0[0]), b0[1] + k * (a1[1] - a0[1]), b0[2] + k * (a1[2] - a0[2])];
            (a0, a1, b0, b1)
        }),
        // Collinear.
        1 => (point(), point(), -2.0..2.0f64, -2.0..2.0f64).prop_map(|(a0, a1, s, t)| {
            (a0, a1, lerp(&a0, &a1, s), lerp(&a0, &a1, t))
        }),
        // Nearly parallel: b1 off the parallel by up to 1e-7.
        1 => (point(), point(), point(), prop::array::uniform3(-1e-7..1e-7f64)).prop_map(|(a0, a1, b0, e)| {
            let b1 = [b0[0] + a1[0] - a0[0] + e[0], b0[1] + a1[1] - a0[1] + e[1], b0[2] + a1[2] - a0[2] + e[2]];
            (a0, a1, b0, b1)
        }),
        // Degenerate: one or both segments are points.
        1 => (point(), point(), point()).prop_map(|(a0, a1, b0)| (a0, a1, b0, b0)),
        1 => (point(), point()).prop_map(|(a0, b0)| (a0, a0, b0, b0)),
        // Touching: b starts on a.
        1 => (point(), point(), 0.0..1.0f64, point()).prop_map(|(a0, a1, s, b1)| (a0, a1, lerp(&a0, &a1, s), b1)),
    ]
}

fn rigid_motion() -> impl Strategy<Value = Isometry3<f64>> {
    (
        prop::array::uniform3(-1.0..1.0f64),
        0.0..PI,
        prop::array::uniform3(-3.0..3.0f64),
    )
        .prop_map(|(axis, angle, t)| {
            let axis = Vector3::from(axis)
                .try_normalize(1e-6)
                .unwrap_or_else(Vector3::z);
            Isometry3::from_parts(
                Translation3::from(Vector3::from(t)),
                UnitQuaternion::from_scaled_axis(axis * angle),
            )
        })
}

fn moved(m: &Isometry3<f64>, p: &Point3) -> Point3 {
    let w = m.transform_point(&NaPoint3::from(Vector3::from(*p)));
    [w.x, w.y, w.z]
}

proptest! {
    /// Point–segment: ≥ 0, equal to the ternary-search reference, never above the nearest of
    /// 2001 sampled points, and within half a sample spacing of it (dense sampling).
    #[test]
    fn point_segment_is_exact(p in point(), a in point(), b in point(), degenerate in any::<bool>()) {
        let b = if degenerate { a } else { b };
        let d = point_segment_distance(&p, &a, &b);
        prop_assert!(d >= 0.0);
        let reference = point_segment_reference(&p, &a, &b);
        prop_assert!((d - reference).abs() <= 1e-9, "{d} vs {reference}");
        let n = 2000;
        let sampled = (0..=n).map(|i| dist(&p, &lerp(&a, &b, i as f64 / n as f64))).fold(f64::INFINITY, f64::min);
        prop_assert!(d <= sampled + 1e-12, "{d} > sampled {sampled}");
        prop_assert!(sampled - d <= dist(&a, &b) / (2 * n) as f64 + 1e-12, "{d} far below sampled {sampled}");
    }

    /// Segment–segment: ≥ 0, symmetric (swapping the segments or their ends), exact against
    /// the reference, and never above any sampled pair.
    #[test]
    fn segment_segment_is_exact_and_symmetric((a0, a1, b0, b1) in segment_pair()) {
        let d = segment_segment_distance(&a0, &a1, &b0, &b1);
        prop_assert!(d >= 0.0);
        for other in [
            segment_segment_distance(&b0, &b1, &a0, &a1),
            segment_segment_distance(&a1, &a0, &b0, &b1),
            segment_segment_distance(&a0, &a1, &b1, &b0),
            segment_segment_distance(&b1, &b0, &a1, &a0),
        ] {
            prop_assert!((d - other).abs() <= 1e-9, "{d} vs {other}");
        }
        let reference = segment_segment_reference(&a0, &a1, &b0, &b1)
            .min(segment_segment_reference(&b0, &b1, &a0, &a1));
        prop_assert!((d - reference).abs() <= 1e-9, "{d} vs reference {reference}");
        for i in 0..=20 {
            for j in 0..=20 {
                let pair = dist(&lerp(&a0, &a1, i as f64 / 20.0), &lerp(&b0, &b1, j as f64 / 20.0));
                prop_assert!(d <= pair + 1e-12);
            }
        }
    }

    /// Distances do not change under a rigid motion of both shapes.
    #[test]
    fn distances_are_invariant_under_rigid_motion((a0, a1, b0, b1) in segment_pair(), m in rigid_motion(), p in point()) {
        let d = segment_segment_distance(&a0, &a1, &b0, &b1);
        let dm = segment_segment_distance(&moved(&m, &a0), &moved(&m, &a1), &moved(&m, &b0), &moved(&m, &b1));
        prop_assert!((d - dm).abs() <= 1e-9, "{d} vs {dm}");
        let e = point_segment_distance(&p, &a0, &a1);
        let em = point_segment_distance(&moved(&m, &p), &moved(&m, &a0), &moved(&m, &a1));
        prop_assert!((e - em).abs() <= 1e-9, "{e} vs {em}");
    }

    /// Capsule distance: ≥ 0, symmetric, ≤ the centre-line distance, and exactly
    /// max(0, centre-line − r1 − r2).
    #[test]
    fn capsule_distance_is_the_surface_gap((a0, a1, b0, b1) in segment_pair(), r1 in 0.0..0.5f64, r2 in 0.0..0.5f64) {
        let x = Capsule { a_m: a0, b_m: a1, radius_m: r1 };
        let y = Capsule { a_m: b0, b_m: b1, radius_m: r2 };
        let d = capsule_distance(&x, &y);
        let centre = centre_line_distance(&x, &y);
        prop_assert!(d >= 0.0);
        prop_assert!(d <= centre);
        prop_assert!((d - capsule_distance(&y, &x)).abs() <= 1e-9);
        prop_assert!((d - (centre - r1 - r2).max(0.0)).abs() <= 1e-15);
    }

    /// `closest_approaches` is the brute-force minimum over every link, and names a link at
    /// that distance; untracked parts give `None`.
    #[test]
    fn closest_approaches_is_the_minimum(
        q in prop::array::uniform6(-PI..PI),
        head in prop::option::of(point()),
        hand in prop::option::of(point()),
        torso in prop::option::of((point(), point())),
    ) {
        let c = capsules_at(&ArmModel::ur5e_gripper(), &q);
        let m = BodyModel::default_adult();
        let body = HumanBody {
            head_m: head,
            left_hand_m: None,
            right_hand_m: hand,
            torso: torso.map(|(s, n)| Torso { shoulder_mid_m: s, normal: n }),
        };
        let a = closest_approaches(&c, &body, &m);
        for (k, part) in BodyPart::ALL.iter().enumerate() {
            match (m.capsule(&body, *part), a[k]) {
                (None, None) => prop_assert!(!body.tracks(*part)),
                (Some(h), Some(ap)) => {
                    prop_assert_eq!(ap.part, *part);
                    let brute = c.iter().map(|x| capsule_distance(x, &h)).fold(f64::INFINITY, f64::min);
                    prop_assert_eq!(ap.distance_m, brute);
                    prop_assert_eq!(capsule_distance(&c[ap.link.index()], &h), brute);
                    // The pruned search names the same link as the brute force: the first one
                    // (in ArmLink::ALL order) at the smallest distance.
                    let first = c
                        .iter()
                        .position(|x| capsule_distance(x, &h) == brute)
                        .map(|k| ArmLink::ALL[k]);
                    prop_assert_eq!(Some(ap.link), first);
                }
                (h, ap) => prop_assert!(false, "{:?} vs {:?}", h, ap),
            }
        }
    }
}
