//! A client of the UR dashboard server (TCP 29999), with typed replies.
//!
//! The dashboard server speaks one line per command and one line per reply. The replies
//! parsed here follow UR's dashboard server documentation (e-Series, PolyScope 5).

use std::time::Duration;

use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::TcpStream;
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};

use crate::types::safety_mode;
use crate::{Result, RobotIoError};

/// Dashboard server port of a UR controller.
pub const DASHBOARD_PORT: u16 = 29999;

/// The commands this client sends (and the emulator answers).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DashboardCommand {
    /// `power on`.
    PowerOn,
    /// `power off`.
    PowerOff,
    /// `brake release`.
    BrakeRelease,
    /// `play`.
    Play,
    /// `pause`.
    Pause,
    /// `stop`.
    Stop,
    /// `safetystatus`.
    SafetyStatus,
    /// `robotmode`.
    RobotMode,
    /// `unlock protective stop`.
    UnlockProtectiveStop,
    /// `close safety popup`.
    CloseSafetyPopup,
    /// `is in remote control`.
    IsInRemoteControl,
    /// `quit`.
    Quit,
}

impl DashboardCommand {
    /// Every command.
    pub const ALL: [DashboardCommand; 12] = [
        DashboardCommand::PowerOn,
        DashboardCommand::PowerOff,
        DashboardCommand::BrakeRelease,
        DashboardCommand::Play,
        DashboardCommand::Pause,
        DashboardCommand::Stop,
        DashboardCommand::SafetyStatus,
        DashboardCommand::RobotMode,
        DashboardCommand::UnlockProtectiveStop,
        DashboardCommand::CloseSafetyPopup,
        DashboardCommand::IsInRemoteControl,
        DashboardCommand::Quit,
    ];

    /// The command line (without newline).
    pub const fn as_str(self) -> &'static str {
        match self {
            DashboardCommand::PowerOn => "power on",
            DashboardCommand::PowerOff => "power off",
            DashboardCommand::BrakeRelease => "brake release",
            DashboardCommand::Play => "play",
            DashboardCommand::Pause => "pause",
            DashboardCommand::Stop => "stop",
            DashboardCommand::SafetyStatus => "safetystatus",
            DashboardCommand::RobotMode => "robotmode",
            DashboardCommand::UnlockProtectiveStop => "unlock protective stop",
            DashboardCommand::CloseSafetyPopup => "close safety popup",
            DashboardCommand::IsInRemoteControl => "is in remote control",
            DashboardCommand::Quit => "quit",
        }
    }

    /// Parses a command line (case-insensitive, surrounding whitespace ignored).
    pub fn parse(line: &str) -> Option<DashboardCommand> {
        let line = line.trim();
        DashboardCommand::ALL
            .into_iter()
            .find(|c| c.as_str().eq_ignore_ascii_case(line))
    }
}

/// `safetystatus` names, by UR `safety_mode` / safety status value.
const SAFETY_NAMES: [(&str, i32); 11] = [
    ("NORMAL", safety_mode::NORMAL),
    ("REDUCED", safety_mode::REDUCED),
    ("PROTECTIVE_STOP", safety_mode::PROTECTIVE_STOP),
    ("RECOVERY", 4),
    ("SAFEGUARD_STOP", safety_mode::SAFEGUARD_STOP),
    ("SYSTEM_EMERGENCY_STOP", safety_mode::SYSTEM_EMERGENCY_STOP),
    ("ROBOT_EMERGENCY_STOP", safety_mode::ROBOT_EMERGENCY_STOP),
    ("VIOLATION", 8),
    ("FAULT", safety_mode::FAULT),
    ("AUTOMATIC_MODE_SAFEGUARD_STOP", 10),
    ("SYSTEM_THREE_POSITION_ENABLING_STOP", 11),
];

/// The dashboard name of a safety mode (`"NORMAL"`, `"PROTECTIVE_STOP"`, …).
pub fn safety_status_name(mode: i32) -> &'static str {
    SAFETY_NAMES
        .iter()
        .find(|(_, m)| *m == mode)
        .map_or("UNDEFINED_SAFETY_MODE", |(n, _)| n)
}

