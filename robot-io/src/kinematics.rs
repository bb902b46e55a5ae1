//! UR5e forward kinematics shared by the simulator, the controller and the supervisor.
//!
//! The model is UR's standard Denavit–Hartenberg chain: link `i` (joint `i + 1`) is
//! `T_i = Rz(θ_i)·Tz(d_i)·Tx(a_i)·Rx(α_i)` with the UR5e parameters [`UR5E_DH_D`],
//! [`UR5E_DH_A`] and [`UR5E_DH_ALPHA`] (UR's published values). Frame 0 is the robot base
//! (`base`, as RTDE reports poses), frame `i` is the frame after joint `i`, and frame 6 is the
//! tool flange (`tool0`, no TCP offset). The joint `i + 1` rotates about the z axis of frame
//! `i`.
//!
//! Everything here is allocation-free and panic-free: poses are [`Isometry3`], Jacobians are
//! fixed-size [`nalgebra`] matrices, and bulk outputs go into caller-owned arrays.
//!
//! - [`link_frames`]: all 7 frames (base, after each joint);
//! - [`flange_pose`], [`tcp_pose`]: the flange and a TCP with a configurable tool offset;
//! - [`jacobian`]: the 6×6 geometric Jacobian of the TCP (linear rows first, then angular,
//!   in the base frame);
//! - [`point_jacobian`]: position and 3×6 linear Jacobian of a point fixed in any link;
//! - [`control_points`]: the named points ([`ControlPoint`]) used by separation monitoring;
//! - [`pose_to_vector`] / [`pose_from_vector`]: RTDE's `[x, y, z, rx, ry, rz]` pose format.
//!
//! # Example
//! ```
//! use robot_io::kinematics::{flange_pose, jacobian};
//! use nalgebra::Isometry3;
//! let q = [0.0; 6];
//! let flange = flange_pose(&q);
//! // All joints at zero: x = a2 + a3, y = −(d4 + d6), z = d1 − d5.
//! assert!((flange.translation.vector - nalgebra::Vector3::new(-0.8172, -0.2329, 0.0628)).norm() < 1e-12);
//! let j = jacobian(&q, &Isometry3::identity());
//! assert_eq!(j.nrows(), 6);
//! ```

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{
    Isometry3, Matrix3, Matrix3x6, Matrix6, Point3, Translation3, UnitQuaternion, Vector3,
};

use crate::types::Joints;

/// UR5e standard DH parameter d [m], base to wrist 3.
pub const UR5E_DH_D: Joints = [0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996];
/// UR5e standard DH parameter a [m].
pub const UR5E_DH_A: Joints = [0.0, -0.425, -0.3922, 0.0, 0.0, 0.0];
/// UR5e standard DH parameter alpha [rad].
pub const UR5E_DH_ALPHA: Joints = [FRAC_PI_2, 0.0, 0.0, FRAC_PI_2, -FRAC_PI_2, 0.0];

/// Number of frames [`link_frames`] fills: the base and one after each of the 6 joints.
pub const FRAME_COUNT: usize = 7;

/// A 3×3 rotation matrix, row-major [-] (the plain-array form the simulator uses).
pub type Mat3 = [[f64; 3]; 3];

/// Each link's constant twist `from_axis_angle(x, alpha_i)` (computed once, so it is the same
/// value the expression gives).
static LINK_TWISTS: std::sync::LazyLock<[UnitQuaternion<f64>; 6]> =
    std::sync::LazyLock::new(|| {
        UR5E_DH_ALPHA.map(|alpha| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), alpha))
    });

/// The DH transform of link `i` (0-based) at joint angle `theta` [rad]; identity for `i > 5`.
pub fn dh_link(i: usize, theta: f64) -> Isometry3<f64> {
    let (Some(&d), Some(&a), Some(&alpha)) =
        (UR5E_DH_D.get(i), UR5E_DH_A.get(i), UR5E_DH_ALPHA.get(i))
    else {
        return Isometry3::identity();
    };
    let (st, ct) = theta.sin_cos();
    // The twist about x is constant per link: computed once, by the same expression.
    let twist = LINK_TWISTS
        .get(i)
        .copied()
        .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), alpha));
    let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), theta) * twist;
    Isometry3::from_parts(Translation3::new(a * ct, a * st, d), rotation)
}

/// Forward kinematics of every link frame for joint positions `q` [rad]: `out[0]` is the base
/// (identity), `out[i]` the frame after joint `i`, `out[6]` the flange; poses in the base frame
/// (positions [m]). Allocates nothing.
pub fn link_frames(q: &Joints, out: &mut [Isometry3<f64>; FRAME_COUNT]) {
    let mut t = Isometry3::identity();
    let mut frames = out.iter_mut();
    if let Some(base) = frames.next() {
        *base = t;
    }
    for (i, (frame, &theta)) in frames.zip(q).enumerate() {
        t *= dh_link(i, theta);
        *frame = t;
    }
}

/// The flange (`tool0`) pose in the base frame for joint positions `q` [rad] (position [m]).
pub fn flange_pose(q: &Joints) -> Isometry3<f64> {
    q.iter()
        .enumerate()
        .fold(Isometry3::identity(), |t, (i, &theta)| {
            t * dh_link(i, theta)
        })
}

