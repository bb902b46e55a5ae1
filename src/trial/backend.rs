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
//! `read_state` waits for a newer sample until it is one period overdue, and at least
//! [`SAMPLE_WAIT`], one period of the real controller (2 ms of wall time; on the emulator at
//! speedup *s* that spans *s* emulated cycles): at most 4 ms ([`sample_wait`]). It polls the
//! client's non-blocking read and naps [`POLL_NAP`] between polls: no lock, no tokio timer, no
//! wake from another thread, so nothing the client's tasks do (or fail to do: a runtime whose
//! workers are stuck) can stretch it. It returns at most one nap's
//! overshoot and one read after the deadline ([`paced_read`], whose bound
//! `paced_read_returns_by_the_deadline_and_never_misses_a_sample_that_came_before_it` proves on
//! a scripted clock; `read_state_returns_while_the_tokio_runtime_is_stuck` shows it on the
//! real client). A controller sends a sample every period, so the wait normally ends within
//! one. When none arrives in time, `read_state` returns the previous state again (same
//! timestamp): the runtime counts a missed cycle and the supervisor's robot-state staleness
//! check (SAF-REQ-009) stops the robot after 3 of them. While the client knows the link is
//! down (reconnecting), `read_state` keeps polling for the same bounded time and then fails
//! with `LinkDown`, and `send` fails too (the command is kept for the reconnection; the
//! supervisor latches SAF-REQ-012 and stops).
//!
//! The [`RtdeRobot`]'s client reconnects by itself (the RTDE set-up again, then the last
//! inputs). Whether the trial resumes is the runtime's decision (`[link]` in the trial
//! config); when it does and the controller's register watchdog stopped our program
//! meanwhile, the runtime asks for it again through [`TrialRobot::restart_program`], which
//! re-sends it through a `ScriptSender` on the tokio runtime without blocking the loop.

use std::sync::atomic::AtomicBool;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use crate::Error;
use crate::error::ResultExt as _;
use robot_io::dashboard::DashboardClient;
use robot_io::emulator::{Emulator, EmulatorConfig, SimBackend};
use robot_io::realtime::{RtPriority, Scheduling};
use robot_io::rtde_robot::{RtdeRobot, RtdeRobotConfig};
use robot_io::script::RegisterMap;
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Robot, RobotState, runtime_state};

use super::config::{EmulatorSection, RealtimeConfig};
use super::runtime::TrialRobot;

/// How long `read_state` waits for a newer sample at least: one period of the real
/// controller, in wall time [s] (see [`sample_wait`] for when it waits longer).
pub(crate) const SAMPLE_WAIT: Duration = Duration::from_millis(2);

/// The wall-clock period of a real controller's samples [s].
pub(crate) const UR_PERIOD: Duration = Duration::from_millis(2);

/// How long a `read_state` called at `call` waits for the next sample, when the previous one
/// was read at `last_fresh` and samples come every `period` (wall time): until the next
/// sample is one whole period overdue (`last_fresh + 2·period`), but at least
/// [`SAMPLE_WAIT`] after the call.
///
/// Measured from the call alone, a wait of one period ended just before a sample that came a
/// little late: at speedup 1 the emulator's samples (a tokio timer of 1 ms resolution) missed
/// a 2 ms wait so often that 35–39 % of the cycles ran on a held state and 23–26 % of the
/// executed-jerk samples were over the bound (BENCHMARKS.md, session 10). Bound: at most
/// `max(SAMPLE_WAIT, 2·period)` after the call, i.e. two periods of the real controller (4 ms)
/// at most.
pub(crate) fn sample_wait(
    call: Instant,
    last_fresh: Option<Instant>,
    period: Duration,
) -> Duration {
    let overdue = last_fresh
        .and_then(|t| t.checked_add(period.saturating_mul(2)))
        .map_or(Duration::ZERO, |d| d.saturating_duration_since(call));
    overdue.max(SAMPLE_WAIT)
}

/// The nap between two polls of the client while waiting for a sample [s]. The control
/// thread's timer slack is lowered to match (`priority::tighten_timer_slack`).
pub(crate) const POLL_NAP: Duration = Duration::from_micros(50);

