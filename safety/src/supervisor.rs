//! [`Supervisor`]: owns the robot, judges every command, and is the only path to
//! `Robot::send`.

use robot_io::geometry::{ARM_CAPSULES, BodyPart, Capsule, HumanBody, closest_approaches};
use robot_io::{JointCommand, Joints, Robot, RobotState, safety_mode, safety_status_bits};

use crate::config::SupervisorConfig;
use crate::error::{Result, SafetyError};
use crate::points::{arm_points, distance};
use crate::separation::{RobotMotion, protective_distance_m};
use crate::verdict::{Counters, MalformedInput, Requirement, Verdict, Violation};

/// servoj lookahead range UR's controller accepts [s].
const SERVO_LOOKAHEAD_RANGE_S: (f64, f64) = (0.03, 0.2);
/// servoj gain range UR's controller accepts [-].
const SERVO_GAIN_RANGE: (f64, f64) = (100.0, 2000.0);
/// Scales are taken this much under a TCP speed cap so the (nonlinear) scaled step lands
/// under it [-].
const TCP_SCALE_MARGIN: f64 = 1e-3;
/// Relative tolerance of the final re-check against rounding [-].
const RECHECK_TOLERANCE: f64 = 1e-9;

/// What the supervisor knows of the world outside the robot in this cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldView {
    /// Time of this cycle on the trial's clock [s] (logged; the checks use ages, not times).
    pub now_s: f64,
    /// The operator's tracked body (head, hands, torso) in the robot base frame [m]; a part
    /// that is `None` is not tracked (and not protected by SAF-REQ-007). A non-finite point
    /// or torso normal is malformed input (SAF-REQ-001).
    pub human: HumanBody,
    /// Age of the perception frame the body comes from [s].
    pub perception_age_s: f64,
    /// Whether a collaboration period C(t) is active (the task phase is Approach, Present or
    /// Release).
    pub collaborating: bool,
}

impl WorldView {
    /// No human tracked, fresh perception, no collaboration, at time `now_s` [s].
    pub fn clear(now_s: f64) -> Self {
        Self {
            now_s,
            human: HumanBody::NONE,
            perception_age_s: 0.0,
            collaborating: false,
        }
    }

    fn is_finite(&self) -> bool {
        self.now_s.is_finite()
            && self.perception_age_s.is_finite()
            && self.perception_age_s >= 0.0
            && self.human.is_finite()
    }
}

/// A command the supervisor has approved. Only the supervisor can build one (its constructor
/// is private), and `Robot::send` is called only with one.
///
/// ```compile_fail
/// // Outside the supervisor a SafeCommand cannot be built.
/// let approved = safety::SafeCommand(robot_io::JointCommand::Stop { decel: 3.0 });
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafeCommand(JointCommand);

impl SafeCommand {
    /// The approved command.
    pub fn command(&self) -> &JointCommand {
        &self.0
    }
}

/// How the previous servo target continues: the last sent target [rad] and its implied
/// velocity [rad/s].
#[derive(Debug, Clone, Copy, PartialEq)]
struct ServoReference {
    q: Joints,
    v: Joints,
    /// Controller time the command stands for [s]: the timestamp of the state it was judged
    /// on, or one cycle after the previous command's if that state was not newer (a cycle run
    /// on a held state is still a cycle).
    timestamp_s: f64,
    /// The period that command covered [s] (its `v` is the mean velocity over it).
    period_s: f64,
}

/// A motion command in the supervisor's terms: the command moves the joints from `q_from`
/// [rad] at velocity `v` [rad/s] for one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Motion {
    servo: Option<(f64, f64)>,
    /// The period the command covers [s]: one cycle, or for a servo step the controller time
    /// since the previous servo command (missed cycles), up to
    /// `SupervisorConfig::command_period_cycles` (a longer gap is judged as if it were this
    /// long, which overstates the implied speed: conservative).
    dt_s: f64,
    /// The time over which `v_prev` changes into `v` [s]: for two servo steps, the time
    /// between the middles of their periods, (previous period + this one) / 2 (each implied
    /// velocity is the mean over its own period); else `dt_s`.
    dv_period_s: f64,
    /// The controller time this command stands for [s] (see `ServoReference::timestamp_s`).
    ref_timestamp_s: f64,
    acc_rad_s2: f64,
    q_from: Joints,
    v: Joints,
    v_prev: Joints,
}

