//! Separation geometry shared by the planner (`adapt`) and the safety supervisor (`safety`):
//! the UR5e arm, its gripper and the carried part as capsules, the operator's tracked body as
//! points and capsules, and exact distances between them.
//!
//! A [`Capsule`] is a segment `a → b` swept by a sphere of radius `r`: every point within `r`
//! of the segment. The distance between two capsules is the distance between their segments
//! minus both radii, clamped at 0 ([`capsule_distance`]); it is the gap between their surfaces.
//!
//! # The arm ([`ArmModel`])
//! One capsule per [`ArmLink`], placed in the frames of `robot_io::kinematics` (UR's standard
//! DH chain: frame `i` is the frame after joint `i`, `z_i` the axis of joint `i + 1`). The DH
//! lines run through the joint axes, but the UR5e's links do not: the upper arm is offset
//! 0.138 m along the shoulder axis from the DH line, the forearm 0.138 − 0.131 = 0.007 m (UR's
//! `shoulder_offset` and `elbow_offset`), and the wrist housings sit on their joint axes. The
//! segments below follow the UR5e collision capsules of MuJoCo Menagerie's `ur5e.xml`, in our
//! DH frames (positions [m]); the default radii are Menagerie's plus 15 mm:
//!
//! | link | frame | segment (in that frame) | Menagerie r | default r |
//! |---|---|---|---|---|
//! | `Shoulder` (joint-2 drum) | 1 | z ∈ [0.038, 0.158] on the shoulder axis | 0.060 | 0.075 |
//! | `UpperArm` | 2 | (0.425, 0, 0.138) → (0, 0, 0.138): shoulder axis to elbow axis | 0.050 | 0.065 |
//! | `Elbow` (joint-3 drum) | 2 | z ∈ [0.027, 0.147] on the elbow axis | 0.055 | 0.070 |
//! | `Forearm` | 3 | (0.3922, 0, 0.007) → (0, 0, 0.007): elbow axis to wrist-1 axis | 0.038 | 0.053 |
//! | `Wrist1` | 3 | z ∈ [−0.013, 0.127] on the wrist-1 axis | 0.040 | 0.055 |
//! | `Wrist2` | 4 | z ∈ [−0.02, d5] on the wrist-2 axis (d5 = 0.0997) | 0.040 | 0.055 |
//! | `Wrist3` | 5 | z ∈ [−0.02, d6] on the wrist-3 axis, to the flange (d6 = 0.0996) | 0.040 | 0.055 |
//! | `Gripper` | 6 | z ∈ [0, L_g] along the tool axis from the flange | — | 0.060, L_g = 0.12 |
//! | `Part` | 6 | z ∈ [L_g, L_g + L_p] beyond the fingertips | — | 0.040, L_p = 0.03 |
//!
//! The `Part` capsule is always included: whether a part is carried is not trusted. Not
//! covered: the fixed base and the joint-1 column below the shoulder axis (it turns about its
//! own axis, so its surface does not move towards anyone).
//!
//! # The operator ([`BodyModel`])
//! The hands are points (the fingers beyond the hand keypoint are the separation's intrusion
//! distance C); the head is a sphere about the head keypoint; the torso is a capsule from the
//! shoulder midpoint down the spine (the direction in the plane of the torso normal and the
//! base frame's z axis, perpendicular to the normal: the operator may lean), with a radius
//! covering half the shoulder breadth. The base frame's z axis is taken as up (a table-mounted
//! robot).
//!
//! Everything here is allocation-free; non-finite inputs give NaN distances (never 0 or a
//! finite value), which callers treat as a violation.
//!
//! # Example
//! ```
//! use robot_io::geometry::{ArmModel, BodyModel, BodyPart, HumanBody, closest_approaches};
//! use robot_io::geometry::{ARM_CAPSULES, ArmLink, Capsule};
//! let arm = ArmModel::ur5e_gripper();
//! let mut capsules = [Capsule::point([0.0; 3], 0.0); ARM_CAPSULES];
//! arm.capsules(&[0.0; 6], &mut capsules);
//! // All joints at zero: the forearm runs along −x at the shoulder height d1 = 0.1625 m,
//! // 0.007 m off the DH line along the elbow axis (−y).
//! let forearm = capsules[ArmLink::Forearm.index()];
//! assert!((forearm.a_m[0] + 0.425).abs() < 1e-12 && (forearm.a_m[1] + 0.007).abs() < 1e-12);
//! // A hand 0.2 m above the middle of the forearm's line is 0.2 − 0.053 m from its surface.
//! let body = HumanBody { right_hand_m: Some([-0.6211, -0.007, 0.3625]), ..HumanBody::default() };
//! let near = closest_approaches(&capsules, &body, &BodyModel::default_adult());
//! let hand = near[BodyPart::RightHand.index()].unwrap();
//! assert_eq!(hand.link, ArmLink::Forearm);
//! assert!((hand.distance_m - 0.147).abs() < 1e-9);
//! ```

