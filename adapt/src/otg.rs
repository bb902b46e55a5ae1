//! Jerk-limited online trajectory generation for the 6 UR5e joints, wrapping `rsruckig`.
//!
//! [`Otg`] plans a time-optimal (or, with a minimum duration, time-stretched and synchronised)
//! jerk-limited motion from the current joint state to a position target (at rest), and samples
//! it every control cycle (2 ms by default). Targets and limits may change at any cycle; the
//! motion is then replanned from the current sampled state (position, velocity, acceleration),
//! so it stays continuous in acceleration.
//!
//! - Limits: [`MotionLimits`] (`max_velocity` [rad/s], `max_acceleration` [rad/s²],
//!   `max_jerk` [rad/s³] per joint), validated finite and > 0. [`MotionLimits::ur5e_nominal`]
//!   holds π rad/s, π rad/s² and [`UR5E_NOMINAL_JERK_RAD_S3`]; [`MotionLimits::scaled`]
//!   applies the adaptation's speed and smoothness scales ([`LimitScale`], in (0, 1]).
//! - Handover timing: [`Otg::set_target`] takes an optional minimum duration [s]; all joints
//!   then arrive together no earlier than that. [`Otg::time_optimal_duration`] gives the
//!   shortest duration for the current state, target and limits.
//! - [`Otg::step`] allocates nothing once built, including when it replans (a counting
//!   allocator checks 1500 cycles with three replans in `tests/otg_vs_ruckig.rs`). Ruckig's
//!   intermediate waypoints are never used.
//!
//! Ruckig's own `calculation_duration` diagnostic reads `std::time::Instant`; nothing here
//! depends on it, so the generated motion is deterministic.
//!
//! # Example
//! ```
//! use adapt::otg::{MotionLimits, Otg, OtgState, PlanStatus};
//! let mut otg = Otg::new(0.002, MotionLimits::ur5e_nominal())?;
//! otg.set_current_state(&[0.0; 6], &[0.0; 6], &[0.0; 6])?;
//! otg.set_target(&[0.5, -0.2, 0.1, 0.0, 0.0, 0.3], None)?;
//! let mut out = OtgState::default();
//! while otg.step(&mut out)? == PlanStatus::Working {}
//! assert!((out.position[0] - 0.5).abs() < 1e-9);
//! # Ok::<(), adapt::AdaptError>(())
//! ```

use std::f64::consts::{PI, TAU};

use robot_io::Joints;
use rsruckig::prelude::{
    InputParameter, OutputParameter, Ruckig, RuckigError, RuckigResult, ThrowErrorHandler,
    Trajectory,
};

use crate::{AdaptError, Result};

/// Degrees of freedom of the UR5e.
pub const DOF: usize = 6;
/// The UR5e control period [s].
pub const UR5E_CYCLE_S: f64 = 0.002;
/// UR5e joint speed limit [rad/s] (180°/s).
pub const UR5E_MAX_VELOCITY_RAD_S: f64 = PI;
/// Nominal UR5e joint acceleration limit [rad/s²] (UR's ROS description placeholder).
pub const UR5E_NOMINAL_ACCELERATION_RAD_S2: f64 = PI;
/// Nominal joint jerk limit [rad/s³]: 10π, so the acceleration ramps to π rad/s² in 0.1 s.
/// UR publishes no jerk limit; this is our choice.
pub const UR5E_NOMINAL_JERK_RAD_S3: f64 = 10.0 * PI;
/// Joint position limit [rad] (±2π); targets beyond it are rejected.
pub const UR5E_JOINT_LIMIT_RAD: f64 = TAU;

fn invalid(name: &'static str, joint: usize, value: f64, rule: &'static str) -> AdaptError {
    AdaptError::InvalidTrajectoryParameter {
        name,
        joint,
        value,
        rule,
    }
}

/// A scale factor in (0, 1] [-], e.g. the adaptation's speed or smoothness scale.
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd)]
pub struct LimitScale(f64);