/// What [`paced_read`] waits on: a clock, a read that never blocks, and a nap.
pub(crate) trait SampleSource {
    /// The time now.
    fn now(&self) -> Instant;
    /// The newest state, or the previous one again when none is newer; never blocks.
    fn read(&mut self, out: &mut RobotState) -> robot_io::Result<()>;
    /// Sleeps for about `d` (an OS sleep may overshoot).
    fn nap(&mut self, d: Duration);
}

/// Reads `src` until it gives a state newer than `*last_ts` [s] (returned, and `*last_ts`
/// advanced) or until `wait` has passed since the call. At the deadline it returns the last
/// read's result: `Ok` with the previous state again (the caller counts a missed cycle), or
/// that read's error (the link is down).
///
/// Bound: it returns by `wait` + the longer of one nap's overshoot and one read, + one read,
/// after the call. A sample that becomes readable before the deadline is always returned: the
/// last read *starts* at or after the deadline (a read that started before it and ended after
/// it is followed by one more at once, with no nap). Naps are at most [`POLL_NAP`].
pub(crate) fn paced_read<S: SampleSource>(
    src: &mut S,
    last_ts: &mut f64,
    out: &mut RobotState,
    wait: Duration,
) -> robot_io::Result<()> {
    let deadline = src.now() + wait;
    loop {
        let started = src.now();
        let r = src.read(out);
        if r.is_ok() && out.timestamp_s > *last_ts {
            *last_ts = out.timestamp_s;
            return Ok(());
        }
        if started >= deadline {
            return r;
        }
        let now = src.now();
        if now < deadline {
            src.nap(deadline.saturating_duration_since(now).min(POLL_NAP));
        }
    }
}

/// The real clock and OS sleep over an [`RtdeRobot`].
struct RtdeSource<'a>(&'a mut RtdeRobot);

impl SampleSource for RtdeSource<'_> {
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
    last_ts: f64,
    /// When the last newer sample was read (`None` before the first).
    last_fresh: Option<Instant>,
    /// The wall-clock period of the robot's samples: 2 ms, or 2 ms / speedup on the emulator.
    period: Duration,
    /// The in-process emulator behind it, for its servo statistics (`None`: a real robot).
    emulator: Option<Arc<Emulator>>,
    /// How the RTDE client's I/O threads are scheduled (their first start says).
    io_scheduling: IoScheduling,
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
        emulator: Option<Arc<Emulator>>,
        period: Duration,
        io_scheduling: IoScheduling,
    ) -> Self {
        Self {
            robot,
            last_ts: f64::NEG_INFINITY,
            last_fresh: None,
            period,
            emulator,
            io_scheduling,
        }
    }
}

