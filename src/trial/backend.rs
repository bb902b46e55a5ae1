//! Robots reached over RTDE for a trial: the in-process controller **emulator** on loopback
//! ports (`--robot emulator`) and a real UR5e (`--robot <ip>`).
//!
//! Both hand the runtime a [`PacedRtde`]: an [`RtdeRobot`] whose `read_state` waits for a
//! sample with a newer controller timestamp, so the trial loop runs once per controller
//! cycle on the **robot's clock** (the emulator's virtual clock, sped up by
//! [`EmulatorConfig::speedup`]), not on the wall clock. When the loop falls behind, it takes
//! the newest sample and skips the older ones (the runtime's time is the controller
//! timestamp, so skipped cycles show as longer steps).
//!
//! # The wait, and link loss
//! `read_state` never blocks longer than [`SAMPLE_WAIT`], two controller periods (4 ms of wall
//! time). A controller sends a sample every period, so the wait normally ends within one.
//! When none arrives in time, `read_state` returns the previous state again (same
//! timestamp): the runtime counts a missed cycle and the supervisor's robot-state staleness
//! check (SAF-REQ-009) stops the robot after 3 of them. While the client knows the link is
//! down (reconnecting), `read_state` waits the same bounded time and then fails with
//! `LinkDown`, and `send` fails too (the command is kept for the reconnection; the
//! supervisor latches SAF-REQ-012 and stops).
//!
//! The [`RtdeRobot`]'s client reconnects by itself (the RTDE set-up again, then the last
//! inputs). Whether the trial resumes is the runtime's decision (`[link]` in the trial
//! config); when it does and the controller's register watchdog stopped our program
//! meanwhile, the runtime asks for it again through [`TrialRobot::restart_program`], which
//! re-sends it through a `ScriptSender` on the tokio runtime without blocking the loop.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use crate::Error;
use crate::error::ResultExt as _;
use robot_io::dashboard::DashboardClient;
use robot_io::emulator::{Emulator, EmulatorConfig, SimBackend};
use robot_io::rtde_robot::{RtdeRobot, RtdeRobotConfig};
use robot_io::script::RegisterMap;
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Robot, RobotIoError, RobotState, runtime_state};

use super::runtime::TrialRobot;

/// The longest `read_state` waits for a newer sample: two controller periods of wall time.
pub(crate) const SAMPLE_WAIT: Duration = Duration::from_millis(4);

/// How long set-up (connect, the program starting) waits for one sample.
const SETUP_SAMPLE_TIMEOUT: Duration = Duration::from_secs(2);

/// Ports of a UR controller (or of `hrc-adapt emulate`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct UrPorts {
    /// RTDE (30004).
    pub(crate) rtde: u16,
    /// Dashboard server (29999).
    pub(crate) dashboard: u16,
    /// Script port our control program is sent to (30002, the secondary interface).
    pub(crate) script: u16,
}

impl Default for UrPorts {
    fn default() -> Self {
        Self {
            rtde: robot_io::client::RTDE_PORT,
            dashboard: robot_io::dashboard::DASHBOARD_PORT,
            script: robot_io::script::SECONDARY_PORT,
        }
    }
}

/// An [`RtdeRobot`] paced on the controller timestamp (see the module docs).
pub(crate) struct PacedRtde {
    robot: RtdeRobot,
    rt: tokio::runtime::Handle,
    last_ts: f64,
    /// The in-process emulator behind it, for its servo statistics (`None`: a real robot).
    emulator: Option<Arc<Emulator>>,
}

impl std::fmt::Debug for PacedRtde {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PacedRtde")
            .field("last_ts", &self.last_ts)
            .finish_non_exhaustive()
    }
}

impl PacedRtde {
    fn new(
        robot: RtdeRobot,
        rt: &tokio::runtime::Runtime,
        emulator: Option<Arc<Emulator>>,
    ) -> Self {
        Self {
            robot,
            rt: rt.handle().clone(),
            last_ts: f64::NEG_INFINITY,
            emulator,
        }
    }
}

