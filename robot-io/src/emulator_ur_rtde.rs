//! The emulator's runner of SDU ur_rtde's control script (issue 11): what a controller does
//! with the `rtde_control.script` that ur_rtde 1.6.5's `RTDEControlInterface` uploads.
//!
//! ur_rtde sends its script to port 30003 (`def rtde_control(): … end`) and then talks to it
//! over RTDE registers, `reg_offset` = 0 (registers 0–23) or 24 with its upper-range flag:
//! - `input_int_register_<off+0>`: the command (ur_rtde's `RobotCommand::Type`), 0 = none;
//!   `input_int_register_<off+1>`: the async flag of moveJ/stopJ; `input_double_register_
//!   <off+0…>`: the arguments.
//! - `output_int_register_<off+0>`: the script's state, 1 = ready for a command, 2 = done
//!   with the command; `output_int_register_<off+1>`: a getter's integer result;
//!   `output_int_register_<off+2>`: the async progress register; `output_double_register_
//!   <off+0…5>`: a getter's vector result.
//!
//! [`UrRtdeControl::cycle`] runs one iteration of the script's main loop per 2 ms controller
//! cycle, as the script does (one `sync()` per iteration): a "real-time" command (servoJ,
//! speedJ, the RT getters) is processed every cycle it stands in the register and the script
//! signals ready; any other command is processed once and the script signals done, and it
//! signals ready again when ur_rtde has cleared the register. A synchronous moveJ or stop
//! holds the loop (the done signal waits) until the arm has arrived or stopped.
//!
//! # What is modelled, on the emulator's [`SimRobot`]
//! | ur_rtde call | cmd | emulated as |
//! |---|---|---|
//! | `servoJ(q, v, a, t, lookahead, gain)` | 11 | [`JointCommand::Servo`] with the target, lookahead and gain (v, a and t unused, as by UR's servoj) |
//! | `speedJ(qd, a, t)` | 9 | [`JointCommand::Speed`] `{ qd, a }` until the next command |
//! | `moveJ(q, v, a, async)` | 1 | a synchronised trapezoid in joint space, the leading joint at `v` [rad/s] and `a` [rad/s²] (capped at the model's limits), [`MoveJProfile`]; time-scaled by the speed slider and speed scaling |
//! | `stopJ(a, async)` | 34 | [`JointCommand::Stop`] `{ decel: a }` |
//! | `servoStop(a)`, `speedStop(a)` | 16, 15 | the same stop, synchronous; servoStop's `stopl(a)` is read as a joint deceleration [rad/s²] (the model has no tool-space braking) |
//! | `setWatchdog(f)`, `kickWatchdog()` | 35, — | the RTDE watchdog on `input_int_register_<off>`: without a package writing it for `1/f` s the program stops |
//! | `triggerProtectiveStop()` | 31 | [`SimRobot::inject_protective_stop`] |
//! | `stopScript()` | 255 | the program stops |
//! | `setPayload(m, cog)` | 17 | accepted and logged; the motion model has no payload |
//! | `getStepTime()` | 26 | 0.002 s |
//! | `getJointTorques()` | 38 | zeros: UR returns the torque beyond what the arm needs to move itself, and the model has no external load |
//! | `getForwardKinematics()` | 43, 44 | UR5e forward kinematics of the actual (or given) joints, with the given TCP offset |
//! | `getTCPOffset()` | 40 | zeros (the emulator has no TCP offset; `setTCP` is refused) |
//! | `isSteady()` | 47 | every actual joint speed is 0 |
//! | `isJointsWithinSafetyLimits(q)` | 37 | `q` finite and within the model's joint limits |
//!
//! Every other command (Cartesian moves and servoing, force mode, jogging, teach and freedrive
//! mode, contact detection, inverse kinematics, paths, the dynamics getters, …) is **refused
//! the way a controller refuses a script error**: the program stops with a log line naming
//! the command, `runtime_state` leaves PLAYING, and ur_rtde reports the command as failed
//! (`RTDE control script is not running!`, the call returns false) instead of waiting for it.
//! A real-time command is not waited for by ur_rtde, so the failure shows on the next call.
//! A moveJ target outside the joint limits, or non-finite arguments, stop the program too, as
//! URScript's runtime errors do.
//!
//! Simplifications, stated: a pause (protective stop, dashboard `pause`) ends the motion in
//! progress, and after `play` the script waits for the next command; the watchdog is
//! suspended while the program is not PLAYING; when a command starts a motion while another
//! script thread still moves the arm (an async moveJ, servoing), the newest wins and the older
//! one ends (its async operation reported finished).

use crate::kinematics::{pose_from_vector, pose_to_vector, tcp_pose, ur5e_tcp_pose};
use crate::sim::{CYCLE_S, SimRobot};
use crate::types::{JointCommand, Joints, Robot, runtime_state};

use super::{InputRegisters, REGISTERS};

/// `output_int_register_<off>` value: ready for a command (ur_rtde's
/// `UR_CONTROLLER_RDY_FOR_CMD`).
pub const READY_FOR_CMD: i32 = 1;
/// `output_int_register_<off>` value: done with the command (`UR_CONTROLLER_DONE_WITH_CMD`).
pub const DONE_WITH_CMD: i32 = 2;

/// The text ur_rtde's script writes when it starts: how the emulator recognises it.
const LOADED_MARK: &str = "RTDE Control Script Loaded";

/// Where ur_rtde's script keeps its registers, read from the script as uploaded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UrRtdeScript {
    /// Register offset: 0 (registers 0–23) or 24 (ur_rtde's `FLAG_UPPER_RANGE_REGISTERS`).
    pub reg_offset: usize,
}

