//! `SimRobot`: an in-process UR5e model on a mock clock.
//!
//! Each [`SimRobot::step`] advances one 2 ms controller cycle ([`CYCLE_S`]); the controller
//! `timestamp_s` is `initial_timestamp_s + cycles × 0.002 s`, computed from the cycle count so it
//! does not drift. Nothing reads the wall clock, so a run is deterministic.
//!
//! # Motion model (behavioural, not UR's proprietary controller)
//! The joint servos are ideal: `actual_q == target_q` and `actual_qd == target_qd`. Every cycle
//! the model computes new joint velocities from the latched [`JointCommand`], then integrates
//! `q += qd · dt` (semi-implicit Euler, dt = 2 ms).
//!
//! - **servoJ** `Servo { q, lookahead_s, gain }`: a reference `r` follows the commanded `q`
//!   through a first-order filter with time constant `lookahead_s` [s] (the smoothing the
//!   lookahead buys), and the joint follows `r` with the reference's velocity (feedforward)
//!   plus a proportional position correction of bandwidth `gain` [1/s]. Both are discretised
//!   exactly, so an unconstrained cycle corrects `(1 − e^(−gain·dt)) · (r − q)` of the error;
//!   higher gain tracks tighter, a longer lookahead is smoother and lags more. The correction
//!   is capped at the speed from which the joint can still stop at the reference with
//!   `max_acc_rad_s2` (`√(2·a·|r − q|)`, so it does not overshoot); the resulting velocity is
//!   multiplied by the speed scale (below), capped at `max_speed_rad_s × scale`, and its change
//!   per cycle is limited to `max_acc_rad_s2 · dt`. (Until issue 10 the model had no
//!   feedforward: the whole velocity came from the capped error, so tracking a smooth
//!   trajectory was nonlinear at low speed and showed jerk spikes of its own.) `lookahead_s` must lie in [0.03, 0.2] and
//!   `gain` in [100, 2000], as UR's servoj requires; UR calls the gain unitless, this model
//!   reads it as a bandwidth in [1/s].
//! - **speedJ** `Speed { qd, acc }`: the target velocity is `qd × scale`, shrunk uniformly (its
//!   direction kept) so that no joint exceeds `max_speed_rad_s`; the velocity vector ramps
//!   towards it along a straight line in joint space with the leading joint at
//!   `min(acc, max_acc)` [rad/s²] (UR's "acceleration of the leading axis").
//! - **stopJ** `Stop { decel }`: all joints decelerate together (they stop at the same instant),
//!   the fastest at `min(decel, max_acc)` [rad/s²].
//! - No latched command while running: the arm stops as for stopJ at `max_acc`.
//!
//! **Speed scale** = `speed_scaling × target_speed_fraction` while the program is PLAYING, and it
//! multiplies the commanded velocities (not the accelerations or stops). The reported
//! `speed_scaling` is 0 whenever the program is not PLAYING, as the real controller reports
//! (see the recordings in `data/rtde-traces`).
//!
//! **Joint limits** (UR5e defaults, see [`SimConfig::ur5e`]): position ±2π rad, speed π rad/s,
//! nominal acceleration π rad/s². Near a position limit the velocity is capped at the speed from
//! which the joint can stop at the limit with `max_acc_rad_s2`, and the position is clamped to
//! the limit.
//!
//! # Program, safety and injected faults
//! - `runtime_state`: [`SimRobot::pause`] gives PAUSING while the arm brakes at `max_acc`, then
//!   PAUSED; [`SimRobot::stop_program`] gives STOPPING then STOPPED; [`SimRobot::play`] gives
//!   RESUMING for one published cycle (from PAUSED) and then PLAYING.
//! - [`SimRobot::inject_protective_stop`]: `safety_mode` PROTECTIVE_STOP, `safety_status_bits`
//!   bits 2 (protective stop) and 10 (stopped due to safety); the arm brakes at
//!   `safety_stop_decel_rad_s2` and the program pauses. [`SimRobot::clear_protective_stop`]
//!   (the dashboard's "unlock protective stop") returns to NORMAL; the program stays PAUSED until
//!   [`SimRobot::play`].
//! - [`SimRobot::inject_emergency_stop`]: `safety_mode` ROBOT_EMERGENCY_STOP, bits 6, 7 and 10;
//!   the arm brakes at `safety_stop_decel_rad_s2`, the program stops, and once the arm stands
//!   still `robot_mode` becomes POWER_OFF. Recover with [`SimRobot::clear_emergency_stop`],
//!   [`SimRobot::power_on`], [`SimRobot::brake_release`] and [`SimRobot::play`].
//! - Motion commands sent while the program is not PLAYING, the arm is not RUNNING or a safety
//!   stop is active are ignored (counted in [`SimRobot::ignored_commands`]). Entering any of
//!   these states discards the latched command, so the arm stays still after recovery until a
//!   new command arrives.
//! - [`SimRobot::inject_dropped_cycles`]: for the next `n` steps the published state (what
//!   [`Robot::read_state`] returns) is not updated, so the timestamp freezes, while the model
//!   keeps moving; afterwards the published timestamp jumps by `(n + 1) × 2 ms`, as a client
//!   sees skipped RTDE packages.
//!
//! `actual_tcp_pose` comes from UR5e forward kinematics ([`ur5e_tcp_pose`]);
//! `actual_tcp_speed` is its finite difference over one cycle (linear [m/s], angular [rad/s] in
//! the base frame).
//!
//! # Example
//! ```
//! use robot_io::sim::{SimConfig, SimRobot};
//! use robot_io::{JointCommand, Robot, RobotState};
//! let mut robot = SimRobot::new(SimConfig::ur5e())?;
//! let mut state = RobotState::default();
//! robot.send(&JointCommand::Speed { qd: [0.5, 0.0, 0.0, 0.0, 0.0, 0.0], acc: 1.0 })?;
//! for _ in 0..500 {
//!     robot.step();
//! }
//! robot.read_state(&mut state)?;
//! assert!((state.timestamp_s - 1.0).abs() < 1e-12);
//! assert!((state.actual_qd[0] - 0.5).abs() < 1e-9);
//! # Ok::<(), robot_io::RobotIoError>(())
//! ```
//!
//! `read_state`, `send` and `step` allocate nothing (checked by `tests/sim_alloc.rs`).

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use crate::types::{
    JointCommand, Joints, Robot, RobotState, robot_mode, runtime_state, safety_mode,
    safety_status_bits,
};
use crate::{Result, RobotIoError};

/// The controller cycle [s]: 2 ms (500 Hz).
pub const CYCLE_S: f64 = 0.002;

pub use crate::kinematics::{
    Mat3, UR5E_DH_A, UR5E_DH_ALPHA, UR5E_DH_D, rotation_vector, ur5e_tcp_pose, ur5e_tcp_transform,
};

/// Accepted servoj lookahead time range [s] (UR's servoj).
pub const SERVO_LOOKAHEAD_RANGE_S: (f64, f64) = (0.03, 0.2);
/// Accepted servoj gain range [1/s] (UR's servoj).
pub const SERVO_GAIN_RANGE: (f64, f64) = (100.0, 2000.0);

