//! The 500 Hz handover controller: task → trajectory → speed scaling → servo command.
//!
//! [`Controller::new`] allocates everything; [`Controller::step`] allocates nothing (checked by
//! `tests/controller_alloc.rs`) and never panics. One step:
//! 1. **Task**: [`HandoverTask::step`] with the TCP position (forward kinematics of the
//!    *measured* joints), whether the motion to the current target has finished, the operator's
//!    hands, and the adaptation's timing (start delay, wait-for-attention, attention on robot).
//! 2. **Trajectory** ([`Otg`]): the target follows the task phase (pick, handover, home or pick
//!    again after a timeout). Limits are the nominal UR5e limits scaled by the adaptation:
//!    velocity × speed scale, acceleration × smoothness, jerk × smoothness²
//!    ([`MotionLimits::scaled`]). Entering Approach sets the minimum approach duration; any
//!    later replan of the approach keeps its arrival time (it passes the remaining time).
//! 3. **Speed scaling** ([`SpeedScaler`]): the trajectory's velocity is the reference `q̇_ref`;
//!    the QP keeps it within the nominal joint velocity and acceleration limits (π rad/s,
//!    π rad/s²: full braking authority stays available whatever the smoothness), within the TCP
//!    cap `max_tcp_speed_m_s × speed scale`, and keeps the TCP, wrist and elbow
//!    ([`robot_io::kinematics::control_points`] at the measured joints) within the separation
//!    speeds toward the head and both hands.
//! 4. **Command**: when the QP passes the reference through, the commanded state is the
//!    trajectory's (exact positions, no integration drift). When it changes it, the commanded
//!    position integrates the scaled velocity (trapezoid) and the trajectory generator is reset
//!    to the commanded state, so the motion resumes jerk-limited from where it really is.
//! 5. **Bookkeeping**: task context (C, G, phase), events of this step, last [`QpStatus`] and
//!    [`PlanStatus`], the reference and commanded velocities, counters.
//!
//! # Command: servoJ, not speedJ
//! The output is [`JointCommand::Servo`] with the commanded joint positions. A position command
//! closes the loop on position, so the arm ends exactly at the handover pose and drift from
//! integrating velocities cannot accumulate, and the supervisor can check positions directly.
//! The defaults are `lookahead_s = 0.05` s and `gain = 500`: a short lookahead keeps the lag
//! behind the (already jerk-limited, speed-scaled) command small — about 50 ms, i.e. ≤ 0.16 rad at
//! π rad/s — so the separation monitoring acts on where the arm actually is; the gain is
//! mid-range of UR's [100, 2000] (ur_rtde's examples use 300; higher gains track tighter but ring
//! on a real arm). Both are configurable.
//!
//! When the robot cannot move (safety stop, program not PLAYING, arm not RUNNING) or its state
//! is not finite, the step outputs [`JointCommand::Stop`] at the nominal acceleration and
//! re-synchronises to the measured joints on the next usable state.
//!
//! # Example
//! ```
//! use adapt::controller::{Controller, ControllerConfig, HumanPoints, MotionAdaptation};
//! use robot_io::sim::{SimConfig, SimRobot};
//! use robot_io::{JointCommand, Robot, RobotState};
//! let mut robot = SimRobot::new(SimConfig { initial_q_rad: adapt::task::IK_REFERENCE_Q_RAD, ..SimConfig::ur5e() })?;
//! let mut ctl = Controller::new(ControllerConfig::example())?;
//! let (mut state, mut cmd) = (RobotState::default(), JointCommand::Stop { decel: 1.0 });
//! ctl.start_handover();
//! for _ in 0..500 {
//!     robot.read_state(&mut state)?;
//!     ctl.step(state.timestamp_s, &state, &MotionAdaptation::default(), &HumanPoints::default(), &mut cmd);
//!     robot.send(&cmd)?;
//!     robot.step();
//! }
//! assert_eq!(ctl.phase(), adapt::task::Phase::Fetch);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::time::Duration;

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use robot_io::kinematics::{ControlPoints, control_points, control_points_zeroed};
use robot_io::{JointCommand, Joints, RobotState, robot_mode, runtime_state};
use serde::Deserialize;

