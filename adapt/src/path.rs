//! Time-scaled jerk-limited motion: a planned joint path sampled at a *path time* τ, and a
//! jerk-limited time-scaling factor `s = dτ/dt` that slows the motion along that path without
//! leaving it.
//!
//! # Why time scaling
//! The robot's speed near the operator must follow limits that change every cycle (separation
//! from a moving hand, the collaboration speed cap). Changing the *velocity* of a command to meet
//! them (what a per-cycle velocity QP does) leaves the planned path and forces a re-plan from
//! wherever the robot ended up: the motion becomes stop-and-go. Scaling *time* along the path
//! instead (the approach of UR's speed slider and of the ROS 2 scaled joint trajectory
//! controller) keeps the path and changes only how fast it is run. With `q(τ)` the planned path
//! and `s(t) = dτ/dt`, the executed motion is
//!
//! ```text
//! q̇   = s · q'(τ)
//! q̈   = ṡ · q'(τ) + s² · q''(τ)
//! q⃛   = s̈ · q'(τ) + 3 s ṡ · q''(τ) + s³ · q'''(τ)
//! ```
//! so if the path is planned under `(V, A_p, J_p)` and `s ∈ [0, 1]` itself moves under
//! `|ṡ| ≤ ṡ_max`, `|s̈| ≤ s̈_max` (a one-dimensional jerk-limited trajectory, [`TimeScale`]),
//! every executed joint obeys
//!
//! ```text
//! |q̇| ≤ V,   |q̈| ≤ ṡ_max·Q1 + A_p,   |q⃛| ≤ s̈_max·Q1 + 3 ṡ_max·Q2 + J_p
//! ```
//! with `Q1 = max |q'|` and `Q2 = max |q''|` over the planned path ([`scale_limits_for`] picks
//! `ṡ_max`, `s̈_max` from budgets so that these stay within the planner's own limits).
//!
//! # Example
//! ```
//! use adapt::otg::MotionLimits;
//! use adapt::path::{Path, PathSample, PathState};
//! let mut path = Path::new(MotionLimits::ur5e_nominal());
//! let start = PathState { position: [0.0; 6], velocity: [0.0; 6], acceleration: [0.0; 6] };
//! path.plan(&start, &[0.5, -0.2, 0.1, 0.0, 0.0, 0.3], &MotionLimits::ur5e_nominal(), None)?;
//! let mut end = PathSample::default();
//! path.sample(path.duration_s(), &mut end);
//! assert!((end.position[0] - 0.5).abs() < 1e-9);
//! # Ok::<(), adapt::path::PathError>(())
//! ```

use robot_io::Joints;
use rsruckig::prelude::{
    ControlInterface, DataArrayOrVec, InputParameter, Ruckig, RuckigResult, Synchronization,
    ThrowErrorHandler, Trajectory,
};

use crate::error::positive;
use crate::otg::{DOF, MotionLimits, UR5E_CYCLE_S};
use crate::{AdaptError, Result};

/// A joint state to plan from: positions [rad], velocities [rad/s], accelerations [rad/s²], all
/// in *path* time.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PathState {
    /// Joint positions [rad].
    pub position: Joints,
    /// Joint velocities dq/dτ [rad/s].
    pub velocity: Joints,
    /// Joint accelerations d²q/dτ² [rad/s²].
    pub acceleration: Joints,
}

/// The path sampled at one path time: `q(τ)`, `q'(τ)`, `q''(τ)`, `q'''(τ)`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PathSample {
    /// Joint positions [rad].
    pub position: Joints,
    /// dq/dτ [rad/s].
    pub velocity: Joints,
    /// d²q/dτ² [rad/s²].
    pub acceleration: Joints,
    /// d³q/dτ³ [rad/s³].
    pub jerk: Joints,
}

/// Samples taken along a freshly planned path to find its largest velocity and acceleration
/// (and, in the controller, its largest TCP speed) [-].
pub const PLAN_SAMPLES: usize = 64;