/// `safety_status_bits` bit 0: normal mode.
const BIT_NORMAL_MODE: u32 = 1 << 0;
/// `safety_status_bits` bit 6: robot emergency stopped.
const BIT_ROBOT_EMERGENCY_STOP: u32 = 1 << 6;
/// `robot_status_bits` bit 0: power on.
const BIT_POWER_ON: u32 = 1 << 0;
/// `robot_status_bits` bit 1: program running.
const BIT_PROGRAM_RUNNING: u32 = 1 << 1;

/// Configuration of a [`SimRobot`]; validated by [`SimRobot::new`].
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// Initial joint positions [rad].
    pub initial_q_rad: Joints,
    /// Controller timestamp at construction [s].
    pub initial_timestamp_s: f64,
    /// Lower joint position limits [rad].
    pub min_q_rad: Joints,
    /// Upper joint position limits [rad].
    pub max_q_rad: Joints,
    /// Joint speed limits [rad/s], > 0.
    pub max_speed_rad_s: Joints,
    /// Joint acceleration limits [rad/s²], > 0: caps servoJ and speedJ acceleration and stopJ
    /// deceleration.
    pub max_acc_rad_s2: Joints,
    /// Deceleration of protective and emergency stops, leading joint [rad/s²], > 0.
    pub safety_stop_decel_rad_s2: f64,
    /// Initial controller speed scaling [-] in [0, 1].
    pub speed_scaling: f64,
    /// Initial speed slider fraction [-] in [0, 1].
    pub target_speed_fraction: f64,
}

impl SimConfig {
    /// UR5e defaults: upright home pose `[0, −π/2, 0, −π/2, 0, 0]` rad, limits ±2π rad,
    /// π rad/s, π rad/s² (nominal), safety stops at 2π rad/s², scaling 1, timestamp 0 s.
    pub fn ur5e() -> Self {
        Self {
            initial_q_rad: [0.0, -FRAC_PI_2, 0.0, -FRAC_PI_2, 0.0, 0.0],
            initial_timestamp_s: 0.0,
            min_q_rad: [-TAU; 6],
            max_q_rad: [TAU; 6],
            max_speed_rad_s: [PI; 6],
            max_acc_rad_s2: [PI; 6],
            safety_stop_decel_rad_s2: TAU,
            speed_scaling: 1.0,
            target_speed_fraction: 1.0,
        }
    }

    fn validate(&self) -> Result<()> {
        let bad = |field, reason| Err(RobotIoError::InvalidSimConfig { field, reason });
        if !self.initial_timestamp_s.is_finite() || self.initial_timestamp_s < 0.0 {
            return bad("initial_timestamp_s", "must be finite and >= 0");
        }
        for j in 0..6 {
            let (Some(&lo), Some(&hi), Some(&q0), Some(&v), Some(&a)) = (
                self.min_q_rad.get(j),
                self.max_q_rad.get(j),
                self.initial_q_rad.get(j),
                self.max_speed_rad_s.get(j),
                self.max_acc_rad_s2.get(j),
            ) else {
                continue;
            };
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return bad(
                    "min_q_rad/max_q_rad",
                    "limits must be finite with min < max",
                );
            }
            if !(q0.is_finite() && lo <= q0 && q0 <= hi) {
                return bad(
                    "initial_q_rad",
                    "must be finite and within the joint limits",
                );
            }
            if !(v.is_finite() && v > 0.0) {
                return bad("max_speed_rad_s", "must be finite and > 0");
            }
            if !(a.is_finite() && a > 0.0) {
                return bad("max_acc_rad_s2", "must be finite and > 0");
            }
        }
        if !(self.safety_stop_decel_rad_s2.is_finite() && self.safety_stop_decel_rad_s2 > 0.0) {
            return bad("safety_stop_decel_rad_s2", "must be finite and > 0");
        }
        check_fraction("speed_scaling", self.speed_scaling)?;
        check_fraction("target_speed_fraction", self.target_speed_fraction)
    }
}

impl Default for SimConfig {
    fn default() -> Self {
        Self::ur5e()
    }
}

fn check_fraction(field: &'static str, value: f64) -> Result<()> {
    if (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(RobotIoError::InvalidSimConfig {
            field,
            reason: "must lie in [0, 1]",
        })
    }
}

/// Per-joint limits, copied from the config.
#[derive(Debug, Clone, Copy)]
struct JointLimits {
    min_q: f64,
    max_q: f64,
    max_speed: f64,
    max_acc: f64,
}

/// A servo target unchanged for this many cycles holds still (20 ms): only then the
/// no-overshoot braking cap applies (see `SimRobot::servo`) [-].
const HELD_TARGET_CYCLES: u32 = 10;

/// Per-joint model state.
#[derive(Debug, Clone, Copy, Default)]
struct JointState {
    /// Position [rad].
    q: f64,
    /// Velocity [rad/s].
    qd: f64,
    /// servoJ filtered reference [rad].
    servo_ref: f64,
    /// The servo target of the previous cycle [rad].
    servo_target: f64,
    /// Cycles the servo target has stayed the same [-].
    held_cycles: u32,
}

/// What the arm does this cycle.
#[derive(Debug, Clone, Copy)]
enum Motion {
    /// Bring every joint to rest together, leading joint at this deceleration [rad/s²].
    Brake(f64),
    /// Ramp to these velocities [rad/s], leading joint at this acceleration [rad/s²].
    Ramp(Joints, f64),
    /// servoJ tracking.
    Servo {
        q: Joints,
        lookahead_s: f64,
        gain: f64,
    },
}

/// An in-process UR5e model stepped on a mock clock (see the module docs for the model).
#[derive(Debug, Clone)]
pub struct SimRobot {
    config: SimConfig,
    limits: [JointLimits; 6],
    joints: [JointState; 6],
    cycle: u64,
    command: Option<JointCommand>,
    servo_active: bool,
    speed_scaling: f64,
    target_speed_fraction: f64,
    robot_mode: i32,
    safety_mode: i32,
    safety_status_bits: u32,
    runtime_state: u32,
    /// Steps left in RESUMING before PLAYING.
    resume_left: u32,
    /// Steps left during which the published state is frozen.
    dropped_remaining: u64,
    ignored_commands: u64,
    /// The model's true state after the last step.
    state: RobotState,
    /// What `read_state` returns.
    published: RobotState,
    /// TCP rotation after the last step, for the angular TCP speed.
    tcp_rotation: Mat3,
}

impl SimRobot {
    /// A robot at rest at `config.initial_q_rad`, powered, brakes released (RUNNING), program
    /// PLAYING, safety NORMAL, no command latched.
    pub fn new(config: SimConfig) -> Result<SimRobot> {
        config.validate()?;
        let mut limits = [JointLimits {
            min_q: 0.0,
            max_q: 0.0,
            max_speed: 0.0,
            max_acc: 0.0,
        }; 6];
        let mut joints = [JointState::default(); 6];
        for (j, (l, s)) in limits.iter_mut().zip(joints.iter_mut()).enumerate() {
            let pick = |a: &Joints| a.get(j).copied().unwrap_or_default();
            *l = JointLimits {
                min_q: pick(&config.min_q_rad),
                max_q: pick(&config.max_q_rad),
                max_speed: pick(&config.max_speed_rad_s),
                max_acc: pick(&config.max_acc_rad_s2),
            };
            let q = pick(&config.initial_q_rad);
            *s = JointState {
                q,
                qd: 0.0,
                servo_ref: q,
                servo_target: q,
                held_cycles: 0,
            };
        }
        let mut robot = SimRobot {
            speed_scaling: config.speed_scaling,
            target_speed_fraction: config.target_speed_fraction,
            config,
            limits,
            joints,
            cycle: 0,
            command: None,
            servo_active: false,
            robot_mode: robot_mode::RUNNING,
            safety_mode: safety_mode::NORMAL,
            safety_status_bits: BIT_NORMAL_MODE,
            runtime_state: runtime_state::PLAYING,
            resume_left: 0,
            dropped_remaining: 0,
            ignored_commands: 0,
            state: RobotState::default(),
            published: RobotState::default(),
            tcp_rotation: IDENTITY,
        };
        let q = robot.joint_positions();
        robot.tcp_rotation = ur5e_tcp_transform(&q).0;
        robot.update_state([0.0; 6]);
        robot.published = robot.state;
        Ok(robot)
    }

