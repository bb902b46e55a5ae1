//! The points on the arm the workspace box (SAF-REQ-006) and the TCP speed (SAF-REQ-005)
//! use: the TCP, the wrist and the elbow, from UR5e forward kinematics. Separation
//! (SAF-REQ-007) uses the capsules of `robot_io::geometry` instead.
//!
//! Frame naming follows `robot_io`'s kinematics: frame `i` is the frame after joint `i` of
//! UR's standard DH chain. The **elbow** is the origin of frame 2 (on the elbow axis, far end
//! of the upper arm), the **wrist** the origin of frame 3 (wrist 1, far end of the forearm),
//! and the **TCP** the flange, frame 6 (no tool offset, as RTDE's `actual_TCP_pose` with no
//! TCP configured). The points lie on the DH lines; link radius and tool size are covered by
//! the workspace box's margins.
//!
//! Forward kinematics is `robot_io::kinematics` (UR's published UR5e DH parameters), the
//! same model `SimRobot` and `adapt` use.

use nalgebra::Isometry3;
use robot_io::Joints;
use robot_io::kinematics::{ControlPoint, FRAME_COUNT, link_frames};

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

/// A point of NaNs, for a frame that is missing (never, for a 7-frame chain); every check
/// treats it as a violation.
const MISSING: [f64; 3] = [f64::NAN; 3];

fn origin(frames: &[Isometry3<f64>; FRAME_COUNT], frame: usize) -> [f64; 3] {
    match frames.get(frame) {
        Some(t) => {
            let v = t.translation.vector;
            [v.x, v.y, v.z]
        }
        None => MISSING,
    }
}

/// Positions of the TCP, wrist and elbow [m] for joint positions `q` [rad], from
/// `robot_io::kinematics::link_frames`. Allocates nothing; non-finite `q` gives non-finite
/// points (which every check treats as a violation).
pub fn arm_points(q: &Joints) -> ArmPoints {
    let mut frames = [Isometry3::identity(); FRAME_COUNT];
    link_frames(q, &mut frames);
    ArmPoints {
        tcp: origin(&frames, ControlPoint::Tcp.link()),
        wrist: origin(&frames, ControlPoint::Wrist.link()),
        elbow: origin(&frames, ControlPoint::Elbow.link()),
    }
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
    use robot_io::kinematics::ur5e_tcp_pose;

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