/// The speed limits in force this cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Caps {
    /// Joint speed [rad/s], perception reduction applied.
    joint_rad_s: f64,
    /// TCP speed [m/s], collaboration and perception reduction applied.
    tcp_m_s: f64,
    /// TCP speed without the perception reduction [m/s].
    tcp_unreduced_m_s: f64,
    /// Perception age when it reduces the caps [s].
    stale_age_s: Option<f64>,
}

/// Owns the robot and judges every command against [`SupervisorConfig`] (see the crate docs
/// for the requirements). Build with [`Supervisor::new`]; each control cycle call
/// [`Supervisor::read_state`] then [`Supervisor::step`].
#[derive(Debug)]
pub struct Supervisor<R: Robot> {
    robot: R,
    config: SupervisorConfig,
    state: RobotState,
    last_read_ok: bool,
    last_step_timestamp_s: Option<f64>,
    stale_cycles: u32,
    servo_ref: Option<ServoReference>,
    last_sent: Option<SafeCommand>,
    last_send_ok: bool,
    latched: Option<Violation>,
    latched_at_timestamp_s: f64,
    last_logged: Option<(u8, Option<Requirement>)>,
    counters: Counters,
}

impl<R: Robot> Supervisor<R> {
    /// Take ownership of `robot`, check `config`'s relations and read the first state.
    pub fn new(robot: R, config: SupervisorConfig) -> Result<Self> {
        config.validate()?;
        let mut supervisor = Self {
            robot,
            config,
            state: RobotState::default(),
            last_read_ok: false,
            last_step_timestamp_s: None,
            stale_cycles: 0,
            servo_ref: None,
            last_sent: None,
            last_send_ok: true,
            latched: None,
            latched_at_timestamp_s: 0.0,
            last_logged: None,
            counters: Counters::default(),
        };
        let mut first = RobotState::default();
        supervisor.read_state(&mut first)?;
        Ok(supervisor)
    }

    /// Read the robot's state into `out` (and keep a copy for the checks). On error the
    /// previous state is kept; the robot-state staleness check (SAF-REQ-009) then stops the
    /// robot after 3 cycles. Allocates nothing unless the robot's error does.
    pub fn read_state(&mut self, out: &mut RobotState) -> Result<()> {
        match self.robot.read_state(&mut self.state) {
            Ok(()) => {
                self.last_read_ok = true;
                *out = self.state;
                Ok(())
            }
            Err(e) => {
                // Logged once per run of failures (a link that is down fails every cycle, 500
                // lines a second); every failure still reaches the caller and the staleness
                // count.
                if self.last_read_ok {
                    tracing::warn!(error = %e, "reading the robot state failed (logged once until a read succeeds)");
                }
                self.last_read_ok = false;
                Err(SafetyError::Robot(e))
            }
        }
    }

    /// The latest robot state read.
    pub fn state(&self) -> &RobotState {
        &self.state
    }

    /// The robot, read-only (for diagnostics; it cannot be commanded from outside).
    pub fn robot(&self) -> &R {
        &self.robot
    }

    /// The configuration.
    pub fn config(&self) -> &SupervisorConfig {
        &self.config
    }

    /// The latched fault, if any.
    pub fn latched(&self) -> Option<Violation> {
        self.latched
    }

    /// The running counts.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// The last command sent to the robot.
    pub fn last_sent(&self) -> Option<&SafeCommand> {
        self.last_sent.as_ref()
    }

    /// Judge `cmd` against the limits, the latest robot state and `world`, send the command,
    /// a scaled version of it or a stop, and say what happened. The only path to
    /// `Robot::send`. Allocates nothing and does not block (beyond `Robot::send`).
    pub fn step(&mut self, cmd: &JointCommand, world: &WorldView) -> Verdict {
        self.track_state_freshness();
        let (verdict, command) = self.judge(cmd, world);
        let verdict = self.send(command, verdict);
        self.counters.record(&verdict);
        self.log(&verdict, world);
        verdict
    }