    /// Advance one 2 ms controller cycle: move the arm per the latched command and the
    /// program/safety state, advance the timestamp, and publish the new state (unless a dropped
    /// cycle is injected). Allocates nothing.
    pub fn step(&mut self) {
        self.cycle = self.cycle.saturating_add(1);
        let (old_rot, old_pos) = (self.tcp_rotation, self.state.actual_tcp_pose);

        let motion = self.motion();
        let velocities = match motion {
            Motion::Brake(decel) => {
                self.servo_active = false;
                self.ramp(&[0.0; 6], decel)
            }
            Motion::Ramp(target, acc) => {
                self.servo_active = false;
                self.ramp(&target, acc)
            }
            Motion::Servo {
                q,
                lookahead_s,
                gain,
            } => self.servo(&q, lookahead_s, gain),
        };
        self.integrate(&velocities);

        // Program state transitions that depend on the arm standing still.
        let at_rest = self.joints.iter().all(|j| j.qd == 0.0);
        match self.runtime_state {
            runtime_state::RESUMING if self.resume_left > 0 => self.resume_left -= 1,
            runtime_state::RESUMING => self.runtime_state = runtime_state::PLAYING,
            runtime_state::PAUSING if at_rest => self.runtime_state = runtime_state::PAUSED,
            runtime_state::STOPPING if at_rest => self.runtime_state = runtime_state::STOPPED,
            _ => {}
        }
        let estopped = self.safety_mode == safety_mode::ROBOT_EMERGENCY_STOP
            || self.safety_mode == safety_mode::SYSTEM_EMERGENCY_STOP;
        if estopped && at_rest {
            self.robot_mode = robot_mode::POWER_OFF;
        }

        // TCP pose and speed.
        let q = self.joint_positions();
        let (rot, pos) = ur5e_tcp_transform(&q);
        let linear = [
            (pos[0] - old_pos[0]) / CYCLE_S,
            (pos[1] - old_pos[1]) / CYCLE_S,
            (pos[2] - old_pos[2]) / CYCLE_S,
        ];
        let delta = rotation_vector(&mat_mul(&rot, &transpose(&old_rot)));
        let angular = [delta[0] / CYCLE_S, delta[1] / CYCLE_S, delta[2] / CYCLE_S];
        self.tcp_rotation = rot;
        self.update_state([
            linear[0], linear[1], linear[2], angular[0], angular[1], angular[2],
        ]);

        if self.dropped_remaining > 0 {
            self.dropped_remaining -= 1;
        } else {
            self.published = self.state;
        }
    }

    /// The model's true state after the last step (unaffected by injected dropped cycles).
    pub fn state(&self) -> &RobotState {
        &self.state
    }

    /// The program's runtime state now (`runtime_state` values), including a change made
    /// since the last step (which [`SimRobot::state`] shows only after the next one).
    pub fn runtime_state(&self) -> u32 {
        self.runtime_state
    }

    /// The speed scale the next step applies to commanded velocities [-]: speed scaling ×
    /// speed slider while PLAYING, else 0 (see the module docs).
    pub fn speed_scale(&self) -> f64 {
        self.scale()
    }

    /// Cycles stepped since construction.
    pub fn cycles(&self) -> u64 {
        self.cycle
    }

    /// The configuration the robot was built with.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// The latched command, if any.
    pub fn command(&self) -> Option<&JointCommand> {
        self.command.as_ref()
    }

    /// Motion commands ignored because the program was not PLAYING, the arm not RUNNING or a
    /// safety stop active.
    pub fn ignored_commands(&self) -> u64 {
        self.ignored_commands
    }

    /// Set the controller's speed scaling [-] in [0, 1] (e.g. to emulate trajectory limiting).
    pub fn set_speed_scaling(&mut self, speed_scaling: f64) -> Result<()> {
        check_fraction("speed_scaling", speed_scaling)?;
        self.speed_scaling = speed_scaling;
        Ok(())
    }

    /// Set the speed slider [-] in [0, 1] (`target_speed_fraction`).
    pub fn set_target_speed_fraction(&mut self, fraction: f64) -> Result<()> {
        check_fraction("target_speed_fraction", fraction)?;
        self.target_speed_fraction = fraction;
        Ok(())
    }

    /// Pause the program: PAUSING while the arm brakes, then PAUSED. Discards the latched
    /// command. No effect unless PLAYING or RESUMING.
    pub fn pause(&mut self) {
        if matches!(
            self.runtime_state,
            runtime_state::PLAYING | runtime_state::RESUMING
        ) {
            self.runtime_state = runtime_state::PAUSING;
            self.command = None;
        }
    }

    /// Stop the program: STOPPING while the arm brakes, then STOPPED. Discards the latched
    /// command.
    pub fn stop_program(&mut self) {
        if !matches!(
            self.runtime_state,
            runtime_state::STOPPED | runtime_state::STOPPING
        ) {
            self.runtime_state = runtime_state::STOPPING;
            self.command = None;
        }
    }

    /// Play: from PAUSED, RESUMING for one cycle then PLAYING; from STOPPED, PLAYING. Refused
    /// (returns `false`) while a safety stop is active, the arm is not RUNNING, or the program
    /// is still pausing or stopping.
    pub fn play(&mut self) -> bool {
        if self.safety_stopped() || self.robot_mode != robot_mode::RUNNING {
            return false;
        }
        match self.runtime_state {
            runtime_state::PAUSED => {
                self.runtime_state = runtime_state::RESUMING;
                self.resume_left = 1;
            }
            runtime_state::STOPPED => self.runtime_state = runtime_state::PLAYING,
            runtime_state::PLAYING | runtime_state::RESUMING => {}
            _ => return false,
        }
        true
    }

    /// Inject a protective stop (see the module docs).
    pub fn inject_protective_stop(&mut self) {
        if self.safety_stopped() {
            return;
        }
        self.safety_mode = safety_mode::PROTECTIVE_STOP;
        self.safety_status_bits =
            safety_status_bits::PROTECTIVE_STOP | safety_status_bits::STOPPED_DUE_TO_SAFETY;
        self.command = None;
        if matches!(
            self.runtime_state,
            runtime_state::PLAYING | runtime_state::RESUMING
        ) {
            self.runtime_state = runtime_state::PAUSING;
        }
    }