/// The TCP pose in the base frame for joint positions `q` [rad]: the flange pose times the
/// tool offset `tool` (the TCP in the flange frame, as set in PolyScope's TCP configuration;
/// identity for none).
pub fn tcp_pose(q: &Joints, tool: &Isometry3<f64>) -> Isometry3<f64> {
    flange_pose(q) * tool
}

/// The 6×6 geometric Jacobian of the TCP (`tool` as in [`tcp_pose`]) at `q` [rad], in the
/// base frame: rows 0–2 map joint velocities [rad/s] to the TCP's linear velocity [m/s], rows
/// 3–5 to its angular velocity [rad/s].
pub fn jacobian(q: &Joints, tool: &Isometry3<f64>) -> Matrix6<f64> {
    let mut frames = [Isometry3::identity(); FRAME_COUNT];
    link_frames(q, &mut frames);
    let flange = frames.last().copied().unwrap_or_else(Isometry3::identity);
    let p = (flange * tool).translation.vector;
    let mut j = Matrix6::zeros();
    for (col, frame) in frames.iter().take(6).enumerate() {
        let z = frame.rotation * Vector3::z();
        let lin = z.cross(&(p - frame.translation.vector));
        j.fixed_view_mut::<3, 1>(0, col).copy_from(&lin);
        j.fixed_view_mut::<3, 1>(3, col).copy_from(&z);
    }
    j
}

/// Position [m] (base frame) and 3×6 linear Jacobian [m/rad] of a point fixed in link frame
/// `link` (0 = base … 6 = flange) at `point` [m] in that frame, from the precomputed
/// `frames` of [`link_frames`]. Joints beyond `link` do not move the point (zero columns).
/// A `link` above 6 is treated as 6.
pub fn point_jacobian_from_frames(
    frames: &[Isometry3<f64>; FRAME_COUNT],
    link: usize,
    point: &Vector3<f64>,
) -> (Vector3<f64>, Matrix3x6<f64>) {
    let link = link.min(FRAME_COUNT - 1);
    let frame = frames
        .get(link)
        .copied()
        .unwrap_or_else(Isometry3::identity);
    let p = frame.transform_point(&Point3::from(*point)).coords;
    let mut j = Matrix3x6::zeros();
    for (col, frame) in frames.iter().take(link).enumerate() {
        let z = frame.rotation * Vector3::z();
        let lin = z.cross(&(p - frame.translation.vector));
        j.fixed_view_mut::<3, 1>(0, col).copy_from(&lin);
    }
    (p, j)
}

/// Position [m] (base frame) and 3×6 linear Jacobian [m/rad] of a point fixed in link frame
/// `link` (0 = base … 6 = flange) at `point` [m] in that frame, for joint positions `q` [rad].
pub fn point_jacobian(
    q: &Joints,
    link: usize,
    point: &Vector3<f64>,
) -> (Vector3<f64>, Matrix3x6<f64>) {
    let mut frames = [Isometry3::identity(); FRAME_COUNT];
    link_frames(q, &mut frames);
    point_jacobian_from_frames(&frames, link, point)
}

/// A named point on the arm that separation monitoring keeps away from the human.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ControlPoint {
    /// The TCP: the flange (frame 6) with the tool offset passed to [`control_points`].
    Tcp,
    /// The wrist: the origin of frame 3, the centre of wrist 1 at the far end of the forearm
    /// (the DH line, i.e. on the wrist-1 axis; the real housing extends about ±0.06 m along
    /// that axis).
    Wrist,
    /// The elbow: the origin of frame 2, on the elbow (joint 3) axis at the far end of the
    /// upper arm.
    Elbow,
}

impl ControlPoint {
    /// All control points, in the order [`control_points`] fills them.
    pub const ALL: [ControlPoint; 3] =
        [ControlPoint::Tcp, ControlPoint::Wrist, ControlPoint::Elbow];

    /// The link frame the point is fixed in (0 = base … 6 = flange).
    pub fn link(self) -> usize {
        match self {
            ControlPoint::Tcp => 6,
            ControlPoint::Wrist => 3,
            ControlPoint::Elbow => 2,
        }
    }
}

/// Position and linear Jacobian of one [`ControlPoint`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlPointState {
    /// Which point.
    pub point: ControlPoint,
    /// Position in the base frame [m].
    pub position: Vector3<f64>,
    /// Linear Jacobian in the base frame [m/rad]: `velocity = jacobian · q̇` [m/s].
    pub jacobian: Matrix3x6<f64>,
}

impl ControlPointState {
    /// A zeroed state for `point` (to preallocate the output of [`control_points`]).
    pub fn zeroed(point: ControlPoint) -> Self {
        ControlPointState {
            point,
            position: Vector3::zeros(),
            jacobian: Matrix3x6::zeros(),
        }
    }
}

/// Caller-owned output of [`control_points`], in the order of [`ControlPoint::ALL`].
pub type ControlPoints = [ControlPointState; 3];

