//! The 500 Hz handover controller: task → jerk-limited path → time scaling → servo command.
//!
//! [`Controller::new`] allocates everything; [`Controller::step`] allocates nothing (checked by
//! `tests/controller_alloc.rs`) and never panics. One step:
//! 1. **Task**: [`HandoverTask::step`] with the TCP position (forward kinematics of the
//!    *measured* joints), whether the motion to the current target has finished, the operator's
//!    hands, and the adaptation's timing (start delay, wait-for-attention, attention on robot).
//! 2. **Path** ([`Path`]): when the target (the task phase), the adaptation's scales or C(t)
//!    change, a new jerk-limited path is planned from the current path state, so the executed
//!    velocity and acceleration stay continuous. Its limits are the planner's (velocity ×
//!    speed scale, acceleration × smoothness, jerk × smoothness²), kept inside the safety
//!    supervisor's ([`SafetyEnvelope`]): joint speed at the planning fraction of the
//!    supervisor's cap, and the TCP speed along the path under the planning fraction of the
//!    supervisor's TCP cap — its collaboration value (0.25 m/s) whenever C(t) holds, so a path
//!    planned for the approach already respects the cap that applies during it. Entering
//!    Approach sets the minimum approach duration; any later replan keeps the arrival time.
//! 3. **Time scaling** ([`TimeScale`], the approach of UR's speed slider and the ROS 2 scaled
//!    joint trajectory controller): the path is run at `s = dτ/dt ∈ [0, 1]`, itself a
//!    jerk-limited trajectory. Its target is the largest `s` from which every point of a
//!    lookahead along the path can still be slowed to its admissible scale in time
//!    ([`Envelope::admissible_scale`]: the supervisor's joint and TCP caps, perception
//!    staleness, and ISO/TS 15066 separation from every tracked body part to every arm capsule,
//!    with the operator's points predicted along their measured velocity). So the planner
//!    slows *before* a cap applies or a hand comes close, and in nominal operation the
//!    supervisor has nothing to correct. `ṡ_max` and `s̈_max` are chosen per path so the
//!    executed acceleration and jerk stay within the planner's limits (`path` module docs).
//! 4. **Command**: the path's position at τ ([`JointCommand::Servo`]); velocity `s q'` and
//!    acceleration `ṡ q' + s² q''` are kept for logging. When more than one control period
//!    elapsed since the last step (missed cycles on a loaded machine), the time scale advances
//!    by the elapsed time, so the command is where the motion should be now.
//! 5. **Override**: when the supervisor changed a command ([`Controller::command_overridden`]),
//!    the next step re-synchronises to the robot's *target* state (what its own servo or
//!    braking trajectory follows) and plans from there, with `s = 0` from rest: the motion
//!    continues from where the robot really is, without a jump and without fighting the stop.
//!
//! # Command: servoJ, not speedJ
//! The output is [`JointCommand::Servo`] with the commanded joint positions. A position command
//! closes the loop on position, so the arm ends exactly at the handover pose and drift from
//! integrating velocities cannot accumulate, and the supervisor can check positions directly.
//! The defaults are `lookahead_s = 0.05` s and `gain = 500`: a short lookahead keeps the lag
//! behind the (already jerk-limited, time-scaled) command small — about 50 ms, i.e. ≤ 0.16 rad
//! at π rad/s — so the separation monitoring acts on where the arm actually is; the gain is
//! mid-range of UR's [100, 2000] (ur_rtde's examples use 300; higher gains track tighter but ring
//! on a real arm). Both are configurable.
//!
//! When the robot cannot move (safety stop, program not PLAYING, arm not RUNNING) or its state
//! is not finite, the step outputs [`JointCommand::Stop`] at the nominal acceleration and
//! re-synchronises on the next usable state.
//!
//! # Example
//! ```
//! use adapt::controller::{Controller, ControllerConfig, MotionAdaptation, OperatorView};
//! use robot_io::sim::{SimConfig, SimRobot};
//! use robot_io::{JointCommand, Robot, RobotState};
//! let mut robot = SimRobot::new(SimConfig { initial_q_rad: adapt::task::IK_REFERENCE_Q_RAD, ..SimConfig::ur5e() })?;
//! let mut ctl = Controller::new(ControllerConfig::example())?;
//! let (mut state, mut cmd) = (RobotState::default(), JointCommand::Stop { decel: 1.0 });
//! ctl.start_handover();
//! for _ in 0..500 {
//!     robot.read_state(&mut state)?;
//!     ctl.step(state.timestamp_s, &state, &MotionAdaptation::default(), &OperatorView::default(), &mut cmd);
//!     robot.send(&cmd)?;
//!     robot.step();
//! }
//! assert_eq!(ctl.phase(), adapt::task::Phase::Fetch);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::time::Duration;

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use robot_io::geometry::{BodyPart, HumanBody, Torso};
use robot_io::kinematics::{ControlPoints, control_points, control_points_zeroed};
use robot_io::{JointCommand, Joints, RobotState, robot_mode, runtime_state};
use serde::Deserialize;

use crate::envelope::{
    Binding, Envelope, PlanningMargins, RawPlanningMargins, SafetyEnvelope, flange_speed_m_s,
};
use crate::otg::{MotionLimits, PlanStatus};
use crate::path::{
    PLAN_SAMPLES, Path, PathSample, PathState, ScaleLimits, TimeScale, scale_limits_for,
};
use crate::task::{
    EventBuffer, HandoverTask, Phase, RawTaskConfig, TaskConfig, TaskEvent, TaskInput,
};
use crate::{AdaptError, Result};

/// Capacity of the per-step event buffer [events]; one step emits at most three.
pub const EVENT_CAPACITY: usize = 8;

/// A scale in (0, 1] [-] for the adaptation's speed (velocity limits and TCP cap).
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd)]
pub struct SpeedScale(f64);

/// A scale in (0, 1] [-] for the adaptation's smoothness: acceleration × s, jerk × s².
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd)]
pub struct SmoothnessScale(f64);