use crate::otg::{LimitScale, MotionLimits, Otg, OtgState, PlanStatus};
use crate::qp::{HumanPoint, N_JOINTS, QpConfig, QpInput, QpParams, QpStatus, SpeedScaler};
use crate::ssm::{HumanPointKind, SsmConfig, SsmParams};
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

            fn limit_scale(self) -> LimitScale {
                LimitScale::new(self.0).unwrap_or(LimitScale::ONE)
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
        }
    }
}

/// The operator's tracked points in the robot base frame [m]; `None` when not tracked this
/// cycle. Non-finite positions are treated as not tracked by the task, and make the speed
/// scaling brake.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HumanPoints {
    /// Head position [m].
    pub head_m: Option<[f64; 3]>,
    /// Left hand position [m].
    pub left_hand_m: Option<[f64; 3]>,
    /// Right hand position [m].
    pub right_hand_m: Option<[f64; 3]>,
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
    /// Separation monitoring (ISO/TS 15066).
    pub ssm: SsmParams,
    /// Speed-scaling solver.
    pub qp: QpParams,
}

/// The file layout of `config/handover.toml`: a single `[controller]` table.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawHandoverFile {
    /// The controller, with its task, SSM and QP tables.
    pub controller: RawControllerConfig,
}

/// The validated controller configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerConfig {
    /// Control period [s], in (0, 0.1].
    pub cycle_s: f64,
    /// Nominal limits (velocity [rad/s], acceleration [rad/s²], jerk [rad/s³]) before the
    /// adaptation scales them; also the QP's velocity and acceleration box.
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
    /// Separation monitoring and the speed-scaling solver.
    pub qp: QpConfig,
}

impl ControllerConfig {
    /// UR5e defaults around [`TaskConfig::example`]: 2 ms, π rad/s, π rad/s², 10π rad/s³,
    /// TCP 1 m/s, servoJ lookahead 0.05 s and gain 500, arrival within 0.005 rad and below
    /// 0.02 rad/s, no tool offset, default SSM and QP parameters.
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
            qp: QpConfig::default(),
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
            qp: QpConfig::new(SsmConfig::try_from(raw.ssm)?, raw.qp)?,
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
    /// Steps in which the QP changed the reference velocity (speed scaling active).
    pub scaled_steps: u64,
    /// Steps whose QP status was a fallback ([`QpStatus::is_fallback`]).
    pub fallback_steps: u64,
    /// Steps in which the trajectory generator failed (the reference was braked to rest).
    pub otg_errors: u64,
    /// Steps that output a stop because the robot could not move or its state was unusable.
    pub stop_steps: u64,
}

/// The 500 Hz controller (see the module docs).
#[derive(Debug)]
pub struct Controller {
    cfg: ControllerConfig,
    task: HandoverTask,
    events: EventBuffer<EVENT_CAPACITY>,
    otg: Otg,
    reference: OtgState,
    scaler: SpeedScaler,
    qp_input: QpInput,
    points: ControlPoints,
    tool: Isometry3<f64>,
    /// Commanded joint positions [rad] and velocities [rad/s].
    q_cmd: Joints,
    qd_cmd: Joints,
    synced: bool,
    /// The target given to the trajectory generator [rad].
    target: Option<Joints>,
    /// Absolute arrival time the current approach must not beat [s].
    arrive_not_before_s: Option<f64>,
    /// The adaptation scales behind the trajectory limits in force.
    applied_scales: (f64, f64),
    last_plan: PlanStatus,
    last_qp: QpStatus,
    last_now_s: f64,
    stats: ControllerStats,
}