    /// Clear a latched fault (SAF-REQ-011). Succeeds only when the cause is gone: for a robot
    /// safety stop, a state read after the fault shows NORMAL with no stop bits; for a failed
    /// send, a later stop was delivered. A reset with nothing latched succeeds.
    pub fn reset(&mut self) -> Result<()> {
        let Some(fault) = self.latched else {
            return Ok(());
        };
        if let Some(cause) = self.fault_still_present(&fault) {
            self.counters.resets_refused = self.counters.resets_refused.saturating_add(1);
            self.counters.bump(Requirement::Saf011Latch);
            tracing::warn!(requirement = Requirement::Saf011Latch.id(), fault = %fault, cause = %cause, "reset refused");
            return Err(SafetyError::ResetRefused { cause });
        }
        self.latched = None;
        self.servo_ref = None;
        // The robot state's staleness (SAF-REQ-009) is not part of the latch: it counts the
        // states as they come, and only a fresh state clears it. (Clearing it here let a
        // reset during a frozen state pass commands for 3 more cycles; found by
        // `saf_req_all_no_command_breaks_a_limit`.)
        self.counters.resets = self.counters.resets.saturating_add(1);
        tracing::info!(requirement = Requirement::Saf011Latch.id(), fault = %fault, "latched fault reset");
        Ok(())
    }

    // --- the decision, step by step ---

    fn track_state_freshness(&mut self) {
        let ts = self.state.timestamp_s;
        let fresh = match self.last_step_timestamp_s {
            None => ts.is_finite(),
            Some(previous) => ts > previous,
        };
        if fresh {
            self.stale_cycles = 0;
            self.last_step_timestamp_s = Some(ts);
        } else {
            self.stale_cycles = self.stale_cycles.saturating_add(1);
        }
    }

    fn judge(&mut self, cmd: &JointCommand, world: &WorldView) -> (Verdict, JointCommand) {
        if let Some(violation) = self.latched {
            return (Verdict::Halted { violation }, self.stop_command());
        }
        if let Some(violation) = self.robot_safety_stop() {
            self.latch(violation);
            return (Verdict::Halted { violation }, self.stop_command());
        }
        match self.check_inputs(world) {
            Err(violation) => (Verdict::Stopped { violation }, self.stop_command()),
            Ok(caps) => self.judge_command(cmd, world, &caps),
        }
    }

    fn robot_safety_stop(&self) -> Option<Violation> {
        let stop_bits = safety_status_bits::PROTECTIVE_STOP
            | safety_status_bits::EMERGENCY_STOP
            | safety_status_bits::STOPPED_DUE_TO_SAFETY;
        let s = &self.state;
        if s.safety_mode != safety_mode::NORMAL || s.safety_status_bits & stop_bits != 0 {
            Some(Violation::RobotSafetyStop {
                safety_mode: s.safety_mode,
                safety_status_bits: s.safety_status_bits,
            })
        } else {
            None
        }
    }

    fn latch(&mut self, violation: Violation) {
        if self.latched.is_none() {
            self.latched = Some(violation);
            self.latched_at_timestamp_s = self.state.timestamp_s;
            tracing::error!(requirement = violation.requirement().id(), fault = %violation, "fault latched");
        }
    }

    fn fault_still_present(&self, fault: &Violation) -> Option<Violation> {
        match fault {
            Violation::SendFailed if !self.last_send_ok => Some(Violation::SendFailed),
            Violation::SendFailed => None,
            _ => {
                if let Some(still) = self.robot_safety_stop() {
                    return Some(still);
                }
                let newer = self.state.timestamp_s > self.latched_at_timestamp_s;
                if self.last_read_ok && newer {
                    None
                } else {
                    // No state read since the fault: the cause cannot be shown to be gone.
                    Some(*fault)
                }
            }
        }
    }

