//! Validated limits and the supervisor's configuration.
//!
//! Every limit is a newtype whose constructor rejects values that would make a check
//! meaningless (non-finite numbers, empty ranges, non-positive speeds). Once built, a value is
//! valid for the rest of its life: fields are private and there are no setters.

use std::f64::consts::{PI, TAU};

use robot_io::Joints;
use robot_io::geometry::{ArmModel, BodyModel};
pub use robot_io::separation::SeparationParams;

use crate::error::{Result, SafetyError};

fn invalid<T>(field: &'static str, reason: &'static str) -> Result<T> {
    Err(SafetyError::InvalidConfig { field, reason })
}

fn finite_positive(field: &'static str, value: f64) -> Result<f64> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        invalid(field, "must be finite and > 0")
    }
}

fn finite_non_negative(field: &'static str, value: f64) -> Result<f64> {
    if value.is_finite() && value >= 0.0 {
        Ok(value)
    } else {
        invalid(field, "must be finite and >= 0")
    }
}

/// Joint position limits with a safety margin [rad].
///
/// A joint position `q` is allowed when `lower + margin <= q <= upper - margin`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    lower_rad: Joints,
    upper_rad: Joints,
    margin_rad: f64,
}

impl JointLimits {
    /// Limits `lower_rad[j] < upper_rad[j]` [rad] and a margin `margin_rad` [rad] kept inside
    /// them. Rejects non-finite values, `lower >= upper`, a negative margin and a margin that
    /// leaves no allowed range.
    pub fn new(lower_rad: Joints, upper_rad: Joints, margin_rad: f64) -> Result<Self> {
        let margin_rad = finite_non_negative("joint_limits.margin_rad", margin_rad)?;
        for (&lo, &hi) in lower_rad.iter().zip(&upper_rad) {
            if !(lo.is_finite() && hi.is_finite()) {
                return invalid("joint_limits", "limits must be finite");
            }
            if lo >= hi {
                return invalid("joint_limits", "lower must be < upper");
            }
            if lo + margin_rad >= hi - margin_rad {
                return invalid("joint_limits.margin_rad", "leaves no allowed range");
            }
        }
        Ok(Self {
            lower_rad,
            upper_rad,
            margin_rad,
        })
    }

    /// UR5e: ±2π rad on every joint, margin 0.05 rad (about 3°).
    pub fn ur5e() -> Self {
        Self {
            lower_rad: [-TAU; 6],
            upper_rad: [TAU; 6],
            margin_rad: 0.05,
        }
    }

    /// The allowed interval of joint `joint` (0-based) [rad], margin applied; `None` for
    /// `joint > 5`.
    pub fn allowed(&self, joint: usize) -> Option<(f64, f64)> {
        let lo = self.lower_rad.get(joint)?;
        let hi = self.upper_rad.get(joint)?;
        Some((lo + self.margin_rad, hi - self.margin_rad))
    }

    /// The margin [rad].
    pub fn margin_rad(&self) -> f64 {
        self.margin_rad
    }

    /// The first joint of `q` [rad] outside its allowed interval: `(joint, value_rad,
    /// violated_limit_rad)`. NaN counts as outside.
    pub fn first_violation(&self, q: &Joints) -> Option<(usize, f64, f64)> {
        for (j, (&value, (&lo, &hi))) in q
            .iter()
            .zip(self.lower_rad.iter().zip(&self.upper_rad))
            .enumerate()
        {
            let (min, max) = (lo + self.margin_rad, hi - self.margin_rad);
            if value.is_nan() || value < min {
                return Some((j, value, min));
            }
            if value > max {
                return Some((j, value, max));
            }
        }
        None
    }
}

/// Joint speed [rad/s] and acceleration [rad/s²] limits, the same for every joint, and the
/// deceleration the supervisor's own stops use [rad/s²].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointRateLimits {
    max_speed_rad_s: f64,
    max_acc_rad_s2: f64,
    stop_decel_rad_s2: f64,
}

impl JointRateLimits {
    /// All three must be finite and > 0.
    pub fn new(max_speed_rad_s: f64, max_acc_rad_s2: f64, stop_decel_rad_s2: f64) -> Result<Self> {
        Ok(Self {
            max_speed_rad_s: finite_positive("joint_rates.max_speed_rad_s", max_speed_rad_s)?,
            max_acc_rad_s2: finite_positive("joint_rates.max_acc_rad_s2", max_acc_rad_s2)?,
            stop_decel_rad_s2: finite_positive("joint_rates.stop_decel_rad_s2", stop_decel_rad_s2)?,
        })
    }

