//! Our URScript control program, its RTDE register protocol, and a script sender.
//!
//! The program (`resources/hrc_control.script`) reads RTDE input registers and runs servoj,
//! speedj or stopj; [`RegisterMap`] says which registers and how a [`JointCommand`] maps onto
//! them. It arms `rtde_set_watchdog` on the command register, so the program stops when the
//! client stops writing. [`ScriptSender`] sends the program to the primary/secondary (30001,
//! 30002) or real-time (30003) interface.
//!
//! # servoj feedforward and extrapolation
//! A servo target that arrives late, or that the robot keeps for several cycles (the client
//! missed a cycle; the emulator catches up after a stall in a burst), would be held: the
//! target becomes a staircase and every stair a velocity jump. So each servo command carries a
//! [`ServoFeedforward`]: the joint velocity `qd` [rad/s] and acceleration `qdd` [rad/s²] of the
//! commanded trajectory at the command's time, and the program cycle `valid_tick` the target
//! is meant for. The program counts its loop iterations (one per servoj time t, 2 ms, while it
//! servos) in `tick` and publishes it every iteration in `output_int_register_<int_base>`; the
//! client reads it with each state sample and sends `valid_tick` = the tick of the sample its
//! target was computed from + 1 (or the previous command's + 1 when no newer sample came:
//! [`crate::rtde_robot::servo_slot`]). On every cycle the program servos to
//!
//! ```text
//! target_j = q_j + qd_j·e_j + ½·qdd_j·e_j²,   δ = clamp((tick − valid_tick)·t, −extrapolate_max_s, extrapolate_max_s)
//! ```
//!
//! so a target that reaches the program late, or that it keeps for several cycles, is
//! extrapolated by exactly the time since it was meant to apply, measured on the program's
//! own clock. (Until issue 10 the client sent the target's age as it saw it when sending: the
//! newest sample it had received minus the one it read. Samples the controller had produced
//! but the client not yet received, and the time on the wire, were missed; at `--speedup 4`
//! on a loaded machine that left 2.3 times as many executed-jerk samples over the limit.)
//! `qd_j` and `qdd_j` are clamped to ±[`FEEDFORWARD_MAX_QD_RAD_S`] and
//! ±[`FEEDFORWARD_MAX_QDD_RAD_S2`], and `e_j = δ` except that a joint's target never turns
//! back: when `qd_j·qdd_j < 0`, `e_j = min(δ, −qd_j/qdd_j)` (the target stops where its
//! extrapolated velocity reaches zero), and a joint with `qd_j = 0` holds `q_j`.
//!
//! A target that arrives **before** the tick it is meant for (δ < 0: the client predicted a
//! cycle ahead while a state sample was late, and the sample then came) is evaluated back along
//! its feedforward to the program's tick, by at most `extrapolate_max_s`, with the same rule
//! in reverse (when `qd_j·qdd_j > 0`, `e_j = max(δ, −qd_j/qdd_j)`). Until issue 10's session 7
//! δ was clamped at 0: such a target was applied a cycle early, and each time the client's
//! lead began or ended the target stepped by a cycle (at speedup 1 most of the executed-jerk
//! samples over the limit; `commands_stamped_ahead_are_as_smooth_as_commands_on_time` in
//! `tests/servo_feedforward.rs`: 84 rad/s³ of jerk difference before, 0.15 after). Beyond
//! `extrapolate_max_s` the target holds at δ = `extrapolate_max_s`; when writes stop
//! altogether the watchdog stops the program as before. [`ServoFeedforward::target`] is this
//! formula; the emulator runs it every cycle, the URScript program runs the same arithmetic.
//! [`FeedforwardEstimator`] computes `qd` and `qdd` from the last three servo targets (the
//! derivatives of the parabola through them), as [`crate::RtdeRobot`] does.
//!
//! **Safety argument.** The robot never goes further than `extrapolate_max_s` beyond the last
//! target the client sent (and the supervisor passed) along that target's own velocity and
//! acceleration: per joint `|target − q| ≤ |qd|·δmax + ½·|qdd|·δmax²`. With the clamps at the
//! UR5e limits (π rad/s, π rad/s²) and the default δmax = 3 cycles = 0.006 s that is at most
//! π·0.006 + ½·π·0.006² ≈ 0.0189 rad per joint, the distance the joint covers in 6 ms at its
//! top speed. The bound lives in the program (rendered from [`RegisterMap::extrapolate_max_s`]
//! when it is sent, [`RegisterMap::validate`] keeps it within one watchdog period), not in a
//! register, so no register write can widen it. Only on the emulator is `extrapolate_max_s`
//! scaled with the speedup (its clock is virtual). The supervisor's stopping-configuration
//! checks cover this distance: they check where the joints come to rest if a stop follows the
//! command, `q + v·t_stop/2` with `t_stop = max|v| / a_stop`, which is at least `|v|·δmax`
//! along the command's velocity v whenever the fastest joint moves faster than
//! `2·a_stop·δmax` (0.038 rad/s at a_stop = π rad/s² and δmax = 6 ms). Below that speed the
//! extrapolated target can pass the checked rest point by at most
//! 0.038·0.006 + ½·π·0.006² ≈ 3·10⁻⁴ rad per joint. The extrapolated target never turns back
//! and never passes the point where its own velocity reaches zero. A target evaluated back
//! (δ < 0) lies behind the target sent, along that target's own trajectory, by at most the
//! same distance: towards where the arm comes from, never beyond a checked command.
//!
//! # Register layout
//! With the defaults `int_base = double_base = 24` (offsets from the base in brackets):
//!
//! | register | content |
//! |---|---|
//! | `input_int_register_24` (+0) | command id ([`command_id`]); the watchdog watches it |
//! | `input_int_register_25` (+1) | sequence number (incremented per command) |
//! | `input_int_register_26` (+2) | servoj target's valid tick (program cycle it is meant for) |
//! | `input_double_register_24..=29` (+0..=5) | joint targets, q \[rad\] or qd [rad/s] |
//! | `input_double_register_30` (+6) | servoj time \[s\] |
//! | `input_double_register_31` (+7) | servoj lookahead \[s\], in [0.03, 0.2] |
//! | `input_double_register_32` (+8) | servoj gain [-], in [100, 2000] |
//! | `input_double_register_33` (+9) | speedj acceleration or stopj deceleration [rad/s²] |
//! | `input_double_register_34..=39` (+10..=15) | servoj feedforward velocity qd [rad/s] |
//! | `input_double_register_40..=45` (+16..=21) | servoj feedforward acceleration qdd [rad/s²] |
//! | `output_int_register_24` (+0) | the program's tick, written every loop iteration |
//!
//! The tick is a URScript `int`: 2³¹ iterations are 49.7 days at 2 ms, longer than any program
//! run (the emulator's model takes the difference with wrapping).

