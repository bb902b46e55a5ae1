//! The ur_rtde backend for a trial (`--robot-backend ur_rtde`, feature `ur-rtde`): a
//! [`UrRtdeRobot`] (SDU ur_rtde 1.6.5 through robot-io's C shim) paced like the native
//! backend, on the controller's timestamps ([`paced_read`], the same bounded wait as
//! [`super::backend::PacedRtde`]).
//!
//! ur_rtde's interfaces use UR's fixed ports (30004, 30003, 29999). So with `--robot
//! emulator` the in-process emulator listens on 127.0.0.1 with those ports (it fails clearly
//! when another program holds them), and with `--robot <address>` only the address can be
//! chosen.
//!
//! What differs from the native backend, and why:
//! - The controller runs ur_rtde's control script, not our `hrc_control`: no servo
//!   feedforward (a late target is held, not extrapolated), and no register watchdog (ur_rtde
//!   arms one only on `setWatchdog`, which the trial does not call).
//! - A stop: the supervisor repeats its Stop every cycle while the arm brakes; ur_rtde's
//!   `stopJ` waits for the script's "done" (a few controller cycles), so an identical Stop
//!   that follows a Stop is not sent again (the controller already brakes at that
//!   deceleration), nor after ur_rtde refused it (its script is not running, or the robot is
//!   safety-stopped: the controller holds the arm), except when the link was down. Any other
//!   command is sent every cycle.
//! - A silent link (no new sample: a pulled cable, a stalled controller). ur_rtde's stopJ
//!   waits for the script's "done" on the last state received for up to 300 s, and its
//!   servoJ/speedJ wait up to 3 s for "ready" on it and write to a socket whose peer may have
//!   stopped reading. Those waits happen on [`UrRtdeRobot`]'s sender thread, never in the
//!   control cycle (its `send` only hands over), but a sender thread stuck in one would leave
//!   every later command unsent until its `call_stuck_after` bound reports the link down. So
//!   they are not entered at all on a silent link: by the age of the newest
//!   sample: under [`STALE_AFTER`] a Stop is stopJ; from it on a Stop is speedJ to zero at the
//!   same deceleration (it does not wait for "done"); from [`SILENT_AFTER`] on every command
//!   is refused at once as [`robot_io::RobotIoError::LinkDown`] without calling ur_rtde (the
//!   supervisor latches SAF-REQ-012; nothing reaches the robot then anyway).
//!   Test: `sigstop_of_the_emulator_ends_the_ur_rtde_trial_as_link_lost_without_blocking`.
//! - No program restart after a link loss ([`TrialRobot::restart_program`] is `false`), and
//!   no resume: `[link] resume = true` is refused. ur_rtde's own reconnect re-uploads its
//!   script, which blocks for seconds; and 2.5 s into a silent link (its receive deadline)
//!   ur_rtde 1.6.5's RTDEControlInterface reconnects by itself from its receive thread and,
//!   with the controller still silent, crashes the process (SIGSEGV in
//!   `RTDE::isDataAvailable` called from `RTDEControlInterface::receiveCallback`, seen under
//!   gdb with a SIGSTOPped emulator, 2026-12-07). Without resume the trial ends at
//!   `[link] lost_after_s` (1 s), before that.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use crate::error::ResultExt as _;
use robot_io::emulator::{Emulator, EmulatorConfig, SimBackend};
use robot_io::realtime::Scheduling;
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Robot, RobotState, UrRtdeConfig, UrRtdeRobot};

use super::backend::{RtdeGuard, SampleSource, UR_PERIOD, paced_read, rtde_runtime, sample_wait};
use super::config::{EmulatorSection, RealtimeConfig};
use super::runtime::TrialRobot;

/// From this age of the newest sample on, a Stop is sent as speedJ to zero instead of stopJ
/// (see the module docs) [s]: two UR periods, before the supervisor's staleness stop
/// (SAF-REQ-009, after 3 stale cycles).
pub(crate) const STALE_AFTER: Duration = Duration::from_millis(4);
/// From this age of the newest sample on, every command is refused as a link that is down
/// (see the module docs) [s]: 50 UR periods, far above a late sample and far below the
/// trial's link-loss declaration (`[link] lost_after_s`, 1 s by default).
pub(crate) const SILENT_AFTER: Duration = Duration::from_millis(100);