    /// UR5e: π rad/s, π rad/s² (the issue's nominal limit; UR publishes none), stops at
    /// π rad/s².
    pub fn ur5e() -> Self {
        Self {
            max_speed_rad_s: PI,
            max_acc_rad_s2: PI,
            stop_decel_rad_s2: PI,
        }
    }

    /// Largest joint speed [rad/s].
    pub fn max_speed_rad_s(&self) -> f64 {
        self.max_speed_rad_s
    }

    /// Largest joint acceleration [rad/s²].
    pub fn max_acc_rad_s2(&self) -> f64 {
        self.max_acc_rad_s2
    }

    /// Deceleration of the supervisor's stops, leading joint [rad/s²].
    pub fn stop_decel_rad_s2(&self) -> f64 {
        self.stop_decel_rad_s2
    }
}

/// A TCP speed limit [m/s], finite and > 0.
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd)]
pub struct SpeedLimit(f64);

impl SpeedLimit {
    /// A limit of `m_s` [m/s]; must be finite and > 0.
    pub fn new(m_s: f64) -> Result<Self> {
        Ok(Self(finite_positive("speed_limit_m_s", m_s)?))
    }

    /// The limit [m/s].
    pub fn m_s(&self) -> f64 {
        self.0
    }
}

/// A speed scale factor [-] with 0 < x ≤ 1.
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd)]
pub struct SpeedScale(f64);

impl SpeedScale {
    /// Full speed.
    pub const ONE: SpeedScale = SpeedScale(1.0);

    /// A scale `x` [-]; must satisfy 0 < x ≤ 1 (NaN is rejected).
    pub fn new(x: f64) -> Result<Self> {
        if x > 0.0 && x <= 1.0 {
            Ok(Self(x))
        } else {
            invalid("speed_scale", "must satisfy 0 < x <= 1")
        }
    }

    /// The factor [-].
    pub fn get(&self) -> f64 {
        self.0
    }
}

/// The control period [s], from a rate of at most 500 Hz (the UR5e's RTDE rate).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CyclePeriod(f64);

impl CyclePeriod {
    /// The period of a rate `hz` [Hz] with 0 < hz ≤ 500.
    pub fn from_hz(hz: f64) -> Result<Self> {
        if hz.is_finite() && hz > 0.0 && hz <= 500.0 {
            Ok(Self(1.0 / hz))
        } else {
            invalid("cycle_hz", "must satisfy 0 < f <= 500")
        }
    }

    /// The UR5e's 2 ms (500 Hz).
    pub fn ur5e() -> Self {
        Self(0.002)
    }

    /// The period [s].
    pub fn seconds(&self) -> f64 {
        self.0
    }
}

/// The longest controller time a servo step stands for, in control cycles [-], 1..=64: after
/// missed cycles the planner advances its plan by at most this many cycles and the supervisor
/// judges the step over at most this long. It should be the robot's servo extrapolation bound in
/// cycles + 1: until the bound the robot follows the previous target's extrapolation, so a plan
/// that advances as far stays continuous with it; past the bound the robot holds, and a plan
/// advanced further would make the next target a jump (which a longer judging period would
/// pass as slow).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct CatchUpCycles(u32);

impl CatchUpCycles {
    /// The largest value accepted [cycles].
    pub const MAX: u32 = 64;

    /// `cycles` [cycles], in 1..=[`Self::MAX`].
    pub fn new(cycles: u32) -> Result<Self> {
        if (1..=Self::MAX).contains(&cycles) {
            Ok(Self(cycles))
        } else {
            invalid("command_period_cycles", "must be in 1..=64")
        }
    }

    /// For a robot that extrapolates a servo target for at most `extrapolate_max_s` [s] at
    /// control period `cycle_s` [s]: the bound in whole cycles (rounded) + 1, clamped to
    /// 1..=[`Self::MAX`]; non-finite or non-positive inputs give 1.
    pub fn for_extrapolation(extrapolate_max_s: f64, cycle_s: f64) -> Self {
        let n = extrapolate_max_s / cycle_s;
        if !(n.is_finite() && n >= 0.0 && cycle_s > 0.0) {
            return Self(1);
        }
        // Clamped before the cast: the cast is exact.
        Self((n.round().min(f64::from(Self::MAX)) as u32 + 1).min(Self::MAX))
    }