use std::f64::consts::PI;
use std::time::Duration;

use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;

use crate::codec::Value;
use crate::types::{JointCommand, Joints};
use crate::{Result, RobotIoError};

/// Secondary interface port (accepts URScript).
pub const SECONDARY_PORT: u16 = 30002;
/// Real-time interface port (accepts URScript).
pub const REALTIME_PORT: u16 = 30003;

/// The control program template, with `{{…}}` placeholders; see [`RegisterMap::program`].
pub const CONTROL_PROGRAM_TEMPLATE: &str = include_str!("../resources/hrc_control.script");

/// Name of the program's main function (the emulator recognises the program by it).
pub const PROGRAM_NAME: &str = "hrc_control";

/// Command ids written to the command register.
pub mod command_id {
    /// No command: the program idles (`sync()`).
    pub const IDLE: i32 = 0;
    /// servoj.
    pub const SERVO: i32 = 1;
    /// speedj.
    pub const SPEED: i32 = 2;
    /// stopj.
    pub const STOP: i32 = 3;
}

/// Integer registers used, counted from [`RegisterMap::int_base`].
pub const INT_REGISTERS: usize = 3;
/// Double registers used, counted from [`RegisterMap::double_base`].
pub const DOUBLE_REGISTERS: usize = 22;
/// Values in one input package of the register protocol.
pub const INPUT_VALUES: usize = INT_REGISTERS + DOUBLE_REGISTERS;

/// Offsets of the double registers from [`RegisterMap::double_base`].
mod offset {
    pub(super) const TIME: usize = 6;
    pub(super) const LOOKAHEAD: usize = 7;
    pub(super) const GAIN: usize = 8;
    pub(super) const ACC: usize = 9;
    pub(super) const QD: usize = 10;
    pub(super) const QDD: usize = 16;
}

/// The controller cycle the program's extrapolation counts in \[s\] (servoj time 2 ms).
pub const CONTROLLER_CYCLE_S: f64 = 0.002;
/// Default [`RegisterMap::extrapolate_max_s`]: three controller cycles \[s\].
pub const DEFAULT_EXTRAPOLATE_MAX_S: f64 = 3.0 * CONTROLLER_CYCLE_S;
/// The program clamps the feedforward velocity to ± this [rad/s] (UR5e joint speed limit).
pub const FEEDFORWARD_MAX_QD_RAD_S: f64 = PI;
/// The program clamps the feedforward acceleration to ± this [rad/s²] (UR5e nominal joint
/// acceleration).
pub const FEEDFORWARD_MAX_QDD_RAD_S2: f64 = PI;
/// Servo targets further apart in time than this many × [`RegisterMap::extrapolate_max_s`]
/// restart the feedforward estimate (see [`RegisterMap::feedforward_max_gap_s`]) [-].
pub const FEEDFORWARD_GAP_FACTOR: f64 = 4.0;

/// The feedforward a servo command carries (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ServoFeedforward {
    /// Joint velocity of the commanded trajectory at the target's time [rad/s].
    pub qd: Joints,
    /// Joint acceleration of the commanded trajectory at the target's time [rad/s²].
    pub qdd: Joints,
    /// The program tick (loop iteration) the target is meant for [cycles]: the tick of the
    /// state sample it was computed from + 1.
    pub valid_tick: i32,
}

impl ServoFeedforward {
    /// No feedforward: the target is held as sent.
    pub const ZERO: ServoFeedforward = ServoFeedforward {
        qd: [0.0; 6],
        qdd: [0.0; 6],
        valid_tick: 0,
    };

    /// The values the program works with: non-finite values become 0, `qd` and `qdd` are
    /// clamped to ±[`FEEDFORWARD_MAX_QD_RAD_S`] and ±[`FEEDFORWARD_MAX_QDD_RAD_S2`].
    pub fn clamped(&self) -> ServoFeedforward {
        let c = |x: f64, m: f64| if x.is_finite() { x.clamp(-m, m) } else { 0.0 };
        ServoFeedforward {
            qd: self.qd.map(|v| c(v, FEEDFORWARD_MAX_QD_RAD_S)),
            qdd: self.qdd.map(|a| c(a, FEEDFORWARD_MAX_QDD_RAD_S2)),
            valid_tick: self.valid_tick,
        }
    }

    /// The time by which the program extrapolates at tick `tick`, with servoj time
    /// `servo_time_s` [s]: `(tick − valid_tick)·t` [s] (wrapping difference; negative when
    /// the target is meant for a later tick, which [`ServoFeedforward::target`] evaluates back
    /// to the tick).
    pub fn since_valid_s(&self, tick: i32, servo_time_s: f64) -> f64 {
        f64::from(tick.wrapping_sub(self.valid_tick)) * servo_time_s
    }

