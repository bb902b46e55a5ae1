//! [`RtdeRobot`]: the [`Robot`] trait over RTDE, for a real UR5e, URSim or the emulator.
//!
//! Reads the state fields of [`RobotState`] at up to 500 Hz and writes joint commands into
//! the input registers of our control program ([`RegisterMap`]). The program itself is sent
//! separately, with [`crate::script::ScriptSender::send_control_program`].

use std::borrow::Cow;
use std::time::Duration;

use crate::client::{ClientConfig, LinkState, OutputBuffer, RtdeClient};
use crate::codec::{FieldSlot, Value};
use crate::script::{INPUT_VALUES, RegisterMap};
use crate::types::{JointCommand, Robot, RobotState};
use crate::{Result, RobotIoError};

/// The output fields [`RtdeRobot`] subscribes to, one per [`RobotState`] field.
pub const STATE_FIELDS: [&str; 14] = [
    "timestamp",
    "actual_q",
    "actual_qd",
    "target_q",
    "target_qd",
    "actual_TCP_pose",
    "actual_TCP_speed",
    "speed_scaling",
    "target_speed_fraction",
    "robot_mode",
    "safety_mode",
    "runtime_state",
    "robot_status_bits",
    "safety_status_bits",
];

/// Settings of an [`RtdeRobot`].
#[derive(Debug, Clone, PartialEq)]
pub struct RtdeRobotConfig {
    /// Controller host.
    pub host: String,
    /// RTDE port (30004).
    pub port: u16,
    /// Output frequency \[Hz\], ≤ 500.
    pub frequency_hz: f64,
    /// Where the register protocol lives.
    pub registers: RegisterMap,
    /// Floor of the link-loss timeout (see [`ClientConfig::link_loss_min`]).
    pub link_loss_min: Duration,
}

impl RtdeRobotConfig {
    /// 500 Hz on port 30004, registers 24 and up.
    pub fn new(host: impl Into<String>) -> Self {
        Self {
            host: host.into(),
            port: crate::client::RTDE_PORT,
            frequency_hz: 500.0,
            registers: RegisterMap::default(),
            link_loss_min: Duration::ZERO,
        }
    }

    /// The client configuration this robot uses.
    pub fn client_config(&self) -> ClientConfig {
        let mut c = ClientConfig::new(self.host.clone(), &STATE_FIELDS);
        c.port = self.port;
        c.frequency_hz = self.frequency_hz;
        c.input_recipes = vec![self.registers.input_names()];
        c.link_loss_min = self.link_loss_min;
        c
    }
}

/// Precomputed slots of the state fields.
#[derive(Debug, Clone, Copy)]
struct StateSlots([FieldSlot; 14]);

/// A UR arm over RTDE. See the [module docs](self).
#[derive(Debug)]
pub struct RtdeRobot {
    client: RtdeClient,
    buf: OutputBuffer,
    slots: StateSlots,
    map: RegisterMap,
    values: [Value; INPUT_VALUES],
    seq: i32,
    last: RobotState,
    received: bool,
}

impl RtdeRobot {
    /// Connects, sets up the recipes, writes an idle command and starts streaming. Call
    /// within a tokio runtime; the client's tasks run on it.
    pub async fn connect(cfg: RtdeRobotConfig) -> Result<RtdeRobot> {
        cfg.registers.validate()?;
        let client = RtdeClient::connect(cfg.client_config()).await?;
        let buf = client.output_buffer();
        let mut slots = [FieldSlot {
            offset: 0,
            ty: crate::codec::FieldType::Double,
        }; 14];
        for (slot, name) in slots.iter_mut().zip(STATE_FIELDS) {
            *slot = buf.slot(name).ok_or_else(|| RobotIoError::RecipeMismatch {
                reason: format!("{name} missing from the output recipe"),
            })?;
        }
        let mut values = [Value::Int32(0); INPUT_VALUES];
        cfg.registers
            .encode(&JointCommand::Stop { decel: 1.0 }, 0, &mut values);
        // Idle: command id 0.
        values[0] = Value::Int32(crate::script::command_id::IDLE);
        client.send_inputs(0, &values)?;
        client.start().await?;
        Ok(RtdeRobot {
            client,
            buf,
            slots: StateSlots(slots),
            map: cfg.registers,
            values,
            seq: 0,
            last: RobotState::default(),
            received: false,
        })
    }

