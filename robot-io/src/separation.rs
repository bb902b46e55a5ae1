//! The protective separation distance of ISO/TS 15066 (speed and separation monitoring), the
//! one formula the planner (`adapt`) and the safety supervisor (`safety`) share.
//!
//! ```text
//! S_p = S_h + S_r + S_s + C + Z_d + Z_r
//! S_h = v_h · (T_age + T_r + T_s)     the human keeps moving until the robot stands still
//! S_r = v_r · T_r                     the robot keeps moving until the stop takes effect
//! S_s = v_r · T_s / 2                 the robot's stopping distance at constant deceleration
//! ```
//! - v_h [m/s]: 1.6 for the head and the torso (walking), 2.0 for the hands (arm reach), as in
//!   ISO 13855;
//! - v_r [m/s]: the robot's speed (the supervisor uses the full TCP speed, not only its
//!   component towards the human, which is conservative);
//! - T_r [s]: reaction time from a change of the human's position to the stop command;
//! - T_age [s]: age of the perceived human position (it is that old, so the human may already
//!   be v_h·T_age closer); added to T_r for the human term only;
//! - T_s [s]: the robot's stopping time;
//! - C, Z_d, Z_r [m]: intrusion distance, human position uncertainty, robot position
//!   uncertainty.
//!
//! S_p is measured from the surface of the body part to the surface of the arm's capsules
//! (`robot_io::geometry`): the link radii are in the geometry, not in Z_r.
//!
//! # Example
//! ```
//! use robot_io::geometry::BodyPart;
//! use robot_io::separation::{SeparationParams, protective_distance_m};
//! let p = SeparationParams::handover_default();
//! // A hand, robot at rest, fresh perception: v_h·T_r + C + Z_d + Z_r = 0.2 + 0.17 m.
//! let s = protective_distance_m(&p, BodyPart::LeftHand, 0.0, 0.0, 0.0);
//! assert!((s - 0.37).abs() < 1e-12);
//! ```

use crate::error::{Result, RobotIoError, finite_bound};
use crate::geometry::BodyPart;

fn invalid<T>(field: &'static str, reason: &'static str) -> Result<T> {
    Err(RobotIoError::InvalidSeparation { field, reason })
}

fn finite_positive(field: &'static str, value: f64) -> Result<f64> {
    finite_bound(value, true).or_else(|reason| invalid(field, reason))
}

fn finite_non_negative(field: &'static str, value: f64) -> Result<f64> {
    finite_bound(value, false).or_else(|reason| invalid(field, reason))
}

/// Validated ISO/TS 15066 parameters: v_h for the head and torso (walking) [m/s], v_h for the
/// hands (arm reach) [m/s], T_r [s], C [m], Z_d [m], Z_r [m].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeparationParams {
    head_speed_m_s: f64,
    hand_speed_m_s: f64,
    reaction_time_s: f64,
    intrusion_m: f64,
    human_uncertainty_m: f64,
    robot_uncertainty_m: f64,
}

impl SeparationParams {
    /// - `head_speed_m_s` v_h for the head and the torso [m/s] (> 0);
    /// - `hand_speed_m_s` v_h for the hands [m/s] (> 0);
    /// - `reaction_time_s` T_r, from a change of the human's position to the stop command [s]
    ///   (≥ 0; the perception age of each cycle is added to it);
    /// - `intrusion_m` C [m], `human_uncertainty_m` Z_d [m], `robot_uncertainty_m` Z_r [m]
    ///   (all ≥ 0).
    ///
    /// # Errors
    /// [`RobotIoError::InvalidSeparation`] naming the first invalid value.
    pub fn new(
        head_speed_m_s: f64,
        hand_speed_m_s: f64,
        reaction_time_s: f64,
        intrusion_m: f64,
        human_uncertainty_m: f64,
        robot_uncertainty_m: f64,
    ) -> Result<Self> {
        Ok(Self {
            head_speed_m_s: finite_positive("separation.head_speed_m_s", head_speed_m_s)?,
            hand_speed_m_s: finite_positive("separation.hand_speed_m_s", hand_speed_m_s)?,
            reaction_time_s: finite_non_negative("separation.reaction_time_s", reaction_time_s)?,
            intrusion_m: finite_non_negative("separation.intrusion_m", intrusion_m)?,
            human_uncertainty_m: finite_non_negative(
                "separation.human_uncertainty_m",
                human_uncertainty_m,
            )?,
            robot_uncertainty_m: finite_non_negative(
                "separation.robot_uncertainty_m",
                robot_uncertainty_m,
            )?,
        })
    }

