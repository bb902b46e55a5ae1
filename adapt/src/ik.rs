//! Analytic UR5e inverse kinematics: all 8 branches, and the branch nearest the current joints.
//!
//! The forward model is [`robot_io::kinematics`] (UR's standard DH chain, frames as there).
//! For a flange pose `T = (R, p)` in the base frame:
//! 1. **θ1** (shoulder left/right): the wrist-2 centre `p5 = p − d6·z6` has the constant offset
//!    `d4` along the joint-2 axis `z1 = (sin θ1, −cos θ1, 0)`, so with `p5 = r·(cos φ, sin φ)`:
//!    `sin(θ1 − φ) = d4 / r`, two solutions (none if `r < d4`).
//! 2. **θ5** (wrist up/down): `p·z1 = d4 + d6·cos θ5`, two solutions `±acos(·)` (none if
//!    `|cos θ5| > 1`).
//! 3. **θ6**: `z1` seen from the flange is `(sin θ5·cos θ6, −sin θ5·sin θ6, cos θ5)`. At a
//!    wrist singularity (`sin θ5 ≈ 0`) θ6 is free and the caller's hint is used.
//! 4. **θ2, θ3, θ4** (elbow up/down): a planar 2R problem for the wrist-1 centre in frame 1,
//!    `cos θ3 = (x² + y² − a2² − a3²) / (2·a2·a3)`, two solutions (none if `|cos θ3| > 1`);
//!    θ4 closes the sum `θ2 + θ3 + θ4`.
//!
//! Each branch is checked against the forward model; one whose pose error exceeds
//! [`POSE_TOLERANCE_M`] / [`ORIENTATION_TOLERANCE_RAD`] is dropped. Angles of a branch lie in
//! (−π, π]; [`nearest`] shifts each joint by multiples of 2π (within the ±2π joint range) to
//! come closest to the current joint vector.
//!
//! # Example
//! ```
//! use robot_io::kinematics::flange_pose;
//! let q = [0.3, -1.2, 1.4, -1.5, -1.6, 0.2];
//! let back = adapt::ik::nearest(&q, &flange_pose(&q))?;
//! assert!(back.iter().zip(&q).all(|(a, b)| (a - b).abs() < 1e-9));
//! # Ok::<(), adapt::AdaptError>(())
//! ```

use std::f64::consts::{PI, TAU};

use nalgebra::{Isometry3, Vector3};
use robot_io::Joints;
use robot_io::kinematics::{UR5E_DH_A, UR5E_DH_D, dh_link, flange_pose};

use crate::{AdaptError, Result};

/// Number of analytic branches: shoulder × wrist × elbow.
pub const BRANCH_COUNT: usize = 8;
/// Largest position error [m] of an accepted branch against the forward model.
pub const POSE_TOLERANCE_M: f64 = 1e-7;
/// Largest orientation error [rad] of an accepted branch against the forward model.
pub const ORIENTATION_TOLERANCE_RAD: f64 = 1e-7;
/// Below this `|sin θ5|` [-] the wrist is singular and θ6 takes the hint.
pub const WRIST_SINGULARITY: f64 = 1e-10;
/// Joint position limit [rad] of every UR5e joint (±2π).
pub const JOINT_LIMIT_RAD: f64 = TAU;

/// The 8 analytic branches of one pose. Branch `k` has bits: 4 = second shoulder solution,
/// 2 = negative wrist (θ5 < 0), 1 = second elbow solution. `None` where the branch does
/// not exist (out of reach for that configuration, or rejected by the forward check).
pub type Branches = [Option<Joints>; BRANCH_COUNT];

/// Wrap an angle [rad] into (−π, π].
fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    if w > PI { w - TAU } else { w }
}