    /// The servo target the program commands `since_s` [s] after the time target `q` [rad]
    /// is valid at ([`ServoFeedforward::since_valid_s`]), extrapolating at most `max_s` [s]
    /// (the module docs give the formula). Allocates nothing.
    pub fn target(&self, q: &Joints, since_s: f64, max_s: f64) -> Joints {
        let ff = self.clamped();
        let max_s = if max_s.is_finite() {
            max_s.max(0.0)
        } else {
            0.0
        };
        let d = since_s;
        let d = if d.is_finite() {
            d.clamp(-max_s, max_s)
        } else {
            0.0
        };
        let mut out = *q;
        for ((o, v), a) in out.iter_mut().zip(ff.qd).zip(ff.qdd) {
            let e = if v == 0.0 {
                0.0
            } else if d >= 0.0 && v * a < 0.0 {
                // Forward: stop where the velocity reaches 0 (never turn back).
                d.min(-v / a)
            } else if d < 0.0 && v * a > 0.0 {
                // Back in time: stop where the velocity, going back, reaches 0.
                d.max(-v / a)
            } else {
                d
            };
            *o += (v + 0.5 * a * e) * e;
        }
        out
    }
}

/// Estimates [`ServoFeedforward::qd`] and [`ServoFeedforward::qdd`] from the last three servo
/// targets and the times they are valid at.
///
/// With targets q0, q1, q2 at t0 < t1 < t2 (h1 = t1 − t0, h2 = t2 − t1), the estimate is the
/// derivative at t2 of the parabola through the three: `qdd = 2·(v2 − v1)/(h1 + h2)` and
/// `qd = v2 + qdd·h2/2`, with the backward differences v1 = (q1 − q0)/h1, v2 = (q2 − q1)/h2.
/// It is exact for trajectories of degree ≤ 2, so the extrapolation of a jerk-limited
/// trajectory errs by O(jerk·h³). With two targets `qd = v2` and `qdd = 0`; with one, both 0.
/// A joint whose `qd` points against its last step v2 (it stopped or turned within the last
/// interval) gets `qd = qdd = 0`: no extrapolation across a kink.
///
/// A target at the same time as the newest replaces it. A target earlier than the newest (a
/// new controller session) or more than `max_gap_s` after it restarts the estimate, as does
/// [`FeedforwardEstimator::reset`] (call it for a non-servo command). Allocates nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedforwardEstimator {
    max_gap_s: f64,
    /// Newest first.
    history: [Option<(f64, Joints)>; 3],
}

impl FeedforwardEstimator {
    /// An empty estimator that restarts after gaps longer than `max_gap_s` \[s\].
    pub fn new(max_gap_s: f64) -> Self {
        Self {
            max_gap_s,
            history: [None; 3],
        }
    }

    /// Forgets every target: the next estimate is 0.
    pub fn reset(&mut self) {
        self.history = [None; 3];
    }

    /// Adds target `q` [rad] valid at controller time `valid_at_s` \[s\] and returns the
    /// estimate at that time (`valid_tick` = 0: the caller sets it). Non-finite inputs reset it
    /// and give 0.
    pub fn push(&mut self, valid_at_s: f64, q: &Joints) -> ServoFeedforward {
        if !valid_at_s.is_finite() || !q.iter().all(|v| v.is_finite()) {
            self.reset();
            return ServoFeedforward::ZERO;
        }
        let [newest, prev, _] = self.history;
        match newest {
            Some((t, _)) if valid_at_s == t => self.history[0] = Some((valid_at_s, *q)),
            Some((t, _)) if valid_at_s > t && valid_at_s - t <= self.max_gap_s => {
                self.history = [Some((valid_at_s, *q)), newest, prev];
            }
            _ => self.history = [Some((valid_at_s, *q)), None, None],
        }
        self.estimate()
    }

    fn estimate(&self) -> ServoFeedforward {
        let mut ff = ServoFeedforward::ZERO;
        let [Some((t2, q2)), Some((t1, q1)), oldest] = self.history else {
            return ff;
        };
        let h2 = t2 - t1;
        for j in 0..6 {
            let (Some(a2), Some(a1), Some(qd), Some(qdd)) =
                (q2.get(j), q1.get(j), ff.qd.get_mut(j), ff.qdd.get_mut(j))
            else {
                continue;
            };
            let v2 = (a2 - a1) / h2;
            let (v, a) = match oldest {
                Some((t0, q0)) => {
                    let v1 = (a1 - q0.get(j).copied().unwrap_or(*a1)) / (t1 - t0);
                    let a = 2.0 * (v2 - v1) / (t2 - t0);
                    (v2 + a * h2 / 2.0, a)
                }
                None => (v2, 0.0),
            };
            if v * v2 > 0.0 && v.is_finite() && a.is_finite() {
                *qd = v;
                *qdd = a;
            }
        }
        ff
    }
}

/// A command read back from the registers, as the program executes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecodedCommand {
    /// The command (lookahead, gain and accelerations clamped as the program clamps them).
    pub command: JointCommand,
    /// Its feedforward, clamped ([`ServoFeedforward::clamped`]); [`ServoFeedforward::ZERO`]
    /// for speedj and stopj.
    pub feedforward: ServoFeedforward,
    /// The sequence number.
    pub seq: i32,
}

/// Where the register protocol lives, how the watchdog is set and how far servo targets are
/// extrapolated (the [module docs](self) give the register layout).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegisterMap {
    /// First integer input register (24 and up: fieldbus adapters and URCaps often claim
    /// 0–23).
    pub int_base: u8,
    /// First double input register (at most 26: the protocol uses 22 of them).
    pub double_base: u8,
    /// Minimum command-register write frequency before the watchdog stops the program \[Hz\].
    pub watchdog_hz: f64,
    /// servoj time sent with each servo command \[s\] (one 500 Hz cycle by default).
    pub servo_time_s: f64,
    /// How far the program extrapolates a servo target beyond the time it is valid at \[s\],
    /// in [0, 1 / `watchdog_hz`]; [`DEFAULT_EXTRAPOLATE_MAX_S`] (3 cycles) on a real robot.
    /// Rendered into the program, not written to a register.
    pub extrapolate_max_s: f64,
}

impl Default for RegisterMap {
    fn default() -> Self {
        Self {
            int_base: 24,
            double_base: 24,
            watchdog_hz: 10.0,
            servo_time_s: 0.002,
            extrapolate_max_s: DEFAULT_EXTRAPOLATE_MAX_S,
        }
    }
}