macro_rules! unit_scale {
    ($t:ident, $key:literal) => {
        impl $t {
            /// No scaling (1).
            pub const ONE: $t = $t(1.0);

            /// The most cautious scale a caller falls back to when a mapped value is invalid
            /// (fail closed) [-]: 0.1.
            pub const CAUTIOUS: $t = $t(0.1);

            /// A scale `x` [-].
            ///
            /// # Errors
            /// [`AdaptError::InvalidValue`] unless `0 < x ≤ 1`.
            pub fn new(x: f64) -> Result<$t> {
                if x.is_finite() && x > 0.0 && x <= 1.0 {
                    Ok($t(x))
                } else {
                    Err(AdaptError::InvalidValue {
                        key: $key.to_owned(),
                        rule: format!("must be finite and in (0, 1], got {x}"),
                    })
                }
            }

            /// The value [-] in (0, 1].
            pub fn get(self) -> f64 {
                self.0
            }
        }

        impl Default for $t {
            fn default() -> $t {
                $t::ONE
            }
        }
    };
}

unit_scale!(SpeedScale, "speed_scale");
unit_scale!(SmoothnessScale, "smoothness_scale");

/// How the motion adapts to the operator this cycle: the binary maps a policy's output onto
/// it. Every field is valid by construction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionAdaptation {
    /// Joint velocity limits and the TCP speed cap are multiplied by this.
    pub speed_scale: SpeedScale,
    /// Acceleration limits × s, jerk limits × s² (smoother and slower to build up speed).
    pub smoothness_scale: SmoothnessScale,
    /// Hold the gripped part this long before the handover starts.
    pub start_delay: Duration,
    /// The approach to the handover pose takes at least this long (zero: time-optimal).
    pub min_approach_duration: Duration,
    /// Wait for the operator's attention before the approach.
    pub wait_for_attention: bool,
    /// The operator's attention is on the robot now (from the assessment).
    pub attention_on_robot: bool,
    /// Present the part this long before returning it (`None`: the task config's
    /// `present_timeout_s`); taken when a presentation starts.
    pub present_timeout: Option<Duration>,
}

impl Default for MotionAdaptation {
    /// Nominal: full speed and smoothness scale, no delays, no attention gating.
    fn default() -> Self {
        MotionAdaptation {
            speed_scale: SpeedScale::ONE,
            smoothness_scale: SmoothnessScale::ONE,
            start_delay: Duration::ZERO,
            min_approach_duration: Duration::ZERO,
            wait_for_attention: false,
            attention_on_robot: true,
            present_timeout: None,
        }
    }
}

/// What the controller knows of the operator this cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OperatorView {
    /// The operator's tracked body in the robot base frame (untracked parts `None`; a
    /// non-finite value makes the time scale brake to 0).
    pub body: HumanBody,
    /// Age of the perception frame the body comes from [s] (the supervisor's staleness limits
    /// apply to it).
    pub perception_age_s: f64,
}

/// The controller's configuration as the config file gives it (`config/handover.toml`); see
/// [`ControllerConfig`] for the rules.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawControllerConfig {
    /// Control period [s].
    pub cycle_s: f64,
    /// Nominal joint velocity limit [rad/s] (all joints).
    pub max_velocity_rad_s: f64,
    /// Nominal joint acceleration limit [rad/s²] (all joints).
    pub max_acceleration_rad_s2: f64,
    /// Nominal joint jerk limit [rad/s³] (all joints).
    pub max_jerk_rad_s3: f64,
    /// TCP speed cap at speed scale 1 [m/s].
    pub max_tcp_speed_m_s: f64,
    /// servoJ lookahead [s].
    pub servo_lookahead_s: f64,
    /// servoJ gain [-].
    pub servo_gain: f64,
    /// Arrival: every joint within this of the target [rad].
    pub settle_tolerance_rad: f64,
    /// Arrival: every joint slower than this [rad/s].
    pub settle_speed_rad_s: f64,
    /// TCP offset from the flange, in the flange frame [m].
    pub tool_offset_m: [f64; 3],
    /// The handover task.
    pub task: RawTaskConfig,
    /// How far inside the safety supervisor's limits the planner stays.
    pub planning: RawPlanningMargins,
}

/// The file layout of `config/handover.toml`: a single `[controller]` table.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawHandoverFile {
    /// The controller, with its task and planning tables.
    pub controller: RawControllerConfig,
}

/// The validated controller configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerConfig {
    /// Control period [s], in (0, 0.1].
    pub cycle_s: f64,
    /// Nominal limits (velocity [rad/s], acceleration [rad/s²], jerk [rad/s³]) before the
    /// adaptation scales them: the planner's own limits.
    pub limits: MotionLimits,
    /// TCP speed cap at speed scale 1 [m/s], > 0 (UR5e: 1 m/s).
    pub max_tcp_speed_m_s: f64,
    /// servoJ lookahead [s], in [0.03, 0.2].
    pub servo_lookahead_s: f64,
    /// servoJ gain [-], in [100, 2000].
    pub servo_gain: f64,
    /// Arrival tolerance on every joint [rad], > 0.
    pub settle_tolerance_rad: f64,
    /// Arrival speed on every joint [rad/s], > 0.
    pub settle_speed_rad_s: f64,
    /// TCP offset from the flange, in the flange frame [m] (finite).
    pub tool_offset_m: [f64; 3],
    /// The handover task.
    pub task: TaskConfig,
    /// The safety supervisor's limits, which the plan stays inside (the binary sets them from
    /// the supervisor's configuration; the default is [`SafetyEnvelope::ur5e`]).
    pub envelope: SafetyEnvelope,
    /// The margins inside them.
    pub planning: PlanningMargins,
}

impl ControllerConfig {
    /// UR5e defaults around [`TaskConfig::example`]: 2 ms, π rad/s, π rad/s², 10π rad/s³,
    /// TCP 1 m/s, servoJ lookahead 0.05 s and gain 500, arrival within 0.005 rad and below
    /// 0.02 rad/s, no tool offset, the UR5e supervisor envelope and default margins.
    pub fn example() -> ControllerConfig {
        ControllerConfig {
            cycle_s: crate::otg::UR5E_CYCLE_S,
            limits: MotionLimits::ur5e_nominal(),
            max_tcp_speed_m_s: 1.0,
            servo_lookahead_s: 0.05,
            servo_gain: 500.0,
            settle_tolerance_rad: 0.005,
            settle_speed_rad_s: 0.02,
            tool_offset_m: [0.0; 3],
            task: TaskConfig::example(),
            envelope: SafetyEnvelope::ur5e(),
            planning: PlanningMargins::default(),
        }
    }