impl Robot for PacedRtde {
    /// The newest sample if its timestamp is newer than the last one returned; else waits for
    /// the next one, at most [`SAMPLE_WAIT`], and then returns the previous state again.
    ///
    /// # Implementation
    /// Blocks at most [`SAMPLE_WAIT`] (4 ms), on success and on error: normally until the
    /// next sample, within one controller period. While the link is down, errors with
    /// `LinkDown` after the same wait (so a loop polling it runs at about the control rate).
    fn read_state(&mut self, out: &mut RobotState) -> robot_io::Result<()> {
        let deadline = Instant::now() + SAMPLE_WAIT;
        loop {
            if let Err(e) = self.robot.read_state(out) {
                std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
                return Err(e);
            }
            if out.timestamp_s > self.last_ts {
                self.last_ts = out.timestamp_s;
                return Ok(());
            }
            // `out` holds the previous state; wait for the next sample.
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(());
            }
            let mut next = *out;
            match self.rt.block_on(self.robot.wait_state(&mut next, left)) {
                Ok(()) if next.timestamp_s > self.last_ts => {
                    self.last_ts = next.timestamp_s;
                    *out = next;
                    return Ok(());
                }
                Ok(()) => {}
                // No sample in time: the previous state again.
                Err(RobotIoError::Timeout { .. }) => return Ok(()),
                Err(e) => {
                    std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
                    return Err(e);
                }
            }
        }
    }

    fn send(&mut self, cmd: &JointCommand) -> robot_io::Result<()> {
        self.robot.send(cmd)
    }
}

impl TrialRobot for PacedRtde {
    fn restart_program(&self) -> bool {
        self.robot.restart_program()
    }
    fn servo_extrapolation_s(&self) -> Option<f64> {
        Some(self.robot.registers().extrapolate_max_s)
    }
    fn servo_stats(&self) -> Option<robot_io::emulator::ServoStats> {
        self.emulator.as_ref().and_then(|e| e.servo_stats())
    }
    fn emulator_clock(&self) -> Option<robot_io::emulator::ClockStats> {
        self.emulator.as_ref().map(|e| e.clock_stats())
    }
}

/// What keeps an RTDE robot's connection alive: the emulator (`None` for a real robot) and the
/// tokio runtime its tasks and the client's run on.
pub(crate) struct RtdeGuard {
    emulator: Option<Arc<Emulator>>,
    rt: tokio::runtime::Runtime,
}

impl std::fmt::Debug for RtdeGuard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RtdeGuard")
            .field("emulated", &self.emulator.is_some())
            .finish_non_exhaustive()
    }
}

impl RtdeGuard {
    /// The in-process emulator (tests freeze and kill it).
    #[cfg(test)]
    pub(crate) fn emulator(&self) -> Option<Arc<Emulator>> {
        self.emulator.clone()
    }

    /// Stops the emulator (if any) and the runtime.
    pub(crate) fn close(mut self) {
        if let Some(e) = self.emulator.take() {
            e.shutdown();
        }
        self.rt.shutdown_timeout(Duration::from_millis(200));
    }
}

fn runtime() -> crate::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|source| Error::Thread {
            name: "tokio runtime",
            source,
        })
}

/// Connects an `RtdeRobot` at `host:port`, sends our control program to `script_port` and
/// waits until it plays. The robot keeps the script port, to restart the program after a
/// link loss ([`TrialRobot::restart_program`]).
async fn connect(
    host: &str,
    port: u16,
    script_port: u16,
    map: RegisterMap,
) -> crate::Result<RtdeRobot> {
    let mut rcfg = RtdeRobotConfig::new(host);
    rcfg.port = port;
    rcfg.registers = map;
    // A host without real-time scheduling: silence shorter than this is no link loss for the
    // client (the trial's own `[link] lost_after_s` and the supervisor act much sooner).
    rcfg.link_loss_min = Duration::from_secs(3);
    rcfg.program_port = Some(script_port);
    let mut robot = RtdeRobot::connect(rcfg)
        .await
        .with_context(|| format!("cannot connect RTDE at {host}:{port}"))?;
    robot
        .start_program()
        .await
        .context("cannot send the control program")?;
    let mut s = RobotState::default();
    for _ in 0..5000 {
        robot.wait_state(&mut s, SETUP_SAMPLE_TIMEOUT).await?;
        if s.runtime_state == runtime_state::PLAYING {
            return Ok(robot);
        }
    }
    Err(Error::RobotNotReady {
        host: host.to_owned(),
        reason: format!(
            "the control program never started (runtime state {})",
            s.runtime_state
        ),
    })
}