impl UrRtdeScript {
    /// Recognises ur_rtde's control script: `def rtde_control():`, its start message and its
    /// command dispatcher, with the register offsets ur_rtde injects after `# float register
    /// offset` and `# int register offset` (equal, 0 or 24). `None` for any other script.
    pub fn recognise(script: &str) -> Option<Self> {
        if !(script.contains("def rtde_control():")
            && script.contains(LOADED_MARK)
            && script.contains("def rtde_cmd():"))
        {
            return None;
        }
        let float = injected_offset(script, "# float register offset\n")?;
        let int = injected_offset(script, "# int register offset\n")?;
        (float == int && (float == 0 || float == 24)).then_some(Self { reg_offset: int })
    }
}

/// The integer ur_rtde injects right after `mark`.
fn injected_offset(script: &str, mark: &str) -> Option<usize> {
    let at = script.find(mark)? + mark.len();
    let digits: String = script
        .get(at..)?
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.parse().ok()
}

/// The controller's output registers, as running programs write them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputRegisters {
    /// `output_int_register_N`.
    pub int: [i32; REGISTERS],
    /// `output_double_register_N`.
    pub double: [f64; REGISTERS],
}

impl Default for OutputRegisters {
    fn default() -> Self {
        Self {
            int: [0; REGISTERS],
            double: [0.0; REGISTERS],
        }
    }
}

impl OutputRegisters {
    fn set_int(&mut self, i: usize, v: i32) {
        if let Some(r) = self.int.get_mut(i) {
            *r = v;
        }
    }

    fn set_doubles(&mut self, from: usize, v: &[f64; 6]) {
        for (k, x) in v.iter().enumerate() {
            if let Some(r) = self.double.get_mut(from + k) {
                *r = *x;
            }
        }
    }
}

/// The script's async progress register (`write_async_progress_register`): bits 24–30 the
/// operation id, 16–23 a write counter, bit 15 "running", bits 0–14 the progress.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AsyncProgress {
    writes: i32,
    op_id: i32,
}

impl AsyncProgress {
    /// One write as the script does it: `value` 0 starts a new operation (its id counts up),
    /// a value ≥ 0 is the progress of a running one, a negative value ends it. Returns the
    /// register value. Both counters wrap from 127 to 0, as in the script.
    pub fn write(&mut self, value: i32) -> i32 {
        self.writes += 1;
        if self.writes > 127 {
            self.writes = 0;
        }
        if value == 0 {
            self.op_id += 1;
            if self.op_id > 127 {
                self.op_id = 0;
            }
        }
        let mut reg = self.writes * 65_536 + self.op_id * 16_777_216;
        if value >= 0 {
            reg += value.min(32_767) + 32_768;
        }
        reg
    }
}

/// moveJ's motion: all joints move on one trapezoidal time scaling `s(t)` ∈ [0, 1],
/// `q(t) = q0 + s(t)·(q1 − q0)`, so they start and arrive together; the leading joint (the
/// largest |q1 − q0| = D) runs at speed `v` [rad/s] with acceleration `a` [rad/s²], or, when
/// D < v²/a, on a triangle that peaks at √(a·D) below `v`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoveJProfile {
    q0: Joints,
    q1: Joints,
    /// Acceleration time [s].
    t_acc: f64,
    /// Total duration [s].
    t_total: f64,
    /// Acceleration of `s` [1/s²].
    a_s: f64,
    /// Peak speed of `s` [1/s].
    v_s: f64,
}

impl MoveJProfile {
    /// The profile from `q0` to `q1` [rad] with the leading joint's speed `v` [rad/s] and
    /// acceleration `a` [rad/s²], both > 0 and finite (the caller checks).
    pub fn new(q0: Joints, q1: Joints, v: f64, a: f64) -> Self {
        let d = q0
            .iter()
            .zip(&q1)
            .map(|(a, b)| (b - a).abs())
            .fold(0.0, f64::max);
        if d == 0.0 {
            return Self {
                q0,
                q1,
                t_acc: 0.0,
                t_total: 0.0,
                a_s: 0.0,
                v_s: 0.0,
            };
        }
        let (a_s, v_s) = (a / d, v / d);
        let (t_acc, v_s) = if d >= v * v / a {
            (v / a, v_s)
        } else {
            let t = (d / a).sqrt();
            (t, a_s * t)
        };
        let cruise = (1.0 - a_s * t_acc * t_acc) / v_s;
        Self {
            q0,
            q1,
            t_acc,
            t_total: 2.0 * t_acc + cruise.max(0.0),
            a_s,
            v_s,
        }
    }

    /// The motion's duration [s].
    pub fn duration_s(&self) -> f64 {
        self.t_total
    }

    /// The time scaling `s` [-] at `t` [s] (0 before, 1 from the end on).
    pub fn s_at(&self, t: f64) -> f64 {
        if self.t_total == 0.0 || t >= self.t_total {
            return 1.0;
        }
        if t <= 0.0 {
            return 0.0;
        }
        if t < self.t_acc {
            0.5 * self.a_s * t * t
        } else if t <= self.t_total - self.t_acc {
            0.5 * self.a_s * self.t_acc * self.t_acc + self.v_s * (t - self.t_acc)
        } else {
            let r = self.t_total - t;
            1.0 - 0.5 * self.a_s * r * r
        }
    }

