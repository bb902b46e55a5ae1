//! The protective separation distance of ISO/TS 15066 (speed and separation monitoring).
//!
//! The formula and its parameters live in `robot_io::separation`, shared with the planner
//! (the two share formulas, never code paths); this module re-exports them and gives the
//! supervisor's view of the robot's motion ([`RobotMotion`]).
//!
//! ```text
//! S_p = v_h (T_age + T_r + T_s) + v_r T_r + v_r T_s / 2 + C + Z_d + Z_r
//! ```
//! measured from each tracked body part's surface to the surface of the arm's capsules
//! (`robot_io::geometry`). See [`SeparationParams::handover_default`] for the values.

pub use robot_io::geometry::BodyPart;
pub use robot_io::separation::SeparationParams;

/// The robot's motion as the separation formula needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotMotion {
    /// v_r: robot speed [m/s], ≥ 0.
    pub speed_m_s: f64,
    /// T_s: time the robot needs to stand still after the stop command takes effect [s], ≥ 0.
    pub stopping_time_s: f64,
}

impl RobotMotion {
    /// Standing still.
    pub const REST: RobotMotion = RobotMotion {
        speed_m_s: 0.0,
        stopping_time_s: 0.0,
    };
}

/// S_p [m] for body part `part` whose position is `perception_age_s` [s] old, with the robot
/// moving as `motion`: `robot_io::separation::protective_distance_m`. Negative inputs count
/// as 0; NaN propagates (and fails the supervisor's `distance >= S_p` comparison, so it
/// stops).
pub fn protective_distance_m(
    params: &SeparationParams,
    part: BodyPart,
    motion: RobotMotion,
    perception_age_s: f64,
) -> f64 {
    robot_io::separation::protective_distance_m(
        params,
        part,
        motion.speed_m_s,
        motion.stopping_time_s,
        perception_age_s,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrapper_is_the_shared_formula() {
        // By hand with the defaults: a hand, v_r = 0.25 m/s, T_s = 0.2 s, T_age = 0.05 s:
        // 2.0·(0.05 + 0.1 + 0.2) + 0.25·0.1 + 0.25·0.2/2 + 0.1 + 0.05 + 0.02 = 0.92.
        let p = SeparationParams::handover_default();
        let m = RobotMotion {
            speed_m_s: 0.25,
            stopping_time_s: 0.2,
        };
        let s = protective_distance_m(&p, BodyPart::LeftHand, m, 0.05);
        assert!((s - 0.92).abs() < 1e-12, "{s}");
        // The torso walks (1.6 m/s): 1.6·0.35 + 0.05 + 0.17 = 0.78.
        let s = protective_distance_m(&p, BodyPart::Torso, m, 0.05);
        assert!((s - 0.78).abs() < 1e-12, "{s}");
        let s = protective_distance_m(&p, BodyPart::Head, RobotMotion::REST, 0.0);
        assert!((s - 0.33).abs() < 1e-12, "{s}");
    }
}