/// Why a path could not be planned (a value, so the 500 Hz path allocates nothing on failure).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PathError {
    /// Ruckig rejected the input or found no trajectory.
    NoTrajectory,
    /// The trajectory's duration is not finite.
    NonFiniteDuration,
}

impl From<PathError> for AdaptError {
    fn from(e: PathError) -> AdaptError {
        AdaptError::TrajectoryGeneration {
            reason: match e {
                PathError::NoTrajectory => "no trajectory for this state, target and limits",
                PathError::NonFiniteDuration => "the trajectory's duration is not finite",
            }
            .to_owned(),
        }
    }
}

fn result_ok(
    r: core::result::Result<RuckigResult, rsruckig::prelude::RuckigError>,
) -> core::result::Result<(), PathError> {
    match r {
        Ok(RuckigResult::Working | RuckigResult::Finished) => Ok(()),
        _ => Err(PathError::NoTrajectory),
    }
}

/// A jerk-limited joint path from a start state to a target at rest (Ruckig, time-synchronised),
/// sampled at any path time. Planning and sampling allocate nothing.
#[derive(Debug)]
pub struct Path {
    ruckig: Ruckig<DOF, ThrowErrorHandler>,
    input: InputParameter<DOF>,
    trajectory: Trajectory<DOF>,
    scratch: Trajectory<DOF>,
    buf: [DataArrayOrVec<f64, DOF>; 4],
    duration_s: f64,
    target: Joints,
    planned: bool,
    /// max |q'| over joints and samples [rad/s].
    max_velocity: f64,
    /// max |q''| over joints and samples [rad/s²].
    max_acceleration: f64,
}

impl Path {
    /// An empty path (holds wherever it is sampled: zero everywhere until planned), with
    /// `limits` as its initial limits.
    pub fn new(limits: MotionLimits) -> Path {
        let mut input = InputParameter::new(None);
        // Phase synchronisation: a rest-to-rest motion is a straight line in joint space, so no
        // joint turns back on the way (Ruckig falls back to time synchronisation when the start
        // state does not allow it).
        input.synchronization = Synchronization::Phase;
        for i in 0..DOF {
            set(&mut input.max_velocity, i, limits.max_velocity().get(i));
            set(
                &mut input.max_acceleration,
                i,
                limits.max_acceleration().get(i),
            );
            set(&mut input.max_jerk, i, limits.max_jerk().get(i));
        }
        Path {
            ruckig: Ruckig::new(None, UR5E_CYCLE_S),
            input,
            trajectory: Trajectory::new(None),
            scratch: Trajectory::new(None),
            buf: core::array::from_fn(|_| DataArrayOrVec::new(None, 0.0)),
            duration_s: 0.0,
            target: [0.0; DOF],
            planned: false,
            max_velocity: 0.0,
            max_acceleration: 0.0,
        }
    }

    /// Plan from `start` to `target` [rad] (arriving at rest) under `limits`, taking at least
    /// `minimum_duration_s` [s] if given. On error the previous path is kept.
    ///
    /// # Errors
    /// [`PathError`] when Ruckig finds no trajectory (non-finite input, numerical limits).
    pub fn plan(
        &mut self,
        start: &PathState,
        target: &Joints,
        limits: &MotionLimits,
        minimum_duration_s: Option<f64>,
    ) -> core::result::Result<(), PathError> {
        for i in 0..DOF {
            set(&mut self.input.current_position, i, start.position.get(i));
            set(&mut self.input.current_velocity, i, start.velocity.get(i));
            set(
                &mut self.input.current_acceleration,
                i,
                start.acceleration.get(i),
            );
            set(&mut self.input.target_position, i, target.get(i));
            set(&mut self.input.target_velocity, i, Some(&0.0));
            set(&mut self.input.target_acceleration, i, Some(&0.0));
            set(
                &mut self.input.max_velocity,
                i,
                limits.max_velocity().get(i),
            );
            set(
                &mut self.input.max_acceleration,
                i,
                limits.max_acceleration().get(i),
            );
            set(&mut self.input.max_jerk, i, limits.max_jerk().get(i));
        }
        self.input.minimum_duration = minimum_duration_s.filter(|d| d.is_finite() && *d > 0.0);
        result_ok(self.ruckig.calculate(&self.input, &mut self.scratch))?;
        if !self.scratch.get_duration().is_finite() {
            return Err(PathError::NonFiniteDuration);
        }
        core::mem::swap(&mut self.trajectory, &mut self.scratch);
        self.duration_s = self.trajectory.get_duration();
        self.target = *target;
        self.planned = true;
        self.measure();
        Ok(())
    }