/// A float as URScript reads it (always with a decimal point, never an exponent).
fn urscript_float(x: f64) -> String {
    let s = format!("{x}");
    if s.contains('.') { s } else { format!("{s}.0") }
}

impl RegisterMap {
    /// Checks the registers fit in 0..=47, the watchdog frequency is positive, the servoj
    /// time is in [0.002, 0.1] s and `extrapolate_max_s` in [0, 1 / `watchdog_hz`].
    pub fn validate(&self) -> Result<()> {
        let int_top = usize::from(self.int_base) + INT_REGISTERS - 1;
        let dbl_top = usize::from(self.double_base) + DOUBLE_REGISTERS - 1;
        if int_top > 47 || dbl_top > 47 {
            return Err(RobotIoError::InvalidConfig {
                reason: format!(
                    "register protocol needs int {}..={int_top} and double {}..={dbl_top}; registers end at 47",
                    self.int_base, self.double_base
                ),
            });
        }
        if !(self.watchdog_hz > 0.0 && self.watchdog_hz.is_finite()) {
            return Err(RobotIoError::InvalidConfig {
                reason: "watchdog frequency must be > 0 hz".into(),
            });
        }
        if !(self.servo_time_s >= 0.002 && self.servo_time_s <= 0.1) {
            return Err(RobotIoError::InvalidConfig {
                reason: "servoj time must be in [0.002, 0.1] s".into(),
            });
        }
        if !(self.extrapolate_max_s >= 0.0 && self.extrapolate_max_s <= 1.0 / self.watchdog_hz) {
            return Err(RobotIoError::InvalidConfig {
                reason: format!(
                    "extrapolate_max_s {} must be in [0, {}] s (one watchdog period)",
                    self.extrapolate_max_s,
                    1.0 / self.watchdog_hz
                ),
            });
        }
        Ok(())
    }

    /// Servo targets further apart than this \[s\] restart the feedforward estimate:
    /// [`FEEDFORWARD_GAP_FACTOR`] × `extrapolate_max_s` (24 ms by default).
    pub fn feedforward_max_gap_s(&self) -> f64 {
        FEEDFORWARD_GAP_FACTOR * self.extrapolate_max_s
    }

    /// The input field names, in the order of [`RegisterMap::encode`]'s values.
    pub fn input_names(&self) -> Vec<String> {
        let ints = (0..INT_REGISTERS)
            .map(|i| format!("input_int_register_{}", usize::from(self.int_base) + i));
        let dbls = (0..DOUBLE_REGISTERS).map(|i| {
            format!(
                "input_double_register_{}",
                usize::from(self.double_base) + i
            )
        });
        ints.chain(dbls).collect()
    }

    /// Name of the output register the program writes its tick to (`output_int_register_<int_base>`).
    pub fn tick_register(&self) -> String {
        format!("output_int_register_{}", self.int_base)
    }

    /// Name of the command register (the one the watchdog watches).
    pub fn command_register(&self) -> String {
        format!("input_int_register_{}", self.int_base)
    }

    /// Writes `cmd` with feedforward `ff` (written for servo commands only; zeros otherwise)
    /// and sequence number `seq` into `out`, in the order of [`RegisterMap::input_names`].
    /// Allocates nothing.
    pub fn encode(
        &self,
        cmd: &JointCommand,
        ff: &ServoFeedforward,
        seq: i32,
        out: &mut [Value; INPUT_VALUES],
    ) {
        let (id, joints, time, lookahead, gain, acc, ff) = match *cmd {
            JointCommand::Servo {
                q,
                lookahead_s,
                gain,
            } => (
                command_id::SERVO,
                q,
                self.servo_time_s,
                lookahead_s,
                gain,
                0.0,
                *ff,
            ),
            JointCommand::Speed { qd, acc } => (
                command_id::SPEED,
                qd,
                0.0,
                0.0,
                0.0,
                acc,
                ServoFeedforward::ZERO,
            ),
            JointCommand::Stop { decel } => (
                command_id::STOP,
                [0.0; 6],
                0.0,
                0.0,
                0.0,
                decel,
                ServoFeedforward::ZERO,
            ),
        };
        let mut doubles = [0.0; DOUBLE_REGISTERS];
        for (d, v) in doubles.iter_mut().zip(joints) {
            *d = v;
        }
        let scalars = [
            (offset::TIME, time),
            (offset::LOOKAHEAD, lookahead),
            (offset::GAIN, gain),
            (offset::ACC, acc),
        ];
        for (i, v) in scalars {
            if let Some(d) = doubles.get_mut(i) {
                *d = v;
            }
        }
        for (d, v) in doubles.iter_mut().skip(offset::QD).zip(ff.qd) {
            *d = v;
        }
        for (d, v) in doubles.iter_mut().skip(offset::QDD).zip(ff.qdd) {
            *d = v;
        }
        let mut values = out.iter_mut();
        for v in [id, seq, ff.valid_tick] {
            if let Some(o) = values.next() {
                *o = Value::Int32(v);
            }
        }
        for (o, d) in values.zip(doubles) {
            *o = Value::Double(d);
        }
    }