    /// The underlying client (link state, reconnects, controller version).
    pub fn client(&self) -> &RtdeClient {
        &self.client
    }

    /// Waits up to `timeout` for a new sample and returns it in `out`.
    pub async fn wait_state(&mut self, out: &mut RobotState, timeout: Duration) -> Result<()> {
        self.client.recv_timeout(&mut self.buf, timeout).await?;
        self.decode()?;
        *out = self.last;
        Ok(())
    }

    fn decode(&mut self) -> Result<()> {
        let p = self.buf.payload();
        let [
            ts,
            aq,
            aqd,
            tq,
            tqd,
            pose,
            speed,
            ss,
            tsf,
            rm,
            sm,
            rs,
            rsb,
            ssb,
        ] = self.slots.0;
        let s = &mut self.last;
        s.timestamp_s = ts.read_f64(p)?;
        aq.read_into(p, &mut s.actual_q)?;
        aqd.read_into(p, &mut s.actual_qd)?;
        tq.read_into(p, &mut s.target_q)?;
        tqd.read_into(p, &mut s.target_qd)?;
        pose.read_into(p, &mut s.actual_tcp_pose)?;
        speed.read_into(p, &mut s.actual_tcp_speed)?;
        s.speed_scaling = ss.read_f64(p)?;
        s.target_speed_fraction = tsf.read_f64(p)?;
        s.robot_mode = rm.read_f64(p)? as i32;
        s.safety_mode = sm.read_f64(p)? as i32;
        s.runtime_state = rs.read_f64(p)? as u32;
        s.robot_status_bits = rsb.read_f64(p)? as u32;
        s.safety_status_bits = ssb.read_f64(p)? as u32;
        self.received = true;
        Ok(())
    }
}

impl Robot for RtdeRobot {
    /// Copies the newest received state into `out`.
    ///
    /// # Implementation
    /// Never blocks and never allocates, on success and on error alike (the reader task
    /// fills a preallocated ring; the link errors carry static or shared texts). When no new
    /// sample arrived since the last call, `out` gets the previous one again. Errors with
    /// [`RobotIoError::LinkDown`] while the link is being re-established or before the first
    /// sample, and [`RobotIoError::LinkClosed`] once the client is closed for good.
    fn read_state(&mut self, out: &mut RobotState) -> Result<()> {
        match self.client.link_state() {
            LinkState::Up => {}
            LinkState::Reconnecting => {
                return Err(RobotIoError::LinkDown {
                    reason: Cow::Borrowed("reconnecting"),
                });
            }
            LinkState::Closed => {
                return Err(self.client.fatal().unwrap_or(RobotIoError::LinkDown {
                    reason: Cow::Borrowed("the client is closed"),
                }));
            }
        }
        if self.client.try_latest(&mut self.buf)?.is_some() {
            self.decode()?;
        }
        if !self.received {
            return Err(RobotIoError::LinkDown {
                reason: Cow::Borrowed("no state received yet"),
            });
        }
        *out = self.last;
        Ok(())
    }

    /// Writes `cmd` into the input registers with the next sequence number.
    ///
    /// # Implementation
    /// Never blocks on the network: the registers are handed to the client's writer task,
    /// which sends them at once (latest value wins). Allocates nothing.
    fn send(&mut self, cmd: &JointCommand) -> Result<()> {
        self.seq = self.seq.wrapping_add(1);
        self.map.encode(cmd, self.seq, &mut self.values);
        self.client.send_inputs(0, &self.values)
    }
}