use std::fmt;

use nalgebra::{Isometry3, Point3 as NaPoint3};
use serde::Deserialize;

use crate::error::{Result, RobotIoError, finite_bound};
use crate::kinematics::{FRAME_COUNT, UR5E_DH_A, UR5E_DH_D, link_frames};
use crate::types::Joints;

/// A point or vector in the robot base frame, `[x, y, z]` [m] (or [-] for a direction).
pub type Point3 = [f64; 3];

// --- small vector helpers on [f64; 3] ---

fn sub(a: &Point3, b: &Point3) -> Point3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn add(a: &Point3, b: &Point3) -> Point3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn scale(a: &Point3, k: f64) -> Point3 {
    [a[0] * k, a[1] * k, a[2] * k]
}

fn dot(a: &Point3, b: &Point3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: &Point3, b: &Point3) -> Point3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: &Point3) -> f64 {
    dot(a, a).sqrt()
}

fn all_finite(p: &Point3) -> bool {
    p.iter().all(|x| x.is_finite())
}

/// `x` clamped to [0, 1]; NaN stays NaN (as `f64::clamp` documents).
fn clamp01(x: f64) -> f64 {
    x.clamp(0.0, 1.0)
}

/// `x` clamped at 0 from below; NaN stays NaN (unlike `f64::max`, which drops it).
fn at_least_zero(x: f64) -> f64 {
    if x < 0.0 { 0.0 } else { x }
}

/// Squared segment length [m²] below which a segment is treated as a point (a length of
/// 1e-12 m; the distance error is at most that).
const DEGENERATE_M2: f64 = 1e-24;

/// Distance [m] from point `p` to the segment `a → b` (all [m]). Exact up to rounding: the
/// projection of `p` onto the line, clamped to the segment. A segment with `a == b` is a
/// point. NaN in any input gives NaN.
pub fn point_segment_distance(p: &Point3, a: &Point3, b: &Point3) -> f64 {
    let ab = sub(b, a);
    let ap = sub(p, a);
    let len2 = dot(&ab, &ab);
    let t = if len2 > DEGENERATE_M2 {
        clamp01(dot(&ap, &ab) / len2)
    } else {
        0.0
    };
    norm(&sub(&ap, &scale(&ab, t)))
}

/// Distance [m] between the segments `a0 → a1` and `b0 → b1` (all [m]). Exact up to rounding
/// (the closest pair of points is solved in closed form, with the parameter of one segment
/// clamped and the other re-solved, as in Ericson, *Real-Time Collision Detection*, §5.1.9);
/// parallel, collinear and degenerate (zero-length) segments are handled. The line–line
/// parameter is computed from cross products (`|d1 × d2|²` rather than `|d1|²|d2|² −
/// (d1·d2)²`, equal by Lagrange's identity), which keeps nearly parallel segments exact too.
/// NaN in any input gives NaN.
pub fn segment_segment_distance(a0: &Point3, a1: &Point3, b0: &Point3, b1: &Point3) -> f64 {
    let d1 = sub(a1, a0);
    let d2 = sub(b1, b0);
    let r = sub(a0, b0);
    let a = dot(&d1, &d1);
    let e = dot(&d2, &d2);
    let f = dot(&d2, &r);
    if a.is_nan() || e.is_nan() || f.is_nan() {
        return f64::NAN;
    }
    let (s, t) = if a <= DEGENERATE_M2 && e <= DEGENERATE_M2 {
        (0.0, 0.0)
    } else if a <= DEGENERATE_M2 {
        (0.0, clamp01(f / e))
    } else {
        let c = dot(&d1, &r);
        if e <= DEGENERATE_M2 {
            (clamp01(-c / a), 0.0)
        } else {
            let b = dot(&d1, &d2);
            // The closest points of the two lines: s = (b f − c e) / (a e − b²), written as
            // (n · (d2 × r)) / |n|² with n = d1 × d2, free of cancellation when the segments
            // are nearly parallel.
            let n = cross(&d1, &d2);
            let denom = dot(&n, &n);
            // Parallel (n = 0): any s works; take 0 and let the clamping below find the
            // closest ends.
            let s = if denom > 0.0 {
                clamp01(dot(&n, &cross(&d2, &r)) / denom)
            } else {
                0.0
            };
            let t = (b * s + f) / e;
            if t < 0.0 {
                (clamp01(-c / a), 0.0)
            } else if t > 1.0 {
                (clamp01((b - c) / a), 1.0)
            } else {
                (s, t)
            }
        }
    };
    let c1 = add(a0, &scale(&d1, s));
    let c2 = add(b0, &scale(&d2, t));
    norm(&sub(&c1, &c2))
}