impl Controller {
    /// Build the controller: validates `cfg` and allocates everything the steps use.
    ///
    /// # Errors
    /// [`AdaptError::InvalidValue`] (and the trajectory and QP set-up errors) for a bad config.
    pub fn new(cfg: ControllerConfig) -> Result<Controller> {
        cfg.validate()?;
        let otg = Otg::new(cfg.cycle_s, cfg.limits)?;
        let scaler = SpeedScaler::new(cfg.qp)?;
        let [x, y, z] = cfg.tool_offset_m;
        Ok(Controller {
            task: HandoverTask::new(cfg.task),
            events: EventBuffer::new(),
            otg,
            reference: OtgState::default(),
            scaler,
            qp_input: QpInput {
                dt_s: cfg.cycle_s,
                max_velocity: *cfg.limits.max_velocity(),
                max_acceleration: *cfg.limits.max_acceleration(),
                ..QpInput::default()
            },
            points: control_points_zeroed(),
            tool: Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::identity()),
            q_cmd: [0.0; 6],
            qd_cmd: [0.0; 6],
            synced: false,
            target: None,
            arrive_not_before_s: None,
            applied_scales: (1.0, 1.0),
            last_plan: PlanStatus::Finished,
            last_qp: QpStatus::Solved,
            last_now_s: 0.0,
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

    /// The QP status of the last step.
    pub fn last_qp_status(&self) -> QpStatus {
        self.last_qp
    }

    /// The trajectory status of the last step.
    pub fn last_plan_status(&self) -> PlanStatus {
        self.last_plan
    }

    /// The trajectory's state of the last step (the QP's reference; velocity [rad/s]).
    pub fn reference(&self) -> &OtgState {
        &self.reference
    }

    /// The commanded joint positions of the last step [rad].
    pub fn commanded_position(&self) -> &Joints {
        &self.q_cmd
    }

    /// The commanded joint velocities of the last step [rad/s] (after speed scaling).
    pub fn commanded_velocity(&self) -> &Joints {
        &self.qd_cmd
    }

    /// The control points (TCP, wrist, elbow) of the last step, at the measured joints.
    pub fn control_points(&self) -> &ControlPoints {
        &self.points
    }

    /// Counters since construction.
    pub fn stats(&self) -> &ControllerStats {
        &self.stats
    }

    /// Tells the controller that its last command was not executed as sent (the safety
    /// supervisor reduced it or replaced it by a stop): the next step re-synchronises the
    /// trajectory to the measured joints instead of continuing a plan the robot did not
    /// follow (which would imply an acceleration jump at the next command).
    pub fn command_overridden(&mut self) {
        self.synced = false;
    }

    /// One 2 ms cycle at time `now_s` [s] (injected; a non-finite value advances the last time
    /// by one cycle): read `state`, run task → trajectory → speed scaling, write `out`.
    /// Allocates nothing, never panics.
    pub fn step(
        &mut self,
        now_s: f64,
        state: &RobotState,
        adaptation: &MotionAdaptation,
        humans: &HumanPoints,
        out: &mut JointCommand,
    ) {
        let now = if now_s.is_finite() {
            now_s
        } else {
            self.last_now_s + self.cfg.cycle_s
        };
        self.last_now_s = now;
        self.stats.steps = self.stats.steps.saturating_add(1);
        self.events.clear();

        let state_ok = state
            .actual_q
            .iter()
            .chain(&state.actual_qd)
            .all(|v| v.is_finite());
        let can_move = state_ok
            && !state.is_safety_stopped()
            && state.robot_mode == robot_mode::RUNNING
            && state.runtime_state == runtime_state::PLAYING;

        // Control points at the measured joints (the last good ones if the state is unusable).
        let q_meas = if state_ok { state.actual_q } else { self.q_cmd };
        control_points(&q_meas, &self.tool, &mut self.points);

        // 1. Task.
        let finished = can_move && self.arrived(state);
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
        };
        self.task.step(&input, &mut self.events);

        if !can_move {
            self.stats.stop_steps = self.stats.stop_steps.saturating_add(1);
            self.synced = false;
            self.qd_cmd = [0.0; 6];
            *out = JointCommand::Stop {
                decel: self.max_acceleration(),
            };
            return;
        }
        if !self.synced {
            self.resync(state);
        }

        // 2. Trajectory: limits and target.
        let scales = (
            adaptation.speed_scale.get(),
            adaptation.smoothness_scale.get(),
        );
        let mut replan = false;
        if scales != self.applied_scales {
            self.applied_scales = scales;
            let limits = self.cfg.limits.scaled(
                adaptation.speed_scale.limit_scale(),
                adaptation.smoothness_scale.limit_scale(),
            );
            self.otg.set_limits(&limits);
            replan = true;
        }
        let wanted = self.task.target_q_rad().copied();
        if let Some(target) = wanted
            && self.target != Some(target)
        {
            self.target = Some(target);
            let min = adaptation.min_approach_duration.as_secs_f64();
            self.arrive_not_before_s =
                (self.task.phase() == Phase::Approach && min > 0.0).then_some(now + min);
            replan = true;
        }
        if replan {
            self.set_otg_target(now);
        }
        let dt = self.cfg.cycle_s;
        match self.otg.step(&mut self.reference) {
            Ok(status) => self.last_plan = status,
            Err(_) => {
                // No trajectory: brake the reference to rest (the QP limits the deceleration).
                self.stats.otg_errors = self.stats.otg_errors.saturating_add(1);
                self.last_plan = PlanStatus::Working;
                self.reference.position = self.q_cmd;
                self.reference.velocity = [0.0; 6];
                self.reference.acceleration = [0.0; 6];
            }
        }

        // 3. Speed scaling.
        self.fill_qp_input(adaptation, humans);
        let mut qd = [0.0; N_JOINTS];
        self.last_qp = self.scaler.solve(&self.qp_input, &mut qd);
        if self.last_qp.is_fallback() {
            self.stats.fallback_steps = self.stats.fallback_steps.saturating_add(1);
        }

        // 4. Command.
        let changed = qd
            .iter()
            .zip(&self.reference.velocity)
            .any(|(a, b)| (a - b).abs() > 1e-9);
        if changed {
            self.stats.scaled_steps = self.stats.scaled_steps.saturating_add(1);
            let max_acc = self.otg.limits().max_acceleration();
            let mut acc = [0.0; 6];
            for i in 0..N_JOINTS {
                let (Some(q), Some(v), Some(a), Some(&new), Some(&amax)) = (
                    self.q_cmd.get_mut(i),
                    self.qd_cmd.get(i),
                    acc.get_mut(i),
                    qd.get(i),
                    max_acc.get(i),
                ) else {
                    continue;
                };
                *q += 0.5 * (v + new) * dt;
                *a = ((new - v) / dt).clamp(-amax, amax);
            }
            self.qd_cmd = qd;
            // Resume the trajectory from the commanded state.
            if self
                .otg
                .set_current_state(&self.q_cmd, &self.qd_cmd, &acc)
                .is_ok()
            {
                self.set_otg_target(now);
            }
        } else {
            self.q_cmd = self.reference.position;
            self.qd_cmd = self.reference.velocity;
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

    /// Whether the robot stands at the current target: trajectory finished, every joint within
    /// the settle tolerance and slower than the settle speed.
    fn arrived(&self, state: &RobotState) -> bool {
        let Some(target) = self.task.target_q_rad() else {
            return false;
        };
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

    /// Start from the measured state at rest-or-moving (velocity as measured, no acceleration).
    fn resync(&mut self, state: &RobotState) {
        self.q_cmd = state.actual_q;
        self.qd_cmd = state.actual_qd;
        self.reference.position = state.actual_q;
        self.reference.velocity = state.actual_qd;
        if self
            .otg
            .set_current_state(&state.actual_q, &state.actual_qd, &[0.0; 6])
            .is_ok()
        {
            self.synced = true;
        }
        if self.target.is_some() {
            self.set_otg_target(self.last_now_s);
        }
    }

    /// (Re)send the current target, with the remaining minimum approach time.
    fn set_otg_target(&mut self, now: f64) {
        let Some(target) = self.target else {
            return;
        };
        let min = self
            .arrive_not_before_s
            .map(|t| t - now)
            .filter(|r| *r > 0.0);
        if self.otg.set_target(&target, min).is_err() {
            self.stats.otg_errors = self.stats.otg_errors.saturating_add(1);
        }
    }

    fn fill_qp_input(&mut self, adaptation: &MotionAdaptation, humans: &HumanPoints) {
        let input = &mut self.qp_input;
        input.qd_ref = self.reference.velocity;
        input.qd_prev = self.qd_cmd;
        input.tcp_speed_cap_m_s = self.cfg.max_tcp_speed_m_s * adaptation.speed_scale.get();
        for (slot, p) in input.control_points.iter_mut().zip(&self.points) {
            slot.position = [p.position.x, p.position.y, p.position.z];
            for (r, row) in slot.jacobian.iter_mut().enumerate() {
                for (c, v) in row.iter_mut().enumerate() {
                    *v = p.jacobian.get((r, c)).copied().unwrap_or(0.0);
                }
            }
        }
        let point = |p: Option<[f64; 3]>, kind| p.map(|position| HumanPoint { position, kind });
        input.humans = [
            point(humans.head_m, HumanPointKind::Head),
            point(humans.left_hand_m, HumanPointKind::Hand),
            point(humans.right_hand_m, HumanPointKind::Hand),
        ];
    }
}