impl Robot for PacedRtde {
    /// The newest sample if its timestamp is newer than the last one returned; else waits for
    /// the next one until it is a period overdue ([`sample_wait`]), and then returns the
    /// previous state again.
    ///
    /// # Implementation
    /// Never allocates, and returns by [`sample_wait`]'s wait (at most 4 ms) plus one OS nap's
    /// overshoot, on success and on error ([`paced_read`]: polling, no lock held by another
    /// thread, no tokio). While the link is down it errors with `LinkDown` after the same wait
    /// (so a loop polling it runs at about the control rate).
    fn read_state(&mut self, out: &mut RobotState) -> robot_io::Result<()> {
        let call = Instant::now();
        let wait = sample_wait(call, self.last_fresh, self.period);
        let before = self.last_ts;
        let r = paced_read(
            &mut RtdeSource(&mut self.robot),
            &mut self.last_ts,
            out,
            wait,
        );
        if self.last_ts > before {
            self.last_fresh = Some(Instant::now());
        }
        r
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
    fn io_scheduling(&self) -> Option<Scheduling> {
        self.io_scheduling.get().cloned()
    }
    fn emulator_clock_scheduling(&self) -> Option<Scheduling> {
        self.emulator.as_ref().and_then(|e| e.clock_scheduling())
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
    /// Keeps `emulator` (if any) and `rt` alive until [`RtdeGuard::close`].
    #[cfg(feature = "ur-rtde")]
    pub(crate) fn new(emulator: Option<Arc<Emulator>>, rt: tokio::runtime::Runtime) -> Self {
        Self { emulator, rt }
    }

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

/// How the RTDE runtime's threads came up: the outcome of the first thread's request (every
/// thread asks for the same priority).
pub(crate) type IoScheduling = Arc<OnceLock<Scheduling>>;

/// The tokio runtime of the RTDE client (and of the in-process emulator's servers): two
/// workers, each put under `SCHED_FIFO` at `io_priority` when it starts (ur_rtde runs its
/// receive thread so), or left at normal priority with the reason in the returned record.
pub(crate) fn rtde_runtime(
    io_priority: Option<RtPriority>,
) -> crate::Result<(tokio::runtime::Runtime, IoScheduling)> {
    let outcome: IoScheduling = Arc::new(OnceLock::new());
    let record = Arc::clone(&outcome);
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .on_thread_start(move || {
            let got = robot_io::realtime::set_current_thread_opt(io_priority);
            if record.set(got.clone()).is_ok() {
                super::priority::warn_if_refused("the RTDE I/O threads", &got);
            }
        })
        .build()
        .map(|rt| (rt, outcome))
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
/// connects to it. Sped up, its clock waits for a late servo command as `emulator` says
/// (`[emulator] wait_for_client_ms`).
pub(crate) fn start_emulator(
    home_q: [f64; 6],
    speedup: u32,
    realtime: RealtimeConfig,
    emulator: EmulatorSection,
) -> crate::Result<(PacedRtde, RtdeGuard)> {
    let asked = [
        realtime.control(),
        realtime.rtde_io(),
        realtime.emulator_clock(),
    ];
    if speedup > 1 && asked.iter().any(Option::is_some) {
        tracing::warn!(
            "[realtime] priorities with the emulator at speedup {speedup}: its real-time \
             threads can take every core and starve the cue cycle (the robot then stops for \
             stale perception, SAF-REQ-008); they are meant for speedup 1"
        );
    }
    let (rt, io_scheduling) = rtde_runtime(realtime.rtde_io())?;
    let (emulator, robot) = rt.block_on(async {
        let sim = SimRobot::new(SimConfig {
            initial_q_rad: home_q,
            ..SimConfig::ur5e()
        })?;
        let emu = Emulator::start(
            EmulatorConfig {
                speedup,
                clock_priority: realtime.emulator_clock(),
                wait_for_client: emulator.wait_for_client(speedup),
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
    let robot = PacedRtde::new(
        robot,
        Some(Arc::clone(&emulator)),
        UR_PERIOD / speedup.max(1),
        io_scheduling,
    );
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
    realtime: RealtimeConfig,
    stop: &AtomicBool,
) -> crate::Result<(PacedRtde, RtdeGuard)> {
    let (rt, io_scheduling) = rtde_runtime(realtime.rtde_io())?;
    check_and_confirm(&rt, host, ports, stop)?;
    let robot = rt.block_on(connect(
        host,
        ports.rtde,
        ports.script,
        RegisterMap::default(),
    ))?;
    let robot = PacedRtde::new(robot, None, UR_PERIOD, io_scheduling);
    Ok((robot, RtdeGuard { emulator: None, rt }))
}

/// The dashboard checks before a real UR5e moves (remote control, normal safety status,
/// printed), then the operator's `yes` on stdin (Ctrl-C there ends as `interrupted`).
pub(crate) fn check_and_confirm(
    rt: &tokio::runtime::Runtime,
    host: &str,
    ports: UrPorts,
    stop: &AtomicBool,
) -> crate::Result<()> {
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
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::borrow::Cow;

    /// A scripted controller link on a scripted clock: samples become readable at given
    /// times, the link is down over given intervals, each read costs time and each nap
    /// overshoots by a given amount.
    #[derive(Debug)]
    struct Script {
        base: Instant,
        now: Duration,
        /// (readable from [µs], controller timestamp [s]), in time order.
        samples: Vec<(u64, f64)>,
        /// Link down over [from, to) [µs].
        down: Vec<(u64, u64)>,
        read_cost_us: Vec<u64>,
        overshoot_us: Vec<u64>,
        reads: usize,
        naps: Vec<Duration>,
        /// The state a read gives before any sample of the script (the previous one).
        previous_ts: f64,
    }

    impl Script {
        fn at_us(&self) -> u64 {
            u64::try_from(self.now.as_micros()).unwrap_or(u64::MAX)
        }
    }

    impl SampleSource for Script {
        fn now(&self) -> Instant {
            self.base + self.now
        }
        fn read(&mut self, out: &mut RobotState) -> robot_io::Result<()> {
            let t = self.at_us();
            let cost = self.read_cost_us[self.reads % self.read_cost_us.len()];
            self.reads += 1;
            self.now += Duration::from_micros(cost);
            if self.down.iter().any(|&(a, b)| (a..b).contains(&t)) {
                return Err(robot_io::RobotIoError::LinkDown {
                    reason: Cow::Borrowed("scripted"),
                });
            }
            out.timestamp_s = self
                .samples
                .iter()
                .take_while(|(from, _)| *from <= t)
                .last()
                .map_or(self.previous_ts, |&(_, ts)| ts);
            Ok(())
        }
        fn nap(&mut self, d: Duration) {
            self.naps.push(d);
            let over = self.overshoot_us[self.naps.len() % self.overshoot_us.len()];
            self.now += d + Duration::from_micros(over);
        }
    }

    fn script() -> impl Strategy<Value = Script> {
        (
            proptest::collection::vec(0u64..5_000, 0..6),
            proptest::collection::vec((0u64..5_000, 0u64..3_000), 0..3),
            proptest::collection::vec(0u64..80, 1..8),
            proptest::collection::vec(0u64..400, 1..8),
        )
            .prop_map(|(mut at, down, read_cost_us, overshoot_us)| {
                at.sort_unstable();
                Script {
                    base: Instant::now(),
                    now: Duration::ZERO,
                    samples: at
                        .into_iter()
                        .enumerate()
                        .map(|(i, t)| (t, 1.0 + 0.002 * i as f64))
                        .collect(),
                    down: down.into_iter().map(|(a, len)| (a, a + len)).collect(),
                    read_cost_us,
                    overshoot_us,
                    reads: 0,
                    naps: Vec::new(),
                    previous_ts: 1.0 - 0.002,
                }
            })
    }

    proptest! {
        /// The wait's bound (issue 10: the control cycle never blocks longer than one
        /// cycle): `paced_read` returns by the deadline + the longer of one nap's overshoot
        /// and one read, + one read,
        /// never naps longer than POLL_NAP, returns a sample that was readable (link up)
        /// at the deadline, and otherwise returns only once the whole wait has passed.
        #[test]
        fn paced_read_returns_by_the_deadline_and_never_misses_a_sample_that_came_before_it(
            mut s in script(),
        ) {
            let wait = SAMPLE_WAIT;
            let wait_us = u64::try_from(wait.as_micros()).unwrap();
            let mut last_ts = s.previous_ts;
            let mut out = RobotState { timestamp_s: s.previous_ts, ..RobotState::default() };
            let r = paced_read(&mut s, &mut last_ts, &mut out, wait);
            let elapsed = s.now;
            let max_over = *s.overshoot_us.iter().max().unwrap();
            let max_cost = *s.read_cost_us.iter().max().unwrap();
            prop_assert!(elapsed <= wait + Duration::from_micros(max_over.max(max_cost) + max_cost),
                "returned after {elapsed:?}");
            prop_assert!(s.naps.iter().all(|n| *n <= POLL_NAP));
            let fresh = r.is_ok() && out.timestamp_s > s.previous_ts;
            if fresh {
                prop_assert_eq!(last_ts, out.timestamp_s);
            } else {
                prop_assert_eq!(last_ts, s.previous_ts);
                prop_assert!(elapsed >= wait, "gave up after {elapsed:?}");
                // Nothing was readable at the deadline: no sample by then, or the link down.
                let came = s.samples.first().is_some_and(|(t, _)| *t <= wait_us);
                let down_at_end = s.down.iter().any(|&(a, b)| a < b && b > wait_us);
                prop_assert!(!came || down_at_end || r.is_err(),
                    "a sample readable before the deadline was not returned: {r:?}");
            }
            if r.is_err() {
                prop_assert!(elapsed >= wait, "an error came early, after {elapsed:?}");
            }
        }
    }

    /// Worked example, by hand: samples every 2 ms (speedup 1), the last read at 10.0 ms.
    /// Called at 10.2 ms, it waits until 14.0 ms (3.8 ms: the next sample is due at 12.0 ms
    /// and a period overdue at 14.0); called at 13.5 ms, the 2 ms floor (until 15.5 ms). At
    /// speedup 4 (0.5 ms) the overdue point is 11.0 ms: the floor again. Before any sample:
    /// the floor.
    #[test]
    fn sample_wait_worked_example() {
        let t0 = Instant::now();
        let ms = |x: f64| t0 + Duration::from_secs_f64(x * 1e-3);
        let p1 = UR_PERIOD;
        let p4 = UR_PERIOD / 4;
        let close = |a: Duration, b: f64| (a.as_secs_f64() - b * 1e-3).abs() < 1e-9;
        assert!(close(sample_wait(ms(10.2), Some(ms(10.0)), p1), 3.8));
        assert!(close(sample_wait(ms(13.5), Some(ms(10.0)), p1), 2.0));
        assert!(close(sample_wait(ms(10.2), Some(ms(10.0)), p4), 2.0));
        assert_eq!(sample_wait(ms(10.2), None, p1), SAMPLE_WAIT);
    }

    proptest! {
        /// The wait ends no earlier than SAMPLE_WAIT after the call and no later than the
        /// later of that and two periods after the last sample: never more than 4 ms on a
        /// real controller's period.
        #[test]
        fn sample_wait_is_bounded(
            since_us in 0u64..20_000,
            period_us in 100u64..=2_000,
        ) {
            let last = Instant::now();
            let call = last + Duration::from_micros(since_us);
            let period = Duration::from_micros(period_us);
            let w = sample_wait(call, Some(last), period);
            prop_assert!(w >= SAMPLE_WAIT);
            prop_assert!(w <= SAMPLE_WAIT.max(2 * period));
            prop_assert!(w <= Duration::from_millis(4));
            prop_assert!(call + w >= last + 2 * period || w == SAMPLE_WAIT);
        }
    }

    /// Worked example: samples 2 ms apart arrive at 0.3 ms and 2.3 ms; one read costs 10 µs,
    /// naps overshoot 20 µs. The first call polls until 0.3 ms and returns that sample; the
    /// second polls on until the 2.3 ms one; a third, with none to come, returns the previous
    /// state again at 2.31 + 2 ms + at most one overshoot and one read.
    #[test]
    fn paced_read_worked_example() {
        let mut s = Script {
            base: Instant::now(),
            now: Duration::ZERO,
            samples: vec![(300, 1.000), (2_300, 1.002)],
            down: vec![],
            read_cost_us: vec![10],
            overshoot_us: vec![20],
            reads: 0,
            naps: Vec::new(),
            previous_ts: 0.998,
        };
        let mut last = 0.998;
        let mut out = RobotState::default();
        paced_read(&mut s, &mut last, &mut out, SAMPLE_WAIT).unwrap();
        assert_eq!(out.timestamp_s, 1.000);
        // Reads at 0, 80, 160, 240, 320 µs (10 µs read + 50 µs nap + 20 µs overshoot).
        assert_eq!(s.now, Duration::from_micros(330));
        paced_read(&mut s, &mut last, &mut out, SAMPLE_WAIT).unwrap();
        assert_eq!(out.timestamp_s, 1.002);
        let t2 = s.now;
        assert!(t2 >= Duration::from_micros(2_310) && t2 <= Duration::from_micros(2_390));
        paced_read(&mut s, &mut last, &mut out, SAMPLE_WAIT).unwrap();
        assert_eq!(out.timestamp_s, 1.002, "the previous state again");
        assert!(s.now >= t2 + SAMPLE_WAIT);
        assert!(s.now <= t2 + SAMPLE_WAIT + Duration::from_micros(30));
    }

    /// Worked example, by hand (the case CI's proptest found): the one sample becomes
    /// readable at 1.97 ms and reads cost 68 µs, naps overshoot 300 µs. Reads start at 0,
    /// 418, 836, 1254, 1672 µs; the one at 1672 µs ends at 1740, the nap ends at
    /// 1740 + 50 + 300 = 2090 µs, past the 2 ms deadline, and the read that starts there sees
    /// the sample. A read that starts before the sample and ends after the deadline is
    /// followed by one more at once.
    #[test]
    fn a_sample_readable_before_the_deadline_is_returned_when_a_read_crosses_it() {
        let script = |overshoot: u64, first_read_at: u64| Script {
            base: Instant::now(),
            now: Duration::from_micros(first_read_at),
            samples: vec![(1_970, 1.000)],
            down: vec![],
            read_cost_us: vec![68],
            overshoot_us: vec![overshoot],
            reads: 0,
            naps: Vec::new(),
            previous_ts: 0.998,
        };
        let mut s = script(300, 0);
        let (mut last, mut out) = (0.998, RobotState::default());
        paced_read(&mut s, &mut last, &mut out, SAMPLE_WAIT).unwrap();
        assert_eq!(out.timestamp_s, 1.000);
        assert_eq!(s.reads, 6);
        assert_eq!(s.now, Duration::from_micros(2_090 + 68));
        // Called at 1950 µs with a 30 µs wait (deadline 1980 µs): the first read runs over
        // [1950, 2018) µs and misses the sample of 1970 µs; the second starts at once, at
        // 2018 µs, and returns it.
        let mut s2 = script(0, 1_950);
        let (mut last, mut out) = (0.998, RobotState::default());
        paced_read(&mut s2, &mut last, &mut out, Duration::from_micros(30)).unwrap();
        assert_eq!(
            out.timestamp_s, 1.000,
            "the read after the crossing one sees the sample"
        );
        assert_eq!(s2.reads, 2);
        assert!(
            s2.naps.is_empty(),
            "no nap after a read that ended past the deadline"
        );
    }

    /// The real client behind `read_state`, with the tokio runtime that runs the client's
    /// reader and writer tasks stuck (both workers blocked, as when the OS does not run
    /// them): `read_state` still returns, with the previous state, each time. The channel's
    /// 30 s timeout only detects a hang (the old `block_on(wait_state)` waited on a tokio
    /// timer that a stuck runtime never fires); it is not a speed check.
    #[test]
    fn read_state_returns_while_the_tokio_runtime_is_stuck() {
        let home = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0];
        let (mut robot, guard) = start_emulator(
            home,
            1,
            RealtimeConfig::default(),
            EmulatorSection::default(),
        )
        .expect("emulator");
        let mut s = RobotState::default();
        robot.read_state(&mut s).expect("a first state");
        let before = s.timestamp_s;
        // Block both workers of the runtime.
        let (release_tx, release_rx) = std::sync::mpsc::channel::<()>();
        let release_rx = Arc::new(std::sync::Mutex::new(release_rx));
        let (running_tx, running_rx) = std::sync::mpsc::channel();
        for _ in 0..2 {
            let (rx, running) = (Arc::clone(&release_rx), running_tx.clone());
            guard.rt.spawn(async move {
                running.send(()).expect("test alive");
                let _ = rx.lock().map(|r| r.recv());
            });
        }
        // The second task can hold the receiver's lock only after the first released it,
        // so it blocks on the lock: either way both workers are blocked.
        for _ in 0..2 {
            running_rx
                .recv_timeout(Duration::from_secs(30))
                .expect("a blocking task started");
        }
        let (tx, rx) = std::sync::mpsc::channel();
        let reader = std::thread::spawn(move || {
            let mut s = RobotState::default();
            for _ in 0..20 {
                let r = robot.read_state(&mut s).map(|()| s.timestamp_s);
                tx.send(r.map_err(|e| e.to_string())).expect("test alive");
            }
            robot
        });
        let mut last = before;
        for i in 0..20 {
            let r = rx
                .recv_timeout(Duration::from_secs(30))
                .unwrap_or_else(|_| panic!("read_state hung on call {i} with the runtime stuck"));
            // At most the samples the reader task had queued before it stopped; then the
            // previous state again.
            last = r.expect("the link is not down, only its tasks are stuck");
        }
        let stale_at_end = last;
        drop(release_tx);
        let robot = reader.join().expect("reader");
        drop(robot);
        assert!(stale_at_end >= before);
        guard.close();
    }
}