/// A segment `a_m → b_m` swept by a sphere of radius `radius_m` [m] (base frame [m]). A point
/// or a sphere is a capsule with `a_m == b_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Capsule {
    /// One end of the segment [m].
    pub a_m: Point3,
    /// The other end of the segment [m].
    pub b_m: Point3,
    /// Radius [m], ≥ 0.
    pub radius_m: f64,
}

impl Capsule {
    /// A sphere of radius `radius_m` [m] about `centre_m` [m] (radius 0: a point).
    pub const fn point(centre_m: Point3, radius_m: f64) -> Capsule {
        Capsule {
            a_m: centre_m,
            b_m: centre_m,
            radius_m,
        }
    }

    /// Whether the ends and the radius are finite.
    pub fn is_finite(&self) -> bool {
        all_finite(&self.a_m) && all_finite(&self.b_m) && self.radius_m.is_finite()
    }
}

/// The distance between the centre lines (segments) of two capsules [m], radii ignored.
pub fn centre_line_distance(x: &Capsule, y: &Capsule) -> f64 {
    segment_segment_distance(&x.a_m, &x.b_m, &y.a_m, &y.b_m)
}

/// The distance between the surfaces of two capsules [m]: the distance between their
/// segments minus both radii, clamped at 0 (0: touching or overlapping). NaN in any input
/// gives NaN.
pub fn capsule_distance(x: &Capsule, y: &Capsule) -> f64 {
    at_least_zero(centre_line_distance(x, y) - x.radius_m - y.radius_m)
}

/// The arm's capsules, in this order (the index into [`ArmModel::capsules`]' output).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ArmLink {
    /// The shoulder drum: the joint-2 housing on the shoulder axis.
    Shoulder,
    /// The upper arm, shoulder axis to elbow axis.
    UpperArm,
    /// The elbow drum: the joint-3 housing on the elbow axis.
    Elbow,
    /// The forearm, elbow axis to wrist-1 axis.
    Forearm,
    /// The wrist-1 housing on its axis.
    Wrist1,
    /// The wrist-2 housing on its axis.
    Wrist2,
    /// The wrist-3 housing on its axis, up to the tool flange.
    Wrist3,
    /// The gripper, from the flange along the tool axis to its fingertips.
    Gripper,
    /// The carried part, beyond the fingertips (always included).
    Part,
}

/// Number of arm capsules ([`ArmLink::ALL`]).
pub const ARM_CAPSULES: usize = 9;

impl ArmLink {
    /// All links, in output order.
    pub const ALL: [ArmLink; ARM_CAPSULES] = [
        ArmLink::Shoulder,
        ArmLink::UpperArm,
        ArmLink::Elbow,
        ArmLink::Forearm,
        ArmLink::Wrist1,
        ArmLink::Wrist2,
        ArmLink::Wrist3,
        ArmLink::Gripper,
        ArmLink::Part,
    ];

    /// Lower-case name, as written in logs (`upper_arm`, `wrist_1`, …).
    pub fn name(self) -> &'static str {
        match self {
            ArmLink::Shoulder => "shoulder",
            ArmLink::UpperArm => "upper_arm",
            ArmLink::Elbow => "elbow",
            ArmLink::Forearm => "forearm",
            ArmLink::Wrist1 => "wrist_1",
            ArmLink::Wrist2 => "wrist_2",
            ArmLink::Wrist3 => "wrist_3",
            ArmLink::Gripper => "gripper",
            ArmLink::Part => "part",
        }
    }

    /// Index into [`ArmLink::ALL`] (0-based).
    pub fn index(self) -> usize {
        match self {
            ArmLink::Shoulder => 0,
            ArmLink::UpperArm => 1,
            ArmLink::Elbow => 2,
            ArmLink::Forearm => 3,
            ArmLink::Wrist1 => 4,
            ArmLink::Wrist2 => 5,
            ArmLink::Wrist3 => 6,
            ArmLink::Gripper => 7,
            ArmLink::Part => 8,
        }
    }
}