impl LimitScale {
    /// No scaling (1).
    pub const ONE: LimitScale = LimitScale(1.0);

    /// A scale `x` [-].
    ///
    /// # Errors
    /// [`AdaptError::InvalidTrajectoryParameter`] unless `0 < x ≤ 1`.
    pub fn new(x: f64) -> Result<Self> {
        if x.is_finite() && x > 0.0 && x <= 1.0 {
            Ok(LimitScale(x))
        } else {
            Err(invalid("limit_scale", 0, x, "must be finite and in (0, 1]"))
        }
    }

    /// The value [-] in (0, 1].
    pub fn get(self) -> f64 {
        self.0
    }
}

/// Per-joint kinematic limits of the trajectory; every value finite and > 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLimits {
    max_velocity: Joints,
    max_acceleration: Joints,
    max_jerk: Joints,
}

impl MotionLimits {
    /// Limits from per-joint `max_velocity` [rad/s], `max_acceleration` [rad/s²] and
    /// `max_jerk` [rad/s³].
    ///
    /// # Errors
    /// [`AdaptError::InvalidTrajectoryParameter`] if any value is not finite or ≤ 0.
    pub fn new(max_velocity: Joints, max_acceleration: Joints, max_jerk: Joints) -> Result<Self> {
        for (name, values) in [
            ("max_velocity_rad_s", &max_velocity),
            ("max_acceleration_rad_s2", &max_acceleration),
            ("max_jerk_rad_s3", &max_jerk),
        ] {
            for (joint, &v) in values.iter().enumerate() {
                if !(v.is_finite() && v > 0.0) {
                    return Err(invalid(name, joint, v, "must be finite and > 0"));
                }
            }
        }
        Ok(MotionLimits {
            max_velocity,
            max_acceleration,
            max_jerk,
        })
    }

    /// The UR5e nominal limits: π rad/s, π rad/s² and [`UR5E_NOMINAL_JERK_RAD_S3`] on every
    /// joint.
    pub fn ur5e_nominal() -> Self {
        MotionLimits {
            max_velocity: [UR5E_MAX_VELOCITY_RAD_S; DOF],
            max_acceleration: [UR5E_NOMINAL_ACCELERATION_RAD_S2; DOF],
            max_jerk: [UR5E_NOMINAL_JERK_RAD_S3; DOF],
        }
    }

    /// These limits under the adaptation's scales: velocity × `speed`, acceleration ×
    /// `smoothness`, jerk × `smoothness`² (so a smoother motion also takes longer to build up
    /// its acceleration: the ramp time a/j grows by 1/`smoothness`). The result stays > 0.
    pub fn scaled(&self, speed: LimitScale, smoothness: LimitScale) -> Self {
        let s = smoothness.get();
        MotionLimits {
            max_velocity: self.max_velocity.map(|v| v * speed.get()),
            max_acceleration: self.max_acceleration.map(|a| a * s),
            max_jerk: self.max_jerk.map(|j| j * s * s),
        }
    }

    /// Per-joint velocity limits [rad/s].
    pub fn max_velocity(&self) -> &Joints {
        &self.max_velocity
    }

    /// Per-joint acceleration limits [rad/s²].
    pub fn max_acceleration(&self) -> &Joints {
        &self.max_acceleration
    }

    /// Per-joint jerk limits [rad/s³].
    pub fn max_jerk(&self) -> &Joints {
        &self.max_jerk
    }
}

/// Outcome of one [`Otg::step`]: a value, not an error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlanStatus {
    /// The motion is under way (or no target is set and the state holds).
    Working,
    /// The target is reached; the state holds at the target.
    Finished,
}

