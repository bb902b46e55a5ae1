//! The protective separation distance of ISO/TS 15066 (speed and separation monitoring).
//!
//! ```text
//! S_p = S_h + S_r + S_s + C + Z_d + Z_r
//! S_h = v_h · (T_age + T_r + T_s)     the human keeps moving until the robot stands still
//! S_r = v_r · T_r                     the robot keeps moving until the stop takes effect
//! S_s = v_r · T_s / 2                 the robot's stopping distance at constant deceleration
//! ```
//! - v_h [m/s]: 1.6 for the head (walking), 2.0 for the hands (arm reach), as in ISO 13855;
//! - v_r [m/s]: the robot's speed; the supervisor uses the full TCP speed (not only its
//!   component towards the human), which is conservative;
//! - T_r [s]: reaction time from a change of the human's position to the stop command;
//! - T_age [s]: age of the perceived human position (it is that old, so the human may already
//!   be v_h·T_age closer); added to T_r for the human term only;
//! - T_s [s]: the robot's stopping time;
//! - C, Z_d, Z_r [m]: intrusion distance, human position uncertainty, robot position
//!   uncertainty.
//!
//! This is the check's own small formula, independent of the planner in `adapt`.

use crate::config::SeparationParams;

/// The tracked human points of [`crate::WorldView::human_points`], in that order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum HumanPoint {
    /// The head (v_h for walking).
    Head,
    /// The left hand (v_h for arm reach).
    LeftHand,
    /// The right hand (v_h for arm reach).
    RightHand,
}

impl HumanPoint {
    /// All human points, in the order of [`crate::WorldView::human_points`].
    pub const ALL: [HumanPoint; 3] = [
        HumanPoint::Head,
        HumanPoint::LeftHand,
        HumanPoint::RightHand,
    ];

    /// v_h for this point [m/s].
    pub fn speed_m_s(self, params: &SeparationParams) -> f64 {
        match self {
            HumanPoint::Head => params.head_speed_m_s(),
            HumanPoint::LeftHand | HumanPoint::RightHand => params.hand_speed_m_s(),
        }
    }
}

/// The robot's motion as the separation formula needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotMotion {
    /// v_r: robot speed [m/s], ≥ 0.
    pub speed_m_s: f64,
    /// T_s: time the robot needs to stand still after the stop command takes effect [s], ≥ 0.
    pub stopping_time_s: f64,
}

/// S_p [m] for human point `human` whose position is `perception_age_s` [s] old, with the
/// robot moving as `motion`. Negative inputs are clamped to 0; NaN propagates (and fails the
/// supervisor's `distance >= S_p` comparison, so it stops).
pub fn protective_distance_m(
    params: &SeparationParams,
    human: HumanPoint,
    motion: RobotMotion,
    perception_age_s: f64,
) -> f64 {
    let v_h = human.speed_m_s(params);
    let v_r = motion.speed_m_s.max(0.0);
    let t_s = motion.stopping_time_s.max(0.0);
    let t_r = params.reaction_time_s();
    let t_age = perception_age_s.max(0.0);
    let s_h = v_h * (t_age + t_r + t_s);
    let s_r = v_r * t_r;
    let s_s = v_r * t_s / 2.0;
    s_h + s_r
        + s_s
        + params.intrusion_m()
        + params.human_uncertainty_m()
        + params.robot_uncertainty_m()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formula_terms_add_up() {
        let p = SeparationParams::new(1.6, 2.0, 0.1, 0.1, 0.05, 0.06).unwrap();
        let m = RobotMotion {
            speed_m_s: 0.25,
            stopping_time_s: 0.2,
        };
        // S_h = 2.0·(0.05 + 0.1 + 0.2) = 0.7; S_r = 0.025; S_s = 0.025; C + Z = 0.21.
        let s = protective_distance_m(&p, HumanPoint::LeftHand, m, 0.05);
        assert!((s - 0.96).abs() < 1e-12, "{s}");
        // The head walks slower: S_h = 1.6·0.35 = 0.56.
        let s = protective_distance_m(&p, HumanPoint::Head, m, 0.05);
        assert!((s - 0.82).abs() < 1e-12, "{s}");
        // At rest with fresh perception only v_h·T_r and the constant terms remain.
        let rest = RobotMotion {
            speed_m_s: 0.0,
            stopping_time_s: 0.0,
        };
        let s = protective_distance_m(&p, HumanPoint::RightHand, rest, 0.0);
        assert!((s - 0.41).abs() < 1e-12, "{s}");
    }
}