/// All analytic inverse kinematics branches of a flange pose (the `tool0` frame in the base
/// frame, position [m]). `q6_hint` [rad] is used for θ6 at a wrist singularity. Angles in
/// (−π, π]. Allocates nothing.
pub fn branches(pose: &Isometry3<f64>, q6_hint: f64) -> Branches {
    let [_, _, _, d4, _, d6] = UR5E_DH_D;
    let [_, a2, a3, _, _, _] = UR5E_DH_A;
    let mut out: Branches = [None; BRANCH_COUNT];
    let rot = pose.rotation.to_rotation_matrix();
    let p = pose.translation.vector;
    let z6 = rot * Vector3::z();
    let p5 = p - z6 * d6;
    let r = p5.x.hypot(p5.y);
    if !(r.is_finite() && r >= d4.abs()) {
        return out;
    }
    let phi = p5.y.atan2(p5.x);
    let s = (d4 / r).clamp(-1.0, 1.0).asin();
    let shoulder = [phi + s, phi + PI - s];
    let mut k = 0usize;
    for theta1 in shoulder {
        let (s1, c1) = theta1.sin_cos();
        let z1 = Vector3::new(s1, -c1, 0.0);
        let c5 = (p.dot(&z1) - d4) / d6;
        // Allow rounding just outside ±1 (wrist exactly straight).
        let c5 = if c5.abs() <= 1.0 + 1e-12 {
            c5.clamp(-1.0, 1.0)
        } else {
            c5
        };
        let wrist = if c5.abs() <= 1.0 {
            let t5 = c5.acos();
            [Some(t5), Some(-t5)]
        } else {
            [None, None]
        };
        for theta5 in wrist {
            let Some(theta5) = theta5 else {
                k += 2;
                continue;
            };
            let s5 = theta5.sin();
            // z1 in flange coordinates.
            let w = rot.inverse() * z1;
            let theta6 = if s5.abs() < WRIST_SINGULARITY {
                q6_hint
            } else {
                (-w.y / s5).atan2(w.x / s5)
            };
            // Frame 4 in frame 1: T14 = T01⁻¹ · T06 · T56⁻¹ · T45⁻¹.
            let t14 = dh_link(0, theta1).inverse()
                * pose
                * dh_link(5, theta6).inverse()
                * dh_link(4, theta5).inverse();
            let x = t14.translation.vector.x;
            let y = t14.translation.vector.y;
            let c3 = (x * x + y * y - a2 * a2 - a3 * a3) / (2.0 * a2 * a3);
            let c3 = if c3.abs() <= 1.0 + 1e-12 {
                c3.clamp(-1.0, 1.0)
            } else {
                c3
            };
            for sign in [1.0, -1.0] {
                let slot = k;
                k += 1;
                if c3.abs() > 1.0 {
                    continue;
                }
                let theta3 = sign * c3.acos();
                let (s3, c3v) = theta3.sin_cos();
                let theta2 = y.atan2(x) - (a3 * s3).atan2(a2 + a3 * c3v);
                let r14 = t14.rotation.to_rotation_matrix();
                let x4 = r14 * Vector3::x();
                let theta4 = x4.y.atan2(x4.x) - theta2 - theta3;
                let q = [theta1, theta2, theta3, theta4, theta5, theta6].map(wrap);
                if reproduces(&q, pose)
                    && let Some(o) = out.get_mut(slot)
                {
                    *o = Some(q);
                }
            }
        }
    }
    out
}

/// Whether `q` [rad] reproduces the flange `pose` within the tolerances.
fn reproduces(q: &Joints, pose: &Isometry3<f64>) -> bool {
    let fk = flange_pose(q);
    let dp = (fk.translation.vector - pose.translation.vector).norm();
    let da = fk.rotation.angle_to(&pose.rotation);
    dp <= POSE_TOLERANCE_M && da <= ORIENTATION_TOLERANCE_RAD
}

/// Shift `angle` [rad] by multiples of 2π to the value within ±[`JOINT_LIMIT_RAD`] closest to
/// `reference` [rad].
pub fn unwrap_near(angle: f64, reference: f64) -> f64 {
    let mut best = angle;
    let mut best_d = f64::INFINITY;
    let base = wrap(angle);
    for k in -2..=2 {
        let c = base + f64::from(k) * TAU;
        if c.abs() > JOINT_LIMIT_RAD {
            continue;
        }
        let d = (c - reference).abs();
        if d < best_d {
            best = c;
            best_d = d;
        }
    }
    best
}

/// The branch nearest `q_current` [rad] that reaches the flange `pose` (position [m]), each
/// joint shifted by multiples of 2π within ±2π towards `q_current`. Distance is the Euclidean
/// norm in joint space. Allocates nothing.
///
/// # Errors
/// [`AdaptError::Unreachable`] if no branch reaches the pose (or it is not finite).
pub fn nearest(q_current: &Joints, pose: &Isometry3<f64>) -> Result<Joints> {
    let hint = q_current[5];
    let mut best: Option<(f64, Joints)> = None;
    for q in branches(pose, hint).into_iter().flatten() {
        let mut shifted = q;
        for (s, &c) in shifted.iter_mut().zip(q_current) {
            *s = unwrap_near(*s, c);
        }
        let d: f64 = shifted
            .iter()
            .zip(q_current)
            .map(|(a, b)| (a - b) * (a - b))
            .sum();
        if best.is_none_or(|(bd, _)| d < bd) {
            best = Some((d, shifted));
        }
    }
    best.map(|(_, q)| q).ok_or_else(|| AdaptError::Unreachable {
        x_m: pose.translation.vector.x,
        y_m: pose.translation.vector.y,
        z_m: pose.translation.vector.z,
    })
}

/// As [`nearest`] for a TCP pose: `tool` is the TCP in the flange frame (see
/// [`robot_io::kinematics::tcp_pose`]).
///
/// # Errors
/// [`AdaptError::Unreachable`] if no branch reaches the pose.
pub fn nearest_tcp(
    q_current: &Joints,
    tcp: &Isometry3<f64>,
    tool: &Isometry3<f64>,
) -> Result<Joints> {
    nearest(q_current, &(tcp * tool.inverse()))
}