impl fmt::Display for ArmLink {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// UR's `shoulder_offset` for the UR5e: the upper arm's axis lies this far along the shoulder
/// axis from the DH line [m].
pub const UR5E_UPPER_ARM_OFFSET_M: f64 = 0.138;
/// The forearm's axis lies this far along the elbow axis from the DH line [m]: UR's
/// `shoulder_offset − elbow_offset` = 0.138 − 0.131.
pub const UR5E_FOREARM_OFFSET_M: f64 = 0.007;

/// The arm's sizes as a config file gives them (all [m]); see [`ArmModel`].
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawArmModel {
    /// Radius of the shoulder drum capsule [m], > 0.
    pub shoulder_radius_m: f64,
    /// Radius of the upper arm capsule [m], > 0.
    pub upper_arm_radius_m: f64,
    /// Radius of the elbow drum capsule [m], > 0.
    pub elbow_radius_m: f64,
    /// Radius of the forearm capsule [m], > 0.
    pub forearm_radius_m: f64,
    /// Radius of the wrist-1 capsule [m], > 0.
    pub wrist_1_radius_m: f64,
    /// Radius of the wrist-2 capsule [m], > 0.
    pub wrist_2_radius_m: f64,
    /// Radius of the wrist-3 capsule [m], > 0.
    pub wrist_3_radius_m: f64,
    /// Gripper length L_g from the flange to the fingertips along the tool axis [m], ≥ 0.
    pub gripper_length_m: f64,
    /// Gripper radius [m], > 0.
    pub gripper_radius_m: f64,
    /// Length L_p the carried part reaches beyond the fingertips [m], ≥ 0.
    pub part_length_m: f64,
    /// Radius of the carried part [m], > 0.
    pub part_radius_m: f64,
}

/// The arm as capsules: validated radii [m] and the gripper's and part's lengths [m] (see the
/// module docs for where each capsule lies). Build with [`ArmModel::new`] or
/// [`ArmModel::ur5e_gripper`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmModel {
    raw: RawArmModel,
}

fn geometry_err<T>(field: &'static str, reason: &'static str) -> Result<T> {
    Err(RobotIoError::InvalidGeometry { field, reason })
}

fn radius(field: &'static str, v: f64) -> Result<f64> {
    finite_bound(v, true).or_else(|reason| geometry_err(field, reason))
}

fn length(field: &'static str, v: f64) -> Result<f64> {
    finite_bound(v, false).or_else(|reason| geometry_err(field, reason))
}

impl ArmModel {
    /// Validate `raw`: every radius finite and > 0, the lengths finite and ≥ 0.
    ///
    /// # Errors
    /// [`RobotIoError::InvalidGeometry`] naming the first invalid field.
    pub fn new(raw: RawArmModel) -> Result<ArmModel> {
        radius("arm.shoulder_radius_m", raw.shoulder_radius_m)?;
        radius("arm.upper_arm_radius_m", raw.upper_arm_radius_m)?;
        radius("arm.elbow_radius_m", raw.elbow_radius_m)?;
        radius("arm.forearm_radius_m", raw.forearm_radius_m)?;
        radius("arm.wrist_1_radius_m", raw.wrist_1_radius_m)?;
        radius("arm.wrist_2_radius_m", raw.wrist_2_radius_m)?;
        radius("arm.wrist_3_radius_m", raw.wrist_3_radius_m)?;
        length("arm.gripper_length_m", raw.gripper_length_m)?;
        radius("arm.gripper_radius_m", raw.gripper_radius_m)?;
        length("arm.part_length_m", raw.part_length_m)?;
        radius("arm.part_radius_m", raw.part_radius_m)?;
        Ok(ArmModel { raw })
    }

    /// The UR5e with a parallel gripper and a small part: MuJoCo Menagerie's UR5e collision
    /// radii plus 15 mm (shoulder 0.075, upper arm 0.065, elbow 0.070, forearm 0.053,
    /// wrists 0.055 m); a gripper 0.12 m long from the flange to the fingertips, radius
    /// 0.06 m (a 2F-85-class gripper, fingers open); a part reaching 0.03 m beyond the
    /// fingertips, radius 0.04 m. With `config/handover.toml`'s pick pose (flange 0.15 m above
    /// the table, tool down) the part's end is at the table.
    pub fn ur5e_gripper() -> ArmModel {
        ArmModel {
            raw: RawArmModel {
                shoulder_radius_m: 0.075,
                upper_arm_radius_m: 0.065,
                elbow_radius_m: 0.070,
                forearm_radius_m: 0.053,
                wrist_1_radius_m: 0.055,
                wrist_2_radius_m: 0.055,
                wrist_3_radius_m: 0.055,
                gripper_length_m: 0.12,
                gripper_radius_m: 0.06,
                part_length_m: 0.03,
                part_radius_m: 0.04,
            },
        }
    }