    /// Reads the command the program would execute from register values (`ints` from
    /// `int_base`, `doubles` from `double_base`), clamping lookahead, gain, accelerations and
    /// the feedforward as the program does. `None` for IDLE or an unknown id.
    pub fn decode(
        ints: &[i32; INT_REGISTERS],
        doubles: &[f64; DOUBLE_REGISTERS],
    ) -> Option<DecodedCommand> {
        let [id, seq, valid_tick] = *ints;
        let at = |i: usize| doubles.get(i).copied().unwrap_or(0.0);
        let joints: Joints = std::array::from_fn(at);
        let lookahead = at(offset::LOOKAHEAD);
        let gain = at(offset::GAIN);
        let acc = at(offset::ACC);
        let (command, feedforward) = match id {
            command_id::SERVO => (
                JointCommand::Servo {
                    q: joints,
                    lookahead_s: lookahead.clamp(0.03, 0.2),
                    gain: gain.clamp(100.0, 2000.0),
                },
                ServoFeedforward {
                    qd: std::array::from_fn(|j| at(offset::QD + j)),
                    qdd: std::array::from_fn(|j| at(offset::QDD + j)),
                    valid_tick,
                }
                .clamped(),
            ),
            command_id::SPEED => (
                JointCommand::Speed {
                    qd: joints,
                    acc: acc.clamp(0.01, 40.0),
                },
                ServoFeedforward::ZERO,
            ),
            command_id::STOP => (
                JointCommand::Stop {
                    decel: acc.clamp(0.01, 40.0),
                },
                ServoFeedforward::ZERO,
            ),
            _ => return None,
        };
        Some(DecodedCommand {
            command,
            feedforward,
            seq,
        })
    }

    /// The control program with this map's registers, watchdog and extrapolation bound
    /// filled in.
    pub fn program(&self) -> String {
        let d = |i: usize| (usize::from(self.double_base) + i).to_string();
        let mut s = CONTROL_PROGRAM_TEMPLATE
            .replace("{{INT_BASE}}", &self.int_base.to_string())
            .replace("{{INT_SEQ}}", &(usize::from(self.int_base) + 1).to_string())
            .replace(
                "{{INT_VALID_TICK}}",
                &(usize::from(self.int_base) + 2).to_string(),
            )
            .replace("{{DOUBLE_BASE}}", &self.double_base.to_string())
            .replace("{{WATCHDOG_HZ}}", &format!("{}", self.watchdog_hz))
            .replace(
                "{{EXTRAPOLATE_MAX_S}}",
                &urscript_float(self.extrapolate_max_s),
            )
            .replace("{{FF_MAX_QD}}", &urscript_float(FEEDFORWARD_MAX_QD_RAD_S))
            .replace(
                "{{FF_MAX_QDD}}",
                &urscript_float(FEEDFORWARD_MAX_QDD_RAD_S2),
            )
            .replace("{{D_TIME}}", &d(offset::TIME))
            .replace("{{D_LOOKAHEAD}}", &d(offset::LOOKAHEAD))
            .replace("{{D_GAIN}}", &d(offset::GAIN))
            .replace("{{D_ACC}}", &d(offset::ACC));
        for i in 0..6 {
            s = s
                .replace(&format!("{{{{D{i}}}}}"), &d(i))
                .replace(&format!("{{{{D_QD{i}}}}}"), &d(offset::QD + i))
                .replace(&format!("{{{{D_QDD{i}}}}}"), &d(offset::QDD + i));
        }
        s
    }

    /// Reads the map back from a program's `# hrc-registers:` header line (as the emulator
    /// does); `None` if the script is not our program.
    pub fn from_program(script: &str) -> Option<RegisterMap> {
        if !script.contains(&format!("def {PROGRAM_NAME}():")) {
            return None;
        }
        let line = script
            .lines()
            .find_map(|l| l.trim().strip_prefix("# hrc-registers:"))?;
        let mut map = RegisterMap::default();
        for kv in line.split_whitespace() {
            let (k, v) = kv.split_once('=')?;
            match k {
                "int_base" => map.int_base = v.parse().ok()?,
                "double_base" => map.double_base = v.parse().ok()?,
                "watchdog_hz" => map.watchdog_hz = v.parse().ok()?,
                "extrapolate_max_s" => map.extrapolate_max_s = v.parse().ok()?,
                _ => {}
            }
        }
        map.validate().ok().map(|()| map)
    }
}

/// Sends URScript to a controller's script port.
#[derive(Debug, Clone)]
pub struct ScriptSender {
    host: String,
    port: u16,
    timeout: Duration,
}

impl ScriptSender {
    /// A sender to `host:port` (30002 secondary or 30003 real-time) with a 2 s timeout.
    pub fn new(host: impl Into<String>, port: u16) -> Self {
        Self {
            host: host.into(),
            port,
            timeout: Duration::from_secs(2),
        }
    }

    /// Sets the connect and write timeout.
    pub fn with_timeout(mut self, timeout: Duration) -> Self {
        self.timeout = timeout;
        self
    }

    /// Connects, sends `script` (a newline is appended if missing) and closes.
    pub async fn send(&self, script: &str) -> Result<()> {
        let addr = format!("{}:{}", self.host, self.port);
        let io = |context: String| move |source| RobotIoError::Io { context, source };
        let work = async {
            let mut s = TcpStream::connect(&addr)
                .await
                .map_err(|e| RobotIoError::connecting(e, &addr))?;
            s.write_all(script.as_bytes())
                .await
                .map_err(io(format!("sending script to {addr}")))?;
            if !script.ends_with('\n') {
                s.write_all(b"\n")
                    .await
                    .map_err(io(format!("sending script to {addr}")))?;
            }
            s.shutdown()
                .await
                .map_err(io(format!("closing script connection to {addr}")))?;
            Ok(())
        };
        tokio::time::timeout(self.timeout, work)
            .await
            .map_err(|_| RobotIoError::Timeout {
                what: "sending the script",
                after_ms: u64::try_from(self.timeout.as_millis()).unwrap_or(u64::MAX),
            })?
    }