/// The sampled trajectory state of one cycle (caller-owned output of [`Otg::step`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OtgState {
    /// Joint positions [rad].
    pub position: Joints,
    /// Joint velocities [rad/s].
    pub velocity: Joints,
    /// Joint accelerations [rad/s²].
    pub acceleration: Joints,
    /// Time since the current plan was computed [s].
    pub time_s: f64,
    /// Duration of the current plan [s].
    pub duration_s: f64,
    /// Whether this step computed a new plan (target, limits or state changed).
    pub replanned: bool,
}

fn ruckig_error(e: RuckigError) -> AdaptError {
    AdaptError::TrajectoryGeneration {
        reason: e.to_string().to_lowercase(),
    }
}

fn result_error(r: &RuckigResult) -> AdaptError {
    let reason = match r {
        RuckigResult::Error => "unclassified calculation error",
        RuckigResult::ErrorInvalidInput => "invalid input",
        RuckigResult::ErrorTrajectoryDuration => "trajectory duration exceeds numerical limits",
        RuckigResult::ErrorPositionalLimits => "positional limits violated",
        RuckigResult::ErrorZeroLimits => "conflict with zero limits",
        RuckigResult::ErrorExecutionTimeCalculation => "execution time calculation (step 1)",
        RuckigResult::ErrorSynchronizationCalculation => "synchronization calculation (step 2)",
        RuckigResult::Working | RuckigResult::Finished => "unexpected result",
    };
    AdaptError::TrajectoryGeneration {
        reason: reason.to_owned(),
    }
}

/// Validate a joint vector: finite, and within ±`bound` if given.
fn check_joints(name: &'static str, v: &Joints, bound: Option<f64>) -> Result<()> {
    for (joint, &x) in v.iter().enumerate() {
        if !x.is_finite() {
            return Err(invalid(name, joint, x, "must be finite"));
        }
        if let Some(b) = bound
            && x.abs() > b
        {
            return Err(invalid(name, joint, x, "outside the joint range ±2π rad"));
        }
    }
    Ok(())
}

/// Online jerk-limited trajectory generator for 6 joints, built once and stepped every cycle.
#[derive(Debug)]
pub struct Otg {
    ruckig: Ruckig<DOF, ThrowErrorHandler>,
    input: InputParameter<DOF>,
    output: OutputParameter<DOF>,
    scratch: Trajectory<DOF>,
    limits: MotionLimits,
    cycle_s: f64,
    has_target: bool,
}

impl Otg {
    /// A generator stepping by `cycle_s` [s] (0 < `cycle_s` ≤ 1; the UR5e uses
    /// [`UR5E_CYCLE_S`]) under `limits`. The state starts at rest at zero and no target is set
    /// (steps hold the state); call [`Otg::set_current_state`] and [`Otg::set_target`].
    ///
    /// # Errors
    /// [`AdaptError::InvalidTrajectoryParameter`] for a bad `cycle_s`.
    pub fn new(cycle_s: f64, limits: MotionLimits) -> Result<Self> {
        if !(cycle_s.is_finite() && cycle_s > 0.0 && cycle_s <= 1.0) {
            return Err(invalid(
                "cycle_s",
                0,
                cycle_s,
                "must be finite and in (0, 1] s",
            ));
        }
        let mut otg = Otg {
            ruckig: Ruckig::new(None, cycle_s),
            input: InputParameter::new(None),
            output: OutputParameter::new(None),
            scratch: Trajectory::new(None),
            limits,
            cycle_s,
            has_target: false,
        };
        otg.apply_limits();
        Ok(otg)
    }

    /// The control period [s].
    pub fn cycle_s(&self) -> f64 {
        self.cycle_s
    }

    /// The limits in force.
    pub fn limits(&self) -> &MotionLimits {
        &self.limits
    }