    /// Unlock a protective stop: back to NORMAL; the program stays paused until
    /// [`SimRobot::play`]. Returns `false` (and does nothing) if no protective stop is active.
    pub fn clear_protective_stop(&mut self) -> bool {
        if self.safety_mode != safety_mode::PROTECTIVE_STOP {
            return false;
        }
        self.safety_mode = safety_mode::NORMAL;
        self.safety_status_bits = BIT_NORMAL_MODE;
        true
    }

    /// Inject a robot emergency stop (see the module docs).
    pub fn inject_emergency_stop(&mut self) {
        self.safety_mode = safety_mode::ROBOT_EMERGENCY_STOP;
        self.safety_status_bits = BIT_ROBOT_EMERGENCY_STOP
            | safety_status_bits::EMERGENCY_STOP
            | safety_status_bits::STOPPED_DUE_TO_SAFETY;
        self.command = None;
        if self.runtime_state != runtime_state::STOPPED {
            self.runtime_state = runtime_state::STOPPING;
        }
    }

    /// Release an emergency stop once the arm stands still: safety NORMAL, `robot_mode`
    /// POWER_OFF. Returns `false` (and does nothing) if no e-stop is active or the arm still
    /// moves.
    pub fn clear_emergency_stop(&mut self) -> bool {
        let estopped = self.safety_mode == safety_mode::ROBOT_EMERGENCY_STOP
            || self.safety_mode == safety_mode::SYSTEM_EMERGENCY_STOP;
        if !estopped || self.robot_mode != robot_mode::POWER_OFF {
            return false;
        }
        self.safety_mode = safety_mode::NORMAL;
        self.safety_status_bits = BIT_NORMAL_MODE;
        true
    }

    /// Power off (the dashboard's `power off`): `robot_mode` POWER_OFF at once, the arm brakes
    /// at `safety_stop_decel_rad_s2`, the program stops and the latched command is discarded.
    pub fn power_off(&mut self) {
        self.robot_mode = robot_mode::POWER_OFF;
        self.command = None;
        if self.runtime_state != runtime_state::STOPPED {
            self.runtime_state = runtime_state::STOPPING;
        }
    }

    /// Power on: POWER_OFF → IDLE (brakes engaged). Returns `false` if not POWER_OFF or a
    /// safety stop is active.
    pub fn power_on(&mut self) -> bool {
        if self.robot_mode != robot_mode::POWER_OFF || self.safety_stopped() {
            return false;
        }
        self.robot_mode = robot_mode::IDLE;
        true
    }

    /// Release the brakes: IDLE → RUNNING. Returns `false` if not IDLE.
    pub fn brake_release(&mut self) -> bool {
        if self.robot_mode != robot_mode::IDLE {
            return false;
        }
        self.robot_mode = robot_mode::RUNNING;
        true
    }

    /// Freeze the published state for the next `cycles` steps (dropped RTDE packages); adds to
    /// any injection still pending.
    pub fn inject_dropped_cycles(&mut self, cycles: u64) {
        self.dropped_remaining = self.dropped_remaining.saturating_add(cycles);
    }

    fn safety_stopped(&self) -> bool {
        !(self.safety_mode == safety_mode::NORMAL || self.safety_mode == safety_mode::REDUCED)
    }

    fn accepts_motion(&self) -> bool {
        !self.safety_stopped()
            && self.robot_mode == robot_mode::RUNNING
            && self.runtime_state == runtime_state::PLAYING
    }

    fn min_max_acc(&self) -> f64 {
        self.limits
            .iter()
            .map(|l| l.max_acc)
            .fold(f64::INFINITY, f64::min)
    }

    /// Combined speed scale applied to commanded velocities.
    fn scale(&self) -> f64 {
        if self.runtime_state == runtime_state::PLAYING {
            self.speed_scaling * self.target_speed_fraction
        } else {
            0.0
        }
    }

    fn motion(&self) -> Motion {
        if self.safety_stopped() || self.robot_mode != robot_mode::RUNNING {
            return Motion::Brake(self.config.safety_stop_decel_rad_s2);
        }
        let max_acc = self.min_max_acc();
        if self.runtime_state != runtime_state::PLAYING {
            return Motion::Brake(max_acc);
        }
        match self.command {
            None => Motion::Brake(max_acc),
            Some(JointCommand::Stop { decel }) => Motion::Brake(decel.min(max_acc)),
            Some(JointCommand::Speed { qd, acc }) => {
                let scale = self.scale();
                // Shrink uniformly so that no joint exceeds its speed limit.
                let shrink = qd
                    .iter()
                    .zip(&self.limits)
                    .map(|(v, l)| {
                        if v.abs() > l.max_speed {
                            l.max_speed / v.abs()
                        } else {
                            1.0
                        }
                    })
                    .fold(1.0, f64::min);
                Motion::Ramp(qd.map(|v| v * shrink * scale), acc.min(max_acc))
            }
            Some(JointCommand::Servo {
                q,
                lookahead_s,
                gain,
            }) => Motion::Servo {
                q,
                lookahead_s,
                gain,
            },
        }
    }

    /// Velocities after one cycle of a straight-line ramp (in joint space) to `target`, the
    /// leading joint at `acc` [rad/s²].
    fn ramp(&self, target: &Joints, acc: f64) -> Joints {
        let mut out = [0.0; 6];
        let max_delta = self
            .joints
            .iter()
            .zip(target)
            .map(|(j, t)| (t - j.qd).abs())
            .fold(0.0, f64::max);
        let step = acc * CYCLE_S;
        let k = if max_delta <= step {
            1.0
        } else {
            step / max_delta
        };
        for ((o, j), t) in out.iter_mut().zip(&self.joints).zip(target) {
            *o = if k == 1.0 { *t } else { j.qd + (t - j.qd) * k };
        }
        out
    }

    /// Velocities after one cycle of servoJ tracking (see the module docs).
    fn servo(&mut self, target: &Joints, lookahead_s: f64, gain: f64) -> Joints {
        if !self.servo_active {
            for (j, t) in self.joints.iter_mut().zip(target) {
                j.servo_ref = j.q;
                j.servo_target = *t;
                j.held_cycles = 0;
            }
            self.servo_active = true;
        }
        let scale = self.scale();
        let filter = 1.0 - (-CYCLE_S / lookahead_s).exp();
        let track = 1.0 - (-gain * CYCLE_S).exp();
        let mut out = [0.0; 6];
        for ((o, j), (l, t)) in out
            .iter_mut()
            .zip(&mut self.joints)
            .zip(self.limits.iter().zip(target))
        {
            let before = j.servo_ref;
            j.servo_ref += (t - j.servo_ref) * filter;
            // Velocity feedforward of the (filtered) reference, plus a position correction
            // that is capped so the joint can still stop at the reference (no overshoot).
            let feedforward = (j.servo_ref - before) / CYCLE_S;
            let error = j.servo_ref - j.q;
            let correction_cap = (2.0 * l.max_acc * error.abs()).sqrt();
            let correction = (error * track / CYCLE_S).clamp(-correction_cap, correction_cap);
            let cap = l.max_speed * scale;
            let mut wanted = ((feedforward + correction) * scale).clamp(-cap, cap);
            // No overshoot of a target that holds still (a step, or the end of a motion: the
            // same target for HELD_TARGET_CYCLES cycles): the speed toward it stays one from
            // which the joint can stop at it. A moving target — a trajectory streamed every
            // cycle, or every few cycles when commands come late or in bursts — is tracked by
            // the feedforward instead.
            if *t == j.servo_target {
                j.held_cycles = j.held_cycles.saturating_add(1);
            } else {
                j.held_cycles = 0;
            }
            j.servo_target = *t;
            if j.held_cycles >= HELD_TARGET_CYCLES {
                let to_target = t - j.q;
                // The discrete braking curve: from this speed, slowing by a·dt per cycle
                // (with q += v·dt after each change) covers at most |to_target|.
                let step = l.max_acc * CYCLE_S;
                let approach_cap =
                    step * ((0.25 + 2.0 * to_target.abs() / (step * CYCLE_S)).sqrt() - 0.5);
                if to_target > 0.0 && wanted > approach_cap {
                    wanted = approach_cap;
                } else if to_target < 0.0 && wanted < -approach_cap {
                    wanted = -approach_cap;
                }
            }
            let wanted = wanted.clamp(-cap, cap);
            let dv = l.max_acc * CYCLE_S;
            *o = j.qd + (wanted - j.qd).clamp(-dv, dv);
        }
        out
    }