    /// Robot-state staleness, robot state and world view sanity, perception staleness; on
    /// success, the speed caps in force.
    fn check_inputs(&self, world: &WorldView) -> std::result::Result<Caps, Violation> {
        let staleness = &self.config.staleness;
        let limit_cycles = staleness.robot_state_max_stale_cycles();
        if self.stale_cycles > limit_cycles {
            return Err(Violation::RobotStateStale {
                cycles: self.stale_cycles,
                limit_cycles,
            });
        }
        if !robot_state_is_finite(&self.state) {
            return Err(Violation::Malformed {
                input: MalformedInput::RobotState,
            });
        }
        if !world.is_finite() {
            return Err(Violation::Malformed {
                input: MalformedInput::WorldView,
            });
        }
        let age = world.perception_age_s;
        if age > staleness.perception_stop_after_s() {
            return Err(Violation::PerceptionStale {
                age_s: age,
                limit_s: staleness.perception_stop_after_s(),
            });
        }
        let stale = age > staleness.perception_reduce_after_s();
        let scale = if stale {
            self.config.stale_perception_scale.get()
        } else {
            1.0
        };
        let tcp_unreduced = if world.collaborating {
            self.config.collaboration_tcp_speed.m_s()
        } else {
            self.config.tcp_speed.m_s()
        };
        Ok(Caps {
            joint_rad_s: self.config.joint_rates.max_speed_rad_s() * scale,
            tcp_m_s: tcp_unreduced * scale,
            tcp_unreduced_m_s: tcp_unreduced,
            stale_age_s: if stale { Some(age) } else { None },
        })
    }

    fn judge_command(
        &mut self,
        cmd: &JointCommand,
        world: &WorldView,
        caps: &Caps,
    ) -> (Verdict, JointCommand) {
        let motion = match self.motion_of(cmd) {
            Ok(Some(motion)) => motion,
            Ok(None) => return self.pass_stop(cmd),
            Err(violation) => return (Verdict::Stopped { violation }, self.stop_command()),
        };
        match self.judge_motion(&motion, world, caps) {
            Ok((scale, reason, command)) => {
                let verdict = match reason {
                    None => Verdict::Passed,
                    Some(violation) => Verdict::Reduced { scale, violation },
                };
                (verdict, command)
            }
            Err(violation) => (Verdict::Stopped { violation }, self.stop_command()),
        }
    }

    /// An upstream stop passes, at no less than the configured deceleration.
    fn pass_stop(&self, cmd: &JointCommand) -> (Verdict, JointCommand) {
        let floor = self.config.joint_rates.stop_decel_rad_s2();
        match *cmd {
            JointCommand::Stop { decel } if decel.is_finite() && decel > 0.0 => (
                Verdict::Passed,
                JointCommand::Stop {
                    decel: decel.max(floor),
                },
            ),
            _ => (
                Verdict::Stopped {
                    violation: Violation::Malformed {
                        input: MalformedInput::CommandValue,
                    },
                },
                self.stop_command(),
            ),
        }
    }

    /// The motion a command asks for; `Ok(None)` for a stop; `Err` for malformed values.
    fn motion_of(&self, cmd: &JointCommand) -> std::result::Result<Option<Motion>, Violation> {
        let value = Violation::Malformed {
            input: MalformedInput::CommandValue,
        };
        let cycle = self.config.cycle.seconds();
        let max_period = f64::from(self.config.command_period_cycles.get()) * cycle;
        match *cmd {
            JointCommand::Stop { .. } => Ok(None),
            JointCommand::Servo {
                q,
                lookahead_s,
                gain,
            } => {
                if !(all_finite(&q) && lookahead_s.is_finite() && gain.is_finite()) {
                    return Err(value);
                }
                let (lo, hi) = SERVO_LOOKAHEAD_RANGE_S;
                let (g_lo, g_hi) = SERVO_GAIN_RANGE;
                if !(lo..=hi).contains(&lookahead_s) || !(g_lo..=g_hi).contains(&gain) {
                    return Err(Violation::Malformed {
                        input: MalformedInput::ServoParameter,
                    });
                }
                let (q_from, v_prev, dt, dv_period, ref_ts) = match self.servo_ref {
                    Some(r) => {
                        // The controller's clock rule (`robot_io::cycle_time_s`), so the
                        // period judged is the one the controller advanced its plan by.
                        let ref_ts =
                            robot_io::cycle_time_s(r.timestamp_s, self.state.timestamp_s, cycle);
                        let elapsed = ref_ts - r.timestamp_s;
                        let dt = if elapsed.is_finite() {
                            elapsed.clamp(cycle, max_period)
                        } else {
                            cycle
                        };
                        (r.q, r.v, dt, 0.5 * (r.period_s + dt), ref_ts)
                    }
                    None => (
                        self.state.target_q,
                        self.state.target_qd,
                        cycle,
                        cycle,
                        self.state.timestamp_s,
                    ),
                };
                let v = map2(&q, &q_from, |a, b| (a - b) / dt);
                Ok(Some(Motion {
                    servo: Some((lookahead_s, gain)),
                    dt_s: dt,
                    dv_period_s: dv_period,
                    ref_timestamp_s: ref_ts,
                    acc_rad_s2: self.config.joint_rates.max_acc_rad_s2(),
                    q_from,
                    v,
                    v_prev,
                }))
            }
            JointCommand::Speed { qd, acc } => {
                if !(all_finite(&qd) && acc.is_finite() && acc > 0.0) {
                    return Err(value);
                }
                Ok(Some(Motion {
                    servo: None,
                    dt_s: cycle,
                    dv_period_s: cycle,
                    ref_timestamp_s: self.state.timestamp_s,
                    acc_rad_s2: acc,
                    q_from: self.state.actual_q,
                    v: qd,
                    v_prev: self.state.actual_qd,
                }))
            }
        }
    }