    /// The joint positions [rad] at `t` [s] (exactly `q1` from the end on).
    pub fn at(&self, t: f64) -> Joints {
        if t >= self.t_total {
            return self.q1;
        }
        let s = self.s_at(t);
        std::array::from_fn(|i| {
            let (a, b) = (self.q0.get(i).copied(), self.q1.get(i).copied());
            let (a, b) = (a.unwrap_or(0.0), b.unwrap_or(0.0));
            a + s * (b - a)
        })
    }
}

/// What the emulated script makes the arm do.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    Idle,
    Servo(Joints),
    Speed,
    MoveJ {
        profile: MoveJProfile,
        /// Profile time reached [s] (advanced by the speed scale each cycle).
        tau_s: f64,
        asynchronous: bool,
    },
    Stop {
        asynchronous: bool,
    },
}

/// How a cycle of the script ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Verdict {
    /// The script runs on.
    Running,
    /// The script stopped (the reason, for the log): the program ends.
    Stopped(String),
    /// The RTDE watchdog stopped the program (the reason, for the log).
    WatchdogExpired(String),
}

/// ur_rtde's command names (`RTDE::RobotCommand::Type`), for the log.
const COMMAND_NAMES: [(i32, &str); 66] = [
    (1, "moveJ"),
    (2, "moveJ_IK"),
    (3, "moveL"),
    (4, "moveL_FK"),
    (6, "forceMode"),
    (7, "forceModeStop"),
    (8, "zeroFtSensor"),
    (9, "speedJ"),
    (10, "speedL"),
    (11, "servoJ"),
    (12, "servoC"),
    (13, "setStandardDigitalOut"),
    (14, "setToolDigitalOut"),
    (15, "speedStop"),
    (16, "servoStop"),
    (17, "setPayload"),
    (18, "teachMode"),
    (19, "endTeachMode"),
    (20, "forceModeSetDamping"),
    (21, "forceModeSetGainScaling"),
    (22, "setSpeedSlider"),
    (23, "setAnalogOutput"),
    (24, "servoL"),
    (25, "toolContact"),
    (26, "getStepTime"),
    (27, "getActualJointPositionsHistory"),
    (28, "getTargetWaypoint"),
    (29, "setTcp"),
    (30, "getInverseKinematics"),
    (31, "triggerProtectiveStop"),
    (33, "stopL"),
    (34, "stopJ"),
    (35, "setWatchdog"),
    (36, "isPoseWithinSafetyLimits"),
    (37, "isJointsWithinSafetyLimits"),
    (38, "getJointTorques"),
    (39, "poseTrans"),
    (40, "getTCPOffset"),
    (41, "jogStart"),
    (42, "jogStop"),
    (43, "getForwardKinematics"),
    (44, "getForwardKinematics(q, tcp)"),
    (45, "movePath"),
    (46, "getInverseKinematics"),
    (47, "isSteady"),
    (48, "setConfigurableDigitalOut"),
    (49, "setInputIntRegister"),
    (50, "setInputDoubleRegister"),
    (51, "moveUntilContact"),
    (52, "freedriveMode"),
    (53, "endFreedriveMode"),
    (54, "getFreedriveStatus"),
    (55, "setExternalForceTorque"),
    (56, "ftRtdeInputEnable"),
    (57, "enableExternalFtSensor"),
    (58, "getActualToolFlangePose"),
    (59, "setGravity"),
    (60, "getInverseKinematicsHasSolution"),
    (61, "getInverseKinematicsHasSolution(args)"),
    (62, "startContactDetection"),
    (63, "stopContactDetection"),
    (64, "readContactDetection"),
    (65, "setTargetPayload"),
    (66, "directTorque"),
    (67, "getMassMatrix"),
    (68, "getCoriolisAndCentrifugalTorques"),
];

/// ur_rtde's name of command `cmd`.
pub fn command_name(cmd: i32) -> &'static str {
    match cmd {
        69 => "getTargetJointAccelerations",
        70 => "getJacobian",
        71 => "getJacobianTimeDerivative",
        255 => "stopScript",
        _ => COMMAND_NAMES
            .iter()
            .find(|(c, _)| *c == cmd)
            .map_or("unknown", |(_, n)| n),
    }
}

/// The commands the script processes as "real-time" (every cycle, then ready; ur_rtde does
/// not wait for them), from its main loop.
pub fn is_realtime(cmd: i32) -> bool {
    matches!(
        cmd,
        24 | 11 | 9 | 10 | 6 | 25 | 26 | 27 | 38 | 58 | 66 | 67 | 68 | 69 | 70 | 71
    )
}

/// What processing a command did.
enum Outcome {
    /// Done in this cycle.
    Done,
    /// The main loop waits until the motion ends, then signals done.
    Blocks,
}

/// ur_rtde's control script, running on the emulator's [`SimRobot`] (see the module docs).
#[derive(Debug, Clone)]
pub struct UrRtdeControl {
    off: usize,
    /// The script's `executing_cmd`: a non-RT command was processed and not yet cleared.
    executing: bool,
    /// A synchronous command holds the main loop until the motion ends.
    blocking: bool,
    motion: Motion,
    progress: AsyncProgress,
    /// An async operation (moveJ or stopJ) runs.
    async_running: bool,
    /// The RTDE watchdog: minimum frequency [Hz] and the cycle it counts from.
    watchdog: Option<(f64, u64)>,
    /// Commands processed (each non-RT command once, an RT command when its arguments change).
    commands: u64,
    /// The last RT command and its arguments, to count changes.
    last_rt: Option<(i32, [u64; 11])>,
    /// The payload last set [kg] (recorded, not modelled).
    payload_kg: Option<f64>,
}

