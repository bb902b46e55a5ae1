//! The points on the arm the supervisor watches: the TCP, the wrist and the elbow, from UR5e
//! forward kinematics.
//!
//! Frame naming follows `robot_io`'s kinematics: frame `i` is the frame after joint `i` of
//! UR's standard DH chain. The **elbow** is the origin of frame 2 (on the elbow axis, far end
//! of the upper arm), the **wrist** the origin of frame 3 (wrist 1, far end of the forearm),
//! and the **TCP** the flange, frame 6 (no tool offset, as RTDE's `actual_TCP_pose` with no
//! TCP configured). The points lie on the DH lines; link radius and tool size are covered by
//! the separation's Z_r term and the workspace box's margins.
//!
//! The DH parameters come from `robot_io::sim` (UR's published UR5e values).

use robot_io::Joints;
use robot_io::sim::{UR5E_DH_A, UR5E_DH_ALPHA, UR5E_DH_D};

/// A watched point on the arm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ArmPoint {
    /// The TCP (flange, frame 6).
    Tcp,
    /// The wrist (origin of frame 3, wrist 1).
    Wrist,
    /// The elbow (origin of frame 2, on the elbow axis).
    Elbow,
}

impl ArmPoint {
    /// All watched points, in the order of [`ArmPoints::as_array`].
    pub const ALL: [ArmPoint; 3] = [ArmPoint::Tcp, ArmPoint::Wrist, ArmPoint::Elbow];
}

/// Positions of the watched points in the robot base frame [m].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmPoints {
    /// TCP position [m].
    pub tcp: [f64; 3],
    /// Wrist position [m].
    pub wrist: [f64; 3],
    /// Elbow position [m].
    pub elbow: [f64; 3],
}

impl ArmPoints {
    /// The points with their names, in the order of [`ArmPoint::ALL`].
    pub fn as_array(&self) -> [(ArmPoint, [f64; 3]); 3] {
        [
            (ArmPoint::Tcp, self.tcp),
            (ArmPoint::Wrist, self.wrist),
            (ArmPoint::Elbow, self.elbow),
        ]
    }
}

type Mat3 = [[f64; 3]; 3];

const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let [[a00, a01, a02], [a10, a11, a12], [a20, a21, a22]] = *a;
    let [[b00, b01, b02], [b10, b11, b12], [b20, b21, b22]] = *b;
    [
        [
            a00 * b00 + a01 * b10 + a02 * b20,
            a00 * b01 + a01 * b11 + a02 * b21,
            a00 * b02 + a01 * b12 + a02 * b22,
        ],
        [
            a10 * b00 + a11 * b10 + a12 * b20,
            a10 * b01 + a11 * b11 + a12 * b21,
            a10 * b02 + a11 * b12 + a12 * b22,
        ],
        [
            a20 * b00 + a21 * b10 + a22 * b20,
            a20 * b01 + a21 * b11 + a22 * b21,
            a20 * b02 + a21 * b12 + a22 * b22,
        ],
    ]
}

fn mat_vec(a: &Mat3, v: &[f64; 3]) -> [f64; 3] {
    let [[a00, a01, a02], [a10, a11, a12], [a20, a21, a22]] = *a;
    let [x, y, z] = *v;
    [
        a00 * x + a01 * y + a02 * z,
        a10 * x + a11 * y + a12 * z,
        a20 * x + a21 * y + a22 * z,
    ]
}

/// Positions of the TCP, wrist and elbow [m] for joint positions `q` [rad]. Allocates
/// nothing; non-finite `q` gives non-finite points (which every check treats as a violation).
pub fn arm_points(q: &Joints) -> ArmPoints {
    let mut rot = IDENTITY;
    let mut pos = [0.0; 3];
    let mut origins = [[0.0; 3]; 6];
    let links = q
        .iter()
        .zip(&UR5E_DH_D)
        .zip(UR5E_DH_A.iter().zip(&UR5E_DH_ALPHA));
    for (origin, ((&theta, &d), (&a, &alpha))) in origins.iter_mut().zip(links) {
        let (st, ct) = theta.sin_cos();
        let (sa, ca) = alpha.sin_cos();
        let link: Mat3 = [
            [ct, -st * ca, st * sa],
            [st, ct * ca, -ct * sa],
            [0.0, sa, ca],
        ];
        let [ox, oy, oz] = mat_vec(&rot, &[a * ct, a * st, d]);
        let [px, py, pz] = pos;
        pos = [px + ox, py + oy, pz + oz];
        rot = mat_mul(&rot, &link);
        *origin = pos;
    }
    // origins[i] is the origin of frame i + 1.
    let [_, elbow, wrist, _, _, tcp] = origins;
    ArmPoints { tcp, wrist, elbow }
}

/// Euclidean distance between two points [m].
pub fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let [ax, ay, az] = *a;
    let [bx, by, bz] = *b;
    ((ax - bx).powi(2) + (ay - by).powi(2) + (az - bz).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use robot_io::sim::ur5e_tcp_pose;

    #[test]
    fn tcp_matches_robot_io_forward_kinematics() {
        let qs = [
            [0.0; 6],
            [0.0, -1.2, 0.1, -1.4, 0.0, 0.0],
            [0.3, -1.2, 0.9, -1.1, -1.6, 0.4],
            [-2.0, -0.5, 2.1, 0.3, 1.0, -3.0],
        ];
        for q in qs {
            let p = arm_points(&q);
            let reference = ur5e_tcp_pose(&q);
            for (a, b) in p.tcp.iter().zip(&reference) {
                assert!((a - b).abs() < 1e-12, "{q:?}: {p:?} vs {reference:?}");
            }
        }
    }

    #[test]
    fn elbow_and_wrist_at_zero_follow_the_dh_lines() {
        // All joints zero: the upper arm lies along −x at height d1.
        let p = arm_points(&[0.0; 6]);
        let expect_elbow = [-0.425, 0.0, 0.1625];
        let expect_wrist = [-0.8172, 0.0, 0.1625];
        for (a, b) in p.elbow.iter().zip(&expect_elbow) {
            assert!((a - b).abs() < 1e-12, "{p:?}");
        }
        for (a, b) in p.wrist.iter().zip(&expect_wrist) {
            assert!((a - b).abs() < 1e-12, "{p:?}");
        }
    }
}