    /// Scale the motion to the caps, then check positions, workspace and separation of the
    /// result. `Ok((scale, reason, command))`, where `reason` is `None` when unchanged.
    fn judge_motion(
        &mut self,
        motion: &Motion,
        world: &WorldView,
        caps: &Caps,
    ) -> std::result::Result<(f64, Option<Violation>, JointCommand), Violation> {
        let dt = motion.dt_s;
        let a_max = self.config.joint_rates.max_acc_rad_s2();
        let (cap_scale, cap_reason) = self.speed_cap_scale(motion, caps);
        let (scale, mut reason) = match motion.servo {
            Some(_) => servo_scale(motion, cap_scale, cap_reason, a_max * motion.dv_period_s)?,
            None => (cap_scale, cap_reason),
        };
        let v = map1(&motion.v, |x| x * scale);
        let q_next = map2(&motion.q_from, &v, |q, v| q + v * dt);
        let mut acc = motion.acc_rad_s2;
        if motion.servo.is_none() && acc > a_max {
            reason = reason.or(Some(Violation::JointAcceleration {
                joint: 0,
                value_rad_s2: acc,
                limit_rad_s2: a_max,
            }));
            acc = a_max;
        }
        self.recheck_speeds(motion, &v, caps)?;
        let q_stop = self.stopping_position(&q_next, &v);
        self.check_positions(&q_next, &q_stop)?;
        self.check_workspace(&q_next, &q_stop)?;
        self.check_separation(&q_stop, &v, motion, world)?;
        let command = match motion.servo {
            Some((lookahead_s, gain)) => {
                self.servo_ref = Some(ServoReference {
                    q: q_next,
                    v,
                    timestamp_s: motion.ref_timestamp_s,
                    period_s: dt,
                });
                JointCommand::Servo {
                    q: q_next,
                    lookahead_s,
                    gain,
                }
            }
            None => JointCommand::Speed { qd: v, acc },
        };
        Ok((scale, reason, command))
    }

    /// The largest scale in [0, 1] meeting the joint and TCP speed caps, and the binding cap.
    fn speed_cap_scale(&self, motion: &Motion, caps: &Caps) -> (f64, Option<Violation>) {
        let mut scale = 1.0;
        let mut reason = None;
        let full_joint = self.config.joint_rates.max_speed_rad_s();
        for (joint, &v) in motion.v.iter().enumerate() {
            let speed = v.abs();
            if speed > caps.joint_rad_s {
                let s = caps.joint_rad_s / speed;
                if s < scale {
                    scale = s;
                    reason = Some(self.cap_violation(
                        speed > full_joint,
                        Violation::JointSpeed {
                            joint,
                            value_rad_s: speed,
                            limit_rad_s: caps.joint_rad_s,
                        },
                        caps,
                    ));
                }
            }
        }
        let tcp = tcp_speed_m_s(&motion.q_from, &motion.v, self.config.cycle.seconds());
        if tcp > caps.tcp_m_s {
            let s = caps.tcp_m_s / tcp * (1.0 - TCP_SCALE_MARGIN);
            if s < scale {
                scale = s;
                reason = Some(self.cap_violation(
                    tcp > caps.tcp_unreduced_m_s,
                    Violation::TcpSpeed {
                        value_m_s: tcp,
                        limit_m_s: caps.tcp_m_s,
                    },
                    caps,
                ));
            }
        }
        (scale, reason)
    }