impl UrRtdeControl {
    /// The script as it starts: `reset_async_progress()` then `signal_ready()` (both written
    /// into `out`).
    pub fn start(script: UrRtdeScript, out: &mut OutputRegisters) -> Self {
        let mut this = Self {
            off: script.reg_offset,
            executing: false,
            blocking: false,
            motion: Motion::Idle,
            progress: AsyncProgress::default(),
            async_running: false,
            watchdog: None,
            commands: 0,
            last_rt: None,
            payload_kg: None,
        };
        let reg = this.progress.write(-1);
        out.set_int(this.off + 2, reg);
        out.set_int(this.off, READY_FOR_CMD);
        this
    }

    /// The register offset (0 or 24).
    pub fn reg_offset(&self) -> usize {
        self.off
    }

    /// Commands processed so far.
    pub fn commands(&self) -> u64 {
        self.commands
    }

    /// The payload set through `setPayload` [kg], if any (the motion model ignores it).
    pub fn payload_kg(&self) -> Option<f64> {
        self.payload_kg
    }

    fn int(&self, inputs: &InputRegisters, i: usize) -> i32 {
        inputs.int.get(self.off + i).copied().unwrap_or(0)
    }

    fn double(&self, inputs: &InputRegisters, i: usize) -> f64 {
        inputs.double.get(self.off + i).copied().unwrap_or(0.0)
    }

    fn joints(&self, inputs: &InputRegisters, from: usize) -> Joints {
        std::array::from_fn(|k| self.double(inputs, from + k))
    }

    /// One iteration of the script's main loop (one controller cycle), before the arm's step.
    /// Sends the arm its command for this cycle and writes the output registers.
    pub fn cycle(
        &mut self,
        inputs: &InputRegisters,
        robot: &mut SimRobot,
        out: &mut OutputRegisters,
    ) -> Verdict {
        match robot.runtime_state() {
            runtime_state::PLAYING => {}
            runtime_state::STOPPED | runtime_state::STOPPING => {
                return Verdict::Stopped("the program was stopped".into());
            }
            _ => {
                // Paused: the script does not run; the motion in progress ends (module docs).
                self.end_motion(out);
                self.blocking = false;
                if let Some((_, from)) = &mut self.watchdog {
                    *from = inputs.cycle;
                }
                return Verdict::Running;
            }
        }
        if let Some((hz, from)) = self.watchdog {
            let written = inputs.int_written.get(self.off).copied().unwrap_or(0);
            let last = written.max(from);
            let limit = (1.0 / (hz * CYCLE_S)).ceil() as u64;
            if inputs.cycle.saturating_sub(last) > limit {
                return Verdict::WatchdogExpired(format!(
                    "rtde watchdog expired: no package wrote input_int_register_{} for {} cycles \
                     (setWatchdog({hz} Hz))",
                    self.off,
                    inputs.cycle.saturating_sub(last)
                ));
            }
        }
        let verdict = if self.blocking {
            Verdict::Running
        } else {
            self.dispatch(inputs, robot, out)
        };
        if verdict != Verdict::Running {
            return verdict;
        }
        let finished = self.advance(robot, out);
        if finished && self.blocking {
            self.blocking = false;
            out.set_int(self.off, DONE_WITH_CMD);
        }
        Verdict::Running
    }

    /// The main loop's command handling for one iteration.
    fn dispatch(
        &mut self,
        inputs: &InputRegisters,
        robot: &mut SimRobot,
        out: &mut OutputRegisters,
    ) -> Verdict {
        let cmd = self.int(inputs, 0);
        if is_realtime(cmd) {
            let args: [u64; 11] = std::array::from_fn(|k| self.double(inputs, k).to_bits());
            if self.last_rt != Some((cmd, args)) {
                self.last_rt = Some((cmd, args));
                self.commands += 1;
            }
            if let Err(reason) = self.realtime(cmd, inputs, robot, out) {
                return Verdict::Stopped(reason);
            }
            out.set_int(self.off, READY_FOR_CMD);
            return Verdict::Running;
        }
        self.last_rt = None;
        if cmd == 0 {
            self.executing = false;
            out.set_int(self.off, READY_FOR_CMD);
            return Verdict::Running;
        }
        if self.executing {
            return Verdict::Running;
        }
        self.executing = true;
        self.commands += 1;
        match self.command(cmd, inputs, robot, out) {
            Err(reason) => Verdict::Stopped(reason),
            Ok(Outcome::Done) => {
                out.set_int(self.off, DONE_WITH_CMD);
                Verdict::Running
            }
            Ok(Outcome::Blocks) => {
                self.blocking = true;
                Verdict::Running
            }
        }
    }

    /// A real-time command (processed every cycle it stands in the register).
    fn realtime(
        &mut self,
        cmd: i32,
        inputs: &InputRegisters,
        robot: &mut SimRobot,
        out: &mut OutputRegisters,
    ) -> Result<(), String> {
        match cmd {
            11 => {
                let q = self.joints(inputs, 0);
                let (lookahead_s, gain) = (self.double(inputs, 9), self.double(inputs, 10));
                if self.motion == Motion::Servo(q) {
                    return Ok(());
                }
                self.supersede(out);
                send(
                    robot,
                    &JointCommand::Servo {
                        q,
                        lookahead_s,
                        gain,
                    },
                    "servoJ",
                )?;
                self.motion = Motion::Servo(q);
                Ok(())
            }
            9 => {
                let qd = self.joints(inputs, 0);
                let acc = self.double(inputs, 6);
                if !(acc.is_finite() && acc > 0.0) {
                    return Err(format!("speedJ: acceleration {acc} rad/s² is not > 0"));
                }
                if !matches!(self.motion, Motion::Speed) {
                    self.supersede(out);
                }
                send(robot, &JointCommand::Speed { qd, acc }, "speedJ")?;
                self.motion = Motion::Speed;
                Ok(())
            }
            26 => {
                if let Some(r) = out.double.get_mut(self.off) {
                    *r = CYCLE_S;
                }
                Ok(())
            }
            38 => {
                out.set_doubles(self.off, &[0.0; 6]);
                Ok(())
            }
            _ => Err(not_modelled(cmd)),
        }
    }