    /// Check every rule listed on the fields.
    pub fn validate(&self) -> Result<()> {
        let rule = |key: &str, ok: bool, what: &str, v: f64| {
            if ok {
                Ok(())
            } else {
                Err(AdaptError::InvalidValue {
                    key: key.to_owned(),
                    rule: format!("{what}, got {v}"),
                })
            }
        };
        let c = self.cycle_s;
        rule(
            "cycle_s",
            c.is_finite() && c > 0.0 && c <= 0.1,
            "must be in (0, 0.1]",
            c,
        )?;
        let v = self.max_tcp_speed_m_s;
        rule(
            "max_tcp_speed_m_s",
            v.is_finite() && v > 0.0,
            "must be finite and > 0",
            v,
        )?;
        let v = self.servo_lookahead_s;
        rule(
            "servo_lookahead_s",
            (0.03..=0.2).contains(&v),
            "must be in [0.03, 0.2]",
            v,
        )?;
        let v = self.servo_gain;
        rule(
            "servo_gain",
            (100.0..=2000.0).contains(&v),
            "must be in [100, 2000]",
            v,
        )?;
        let v = self.settle_tolerance_rad;
        rule(
            "settle_tolerance_rad",
            v.is_finite() && v > 0.0,
            "must be finite and > 0",
            v,
        )?;
        let v = self.settle_speed_rad_s;
        rule(
            "settle_speed_rad_s",
            v.is_finite() && v > 0.0,
            "must be finite and > 0",
            v,
        )?;
        for v in self.tool_offset_m {
            rule("tool_offset_m", v.is_finite(), "must be finite", v)?;
        }
        self.task.validate()
    }
}

impl TryFrom<&RawControllerConfig> for ControllerConfig {
    type Error = AdaptError;

    fn try_from(raw: &RawControllerConfig) -> Result<ControllerConfig> {
        let limits = MotionLimits::new(
            [raw.max_velocity_rad_s; 6],
            [raw.max_acceleration_rad_s2; 6],
            [raw.max_jerk_rad_s3; 6],
        )?;
        let cfg = ControllerConfig {
            cycle_s: raw.cycle_s,
            limits,
            max_tcp_speed_m_s: raw.max_tcp_speed_m_s,
            servo_lookahead_s: raw.servo_lookahead_s,
            servo_gain: raw.servo_gain,
            settle_tolerance_rad: raw.settle_tolerance_rad,
            settle_speed_rad_s: raw.settle_speed_rad_s,
            tool_offset_m: raw.tool_offset_m,
            task: TaskConfig::try_from(&raw.task)?,
            envelope: SafetyEnvelope::ur5e(),
            planning: PlanningMargins::try_from(raw.planning)?,
        };
        cfg.validate()?;
        Ok(cfg)
    }
}

/// Counters since construction.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ControllerStats {
    /// Steps run.
    pub steps: u64,
    /// Steps in which the time scale was below 1 (the plan ran slower than planned).
    pub scaled_steps: u64,
    /// Steps in which the time scale's own trajectory failed and a rate-limited ramp stood in.
    pub fallback_steps: u64,
    /// Plans that failed (the motion was then brought to rest along the old path).
    pub otg_errors: u64,
    /// Steps that output a stop because the robot could not move or its state was unusable.
    pub stop_steps: u64,
    /// Controller cycles that elapsed without a step (missed), whether caught up or, beyond
    /// the envelope's catch-up bound, not [-].
    pub missed_cycles: u64,
    /// Re-synchronisations to the robot's target state (start, after a stop or an override).
    pub resyncs: u64,
    /// Plans computed (targets, limit changes and re-synchronisations).
    pub plans: u64,
}

/// What set the time scale's target in the last step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaleReport {
    /// The time scale s [-] after the step.
    pub scale: f64,
    /// The target it moved toward [-].
    pub target: f64,
    /// The admissible scale now, at the current path point [-].
    pub admissible_now: f64,
    /// The limit that bound the target (at the most restrictive lookahead sample).
    pub binding: Binding,
    /// Smallest body-to-arm surface distance now [m] (∞ with nobody tracked).
    pub min_distance_m: f64,
}

/// Lookahead samples along the path for the time-scale target [-].
const LOOKAHEAD_SAMPLES: usize = 10;
/// Share of the reachable drop of `s` the lookahead counts on [-] (the rest is margin for a
/// rate that is still rising).
const DROP_SHARE: f64 = 0.7;
/// The path's own acceleration and jerk as fractions of the planner's (the rest is the time
/// scale's budget, see `path`'s module docs) [-].
const PATH_ACC_SHARE: f64 = 0.6;
const PATH_JERK_SHARE: f64 = 0.6;
/// Executed acceleration stays below this share of the supervisor's acceleration cap [-].
const SUPERVISOR_ACC_SHARE: f64 = 0.95;
/// Iterations that shrink the path's velocity limit until its TCP speed meets the cap.
const TCP_PLAN_ITERATIONS: usize = 4;
/// A reduction of the time scale's target holds this long before the target may rise [s].
const TARGET_HOLD_S: f64 = 0.6;
/// How long the robot must stand settled at a target before the motion counts as finished
/// [s].
const SETTLE_DWELL_S: f64 = 0.25;
/// A robot whose target joint speeds are all below this is at rest for a re-synchronisation
/// [rad/s].
const REST_SPEED_RAD_S: f64 = 1e-3;

/// Tracks the operator's points between perception frames: last position and a smoothed
/// velocity per point, for the lookahead's prediction. Allocates nothing.
#[derive(Debug, Clone, Copy, Default)]
struct HumanTracker {
    points: [TrackedPoint; 4],
    torso_normal: Option<[f64; 3]>,
}