    /// A cap broken only because perception is stale is reported as SAF-REQ-008.
    fn cap_violation(&self, over_unreduced: bool, violation: Violation, caps: &Caps) -> Violation {
        match caps.stale_age_s {
            Some(age_s) if !over_unreduced => Violation::PerceptionStale {
                age_s,
                limit_s: self.config.staleness.perception_reduce_after_s(),
            },
            _ => violation,
        }
    }

    /// Re-check the scaled velocity against the joint and TCP caps (the TCP is nonlinear in
    /// the scale). A motion decelerating on every joint may stay above a cap that just dropped.
    fn recheck_speeds(
        &self,
        motion: &Motion,
        v: &Joints,
        caps: &Caps,
    ) -> std::result::Result<(), Violation> {
        let decelerating = v
            .iter()
            .zip(&motion.v_prev)
            .all(|(now, before)| now.abs() <= before.abs());
        let full_joint = self.config.joint_rates.max_speed_rad_s();
        let joint_cap = if decelerating {
            full_joint
        } else {
            caps.joint_rad_s
        };
        for (joint, &x) in v.iter().enumerate() {
            if x.abs() > joint_cap * (1.0 + RECHECK_TOLERANCE) {
                return Err(Violation::JointSpeed {
                    joint,
                    value_rad_s: x.abs(),
                    limit_rad_s: joint_cap,
                });
            }
        }
        let tcp = tcp_speed_m_s(&motion.q_from, v, self.config.cycle.seconds());
        let tcp_cap = if decelerating {
            self.config.tcp_speed.m_s()
        } else {
            caps.tcp_m_s
        };
        if tcp > tcp_cap * (1.0 + RECHECK_TOLERANCE) {
            return Err(Violation::TcpSpeed {
                value_m_s: tcp,
                limit_m_s: tcp_cap,
            });
        }
        Ok(())
    }

    /// Where the joints come to rest [rad] if a stop follows this command: all joints stop
    /// together, the fastest at the stop deceleration.
    fn stopping_position(&self, q_next: &Joints, v: &Joints) -> Joints {
        let t_stop = self.stopping_time_s(v);
        map2(q_next, v, |q, v| q + v * t_stop / 2.0)
    }

    fn stopping_time_s(&self, v: &Joints) -> f64 {
        let fastest = v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        fastest / self.config.joint_rates.stop_decel_rad_s2()
    }

    fn check_positions(
        &self,
        q_next: &Joints,
        q_stop: &Joints,
    ) -> std::result::Result<(), Violation> {
        for q in [q_next, q_stop] {
            if let Some((joint, value_rad, limit_rad)) = self.config.joint_limits.first_violation(q)
            {
                return Err(Violation::JointOutOfLimit {
                    joint,
                    value_rad,
                    limit_rad,
                });
            }
        }
        Ok(())
    }

    fn check_workspace(
        &self,
        q_next: &Joints,
        q_stop: &Joints,
    ) -> std::result::Result<(), Violation> {
        for q in [q_next, q_stop] {
            for (point, position_m) in arm_points(q).as_array() {
                if !self.config.workspace.contains(&position_m) {
                    return Err(Violation::OutsideWorkspace { point, position_m });
                }
            }
        }
        Ok(())
    }