    /// Find the largest |q'| and |q''| over [`PLAN_SAMPLES`] + 1 evenly spaced path times.
    fn measure(&mut self) {
        let mut s = PathSample::default();
        let (mut v, mut a) = (0.0_f64, 0.0_f64);
        for k in 0..=PLAN_SAMPLES {
            let tau = self.duration_s * k as f64 / PLAN_SAMPLES as f64;
            self.sample(tau, &mut s);
            for i in 0..DOF {
                v = v.max(s.velocity.get(i).map_or(0.0, |x| x.abs()));
                a = a.max(s.acceleration.get(i).map_or(0.0, |x| x.abs()));
            }
        }
        self.max_velocity = v;
        self.max_acceleration = a;
    }

    /// Whether a path has been planned.
    pub fn is_planned(&self) -> bool {
        self.planned
    }

    /// The path's duration [s] (path time; 0 before the first plan).
    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    /// The target of the current plan [rad].
    pub fn target(&self) -> &Joints {
        &self.target
    }

    /// Largest |q'| over the joints along the plan [rad/s] (sampled, [`PLAN_SAMPLES`]).
    pub fn max_velocity(&self) -> f64 {
        self.max_velocity
    }

    /// Largest |q''| over the joints along the plan [rad/s²] (sampled).
    pub fn max_acceleration(&self) -> f64 {
        self.max_acceleration
    }

    /// The path at path time `tau_s` [s] (clamped to [0, duration]; before the first plan,
    /// all zero). Allocates nothing.
    pub fn sample(&mut self, tau_s: f64, out: &mut PathSample) {
        if !self.planned {
            *out = PathSample::default();
            return;
        }
        let t = if tau_s.is_finite() {
            tau_s.clamp(0.0, self.duration_s)
        } else {
            0.0
        };
        let [p, v, a, j] = &mut self.buf;
        let mut section = None;
        self.trajectory.at_time(
            t,
            &mut Some(p),
            &mut Some(v),
            &mut Some(a),
            &mut Some(j),
            &mut section,
        );
        for i in 0..DOF {
            copy(&mut out.position, i, self.buf[0].get(i));
            copy(&mut out.velocity, i, self.buf[1].get(i));
            copy(&mut out.acceleration, i, self.buf[2].get(i));
            copy(&mut out.jerk, i, self.buf[3].get(i));
        }
        if t >= self.duration_s {
            // At the end the path rests exactly at its target.
            out.position = self.target;
            out.velocity = [0.0; DOF];
            out.acceleration = [0.0; DOF];
            out.jerk = [0.0; DOF];
        }
    }
}

fn set(d: &mut DataArrayOrVec<f64, DOF>, i: usize, v: Option<&f64>) {
    if let (Some(slot), Some(v)) = (d.get_mut(i), v) {
        *slot = *v;
    }
}

fn copy(out: &mut Joints, i: usize, v: Option<&f64>) {
    if let (Some(slot), Some(v)) = (out.get_mut(i), v) {
        *slot = *v;
    }
}

/// The limits of the time-scaling factor: `ṡ_max` [1/s] and `s̈_max` [1/s²], validated finite
/// and > 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaleLimits {
    rate: f64,
    accel: f64,
}

impl ScaleLimits {
    /// Limits `rate` = ṡ_max [1/s] and `accel` = s̈_max [1/s²].
    ///
    /// # Errors
    /// [`AdaptError::InvalidValue`] unless both are finite and > 0.
    pub fn new(rate: f64, accel: f64) -> Result<ScaleLimits> {
        Ok(ScaleLimits {
            rate: positive("scale_rate", rate)?,
            accel: positive("scale_accel", accel)?,
        })
    }