#[derive(Debug, Clone, Copy, Default)]
struct TrackedPoint {
    last: Option<[f64; 3]>,
    since_s: f64,
    velocity: [f64; 3],
    /// When the point was last tracked [s].
    seen_s: f64,
    /// Whether it is tracked now (else `last` is held for [`HOLD_LOST_S`]).
    tracked: bool,
}

/// How long the planner keeps a body point that perception lost at its last position [s]: a
/// hand that drops out for a moment and comes back where it was must not surprise the time
/// scale (the supervisor, independently, watches only what is tracked).
const HOLD_LOST_S: f64 = 1.0;
/// Share of a new velocity sample taken into a body point's smoothed velocity (per perception
/// frame) [-].
const VELOCITY_SMOOTHING: f64 = 0.3;
/// A body point slower than this is not extrapolated [m/s].
const VELOCITY_DEAD_BAND_M_S: f64 = 0.15;
/// A body point is extrapolated along its velocity at most this far ahead [s].
const PREDICTION_HORIZON_S: f64 = 0.5;

impl TrackedPoint {
    fn update(&mut self, p: Option<[f64; 3]>, now: f64, max_speed: f64) {
        let Some(p) = p.filter(|p| p.iter().all(|v| v.is_finite())) else {
            if self.tracked {
                self.tracked = false;
                self.velocity = [0.0; 3];
            }
            if now - self.seen_s > HOLD_LOST_S {
                *self = TrackedPoint::default();
            }
            return;
        };
        self.tracked = true;
        self.seen_s = now;
        match self.last {
            Some(last) if last != p => {
                let dt = now - self.since_s;
                if dt > 1e-6 && dt < 0.5 {
                    let mut v = [0.0; 3];
                    for ((v, a), b) in v.iter_mut().zip(&p).zip(&last) {
                        *v = (a - b) / dt;
                    }
                    let speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                    if speed > max_speed {
                        for x in &mut v {
                            *x *= max_speed / speed;
                        }
                    }
                    for (s, n) in self.velocity.iter_mut().zip(v) {
                        *s += VELOCITY_SMOOTHING * (n - *s);
                    }
                } else {
                    self.velocity = [0.0; 3];
                }
                self.last = Some(p);
                self.since_s = now;
            }
            Some(_) => {}
            None => {
                self.last = Some(p);
                self.since_s = now;
                self.velocity = [0.0; 3];
            }
        }
    }

    /// Whether the point is extrapolated along its velocity (perception jitter is not motion:
    /// below the dead band the point is taken as still).
    fn extrapolates(&self) -> bool {
        let v = self.velocity;
        self.last.is_some()
            && (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() >= VELOCITY_DEAD_BAND_M_S
    }

    fn predict(&self, h_s: f64) -> Option<[f64; 3]> {
        let v = self.velocity;
        let h = if self.extrapolates() {
            h_s.clamp(0.0, PREDICTION_HORIZON_S)
        } else {
            0.0
        };
        self.last
            .map(|p| [p[0] + v[0] * h, p[1] + v[1] * h, p[2] + v[2] * h])
    }
}

impl HumanTracker {
    /// Whether any point is extrapolated (else every prediction is the body as it is now).
    fn any_extrapolated(&self) -> bool {
        self.points.iter().any(TrackedPoint::extrapolates)
    }

    fn update(&mut self, body: &HumanBody, now: f64, envelope: &SafetyEnvelope) {
        let sep = envelope.separation();
        let [head, left, right, torso] = &mut self.points;
        head.update(body.head_m, now, sep.human_speed_m_s(BodyPart::Head));
        left.update(
            body.left_hand_m,
            now,
            sep.human_speed_m_s(BodyPart::LeftHand),
        );
        right.update(
            body.right_hand_m,
            now,
            sep.human_speed_m_s(BodyPart::RightHand),
        );
        torso.update(
            body.torso.map(|t| t.shoulder_mid_m),
            now,
            sep.human_speed_m_s(BodyPart::Torso),
        );
    }

    /// The body as the planner takes it now: tracked points as given, lost ones held at their
    /// last position for [`HOLD_LOST_S`]; the torso's normal is remembered with it.
    fn effective(&mut self, body: &HumanBody) -> HumanBody {
        if let Some(t) = body.torso {
            self.torso_normal = Some(t.normal);
        }
        self.predict(0.0)
    }