    /// SAF-REQ-007: every tracked body part's surface must be at least S_p from the surface
    /// of every arm capsule (links, gripper, carried part), at the measured joints now and at
    /// the stopping configuration. v_r is the larger of the commanded and measured TCP speed,
    /// T_s the longer of the stops from the commanded and the measured joint speeds, v_h per
    /// body part (walking for the head and torso, arm reach for the hands). The violation
    /// names the part and the nearest link. Allocates nothing.
    fn check_separation(
        &self,
        q_stop: &Joints,
        v: &Joints,
        motion: &Motion,
        world: &WorldView,
    ) -> std::result::Result<(), Violation> {
        if world.human == HumanBody::NONE {
            return Ok(());
        }
        let dt = self.config.cycle.seconds();
        let [tx, ty, tz, ..] = self.state.actual_tcp_speed;
        let measured = (tx * tx + ty * ty + tz * tz).sqrt();
        let commanded = tcp_speed_m_s(&motion.q_from, v, dt);
        let t_stop = self
            .stopping_time_s(v)
            .max(self.stopping_time_s(&self.state.actual_qd));
        let robot = RobotMotion {
            speed_m_s: commanded.max(measured),
            stopping_time_s: t_stop,
        };
        let mut now = [Capsule::point([0.0; 3], 0.0); ARM_CAPSULES];
        let mut stop = now;
        self.config.arm.capsules(&self.state.actual_q, &mut now);
        self.config.arm.capsules(q_stop, &mut stop);
        let body = &self.config.body;
        let now = closest_approaches(&now, &world.human, body);
        let stop = closest_approaches(&stop, &world.human, body);
        for ((part, at_now), at_stop) in BodyPart::ALL.iter().zip(&now).zip(&stop) {
            let required_m = protective_distance_m(
                &self.config.separation,
                *part,
                robot,
                world.perception_age_s,
            );
            for approach in [at_now, at_stop].into_iter().flatten() {
                let distance_m = approach.distance_m;
                if distance_m.is_nan() || required_m.is_nan() || distance_m < required_m {
                    return Err(Violation::Separation {
                        part: *part,
                        link: approach.link,
                        distance_m,
                        required_m,
                    });
                }
            }
        }
        Ok(())
    }

    // --- sending, logging ---

    fn stop_command(&self) -> JointCommand {
        JointCommand::Stop {
            decel: self.config.joint_rates.stop_decel_rad_s2(),
        }
    }

    /// The only call of `Robot::send`.
    fn send(&mut self, command: JointCommand, verdict: Verdict) -> Verdict {
        if matches!(
            command,
            JointCommand::Stop { .. } | JointCommand::Speed { .. }
        ) {
            self.servo_ref = None;
        }
        let approved = SafeCommand(command);
        match self.robot.send(approved.command()) {
            Ok(()) => {
                self.last_send_ok = true;
                self.last_sent = Some(approved);
                verdict
            }
            Err(e) => {
                self.last_send_ok = false;
                self.servo_ref = None;
                tracing::error!(requirement = Requirement::Saf012SendFailed.id(), error = %e, "sending to the robot failed");
                let violation = self.latched.unwrap_or(Violation::SendFailed);
                self.latch(violation);
                // Try to stop the robot all the same.
                let stop = SafeCommand(JointCommand::Stop {
                    decel: self.config.joint_rates.stop_decel_rad_s2(),
                });
                if self.robot.send(stop.command()).is_ok() {
                    self.last_sent = Some(stop);
                }
                Verdict::Halted { violation }
            }
        }
    }

    /// Log each change of verdict (kind or requirement) at warn/info level, every verdict at
    /// trace level. Formats nothing unless a subscriber is interested.
    fn log(&mut self, verdict: &Verdict, world: &WorldView) {
        let kind: u8 = match verdict {
            Verdict::Passed => 0,
            Verdict::Reduced { .. } => 1,
            Verdict::Stopped { .. } => 2,
            Verdict::Halted { .. } => 3,
        };
        let key = (kind, verdict.requirement());
        let changed = self.last_logged != Some(key);
        self.last_logged = Some(key);
        let now_s = world.now_s;
        match verdict {
            Verdict::Passed if changed => tracing::info!(now_s, "commands pass"),
            Verdict::Reduced { scale, violation } if changed => {
                tracing::info!(now_s, requirement = violation.requirement().id(), scale, violation = %violation, "speed reduced")
            }
            Verdict::Stopped { violation } if changed => {
                tracing::warn!(now_s, requirement = violation.requirement().id(), violation = %violation, "command replaced by a stop")
            }
            Verdict::Halted { violation } if changed => {
                tracing::error!(now_s, requirement = violation.requirement().id(), violation = %violation, "halted: fault latched")
            }
            _ => tracing::trace!(now_s, ?verdict, "verdict"),
        }
    }
}