    /// ṡ_max [1/s].
    pub fn rate(&self) -> f64 {
        self.rate
    }

    /// s̈_max [1/s²].
    pub fn accel(&self) -> f64 {
        self.accel
    }

    /// The largest drop of `s` [-] that can be completed within `h_s` [s] starting from
    /// `ṡ = 0` under these limits: `½ s̈_max h²` while the rate builds up (h ≤ ṡ_max/s̈_max),
    /// then `ṡ_max (h − ṡ_max / (2 s̈_max))`.
    pub fn reachable_drop(&self, h_s: f64) -> f64 {
        if !(h_s.is_finite() && h_s > 0.0) {
            return 0.0;
        }
        let ramp = self.rate / self.accel;
        if h_s <= ramp {
            0.5 * self.accel * h_s * h_s
        } else {
            self.rate * (h_s - 0.5 * ramp)
        }
    }

    /// The time [s] a full stop of the scale (1 → 0) takes from `ṡ = 0`.
    pub fn full_stop_s(&self) -> f64 {
        1.0 / self.rate + self.rate / self.accel
    }
}

/// Chooses `ṡ_max` and `s̈_max` for a path so that the executed motion keeps the planner's
/// limits (module docs): with `Q1`, `Q2` the path's largest |q'| and |q''|,
/// `ṡ_max = min(acc_budget / Q1, jerk_budget / (2·3·Q2))` and `s̈_max = jerk_budget / (2·Q1)`,
/// each capped at `max_rate` [1/s] and `max_accel` [1/s²] (a path at rest needs no limit).
/// `acc_budget` [rad/s²] and `jerk_budget` [rad/s³] are what the path's own limits leave free.
pub fn scale_limits_for(
    max_path_velocity: f64,
    max_path_acceleration: f64,
    acc_budget: f64,
    jerk_budget: f64,
    max_rate: f64,
    max_accel: f64,
) -> ScaleLimits {
    let q1 = max_path_velocity.max(1e-9);
    let q2 = max_path_acceleration.max(1e-9);
    let rate = (acc_budget / q1)
        .min(jerk_budget / (6.0 * q2))
        .min(max_rate);
    let accel = (jerk_budget / (2.0 * q1)).min(max_accel);
    // Budgets are positive by construction in the controller; guard anyway.
    let rate = if rate.is_finite() && rate > 0.0 {
        rate
    } else {
        1e-3
    };
    let accel = if accel.is_finite() && accel > 0.0 {
        accel
    } else {
        1e-3
    };
    ScaleLimits { rate, accel }
}

/// The time-scaling factor `s = dτ/dt ∈ [0, 1]` as a one-dimensional jerk-limited trajectory
/// (Ruckig's velocity interface on the path time τ): each step moves `s` toward a target under
/// [`ScaleLimits`], and advances τ by ∫ s dt. Allocates nothing.
#[derive(Debug)]
pub struct TimeScale {
    ruckig: Ruckig<1, ThrowErrorHandler>,
    input: InputParameter<1>,
    trajectory: Trajectory<1>,
    buf: [DataArrayOrVec<f64, 1>; 3],
    tau: f64,
    s: f64,
    s_dot: f64,
    limits: ScaleLimits,
    errors: u64,
}

impl TimeScale {
    /// At path time 0 with `s = 1`, `ṡ = 0`.
    pub fn new(limits: ScaleLimits) -> TimeScale {
        let mut input = InputParameter::new(None);
        input.control_interface = ControlInterface::Velocity;
        TimeScale {
            ruckig: Ruckig::new(None, UR5E_CYCLE_S),
            input,
            trajectory: Trajectory::new(None),
            buf: core::array::from_fn(|_| DataArrayOrVec::new(None, 0.0)),
            tau: 0.0,
            s: 1.0,
            s_dot: 0.0,
            limits,
            errors: 0,
        }
    }