/// `robotmode` names by UR `robot_mode` value (−1 NO_CONTROLLER … 8 UPDATING_FIRMWARE).
const ROBOT_MODE_NAMES: [(&str, i32); 10] = [
    ("NO_CONTROLLER", -1),
    ("DISCONNECTED", 0),
    ("CONFIRM_SAFETY", 1),
    ("BOOTING", 2),
    ("POWER_OFF", 3),
    ("POWER_ON", 4),
    ("IDLE", 5),
    ("BACKDRIVE", 6),
    ("RUNNING", 7),
    ("UPDATING_FIRMWARE", 8),
];

/// The dashboard name of a robot mode (`"RUNNING"`, `"POWER_OFF"`, …).
pub fn robot_mode_name(mode: i32) -> &'static str {
    ROBOT_MODE_NAMES
        .iter()
        .find(|(_, m)| *m == mode)
        .map_or("UNKNOWN", |(n, _)| n)
}

/// A parsed `safetystatus` reply: the UR safety mode value (see [`crate::safety_mode`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SafetyStatus(pub i32);

impl SafetyStatus {
    /// Parses `Safetystatus: NAME`.
    pub fn parse(reply: &str) -> Option<SafetyStatus> {
        let name = reply.trim().strip_prefix("Safetystatus:")?.trim();
        SAFETY_NAMES
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, m)| SafetyStatus(*m))
    }

    /// Whether the mode is NORMAL or REDUCED.
    pub fn is_normal(self) -> bool {
        self.0 == safety_mode::NORMAL || self.0 == safety_mode::REDUCED
    }
}

/// A parsed `robotmode` reply: the UR robot mode value (see [`crate::robot_mode`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RobotModeReply(pub i32);

impl RobotModeReply {
    /// Parses `Robotmode: NAME`.
    pub fn parse(reply: &str) -> Option<RobotModeReply> {
        let name = reply.trim().strip_prefix("Robotmode:")?.trim();
        ROBOT_MODE_NAMES
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, m)| RobotModeReply(*m))
    }
}

/// A client of the dashboard server.
#[derive(Debug)]
pub struct DashboardClient {
    reader: BufReader<OwnedReadHalf>,
    writer: OwnedWriteHalf,
    timeout: Duration,
    line: String,
}

impl DashboardClient {
    /// Connects to `host:port` (29999 on a controller) and reads the greeting. `timeout`
    /// bounds the connect and every reply.
    pub async fn connect(host: &str, port: u16, timeout: Duration) -> Result<DashboardClient> {
        let addr = format!("{host}:{port}");
        let stream = tokio::time::timeout(timeout, TcpStream::connect(&addr))
            .await
            .map_err(|_| RobotIoError::Timeout {
                what: "the dashboard connection",
                after_ms: ms(timeout),
            })?
            .map_err(|e| RobotIoError::connecting(e, &addr))?;
        let (r, w) = stream.into_split();
        let mut c = DashboardClient {
            reader: BufReader::new(r),
            writer: w,
            timeout,
            line: String::new(),
        };
        let greeting = c.read_line().await?;
        if !greeting.starts_with("Connected: Universal Robots Dashboard Server") {
            return Err(RobotIoError::Dashboard {
                command: "(greeting)".into(),
                reply: greeting,
            });
        }
        Ok(c)
    }

    async fn read_line(&mut self) -> Result<String> {
        self.line.clear();
        let n = tokio::time::timeout(self.timeout, self.reader.read_line(&mut self.line))
            .await
            .map_err(|_| RobotIoError::Timeout {
                what: "a dashboard reply",
                after_ms: ms(self.timeout),
            })?
            .map_err(|source| RobotIoError::Io {
                context: "reading a dashboard reply".into(),
                source,
            })?;
        if n == 0 {
            return Err(RobotIoError::LinkDown {
                reason: "the dashboard server closed the connection".into(),
            });
        }
        Ok(self.line.trim_end().to_owned())
    }

    /// Sends `command` and returns the raw reply line.
    pub async fn raw(&mut self, command: &str) -> Result<String> {
        let line = format!("{command}\n");
        tokio::time::timeout(self.timeout, self.writer.write_all(line.as_bytes()))
            .await
            .map_err(|_| RobotIoError::Timeout {
                what: "a dashboard write",
                after_ms: ms(self.timeout),
            })?
            .map_err(|source| RobotIoError::Io {
                context: "writing a dashboard command".into(),
                source,
            })?;
        self.read_line().await
    }