/// The scale for a servo motion that keeps the implied acceleration within `dv_max` [rad/s]
/// per cycle: the cap scale if it is reachable; the highest reachable scale if the cap is
/// above it; the lowest reachable one if the cap is below it and every joint decelerates
/// (possibly > 1; reported with the cap's reason, or SAF-REQ-004 when no cap binds); otherwise
/// the motion is refused (SAF-REQ-004).
fn servo_scale(
    motion: &Motion,
    cap_scale: f64,
    cap_reason: Option<Violation>,
    dv_max: f64,
) -> std::result::Result<(f64, Option<Violation>), Violation> {
    let acceleration_at = |s: f64| -> Violation {
        let mut worst = (0, 0.0);
        for (joint, (v, v_prev)) in motion.v.iter().zip(&motion.v_prev).enumerate() {
            let dv = (s * v - v_prev).abs();
            if dv > worst.1 {
                worst = (joint, dv);
            }
        }
        let (joint, dv) = worst;
        let dt_per_dv = motion.acc_rad_s2 / dv_max;
        Violation::JointAcceleration {
            joint,
            value_rad_s2: dv * dt_per_dv,
            limit_rad_s2: motion.acc_rad_s2,
        }
    };
    let Some((lo, hi)) = acceleration_interval(&motion.v, &motion.v_prev, dv_max) else {
        return Err(acceleration_at(cap_scale));
    };
    if cap_scale > hi {
        return Ok((hi, Some(acceleration_at(cap_scale))));
    }
    if cap_scale >= lo {
        return Ok((cap_scale, cap_reason));
    }
    let decelerating = motion
        .v
        .iter()
        .zip(&motion.v_prev)
        .all(|(v, v_prev)| (lo * v).abs() <= v_prev.abs());
    if decelerating {
        // Slow it at the limit along its direction: `lo` > the cap scale, maybe > 1 (more
        // speed than asked). The command is changed, so a reason is reported: the cap that
        // made it slow down, or — when the command itself decelerates harder than the limit
        // allows — the acceleration limit (SAF-REQ-004).
        Ok((lo, cap_reason.or_else(|| Some(acceleration_at(cap_scale)))))
    } else {
        Err(acceleration_at(cap_scale))
    }
}

/// The scales `s` ≥ 0 for which `|s·v_j − v_prev_j| ≤ dv_max` on every joint, as `[lo, hi]`;
/// `None` if there are none.
fn acceleration_interval(v: &Joints, v_prev: &Joints, dv_max: f64) -> Option<(f64, f64)> {
    // Shrink by a hair so that rounding does not push the chosen end over the limit.
    let dv = dv_max * (1.0 - RECHECK_TOLERANCE);
    let mut lo: f64 = 0.0;
    let mut hi = f64::INFINITY;
    for (&v, &v_prev) in v.iter().zip(v_prev) {
        if v == 0.0 {
            if v_prev.abs() > dv {
                return None;
            }
            continue;
        }
        let a = (v_prev - dv) / v;
        let b = (v_prev + dv) / v;
        let (l, h) = if v > 0.0 { (a, b) } else { (b, a) };
        lo = lo.max(l);
        hi = hi.min(h);
    }
    if lo <= hi { Some((lo, hi)) } else { None }
}

/// Instantaneous TCP speed [m/s] at joint positions `q` [rad] with joint velocity `v`
/// [rad/s]: `|J(q)·v|`, evaluated as a finite difference over a step of at most 1e-4 rad per
/// joint (so it is linear in `v` to ~1e-8 relative). `dt` [s] bounds the probe step.
pub(crate) fn tcp_speed_m_s(q: &Joints, v: &Joints, dt: f64) -> f64 {
    let fastest = v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    if fastest == 0.0 {
        return 0.0;
    }
    let h = dt.min(1e-4 / fastest);
    let q_probe = map2(q, v, |q, v| q + v * h);
    distance(&arm_points(q).tcp, &arm_points(&q_probe).tcp) / h
}

fn all_finite(values: &Joints) -> bool {
    values.iter().all(|x| x.is_finite())
}

fn robot_state_is_finite(s: &RobotState) -> bool {
    s.timestamp_s.is_finite()
        && all_finite(&s.actual_q)
        && all_finite(&s.actual_qd)
        && all_finite(&s.target_q)
        && all_finite(&s.target_qd)
        && s.actual_tcp_speed.iter().all(|x| x.is_finite())
}

fn map1(a: &Joints, f: impl Fn(f64) -> f64) -> Joints {
    a.map(f)
}

fn map2(a: &Joints, b: &Joints, f: impl Fn(f64, f64) -> f64) -> Joints {
    let mut out = [0.0; 6];
    for (o, (&x, &y)) in out.iter_mut().zip(a.iter().zip(b)) {
        *o = f(x, y);
    }
    out
}