    /// Restart at path time `tau` [s] with factor `s` [-] (clamped to [0, 1]) and `ṡ = 0`.
    pub fn reset(&mut self, tau: f64, s: f64) {
        self.tau = if tau.is_finite() { tau } else { 0.0 };
        self.s = if s.is_finite() {
            s.clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.s_dot = 0.0;
    }

    /// Keep τ, s and ṡ, but move τ to `tau` [s] (a new path starting where the old one was).
    pub fn set_tau(&mut self, tau: f64) {
        self.tau = if tau.is_finite() { tau } else { 0.0 };
    }

    /// Replace the limits (the next step respects them; a rate above the new ṡ_max is brought
    /// within it jerk-limited).
    pub fn set_limits(&mut self, limits: ScaleLimits) {
        self.limits = limits;
    }

    /// The limits in force.
    pub fn limits(&self) -> &ScaleLimits {
        &self.limits
    }

    /// Path time τ [s].
    pub fn tau(&self) -> f64 {
        self.tau
    }

    /// The factor s [-].
    pub fn s(&self) -> f64 {
        self.s
    }

    /// Its rate ṡ [1/s].
    pub fn s_dot(&self) -> f64 {
        self.s_dot
    }

    /// Steps in which Ruckig failed and `s` was ramped down at ṡ_max instead.
    pub fn errors(&self) -> u64 {
        self.errors
    }

    /// Advance by `dt_s` [s] toward `target` (clamped to [0, 1]).
    pub fn step(&mut self, target: f64, dt_s: f64) {
        let target = if target.is_finite() {
            target.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s
        } else {
            return;
        };
        set1(&mut self.input.current_position, self.tau);
        set1(&mut self.input.current_velocity, self.s);
        set1(&mut self.input.current_acceleration, self.s_dot);
        set1(&mut self.input.target_velocity, target);
        set1(&mut self.input.target_acceleration, 0.0);
        set1(&mut self.input.max_velocity, 2.0);
        set1(&mut self.input.max_acceleration, self.limits.rate);
        set1(&mut self.input.max_jerk, self.limits.accel);
        let ok = result_ok(self.ruckig.calculate(&self.input, &mut self.trajectory)).is_ok();
        if ok {
            let [p, v, a] = &mut self.buf;
            let mut section = None;
            self.trajectory.at_time(
                dt,
                &mut Some(p),
                &mut Some(v),
                &mut Some(a),
                &mut None,
                &mut section,
            );
            let tau = self.buf[0].get(0).copied().unwrap_or(self.tau);
            let s = self.buf[1].get(0).copied().unwrap_or(self.s);
            let s_dot = self.buf[2].get(0).copied().unwrap_or(0.0);
            if tau.is_finite() && s.is_finite() && s_dot.is_finite() {
                self.tau = tau.max(self.tau);
                if !(0.0..=1.0).contains(&s) {
                    // Numerical overshoot of the bounds: rest on the bound.
                    self.s = s.clamp(0.0, 1.0);
                    self.s_dot = 0.0;
                } else {
                    self.s = s;
                    self.s_dot = s_dot;
                }
                return;
            }
        }
        // No trajectory: fall back to a rate-limited ramp (and count it).
        self.errors = self.errors.saturating_add(1);
        let step = self.limits.rate * dt;
        let s = self.s + (target - self.s).clamp(-step, step);
        self.tau += 0.5 * (self.s + s) * dt;
        self.s = s;
        self.s_dot = 0.0;
    }
}

fn set1(d: &mut DataArrayOrVec<f64, 1>, v: f64) {
    if let Some(slot) = d.get_mut(0) {
        *slot = v;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reachable_drop_is_the_jerk_limited_ramp() {
        // Worked example (by hand): ṡ_max = 2 /s, s̈_max = 10 /s²: the rate builds up in
        // 0.2 s, dropping ½·10·0.2² = 0.2; after 0.5 s: 0.2 + 2·0.3 = 0.8 = 2·(0.5 − 0.1).
        let l = ScaleLimits::new(2.0, 10.0).unwrap();
        assert!((l.reachable_drop(0.1) - 0.05).abs() < 1e-12);
        assert!((l.reachable_drop(0.2) - 0.2).abs() < 1e-12);
        assert!((l.reachable_drop(0.5) - 0.8).abs() < 1e-12);
        assert_eq!(l.reachable_drop(-1.0), 0.0);
        // A full stop 1 → 0 (ending at ṡ = 0) takes 1/2 + 2/10 = 0.7 s. reachable_drop is the
        // drop by h with the rate still at −ṡ_max (no ramp-down): at 0.7 s 2·(0.7 − 0.1) = 1.2,
        // the stop's 1 plus the ramp-down's ṡ_max²/(2 s̈_max) = 4/20 = 0.2.
        assert!((l.full_stop_s() - 0.7).abs() < 1e-12);
        assert!((l.reachable_drop(0.7) - 1.2).abs() < 1e-12);
    }

    #[test]
    fn time_scale_reaches_its_target_within_its_limits() {
        let l = ScaleLimits::new(2.0, 10.0).unwrap();
        let mut ts = TimeScale::new(l);
        let dt = 0.002;
        let (mut prev_s, mut prev_rate) = (ts.s(), 0.0);
        let mut prev_tau = ts.tau();
        for k in 0..1000 {
            let target = if k < 500 { 0.2 } else { 1.0 };
            ts.step(target, dt);
            let rate = (ts.s() - prev_s) / dt;
            assert!(rate.abs() <= 2.0 + 1e-6, "rate {rate} at {k}");
            assert!(
                ((rate - prev_rate) / dt).abs() <= 10.0 * 1.01 + 1e-3 || k == 0,
                "accel at {k}"
            );
            assert!((0.0..=1.0).contains(&ts.s()));
            assert!(ts.tau() >= prev_tau, "τ never goes back");
            prev_tau = ts.tau();
            prev_s = ts.s();
            prev_rate = rate;
            if k == 499 {
                assert!((ts.s() - 0.2).abs() < 1e-9, "s = {}", ts.s());
            }
        }
        assert!((ts.s() - 1.0).abs() < 1e-9);
        assert_eq!(ts.errors(), 0);
    }

    #[test]
    fn scale_limits_keep_the_budgets() {
        // Q1 = 0.5 rad/s, Q2 = 2 rad/s², budgets 0.45 rad/s² and 9 rad/s³:
        // ṡ_max = min(0.45/0.5, 9/(6·2)) = min(0.9, 0.75) = 0.75; s̈_max = 9/(2·0.5) = 9.
        let l = scale_limits_for(0.5, 2.0, 0.45, 9.0, 10.0, 100.0);
        assert!((l.rate() - 0.75).abs() < 1e-12);
        assert!((l.accel() - 9.0).abs() < 1e-12);
        // A path at rest gets the caps.
        let l = scale_limits_for(0.0, 0.0, 0.45, 9.0, 4.0, 40.0);
        assert_eq!((l.rate(), l.accel()), (4.0, 40.0));
    }

    #[test]
    fn path_ends_at_rest_on_target_and_reports_its_maxima() {
        let limits = MotionLimits::ur5e_nominal();
        let mut path = Path::new(limits);
        let start = PathState::default();
        let target = [0.4, -0.3, 0.2, 0.0, 0.1, -0.2];
        path.plan(&start, &target, &limits, None).unwrap();
        let mut s = PathSample::default();
        path.sample(path.duration_s() + 1.0, &mut s);
        assert_eq!(s.position, target);
        assert_eq!(s.velocity, [0.0; 6]);
        assert!(path.max_velocity() <= std::f64::consts::PI + 1e-9);
        assert!(path.max_velocity() > 0.1);
        assert!(path.max_acceleration() <= std::f64::consts::PI + 1e-9);
        // A minimum duration stretches it.
        let fast = path.duration_s();
        path.plan(&start, &target, &limits, Some(fast * 2.0))
            .unwrap();
        assert!((path.duration_s() - 2.0 * fast).abs() < 1e-6);
    }
}