/// Starts the emulator in-process on ephemeral loopback ports with a `SimRobot` at `home_q`,
/// running `speedup` controller cycles per 2 ms of wall time (one every 2 ms / speedup), and
/// connects to it.
pub(crate) fn start_emulator(
    home_q: [f64; 6],
    speedup: u32,
) -> crate::Result<(PacedRtde, RtdeGuard)> {
    let rt = runtime()?;
    let (emulator, robot) = rt.block_on(async {
        let sim = SimRobot::new(SimConfig {
            initial_q_rad: home_q,
            ..SimConfig::ur5e()
        })?;
        let emu = Emulator::start(
            EmulatorConfig {
                speedup,
                ..EmulatorConfig::ephemeral()
            },
            Box::new(SimBackend::new(sim)),
        )
        .await
        .context("cannot start the emulator")?;
        // The program's watchdog counts virtual time; scale it so that it still allows the
        // real controller's 100 ms of *wall* time between command writes (at speedup 4, a
        // 25 ms stall of this process, e.g. under a parallel build, would otherwise stop it).
        // The servo extrapolation bound likewise covers 3 cycles of *wall* time: at speedup 4
        // a cycle lasts 0.5 ms of wall time, so a stall of this process that the real
        // controller's 6 ms would ride out spans 12 cycles, and must be extrapolated through.
        let map = RegisterMap {
            watchdog_hz: RegisterMap::default().watchdog_hz / f64::from(speedup.max(1)),
            extrapolate_max_s: RegisterMap::default().extrapolate_max_s * f64::from(speedup.max(1)),
            ..RegisterMap::default()
        };
        let robot = connect(
            "127.0.0.1",
            emu.rtde_addr().port(),
            emu.secondary_addr().port(),
            map,
        )
        .await?;
        Ok::<_, Error>((emu, robot))
    })?;
    let emulator = Arc::new(emulator);
    let robot = PacedRtde::new(robot, &rt, Some(Arc::clone(&emulator)));
    Ok((
        robot,
        RtdeGuard {
            emulator: Some(emulator),
            rt,
        },
    ))
}

/// A real UR5e at `host` (or `hrc-adapt emulate` there, on `ports`). Connects the
/// dashboard, prints the robot mode, safety status and remote-control state, refuses unless
/// the robot is in remote control with a normal safety status, asks for confirmation on
/// stdin (Ctrl-C there ends as `interrupted`, nothing moved), then connects RTDE and starts
/// our control program. Untested on a real robot (none available); tested against the
/// emulator process.
pub(crate) fn connect_ur(
    host: &str,
    ports: UrPorts,
    stop: &AtomicBool,
) -> crate::Result<(PacedRtde, RtdeGuard)> {
    let rt = runtime()?;
    rt.block_on(async {
        let mut d = DashboardClient::connect(host, ports.dashboard, Duration::from_secs(3))
            .await
            .with_context(|| format!("cannot connect the dashboard of {host}"))?;
        let remote = d.is_in_remote_control().await?;
        let mode = d.robot_mode().await?;
        let safety = d.safety_status().await?;
        eprintln!(
            "UR5e at {host}: robot mode {}, safety status {safety:?}, remote control {remote}",
            robot_io::dashboard::robot_mode_name(mode.0)
        );
        let not_ready = |reason: &str| Error::RobotNotReady {
            host: host.to_owned(),
            reason: reason.to_owned(),
        };
        ensure!(
            remote,
            not_ready("not in remote control (set it on the teach pendant)")
        );
        ensure!(
            safety.is_normal(),
            not_ready(&format!("the safety status is {safety:?}, not normal"))
        );
        Ok::<_, Error>(())
    })?;
    eprint!(
        "The robot will move. Keep the workspace clear except for the operator. Type `yes` to start: "
    );
    let Some(line) = super::prompt::read_line_or_stop(stop)? else {
        eprintln!();
        return Err(super::runtime::TrialEnded::before_start(
            "interrupted",
            Error::Interrupted {
                at: "the confirmation prompt",
            },
        )
        .into());
    };
    ensure!(
        line.trim() == "yes",
        Error::NotConfirmed {
            answer: line.trim().to_owned(),
        }
    );
    let robot = rt.block_on(connect(
        host,
        ports.rtde,
        ports.script,
        RegisterMap::default(),
    ))?;
    let robot = PacedRtde::new(robot, &rt, None);
    Ok((robot, RtdeGuard { emulator: None, rt }))
}