    async fn expect(&mut self, cmd: DashboardCommand, ok_prefix: &str) -> Result<()> {
        let reply = self.raw(cmd.as_str()).await?;
        if reply.starts_with(ok_prefix) {
            Ok(())
        } else {
            Err(RobotIoError::Dashboard {
                command: cmd.as_str().into(),
                reply,
            })
        }
    }

    /// `power on` (reply `Powering on`).
    pub async fn power_on(&mut self) -> Result<()> {
        self.expect(DashboardCommand::PowerOn, "Powering on").await
    }

    /// `power off` (reply `Powering off`).
    pub async fn power_off(&mut self) -> Result<()> {
        self.expect(DashboardCommand::PowerOff, "Powering off")
            .await
    }

    /// `brake release` (reply `Brake releasing`).
    pub async fn brake_release(&mut self) -> Result<()> {
        self.expect(DashboardCommand::BrakeRelease, "Brake releasing")
            .await
    }

    /// `play` (reply `Starting program`).
    pub async fn play(&mut self) -> Result<()> {
        self.expect(DashboardCommand::Play, "Starting program")
            .await
    }

    /// `pause` (reply `Pausing program`).
    pub async fn pause(&mut self) -> Result<()> {
        self.expect(DashboardCommand::Pause, "Pausing program")
            .await
    }

    /// `stop` (reply `Stopped`).
    pub async fn stop(&mut self) -> Result<()> {
        self.expect(DashboardCommand::Stop, "Stopped").await
    }

    /// `unlock protective stop` (reply `Protective stop releasing`).
    pub async fn unlock_protective_stop(&mut self) -> Result<()> {
        self.expect(
            DashboardCommand::UnlockProtectiveStop,
            "Protective stop releasing",
        )
        .await
    }

    /// `close safety popup` (reply `closing safety popup`).
    pub async fn close_safety_popup(&mut self) -> Result<()> {
        self.expect(DashboardCommand::CloseSafetyPopup, "closing safety popup")
            .await
    }

    /// `safetystatus`, parsed.
    pub async fn safety_status(&mut self) -> Result<SafetyStatus> {
        let reply = self.raw(DashboardCommand::SafetyStatus.as_str()).await?;
        SafetyStatus::parse(&reply).ok_or(RobotIoError::Dashboard {
            command: DashboardCommand::SafetyStatus.as_str().into(),
            reply,
        })
    }

    /// `robotmode`, parsed.
    pub async fn robot_mode(&mut self) -> Result<RobotModeReply> {
        let reply = self.raw(DashboardCommand::RobotMode.as_str()).await?;
        RobotModeReply::parse(&reply).ok_or(RobotIoError::Dashboard {
            command: DashboardCommand::RobotMode.as_str().into(),
            reply,
        })
    }

    /// `is in remote control`, parsed (`true` / `false`).
    pub async fn is_in_remote_control(&mut self) -> Result<bool> {
        let reply = self
            .raw(DashboardCommand::IsInRemoteControl.as_str())
            .await?;
        match reply.trim() {
            "true" => Ok(true),
            "false" => Ok(false),
            _ => Err(RobotIoError::Dashboard {
                command: DashboardCommand::IsInRemoteControl.as_str().into(),
                reply,
            }),
        }
    }
}

fn ms(d: Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_parse_back() {
        for c in DashboardCommand::ALL {
            assert_eq!(DashboardCommand::parse(c.as_str()), Some(c));
        }
        assert_eq!(
            DashboardCommand::parse("  Power On \r"),
            Some(DashboardCommand::PowerOn)
        );
        assert_eq!(DashboardCommand::parse("dance"), None);
    }

    #[test]
    fn replies_parse() {
        assert_eq!(
            SafetyStatus::parse("Safetystatus: PROTECTIVE_STOP"),
            Some(SafetyStatus(3))
        );
        assert!(
            SafetyStatus::parse("Safetystatus: NORMAL")
                .unwrap()
                .is_normal()
        );
        assert_eq!(SafetyStatus::parse("Safetymode: NORMAL"), None);
        assert_eq!(
            RobotModeReply::parse("Robotmode: RUNNING"),
            Some(RobotModeReply(7))
        );
        for (name, mode) in SAFETY_NAMES {
            assert_eq!(safety_status_name(mode), name);
        }
        assert_eq!(robot_mode_name(3), "POWER_OFF");
    }
}