    fn apply_limits(&mut self) {
        for i in 0..DOF {
            let (Some(v), Some(a), Some(j)) = (
                self.limits.max_velocity.get(i),
                self.limits.max_acceleration.get(i),
                self.limits.max_jerk.get(i),
            ) else {
                continue;
            };
            if let (Some(iv), Some(ia), Some(ij)) = (
                self.input.max_velocity.get_mut(i),
                self.input.max_acceleration.get_mut(i),
                self.input.max_jerk.get_mut(i),
            ) {
                *iv = *v;
                *ia = *a;
                *ij = *j;
            }
        }
    }

    /// Replace the limits; the next step replans from the current state (a motion faster than
    /// the new limits is brought within them jerk-limited). Allocates nothing.
    pub fn set_limits(&mut self, limits: &MotionLimits) {
        self.limits = *limits;
        self.apply_limits();
    }

    /// Set the current joint state (e.g. from the robot when (re)starting): `position` [rad],
    /// `velocity` [rad/s], `acceleration` [rad/s²]. The next step replans from it.
    ///
    /// # Errors
    /// [`AdaptError::InvalidTrajectoryParameter`] for non-finite values.
    pub fn set_current_state(
        &mut self,
        position: &Joints,
        velocity: &Joints,
        acceleration: &Joints,
    ) -> Result<()> {
        check_joints("current_position_rad", position, None)?;
        check_joints("current_velocity_rad_s", velocity, None)?;
        check_joints("current_acceleration_rad_s2", acceleration, None)?;
        for i in 0..DOF {
            if let (Some(p), Some(v), Some(a)) = (
                self.input.current_position.get_mut(i),
                self.input.current_velocity.get_mut(i),
                self.input.current_acceleration.get_mut(i),
            ) {
                *p = position.get(i).copied().unwrap_or_default();
                *v = velocity.get(i).copied().unwrap_or_default();
                *a = acceleration.get(i).copied().unwrap_or_default();
            }
        }
        if !self.has_target {
            self.hold_current();
        }
        Ok(())
    }

    /// Without a target, the target is the current position at rest.
    fn hold_current(&mut self) {
        for i in 0..DOF {
            let p = self.input.current_position.get(i).copied();
            if let (Some(p), Some(t), Some(tv), Some(ta)) = (
                p,
                self.input.target_position.get_mut(i),
                self.input.target_velocity.get_mut(i),
                self.input.target_acceleration.get_mut(i),
            ) {
                *t = p;
                *tv = 0.0;
                *ta = 0.0;
            }
        }
    }

    /// Move to `target` [rad] (arriving at rest), taking at least `minimum_duration_s` [s] if
    /// given (handover timing; all joints are stretched to arrive together). Takes effect at
    /// the next step. Allocates nothing.
    ///
    /// # Errors
    /// [`AdaptError::InvalidTrajectoryParameter`] if a target is not finite or beyond ±2π rad,
    /// or the minimum duration is not finite or < 0.
    pub fn set_target(&mut self, target: &Joints, minimum_duration_s: Option<f64>) -> Result<()> {
        check_joints("target_position_rad", target, Some(UR5E_JOINT_LIMIT_RAD))?;
        if let Some(d) = minimum_duration_s
            && !(d.is_finite() && d >= 0.0)
        {
            return Err(invalid(
                "minimum_duration_s",
                0,
                d,
                "must be finite and >= 0",
            ));
        }
        for (i, &t) in target.iter().enumerate() {
            if let (Some(p), Some(tv), Some(ta)) = (
                self.input.target_position.get_mut(i),
                self.input.target_velocity.get_mut(i),
                self.input.target_acceleration.get_mut(i),
            ) {
                *p = t;
                *tv = 0.0;
                *ta = 0.0;
            }
        }
        self.input.minimum_duration = minimum_duration_s;
        self.has_target = true;
        Ok(())
    }