/// What a command becomes at a given age of the newest sample (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Route {
    /// Sent as it is (a Stop as stopJ).
    AsIs,
    /// A Stop, sent as speedJ to zero at its deceleration.
    StopBySpeed,
    /// Refused: the link is silent.
    Refuse,
}

fn route(cmd: &JointCommand, age: Option<Duration>) -> Route {
    match age {
        Some(a) if a >= SILENT_AFTER => Route::Refuse,
        Some(a) if a >= STALE_AFTER && matches!(cmd, JointCommand::Stop { .. }) => {
            Route::StopBySpeed
        }
        _ => Route::AsIs,
    }
}

/// A [`UrRtdeRobot`] paced on the controller timestamp (see the module docs).
pub(crate) struct PacedUrRtde {
    robot: UrRtdeRobot,
    last_ts: f64,
    last_fresh: Option<Instant>,
    period: Duration,
    emulator: Option<Arc<Emulator>>,
    /// The Stop last sent, while no other command followed it.
    stopping: Option<JointCommand>,
}

impl std::fmt::Debug for PacedUrRtde {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PacedUrRtde")
            .field("last_ts", &self.last_ts)
            .finish_non_exhaustive()
    }
}

struct Source<'a>(&'a mut UrRtdeRobot);

impl SampleSource for Source<'_> {
    fn now(&self) -> Instant {
        Instant::now()
    }
    fn read(&mut self, out: &mut RobotState) -> robot_io::Result<()> {
        self.0.read_state(out)
    }
    fn nap(&mut self, d: Duration) {
        std::thread::sleep(d);
    }
}

impl Robot for PacedUrRtde {
    /// As [`super::backend::PacedRtde`]: the newest sample if newer, else a bounded wait for
    /// the next one. ur_rtde's read copies its receive thread's latest sample and allocates
    /// nothing (robot-io's `ur_rtde_robot` module docs).
    fn read_state(&mut self, out: &mut RobotState) -> robot_io::Result<()> {
        let wait = sample_wait(Instant::now(), self.last_fresh, self.period);
        let before = self.last_ts;
        let r = paced_read(&mut Source(&mut self.robot), &mut self.last_ts, out, wait);
        if self.last_ts > before {
            self.last_fresh = Some(Instant::now());
        }
        r
    }

    fn send(&mut self, cmd: &JointCommand) -> robot_io::Result<()> {
        let stop = matches!(cmd, JointCommand::Stop { .. });
        if stop && self.stopping.as_ref() == Some(cmd) {
            // Not sent again, but a failure of the one sent (reported by ur_rtde's sender
            // thread after the call) still reaches the supervisor, and a Stop refused on a
            // link that is down is sent again next cycle.
            return match self.robot.take_failure() {
                Some(e) => {
                    if matches!(e, robot_io::RobotIoError::LinkDown { .. }) {
                        self.stopping = None;
                    }
                    Err(e)
                }
                None => Ok(()),
            };
        }
        // A Stop is remembered even when ur_rtde refuses it: it refuses when its script is
        // not running or the robot is safety-stopped, and then the controller holds the arm
        // already. The refusal reaches the supervisor once (SAF-REQ-012), instead of ur_rtde
        // refusing (and printing) 500 times a second. Not on a link that is down (refused at
        // once by the shim): that Stop is sent again next cycle, in case the link returns.
        let age = self.last_fresh.map(|t| t.elapsed());
        let sent = match (route(cmd, age), cmd) {
            (Route::Refuse, _) => Err(robot_io::RobotIoError::LinkDown {
                reason: std::borrow::Cow::Borrowed(
                    "no new robot state for 100 ms: the command is not handed to ur_rtde, \
                     which would wait on the silent link",
                ),
            }),
            (Route::StopBySpeed, JointCommand::Stop { decel }) => {
                self.robot.send(&JointCommand::Speed {
                    qd: [0.0; 6],
                    acc: *decel,
                })
            }
            _ => {
                self.stopping = stop.then_some(*cmd);
                self.robot.send(cmd)
            }
        };
        if matches!(sent, Err(robot_io::RobotIoError::LinkDown { .. })) {
            self.stopping = None;
        }
        sent
    }
}