    /// The sizes, as a config file would give them.
    pub fn raw(&self) -> RawArmModel {
        self.raw
    }

    /// The radius of `link`'s capsule [m].
    pub fn radius_m(&self, link: ArmLink) -> f64 {
        let r = &self.raw;
        match link {
            ArmLink::Shoulder => r.shoulder_radius_m,
            ArmLink::UpperArm => r.upper_arm_radius_m,
            ArmLink::Elbow => r.elbow_radius_m,
            ArmLink::Forearm => r.forearm_radius_m,
            ArmLink::Wrist1 => r.wrist_1_radius_m,
            ArmLink::Wrist2 => r.wrist_2_radius_m,
            ArmLink::Wrist3 => r.wrist_3_radius_m,
            ArmLink::Gripper => r.gripper_radius_m,
            ArmLink::Part => r.part_radius_m,
        }
    }

    /// Where `link`'s segment lies: the link frame (0 = base … 6 = flange) and both ends in
    /// that frame [m] (see the table in the module docs).
    pub fn segment_in_frame(&self, link: ArmLink) -> (usize, Point3, Point3) {
        let [_, a2, a3, ..] = UR5E_DH_A;
        let [_, _, _, _, d5, d6] = UR5E_DH_D;
        let ua = UR5E_UPPER_ARM_OFFSET_M;
        let fa = UR5E_FOREARM_OFFSET_M;
        let lg = self.raw.gripper_length_m;
        let lp = self.raw.part_length_m;
        match link {
            ArmLink::Shoulder => (1, [0.0, 0.0, 0.038], [0.0, 0.0, 0.158]),
            // In frame 2 the shoulder axis is at x = −a2.
            ArmLink::UpperArm => (2, [-a2, 0.0, ua], [0.0, 0.0, ua]),
            ArmLink::Elbow => (2, [0.0, 0.0, 0.027], [0.0, 0.0, 0.147]),
            // In frame 3 the elbow axis is at x = −a3.
            ArmLink::Forearm => (3, [-a3, 0.0, fa], [0.0, 0.0, fa]),
            ArmLink::Wrist1 => (3, [0.0, 0.0, -0.013], [0.0, 0.0, 0.127]),
            ArmLink::Wrist2 => (4, [0.0, 0.0, -0.02], [0.0, 0.0, d5]),
            ArmLink::Wrist3 => (5, [0.0, 0.0, -0.02], [0.0, 0.0, d6]),
            ArmLink::Gripper => (6, [0.0, 0.0, 0.0], [0.0, 0.0, lg]),
            ArmLink::Part => (6, [0.0, 0.0, lg], [0.0, 0.0, lg + lp]),
        }
    }

    /// Fill `out` (in [`ArmLink::ALL`] order) with the capsules at joint positions `q` [rad],
    /// in the base frame [m], from `robot_io::kinematics::link_frames` (UR5e DH). The `Part`
    /// capsule is always included. Allocates nothing; non-finite `q` gives non-finite
    /// capsules (NaN distances).
    pub fn capsules(&self, q: &Joints, out: &mut [Capsule; ARM_CAPSULES]) {
        let mut frames = [Isometry3::identity(); FRAME_COUNT];
        link_frames(q, &mut frames);
        for (slot, link) in out.iter_mut().zip(ArmLink::ALL) {
            let (frame, a, b) = self.segment_in_frame(link);
            let place = |p: Point3| -> Point3 {
                match frames.get(frame) {
                    Some(t) => {
                        let w = t.transform_point(&NaPoint3::new(p[0], p[1], p[2]));
                        [w.x, w.y, w.z]
                    }
                    // Never for frames 1..=6 of a 7-frame chain; NaN fails every check.
                    None => [f64::NAN; 3],
                }
            };
            *slot = Capsule {
                a_m: place(a),
                b_m: place(b),
                radius_m: self.radius_m(link),
            };
        }
    }
}

impl Default for ArmModel {
    /// [`ArmModel::ur5e_gripper`].
    fn default() -> Self {
        ArmModel::ur5e_gripper()
    }
}

/// Upper-body cue: the shoulder midpoint [m] and the torso (chest) normal (any length > 0,
/// pointing out of the chest) [-], in the robot base frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Torso {
    /// Shoulder midpoint [m].
    pub shoulder_mid_m: Point3,
    /// Torso normal [-], any length > 0.
    pub normal: Point3,
}

/// The operator's tracked body in the robot base frame [m]; `None` = not tracked.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HumanBody {
    /// Head keypoint [m].
    pub head_m: Option<Point3>,
    /// Left hand keypoint [m].
    pub left_hand_m: Option<Point3>,
    /// Right hand keypoint [m].
    pub right_hand_m: Option<Point3>,
    /// Upper body (shoulder midpoint and torso normal).
    pub torso: Option<Torso>,
}