    /// A command the script processes once (it signals done afterwards).
    fn command(
        &mut self,
        cmd: i32,
        inputs: &InputRegisters,
        robot: &mut SimRobot,
        out: &mut OutputRegisters,
    ) -> Result<Outcome, String> {
        let state = *robot.state();
        match cmd {
            1 => {
                let q = self.joints(inputs, 0);
                let (v, a) = (self.double(inputs, 6), self.double(inputs, 7));
                let asynchronous = self.int(inputs, 1) == 1;
                let limits = robot.config();
                if !(v.is_finite() && v > 0.0 && a.is_finite() && a > 0.0) {
                    return Err(format!(
                        "moveJ: speed {v} rad/s and acceleration {a} rad/s² must be > 0"
                    ));
                }
                let within = q.iter().enumerate().all(|(i, x)| {
                    x.is_finite()
                        && limits.min_q_rad.get(i).is_some_and(|lo| x >= lo)
                        && limits.max_q_rad.get(i).is_some_and(|hi| x <= hi)
                });
                if !within {
                    return Err(format!(
                        "moveJ: target {q:?} rad is outside the joint limits"
                    ));
                }
                let v = v.min(min_of(&limits.max_speed_rad_s));
                let a = a.min(min_of(&limits.max_acc_rad_s2));
                self.supersede(out);
                self.motion = Motion::MoveJ {
                    profile: MoveJProfile::new(state.actual_q, q, v, a),
                    tau_s: 0.0,
                    asynchronous,
                };
                if asynchronous {
                    self.start_async(out);
                    Ok(Outcome::Done)
                } else {
                    Ok(Outcome::Blocks)
                }
            }
            15 | 16 | 34 => {
                let decel = self.double(inputs, 0);
                if !(decel.is_finite() && decel > 0.0) {
                    return Err(format!(
                        "{}: deceleration {decel} rad/s² is not > 0",
                        command_name(cmd)
                    ));
                }
                let asynchronous = cmd == 34 && self.int(inputs, 1) == 1;
                self.supersede(out);
                send(robot, &JointCommand::Stop { decel }, command_name(cmd))?;
                self.motion = Motion::Stop { asynchronous };
                if asynchronous {
                    self.start_async(out);
                    Ok(Outcome::Done)
                } else {
                    Ok(Outcome::Blocks)
                }
            }
            17 => {
                let mass = self.double(inputs, 0);
                tracing::info!(
                    "emulator: ur_rtde setPayload({mass} kg) recorded; the motion model has no payload"
                );
                self.payload_kg = Some(mass);
                Ok(Outcome::Done)
            }
            31 => {
                tracing::info!("emulator: ur_rtde triggerProtectiveStop");
                robot.inject_protective_stop();
                Ok(Outcome::Done)
            }
            35 => {
                let hz = self.double(inputs, 0);
                self.watchdog = (hz.is_finite() && hz > 0.0).then_some((hz, inputs.cycle));
                tracing::info!("emulator: ur_rtde setWatchdog({hz} Hz)");
                Ok(Outcome::Done)
            }
            37 => {
                let q = self.joints(inputs, 0);
                let limits = robot.config();
                let within = q.iter().enumerate().all(|(i, x)| {
                    x.is_finite()
                        && limits.min_q_rad.get(i).is_some_and(|lo| x >= lo)
                        && limits.max_q_rad.get(i).is_some_and(|hi| x <= hi)
                });
                out.set_int(self.off + 1, i32::from(within));
                Ok(Outcome::Done)
            }
            40 => {
                out.set_doubles(self.off, &[0.0; 6]);
                Ok(Outcome::Done)
            }
            43 => {
                out.set_doubles(self.off, &ur5e_tcp_pose(&state.actual_q));
                Ok(Outcome::Done)
            }
            44 => {
                let q = self.joints(inputs, 0);
                let tool = pose_from_vector(&self.joints(inputs, 6));
                out.set_doubles(self.off, &pose_to_vector(&tcp_pose(&q, &tool)));
                Ok(Outcome::Done)
            }
            47 => {
                let steady = state.actual_qd.iter().all(|v| *v == 0.0);
                out.set_int(self.off + 1, i32::from(steady));
                Ok(Outcome::Done)
            }
            255 => Err("ur_rtde stopScript".into()),
            _ => Err(not_modelled(cmd)),
        }
    }

    /// A new motion command replaces the motion in progress; an async operation that it ends
    /// is reported finished (as the script's `stop_async_move` does).
    fn supersede(&mut self, out: &mut OutputRegisters) {
        if self.async_running {
            self.finish_async(out);
        }
        self.motion = Motion::Idle;
    }

    fn start_async(&mut self, out: &mut OutputRegisters) {
        let reg = self.progress.write(0);
        out.set_int(self.off + 2, reg);
        self.async_running = true;
    }

    fn finish_async(&mut self, out: &mut OutputRegisters) {
        let reg = self.progress.write(-1);
        out.set_int(self.off + 2, reg);
        self.async_running = false;
    }