/// A zeroed [`ControlPoints`] array, in the order of [`ControlPoint::ALL`].
pub fn control_points_zeroed() -> ControlPoints {
    ControlPoint::ALL.map(ControlPointState::zeroed)
}

/// Fill `out` with the positions [m] and 3×6 linear Jacobians [m/rad] of [`ControlPoint::ALL`]
/// (TCP, wrist, elbow; in that order) at joint positions `q` [rad]; `tool` is the TCP offset
/// in the flange frame. Allocates nothing.
pub fn control_points(q: &Joints, tool: &Isometry3<f64>, out: &mut ControlPoints) {
    let mut frames = [Isometry3::identity(); FRAME_COUNT];
    link_frames(q, &mut frames);
    for (slot, point) in out.iter_mut().zip(ControlPoint::ALL) {
        let offset = match point {
            ControlPoint::Tcp => tool.translation.vector,
            ControlPoint::Wrist | ControlPoint::Elbow => Vector3::zeros(),
        };
        let (position, jacobian) = point_jacobian_from_frames(&frames, point.link(), &offset);
        *slot = ControlPointState {
            point,
            position,
            jacobian,
        };
    }
}

/// A pose as RTDE writes it: `[x, y, z]` [m] and a rotation vector `[rx, ry, rz]` (axis ×
/// angle, angle in [0, π]) [rad].
pub fn pose_to_vector(pose: &Isometry3<f64>) -> [f64; 6] {
    let p = pose.translation.vector;
    let rv = rotation_vector(&to_mat3(&pose.rotation.to_rotation_matrix().into_inner()));
    [p.x, p.y, p.z, rv[0], rv[1], rv[2]]
}

/// The pose of an RTDE `[x, y, z, rx, ry, rz]` vector ([m], rotation vector [rad]).
pub fn pose_from_vector(v: &[f64; 6]) -> Isometry3<f64> {
    let [x, y, z, rx, ry, rz] = *v;
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_scaled_axis(Vector3::new(rx, ry, rz)),
    )
}

/// A nalgebra rotation matrix as a row-major [`Mat3`].
pub fn to_mat3(m: &Matrix3<f64>) -> Mat3 {
    [
        [m.m11, m.m12, m.m13],
        [m.m21, m.m22, m.m23],
        [m.m31, m.m32, m.m33],
    ]
}

/// The rotation vector (axis × angle [rad], angle in [0, π]) of a rotation matrix; robust near
/// 0 and near π.
pub fn rotation_vector(r: &Mat3) -> [f64; 3] {
    let v = [r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]];
    let sin2 = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt(); // 2 sin θ
    let cos2 = r[0][0] + r[1][1] + r[2][2] - 1.0; // 2 cos θ
    let angle = sin2.atan2(cos2);
    if angle < 1e-12 {
        // First order: R ≈ I + [ω]×.
        return [v[0] / 2.0, v[1] / 2.0, v[2] / 2.0];
    }
    if angle < PI - 1e-4 {
        let k = angle / sin2;
        return [v[0] * k, v[1] * k, v[2] * k];
    }
    // Near π: the axis from the symmetric part, R + I ≈ 2 n nᵀ; pick the largest diagonal.
    let d = [r[0][0], r[1][1], r[2][2]];
    let mut axis = if d[0] >= d[1] && d[0] >= d[2] {
        let x = ((d[0] + 1.0) / 2.0).max(0.0).sqrt();
        [
            x,
            (r[0][1] + r[1][0]) / (4.0 * x),
            (r[0][2] + r[2][0]) / (4.0 * x),
        ]
    } else if d[1] >= d[2] {
        let y = ((d[1] + 1.0) / 2.0).max(0.0).sqrt();
        [
            (r[0][1] + r[1][0]) / (4.0 * y),
            y,
            (r[1][2] + r[2][1]) / (4.0 * y),
        ]
    } else {
        let z = ((d[2] + 1.0) / 2.0).max(0.0).sqrt();
        [
            (r[0][2] + r[2][0]) / (4.0 * z),
            (r[1][2] + r[2][1]) / (4.0 * z),
            z,
        ]
    };
    let norm = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    // Orient the axis with the (small but signed) antisymmetric part.
    let sign = if axis[0] * v[0] + axis[1] * v[1] + axis[2] * v[2] < 0.0 {
        -1.0
    } else {
        1.0
    };
    for a in &mut axis {
        *a *= sign * angle / norm;
    }
    axis
}

/// The flange pose for `q` [rad] as a row-major rotation matrix and a position [m] in the base
/// frame (the simulator's plain-array form of [`flange_pose`]).
pub fn ur5e_tcp_transform(q: &Joints) -> (Mat3, [f64; 3]) {
    let t = flange_pose(q);
    let p = t.translation.vector;
    (
        to_mat3(&t.rotation.to_rotation_matrix().into_inner()),
        [p.x, p.y, p.z],
    )
}

/// UR5e flange pose for joint positions `q` [rad]: position [m] and rotation vector [rad] in
/// the base frame, as in RTDE's `actual_TCP_pose` with no TCP offset configured.
pub fn ur5e_tcp_pose(q: &Joints) -> [f64; 6] {
    pose_to_vector(&flange_pose(q))
}