impl HumanBody {
    /// Nothing tracked.
    pub const NONE: HumanBody = HumanBody {
        head_m: None,
        left_hand_m: None,
        right_hand_m: None,
        torso: None,
    };

    /// Whether `part` is tracked (finite or not).
    pub fn tracks(&self, part: BodyPart) -> bool {
        match part {
            BodyPart::Head => self.head_m.is_some(),
            BodyPart::LeftHand => self.left_hand_m.is_some(),
            BodyPart::RightHand => self.right_hand_m.is_some(),
            BodyPart::Torso => self.torso.is_some(),
        }
    }

    /// Whether every tracked value (points, shoulder midpoint, torso normal) is finite.
    pub fn is_finite(&self) -> bool {
        let point = |p: &Option<Point3>| p.as_ref().is_none_or(all_finite);
        point(&self.head_m)
            && point(&self.left_hand_m)
            && point(&self.right_hand_m)
            && self
                .torso
                .as_ref()
                .is_none_or(|t| all_finite(&t.shoulder_mid_m) && all_finite(&t.normal))
    }
}

/// A tracked part of the operator's body.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BodyPart {
    /// The head (a sphere about the head keypoint).
    Head,
    /// The left hand (a point).
    LeftHand,
    /// The right hand (a point).
    RightHand,
    /// The torso (a capsule down the spine from the shoulder midpoint).
    Torso,
}

impl BodyPart {
    /// All parts, in the order of [`closest_approaches`]' output.
    pub const ALL: [BodyPart; 4] = [
        BodyPart::Head,
        BodyPart::LeftHand,
        BodyPart::RightHand,
        BodyPart::Torso,
    ];

    /// Lower-case name, as written in logs (`head`, `left_hand`, `right_hand`, `torso`).
    pub fn name(self) -> &'static str {
        match self {
            BodyPart::Head => "head",
            BodyPart::LeftHand => "left_hand",
            BodyPart::RightHand => "right_hand",
            BodyPart::Torso => "torso",
        }
    }

    /// Whether this is a hand (v_h of arm reach rather than walking).
    pub fn is_hand(self) -> bool {
        matches!(self, BodyPart::LeftHand | BodyPart::RightHand)
    }

    /// Index into [`BodyPart::ALL`] (0-based).
    pub fn index(self) -> usize {
        match self {
            BodyPart::Head => 0,
            BodyPart::LeftHand => 1,
            BodyPart::RightHand => 2,
            BodyPart::Torso => 3,
        }
    }
}

impl fmt::Display for BodyPart {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The body's sizes as a config file gives them (all [m]); see [`BodyModel`].
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawBodyModel {
    /// Radius of the head sphere about the head keypoint [m], > 0.
    pub head_radius_m: f64,
    /// Radius of the torso capsule [m], > 0: at least half the shoulder breadth, so the
    /// shoulders are inside it.
    pub torso_radius_m: f64,
    /// Length of the torso segment down the spine from the shoulder midpoint [m], ≥ 0.
    pub torso_length_m: f64,
}

/// The operator's body sizes, validated. Hands are points (their fingers are the separation's
/// intrusion distance C). Build with [`BodyModel::new`] or [`BodyModel::default_adult`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyModel {
    raw: RawBodyModel,
}

impl BodyModel {
    /// Validate `raw`: radii finite and > 0, the torso length finite and ≥ 0.
    ///
    /// # Errors
    /// [`RobotIoError::InvalidGeometry`] naming the first invalid field.
    pub fn new(raw: RawBodyModel) -> Result<BodyModel> {
        radius("body.head_radius_m", raw.head_radius_m)?;
        radius("body.torso_radius_m", raw.torso_radius_m)?;
        length("body.torso_length_m", raw.torso_length_m)?;
        Ok(BodyModel { raw })
    }

    /// An adult operator: head radius 0.12 m about the head keypoint (the face-model origin
    /// behind the nose; crown and chin are about 0.12 m from it); torso radius 0.22 m (half a
    /// 95th-percentile shoulder breadth of about 0.44 m; the chest then lies inside with about
    /// 0.1 m to spare in front); torso 0.5 m from the shoulders to the hips.
    pub fn default_adult() -> BodyModel {
        BodyModel {
            raw: RawBodyModel {
                head_radius_m: 0.12,
                torso_radius_m: 0.22,
                torso_length_m: 0.5,
            },
        }
    }

    /// The sizes, as a config file would give them.
    pub fn raw(&self) -> RawBodyModel {
        self.raw
    }

