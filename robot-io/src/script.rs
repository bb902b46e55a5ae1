//! Our URScript control program, its RTDE register protocol, and a script sender.
//!
//! The program (`resources/hrc_control.script`) reads RTDE input registers and runs servoj,
//! speedj or stopj; [`RegisterMap`] says which registers and how a [`JointCommand`] maps onto
//! them. It arms `rtde_set_watchdog` on the command register, so the program stops when the
//! client stops writing. [`ScriptSender`] sends the program to the primary/secondary (30001,
//! 30002) or real-time (30003) interface.

use std::time::Duration;

use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;

use crate::codec::Value;
use crate::types::JointCommand;
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
pub const INT_REGISTERS: usize = 2;
/// Double registers used, counted from [`RegisterMap::double_base`].
pub const DOUBLE_REGISTERS: usize = 10;
/// Values in one input package of the register protocol.
pub const INPUT_VALUES: usize = INT_REGISTERS + DOUBLE_REGISTERS;

/// Where the register protocol lives and how the watchdog is set.
///
/// Registers (with the defaults `int_base = double_base = 24`):
/// - `input_int_register_24`: command id ([`command_id`]); the watchdog watches it;
/// - `input_int_register_25`: sequence number (incremented per command);
/// - `input_double_register_24..29`: joint targets, q \[rad\] or qd [rad/s];
/// - `input_double_register_30`: servoj time \[s\];
/// - `input_double_register_31`: servoj lookahead \[s\], in [0.03, 0.2];
/// - `input_double_register_32`: servoj gain [-], in [100, 2000];
/// - `input_double_register_33`: speedj acceleration or stopj deceleration [rad/s²].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegisterMap {
    /// First integer input register (24 and up: fieldbus adapters and URCaps often claim
    /// 0–23).
    pub int_base: u8,
    /// First double input register.
    pub double_base: u8,
    /// Minimum command-register write frequency before the watchdog stops the program \[Hz\].
    pub watchdog_hz: f64,
    /// servoj time sent with each servo command \[s\] (one 500 Hz cycle by default).
    pub servo_time_s: f64,
}

impl Default for RegisterMap {
    fn default() -> Self {
        Self {
            int_base: 24,
            double_base: 24,
            watchdog_hz: 10.0,
            servo_time_s: 0.002,
        }
    }
}

impl RegisterMap {
    /// Checks the registers fit in 0..=47 and the watchdog frequency is positive.
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
        Ok(())
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

    /// Name of the command register (the one the watchdog watches).
    pub fn command_register(&self) -> String {
        format!("input_int_register_{}", self.int_base)
    }