    /// Defaults for the handover cell:
    /// - v_h = 1.6 m/s for the head and torso (walking) and 2.0 m/s for the hands (arm
    ///   reach), as in ISO 13855;
    /// - T_r = 0.1 s: one 2 ms control cycle, the RTDE round trip and a margin for the pose
    ///   pipeline's processing; the camera frame's age is added per cycle;
    /// - C = 0.10 m: the fingers beyond the tracked hand keypoint;
    /// - Z_d = 0.05 m: keypoint depth uncertainty of the camera;
    /// - Z_r = 0.02 m: the arm's position uncertainty. The link, gripper and part sizes are
    ///   modelled as capsules (with 15 mm over MuJoCo Menagerie's UR5e collision radii), so
    ///   Z_r no longer stands in for them. What is left:
    ///   - servo lag, 12.5 mm: while a servoJ stream runs the arm trails the commanded target
    ///     by about v·lookahead, 0.25 m/s × 0.05 s at the collaborative speed cap. The
    ///     supervisor checks the measured pose and the stopping configuration computed from
    ///     the commanded target, which bracket the arm, and takes the larger of the measured
    ///     and commanded speeds for v_r; Z_r covers the tracking error that is neither (the
    ///     arm catching up on the lag between a sample and the stop taking effect);
    ///   - the nominal DH model against the robot's factory-calibrated kinematics, and link
    ///     deflection under a 5 kg payload: a few mm at the flange (UR's repeatability is
    ///     ±0.03 mm, but its calibration corrections to the nominal DH are millimetres);
    ///   - rounding up: 0.02 m.
    pub fn handover_default() -> Self {
        Self {
            head_speed_m_s: 1.6,
            hand_speed_m_s: 2.0,
            reaction_time_s: 0.1,
            intrusion_m: 0.10,
            human_uncertainty_m: 0.05,
            robot_uncertainty_m: 0.02,
        }
    }

    /// v_h for the head and the torso (walking) [m/s].
    pub fn head_speed_m_s(&self) -> f64 {
        self.head_speed_m_s
    }

    /// v_h for the hands (arm reach) [m/s].
    pub fn hand_speed_m_s(&self) -> f64 {
        self.hand_speed_m_s
    }

    /// v_h for `part` [m/s]: arm reach for the hands, walking for the head and the torso.
    pub fn human_speed_m_s(&self, part: BodyPart) -> f64 {
        if part.is_hand() {
            self.hand_speed_m_s
        } else {
            self.head_speed_m_s
        }
    }

    /// T_r [s].
    pub fn reaction_time_s(&self) -> f64 {
        self.reaction_time_s
    }

    /// C [m].
    pub fn intrusion_m(&self) -> f64 {
        self.intrusion_m
    }

    /// Z_d [m].
    pub fn human_uncertainty_m(&self) -> f64 {
        self.human_uncertainty_m
    }

    /// Z_r [m].
    pub fn robot_uncertainty_m(&self) -> f64 {
        self.robot_uncertainty_m
    }
}

impl Default for SeparationParams {
    /// [`SeparationParams::handover_default`].
    fn default() -> Self {
        Self::handover_default()
    }
}

/// `x` clamped at 0 from below; NaN stays NaN (unlike `f64::max`, which drops it).
fn at_least_zero(x: f64) -> f64 {
    if x < 0.0 { 0.0 } else { x }
}