    /// The capsule of `part` in the base frame [m]; `None` if it is not tracked or not finite.
    ///
    /// - hands: a point (radius 0);
    /// - head: a sphere of the head radius;
    /// - torso: from the shoulder midpoint, `torso_length_m` down the spine, radius
    ///   `torso_radius_m`. The spine direction is −z (base frame, up = +z) with its component
    ///   along the torso normal removed, so a leaning operator's torso leans with them; if the
    ///   normal is zero or (nearly) vertical it is −z.
    pub fn capsule(&self, body: &HumanBody, part: BodyPart) -> Option<Capsule> {
        let point = |p: Option<Point3>, r: f64| p.filter(all_finite).map(|c| Capsule::point(c, r));
        match part {
            BodyPart::Head => point(body.head_m, self.raw.head_radius_m),
            BodyPart::LeftHand => point(body.left_hand_m, 0.0),
            BodyPart::RightHand => point(body.right_hand_m, 0.0),
            BodyPart::Torso => {
                let t = body.torso?;
                if !(all_finite(&t.shoulder_mid_m) && all_finite(&t.normal)) {
                    return None;
                }
                let spine = spine_direction(&t.normal);
                Some(Capsule {
                    a_m: t.shoulder_mid_m,
                    b_m: add(&t.shoulder_mid_m, &scale(&spine, self.raw.torso_length_m)),
                    radius_m: self.raw.torso_radius_m,
                })
            }
        }
    }
}

impl Default for BodyModel {
    /// [`BodyModel::default_adult`].
    fn default() -> Self {
        BodyModel::default_adult()
    }
}

/// Unit spine direction (shoulders → hips) for a finite torso normal: −z with its component
/// along the normal removed, or −z if that leaves (almost) nothing.
fn spine_direction(normal: &Point3) -> Point3 {
    const DOWN: Point3 = [0.0, 0.0, -1.0];
    let n_len = norm(normal);
    if !(n_len > 0.0 && n_len.is_finite()) {
        return DOWN;
    }
    let n = scale(normal, 1.0 / n_len);
    let d = sub(&DOWN, &scale(&n, dot(&DOWN, &n)));
    let d_len = norm(&d);
    // |d| = sin(angle between the normal and the vertical); below 0.1 (6°) the lean is
    // ill-defined.
    if d_len > 0.1 {
        scale(&d, 1.0 / d_len)
    } else {
        DOWN
    }
}

/// The closest approach between one body part and the arm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Approach {
    /// Surface-to-surface distance [m], ≥ 0; NaN if any input was not finite.
    pub distance_m: f64,
    /// The nearest arm link (for NaN: the first link whose distance was NaN).
    pub link: ArmLink,
    /// The body part.
    pub part: BodyPart,
}

/// For each [`BodyPart`] (index = [`BodyPart::ALL`] order) the nearest arm link and its
/// surface distance [m]; `None` when the part is not tracked. A tracked part with a
/// non-finite value, or a non-finite arm capsule, gives distance NaN (callers treat NaN as a
/// violation). Allocates nothing.
///
/// The result is exactly the brute-force minimum over the links in [`ArmLink::ALL`] order (the
/// first link at the smallest distance), but a link whose distance provably exceeds the best
/// one found so far is not computed: `|m_x − m_y| − h_x − h_y − r_x − r_y` (midpoints `m`,
/// half-lengths `h`, radii `r`) is a lower bound of the surface distance, and a link is
/// skipped when that bound exceeds the best by more than [`PRUNE_SLACK_M`] (far above the
/// rounding of either computation), so a skipped link could never have been the nearest nor
/// tied with it. The link with the smallest bound is computed first.
pub fn closest_approaches(
    arm: &[Capsule; ARM_CAPSULES],
    body: &HumanBody,
    model: &BodyModel,
) -> [Option<Approach>; 4] {
    if !arm.iter().all(within_pruning_range) {
        return closest_approaches_unpruned(arm, body, model);
    }
    let spheres = arm.map(|c| BoundingSphere::of(&c));
    BodyPart::ALL.map(|part| nearest_link(arm, &spheres, body, model, part))
}