    /// Apply the position-limit envelope and integrate one cycle.
    fn integrate(&mut self, velocities: &Joints) {
        for ((j, l), &v) in self.joints.iter_mut().zip(&self.limits).zip(velocities) {
            let mut v = v;
            if v > 0.0 {
                v = v.min((2.0 * l.max_acc * (l.max_q - j.q).max(0.0)).sqrt());
            } else if v < 0.0 {
                v = v.max(-(2.0 * l.max_acc * (j.q - l.min_q).max(0.0)).sqrt());
            }
            let mut q = j.q + v * CYCLE_S;
            if q >= l.max_q {
                q = l.max_q;
                v = v.min(0.0);
            } else if q <= l.min_q {
                q = l.min_q;
                v = v.max(0.0);
            }
            j.q = q;
            j.qd = v;
        }
    }

    fn joint_positions(&self) -> Joints {
        self.joints.map(|j| j.q)
    }

    fn update_state(&mut self, tcp_speed: [f64; 6]) {
        let q = self.joint_positions();
        let qd = self.joints.map(|j| j.qd);
        let s = &mut self.state;
        s.timestamp_s = self.config.initial_timestamp_s + self.cycle as f64 * CYCLE_S;
        s.actual_q = q;
        s.actual_qd = qd;
        s.target_q = q;
        s.target_qd = qd;
        s.actual_tcp_pose = ur5e_tcp_pose(&q);
        s.actual_tcp_speed = tcp_speed;
        s.speed_scaling = if self.runtime_state == runtime_state::PLAYING {
            self.speed_scaling
        } else {
            0.0
        };
        s.target_speed_fraction = self.target_speed_fraction;
        s.robot_mode = self.robot_mode;
        s.safety_mode = self.safety_mode;
        s.runtime_state = self.runtime_state;
        let mut bits = 0;
        if self.robot_mode != robot_mode::POWER_OFF {
            bits |= BIT_POWER_ON;
        }
        if self.runtime_state == runtime_state::PLAYING {
            bits |= BIT_PROGRAM_RUNNING;
        }
        s.robot_status_bits = bits;
        s.safety_status_bits = self.safety_status_bits;
    }
}

impl Robot for SimRobot {
    /// Copies the published state; does not advance the model (call [`SimRobot::step`]).
    ///
    /// # Implementation
    /// Never blocks, never fails, allocates nothing.
    fn read_state(&mut self, out: &mut RobotState) -> Result<()> {
        *out = self.published;
        Ok(())
    }

    /// Latches `cmd`; it acts from the next [`SimRobot::step`] until replaced. Ignored (still
    /// `Ok`) while the program is not PLAYING, the arm not RUNNING, or a safety stop is active.
    ///
    /// # Implementation
    /// Never blocks, allocates nothing. Errors ([`RobotIoError::InvalidCommand`]) for
    /// non-finite values, a non-positive acceleration or deceleration, or servoj lookahead or
    /// gain outside UR's ranges ([`SERVO_LOOKAHEAD_RANGE_S`], [`SERVO_GAIN_RANGE`]).
    fn send(&mut self, cmd: &JointCommand) -> Result<()> {
        validate_command(cmd)?;
        if self.accepts_motion() {
            self.command = Some(*cmd);
        } else {
            self.ignored_commands = self.ignored_commands.saturating_add(1);
        }
        Ok(())
    }
}

fn validate_command(cmd: &JointCommand) -> Result<()> {
    let invalid = |reason| Err(RobotIoError::InvalidCommand { reason });
    match *cmd {
        JointCommand::Servo {
            q,
            lookahead_s,
            gain,
        } => {
            if !q.iter().all(|v| v.is_finite()) {
                return invalid("servoj target is not finite");
            }
            let (lo, hi) = SERVO_LOOKAHEAD_RANGE_S;
            if !(lo..=hi).contains(&lookahead_s) {
                return invalid("servoj lookahead outside [0.03, 0.2] s");
            }
            let (lo, hi) = SERVO_GAIN_RANGE;
            if !(lo..=hi).contains(&gain) {
                return invalid("servoj gain outside [100, 2000]");
            }
        }
        JointCommand::Speed { qd, acc } => {
            if !qd.iter().all(|v| v.is_finite()) {
                return invalid("speedj velocity is not finite");
            }
            if !(acc.is_finite() && acc > 0.0) {
                return invalid("speedj acceleration must be finite and > 0");
            }
        }
        JointCommand::Stop { decel } => {
            if !(decel.is_finite() && decel > 0.0) {
                return invalid("stopj deceleration must be finite and > 0");
            }
        }
    }
    Ok(())
}

const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for (out_row, a_row) in out.iter_mut().zip(a) {
        for (c, o) in out_row.iter_mut().enumerate() {
            *o = a_row
                .iter()
                .zip(b)
                .map(|(x, b_row)| x * b_row.get(c).copied().unwrap_or_default())
                .sum();
        }
    }
    out
}

