//! [`RtdeRobot`]: the [`Robot`] trait over RTDE, for a real UR5e, URSim or the emulator.
//!
//! Reads the state fields of [`RobotState`] at up to 500 Hz and writes joint commands into
//! the input registers of our control program ([`RegisterMap`]). The program itself is sent
//! to a script port ([`RtdeRobotConfig::program_port`]) by [`RtdeRobot::start_program`], or
//! separately with [`crate::script::ScriptSender::send_control_program`].
//!
//! # Link loss and recovery
//! The [`RtdeClient`] underneath detects a lost link (socket error, or silence longer than
//! [`ClientConfig::link_loss_timeout`]) and reconnects on its own, with backoff: it re-runs
//! the whole RTDE set-up (protocol version, recipes, checked against the first ones),
//! re-sends the last inputs and restarts the stream. While it does, [`Robot::read_state`] and
//! [`Robot::send`] fail with [`RobotIoError::LinkDown`] (the command is still kept, so the
//! reconnection delivers the newest one). A controller whose program stopped meanwhile (its
//! register watchdog fires when writes stop) needs the program again:
//! [`RtdeRobot::restart_program`] re-sends it through a [`ScriptSender`] on the tokio runtime,
//! without blocking the caller. Restarting is the caller's decision (a program stopped from
//! the pendant must stay stopped), never automatic.

use std::borrow::Cow;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use crate::client::{ClientConfig, LinkState, OutputBuffer, RtdeClient};
use crate::codec::{FieldSlot, Value};
use crate::script::{
    CONTROLLER_CYCLE_S, FeedforwardEstimator, INPUT_VALUES, RegisterMap, ScriptSender,
    ServoFeedforward,
};
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
    /// Script port (30002 secondary, 30003 real-time) our control program is sent to by
    /// [`RtdeRobot::start_program`] and [`RtdeRobot::restart_program`]; `None`: the program is
    /// managed elsewhere and those fail.
    pub program_port: Option<u16>,
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
            program_port: None,
        }
    }

    /// The client configuration this robot uses.
    pub fn client_config(&self) -> ClientConfig {
        let mut c = ClientConfig::new(self.host.clone(), &STATE_FIELDS);
        c.output_fields.push(self.registers.tick_register());
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

/// Sends our control program to the controller's script port, in the background.
#[derive(Debug)]
struct ProgramSender {
    sender: ScriptSender,
    map: RegisterMap,
    /// The runtime the client runs on (the sends are spawned there).
    rt: tokio::runtime::Handle,
    /// A background send is under way.
    in_flight: Arc<AtomicBool>,
    /// Background sends that completed without error.
    sent: Arc<AtomicU64>,
}

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
    program: Option<ProgramSender>,
    /// Controller timestamp of the last state `read_state`/`wait_state` returned \[s\].
    read_ts: f64,
    /// Where the program's tick is in a sample.
    tick_slot: FieldSlot,
    /// The program tick of the last decoded sample, and of the last state returned.
    last_tick: i32,
    read_tick: i32,
    /// The program tick and controller time \[s\] the last servo command was meant for
    /// (`None` after a non-servo command).
    last_valid: Option<(i32, f64)>,
    /// Feedforward of the servo commands ([`Robot::send`]).
    feedforward: FeedforwardEstimator,
}

/// The most cycles a servo command is stamped ahead of the newest state read + 1 [-]: a caller
/// that sends once per cycle while no new state arrives (its own clock predicting the robot's)
/// gets consecutive ticks for its consecutive commands; a lead beyond this (a restarted
/// program, whose tick began again at 0) falls back to the state's tick + 1.
pub const MAX_SERVO_LEAD_CYCLES: i32 = 8;