/// The pruned search of [`closest_approaches`] for one part (`arm` within the pruning range,
/// `spheres` its bounding spheres).
fn nearest_link(
    arm: &[Capsule; ARM_CAPSULES],
    spheres: &[BoundingSphere; ARM_CAPSULES],
    body: &HumanBody,
    model: &BodyModel,
    part: BodyPart,
) -> Option<Approach> {
    if !body.tracks(part) {
        return None;
    }
    let Some(human) = model.capsule(body, part).filter(within_pruning_range) else {
        return nearest_link_unpruned(arm, body, model, part);
    };
    let hs = BoundingSphere::of(&human);
    // Squared midpoint distances, and the link with the smallest lower bound.
    let mut mid2 = [0.0_f64; ARM_CAPSULES];
    let mut first = 0;
    let mut first_bound = f64::INFINITY;
    for (k, (m2, s)) in mid2.iter_mut().zip(spheres).enumerate() {
        let d = sub(&s.centre, &hs.centre);
        *m2 = dot(&d, &d);
        let bound = m2.sqrt() - s.reach - hs.reach;
        if bound < first_bound {
            first_bound = bound;
            first = k;
        }
    }
    let (Some(c0), Some(l0)) = (arm.get(first), ArmLink::ALL.get(first)) else {
        return nearest_link_unpruned(arm, body, model, part);
    };
    let d0 = capsule_distance(c0, &human);
    if d0.is_nan() {
        return nearest_link_unpruned(arm, body, model, part);
    }
    let mut best = Approach {
        distance_m: d0,
        link: *l0,
        part,
    };
    let mut best_k = first;
    for (k, ((link, capsule), (s, m2))) in ArmLink::ALL
        .iter()
        .zip(arm)
        .zip(spheres.iter().zip(&mid2))
        .enumerate()
    {
        if k == first {
            continue;
        }
        // Skip when |m_x − m_y| ≥ best + reach_x + reach_y + slack (squared; both sides ≥ 0).
        let t = best.distance_m + s.reach + hs.reach + PRUNE_SLACK_M;
        if *m2 >= t * t {
            continue;
        }
        let d = capsule_distance(capsule, &human);
        if d.is_nan() {
            return nearest_link_unpruned(arm, body, model, part);
        }
        if d < best.distance_m || (d == best.distance_m && k < best_k) {
            best = Approach {
                distance_m: d,
                link: *link,
                part,
            };
            best_k = k;
        }
    }
    Some(best)
}

/// Margin [m] by which a link's lower bound must exceed the best distance for
/// [`closest_approaches`] to skip it (the rounding of the bound and of the distance is
/// ~1e-15 m at the arm's scale).
pub const PRUNE_SLACK_M: f64 = 1e-9;

/// Coordinates and radii up to this size [m] are pruned; larger (absurd) ones, where the
/// products of the distance computation could overflow, take the brute-force path.
const PRUNE_RANGE_M: f64 = 1e6;

/// Whether `c` is finite and within [`PRUNE_RANGE_M`].
fn within_pruning_range(c: &Capsule) -> bool {
    c.a_m
        .iter()
        .chain(&c.b_m)
        .chain(std::iter::once(&c.radius_m))
        .all(|v| v.abs() <= PRUNE_RANGE_M)
}

/// A capsule's bounding sphere: the segment's midpoint and half-length plus the radius [m].
#[derive(Clone, Copy)]
struct BoundingSphere {
    centre: Point3,
    reach: f64,
}

impl BoundingSphere {
    fn of(c: &Capsule) -> BoundingSphere {
        let centre = scale(&add(&c.a_m, &c.b_m), 0.5);
        BoundingSphere {
            centre,
            reach: 0.5 * norm(&sub(&c.b_m, &c.a_m)) + c.radius_m,
        }
    }
}

/// [`closest_approaches`] by brute force (every link), for non-finite input.
fn closest_approaches_unpruned(
    arm: &[Capsule; ARM_CAPSULES],
    body: &HumanBody,
    model: &BodyModel,
) -> [Option<Approach>; 4] {
    BodyPart::ALL.map(|part| {
        if !body.tracks(part) {
            return None;
        }
        nearest_link_unpruned(arm, body, model, part)
    })
}

/// The nearest link to a tracked `part` by brute force (NaN as [`closest_approaches`] says).
fn nearest_link_unpruned(
    arm: &[Capsule; ARM_CAPSULES],
    body: &HumanBody,
    model: &BodyModel,
    part: BodyPart,
) -> Option<Approach> {
    let nan = |link| {
        Some(Approach {
            distance_m: f64::NAN,
            link,
            part,
        })
    };
    let Some(human) = model.capsule(body, part) else {
        return nan(ArmLink::Shoulder);
    };
    let mut best: Option<Approach> = None;
    for (link, capsule) in ArmLink::ALL.iter().zip(arm) {
        let d = capsule_distance(capsule, &human);
        if d.is_nan() {
            return nan(*link);
        }
        if best.is_none_or(|b| d < b.distance_m) {
            best = Some(Approach {
                distance_m: d,
                link: *link,
                part,
            });
        }
    }
    best
}