    /// Writes `cmd` with sequence number `seq` into `out`, in the order of
    /// [`RegisterMap::input_names`]. Allocates nothing.
    pub fn encode(&self, cmd: &JointCommand, seq: i32, out: &mut [Value; INPUT_VALUES]) {
        let (id, joints, time, lookahead, gain, acc) = match *cmd {
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
            ),
            JointCommand::Speed { qd, acc } => (command_id::SPEED, qd, 0.0, 0.0, 0.0, acc),
            JointCommand::Stop { decel } => (command_id::STOP, [0.0; 6], 0.0, 0.0, 0.0, decel),
        };
        let [j0, j1, j2, j3, j4, j5] = joints;
        *out = [
            Value::Int32(id),
            Value::Int32(seq),
            Value::Double(j0),
            Value::Double(j1),
            Value::Double(j2),
            Value::Double(j3),
            Value::Double(j4),
            Value::Double(j5),
            Value::Double(time),
            Value::Double(lookahead),
            Value::Double(gain),
            Value::Double(acc),
        ];
    }

    /// Reads the command the program would execute from register values (`ints` from
    /// `int_base`, `doubles` from `double_base`), clamping lookahead and gain as the program
    /// does. `None` for IDLE or an unknown id.
    pub fn decode(
        ints: &[i32; INT_REGISTERS],
        doubles: &[f64; DOUBLE_REGISTERS],
    ) -> Option<JointCommand> {
        let [id, _seq] = *ints;
        let [j0, j1, j2, j3, j4, j5, _time, lookahead, gain, acc] = *doubles;
        let joints = [j0, j1, j2, j3, j4, j5];
        match id {
            command_id::SERVO => Some(JointCommand::Servo {
                q: joints,
                lookahead_s: lookahead.clamp(0.03, 0.2),
                gain: gain.clamp(100.0, 2000.0),
            }),
            command_id::SPEED => Some(JointCommand::Speed {
                qd: joints,
                acc: acc.clamp(0.01, 40.0),
            }),
            command_id::STOP => Some(JointCommand::Stop {
                decel: acc.clamp(0.01, 40.0),
            }),
            _ => None,
        }
    }

    /// The control program with this map's registers and watchdog filled in.
    pub fn program(&self) -> String {
        let d = |i: usize| (usize::from(self.double_base) + i).to_string();
        let mut s = CONTROL_PROGRAM_TEMPLATE
            .replace("{{INT_BASE}}", &self.int_base.to_string())
            .replace("{{INT_SEQ}}", &(usize::from(self.int_base) + 1).to_string())
            .replace("{{DOUBLE_BASE}}", &self.double_base.to_string())
            .replace("{{WATCHDOG_HZ}}", &format!("{}", self.watchdog_hz))
            .replace("{{D_TIME}}", &d(6))
            .replace("{{D_LOOKAHEAD}}", &d(7))
            .replace("{{D_GAIN}}", &d(8))
            .replace("{{D_ACC}}", &d(9));
        for i in 0..6 {
            s = s.replace(&format!("{{{{D{i}}}}}"), &d(i));
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
    use super::*;

    #[test]
    fn program_renders_every_placeholder_and_parses_back() {
        let map = RegisterMap {
            int_base: 30,
            double_base: 36,
            watchdog_hz: 25.0,
            servo_time_s: 0.002,
        };
        let p = map.program();
        assert!(!p.contains("{{"), "unrendered placeholder in:\n{p}");
        assert!(p.contains(r#"rtde_set_watchdog("input_int_register_30", 25, "stop")"#));
        assert!(p.contains("read_input_float_register(45)")); // 36 + 9: acceleration
        assert!(p.contains("servoj(q, 0, 0, t, lookahead, gain)"));
        assert!(p.contains("speedj(qd, a, 0.008)"));
        assert!(p.contains("stopj("));
        assert_eq!(RegisterMap::from_program(&p), Some(map));
        assert_eq!(RegisterMap::from_program("def other():\nend\n"), None);
    }

    #[test]
    fn out_of_range_registers_are_refused() {
        let map = RegisterMap {
            double_base: 40,
            ..RegisterMap::default()
        };
        assert!(map.validate().is_err());
        assert!(RegisterMap::default().validate().is_ok());
    }

    #[test]
    fn commands_round_trip_through_registers() {
        let map = RegisterMap::default();
        let names = map.input_names();
        assert_eq!(names[0], "input_int_register_24");
        assert_eq!(names[1], "input_int_register_25");
        assert_eq!(names[2], "input_double_register_24");
        assert_eq!(names[11], "input_double_register_33");
        let cmds = [
            JointCommand::Servo {
                q: [0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
                lookahead_s: 0.1,
                gain: 300.0,
            },
            JointCommand::Speed {
                qd: [0.1, -0.1, 0.0, 0.0, 0.0, 0.2],
                acc: 1.5,
            },
            JointCommand::Stop { decel: 2.0 },
        ];
        for cmd in cmds {
            let mut v = [Value::Int32(0); INPUT_VALUES];
            map.encode(&cmd, 7, &mut v);
            let ints = [v[0], v[1]].map(|x| match x {
                Value::Int32(i) => i,
                _ => panic!(),
            });
            let doubles: [f64; DOUBLE_REGISTERS] = std::array::from_fn(|i| match v[2 + i] {
                Value::Double(d) => d,
                _ => panic!(),
            });
            assert_eq!(ints[1], 7);
            assert_eq!(RegisterMap::decode(&ints, &doubles), Some(cmd));
        }
        // Out-of-range lookahead and gain are clamped as the program does.
        let mut v = [Value::Int32(0); INPUT_VALUES];
        map.encode(
            &JointCommand::Servo {
                q: [0.0; 6],
                lookahead_s: 1.0,
                gain: 5.0,
            },
            1,
            &mut v,
        );
        let doubles: [f64; DOUBLE_REGISTERS] =
            std::array::from_fn(|i| v[2 + i].component(0).unwrap());
        assert_eq!(
            RegisterMap::decode(&[1, 1], &doubles),
            Some(JointCommand::Servo {
                q: [0.0; 6],
                lookahead_s: 0.2,
                gain: 100.0
            })
        );
        assert_eq!(RegisterMap::decode(&[0, 1], &doubles), None);
    }
}