    /// Sends our control program for `map`.
    pub async fn send_control_program(&self, map: &RegisterMap) -> Result<()> {
        map.validate()?;
        self.send(&map.program()).await
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use proptest::prelude::*;

    use super::*;

    /// The register numbers a program reads with `read_input_<kind>_register(N)`.
    fn registers_read(program: &str, kind: &str) -> BTreeSet<usize> {
        let pat = format!("read_input_{kind}_register(");
        program
            .match_indices(&pat)
            .filter_map(|(i, _)| {
                let rest = program.get(i + pat.len()..)?;
                rest.split(')').next()?.parse().ok()
            })
            .collect()
    }

    #[test]
    fn program_renders_every_placeholder_and_parses_back() {
        let map = RegisterMap {
            int_base: 30,
            double_base: 25,
            watchdog_hz: 25.0,
            servo_time_s: 0.002,
            extrapolate_max_s: 0.02,
        };
        let p = map.program();
        assert!(!p.contains("{{"), "unrendered placeholder in:\n{p}");
        assert!(p.contains(r#"rtde_set_watchdog("input_int_register_30", 25, "stop")"#));
        assert!(p.contains("read_input_float_register(34)")); // 25 + 9: acceleration
        assert!(p.contains("write_output_integer_register(30, tick)"));
        assert!(p.contains("clamp((tick - read_input_integer_register(32)) * t, -0.02, 0.02)"));
        assert!(p.contains("e = clamp(d, -vc / ac, 0.0)"));
        assert!(p.contains("vc = clamp(v, -3.141592653589793, 3.141592653589793)"));
        assert!(p.contains("ac = clamp(a, -3.141592653589793, 3.141592653589793)"));
        assert!(p.contains(
            "servoj(extrapolate(q, read_qd(), read_qdd(), d), 0, 0, t, lookahead, gain)"
        ));
        assert!(p.contains("speedj(qd, a, 0.008)"));
        assert!(p.contains("stopj("));
        // Every register of the protocol is read, and no other.
        let doubles: BTreeSet<usize> = (25..25 + DOUBLE_REGISTERS).collect();
        assert_eq!(registers_read(&p, "float"), doubles);
        assert_eq!(registers_read(&p, "integer"), BTreeSet::from([30, 32]));
        assert_eq!(RegisterMap::from_program(&p), Some(map));
        assert_eq!(RegisterMap::from_program("def other():\nend\n"), None);
        // The default renders the 6 ms bound with a decimal point.
        let d = RegisterMap::default().program();
        assert!(d.contains("extrapolate_max_s=0.006"), "{d}");
        assert!(d.contains(") * t, -0.006, 0.006)"));
        assert_eq!(RegisterMap::from_program(&d), Some(RegisterMap::default()));
        let zero = RegisterMap {
            extrapolate_max_s: 0.0,
            ..RegisterMap::default()
        };
        assert!(zero.program().contains(") * t, -0.0, 0.0)"));
    }

    #[test]
    fn out_of_range_registers_and_bounds_are_refused() {
        assert!(RegisterMap::default().validate().is_ok());
        // 22 double registers: base 26 ends at 47, base 27 would need 48; 3 int registers:
        // base 45 ends at 47.
        let top = RegisterMap {
            int_base: 45,
            double_base: 26,
            ..RegisterMap::default()
        };
        assert!(top.validate().is_ok());
        for bad in [
            RegisterMap {
                double_base: 27,
                ..RegisterMap::default()
            },
            RegisterMap {
                int_base: 46,
                ..RegisterMap::default()
            },
            RegisterMap {
                extrapolate_max_s: -0.001,
                ..RegisterMap::default()
            },
            RegisterMap {
                extrapolate_max_s: f64::NAN,
                ..RegisterMap::default()
            },
            // Beyond one watchdog period (10 Hz: 0.1 s).
            RegisterMap {
                extrapolate_max_s: 0.11,
                ..RegisterMap::default()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?} accepted");
        }
        // Scaled for the emulator at speedup 4, as the trial does: 2.5 Hz and 24 ms.
        let emulated = RegisterMap {
            watchdog_hz: 2.5,
            extrapolate_max_s: 0.024,
            ..RegisterMap::default()
        };
        assert!(emulated.validate().is_ok());
        assert!((emulated.feedforward_max_gap_s() - 0.096).abs() < 1e-15);
    }

    fn decode_values(v: &[Value; INPUT_VALUES]) -> Option<DecodedCommand> {
        let ints = [v[0], v[1], v[2]].map(|x| match x {
            Value::Int32(i) => i,
            _ => panic!("not an int: {x:?}"),
        });
        let doubles: [f64; DOUBLE_REGISTERS] =
            std::array::from_fn(|i| match v[INT_REGISTERS + i] {
                Value::Double(d) => d,
                x => panic!("not a double: {x:?}"),
            });
        RegisterMap::decode(&ints, &doubles)
    }

    #[test]
    fn commands_round_trip_through_registers() {
        let map = RegisterMap::default();
        let names = map.input_names();
        assert_eq!(names.len(), INPUT_VALUES);
        assert_eq!(names[0], "input_int_register_24");
        assert_eq!(names[1], "input_int_register_25");
        assert_eq!(names[2], "input_int_register_26"); // valid tick
        assert_eq!(names[3], "input_double_register_24");
        assert_eq!(names[12], "input_double_register_33");
        assert_eq!(names[13], "input_double_register_34"); // qd of joint 0
        assert_eq!(names[19], "input_double_register_40"); // qdd of joint 0
        assert_eq!(names[24], "input_double_register_45"); // qdd of joint 5
        let ff = ServoFeedforward {
            qd: [0.5, -0.25, 0.0, 1.0, -3.0, 0.125],
            qdd: [1.5, -2.0, 0.0, 0.5, 3.0, -0.75],
            valid_tick: 4321,
        };
        let servo = JointCommand::Servo {
            q: [0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
            lookahead_s: 0.1,
            gain: 300.0,
        };
        let mut v = [Value::Int32(0); INPUT_VALUES];
        map.encode(&servo, &ff, 7, &mut v);
        assert_eq!(v[2], Value::Int32(4321));
        assert_eq!(v[13], Value::Double(0.5));
        assert_eq!(v[24], Value::Double(-0.75));
        assert_eq!(
            decode_values(&v),
            Some(DecodedCommand {
                command: servo,
                feedforward: ff,
                seq: 7
            })
        );
        // speedj and stopj carry no feedforward, whatever is passed.
        for cmd in [
            JointCommand::Speed {
                qd: [0.1, -0.1, 0.0, 0.0, 0.0, 0.2],
                acc: 1.5,
            },
            JointCommand::Stop { decel: 2.0 },
        ] {
            map.encode(&cmd, &ff, 8, &mut v);
            assert_eq!(v[2], Value::Int32(0));
            assert!(v[13..].iter().all(|x| *x == Value::Double(0.0)));
            assert_eq!(
                decode_values(&v),
                Some(DecodedCommand {
                    command: cmd,
                    feedforward: ServoFeedforward::ZERO,
                    seq: 8
                })
            );
        }
        // Out-of-range lookahead, gain and feedforward are clamped as the program does;
        // NaN feedforward becomes 0; any valid tick passes (the program clamps δ).
        let wild = ServoFeedforward {
            qd: [10.0, -10.0, f64::NAN, 0.0, 0.0, 0.0],
            qdd: [-10.0, 10.0, f64::INFINITY, 0.0, 0.0, 0.0],
            valid_tick: i32::MIN,
        };
        map.encode(
            &JointCommand::Servo {
                q: [0.0; 6],
                lookahead_s: 1.0,
                gain: 5.0,
            },
            &wild,
            1,
            &mut v,
        );
        let d = decode_values(&v).unwrap();
        assert_eq!(
            d.command,
            JointCommand::Servo {
                q: [0.0; 6],
                lookahead_s: 0.2,
                gain: 100.0
            }
        );
        assert_eq!(d.feedforward.qd, [PI, -PI, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(d.feedforward.qdd, [-PI, PI, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(d.feedforward.valid_tick, i32::MIN);
        let doubles: [f64; DOUBLE_REGISTERS] =
            std::array::from_fn(|i| v[INT_REGISTERS + i].component(0).unwrap());
        assert_eq!(RegisterMap::decode(&[0, 1, 0], &doubles), None);
    }

    fn one_joint(qd: f64, qdd: f64) -> ServoFeedforward {
        ServoFeedforward {
            qd: [qd, 0.0, 0.0, 0.0, 0.0, 0.0],
            qdd: [qdd, 0.0, 0.0, 0.0, 0.0, 0.0],
            valid_tick: 100,
        }
    }

    #[test]
    fn the_time_since_the_valid_tick_counts_program_cycles() {
        // Worked by hand: valid at tick 100, now tick 103, t = 2 ms: 3 · 0.002 = 0.006 s.
        let ff = one_joint(0.5, 0.0);
        assert!((ff.since_valid_s(103, 0.002) - 0.006).abs() < 1e-15);
        assert_eq!(ff.since_valid_s(100, 0.002), 0.0);
        // Early (meant for a later tick): negative, and `target` evaluates it back to the
        // tick: 0.5 rad/s · (−0.004 s) = −0.002 rad.
        assert!((ff.since_valid_s(98, 0.002) + 0.004).abs() < 1e-15);
        let q = [1.0; 6];
        let back = ff.target(&q, ff.since_valid_s(98, 0.002), 0.006);
        assert!((back[0] - 0.998).abs() < 1e-15, "{back:?}");
        assert_eq!(back[1..], q[1..]);
        // Across the i32 wrap: valid at i32::MAX, now i32::MIN + 1 is 2 ticks later.
        let wrap = ServoFeedforward {
            valid_tick: i32::MAX,
            ..ff
        };
        assert!((wrap.since_valid_s(i32::MIN + 1, 0.002) - 0.004).abs() < 1e-15);
    }

    #[test]
    fn extrapolated_target_worked_examples() {
        // Worked by hand. q = 1 rad, qd = 0.5 rad/s, qdd = 2 rad/s², 5 ms after the time the
        // target is valid at, bound 6 ms: δ = 5 ms,
        // target = 1 + 0.5·0.005 + ½·2·0.005² = 1 + 0.0025 + 0.000025 = 1.002525.
        let q = [1.0, 2.0, 0.0, 0.0, 0.0, 0.0];
        let ff = one_joint(0.5, 2.0);
        let t = ff.target(&q, 0.005, 0.006);
        assert!((t[0] - 1.002525).abs() < 1e-12, "{}", t[0]);
        assert_eq!(t[1], 2.0); // no feedforward: held
        // Past the bound it holds at δ = 6 ms: 1 + 0.003 + ½·2·0.006² = 1.003036.
        for since in [0.006, 0.0061, 0.1, 1e9] {
            let t = ff.target(&q, since, 0.006);
            assert!((t[0] - 1.003036).abs() < 1e-12, "{since}: {}", t[0]);
        }
        // A command 4 ms late on arrival is extrapolated by those 4 ms at once:
        // 1 + 0.5·0.004 + ½·2·0.004² = 1.002016.
        assert!((ff.target(&q, 0.004, 0.006)[0] - 1.002016).abs() < 1e-12);
        // Decelerating: qd = 0.01 rad/s, qdd = −10 clamped to −π. The target stops where
        // 0.01 − π·e = 0, e = 3.1831 ms < 6 ms, at q + ½·0.01·e = q + 1.59155e-5 rad.
        let braking = one_joint(0.01, -10.0);
        let t = braking.target(&q, 0.006, 0.006);
        let e = 0.01 / PI;
        assert!((e - 0.0031831).abs() < 1e-7);
        assert!((t[0] - (1.0 + 0.5 * 0.01 * e)).abs() < 1e-15);
        assert!((t[0] - 1.0000159155).abs() < 1e-10);
        // qd = 0: the acceleration alone never starts a motion.
        assert_eq!(one_joint(0.0, 3.0).target(&q, 0.006, 0.006), q);
        // No extrapolation with a zero bound, or at δ = 0 (on time).
        assert_eq!(ff.target(&q, 0.004, 0.0), q);
        assert_eq!(ff.target(&q, 0.0, 0.006), q);
        // At the UR5e limits the safety bound: π·0.006 + ½·π·0.006² ≈ 0.0189 rad.
        let fastest = one_joint(100.0, 100.0);
        let reach = fastest.target(&q, 1.0, 0.006)[0] - 1.0;
        assert!((reach - (PI * 0.006 + 0.5 * PI * 0.006 * 0.006)).abs() < 1e-15);
        assert!(reach < 0.019);
    }

    fn joints() -> impl Strategy<Value = Joints> {
        proptest::array::uniform6(-6.0..6.0f64)
    }

    proptest! {
        /// The target never leaves the safety bound, never moves against qd, moves away
        /// from q monotonically with the time since arrival and holds beyond the bound.
        #[test]
        fn extrapolated_target_stays_within_its_bound(
            q in joints(),
            qd in proptest::array::uniform6(-5.0..5.0f64),
            qdd in proptest::array::uniform6(-5.0..5.0f64),
            since in -0.01..0.05f64,
            later in 0.0..0.05f64,
            max in 0.0..0.05f64,
        ) {
            let ff = ServoFeedforward { qd, qdd, valid_tick: 0 };
            let c = ff.clamped();
            let t = ff.target(&q, since, max);
            let t2 = ff.target(&q, since + later, max);
            let held = ff.target(&q, max + 1.0, max);
            let first = ff.target(&q, -max - 1.0, max);
            for j in 0..6 {
                let bound = c.qd[j].abs() * max + 0.5 * c.qdd[j].abs() * max * max;
                let (o, o2) = (t[j] - q[j], t2[j] - q[j]);
                prop_assert!(o.abs() <= bound + 1e-12);
                // Ahead of q along qd after the valid time, behind it before.
                prop_assert!(o * c.qd[j] * since.signum() >= 0.0);
                // Later is never further back along qd: the target moves one way only.
                prop_assert!((o2 - o) * c.qd[j] >= -1e-15);
                prop_assert!((o2 - (held[j] - q[j])) * c.qd[j] <= 1e-15);
                prop_assert!((o - (first[j] - q[j])) * c.qd[j] >= -1e-15);
                if since >= max {
                    prop_assert_eq!(t[j], held[j]);
                }
            }
        }

        /// The estimate is exact for a quadratic, whatever the spacing of the three targets.
        #[test]
        fn estimate_is_exact_for_quadratics(
            c0 in -2.0..2.0f64,
            c1 in -1.0..1.0f64,
            c2 in -1.5..1.5f64,
            t0 in 0.0..100.0f64,
            h1 in 0.002..0.02f64,
            h2 in 0.002..0.02f64,
        ) {
            let f = |t: f64| c0 + c1 * (t - t0) + c2 * (t - t0).powi(2);
            let mut est = FeedforwardEstimator::new(0.024);
            let (ta, tb, tc) = (t0, t0 + h1, t0 + h1 + h2);
            est.push(ta, &[f(ta); 6]);
            est.push(tb, &[f(tb); 6]);
            let ff = est.push(tc, &[f(tc); 6]);
            let v = c1 + 2.0 * c2 * (tc - t0);
            let v2 = (f(tc) - f(tb)) / h2;
            if v * v2 > 1e-6 {
                prop_assert!((ff.qd[0] - v).abs() < 1e-6, "qd {} vs {v}", ff.qd[0]);
                prop_assert!((ff.qdd[0] - 2.0 * c2).abs() < 1e-3, "qdd {} vs {}", ff.qdd[0], 2.0 * c2);
            } else if v * v2 < 0.0 {
                // A turn within the last interval: no extrapolation.
                prop_assert_eq!(ff.qd[0], 0.0);
                prop_assert_eq!(ff.qdd[0], 0.0);
            }
            prop_assert_eq!(ff.valid_tick, 0);
        }
    }

    #[test]
    fn estimator_worked_example_and_restarts() {
        // Worked by hand: q(t) = 1 + 0.5·t + 1.5·t² at t = 10, 18, 26 ms:
        // q0 = 1.00515, q1 = 1.009486, q2 = 1.014014; v1 = 0.004336/0.008 = 0.542,
        // v2 = 0.004528/0.008 = 0.566; qdd = 2·(0.566 − 0.542)/0.016 = 3.0;
        // qd = 0.566 + 3.0·0.004 = 0.578 = q'(0.026) = 0.5 + 3·0.026.
        let mut est = FeedforwardEstimator::new(0.024);
        let q = |x: f64| [x, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(est.push(0.010, &q(1.00515)), ServoFeedforward::ZERO);
        let two = est.push(0.018, &q(1.009486));
        assert!((two.qd[0] - 0.542).abs() < 1e-9); // two targets: the backward difference
        assert_eq!(two.qdd[0], 0.0);
        let ff = est.push(0.026, &q(1.014014));
        assert!((ff.qd[0] - 0.578).abs() < 1e-9, "{}", ff.qd[0]);
        assert!((ff.qdd[0] - 3.0).abs() < 1e-6, "{}", ff.qdd[0]);
        assert_eq!(ff.qd[1], 0.0);
        // A second target for the same time replaces the newest (same estimate again).
        let again = est.push(0.026, &q(1.014014));
        assert_eq!(again, ff);
        // A stop (the same target again): v2 = 0, no extrapolation across the kink.
        let stop = est.push(0.034, &q(1.014014));
        assert_eq!(stop, ServoFeedforward::ZERO);
        // A gap longer than 24 ms restarts it: one target, nothing to difference.
        est.push(0.042, &q(1.02));
        assert_eq!(est.push(0.070, &q(1.03)), ServoFeedforward::ZERO);
        // So does a timestamp going back (a new controller session) ...
        est.push(0.072, &q(1.031));
        assert_eq!(est.push(0.001, &q(1.032)), ServoFeedforward::ZERO);
        // ... a non-finite input, and reset().
        est.push(0.003, &q(1.033));
        assert_eq!(est.push(f64::NAN, &q(1.034)), ServoFeedforward::ZERO);
        est.push(0.005, &q(1.035));
        est.reset();
        assert_eq!(est.push(0.007, &q(1.036)), ServoFeedforward::ZERO);
        assert!(est.push(0.009, &q(1.037)).qd[0] > 0.0);
    }
}