    /// Our control program's bound on a UR5e: 3 cycles (6 ms) + 1 = 4.
    pub fn ur5e() -> Self {
        Self(4)
    }

    /// The value [cycles].
    pub fn get(&self) -> u32 {
        self.0
    }
}

/// An axis-aligned box in the robot base frame [m] that the TCP, the wrist and the elbow must
/// stay in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorkspaceBox {
    min_m: [f64; 3],
    max_m: [f64; 3],
}

impl WorkspaceBox {
    /// Corners `min_m` and `max_m` [m] (x, y, z in the base frame); finite with min < max on
    /// every axis.
    pub fn new(min_m: [f64; 3], max_m: [f64; 3]) -> Result<Self> {
        for (&lo, &hi) in min_m.iter().zip(&max_m) {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return invalid("workspace", "corners must be finite with min < max");
            }
        }
        Ok(Self { min_m, max_m })
    }

    /// A table-mounted UR5e: x, y in [−1.0, 1.0] m (reach 0.85 m plus tool), z in
    /// [0.02, 1.3] m (nothing below the table plane the base stands on).
    pub fn ur5e_table() -> Self {
        Self {
            min_m: [-1.0, -1.0, 0.02],
            max_m: [1.0, 1.0, 1.3],
        }
    }

    /// Whether `p` [m] lies inside (boundary included). NaN is outside.
    pub fn contains(&self, p: &[f64; 3]) -> bool {
        p.iter()
            .zip(self.min_m.iter().zip(&self.max_m))
            .all(|(&x, (&lo, &hi))| x >= lo && x <= hi)
    }

    /// Lower corner [m].
    pub fn min_m(&self) -> [f64; 3] {
        self.min_m
    }

    /// Upper corner [m].
    pub fn max_m(&self) -> [f64; 3] {
        self.max_m
    }
}

/// Staleness thresholds for perception [s] and the robot state [cycles].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StalenessLimits {
    perception_reduce_after_s: f64,
    perception_stop_after_s: f64,
    robot_state_max_stale_cycles: u32,
}

impl StalenessLimits {
    /// Perception older than `perception_reduce_after_s` [s] reduces speed, older than
    /// `perception_stop_after_s` [s] stops (0 < reduce < stop, finite); more than
    /// `robot_state_max_stale_cycles` consecutive cycles without a new controller timestamp
    /// stop.
    pub fn new(
        perception_reduce_after_s: f64,
        perception_stop_after_s: f64,
        robot_state_max_stale_cycles: u32,
    ) -> Result<Self> {
        let reduce = finite_positive(
            "staleness.perception_reduce_after_s",
            perception_reduce_after_s,
        )?;
        let stop = finite_positive("staleness.perception_stop_after_s", perception_stop_after_s)?;
        if reduce >= stop {
            return invalid(
                "staleness.perception_reduce_after_s",
                "must be < perception_stop_after_s",
            );
        }
        Ok(Self {
            perception_reduce_after_s: reduce,
            perception_stop_after_s: stop,
            robot_state_max_stale_cycles,
        })
    }

    /// 0.2 s, 1 s and 3 cycles (issue 4).
    pub fn issue_default() -> Self {
        Self {
            perception_reduce_after_s: 0.2,
            perception_stop_after_s: 1.0,
            robot_state_max_stale_cycles: 3,
        }
    }

    /// Perception age above which speed is reduced [s].
    pub fn perception_reduce_after_s(&self) -> f64 {
        self.perception_reduce_after_s
    }

    /// Perception age above which the robot stops [s].
    pub fn perception_stop_after_s(&self) -> f64 {
        self.perception_stop_after_s
    }

    /// Consecutive cycles without a new controller timestamp tolerated [cycles].
    pub fn robot_state_max_stale_cycles(&self) -> u32 {
        self.robot_state_max_stale_cycles
    }
}

