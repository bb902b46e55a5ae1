//! Robots reached over RTDE for a trial: the in-process controller **emulator** on loopback
//! ports (`--robot emulator`) and a real UR5e (`--robot <ip>`).
//!
//! Both hand the runtime a [`PacedRtde`]: an [`RtdeRobot`] whose `read_state` blocks until a
//! sample with a newer controller timestamp arrives, so the trial loop runs once per controller
//! cycle on the **robot's clock** (the emulator's virtual clock, sped up by
//! [`EmulatorConfig::speedup`]), not on the wall clock. When the loop falls behind, it takes
//! the newest sample and skips the older ones (the runtime's time is the controller
//! timestamp, so skipped cycles show as longer steps).

use std::io::BufRead as _;
use std::time::Duration;

use anyhow::Context as _;
use robot_io::dashboard::DashboardClient;
use robot_io::emulator::{Emulator, EmulatorConfig, SimBackend};
use robot_io::rtde_robot::{RtdeRobot, RtdeRobotConfig};
use robot_io::script::{RegisterMap, ScriptSender};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Robot, RobotState, runtime_state};

/// How long `read_state` waits for a newer sample before it reports the link as down.
const SAMPLE_TIMEOUT: Duration = Duration::from_secs(2);

/// An [`RtdeRobot`] paced on the controller timestamp (see the module docs).
pub(crate) struct PacedRtde {
    robot: RtdeRobot,
    rt: tokio::runtime::Handle,
    last_ts: f64,
}

impl std::fmt::Debug for PacedRtde {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PacedRtde")
            .field("last_ts", &self.last_ts)
            .finish_non_exhaustive()
    }
}

impl Robot for PacedRtde {
    /// The newest sample if its timestamp is newer than the last one returned; else waits for
    /// the next one.
    fn read_state(&mut self, out: &mut RobotState) -> robot_io::Result<()> {
        if self.robot.read_state(out).is_ok() && out.timestamp_s > self.last_ts {
            self.last_ts = out.timestamp_s;
            return Ok(());
        }
        loop {
            self.rt
                .block_on(self.robot.wait_state(out, SAMPLE_TIMEOUT))?;
            if out.timestamp_s > self.last_ts {
                self.last_ts = out.timestamp_s;
                return Ok(());
            }
        }
    }

    fn send(&mut self, cmd: &JointCommand) -> robot_io::Result<()> {
        self.robot.send(cmd)
    }
}

/// What keeps an RTDE robot's connection alive: the emulator (`None` for a real robot) and the
/// tokio runtime its tasks and the client's run on.
pub(crate) struct RtdeGuard {
    emulator: Option<Emulator>,
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
    /// Stops the emulator (if any) and the runtime.
    pub(crate) fn close(mut self) {
        if let Some(mut e) = self.emulator.take() {
            e.shutdown();
        }
        self.rt.shutdown_timeout(Duration::from_millis(200));
    }
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the tokio runtime")
}

/// Connects an `RtdeRobot` at `host:port`, sends our control program to `script_port` and
/// waits until it plays.
async fn connect(
    host: &str,
    port: u16,
    script_port: u16,
    map: RegisterMap,
) -> anyhow::Result<RtdeRobot> {
    let mut rcfg = RtdeRobotConfig::new(host);
    rcfg.port = port;
    rcfg.registers = map;
    rcfg.link_loss_min = Duration::from_secs(3);
    let mut robot = RtdeRobot::connect(rcfg)
        .await
        .with_context(|| format!("cannot connect RTDE at {host}:{port}"))?;
    ScriptSender::new(host, script_port)
        .send_control_program(&map)
        .await
        .context("cannot send the control program")?;
    let mut s = RobotState::default();
    for _ in 0..5000 {
        robot.wait_state(&mut s, SAMPLE_TIMEOUT).await?;
        if s.runtime_state == runtime_state::PLAYING {
            return Ok(robot);
        }
    }
    anyhow::bail!(
        "the control program never started (runtime state {})",
        s.runtime_state
    )
}

/// Starts the emulator in-process on ephemeral loopback ports with a `SimRobot` at `home_q`,
/// running `speedup` controller cycles per 2 ms of wall time, and connects to it.
pub(crate) fn start_emulator(
    home_q: [f64; 6],
    speedup: u32,
) -> anyhow::Result<(PacedRtde, RtdeGuard)> {
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
        // each command is held for a burst of 4 cycles, and must be extrapolated through it.
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
        anyhow::Ok((emu, robot))
    })?;
    let robot = PacedRtde {
        robot,
        rt: rt.handle().clone(),
        last_ts: f64::NEG_INFINITY,
    };
    Ok((
        robot,
        RtdeGuard {
            emulator: Some(emulator),
            rt,
        },
    ))
}

/// A real UR5e at `host` (untested here: no robot available). Connects the dashboard, prints
/// the robot mode, safety status and remote-control state, refuses unless the robot is in
/// remote control with a normal safety status, asks for confirmation on stdin, then connects
/// RTDE and starts our control program.
pub(crate) fn connect_ur(host: &str) -> anyhow::Result<(PacedRtde, RtdeGuard)> {
    let rt = runtime()?;
    rt.block_on(async {
        let mut d = DashboardClient::connect(
            host,
            robot_io::dashboard::DASHBOARD_PORT,
            Duration::from_secs(3),
        )
        .await
        .with_context(|| format!("cannot connect the dashboard of {host}"))?;
        let remote = d.is_in_remote_control().await?;
        let mode = d.robot_mode().await?;
        let safety = d.safety_status().await?;
        eprintln!(
            "UR5e at {host}: robot mode {}, safety status {safety:?}, remote control {remote}",
            robot_io::dashboard::robot_mode_name(mode.0)
        );
        anyhow::ensure!(
            remote,
            "the robot is not in remote control (set it on the teach pendant)"
        );
        anyhow::ensure!(safety.is_normal(), "the safety status is not normal");
        anyhow::Ok(())
    })?;
    eprint!(
        "The robot will move. Keep the workspace clear except for the operator. Type `yes` to start: "
    );
    let mut line = String::new();
    std::io::stdin().lock().read_line(&mut line)?;
    anyhow::ensure!(line.trim() == "yes", "not confirmed; nothing moved");
    let robot = rt.block_on(connect(
        host,
        robot_io::client::RTDE_PORT,
        robot_io::script::SECONDARY_PORT,
        RegisterMap::default(),
    ))?;
    let robot = PacedRtde {
        robot,
        rt: rt.handle().clone(),
        last_ts: f64::NEG_INFINITY,
    };
    Ok((robot, RtdeGuard { emulator: None, rt }))
}