/// S_p [m] = v_h (T_age + T_r + T_s) + v_r T_r + v_r T_s / 2 + C + Z_d + Z_r for body part
/// `part` whose position is `perception_age_s` [s] old, with the robot moving at
/// `robot_speed_m_s` v_r [m/s] and needing `stopping_time_s` T_s [s] to stand still. Negative
/// speeds and times count as 0; NaN propagates (and fails every `distance >= S_p` check).
pub fn protective_distance_m(
    p: &SeparationParams,
    part: BodyPart,
    robot_speed_m_s: f64,
    stopping_time_s: f64,
    perception_age_s: f64,
) -> f64 {
    let v_h = p.human_speed_m_s(part);
    let v_r = at_least_zero(robot_speed_m_s);
    let t_s = at_least_zero(stopping_time_s);
    let t_age = at_least_zero(perception_age_s);
    let t_r = p.reaction_time_s;
    let s_h = v_h * (t_age + t_r + t_s);
    let s_r = v_r * t_r;
    let s_s = v_r * t_s / 2.0;
    s_h + s_r + s_s + p.intrusion_m + p.human_uncertainty_m + p.robot_uncertainty_m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn worked_example_terms_add_up() {
        // Computed by hand: v_h = 2.0 (hand), T_age = 0.05, T_r = 0.1, T_s = 0.2, v_r = 0.25:
        // S_h = 2.0·0.35 = 0.7; S_r = 0.025; S_s = 0.25·0.2/2 = 0.025; C + Z_d + Z_r = 0.21.
        let p = SeparationParams::new(1.6, 2.0, 0.1, 0.1, 0.05, 0.06).unwrap();
        let s = protective_distance_m(&p, BodyPart::LeftHand, 0.25, 0.2, 0.05);
        assert!((s - 0.96).abs() < 1e-12, "{s}");
        // The head and the torso walk: S_h = 1.6·0.35 = 0.56.
        for part in [BodyPart::Head, BodyPart::Torso] {
            let s = protective_distance_m(&p, part, 0.25, 0.2, 0.05);
            assert!((s - 0.82).abs() < 1e-12, "{part}: {s}");
        }
        // At rest with fresh perception only v_h·T_r and the constant terms remain.
        let s = protective_distance_m(&p, BodyPart::RightHand, 0.0, 0.0, 0.0);
        assert!((s - 0.41).abs() < 1e-12, "{s}");
        // Negative inputs count as 0; NaN propagates.
        let s = protective_distance_m(&p, BodyPart::RightHand, -1.0, -1.0, -1.0);
        assert!((s - 0.41).abs() < 1e-12, "{s}");
        assert!(protective_distance_m(&p, BodyPart::Head, f64::NAN, 0.0, 0.0).is_nan());
        assert!(protective_distance_m(&p, BodyPart::Head, 0.0, 0.0, f64::NAN).is_nan());
    }

    #[test]
    fn parameters_are_validated() {
        assert!(SeparationParams::new(1.6, 2.0, -0.1, 0.0, 0.0, 0.0).is_err());
        assert!(SeparationParams::new(0.0, 2.0, 0.1, 0.0, 0.0, 0.0).is_err());
        assert!(SeparationParams::new(1.6, f64::NAN, 0.1, 0.0, 0.0, 0.0).is_err());
        assert!(SeparationParams::new(1.6, 2.0, 0.1, 0.0, 0.0, f64::INFINITY).is_err());
        let e = SeparationParams::new(1.6, 2.0, 0.1, -1.0, 0.0, 0.0)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "invalid separation setting `separation.intrusion_m`: must be finite and >= 0"
        );
        let d = SeparationParams::handover_default();
        assert_eq!(
            SeparationParams::new(1.6, 2.0, 0.1, 0.1, 0.05, 0.02).unwrap(),
            d
        );
    }
}