fn transpose(a: &Mat3) -> Mat3 {
    [
        [a[0][0], a[1][0], a[2][0]],
        [a[0][1], a[1][1], a[2][1]],
        [a[0][2], a[1][2], a[2][2]],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::Trace;

    const HOME: Joints = [0.0, -FRAC_PI_2, 0.0, -FRAC_PI_2, 0.0, 0.0];

    fn robot() -> SimRobot {
        SimRobot::new(SimConfig::ur5e()).unwrap()
    }

    fn read(robot: &mut SimRobot) -> RobotState {
        let mut s = RobotState::default();
        robot.read_state(&mut s).unwrap();
        s
    }

    fn run(robot: &mut SimRobot, cycles: usize) {
        for _ in 0..cycles {
            robot.step();
        }
    }

    fn speed(qd0: f64, acc: f64) -> JointCommand {
        JointCommand::Speed {
            qd: [qd0, 0.0, 0.0, 0.0, 0.0, 0.0],
            acc,
        }
    }

    #[test]
    fn fk_all_zeros_matches_hand_derivation() {
        // By hand: x = a2 + a3, y = −(d4 + d6), z = d1 − d5; flange rotated +90° about x.
        let pose = ur5e_tcp_pose(&[0.0; 6]);
        let expected = [-0.8172, -0.2329, 0.0628, FRAC_PI_2, 0.0, 0.0];
        for (p, e) in pose.iter().zip(expected) {
            assert!((p - e).abs() < 1e-12, "{pose:?}");
        }
    }

    #[test]
    fn fk_matches_a_real_ur5e_at_home() {
        // The record.py recording (a real e-Series arm at the upright home pose): its
        // controller-computed actual_TCP_pose agrees with the nominal DH model within the arm's
        // calibration (about 1 mm).
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../data/rtde-traces/eseries_10hz_recordpy_paused.csv");
        let trace = Trace::read(path).unwrap();
        let mut state = RobotState::default();
        trace.fill_state(0, &mut state).unwrap();
        let (rot, pos) = ur5e_tcp_transform(&state.actual_q);
        for (p, r) in pos.iter().zip(&state.actual_tcp_pose) {
            assert!(
                (p - r).abs() < 2e-3,
                "{pos:?} vs {:?}",
                state.actual_tcp_pose
            );
        }
        // Compare orientations as matrices (a rotation vector near π is sign-ambiguous).
        let recorded = rotation_matrix(&[
            state.actual_tcp_pose[3],
            state.actual_tcp_pose[4],
            state.actual_tcp_pose[5],
        ]);
        let diff = rotation_vector(&mat_mul(&rot, &transpose(&recorded)));
        let angle = diff.iter().map(|d| d * d).sum::<f64>().sqrt();
        assert!(angle < 5e-3, "orientation differs by {angle} rad");
    }

    /// Rodrigues' formula, for the tests.
    fn rotation_matrix(rv: &[f64; 3]) -> Mat3 {
        let angle = (rv[0] * rv[0] + rv[1] * rv[1] + rv[2] * rv[2]).sqrt();
        let k = [rv[0] / angle, rv[1] / angle, rv[2] / angle];
        let (s, c) = angle.sin_cos();
        let t = 1.0 - c;
        [
            [
                c + k[0] * k[0] * t,
                k[0] * k[1] * t - k[2] * s,
                k[0] * k[2] * t + k[1] * s,
            ],
            [
                k[1] * k[0] * t + k[2] * s,
                c + k[1] * k[1] * t,
                k[1] * k[2] * t - k[0] * s,
            ],
            [
                k[2] * k[0] * t - k[1] * s,
                k[2] * k[1] * t + k[0] * s,
                c + k[2] * k[2] * t,
            ],
        ]
    }

    #[test]
    fn rotation_vector_round_trips_including_near_pi() {
        for rv in [
            [0.0, 0.0, 0.0],
            [1e-9, 0.0, 0.0],
            [0.3, -0.2, 0.1],
            [0.0, -2.2187278258508263, 2.2193870835226552],
            [PI, 0.0, 0.0],
            [0.0, 0.0, -(PI - 1e-6)],
        ] {
            if rv == [0.0; 3] {
                assert_eq!(rotation_vector(&IDENTITY), [0.0; 3]);
                continue;
            }
            let back = rotation_matrix(&rotation_vector(&rotation_matrix(&rv)));
            let original = rotation_matrix(&rv);
            for (a, b) in back.iter().flatten().zip(original.iter().flatten()) {
                assert!((a - b).abs() < 1e-9, "{rv:?}");
            }
        }
    }

    #[test]
    fn starts_at_rest_in_a_sane_state() {
        let mut r = robot();
        let s = read(&mut r);
        assert_eq!(s.timestamp_s, 0.0);
        assert_eq!(s.actual_q, HOME);
        assert_eq!(s.robot_mode, robot_mode::RUNNING);
        assert_eq!(s.safety_mode, safety_mode::NORMAL);
        assert_eq!(s.runtime_state, runtime_state::PLAYING);
        assert!(!s.is_safety_stopped());
        assert!(
            (s.actual_tcp_pose[2] - 1.0794).abs() < 1e-12,
            "{:?}",
            s.actual_tcp_pose
        );
    }

    #[test]
    fn timestamp_advances_2ms_per_step_and_read_does_not_advance() {
        let mut config = SimConfig::ur5e();
        config.initial_timestamp_s = 100.0;
        let mut r = SimRobot::new(config).unwrap();
        run(&mut r, 3);
        assert_eq!(read(&mut r).timestamp_s, 100.006);
        assert_eq!(read(&mut r).timestamp_s, 100.006);
        run(&mut r, 50_000 - 3);
        // Computed from the cycle count: no drift after 100 s.
        assert!((read(&mut r).timestamp_s - 200.0).abs() < 1e-12);
        assert_eq!(r.cycles(), 50_000);
    }

    #[test]
    fn servoj_step_converges_within_velocity_and_acceleration_limits() {
        let mut r = robot();
        let mut target = HOME;
        target[0] += 0.5;
        target[2] -= 0.3;
        let cmd = JointCommand::Servo {
            q: target,
            lookahead_s: 0.1,
            gain: 300.0,
        };
        let mut prev = read(&mut r);
        let mut peak: f64 = 0.0;
        for cycle in 0..2000 {
            r.send(&cmd).unwrap();
            r.step();
            let s = read(&mut r);
            for j in 0..6 {
                assert!(s.actual_qd[j].abs() <= PI + 1e-9, "cycle {cycle}");
                let acc = (s.actual_qd[j] - prev.actual_qd[j]) / CYCLE_S;
                assert!(acc.abs() <= PI + 1e-6, "cycle {cycle} joint {j}: {acc}");
                // Joint 0 never passes the target (no overshoot beyond numerical noise).
                assert!(
                    s.actual_q[0] <= target[0] + 1e-4,
                    "cycle {cycle}: q0 {} qd0 {} target {}",
                    s.actual_q[0],
                    s.actual_qd[0],
                    target[0]
                );
            }
            peak = peak.max(s.actual_qd[0].abs());
            prev = s;
        }
        for ((q, t), qd) in prev.actual_q.iter().zip(target).zip(prev.actual_qd) {
            assert!((q - t).abs() < 1e-6, "{:?}", prev.actual_q);
            assert!(qd.abs() < 1e-6);
        }
        assert!(peak > 0.3, "the move actually used speed: {peak}");
    }

    #[test]
    fn servoj_gain_and_lookahead_shape_the_response() {
        // Distance covered in 0.1 s towards a small step (well inside the limits).
        let covered = |lookahead_s, gain| {
            let mut r = robot();
            let mut q = HOME;
            q[5] += 0.01;
            r.send(&JointCommand::Servo {
                q,
                lookahead_s,
                gain,
            })
            .unwrap();
            run(&mut r, 50);
            read(&mut r).actual_q[5]
        };
        // With velocity feedforward the joint follows the filtered reference; the gain only
        // corrects what feedforward and the acceleration limit leave: never worse when higher.
        assert!(covered(0.03, 2000.0) >= covered(0.03, 100.0) - 1e-12);
        assert!(covered(0.03, 300.0) > covered(0.2, 300.0));
    }

    #[test]
    fn speedj_ramps_at_the_commanded_acceleration() {
        let mut r = robot();
        r.send(&speed(0.5, 1.0)).unwrap();
        let mut prev = read(&mut r);
        for cycle in 1..=250 {
            r.step();
            let s = read(&mut r);
            let acc = (s.actual_qd[0] - prev.actual_qd[0]) / CYCLE_S;
            assert!((acc - 1.0).abs() < 1e-6, "cycle {cycle}: {acc}");
            prev = s;
        }
        assert!((prev.actual_qd[0] - 0.5).abs() < 1e-9);
        run(&mut r, 10);
        let s = read(&mut r);
        assert!((s.actual_qd[0] - 0.5).abs() < 1e-12);
        assert_eq!(s.actual_qd[1], 0.0);
        // Acceleration above the limit is capped at π rad/s².
        let mut r = robot();
        r.send(&speed(3.0, 50.0)).unwrap();
        r.step();
        assert!((read(&mut r).actual_qd[0] - PI * CYCLE_S).abs() < 1e-12);
    }

    #[test]
    fn speedj_keeps_direction_when_capped_and_leading_axis_sets_the_ramp() {
        let mut r = robot();
        r.send(&JointCommand::Speed {
            qd: [6.0, -3.0, 0.0, 0.0, 0.0, 0.0],
            acc: 3.0,
        })
        .unwrap();
        run(&mut r, 1);
        let s = read(&mut r);
        assert!((s.actual_qd[0] - 3.0 * CYCLE_S).abs() < 1e-12);
        assert!((s.actual_qd[1] + 1.5 * CYCLE_S).abs() < 1e-12);
        // 1.2 s: past the 1.05 s ramp, short of the joint limit.
        run(&mut r, 600);
        let s = read(&mut r);
        assert!((s.actual_qd[0] - PI).abs() < 1e-9, "{:?}", s.actual_qd);
        assert!((s.actual_qd[1] + PI / 2.0).abs() < 1e-9);
    }

    #[test]
    fn stopj_decelerates_at_its_deceleration_all_joints_together() {
        let mut r = robot();
        r.send(&JointCommand::Speed {
            qd: [1.0, 0.5, 0.0, 0.0, 0.0, 0.0],
            acc: PI,
        })
        .unwrap();
        run(&mut r, 500);
        r.send(&JointCommand::Stop { decel: 2.0 }).unwrap();
        let mut prev = read(&mut r);
        let mut cycles = 0;
        while read(&mut r).actual_qd[0] != 0.0 {
            r.step();
            let s = read(&mut r);
            let decel = (prev.actual_qd[0] - s.actual_qd[0]) / CYCLE_S;
            assert!(decel <= 2.0 + 1e-9);
            // Joints stay in proportion: joint 1 runs at half of joint 0 all the way down.
            assert!((s.actual_qd[1] - s.actual_qd[0] / 2.0).abs() < 1e-12);
            prev = s;
            cycles += 1;
        }
        assert_eq!(cycles, 250, "1 rad/s at 2 rad/s² takes 0.5 s");
        assert_eq!(read(&mut r).actual_qd[1], 0.0);
    }

    #[test]
    fn protective_stop_halts_and_blocks_commands_until_cleared_and_played() {
        let mut r = robot();
        r.send(&speed(1.0, PI)).unwrap();
        run(&mut r, 500);
        r.inject_protective_stop();
        run(&mut r, 1);
        let s = read(&mut r);
        assert_eq!(s.safety_mode, safety_mode::PROTECTIVE_STOP);
        assert_ne!(
            s.safety_status_bits & safety_status_bits::PROTECTIVE_STOP,
            0
        );
        assert_ne!(
            s.safety_status_bits & safety_status_bits::STOPPED_DUE_TO_SAFETY,
            0
        );
        assert!(s.is_safety_stopped());
        // Braking at the safety deceleration: 1 rad/s at 2π rad/s² stops within 0.16 s.
        run(&mut r, 80);
        let stopped = read(&mut r);
        assert_eq!(stopped.actual_qd, [0.0; 6]);
        assert_eq!(stopped.runtime_state, runtime_state::PAUSED);
        assert_eq!(stopped.speed_scaling, 0.0);
        // Commands are ignored and nothing moves.
        r.send(&speed(1.0, PI)).unwrap();
        run(&mut r, 100);
        assert_eq!(read(&mut r).actual_q, stopped.actual_q);
        assert_eq!(r.ignored_commands(), 1);
        assert!(!r.play(), "play is refused during a protective stop");
        // Unlock, then play: commands act again.
        assert!(r.clear_protective_stop());
        assert!(!r.clear_protective_stop());
        let s = {
            run(&mut r, 1);
            read(&mut r)
        };
        assert_eq!(s.safety_mode, safety_mode::NORMAL);
        assert!(!s.is_safety_stopped());
        assert_eq!(s.runtime_state, runtime_state::PAUSED);
        assert!(r.play());
        run(&mut r, 1);
        assert_eq!(read(&mut r).runtime_state, runtime_state::RESUMING);
        run(&mut r, 1);
        assert_eq!(read(&mut r).runtime_state, runtime_state::PLAYING);
        // The command sent during the stop was discarded: the arm stays still.
        run(&mut r, 10);
        assert_eq!(read(&mut r).actual_q, stopped.actual_q);
        r.send(&speed(1.0, PI)).unwrap();
        run(&mut r, 10);
        assert!(read(&mut r).actual_q[0] > stopped.actual_q[0]);
    }

    #[test]
    fn emergency_stop_powers_off_and_needs_the_full_recovery() {
        let mut r = robot();
        r.send(&speed(0.5, PI)).unwrap();
        run(&mut r, 200);
        r.inject_emergency_stop();
        assert!(!r.clear_emergency_stop(), "still moving");
        run(&mut r, 100);
        let s = read(&mut r);
        assert_eq!(s.safety_mode, safety_mode::ROBOT_EMERGENCY_STOP);
        assert_ne!(s.safety_status_bits & safety_status_bits::EMERGENCY_STOP, 0);
        assert_eq!(s.actual_qd, [0.0; 6]);
        assert_eq!(s.robot_mode, robot_mode::POWER_OFF);
        assert_eq!(s.runtime_state, runtime_state::STOPPED);
        assert!(!r.power_on(), "refused while e-stopped");
        assert!(r.clear_emergency_stop());
        assert!(!r.brake_release());
        assert!(r.power_on());
        assert!(!r.play(), "brakes still engaged");
        assert!(r.brake_release());
        assert!(r.play());
        r.send(&speed(0.5, PI)).unwrap();
        run(&mut r, 10);
        let s = read(&mut r);
        assert_eq!(s.runtime_state, runtime_state::PLAYING);
        assert!(s.actual_qd[0] > 0.0);
    }

    #[test]
    fn power_off_brakes_and_needs_power_on_and_brake_release() {
        let mut r = robot();
        r.send(&speed(0.5, PI)).unwrap();
        run(&mut r, 200);
        r.power_off();
        run(&mut r, 100);
        let s = read(&mut r);
        assert_eq!(s.robot_mode, robot_mode::POWER_OFF);
        assert_eq!(s.robot_status_bits & BIT_POWER_ON, 0);
        assert_eq!(s.actual_qd, [0.0; 6]);
        assert_eq!(s.runtime_state, runtime_state::STOPPED);
        r.send(&speed(0.5, PI)).unwrap();
        assert_eq!(r.ignored_commands(), 1);
        assert!(!r.play());
        assert!(r.power_on() && r.brake_release() && r.play());
        r.send(&speed(0.5, PI)).unwrap();
        run(&mut r, 5);
        assert!(read(&mut r).actual_qd[0] > 0.0);
    }

    #[test]
    fn dropped_cycles_freeze_the_published_state() {
        let mut r = robot();
        r.send(&speed(0.5, PI)).unwrap();
        run(&mut r, 10);
        let before = read(&mut r);
        r.inject_dropped_cycles(5);
        for _ in 0..5 {
            r.step();
            let s = read(&mut r);
            assert_eq!(s, before, "stale state while cycles are dropped");
        }
        // The model kept moving underneath.
        assert!(r.state().actual_q[0] > before.actual_q[0]);
        r.step();
        let after = read(&mut r);
        assert!((after.timestamp_s - before.timestamp_s - 6.0 * CYCLE_S).abs() < 1e-12);
        assert_eq!(after, *r.state());
    }

    #[test]
    fn speed_scaling_half_halves_the_speed() {
        let steady = |scaling: f64, fraction: f64| {
            let mut r = robot();
            r.set_speed_scaling(scaling).unwrap();
            r.set_target_speed_fraction(fraction).unwrap();
            r.send(&speed(1.0, PI)).unwrap();
            run(&mut r, 1000);
            let s = read(&mut r);
            assert_eq!(s.speed_scaling, scaling);
            assert_eq!(s.target_speed_fraction, fraction);
            s.actual_qd[0]
        };
        assert!((steady(1.0, 1.0) - 1.0).abs() < 1e-12);
        assert!((steady(0.5, 1.0) - 0.5).abs() < 1e-12);
        assert!((steady(1.0, 0.5) - 0.5).abs() < 1e-12);
        assert!((steady(0.5, 0.5) - 0.25).abs() < 1e-12);
        assert!(robot().set_speed_scaling(1.5).is_err());

        // servoJ under scaling 0.5: the peak speed of a long move halves (capped at π/2).
        let peak = |scaling: f64| {
            let mut r = robot();
            r.set_speed_scaling(scaling).unwrap();
            let mut q = HOME;
            q[0] = 6.0;
            let cmd = JointCommand::Servo {
                q,
                lookahead_s: 0.03,
                gain: 2000.0,
            };
            let mut peak: f64 = 0.0;
            for _ in 0..4000 {
                r.send(&cmd).unwrap();
                r.step();
                peak = peak.max(read(&mut r).actual_qd[0]);
            }
            peak
        };
        assert!((peak(1.0) - PI).abs() < 1e-9);
        assert!((peak(0.5) - PI / 2.0).abs() < 1e-9);
    }

    #[test]
    fn pause_and_stop_program_follow_ur_runtime_states() {
        let mut r = robot();
        r.send(&speed(1.0, PI)).unwrap();
        run(&mut r, 400);
        r.pause();
        run(&mut r, 1);
        let s = read(&mut r);
        assert_eq!(s.runtime_state, runtime_state::PAUSING);
        assert_eq!(s.speed_scaling, 0.0);
        assert_eq!(s.robot_status_bits & BIT_PROGRAM_RUNNING, 0);
        run(&mut r, 400);
        assert_eq!(read(&mut r).runtime_state, runtime_state::PAUSED);
        assert_eq!(read(&mut r).actual_qd, [0.0; 6]);
        r.stop_program();
        run(&mut r, 1);
        assert_eq!(read(&mut r).runtime_state, runtime_state::STOPPED);
        assert!(r.play());
        run(&mut r, 1);
        let s = read(&mut r);
        assert_eq!(s.runtime_state, runtime_state::PLAYING);
        assert_eq!(s.speed_scaling, 1.0);
        assert_eq!(s.robot_status_bits, BIT_POWER_ON | BIT_PROGRAM_RUNNING);
    }

    #[test]
    fn joints_stay_within_position_limits() {
        let mut r = robot();
        r.send(&JointCommand::Speed {
            qd: [PI, PI, -PI, PI, -PI, PI],
            acc: PI,
        })
        .unwrap();
        let mut max_excursion: f64 = 0.0;
        for _ in 0..5000 {
            r.step();
            let s = read(&mut r);
            for q in s.actual_q {
                assert!(q.abs() <= TAU, "{q}");
                max_excursion = max_excursion.max(q.abs());
            }
        }
        assert!(
            max_excursion > TAU - 1e-3,
            "reached the limit: {max_excursion}"
        );
        assert_eq!(read(&mut r).actual_qd[0], 0.0, "held at the limit");
    }

    #[test]
    fn invalid_commands_and_configs_are_refused() {
        let mut r = robot();
        let bad = [
            JointCommand::Servo {
                q: [f64::NAN; 6],
                lookahead_s: 0.1,
                gain: 300.0,
            },
            JointCommand::Servo {
                q: HOME,
                lookahead_s: 0.01,
                gain: 300.0,
            },
            JointCommand::Servo {
                q: HOME,
                lookahead_s: 0.1,
                gain: 5000.0,
            },
            speed(f64::INFINITY, 1.0),
            speed(0.1, 0.0),
            JointCommand::Stop { decel: -1.0 },
        ];
        for cmd in bad {
            assert!(
                matches!(r.send(&cmd), Err(RobotIoError::InvalidCommand { .. })),
                "{cmd:?}"
            );
        }
        assert!(r.command().is_none());

        let mut c = SimConfig::ur5e();
        c.initial_q_rad[3] = 7.0;
        assert!(matches!(
            SimRobot::new(c),
            Err(RobotIoError::InvalidSimConfig {
                field: "initial_q_rad",
                ..
            })
        ));
        let mut c = SimConfig::ur5e();
        c.max_acc_rad_s2[1] = 0.0;
        assert!(SimRobot::new(c).is_err());
        let mut c = SimConfig::ur5e();
        c.min_q_rad[0] = 1.0;
        c.max_q_rad[0] = -1.0;
        assert!(SimRobot::new(c).is_err());
    }

    #[test]
    fn tcp_speed_matches_the_pose_change() {
        let mut r = robot();
        r.send(&speed(0.5, PI)).unwrap();
        run(&mut r, 300);
        let a = read(&mut r);
        r.step();
        let b = read(&mut r);
        for k in 0..3 {
            let fd = (b.actual_tcp_pose[k] - a.actual_tcp_pose[k]) / CYCLE_S;
            assert!((b.actual_tcp_speed[k] - fd).abs() < 1e-9);
        }
        // Rotating the base at 0.5 rad/s turns the flange at 0.5 rad/s about the base z axis.
        assert!(
            (b.actual_tcp_speed[5] - 0.5).abs() < 1e-9,
            "{:?}",
            b.actual_tcp_speed
        );
        assert!(b.actual_tcp_speed[3].abs() < 1e-9 && b.actual_tcp_speed[4].abs() < 1e-9);
    }

    #[test]
    fn runs_are_deterministic() {
        let trial = || {
            let mut r = robot();
            let mut log = Vec::new();
            for i in 0..1500 {
                let cmd = match i {
                    0 => Some(speed(0.8, 2.0)),
                    500 => Some(JointCommand::Stop { decel: 1.5 }),
                    _ if i > 900 => Some(JointCommand::Servo {
                        q: [0.3, -1.2, 0.4, -1.5, 0.2, 0.1],
                        lookahead_s: 0.05,
                        gain: 500.0,
                    }),
                    _ => None,
                };
                if let Some(cmd) = cmd {
                    r.send(&cmd).unwrap();
                }
                if i == 700 {
                    r.inject_dropped_cycles(3);
                }
                r.step();
                log.push(read(&mut r));
            }
            log
        };
        assert_eq!(trial(), trial());
    }
}