    fn end_motion(&mut self, out: &mut OutputRegisters) {
        if self.async_running {
            self.finish_async(out);
        }
        self.motion = Motion::Idle;
    }

    /// Advances a moveJ or a stop by one cycle; whether the motion in progress has ended
    /// (the arm arrived or stands still). An async operation that ends is reported finished.
    fn advance(&mut self, robot: &mut SimRobot, out: &mut OutputRegisters) -> bool {
        let state = *robot.state();
        let max_acc = min_of(&robot.config().max_acc_rad_s2);
        let ended = match &mut self.motion {
            Motion::Idle | Motion::Servo(_) | Motion::Speed => return true,
            Motion::Stop { .. } => state.actual_qd.iter().all(|v| *v == 0.0),
            Motion::MoveJ { profile, tau_s, .. } if *tau_s >= profile.duration_s() => {
                // Arrived on the last cycle: hold still.
                let _ = robot.send(&JointCommand::Speed {
                    qd: [0.0; 6],
                    acc: max_acc,
                });
                true
            }
            Motion::MoveJ { profile, tau_s, .. } => {
                // Time-scaled like a controller's trajectory: the profile advances by the
                // speed scale, and the velocity asked for is divided by it because the arm
                // multiplies commanded velocities by it (crate::sim). The velocity closes on
                // the profile's next position from the actual one, so rounding never
                // accumulates.
                let scale = robot.speed_scale();
                let qd = if scale > 0.0 {
                    *tau_s = (*tau_s + CYCLE_S * scale).min(profile.duration_s());
                    let next = profile.at(*tau_s);
                    std::array::from_fn(|i| {
                        let now = state.actual_q.get(i).copied().unwrap_or(0.0);
                        (next.get(i).copied().unwrap_or(now) - now) / (CYCLE_S * scale)
                    })
                } else {
                    [0.0; 6]
                };
                let _ = robot.send(&JointCommand::Speed { qd, acc: max_acc });
                false
            }
        };
        if ended {
            self.motion = Motion::Idle;
            if self.async_running {
                self.finish_async(out);
            }
        }
        ended
    }
}

/// The smallest of six limits.
fn min_of(v: &Joints) -> f64 {
    v.iter().copied().fold(f64::INFINITY, f64::min)
}

/// Sends `cmd` to the model; a refusal (a value the model rejects) is a script error.
fn send(robot: &mut SimRobot, cmd: &JointCommand, what: &str) -> Result<(), String> {
    robot
        .send(cmd)
        .map_err(|e| format!("{what}: the controller refused the command: {e}"))
}