    /// The shortest duration [s] of a motion from the current state to the current target
    /// under the current limits (ignoring any minimum duration). Allocates nothing.
    ///
    /// # Errors
    /// [`AdaptError::TrajectoryGeneration`] if Ruckig finds no trajectory.
    pub fn time_optimal_duration(&mut self) -> Result<f64> {
        let minimum = self.input.minimum_duration.take();
        let result = self.ruckig.calculate(&self.input, &mut self.scratch);
        self.input.minimum_duration = minimum;
        match result.map_err(ruckig_error)? {
            RuckigResult::Working | RuckigResult::Finished => Ok(self.scratch.get_duration()),
            other => Err(result_error(&other)),
        }
    }

    /// Advance one cycle: replan if the target, limits or state changed, then write the state
    /// one cycle ahead into `out`. The sampled state becomes the next cycle's current state.
    /// Allocates nothing.
    ///
    /// # Errors
    /// [`AdaptError::TrajectoryGeneration`] if Ruckig finds no trajectory (the internal state
    /// is left unchanged).
    pub fn step(&mut self, out: &mut OtgState) -> Result<PlanStatus> {
        let status = match self
            .ruckig
            .update(&self.input, &mut self.output)
            .map_err(ruckig_error)?
        {
            RuckigResult::Working => PlanStatus::Working,
            RuckigResult::Finished => PlanStatus::Finished,
            other => return Err(result_error(&other)),
        };
        self.output.pass_to_input(&mut self.input);
        for i in 0..DOF {
            if let (Some(p), Some(v), Some(a), Some(op), Some(ov), Some(oa)) = (
                out.position.get_mut(i),
                out.velocity.get_mut(i),
                out.acceleration.get_mut(i),
                self.output.new_position.get(i),
                self.output.new_velocity.get(i),
                self.output.new_acceleration.get(i),
            ) {
                *p = *op;
                *v = *ov;
                *a = *oa;
            }
        }
        out.time_s = self.output.time;
        out.duration_s = self.output.trajectory.get_duration();
        out.replanned = self.output.new_calculation;
        Ok(status)
    }
}

/// The duration [s] Ruckig computes for one 6-DoF state-to-state problem, from scratch; for
/// offline checks (it allocates the Ruckig instance). Positions [rad], velocities [rad/s],
/// accelerations [rad/s²]; `minimum_duration_s` [s] as in [`Otg::set_target`].
///
/// # Errors
/// [`AdaptError::TrajectoryGeneration`] if Ruckig rejects the input or finds no trajectory.
pub fn trajectory_duration(
    current: [&Joints; 3],
    target: [&Joints; 3],
    limits: &MotionLimits,
    minimum_duration_s: Option<f64>,
) -> Result<f64> {
    let mut ruckig = Ruckig::<DOF, ThrowErrorHandler>::new(None, UR5E_CYCLE_S);
    let mut input = InputParameter::<DOF>::new(None);
    let mut trajectory = Trajectory::<DOF>::new(None);
    let [cp, cv, ca] = current;
    let [tp, tv, ta] = target;
    for i in 0..DOF {
        let get = |v: &Joints| v.get(i).copied().unwrap_or_default();
        let set = |d: &mut rsruckig::prelude::DataArrayOrVec<f64, DOF>, x: f64| {
            if let Some(s) = d.get_mut(i) {
                *s = x;
            }
        };
        set(&mut input.current_position, get(cp));
        set(&mut input.current_velocity, get(cv));
        set(&mut input.current_acceleration, get(ca));
        set(&mut input.target_position, get(tp));
        set(&mut input.target_velocity, get(tv));
        set(&mut input.target_acceleration, get(ta));
        set(&mut input.max_velocity, get(&limits.max_velocity));
        set(&mut input.max_acceleration, get(&limits.max_acceleration));
        set(&mut input.max_jerk, get(&limits.max_jerk));
    }
    input.minimum_duration = minimum_duration_s;
    match ruckig
        .calculate(&input, &mut trajectory)
        .map_err(ruckig_error)?
    {
        RuckigResult::Working | RuckigResult::Finished => Ok(trajectory.get_duration()),
        other => Err(result_error(&other)),
    }
}