/// Everything the supervisor checks against. Build with [`SupervisorConfig::ur5e`] and
/// replace fields; every field is already validated, and [`crate::Supervisor::new`] checks
/// the relations between them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupervisorConfig {
    /// Control period [s] (2 ms on a UR5e).
    pub cycle: CyclePeriod,
    /// The longest controller time one servo step is judged over [cycles] (the robot's servo
    /// extrapolation bound + 1; the planner catches up as far).
    pub command_period_cycles: CatchUpCycles,
    /// Joint position limits and margin [rad].
    pub joint_limits: JointLimits,
    /// Joint speed [rad/s] and acceleration [rad/s²] limits, stop deceleration [rad/s²].
    pub joint_rates: JointRateLimits,
    /// TCP speed limit outside collaboration [m/s].
    pub tcp_speed: SpeedLimit,
    /// TCP speed limit while a collaboration period C(t) is active [m/s]; ≤ `tcp_speed`.
    pub collaboration_tcp_speed: SpeedLimit,
    /// Scale applied to the joint and TCP speed limits while perception is stale [-].
    pub stale_perception_scale: SpeedScale,
    /// Box the TCP, wrist and elbow must stay in [m].
    pub workspace: WorkspaceBox,
    /// Protective separation distance parameters (SAF-REQ-007).
    pub separation: SeparationParams,
    /// The arm, gripper and carried part as capsules (SAF-REQ-007).
    pub arm: ArmModel,
    /// The operator's body sizes (SAF-REQ-007).
    pub body: BodyModel,
    /// Perception and robot-state staleness thresholds.
    pub staleness: StalenessLimits,
}

impl SupervisorConfig {
    /// UR5e defaults:
    /// - 2 ms cycle, a servo step judged over at most 4 cycles ([`CatchUpCycles::ur5e`]);
    ///   joints ±2π rad with a 0.05 rad margin, π rad/s, π rad/s², stops at
    ///   π rad/s²;
    /// - TCP 1 m/s; 0.25 m/s while collaborating: ISO 10218-1's reduced speed, well under the
    ///   0.68 m/s quasi-static PFL figure for the hand in issue 4, so a hand clamped against
    ///   the tool stays under 140 N even if separation monitoring misses it;
    /// - speed ×0.25 while perception is stale;
    /// - workspace [`WorkspaceBox::ur5e_table`]; separation
    ///   [`SeparationParams::handover_default`] (Z_r = 0.02 m: the robot's position
    ///   uncertainty; the link sizes are in the capsules), from the capsules of
    ///   [`ArmModel::ur5e_gripper`] to the operator's [`BodyModel::default_adult`];
    ///   staleness 0.2 s / 1 s / 3 cycles.
    pub fn ur5e() -> Self {
        Self {
            cycle: CyclePeriod::ur5e(),
            command_period_cycles: CatchUpCycles::ur5e(),
            joint_limits: JointLimits::ur5e(),
            joint_rates: JointRateLimits::ur5e(),
            tcp_speed: SpeedLimit(1.0),
            collaboration_tcp_speed: SpeedLimit(0.25),
            stale_perception_scale: SpeedScale(0.25),
            workspace: WorkspaceBox::ur5e_table(),
            separation: SeparationParams::handover_default(),
            arm: ArmModel::ur5e_gripper(),
            body: BodyModel::default_adult(),
            staleness: StalenessLimits::issue_default(),
        }
    }

    /// Check the relations between fields (the fields themselves are valid by construction).
    pub fn validate(&self) -> Result<()> {
        if self.collaboration_tcp_speed > self.tcp_speed {
            return invalid("collaboration_tcp_speed", "must be <= tcp_speed");
        }
        Ok(())
    }
}