impl TrialRobot for PacedUrRtde {
    fn servo_stats(&self) -> Option<robot_io::emulator::ServoStats> {
        // Counted for our program only; ur_rtde's script is not our feedforward protocol.
        None
    }
    fn emulator_clock(&self) -> Option<robot_io::emulator::ClockStats> {
        self.emulator.as_ref().map(|e| e.clock_stats())
    }
    fn emulator_clock_scheduling(&self) -> Option<Scheduling> {
        self.emulator.as_ref().and_then(|e| e.clock_scheduling())
    }
}

fn connect(
    host: &str,
    emulator: Option<Arc<Emulator>>,
    period: Duration,
) -> crate::Result<PacedUrRtde> {
    let robot = UrRtdeRobot::connect(&UrRtdeConfig::new(host))
        .with_context(|| format!("cannot connect ur_rtde to {host}"))?;
    Ok(PacedUrRtde {
        robot,
        last_ts: f64::NEG_INFINITY,
        last_fresh: None,
        period,
        emulator,
        stopping: None,
    })
}

/// The in-process emulator on 127.0.0.1 with UR's ports and a `SimRobot` at `home_q`, and
/// ur_rtde connected to it (its control script uploaded and running).
pub(crate) fn start_emulator(
    home_q: [f64; 6],
    speedup: u32,
    realtime: RealtimeConfig,
    emulator: EmulatorSection,
) -> crate::Result<(PacedUrRtde, RtdeGuard)> {
    let (rt, _io) = rtde_runtime(None)?;
    let emu = rt.block_on(async {
        let sim = SimRobot::new(SimConfig {
            initial_q_rad: home_q,
            ..SimConfig::ur5e()
        })?;
        Emulator::start(
            EmulatorConfig {
                speedup,
                clock_priority: realtime.emulator_clock(),
                wait_for_client: emulator.wait_for_client(speedup),
                ..EmulatorConfig::default()
            },
            Box::new(SimBackend::new(sim)),
        )
        .await
        .context(
            "cannot start the emulator on 127.0.0.1 with UR's ports 30004, 29999, 30002, \
             30003, which ur_rtde needs (is another emulator running?)",
        )
    })?;
    let emu = Arc::new(emu);
    let robot = connect(
        "127.0.0.1",
        Some(Arc::clone(&emu)),
        UR_PERIOD / speedup.max(1),
    )?;
    Ok((robot, RtdeGuard::new(Some(emu), rt)))
}

/// A real UR5e at `host` through ur_rtde, after the same dashboard checks and confirmation as
/// the native backend ([`super::backend::check_and_confirm`]). Refused with `[link] resume =
/// true` (see the module docs).
pub(crate) fn connect_ur(
    host: &str,
    realtime: RealtimeConfig,
    resume: bool,
    stop: &AtomicBool,
) -> crate::Result<(PacedUrRtde, RtdeGuard)> {
    if resume {
        return Err(crate::Error::Config {
            field: "link.resume".into(),
            reason: "= true is not supported with --robot-backend ur_rtde: ur_rtde 1.6.5's \
                     control interface reconnects on its own 2.5 s into a silent link and \
                     crashes the process there (SIGSEGV in RTDE::isDataAvailable); use resume \
                     = false (the trial then ends as link_lost) or the native backend"
                .into(),
        });
    }
    let (rt, _io) = rtde_runtime(realtime.rtde_io())?;
    super::backend::check_and_confirm(&rt, host, super::backend::UrPorts::default(), stop)?;
    let robot = connect(host, None, UR_PERIOD)?;
    Ok((robot, RtdeGuard::new(None, rt)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_command_is_routed_by_the_age_of_the_newest_sample() {
        let stop = JointCommand::Stop { decel: 3.0 };
        let servo = JointCommand::Servo {
            q: [0.0; 6],
            lookahead_s: 0.1,
            gain: 300.0,
        };
        let ms = |x: u64| Some(Duration::from_millis(x));
        // No sample yet, or a fresh one: as it is.
        assert_eq!(route(&stop, None), Route::AsIs);
        assert_eq!(route(&stop, ms(3)), Route::AsIs);
        // Two periods without a sample: a Stop no longer waits for the script's "done".
        assert_eq!(route(&stop, ms(4)), Route::StopBySpeed);
        assert_eq!(route(&servo, ms(4)), Route::AsIs);
        assert_eq!(route(&servo, ms(99)), Route::AsIs);
        // 100 ms of silence: nothing is handed to ur_rtde.
        assert_eq!(route(&stop, ms(100)), Route::Refuse);
        assert_eq!(route(&servo, ms(100)), Route::Refuse);
    }
}