fn not_modelled(cmd: i32) -> String {
    format!(
        "ur_rtde command {cmd} ({}) is not modelled by the emulator; the script stops as on a \
         script error, and ur_rtde reports the call as failed",
        command_name(cmd)
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::{EmulatorBackend, SimBackend};
    use crate::sim::SimConfig;
    use proptest::prelude::*;

    /// The parts of ur_rtde's script the emulator reads, with ur_rtde's injection (offset
    /// `off` written right after each marker, as `ScriptClient::sendScript` does).
    fn script(off: usize) -> String {
        format!(
            "def rtde_control():\n    global reg_offset_float = # float register offset\n{off}    \
             global reg_offset_int = # int register offset\n{off}    def rtde_cmd():\n      \
             return 0\n    end\n    textmsg(\"RTDE Control Script Loaded (14.02.2024-12:23)\")\nend\n"
        )
    }

    #[test]
    fn recognises_ur_rtde_script_and_its_offsets() {
        assert_eq!(
            UrRtdeScript::recognise(&script(0)),
            Some(UrRtdeScript { reg_offset: 0 })
        );
        assert_eq!(
            UrRtdeScript::recognise(&script(24)),
            Some(UrRtdeScript { reg_offset: 24 })
        );
        // An offset ur_rtde never injects, and a script that is not ur_rtde's.
        assert_eq!(UrRtdeScript::recognise(&script(12)), None);
        let ours = crate::script::RegisterMap::default().program();
        assert_eq!(UrRtdeScript::recognise(&ours), None);
    }

    #[test]
    fn async_progress_worked_example() {
        // By hand from the script's write_async_progress_register: the start writes −1
        // (count 1, id 0): 1·65536 = 65536. An async moveJ starts (0: count 2, id 1):
        // 2·65536 + 1·16777216 + 0 + 32768 = 16941056; it ends (−1: count 3, id 1):
        // 3·65536 + 16777216 = 16973824.
        let mut p = AsyncProgress::default();
        assert_eq!(p.write(-1), 65_536);
        assert_eq!(p.write(0), 16_941_056);
        assert_eq!(p.write(-1), 16_973_824);
        // ur_rtde: running = bit 15; when not running it returns id % 2 − 2 = −1.
        assert_eq!(16_941_056 & 0x8000, 0x8000);
        assert_eq!(16_973_824 & 0x8000, 0);
        assert_eq!((16_973_824 >> 24) & 0x7f, 1);
    }

    #[test]
    fn async_progress_counters_wrap_at_127() {
        let mut p = AsyncProgress::default();
        for _ in 0..127 {
            p.write(0);
        }
        // After 127 starts, count 127 and id 127; the 128th wraps both to 0 (by hand: the
        // register is then 0·65536 + 0·16777216 + 0 + 32768).
        assert_eq!(p.write(0), 32_768);
    }

    #[test]
    fn move_j_profile_worked_examples() {
        // Trapezoid, by hand: Δq = (1, −0.5), v = 1 rad/s, a = 2 rad/s². Leading D = 1 ≥
        // v²/a = 0.5, so t_acc = v/a = 0.5 s and T = D/v + v/a = 1.5 s. s(0.25) = ½·2·0.25²
        // = 0.0625; s(1.0) = ½·2·0.5² + 1·(1.0 − 0.5) = 0.75; s(1.25) = 1 − ½·2·0.25² =
        // 0.9375.
        let q0 = [0.0; 6];
        let q1 = [1.0, -0.5, 0.0, 0.0, 0.0, 0.0];
        let p = MoveJProfile::new(q0, q1, 1.0, 2.0);
        assert!((p.duration_s() - 1.5).abs() < 1e-15);
        assert!((p.s_at(0.25) - 0.0625).abs() < 1e-15);
        assert!((p.s_at(1.0) - 0.75).abs() < 1e-15);
        assert!((p.s_at(1.25) - 0.9375).abs() < 1e-15);
        let q = p.at(0.25);
        assert!((q[0] - 0.0625).abs() < 1e-15 && (q[1] + 0.03125).abs() < 1e-15);
        assert_eq!(p.at(1.5), q1);
        // Triangle, by hand: D = 0.25 < v²/a = 1 (v = a = 1): t_acc = √(D/a) = 0.5 s, T = 1 s,
        // peak joint speed a·t_acc = 0.5 rad/s (below v); s(0.5) = 0.5.
        let p = MoveJProfile::new(q0, [0.25, 0.0, 0.0, 0.0, 0.0, 0.0], 1.0, 1.0);
        assert!((p.duration_s() - 1.0).abs() < 1e-15);
        assert!((p.s_at(0.5) - 0.5).abs() < 1e-15);
        assert!((p.at(0.5)[0] - 0.125).abs() < 1e-15);
        // No motion: done at once.
        assert_eq!(MoveJProfile::new(q1, q1, 1.0, 1.0).duration_s(), 0.0);
    }

    proptest! {
        #[test]
        fn move_j_profile_respects_speed_and_acceleration(
            d in prop::array::uniform6(-3.0f64..3.0),
            v in 0.05f64..std::f64::consts::PI,
            a in 0.05f64..40.0,
        ) {
            let q0 = [0.1; 6];
            let q1: Joints = std::array::from_fn(|i| q0[i] + d[i]);
            let p = MoveJProfile::new(q0, q1, v, a);
            let dt = 1e-3;
            let n = (p.duration_s() / dt).ceil() as usize + 2;
            let qs: Vec<Joints> = (0..=n).map(|k| p.at(k as f64 * dt)).collect();
            prop_assert_eq!(qs[n], q1);
            for w in qs.windows(3) {
                for j in 0..6 {
                    let v1 = (w[1][j] - w[0][j]) / dt;
                    let v2 = (w[2][j] - w[1][j]) / dt;
                    prop_assert!(v1.abs() <= v * (1.0 + 1e-9) + 1e-9, "speed {v1} over {v}");
                    prop_assert!((v2 - v1).abs() / dt <= a * (1.0 + 1e-6) + 1e-6,
                        "acceleration {} over {a}", (v2 - v1).abs() / dt);
                    // Every joint moves monotonically towards its target.
                    prop_assert!(v1 * d[j] >= -1e-12);
                }
            }
        }

        #[test]
        fn split_program_finds_each_program_once(n in 1usize..4, tail in "[a-z]{0,8}") {
            let one = "def p():\n  textmsg(\"x\")\nend\np()\n";
            let text = format!("{}{tail}", one.repeat(n));
            let mut rest = text.as_bytes();
            let mut found = 0;
            while let Some(end) = crate::emulator::split_program(rest) {
                prop_assert_eq!(&rest[..end], one.as_bytes());
                rest = &rest[end..];
                found += 1;
            }
            prop_assert_eq!(found, n);
            prop_assert_eq!(rest, tail.as_bytes());
        }
    }

    #[test]
    fn split_program_examples() {
        use crate::emulator::split_program;
        let ur = script(0);
        assert_eq!(split_program(ur.as_bytes()), Some(ur.len()));
        // Incomplete: no top-level end yet; an indented end does not close the program.
        assert_eq!(split_program(b"def p():\n  while True:\n  end\n"), None);
        // Our program's trailing call belongs to it; the next def starts a new one.
        let two = b"def a():\nend\na()\ndef b():\nend\n";
        assert_eq!(split_program(two), Some(17));
    }

    /// A SimBackend fed by hand-written input registers, as an RTDE client writes them.
    struct Bench {
        b: SimBackend,
        inputs: InputRegisters,
    }

    impl Bench {
        fn new(off: usize) -> Self {
            let robot = SimRobot::new(SimConfig::ur5e()).unwrap();
            let mut b = SimBackend::new(robot);
            assert!(b.load_program(&script(off)));
            Self {
                b,
                inputs: InputRegisters::default(),
            }
        }
        fn int(&mut self, i: usize, v: i32) {
            self.inputs.int[i] = v;
            self.inputs.int_written[i] = self.inputs.cycle.max(1);
        }
        fn doubles(&mut self, from: usize, v: &[f64]) {
            self.inputs.double[from..from + v.len()].copy_from_slice(v);
        }
        fn step(&mut self) {
            self.inputs.cycle += 1;
            self.b.step(&self.inputs);
        }
        fn out_int(&self, i: usize) -> i32 {
            self.b.output_registers().int[i]
        }
        fn q(&mut self) -> Joints {
            self.b.robot_mut().state().actual_q
        }
        /// Steps until the script signals done; the cycles it took.
        fn until_done(&mut self, off: usize) -> u64 {
            for n in 1..=100_000 {
                self.step();
                if self.out_int(off) == DONE_WITH_CMD {
                    return n;
                }
            }
            panic!("the command never finished");
        }
    }

    #[test]
    fn move_j_synchronous_holds_the_loop_until_arrival_then_ready_after_clear() {
        for off in [0, 24] {
            let mut t = Bench::new(off);
            assert_eq!(t.out_int(off), READY_FOR_CMD);
            assert_eq!(t.out_int(off + 2), 65_536);
            let mut target = t.q();
            target[0] += 0.3;
            t.doubles(off, &target);
            t.doubles(off + 6, &[1.0, 1.0]);
            t.int(off + 1, 0);
            t.int(off, 1);
            let cycles = t.until_done(off);
            // D = 0.3 < v²/a = 1: a triangle of T = 2·√0.3 = 1.0954 s, 548 cycles of 2 ms
            // (the profile time reaches T on the 548th), and one more to see it arrived.
            assert_eq!(cycles, 549);
            assert_eq!(t.q(), target);
            t.int(off, 0);
            t.step();
            assert_eq!(t.out_int(off), READY_FOR_CMD);
        }
    }

    #[test]
    fn async_move_j_progress_then_stop_j_brakes_it() {
        let mut t = Bench::new(0);
        let start = t.q();
        let mut target = start;
        target[1] += 1.0;
        t.doubles(0, &target);
        t.doubles(6, &[0.5, 1.0]);
        t.int(1, 1);
        t.int(0, 1);
        t.step();
        // Done at once, the operation running.
        assert_eq!(t.out_int(0), DONE_WITH_CMD);
        assert_ne!(t.out_int(2) & 0x8000, 0);
        t.int(0, 0);
        for _ in 0..300 {
            t.step();
        }
        assert_eq!(t.out_int(0), READY_FOR_CMD);
        assert!(t.q()[1] > start[1]);
        // stopJ(2 rad/s², sync): the loop holds until the arm stands; the async op ends.
        t.doubles(0, &[2.0]);
        t.int(1, 0);
        t.int(0, 34);
        t.until_done(0);
        assert_eq!(t.out_int(2) & 0x8000, 0);
        assert!(t.b.robot_mut().state().actual_qd.iter().all(|v| *v == 0.0));
        assert!(t.q()[1] < target[1]);
    }

    #[test]
    fn servo_j_latches_the_target_and_signals_ready() {
        let mut t = Bench::new(0);
        let mut q = t.q();
        q[2] += 0.01;
        t.doubles(0, &q);
        t.doubles(6, &[0.5, 0.5, 0.002, 0.1, 300.0]);
        t.int(0, 11);
        t.step();
        assert_eq!(t.out_int(0), READY_FOR_CMD);
        assert_eq!(
            t.b.robot_mut().command(),
            Some(&JointCommand::Servo {
                q,
                lookahead_s: 0.1,
                gain: 300.0
            })
        );
    }

    #[test]
    fn unmodelled_command_stops_the_program() {
        let mut t = Bench::new(0);
        t.int(0, 3); // moveL
        t.step();
        assert!(!t.b.program_running());
        assert_ne!(t.b.runtime_state(), runtime_state::PLAYING);
        assert_eq!(t.out_int(0), 0);
    }

    #[test]
    fn watchdog_stops_the_program_after_its_period_of_silence() {
        let mut t = Bench::new(0);
        t.doubles(0, &[50.0]);
        t.int(0, 35);
        t.step();
        assert_eq!(t.out_int(0), DONE_WITH_CMD);
        // 50 Hz: at most ceil(1/(50·0.002)) = 10 cycles between writes.
        for _ in 0..5 {
            for _ in 0..10 {
                t.step();
            }
            t.int(0, 0);
        }
        assert!(t.b.program_running());
        for _ in 0..10 {
            t.step();
        }
        assert!(t.b.program_running());
        t.step();
        assert!(!t.b.program_running());
        assert_eq!(t.b.watchdog_trips(), 1);
    }

    #[test]
    fn getters_write_their_registers() {
        let mut t = Bench::new(0);
        // getForwardKinematics(): the actual joints' flange pose.
        t.int(0, 43);
        t.step();
        let q = t.q();
        assert_eq!(
            t.b.output_registers().double[..6],
            ur5e_tcp_pose(&q)[..],
            "forward kinematics"
        );
        t.int(0, 0);
        t.step();
        // isJointsWithinSafetyLimits: 7 rad is beyond ±2π.
        t.doubles(0, &[7.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        t.int(0, 37);
        t.step();
        assert_eq!(t.out_int(1), 0);
        t.int(0, 0);
        t.step();
        t.doubles(0, &q);
        t.int(0, 37);
        t.step();
        assert_eq!(t.out_int(1), 1);
        // getStepTime (real time): ready, not done.
        t.int(0, 26);
        t.step();
        assert_eq!(t.b.output_registers().double[0], CYCLE_S);
        assert_eq!(t.out_int(0), READY_FOR_CMD);
    }

    #[test]
    fn a_new_upload_replaces_the_running_script() {
        let mut t = Bench::new(0);
        assert!(t.b.load_program(&script(24)));
        // The old program stops; the new one starts once the arm is STOPPED.
        for _ in 0..3 {
            t.step();
        }
        assert_eq!(
            t.b.ur_rtde_control().map(UrRtdeControl::reg_offset),
            Some(24)
        );
        assert_eq!(t.out_int(24), READY_FOR_CMD);
        assert_eq!(t.b.runtime_state(), runtime_state::PLAYING);
    }
}