    /// The body `h_s` [s] ahead (points moved along their smoothed velocity).
    fn predict(&self, h_s: f64) -> HumanBody {
        let [head, left, right, torso] = &self.points;
        HumanBody {
            head_m: head.predict(h_s),
            left_hand_m: left.predict(h_s),
            right_hand_m: right.predict(h_s),
            torso: torso.predict(h_s).map(|p| Torso {
                shoulder_mid_m: p,
                normal: self.torso_normal.unwrap_or([1.0, 0.0, 0.0]),
            }),
        }
    }
}

/// The 500 Hz controller (see the module docs).
#[derive(Debug)]
pub struct Controller {
    cfg: ControllerConfig,
    task: HandoverTask,
    events: EventBuffer<EVENT_CAPACITY>,
    path: Path,
    scale: TimeScale,
    envelope: Envelope,
    humans: HumanTracker,
    /// The path at the current path time.
    sample: PathSample,
    lookahead: PathSample,
    points: ControlPoints,
    tool: Isometry3<f64>,
    /// Commanded joint positions [rad], velocities [rad/s] and accelerations [rad/s²].
    q_cmd: Joints,
    qd_cmd: Joints,
    qdd_cmd: Joints,
    /// The command of the cycle before [rad] (a supervisor's reduction scales the step from it).
    q_cmd_prev: Joints,
    /// The supervisor reduced the last command by this scale [-]: re-plan from what was sent.
    reduced_by: Option<f64>,
    synced: bool,
    /// The target given to the path [rad].
    target: Option<Joints>,
    /// Absolute arrival time the current approach must not beat [s].
    arrive_not_before_s: Option<f64>,
    /// The adaptation scales behind the path limits in force.
    applied_scales: (f64, f64),
    /// The adaptation's scales of the latest step (the next path's).
    wanted_scales: (f64, f64),
    /// C(t) when the current path was planned (its TCP cap).
    planned_collaborating: bool,
    last_plan: PlanStatus,
    last_now_s: Option<f64>,
    /// Since when the robot stands settled at its target [s].
    settled_since_s: Option<f64>,
    /// The time scale's target held since a reduction: (target [-], since [s]).
    held_target: Option<(f64, f64)>,
    /// After a supervisor stop: brake to rest before re-synchronising.
    brake_first: bool,
    report: ScaleReport,
    stats: ControllerStats,
}

impl Controller {
    /// Build the controller: validates `cfg` and allocates everything the steps use.
    ///
    /// # Errors
    /// [`AdaptError::InvalidValue`] (and the trajectory set-up errors) for a bad config.
    pub fn new(cfg: ControllerConfig) -> Result<Controller> {
        cfg.validate()?;
        let [x, y, z] = cfg.tool_offset_m;
        let initial_scale = ScaleLimits::new(
            cfg.planning.get().max_scale_rate_per_s,
            cfg.planning.get().max_scale_accel_per_s2,
        )?;
        Ok(Controller {
            task: HandoverTask::new(cfg.task),
            events: EventBuffer::new(),
            path: Path::new(cfg.limits),
            scale: TimeScale::new(initial_scale),
            envelope: Envelope::new(cfg.envelope, cfg.planning),
            humans: HumanTracker::default(),
            sample: PathSample::default(),
            lookahead: PathSample::default(),
            points: control_points_zeroed(),
            tool: Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::identity()),
            q_cmd: [0.0; 6],
            qd_cmd: [0.0; 6],
            qdd_cmd: [0.0; 6],
            q_cmd_prev: [0.0; 6],
            reduced_by: None,
            synced: false,
            target: None,
            arrive_not_before_s: None,
            applied_scales: (1.0, 1.0),
            wanted_scales: (1.0, 1.0),
            planned_collaborating: false,
            last_plan: PlanStatus::Finished,
            last_now_s: None,
            settled_since_s: None,
            held_target: None,
            brake_first: false,
            report: ScaleReport {
                scale: 1.0,
                target: 1.0,
                admissible_now: 1.0,
                binding: Binding::None,
                min_distance_m: f64::INFINITY,
            },
            stats: ControllerStats::default(),
            cfg,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &ControllerConfig {
        &self.cfg
    }

    /// Arm the handover: the next step leaves Idle (see [`HandoverTask::start`]).
    pub fn start_handover(&mut self) {
        self.task.start();
    }

    /// After Done: back to Idle for another handover ([`HandoverTask::reset`]).
    pub fn reset_task(&mut self) {
        self.task.reset();
    }

    /// The handover task (phase, context, config).
    pub fn task(&self) -> &HandoverTask {
        &self.task
    }

    /// The task phase.
    pub fn phase(&self) -> Phase {
        self.task.phase()
    }

    /// C(t): a collaboration period is active (Approach, Present, Release).
    pub fn collaborating(&self) -> bool {
        self.task.collaborating()
    }

    /// G(t): the handover is incomplete (release not confirmed).
    pub fn incomplete(&self) -> bool {
        self.task.incomplete()
    }

    /// Task events of the last step, with their timestamps [s].
    pub fn events(&self) -> &[TaskEvent] {
        self.events.as_slice()
    }

    /// The trajectory status of the last step (Finished once the path's end is reached).
    pub fn last_plan_status(&self) -> PlanStatus {
        self.last_plan
    }

    /// The time scale of the last step and what bound it.
    pub fn scale_report(&self) -> &ScaleReport {
        &self.report
    }

    /// The planner's jerk limit in force [rad/s³] (largest over the joints): the nominal jerk
    /// × smoothness², which the executed motion stays within (see `path`'s module docs).
    pub fn jerk_limit_rad_s3(&self) -> f64 {
        let smooth = self.applied_scales.1;
        self.cfg
            .limits
            .max_jerk()
            .iter()
            .fold(0.0_f64, |m, j| m.max(*j))
            * smooth
            * smooth
    }

    /// The commanded joint positions of the last step [rad].
    pub fn commanded_position(&self) -> &Joints {
        &self.q_cmd
    }

    /// The commanded joint velocities of the last step [rad/s] (s · q'(τ)).
    pub fn commanded_velocity(&self) -> &Joints {
        &self.qd_cmd
    }

    /// The commanded joint accelerations of the last step [rad/s²] (ṡ q' + s² q'').
    pub fn commanded_acceleration(&self) -> &Joints {
        &self.qdd_cmd
    }

    /// The control points (TCP, wrist, elbow) of the last step, at the measured joints.
    pub fn control_points(&self) -> &ControlPoints {
        &self.points
    }

    /// Counters since construction.
    pub fn stats(&self) -> &ControllerStats {
        &self.stats
    }

    /// Tells the controller that its last command was replaced by a stop (the safety
    /// supervisor stopped or halted the robot): the next steps let the robot finish braking,
    /// then re-synchronise to its target state and re-plan from rest, so the motion continues
    /// from where the robot really is instead of fighting the supervisor.
    pub fn command_overridden(&mut self) {
        self.synced = false;
        self.brake_first = true;
    }

    /// Tells the controller that the supervisor sent its last command with the step from the
    /// command before scaled by `scale` [-] (a reduction, or > 1 for a deceleration held at the
    /// limit): the next step re-plans, while moving and without braking (a reduction is no
    /// stop), from what was sent — the scaled position, at the scaled velocity. Not from the
    /// robot's reported target, which lags the servo command by the servo's smoothing (about
    /// v·lookahead, 0.02 rad at 0.4 rad/s and 50 ms): starting there would command a step back.
    pub fn command_reduced(&mut self, scale: f64) {
        self.synced = false;
        self.reduced_by = (scale.is_finite() && scale >= 0.0).then_some(scale);
    }

    /// One cycle at time `now_s` [s] (the controller timestamp of `state`; a non-finite value
    /// advances the last time by one cycle): read `state`, run task → path → time scaling, write
    /// `out`. When more than one control period has passed since the last step (missed cycles),
    /// the plan is advanced by the elapsed time, so the command is where the motion should be
    /// now. Allocates nothing, never panics.
    pub fn step(
        &mut self,
        now_s: f64,
        state: &RobotState,
        adaptation: &MotionAdaptation,
        view: &OperatorView,
        out: &mut JointCommand,
    ) {
        let humans = &view.body;
        let cycle = self.cfg.cycle_s;
        let (now, elapsed) = match self.last_now_s {
            None => (if now_s.is_finite() { now_s } else { 0.0 }, 1.0),
            Some(last) => {
                // At least one cycle on, by the rule the supervisor judges the step by (a
                // late sample that a cycle already ran for is the next cycle, not this one
                // again: comparing with `last` itself made that depend on rounding, and the
                // plan ran a cycle ahead of the supervisor's clock).
                let now = robot_io::cycle_time_s(last, now_s, cycle);
                (now, (now - last) / cycle)
            }
        };
        // Every missed cycle is counted, also those beyond the catch-up bound.
        let missed = (elapsed.round() - 1.0).max(0.0) as u64;
        self.stats.missed_cycles = self.stats.missed_cycles.saturating_add(missed);
        // The plan advances by the elapsed time, as the supervisor judges it, but at most the
        // envelope's catch-up bound (the robot's servo extrapolation + 1, the longest the
        // supervisor judges a step over): a longer gap delays the plan, as the robot held its
        // target, instead of making the next target a jump.
        let elapsed = elapsed.clamp(1.0, f64::from(self.cfg.envelope.catch_up_cycles()));
        self.last_now_s = Some(now);
        self.stats.steps = self.stats.steps.saturating_add(1);
        self.events.clear();
        self.humans.update(humans, now, &self.cfg.envelope);

        let state_ok = state
            .actual_q
            .iter()
            .chain(&state.actual_qd)
            .chain(&state.target_q)
            .chain(&state.target_qd)
            .all(|v| v.is_finite());
        let can_move = state_ok
            && !state.is_safety_stopped()
            && state.robot_mode == robot_mode::RUNNING
            && state.runtime_state == runtime_state::PLAYING;

        // Control points at the measured joints (the last good ones if the state is unusable).
        let q_meas = if state_ok { state.actual_q } else { self.q_cmd };
        control_points(&q_meas, &self.tool, &mut self.points);

        // 1. Task.
        let finished = can_move && self.arrived(state, now);
        let hand = |h: Option<[f64; 3]>| h.filter(|p| p.iter().all(|v| v.is_finite()));
        let tcp = self
            .points
            .first()
            .map_or([0.0; 3], |p| [p.position.x, p.position.y, p.position.z]);
        let input = TaskInput {
            now_s: now,
            tcp_position_m: tcp,
            motion_finished: finished,
            hands_m: [hand(humans.left_hand_m), hand(humans.right_hand_m)],
            wait_for_attention: adaptation.wait_for_attention,
            attention_on_robot: adaptation.attention_on_robot,
            start_delay_s: adaptation.start_delay.as_secs_f64(),
            present_timeout_s: adaptation.present_timeout.map(|d| d.as_secs_f64()),
        };
        self.task.step(&input, &mut self.events);

        if !can_move {
            self.stats.stop_steps = self.stats.stop_steps.saturating_add(1);
            self.synced = false;
            self.qd_cmd = [0.0; 6];
            self.qdd_cmd = [0.0; 6];
            *out = JointCommand::Stop {
                decel: self.max_acceleration(),
            };
            return;
        }

        // 2. Path: limits, target and the collaboration cap it was planned under.
        let scales = (
            adaptation.speed_scale.get(),
            adaptation.smoothness_scale.get(),
        );
        let collaborating = self.task.collaborating();
        let mut replan = false;
        // New adaptation scales shape the next path; a path under way keeps its limits (a
        // re-plan mid-motion under other limits can turn a joint back), except that a lower
        // speed scale applies at once through the time scale (below).
        self.wanted_scales = scales;
        if scales != self.applied_scales && self.last_plan == PlanStatus::Finished {
            replan = true;
        }
        if collaborating != self.planned_collaborating {
            replan = true;
        }
        let wanted = self.task.target_q_rad().copied();
        if wanted != self.target {
            self.target = wanted;
            let min = adaptation.min_approach_duration.as_secs_f64();
            self.arrive_not_before_s =
                (self.task.phase() == Phase::Approach && min.is_finite() && min > 0.0)
                    .then_some(now + min);
            replan = true;
        }
        // A path that starts at rest may start at any scale (the executed velocity s·q' and
        // acceleration s²q'' are 0 either way): it starts at the lookahead's target instead of
        // having to ramp down to it.
        let mut from_rest = false;
        if !self.synced {
            let moving = state.target_qd.iter().any(|v| v.abs() > REST_SPEED_RAD_S);
            if !moving {
                self.brake_first = false;
            }
            if moving && self.brake_first {
                // Overridden while moving: let the robot finish braking (our own stop, at the
                // supervisor's deceleration) and resume from rest, instead of re-accelerating
                // into the limit that just stopped it.
                self.qd_cmd = state.target_qd;
                self.qdd_cmd = [0.0; 6];
                *out = JointCommand::Stop {
                    decel: self.cfg.envelope.stop_deceleration_rad_s2(),
                };
                return;
            }
            from_rest = match self.reduced_by.take() {
                Some(scale) if moving => self.resync_to_sent(scale, now),
                _ => self.resync(state, now),
            };
        } else if replan {
            // A new path from where the current one is now (path coordinates): the executed
            // velocity s·q' and acceleration ṡq' + s²q'' stay continuous.
            let start = PathState {
                position: self.sample.position,
                velocity: self.sample.velocity,
                acceleration: self.sample.acceleration,
            };
            from_rest = start
                .velocity
                .iter()
                .chain(&start.acceleration)
                .all(|x| *x == 0.0);
            self.plan_from(&start, now);
        }

        // 3. Time scaling: the largest target the lookahead allows, then one jerk-limited step.
        let mut raw_target = self.scale_target(humans, view.perception_age_s, collaborating);
        // A speed scale lowered during a motion applies through the time scale.
        let speed_ratio = self.wanted_scales.0 / self.applied_scales.0;
        if speed_ratio < raw_target {
            raw_target = speed_ratio;
        }
        // Hold a reduction for TARGET_HOLD_S before the target may rise again, so noise in the
        // operator's tracked points never makes the speed pump (stop-and-go); a lower target
        // always applies at once.
        let s_target = match self.held_target {
            Some((held, since)) if raw_target >= held && now - since < TARGET_HOLD_S => held,
            _ => {
                self.held_target = Some((raw_target, now));
                raw_target
            }
        };
        if from_rest {
            self.scale.reset(0.0, s_target);
        }
        self.scale.step(s_target, elapsed * cycle);
        let s = self.scale.s();
        let s_dot = self.scale.s_dot();
        let tau = self.scale.tau();
        self.path.sample(tau, &mut self.sample);
        self.last_plan = if tau >= self.path.duration_s() {
            PlanStatus::Finished
        } else {
            PlanStatus::Working
        };
        if s < 1.0 - 1e-9 && self.last_plan == PlanStatus::Working {
            self.stats.scaled_steps = self.stats.scaled_steps.saturating_add(1);
        }
        self.stats.fallback_steps = self.scale.errors();
        self.report.scale = s;
        self.report.target = s_target;

        // 4. Command.
        self.q_cmd_prev = self.q_cmd;
        for i in 0..6 {
            let (Some(q), Some(v), Some(a), Some(p), Some(pv), Some(pa)) = (
                self.q_cmd.get_mut(i),
                self.qd_cmd.get_mut(i),
                self.qdd_cmd.get_mut(i),
                self.sample.position.get(i),
                self.sample.velocity.get(i),
                self.sample.acceleration.get(i),
            ) else {
                continue;
            };
            *q = *p;
            *v = s * pv;
            *a = s_dot * pv + s * s * pa;
        }
        let limit = crate::otg::UR5E_JOINT_LIMIT_RAD;
        for q in &mut self.q_cmd {
            *q = q.clamp(-limit, limit);
        }
        *out = JointCommand::Servo {
            q: self.q_cmd,
            lookahead_s: self.cfg.servo_lookahead_s,
            gain: self.cfg.servo_gain,
        };
    }

    /// The nominal acceleration limit of the slowest joint [rad/s²].
    fn max_acceleration(&self) -> f64 {
        self.cfg
            .limits
            .max_acceleration()
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
    }

    /// Whether the robot stands at the current target: path finished, every joint within the
    /// settle tolerance and slower than the settle speed, continuously for [`SETTLE_DWELL_S`]
    /// (so the servo's lag has died out before the next motion starts: no direction reversal
    /// on a still-moving arm).
    fn arrived(&mut self, state: &RobotState, now: f64) -> bool {
        let settled = match self.task.target_q_rad() {
            None => false,
            Some(target) => {
                self.synced
                    && self.target.as_ref() == Some(target)
                    && self.last_plan == PlanStatus::Finished
                    && state
                        .actual_q
                        .iter()
                        .zip(target)
                        .all(|(q, t)| (q - t).abs() <= self.cfg.settle_tolerance_rad)
                    && state
                        .actual_qd
                        .iter()
                        .all(|v| v.abs() <= self.cfg.settle_speed_rad_s)
            }
        };
        if !settled {
            self.settled_since_s = None;
            return false;
        }
        let since = *self.settled_since_s.get_or_insert(now);
        now - since >= SETTLE_DWELL_S - 1e-9
    }

    /// Start again from the robot's own target state (what its servo loop follows: after a
    /// stop it is the robot's braking trajectory), so the first command continues it.
    /// Returns whether the robot is at rest (its target velocity is 0).
    fn resync(&mut self, state: &RobotState, now: f64) -> bool {
        self.stats.resyncs = self.stats.resyncs.saturating_add(1);
        let start = PathState {
            position: state.target_q,
            velocity: state.target_qd,
            acceleration: [0.0; 6],
        };
        let moving = state.target_qd.iter().any(|v| v.abs() > 1e-3);
        self.q_cmd = state.target_q;
        self.qd_cmd = state.target_qd;
        self.qdd_cmd = [0.0; 6];
        self.plan_from(&start, now);
        // A moving robot continues at s = 1 (the path starts at its velocity); from rest the
        // step starts the scale at its target.
        self.scale.reset(0.0, if moving { 1.0 } else { 0.0 });
        self.path.sample(0.0, &mut self.sample);
        self.synced = true;
        !moving
    }

    /// After a reduction by `scale`: start again from the command the supervisor sent (the
    /// step from the command before, scaled) at the scaled velocity, so the first command
    /// continues what the robot was told. Returns false (moving).
    fn resync_to_sent(&mut self, scale: f64, now: f64) -> bool {
        self.stats.resyncs = self.stats.resyncs.saturating_add(1);
        let mut start = PathState {
            position: self.q_cmd,
            velocity: self.qd_cmd,
            acceleration: [0.0; 6],
        };
        for i in 0..6 {
            let (Some(p), Some(v), Some(prev)) = (
                start.position.get_mut(i),
                start.velocity.get_mut(i),
                self.q_cmd_prev.get(i),
            ) else {
                continue;
            };
            *p = prev + scale * (*p - prev);
            *v *= scale;
        }
        self.q_cmd = start.position;
        self.qd_cmd = start.velocity;
        self.qdd_cmd = [0.0; 6];
        self.plan_from(&start, now);
        // The path starts at the sent velocity: it continues at s = 1.
        self.scale.reset(0.0, 1.0);
        self.path.sample(0.0, &mut self.sample);
        self.synced = true;
        false
    }

    /// Plan a new path from `start` (path coordinates) to the target (or to rest where it is,
    /// without one), under the adaptation's limits and the TCP cap of the current phase;
    /// restart path time at 0, keeping the scale and its rate.
    fn plan_from(&mut self, start: &PathState, now: f64) {
        self.stats.plans = self.stats.plans.saturating_add(1);
        let collaborating = self.task.collaborating();
        self.planned_collaborating = collaborating;
        let target = self.target.unwrap_or(start.position);
        let min = self
            .arrive_not_before_s
            .map(|t| t - now)
            .filter(|r| *r > 0.0);
        self.applied_scales = self.wanted_scales;
        let (speed, smooth) = self.applied_scales;
        let env = self.cfg.envelope;
        let fraction = self.cfg.planning.get().speed_fraction;
        // The path's own limits: the adaptation's share of the planner's limits, inside the
        // supervisor's, leaving the time scale its acceleration and jerk budget.
        let v_cap = fraction * env.joint_speed_rad_s();
        let a_cap = SUPERVISOR_ACC_SHARE * env.joint_acceleration_rad_s2();
        let mut v = [0.0; 6];
        let mut a = [0.0; 6];
        let mut j = [0.0; 6];
        for i in 0..6 {
            let (Some(v), Some(a), Some(j), Some(nv), Some(na), Some(nj)) = (
                v.get_mut(i),
                a.get_mut(i),
                j.get_mut(i),
                self.cfg.limits.max_velocity().get(i),
                self.cfg.limits.max_acceleration().get(i),
                self.cfg.limits.max_jerk().get(i),
            ) else {
                continue;
            };
            *v = (nv * speed).min(v_cap);
            *a = PATH_ACC_SHARE * (na * smooth).min(a_cap);
            *j = PATH_JERK_SHARE * nj * smooth * smooth;
        }
        let tcp_cap = self
            .envelope
            .planned_tcp_cap_m_s(collaborating)
            .min(self.cfg.max_tcp_speed_m_s * speed);
        let mut ok = false;
        for _ in 0..TCP_PLAN_ITERATIONS {
            let Ok(limits) = MotionLimits::new(v, a, j) else {
                break;
            };
            if self.path.plan(start, &target, &limits, min).is_err() {
                break;
            }
            ok = true;
            let peak = self.peak_tcp_speed();
            // A NaN peak (non-finite kinematics) also ends the loop: the plan stands and the
            // time scale's own TCP check applies.
            if peak.partial_cmp(&tcp_cap) != Some(std::cmp::Ordering::Greater) {
                break;
            }
            // Shrink the velocity limits by the overshoot (with a 5 % margin) and plan again.
            let k = 0.95 * tcp_cap / peak;
            for x in &mut v {
                *x = (*x * k).max(1e-3);
            }
        }
        if !ok {
            self.stats.otg_errors = self.stats.otg_errors.saturating_add(1);
        }
        self.scale.set_tau(0.0);
        // The time scale's limits for this path (the `path` module docs' budgets).
        let jerk_limit = self.jerk_limit_rad_s3();
        let acc_limit = self
            .cfg
            .limits
            .max_acceleration()
            .iter()
            .fold(f64::INFINITY, |m, x| m.min(*x))
            * smooth;
        let acc_budget = (a_cap.min(acc_limit) * (1.0 - PATH_ACC_SHARE)).max(1e-6);
        let jerk_budget = (jerk_limit * (1.0 - PATH_JERK_SHARE)).max(1e-6);
        let planning = self.cfg.planning.get();
        self.scale.set_limits(scale_limits_for(
            self.path.max_velocity(),
            self.path.max_acceleration(),
            acc_budget,
            jerk_budget,
            planning.max_scale_rate_per_s,
            planning.max_scale_accel_per_s2,
        ));
    }

    /// The largest flange speed along the current path at s = 1 [m/s] (sampled).
    fn peak_tcp_speed(&mut self) -> f64 {
        let d = self.path.duration_s();
        let mut peak = 0.0_f64;
        for k in 0..=PLAN_SAMPLES {
            let tau = d * k as f64 / PLAN_SAMPLES as f64;
            self.path.sample(tau, &mut self.lookahead);
            let u = flange_speed_m_s(&self.lookahead.position, &self.lookahead.velocity);
            peak = peak.max(if u.is_finite() { u } else { f64::INFINITY });
        }
        peak
    }

    /// The time scale's target: the largest `s` from which every lookahead sample's admissible
    /// scale can still be reached in time (`s_k + reachable drop within h_k`), at most 1.
    fn scale_target(
        &mut self,
        humans: &HumanBody,
        perception_age_s: f64,
        collaborating: bool,
    ) -> f64 {
        let age = if perception_age_s.is_finite() {
            perception_age_s.max(0.0)
        } else {
            f64::INFINITY
        };
        let limits = *self.scale.limits();
        let horizon = (limits.full_stop_s() * 1.25).clamp(0.25, 2.0);
        let tau0 = self.scale.tau();
        let now_body = self.humans.effective(humans);
        // With no point extrapolated, the predicted body is the body now: evaluate it once.
        let moving = self.humans.any_extrapolated();
        let mut target = 1.0_f64;
        let mut binding = Binding::None;
        for k in 0..=LOOKAHEAD_SAMPLES {
            let h = horizon * k as f64 / LOOKAHEAD_SAMPLES as f64;
            // Conservative: the path ahead as if it ran at full speed.
            self.path.sample(tau0 + h, &mut self.lookahead);
            // The operator as now and as predicted along their velocity, whichever binds: a
            // point moving away is never counted on.
            let q = self.lookahead.position;
            let qd = self.lookahead.velocity;
            let mut a = self
                .envelope
                .admissible_scale(&q, &qd, &now_body, age, collaborating);
            if k > 0 && moving {
                let body = self.humans.predict(h);
                let p = self
                    .envelope
                    .admissible_scale(&q, &qd, &body, age, collaborating);
                if p.scale < a.scale {
                    a = p;
                }
            }
            if k == 0 {
                self.report.admissible_now = a.scale;
                self.report.min_distance_m = a.min_distance_m;
            }
            let lifted = a.scale + DROP_SHARE * limits.reachable_drop(h);
            if lifted < target {
                target = lifted;
                binding = a.binding;
            }
        }
        self.report.binding = binding;
        target.clamp(0.0, 1.0)
    }
}