/// The program tick and controller time \[s\] a servo command is meant for: the cycle after the
/// last state read (`read_tick` + 1 at `read_ts` + one cycle), or, when the previous servo
/// command `last_valid` was already meant for that cycle or a later one (the state was read
/// again, no newer one having arrived), the cycle after that command. So a caller that predicts
/// one cycle per call while samples are late, as the controller does, stamps each command with
/// the tick its target is for, and never two commands with the same tick.
pub fn servo_slot(read_tick: i32, read_ts: f64, last_valid: Option<(i32, f64)>) -> (i32, f64) {
    let fresh = (read_tick.wrapping_add(1), read_ts + CONTROLLER_CYCLE_S);
    match last_valid {
        Some((tick, t)) if (0..MAX_SERVO_LEAD_CYCLES).contains(&tick.wrapping_sub(fresh.0)) => {
            (tick.wrapping_add(1), t + CONTROLLER_CYCLE_S)
        }
        _ => fresh,
    }
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
        let tick_name = cfg.registers.tick_register();
        let tick_slot = buf
            .slot(&tick_name)
            .ok_or_else(|| RobotIoError::RecipeMismatch {
                reason: format!("{tick_name} missing from the output recipe"),
            })?;
        let mut values = [Value::Int32(0); INPUT_VALUES];
        cfg.registers.encode(
            &JointCommand::Stop { decel: 1.0 },
            &ServoFeedforward::ZERO,
            0,
            &mut values,
        );
        // Idle: command id 0.
        values[0] = Value::Int32(crate::script::command_id::IDLE);
        client.send_inputs(0, &values)?;
        client.start().await?;
        let program = cfg.program_port.map(|port| ProgramSender {
            sender: ScriptSender::new(cfg.host.clone(), port),
            map: cfg.registers,
            rt: tokio::runtime::Handle::current(),
            in_flight: Arc::new(AtomicBool::new(false)),
            sent: Arc::new(AtomicU64::new(0)),
        });
        Ok(RtdeRobot {
            client,
            buf,
            slots: StateSlots(slots),
            map: cfg.registers,
            values,
            seq: 0,
            last: RobotState::default(),
            received: false,
            program,
            read_ts: f64::NAN,
            tick_slot,
            last_tick: 0,
            read_tick: 0,
            last_valid: None,
            feedforward: FeedforwardEstimator::new(cfg.registers.feedforward_max_gap_s()),
        })
    }

    /// The register protocol in use (its extrapolation bound, watchdog and registers).
    pub fn registers(&self) -> &RegisterMap {
        &self.map
    }

    /// The underlying client (link state, reconnects, controller version).
    pub fn client(&self) -> &RtdeClient {
        &self.client
    }

    /// Sends our control program to [`RtdeRobotConfig::program_port`] and waits until it is
    /// sent (not until it plays: watch `runtime_state`). Errors with
    /// [`RobotIoError::InvalidConfig`] when no program port is configured.
    pub async fn start_program(&self) -> Result<()> {
        let p = self.program_sender()?;
        p.sender.send_control_program(&p.map).await
    }

    /// Re-sends our control program in the background (after a link loss, when the
    /// controller's watchdog stopped it) and returns at once: `true` if a send was started,
    /// `false` if one is still under way or no program port is configured. The controller
    /// plays it when it can (not while the arm is still braking, nor under a safety stop): call
    /// again until `runtime_state` shows PLAYING. Failures are logged.
    ///
    /// # Implementation
    /// Never blocks; spawns one task on the runtime [`RtdeRobot::connect`] ran on (allocates).
    pub fn restart_program(&self) -> bool {
        let Ok(p) = self.program_sender() else {
            return false;
        };
        if p.in_flight.swap(true, Ordering::AcqRel) {
            return false;
        }
        let (sender, map) = (p.sender.clone(), p.map);
        let (in_flight, sent) = (p.in_flight.clone(), p.sent.clone());
        p.rt.spawn(async move {
            match sender.send_control_program(&map).await {
                Ok(()) => {
                    sent.fetch_add(1, Ordering::Relaxed);
                    tracing::info!("control program re-sent");
                }
                Err(e) => tracing::warn!("re-sending the control program failed: {e}"),
            }
            in_flight.store(false, Ordering::Release);
        });
        true
    }

    /// Background program sends ([`RtdeRobot::restart_program`]) completed so far.
    pub fn program_restarts(&self) -> u64 {
        self.program
            .as_ref()
            .map_or(0, |p| p.sent.load(Ordering::Relaxed))
    }

    fn program_sender(&self) -> Result<&ProgramSender> {
        self.program
            .as_ref()
            .ok_or_else(|| RobotIoError::InvalidConfig {
                reason: "no program port configured for this robot".into(),
            })
    }

    /// Waits up to `timeout` for a new sample and returns it in `out`.
    pub async fn wait_state(&mut self, out: &mut RobotState, timeout: Duration) -> Result<()> {
        self.client.recv_timeout(&mut self.buf, timeout).await?;
        self.decode()?;
        *out = self.last;
        self.read_ts = self.last.timestamp_s;
        self.read_tick = self.last_tick;
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
        self.last_tick = self.tick_slot.read_f64(p)? as i32;
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
        self.read_ts = self.last.timestamp_s;
        self.read_tick = self.last_tick;
        Ok(())
    }

    /// Writes `cmd` into the input registers with the next sequence number, a servo command
    /// with its feedforward (see below).
    ///
    /// # Implementation
    /// Never blocks on the network: the registers are handed to the client's writer task,
    /// which sends them at once (latest value wins). Allocates nothing. While the link is
    /// being re-established the registers are kept (the reconnection sends the newest ones)
    /// but the command has not reached the robot: errors with [`RobotIoError::LinkDown`].
    ///
    /// # Feedforward
    /// A servo target is taken as valid at the timestamp of the last state `read_state` (or
    /// `wait_state`) returned plus one cycle, and its valid tick is the program tick of that
    /// state + 1 (the program's next cycle after it); when that state was returned again (no
    /// newer one had arrived) and the previous servo command was already meant for that cycle,
    /// the cycle after the previous command ([`servo_slot`]). Its velocity and acceleration are
    /// those of the parabola through the last three servo targets at those times
    /// ([`FeedforwardEstimator`], restarted by a non-servo command, a gap longer than
    /// [`RegisterMap::feedforward_max_gap_s`] or a timestamp going back). The program
    /// extrapolates by the time since the valid tick on its own clock, however late the target
    /// arrives.
    fn send(&mut self, cmd: &JointCommand) -> Result<()> {
        self.seq = self.seq.wrapping_add(1);
        let ff = match cmd {
            JointCommand::Servo { q, .. } => {
                let (tick, t) = servo_slot(self.read_tick, self.read_ts, self.last_valid);
                self.last_valid = Some((tick, t));
                let mut ff = self.feedforward.push(t, q);
                ff.valid_tick = tick;
                ff
            }
            JointCommand::Speed { .. } | JointCommand::Stop { .. } => {
                self.last_valid = None;
                self.feedforward.reset();
                ServoFeedforward::ZERO
            }
        };
        self.map.encode(cmd, &ff, self.seq, &mut self.values);
        self.client.send_inputs(0, &self.values)?;
        match self.client.link_state() {
            LinkState::Up => Ok(()),
            LinkState::Reconnecting => Err(RobotIoError::LinkDown {
                reason: Cow::Borrowed("reconnecting; the command is kept for the reconnection"),
            }),
            LinkState::Closed => Err(self.client.fatal().unwrap_or(RobotIoError::LinkDown {
                reason: Cow::Borrowed("the client is closed"),
            })),
        }
    }
}