impl Default for SupervisorConfig {
    fn default() -> Self {
        Self::ur5e()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Worked by hand: 6 ms at 2 ms is 3 cycles, + 1 = 4; the emulator's 24 ms at speedup 4
    /// gives 12 + 1 = 13; 5 ms rounds to 3 (2.5 → 3) + 1 = 4; 0 gives 1; a huge or broken
    /// bound is clamped, never panics. `new` takes 1..=64 only.
    #[test]
    fn catch_up_cycles_are_the_extrapolation_bound_plus_one() {
        let f = |e, c| CatchUpCycles::for_extrapolation(e, c).get();
        assert_eq!(f(0.006, 0.002), 4);
        assert_eq!(f(0.024, 0.002), 13);
        assert_eq!(f(0.005, 0.002), 4);
        assert_eq!(f(0.0, 0.002), 1);
        assert_eq!(f(1e9, 0.002), CatchUpCycles::MAX);
        assert_eq!(f(f64::NAN, 0.002), 1);
        assert_eq!(f(0.006, 0.0), 1);
        assert_eq!(f(-1.0, 0.002), 1);
        assert_eq!(
            CatchUpCycles::ur5e(),
            CatchUpCycles::for_extrapolation(0.006, 0.002)
        );
        assert!(CatchUpCycles::new(0).is_err());
        assert!(CatchUpCycles::new(65).is_err());
        assert_eq!(CatchUpCycles::new(64).unwrap().get(), 64);
    }

    #[test]
    fn joint_limits_reject_bad_ranges() {
        assert!(JointLimits::new([-1.0; 6], [1.0; 6], 0.1).is_ok());
        assert!(JointLimits::new([1.0; 6], [1.0; 6], 0.0).is_err());
        assert!(JointLimits::new([2.0; 6], [1.0; 6], 0.0).is_err());
        let mut lo = [-1.0; 6];
        lo[3] = f64::NAN;
        assert!(JointLimits::new(lo, [1.0; 6], 0.0).is_err());
        assert!(JointLimits::new([-1.0; 6], [f64::INFINITY; 6], 0.0).is_err());
        assert!(JointLimits::new([-1.0; 6], [1.0; 6], -0.1).is_err());
        assert!(JointLimits::new([-1.0; 6], [1.0; 6], 1.0).is_err());
        assert!(JointLimits::new([-1.0; 6], [1.0; 6], f64::NAN).is_err());
    }

    #[test]
    fn joint_limits_find_violations_and_nan() {
        let l = JointLimits::new([-1.0; 6], [1.0; 6], 0.1).unwrap();
        assert_eq!(l.first_violation(&[0.0; 6]), None);
        assert_eq!(l.first_violation(&[0.9; 6]), None);
        let mut q = [0.0; 6];
        q[2] = 0.95;
        assert_eq!(l.first_violation(&q), Some((2, 0.95, 0.9)));
        q[2] = f64::NAN;
        assert!(l.first_violation(&q).is_some());
        assert_eq!(l.allowed(0), Some((-0.9, 0.9)));
        assert_eq!(l.allowed(6), None);
    }

    #[test]
    fn scalar_newtypes_validate() {
        assert!(SpeedScale::new(1.0).is_ok());
        assert!(SpeedScale::new(0.5).is_ok());
        for bad in [0.0, -0.1, 1.0001, f64::NAN, f64::INFINITY] {
            assert!(SpeedScale::new(bad).is_err(), "{bad}");
        }
        assert!((CyclePeriod::from_hz(500.0).unwrap().seconds() - 0.002).abs() < 1e-15);
        for bad in [0.0, -1.0, 500.1, 1000.0, f64::NAN] {
            assert!(CyclePeriod::from_hz(bad).is_err(), "{bad}");
        }
        assert!(SpeedLimit::new(0.0).is_err());
        assert!(SpeedLimit::new(f64::NAN).is_err());
        assert!(JointRateLimits::new(1.0, 0.0, 1.0).is_err());
        assert!(WorkspaceBox::new([0.0; 3], [0.0, 1.0, 1.0]).is_err());
        assert!(WorkspaceBox::new([0.0; 3], [1.0; 3]).is_ok());
        assert!(StalenessLimits::new(1.0, 0.2, 3).is_err());
        assert!(SeparationParams::new(1.6, 2.0, -0.1, 0.0, 0.0, 0.0).is_err());
        assert!(SeparationParams::new(0.0, 2.0, 0.1, 0.0, 0.0, 0.0).is_err());
    }

    #[test]
    fn config_relations_are_checked() {
        let mut c = SupervisorConfig::ur5e();
        assert!(c.validate().is_ok());
        c.collaboration_tcp_speed = SpeedLimit::new(2.0).unwrap();
        assert!(c.validate().is_err());
    }

    #[test]
    fn errors_are_lowercase() {
        let e = SpeedScale::new(2.0).unwrap_err().to_string();
        assert!(e.starts_with("invalid safety setting"), "{e}");
    }
}
