//! The trial runtime: operator cues (30 Hz) → `Assessor` → policy → `Controller` (500 Hz) →
//! `Supervisor` → robot, as two cycles:
//! - the **control cycle** (`control.rs`, [`ControlCycle`]): read → controller → supervisor →
//!   send → log ring, in [`control_loop`] with the time keeping, the link outage handling, the
//!   handover scheduling and the stuck watch;
//! - the **cue cycle** (`cue_cycle.rs`, [`CueCycle`]): an [`OperatorSource`] (simulated,
//!   recorded or live) → assessor → policy.
//!
//! They meet through a [`CueLink`], one of two:
//! - **lockstep on the mock clock** (`--robot sim`, [`InlineCues`]): one thread; the cue frame
//!   due at a cycle runs inside it. Time is the cycle count × 2 ms and nothing reads the wall
//!   clock, so a trial is deterministic for its seed and config and runs as fast as the CPU
//!   allows.
//! - **threads in real time** (an RTDE robot, `backend.rs`: the emulator or a UR5e;
//!   `threaded`): the control loop runs on a `control` thread paced by the robot's clock (one
//!   cycle per controller sample, the controller's time as trial time; not deterministic), the
//!   cue cycle and the trial log on the caller's thread. They exchange the robot snapshot and
//!   the cue output through wait-free triple buffers, and the control cycle's log records
//!   through a wait-free ring ([`ControlLog`]) that the cue thread absorbs. The control thread
//!   neither waits for the cue thread nor allocates (`control_tests.rs`).
//!
//! After the loop, the one exit path: the control loop stops the robot through the supervisor,
//! the operator source is finished, every log is finished with the reason.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use adapt::controller::{
    Controller, ControllerConfig, MotionAdaptation, RawHandoverFile, SmoothnessScale, SpeedScale,
};
use adapt::envelope::SafetyEnvelope;
use adapt::task::Phase;
use assess::{AssessConfig, Assessor, RobotContext, Workspace};
use policies::{Adaptation, PolicyKind, RuleTable, TaskPhase};
use robot_io::geometry::HumanBody;
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Robot, RobotState};
use safety::{CatchUpCycles, Supervisor, SupervisorConfig, Verdict, Violation, WorldView};

use super::backend::UrPorts;
use super::config::TrialConfig;
use super::control::{ControlCycle, CycleInput, CycleOutput};
use super::cue_cycle::{CueCycle, CueOutput, OperatorSource};
use super::cues::{CueSource, RecordedCues};
use super::events::TrialEvent;
#[cfg(feature = "vision")]
use super::live::LiveCues;
use super::log::{ControlLog, ControlLogReader, ControlSink, LogOptions, TrialLog, TrialMeta};
use super::operator::{Level, RobotView, SimulatedOperator};
use crate::Error;
use crate::error::ResultExt as _;

/// Control period [s] (UR5e).
const CYCLE_S: f64 = 0.002;

/// Everything that defines one simulated trial.
#[derive(Debug, Clone)]
pub struct TrialSpec {
    /// Participant id (folder name and summary).
    pub participant: String,
    /// Task complexity level.
    pub condition: Level,
    /// Policy.
    pub policy: PolicyKind,
    /// Seed of the simulated operator.
    pub seed: u64,
    /// The trial configuration.
    pub config: TrialConfig,
}

/// A `SimRobot` advanced one 2 ms cycle by each `read_state` (the mock clock): read → decide →
/// send → (next read advances the model).
#[derive(Debug)]
pub(crate) struct LockstepSim {
    sim: SimRobot,
    first: bool,
}

impl Robot for LockstepSim {
    fn read_state(&mut self, out: &mut RobotState) -> robot_io::Result<()> {
        if !self.first {
            self.sim.step();
        }
        self.first = false;
        self.sim.read_state(out)
    }

    fn send(&mut self, cmd: &JointCommand) -> robot_io::Result<()> {
        self.sim.send(cmd)
    }
}

pub(super) fn task_phase(p: Phase) -> TaskPhase {
    match p {
        Phase::Idle => TaskPhase::Idle,
        Phase::Fetch => TaskPhase::Fetch,
        Phase::WaitForAttention => TaskPhase::WaitForAttention,
        Phase::Approach => TaskPhase::Approach,
        Phase::Present => TaskPhase::Present,
        Phase::Release => TaskPhase::Release,
        Phase::Retreat => TaskPhase::Retreat,
        Phase::Done => TaskPhase::Done,
    }
}

/// The phase's name as [`TrialEvent::TaskPhase`] carries it (the variant name, which the
/// summary's robot-idle phases and the report's timeline colours match).
pub(crate) fn phase_name(p: Phase) -> &'static str {
    match p {
        Phase::Idle => "Idle",
        Phase::Fetch => "Fetch",
        Phase::WaitForAttention => "WaitForAttention",
        Phase::Approach => "Approach",
        Phase::Present => "Present",
        Phase::Release => "Release",
        Phase::Retreat => "Retreat",
        Phase::Done => "Done",
    }
}

/// Maps a policy's [`Adaptation`] onto adapt's inputs (the policies crate docs' mapping):
/// speed scale → speed scale; smoothness = min(acceleration scale, √jerk scale) (adapt scales
/// acceleration × s and jerk × s²); start delay; minimum approach duration; `gates_start()` →
/// wait-for-attention with `gate.clear` as "attention on the robot"; the present timeout.
///
/// The rule table bounds the timings to [0, `policies::MAX_TIMING_S`]; a timing outside that
/// (built in code, or NaN) cannot panic here: it fails closed to the longest delay and the
/// slowest approach, `MAX_TIMING_S` (issue 10).
pub(super) fn motion_adaptation(a: &Adaptation) -> MotionAdaptation {
    let smooth = a.acceleration_scale.get().min(a.jerk_scale.get().sqrt());
    let max = Duration::from_secs_f64(policies::MAX_TIMING_S);
    let bounded = |s: f64| match s {
        s if s <= 0.0 => Duration::ZERO,
        s => Duration::try_from_secs_f64(s).map_or(max, |d| d.min(max)),
    };
    MotionAdaptation {
        // A scale that does not map fails closed: slow and smooth, never full speed.
        speed_scale: SpeedScale::new(a.speed_scale.get()).unwrap_or(SpeedScale::CAUTIOUS),
        smoothness_scale: SmoothnessScale::new(smooth).unwrap_or(SmoothnessScale::CAUTIOUS),
        start_delay: bounded(a.timing.start_delay_s),
        min_approach_duration: bounded(a.timing.min_approach_duration_s),
        wait_for_attention: a.timing.gates_start(),
        attention_on_robot: a.gate.clear,
        // Not a safety matter (the part is held longer or shorter): a timeout that does not map
        // leaves the task's own.
        present_timeout: a.timing.present_timeout_s.filter(|s| *s > 0.0).map(bounded),
    }
}

/// Live values for the progress display.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Live {
    /// Trial time [s].
    pub(crate) t_s: f64,
    /// Windowed HRC-CWL [-].
    pub(crate) hrc_cwl: f64,
    /// Dominant indicator key.
    pub(crate) dominant: &'static str,
    /// Handovers completed.
    pub(crate) handovers_done: u32,
    /// Handovers planned.
    pub(crate) handovers: u32,
    /// While the robot link is lost and a resume is awaited: for how long [s] (wall time).
    pub(crate) link_down_s: Option<f64>,
}

/// The robot a trial runs on.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum RobotChoice {
    /// In-process `SimRobot` on the mock clock (deterministic).
    Sim,
    /// The controller emulator in-process over loopback RTDE, `speedup` cycles per 2 ms.
    Emulator {
        /// Controller cycles per 2 ms of wall time.
        speedup: u32,
    },
    /// The in-process emulator as above, on 127.0.0.1 with UR's ports, driven through
    /// ur_rtde (`--robot-backend ur_rtde`; needs the `ur-rtde` feature).
    EmulatorUrRtde {
        /// Controller cycles per 2 ms of wall time.
        speedup: u32,
    },
    /// A real UR5e (or `hrc-adapt emulate`) at this address through ur_rtde (UR's fixed
    /// ports; needs the `ur-rtde` feature).
    UrRtde {
        /// Host name or IP address.
        host: String,
    },
    /// A real UR5e (or `hrc-adapt emulate`) at this address.
    Ur {
        /// Host name or IP address.
        host: String,
        /// Its RTDE, dashboard and script ports.
        ports: UrPorts,
    },
}

impl RobotChoice {
    /// A UR5e at `host` on the standard ports (the live camera's tests).
    #[cfg(all(test, feature = "vision"))]
    pub(crate) fn ur(host: &str) -> Self {
        Self::Ur {
            host: host.to_owned(),
            ports: UrPorts::default(),
        }
    }
}

/// Where the loop's time comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Clock {
    /// Cycle count × 2 ms (the lockstep `SimRobot`).
    Mock,
    /// The controller timestamp of each new sample, from the first one; the controller's clock
    /// runs this many times as fast as the wall clock (the emulator's speedup; 1 for a robot).
    Controller(f64),
}

/// Wall-clock timing of the control cycle on a robot's clock (never on the mock clock, whose
/// trials stay deterministic): the latency from a sample's read to the command's send, and the
/// wake jitter — how far the wall time between two consecutive fresh samples' reads departs
/// from the controller time between them (scaled to wall time by the clock's rate), |Δwall −
/// Δts / rate|; a drifting emulator clock does not accumulate into it.
#[derive(Debug)]
struct CycleTimer {
    rate: f64,
    arrival: Instant,
    last_fresh: Option<(Instant, f64)>,
    jitter_s: Option<f64>,
}

impl CycleTimer {
    fn new(rate: f64) -> Self {
        Self {
            rate: if rate.is_finite() && rate > 0.0 {
                rate
            } else {
                1.0
            },
            arrival: Instant::now(),
            last_fresh: None,
            jitter_s: None,
        }
    }

    /// A sample with controller timestamp `ts` [s] was just read (`fresh`: a new one).
    fn arrived(&mut self, ts: f64, fresh: bool) {
        self.arrival = Instant::now();
        self.jitter_s = None;
        if !fresh || !ts.is_finite() {
            return;
        }
        if let Some((wall, last_ts)) = self.last_fresh {
            let wall_s = self.arrival.duration_since(wall).as_secs_f64();
            self.jitter_s = Some((wall_s - (ts - last_ts) / self.rate).abs());
        }
        self.last_fresh = Some((self.arrival, ts));
    }
}

/// Why a trial ended: `summary.json`'s `finish_reason`, the `Finished` event's reason. The
/// first three are normal endings (`Ok`, exit code 0); every other one is a [`TrialEnded`]
/// error with its own exit code ([`exit_code`]; the table is in the README, "Exit codes").
pub mod reason {
    /// Every handover done (the simulated operator finished its task).
    pub const COMPLETED: &str = "completed";
    /// `max_duration_s` of trial time reached.
    pub const MAX_DURATION: &str = "max_duration";
    /// The recorded cue file, or the live camera, ended.
    pub const CUES_ENDED: &str = "cues_ended";
    /// Ctrl-C (the stop flag).
    pub const INTERRUPTED: &str = "interrupted";
    /// No robot state for `[link] lost_after_s`, and no resume (disabled, or the link not back
    /// within `resume_within_s`).
    pub const LINK_LOST: &str = "link_lost";
    /// A motion phase made no progress toward its target for `[progress] stuck_after_s`.
    pub const TASK_IMPOSSIBLE: &str = "task_impossible";
    /// The robot's control program stopped (pendant, protective stop, watchdog).
    pub const ROBOT_PROGRAM_STOPPED: &str = "robot_program_stopped";
    /// An error inside the loop (a failed read, a log write, a panic, the camera failing).
    pub const ERROR: &str = "error";
}

/// The process exit code of a trial that ended with `reason` (README, "Exit codes").
pub fn exit_code(reason: &str) -> u8 {
    match reason {
        reason::COMPLETED | reason::MAX_DURATION | reason::CUES_ENDED => 0,
        reason::LINK_LOST => 3,
        reason::TASK_IMPOSSIBLE => 4,
        reason::ROBOT_PROGRAM_STOPPED => 5,
        reason::INTERRUPTED => 130,
        _ => 1,
    }
}

/// A trial that did not end normally (see [`reason`]): why, where its logs are (`None` if it
/// ended before the logs were opened, e.g. Ctrl-C at the confirmation prompt) and what went
/// wrong. Displayed as one line naming both; the cause is its `source`.
#[derive(Debug)]
pub struct TrialEnded {
    /// The `finish_reason`.
    pub reason: &'static str,
    /// The run folder, with its finished logs.
    pub dir: Option<PathBuf>,
    error: Box<Error>,
}

impl TrialEnded {
    /// A trial stopped before its logs were opened (nothing moved).
    pub fn before_start(reason: &'static str, error: Error) -> Self {
        Self {
            reason,
            dir: None,
            error: Box::new(error),
        }
    }

    /// The process exit code ([`exit_code`]).
    pub fn exit_code(&self) -> u8 {
        exit_code(self.reason)
    }
}

impl std::fmt::Display for TrialEnded {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.dir {
            Some(d) => write!(
                f,
                "trial ended: {} (robot stopped; logs in {})",
                self.reason,
                d.display()
            ),
            None => write!(f, "trial ended before it started: {}", self.reason),
        }
    }
}

impl std::error::Error for TrialEnded {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&*self.error)
    }
}

/// What the trial loop needs of its robot beyond [`Robot`].
pub(crate) trait TrialRobot: Robot + Send {
    /// Restarts the robot's control program without blocking (after a link loss its register
    /// watchdog may have stopped it); `false` when that is not possible now (not supported, or
    /// a restart is still under way). Called only while a resume is being waited for.
    fn restart_program(&self) -> bool {
        false
    }
    /// How long the robot extrapolates a servo target that is not refreshed [s], when it
    /// does (`None`: the UR5e program's default, or a robot that never misses a cycle). The
    /// planner's catch-up and the supervisor's servo period follow it
    /// ([`safety::CatchUpCycles::for_extrapolation`]).
    fn servo_extrapolation_s(&self) -> Option<f64> {
        None
    }
    /// What the robot side did with the servo commands (the in-process emulator counts it;
    /// `None` for other robots): written into `summary.json`'s `motion.robot_servo`.
    fn servo_stats(&self) -> Option<robot_io::emulator::ServoStats> {
        None
    }
    /// How the in-process emulator's own clock kept up with wall time (`None` for other
    /// robots): written into `summary.json`'s `motion.emulator_clock`.
    fn emulator_clock(&self) -> Option<robot_io::emulator::ClockStats> {
        None
    }
    /// How the RTDE client's I/O threads are scheduled (`None`: no such threads).
    fn io_scheduling(&self) -> Option<robot_io::realtime::Scheduling> {
        None
    }
    /// How the in-process emulator's clock thread is scheduled (`None`: no emulator, or its
    /// clock is a tokio task).
    fn emulator_clock_scheduling(&self) -> Option<robot_io::realtime::Scheduling> {
        None
    }
}

impl TrialRobot for LockstepSim {}

/// `first` with `then` added to its context, or `then` alone: the error of an ending that
/// went wrong more than once.
fn chain(first: Option<Error>, then: Error) -> Error {
    match first {
        Some(f) => f.context(then.with_causes().to_string()),
        None => then,
    }
}

/// Joint distance [rad] under which a motion phase counts as at its target (settling, or
/// gripping at the pick pose), never stuck.
const AT_TARGET_RAD: f64 = 0.01;
/// Progress toward the target [rad] that restarts the stuck timer.
const PROGRESS_RAD: f64 = 1e-3;

/// Detects a task that cannot be done: in a motion phase (Fetch, Approach, Retreat), the
/// robot gets no closer to the phase's target (by [`PROGRESS_RAD`], largest joint distance)
/// for `limit_s` of trial time while not at it. The cause named is the requirement the
/// supervisor intervened for most often meanwhile (the same stop repeating, e.g. SAF-REQ-007
/// for a hand held in the protective separation distance, or SAF-REQ-006 for a pose the
/// workspace limits refuse), else `trajectory` when the trajectory generator failed (an
/// unreachable target), else `no_progress` (the planner itself held the robot). Allocates
/// nothing.
#[derive(Debug, Clone)]
struct StuckWatch {
    limit_s: f64,
    phase: Phase,
    target: Option<[f64; 6]>,
    best_rad: f64,
    since_s: f64,
    otg_errors_since: u64,
    /// Interventions since `since_s`, by requirement id.
    interventions: [(&'static str, u64); 16],
}

/// What [`StuckWatch`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Stuck {
    /// The phase that made no progress.
    phase: Phase,
    /// How long [s].
    for_s: f64,
    /// The requirement, `trajectory` or `no_progress`.
    cause: &'static str,
    /// Interventions for that requirement meanwhile (0 for the other causes).
    interventions: u64,
}

impl StuckWatch {
    fn new(limit_s: f64) -> Self {
        Self {
            limit_s,
            phase: Phase::Idle,
            target: None,
            best_rad: f64::INFINITY,
            since_s: 0.0,
            otg_errors_since: 0,
            interventions: [("", 0); 16],
        }
    }

    fn restart(&mut self, t_s: f64, best_rad: f64, otg_errors: u64) {
        self.best_rad = best_rad;
        self.since_s = t_s;
        self.otg_errors_since = otg_errors;
        self.interventions = [("", 0); 16];
    }

    /// One cycle at trial time `t_s` [s]: the task `phase` and its `target` [rad], the
    /// measured joints `q` [rad], the requirement of this cycle's intervention (if any) and
    /// the controller's trajectory-error count.
    fn update(
        &mut self,
        t_s: f64,
        phase: Phase,
        target: Option<&[f64; 6]>,
        q: &[f64; 6],
        intervention: Option<&'static str>,
        otg_errors: u64,
    ) -> Option<Stuck> {
        let moving = matches!(phase, Phase::Fetch | Phase::Approach | Phase::Retreat);
        let d = target.map_or(0.0, |g| {
            g.iter()
                .zip(q)
                .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()))
        });
        if phase != self.phase || target.copied() != self.target {
            self.phase = phase;
            self.target = target.copied();
            self.restart(t_s, d, otg_errors);
            return None;
        }
        if !moving || target.is_none() || d <= AT_TARGET_RAD || d < self.best_rad - PROGRESS_RAD {
            self.restart(t_s, d.min(self.best_rad), otg_errors);
            return None;
        }
        if let Some(id) = intervention {
            let slot = self
                .interventions
                .iter()
                .position(|(r, _)| *r == id)
                .or_else(|| self.interventions.iter().position(|(r, _)| r.is_empty()));
            if let Some(slot) = slot.and_then(|i| self.interventions.get_mut(i)) {
                *slot = (id, slot.1 + 1);
            }
        }
        let for_s = t_s - self.since_s;
        if for_s < self.limit_s {
            return None;
        }
        let (cause, interventions) = match self.interventions.iter().max_by_key(|(_, n)| *n) {
            Some(&(id, n)) if n > 0 => (id, n),
            _ if otg_errors > self.otg_errors_since => ("trajectory", 0),
            _ => ("no_progress", 0),
        };
        Some(Stuck {
            phase,
            for_s,
            cause,
            interventions,
        })
    }
}

/// Run one simulated trial into `out_dir` (created), calling `progress` at the cue rate. Stops
/// early when `stop` becomes true (the robot is stopped through the supervisor, the logs are
/// closed). Returns the folder.
pub(crate) fn run_simulated_with(
    spec: &TrialSpec,
    out_dir: &Path,
    stop: &AtomicBool,
    progress: &mut dyn FnMut(&Live),
) -> crate::Result<PathBuf> {
    run_trial_with(spec, &RobotChoice::Sim, out_dir, stop, progress)
}

/// Run one trial on `robot` with the simulated operator (see [`run_simulated_with`]). `Sim`
/// runs on the mock clock; the RTDE robots run paced on the controller's timestamps
/// (`backend.rs`).
pub(crate) fn run_trial_with(
    spec: &TrialSpec,
    robot: &RobotChoice,
    out_dir: &Path,
    stop: &AtomicBool,
    progress: &mut dyn FnMut(&Live),
) -> crate::Result<PathBuf> {
    run_trial_with_cues(spec, robot, &CueSource::Simulated, out_dir, stop, progress)
}

/// Run one trial on `robot` with its cues from `cues` (see [`run_trial_with`] and the `cues`
/// module: a recorded file is replayed by time, sample-and-hold).
pub(crate) fn run_trial_with_cues(
    spec: &TrialSpec,
    robot: &RobotChoice,
    cues: &CueSource,
    out_dir: &Path,
    stop: &AtomicBool,
    progress: &mut dyn FnMut(&Live),
) -> crate::Result<PathBuf> {
    let setup = load_setup(spec, robot, cues, out_dir)?;
    let home = setup.ctl_cfg.task.home_q_rad;
    match robot {
        RobotChoice::Sim => {
            let sim = SimRobot::new(SimConfig {
                initial_q_rad: home,
                ..SimConfig::ur5e()
            })?;
            let robot = LockstepSim { sim, first: true };
            drive(
                spec,
                setup,
                robot,
                Clock::Mock,
                "sim",
                out_dir,
                stop,
                progress,
            )
        }
        RobotChoice::Emulator { speedup } => {
            let (robot, guard) = super::backend::start_emulator(
                home,
                *speedup,
                spec.config.realtime,
                spec.config.emulator,
            )?;
            let out = drive(
                spec,
                setup,
                robot,
                Clock::Controller(f64::from(*speedup)),
                "emulator",
                out_dir,
                stop,
                progress,
            );
            guard.close();
            out
        }
        #[cfg(feature = "ur-rtde")]
        RobotChoice::EmulatorUrRtde { speedup } => {
            let (robot, guard) = super::backend_ur_rtde::start_emulator(
                home,
                *speedup,
                spec.config.realtime,
                spec.config.emulator,
            )?;
            let out = drive(
                spec,
                setup,
                robot,
                Clock::Controller(f64::from(*speedup)),
                "emulator (ur_rtde)",
                out_dir,
                stop,
                progress,
            );
            guard.close();
            out
        }
        #[cfg(feature = "ur-rtde")]
        RobotChoice::UrRtde { host } => {
            let (robot, guard) = super::backend_ur_rtde::connect_ur(
                host,
                spec.config.realtime,
                spec.config.link.resume,
                stop,
            )?;
            let out = drive(
                spec,
                setup,
                robot,
                Clock::Controller(1.0),
                host,
                out_dir,
                stop,
                progress,
            );
            guard.close();
            out
        }
        #[cfg(not(feature = "ur-rtde"))]
        RobotChoice::EmulatorUrRtde { .. } | RobotChoice::UrRtde { .. } => {
            Err(super::no_ur_rtde_feature())
        }
        RobotChoice::Ur { host, ports } => {
            let (robot, guard) =
                super::backend::connect_ur(host, *ports, spec.config.realtime, stop)?;
            let out = drive(
                spec,
                setup,
                robot,
                Clock::Controller(1.0),
                host,
                out_dir,
                stop,
                progress,
            );
            guard.close();
            out
        }
    }
}

/// Loads everything the trial config names (and starts a live camera) before the robot is
/// contacted.
fn load_setup(
    spec: &TrialSpec,
    robot: &RobotChoice,
    cues: &CueSource,
    out_dir: &Path,
) -> crate::Result<Setup> {
    // Without a camera front-end, the robot and the run folder matter only to a live camera.
    #[cfg(not(feature = "vision"))]
    let _ = (robot, out_dir);
    let cfg = &spec.config;
    let recorded = match cues {
        CueSource::Recorded(p) => Some(RecordedCues::load(p)?),
        CueSource::Simulated | CueSource::Camera(_) => None,
    };
    let workspace = Workspace::from_toml_file(&cfg.workspace)
        .with_context(|| format!("workspace {}", cfg.workspace.display()))?;
    let live = match cues {
        #[cfg(feature = "vision")]
        CueSource::Camera(spec) => {
            let spec = super::cues::CameraSpec {
                require_depth: spec.require_depth
                    || matches!(robot, RobotChoice::Ur { .. } | RobotChoice::UrRtde { .. }),
                station: workspace.station().copied(),
                ..spec.clone()
            };
            Some(LiveCues::start(&spec, out_dir)?)
        }
        #[cfg(not(feature = "vision"))]
        CueSource::Camera(spec) => return Err(crate::vision_cmd::vision_missing(&spec.input)),
        CueSource::Simulated | CueSource::Recorded(_) => None,
    };
    let assess_cfg = match &cfg.assess {
        Some(p) => AssessConfig::from_toml_file(p).map_err(|e| Error::from(e).in_file(p))?,
        None => AssessConfig::default(),
    };
    let raw: RawHandoverFile = toml::from_str(
        &std::fs::read_to_string(&cfg.controller).map_err(Error::io("read", &cfg.controller))?,
    )
    .map_err(Error::toml(cfg.controller.display()))?;
    let ctl_cfg = ControllerConfig::try_from(&raw.controller)?;
    super::config::check_task_poses(
        &ctl_cfg.task,
        &SupervisorConfig::ur5e().workspace,
        &cfg.controller,
    )?;
    let table = RuleTable::from_toml_file(&cfg.policy_table)?;
    Ok(Setup {
        workspace,
        assess_cfg,
        ctl_cfg,
        table,
        recorded,
        live,
    })
}

/// Everything loaded from the trial config before the robot is chosen.
struct Setup {
    workspace: Workspace,
    assess_cfg: AssessConfig,
    ctl_cfg: ControllerConfig,
    table: RuleTable,
    /// The recorded cue file replayed instead of the simulated operator's cues.
    recorded: Option<RecordedCues>,
    /// The live camera used instead of the simulated operator's cues.
    live: Option<LiveCues>,
}

/// Without the `vision` feature there is no live source (the type is never built).
#[cfg(not(feature = "vision"))]
#[derive(Debug)]
enum LiveCues {}

#[cfg(not(feature = "vision"))]
impl OperatorSource for LiveCues {
    fn label(&self) -> Option<&str> {
        match *self {}
    }
    fn simulated(&self) -> bool {
        match *self {}
    }
    fn frame(
        &mut self,
        _tc: f64,
        _robot: &RobotView,
        _frame: &mut assess::CueFrame,
        _log: &mut TrialLog,
    ) -> crate::Result<Option<f64>> {
        match *self {}
    }
}

/// The trial loop on any robot.
#[allow(clippy::too_many_arguments)]
fn drive<R: TrialRobot>(
    spec: &TrialSpec,
    setup: Setup,
    robot: R,
    clock: Clock,
    robot_label: &str,
    out_dir: &Path,
    stop: &AtomicBool,
    progress: &mut dyn FnMut(&Live),
) -> crate::Result<PathBuf> {
    let cfg = &spec.config;
    let Setup {
        workspace,
        assess_cfg,
        ctl_cfg,
        table,
        recorded,
        live: camera,
    } = setup;
    // The simulated operator's task parameters set the schedule, whoever the operator is.
    let response = cfg.operator.response;
    let operator = SimulatedOperator::new(spec.condition, &workspace, spec.seed, response)?;
    // The operator is simulated only when no recorded or live cues replace it.
    let source: Box<dyn OperatorSource> = match (recorded, camera) {
        (Some(r), _) => Box::new(r),
        (None, Some(l)) => Box::new(l),
        (None, None) => Box::new(SimulatedOperator::new(
            spec.condition,
            &workspace,
            spec.seed,
            response,
        )?),
    };
    let simulated = source.simulated();
    let cue_source = source.label().map(str::to_owned);
    let mut cue = CueCycle::new(
        source,
        Assessor::new(workspace.clone(), assess_cfg.clone())?,
        spec.policy.build(&table),
        workspace.clone(),
        cfg.frame,
    );
    let mut cc = control_cycle(robot, ctl_cfg)?;
    let meta = TrialMeta {
        participant: spec.participant.clone(),
        condition: spec.condition.as_str().to_owned(),
        policy: spec.policy.as_str().to_owned(),
        seed: spec.seed,
        // A recorded or live operator is not simulated (the robot may still be: see `robot`).
        simulated,
        cue_source,
        // Wall clock: only in trial.mcap's /trial/meta and the report, never in summary.json.
        started_utc: super::utc_now_iso(),
        robot: robot_label.to_owned(),
    };
    let mut log = TrialLog::create(
        out_dir,
        &meta,
        LogOptions {
            robot_full_rate: cfg.robot_full_rate,
            cwl_medium_from: assess_cfg.composite.medium_from,
            cwl_high_from: assess_cfg.composite.high_from,
            window_horizon_s: assess_cfg.window.horizon_s,
            ..LogOptions::default()
        },
    )?;

    let n_handovers = operator.params().handovers() as u32;
    // Nominal need time of part k, counted from the release of part k − 1 (from the start for
    // the first): segment k's work begins only once the operator holds the previous part, so
    // a schedule in absolute time runs ahead of the operator by every earlier handover's
    // duration (issue 14). The segment's nominal work with the expected excursion overhead;
    // the robot starts fetching `lead_time_s` earlier.
    let overhead = operator.params().overhead_factor();
    let need_after_release_s: Vec<f64> = operator.params().work_s[..n_handovers as usize]
        .iter()
        .map(|work| work * overhead)
        .collect();

    let plan = LoopPlan {
        cfg,
        clock,
        n_handovers,
        need_after_release_s,
        simulated,
        control_scheduling: std::sync::OnceLock::new(),
    };
    // --- The loop, then the one exit path: every ending comes here. ---
    // 1. The control loop ends by stopping the robot through the supervisor.
    let LoopEnd {
        mut reason,
        detail,
        mut failure,
        t_end,
    } = match clock {
        Clock::Mock => {
            let mut link = InlineCues {
                cue: &mut cue,
                runner: CueRunner::new(cfg.cue_rate_hz, n_handovers),
                progress,
            };
            control_loop(&plan, &mut cc, &mut log, &mut link, stop)
        }
        Clock::Controller(_) => threaded::run(&plan, &mut cc, &mut log, &mut cue, stop, progress),
    };
    // 2. The operator source: a camera's thread (an error or a panic there ended the cues:
    //    "cues_ended").
    if let Err(e) = cue.finish()
        && failure.is_none()
    {
        reason = reason::ERROR;
        failure = Some(e.context("the live camera failed"));
    }
    // 3. Every log, with the reason.
    if let Some(st) = cc.supervisor.robot().servo_stats() {
        log.set_robot_servo(st);
    }
    if let Some(st) = cc.supervisor.robot().emulator_clock() {
        log.set_emulator_clock(st);
    }
    if let Some(control) = plan.control_scheduling.get() {
        let robot = cc.supervisor.robot();
        log.set_scheduling(crate::trial::priority::SchedulingSummary {
            control: control.to_string(),
            rtde_io: robot.io_scheduling().map(|s| s.to_string()),
            emulator_clock: robot.emulator_clock_scheduling().map(|s| s.to_string()),
        });
    }
    let event = log.event(t_end, &TrialEvent::Finished { reason });
    let finished = log.finish();
    let dir = match event.and(finished) {
        Ok(files) if files.dropped_records > 0 => {
            // The control thread's log ring overflowed: the logs miss records (the motion
            // metrics included), so the trial's figures cannot be trusted.
            reason = reason::ERROR;
            failure = Some(Error::LogIncomplete {
                dropped: files.dropped_records,
                dir: files.dir.clone(),
            });
            files.dir
        }
        Ok(files) => files.dir,
        Err(e) => {
            let e = e.context(format!(
                "cannot finish the trial log in {}",
                out_dir.display()
            ));
            failure = Some(chain(failure.take(), e));
            reason = reason::ERROR;
            out_dir.to_path_buf()
        }
    };
    if exit_code(reason) == 0 && failure.is_none() {
        return Ok(dir);
    }
    let error = failure.unwrap_or_else(|| Error::Ending {
        why: detail.unwrap_or_else(|| match reason {
            reason::INTERRUPTED => "interrupted (Ctrl-C)".to_owned(),
            r => r.to_owned(),
        }),
    });
    Err(TrialEnded {
        reason,
        dir: Some(dir),
        error: Box::new(error),
    }
    .into())
}

/// What the control loop hands the exit path.
struct LoopEnd {
    reason: &'static str,
    detail: Option<String>,
    failure: Option<Error>,
    /// Trial time of the end [s].
    t_end: f64,
}

/// What the control loop needs that stays fixed for the trial.
struct LoopPlan<'a> {
    cfg: &'a TrialConfig,
    clock: Clock,
    n_handovers: u32,
    /// The operator's nominal need time of part k after the release of part k − 1 (after the
    /// trial's start for k = 0) [s]; the fetch starts `lead_time_s` before it.
    need_after_release_s: Vec<f64>,
    simulated: bool,
    /// How the control thread was scheduled (set by the threaded loop; unset on the mock
    /// clock, where no thread is spawned).
    control_scheduling: std::sync::OnceLock<robot_io::realtime::Scheduling>,
}

/// What the cue cycle sees of the robot, once per control cycle.
#[derive(Debug, Clone, Copy, Default)]
struct RobotSnapshot {
    /// Trial time [s].
    t_s: f64,
    view: RobotView,
    robot: RobotContext,
    /// Handovers completed.
    done: u32,
}

/// What a control cycle learns from the cue cycle.
// Returned by value each cycle on the real-time path: boxing the output would allocate.
#[allow(clippy::large_enum_variant)]
enum CueExchange {
    /// No new cue output since the last cycle.
    Nothing,
    /// A new cue output.
    New(CueOutput),
    /// The cues are over: `completed` (the work is done), `cues_ended`, or `error`.
    Ended(&'static str),
}

/// How the control loop meets the cue cycle: inline on the same thread (the mock clock: the
/// two cycles in lockstep, deterministic) or through single-slot handoffs with a cue thread of
/// its own (real time; [`ThreadedCues`]).
trait CueLink<L: ControlSink> {
    /// Called every control cycle after the state is read.
    fn exchange(&mut self, robot: &RobotSnapshot, log: &mut L) -> crate::Result<CueExchange>;
    /// The controller confirmed a release at `t_s` [s].
    fn released(&mut self, t_s: f64, log: &mut L) -> crate::Result<()>;
    /// The robot link is down for `down_s` [s] (`None`: back), for the progress display.
    fn link_down(&mut self, down_s: Option<f64>);
}

/// What both cue links share: the cue frames' schedule (frame n at trial time n / rate) and
/// the progress display.
struct CueRunner {
    /// Cue rate [frames/s].
    rate: f64,
    /// The next frame's number.
    next: u64,
    live: Live,
}

impl CueRunner {
    fn new(rate: f64, handovers: u32) -> Self {
        Self {
            rate,
            next: 0,
            live: Live {
                handovers,
                dominant: "none",
                ..Live::default()
            },
        }
    }

    /// Whether a cue frame is due at the snapshot's trial time.
    fn is_due(&self, robot: &RobotSnapshot) -> bool {
        // Frame n is due at cycle ceil(n / rate / 2 ms): integer test k·2ms·rate ≥ n.
        robot.t_s * self.rate + 1e-9 >= self.next as f64
    }

    /// Runs the cue frame due at the snapshot's trial time, if one is (one per call), and
    /// shows it: `Nothing` (none due), `New`, or `Ended` (`cues_ended`: the source ended;
    /// `completed`: the work is done).
    fn run_due(
        &mut self,
        cue: &mut CueCycle,
        robot: &RobotSnapshot,
        log: &mut TrialLog,
        progress: &mut dyn FnMut(&Live),
    ) -> crate::Result<CueExchange> {
        if !self.is_due(robot) {
            return Ok(CueExchange::Nothing);
        }
        let tc = self.next as f64 / self.rate;
        self.next += 1;
        let Some(out) = cue.step(tc, &robot.view, robot.robot, robot.view.phase, log)? else {
            return Ok(CueExchange::Ended(reason::CUES_ENDED));
        };
        self.live.t_s = tc;
        self.live.hrc_cwl = out.hrc_cwl;
        self.live.dominant = out.dominant;
        self.live.handovers_done = robot.done;
        progress(&self.live);
        if cue.source.finished(robot.done, self.live.handovers) {
            return Ok(CueExchange::Ended(reason::COMPLETED));
        }
        Ok(CueExchange::New(out))
    }

    /// Shows the link state when it changes (`None`: up).
    fn link_down(&mut self, down_s: Option<f64>, progress: &mut dyn FnMut(&Live)) {
        if down_s != self.live.link_down_s {
            self.live.link_down_s = down_s;
            progress(&self.live);
        }
    }
}

/// The cue cycle run inside the control cycle it falls in (the mock clock).
struct InlineCues<'a> {
    cue: &'a mut CueCycle,
    runner: CueRunner,
    progress: &'a mut dyn FnMut(&Live),
}

impl CueLink<TrialLog> for InlineCues<'_> {
    fn exchange(
        &mut self,
        robot: &RobotSnapshot,
        log: &mut TrialLog,
    ) -> crate::Result<CueExchange> {
        self.runner.run_due(self.cue, robot, log, self.progress)
    }

    fn released(&mut self, t_s: f64, log: &mut TrialLog) -> crate::Result<()> {
        self.cue.source.released(t_s, log)
    }

    fn link_down(&mut self, down_s: Option<f64>) {
        self.runner.link_down(down_s, self.progress);
    }
}

/// The 500 Hz loop: read → (cue link) → handover scheduling → controller → supervisor → send
/// → log, until the trial ends; then it stops the robot through the supervisor. Every `?` and
/// panic inside the loop ends it here, never in the caller, so the exit path always runs.
fn control_loop<R: TrialRobot, L: ControlSink, C: CueLink<L>>(
    plan: &LoopPlan<'_>,
    cc: &mut ControlCycle<R>,
    log: &mut L,
    link: &mut C,
    stop: &AtomicBool,
) -> LoopEnd {
    let cfg = plan.cfg;
    let clock = plan.clock;
    let n_handovers = plan.n_handovers;
    let need_after_release_s = &plan.need_after_release_s;
    let simulated = plan.simulated;
    let max_cycles = (cfg.max_duration_s / CYCLE_S).ceil() as u64;
    let mut motion = MotionAdaptation::default();
    let mut humans = HumanBody::default();
    let mut last_cue_t = 0.0;
    // Whether a cue output has arrived yet (handovers are armed only after it).
    let mut cue_seen = false;
    // When the last part was released [s] (0: none yet); the next need is counted from it.
    let mut last_release_t = 0.0;
    let mut started: u32 = 0; // handovers armed
    let mut done: u32 = 0; // handovers completed
    let mut prev_tcp_v = [0.0f64; 3];
    let mut peak_acc = 0.0f64;
    let mut reason = reason::MAX_DURATION;

    let mut k: u64 = 0;
    let mut t0: Option<f64> = None;
    let mut prev_t = 0.0;
    let mut t = 0.0;
    // Link loss (controller clock only; see "Link loss" in the module docs).
    let link_cfg = cfg.link;
    let mut last_ts = f64::NEG_INFINITY; // the newest robot timestamp seen
    let mut timer = match clock {
        Clock::Mock => None,
        Clock::Controller(rate) => Some(CycleTimer::new(rate)),
    };
    let mut outage: Option<Outage> = None;
    let mut stuck = StuckWatch::new(cfg.progress.stuck_after_s);
    // Why the trial ended, when the reason alone does not say it.
    let mut detail: Option<String> = None;
    let hold_cmd = JointCommand::Stop { decel: 3.0 };
    // The loop runs inside a closure (every `?` and panic leaves it, never `drive`), so the exit
    // path below always runs: stop the robot, close the camera, finish the logs.
    let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> crate::Result<()> {
        while k < max_cycles {
            if stop.load(Ordering::Relaxed) {
                reason = reason::INTERRUPTED;
                break;
            }
            // No new sample now: the supervisor keeps the previous state and counts the
            // missed cycle (SAF-REQ-009).
            let fresh = cc.read(last_ts).context("reading the robot state failed")?;
            // The newest sample shows our control program stopped (controller clock only).
            let mut program_stopped = false;
            if fresh {
                last_ts = cc.state.timestamp_s;
            }
            if let Some(timer) = timer.as_mut() {
                timer.arrived(cc.state.timestamp_s, fresh);
            }
            let dt = match clock {
                Clock::Mock => {
                    t = k as f64 * CYCLE_S;
                    CYCLE_S
                }
                Clock::Controller(_) => {
                    let now = Instant::now();
                    if fresh && matches!(cc.supervisor.latched(), Some(Violation::SendFailed)) {
                        // A send failed while the link was down (SAF-REQ-012); the link is back:
                        // the reset succeeds once a stop has been delivered since.
                        let _ = cc.supervisor.reset();
                    }
                    if !fresh && outage.is_none() {
                        outage = Some(Outage::new(now));
                    }
                    let mut resumed = false;
                    if let Some(o) = outage.as_mut() {
                        let down_s = now.duration_since(o.since).as_secs_f64();
                        if o.declared || down_s >= link_cfg.lost_after_s {
                            if !o.declared {
                                o.declared = true;
                                log.event(t, &TrialEvent::Link { up: false })?;
                                if !link_cfg.resume {
                                    reason = reason::LINK_LOST;
                                    detail = Some(format!(
                                        "no robot state for {down_s:.2} s at t = {t:.3} s (the \
                                     supervisor stopped the robot); resuming is off ([link] \
                                     resume = false)"
                                    ));
                                    break;
                                }
                            }
                            if down_s >= link_cfg.lost_after_s + link_cfg.resume_within_s {
                                reason = reason::LINK_LOST;
                                detail = Some(format!(
                                    "the robot link lost at t = {t:.3} s was not back within \
                                 [link] resume_within_s = {} s",
                                    link_cfg.resume_within_s
                                ));
                                break;
                            }
                            // The trial is paused: the supervisor holds the robot stopped.
                            cc.world.now_s = t;
                            let _ = cc.supervisor.step(&hold_cmd, &cc.world);
                            let playing =
                                cc.state.runtime_state == robot_io::runtime_state::PLAYING;
                            let at_rest = cc.state.actual_qd.iter().all(|v| v.abs() < REST_RAD_S);
                            if fresh && playing && at_rest && cc.supervisor.latched().is_none() {
                                resumed = true;
                            } else {
                                if fresh && !playing && o.restart_due(now) {
                                    // The controller's watchdog stopped our program meanwhile.
                                    cc.supervisor.robot().restart_program();
                                }
                                o.holds += 1;
                                if o.holds % 25 == 1 {
                                    link.link_down(Some(down_s));
                                }
                                continue;
                            }
                        } else if fresh {
                            // A hiccup shorter than a link loss: over.
                            outage = None;
                        }
                    }
                    if resumed {
                        // Back: trial time goes on from where it stopped, and the controller
                        // re-plans from the measured joints.
                        outage = None;
                        link.link_down(None);
                        t0 = Some(cc.state.timestamp_s - (prev_t + CYCLE_S));
                        cc.controller.command_overridden();
                        log.event(prev_t + CYCLE_S, &TrialEvent::Link { up: true })?;
                    }
                    let t_robot = cc.state.timestamp_s - *t0.get_or_insert(cc.state.timestamp_s);
                    t = if !fresh {
                        // A missed sample: this cycle runs on the held state at the predicted
                        // time; the supervisor stops the robot after 3 of them (SAF-REQ-009).
                        prev_t + CYCLE_S
                    } else if k == 0 {
                        t_robot
                    } else if t_robot < prev_t - CLOCK_RESTART_S {
                        // The robot's clock went back (a restarted controller): re-base.
                        t0 = Some(cc.state.timestamp_s - (prev_t + CYCLE_S));
                        prev_t + CYCLE_S
                    } else {
                        // The robot's time, but at least one cycle on (a late sample that a
                        // held cycle already ran for): the rule of the controller and the
                        // supervisor, so all three advance by the same time.
                        robot_io::cycle_time_s(prev_t, t_robot, CYCLE_S)
                    };
                    if t >= cfg.max_duration_s {
                        break;
                    }
                    if fresh && cc.state.runtime_state != robot_io::runtime_state::PLAYING {
                        // The control program stopped (watchdog, protective stop, pendant):
                        // nothing we send moves the robot any more. This cycle still goes
                        // through the supervisor, which judges the sample that shows it (a
                        // protective stop arrives with the paused program in one sample:
                        // SAF-REQ-010 is counted here), and the loop ends after it.
                        program_stopped = true;
                    }
                    (t - prev_t).max(CYCLE_S)
                }
            };
            prev_t = t;
            let v = &cc.state.actual_tcp_speed;
            let acc = ((v[0] - prev_tcp_v[0]).powi(2)
                + (v[1] - prev_tcp_v[1]).powi(2)
                + (v[2] - prev_tcp_v[2]).powi(2))
            .sqrt()
                / dt;
            if k > 0 {
                peak_acc = peak_acc.max(acc);
            }
            prev_tcp_v = [v[0], v[1], v[2]];

            // --- the cue cycle: inline (mock clock) or through the handoffs (real time) ---
            let p = &cc.state.actual_tcp_pose;
            let snapshot = RobotSnapshot {
                t_s: t,
                view: RobotView {
                    phase: cc.controller.phase(),
                    tcp_m: cfg.frame.to_workspace([p[0], p[1], p[2]]),
                    tcp_speed_m_s: (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt(),
                    tcp_peak_acc_m_s2: peak_acc,
                },
                robot: RobotContext {
                    collaborating: cc.controller.collaborating(),
                    incomplete: cc.controller.incomplete(),
                },
                done,
            };
            match link.exchange(&snapshot, log)? {
                CueExchange::Nothing => {}
                CueExchange::New(out) => {
                    cue_seen = true;
                    peak_acc = 0.0;
                    motion = out.motion;
                    humans = out.humans;
                    // A held recorded or camera frame is as old as its (mapped) time.
                    last_cue_t = out.cue_t_s;
                }
                CueExchange::Ended(why) => {
                    reason = why;
                    break;
                }
            }

            // --- handover scheduling ---
            // Nothing moves before the first cue output: until then the operator is unknown,
            // not absent (on the mock clock it arrives in the first cycle; on a control thread
            // a few milliseconds in).
            let phase = cc.controller.phase();
            if (phase == Phase::Idle || phase == Phase::Done)
                && cue_seen
                && started == done
                && started < n_handovers
                && t >= last_release_t + need_after_release_s[started as usize]
                    - cfg.lead_time_s
                    - if motion.wait_for_attention {
                        // Held until the operator is ready: staged early, outside the shared zone.
                        cfg.staged_lead_s
                    } else {
                        0.0
                    }
            {
                if phase == Phase::Done {
                    cc.controller.reset_task();
                }
                cc.controller.start_handover();
                started += 1;
            } else if phase == Phase::Done && cc.controller.task().part_returned() {
                // The part came back (present timeout): try the same handover again.
                cc.controller.reset_task();
                cc.controller.start_handover();
            }

            // --- 500 Hz: controller → supervisor → robot → log ring ---
            let input = CycleInput {
                t_s: t,
                fresh,
                humans,
                cue_t_s: last_cue_t,
                motion: &motion,
                started,
                done,
                simulated,
                missed: match clock {
                    Clock::Mock => 0,
                    Clock::Controller(_) => ((dt / CYCLE_S).round() as u32).saturating_sub(1),
                },
                read_at: timer.as_ref().map(|t| t.arrival),
                wake_jitter_s: timer.as_ref().and_then(|t| t.jitter_s),
            };
            let CycleOutput { verdict, released } = cc.act(&input, log)?;
            if released {
                link.released(t, log)?;
                done += 1;
                last_release_t = t;
            }
            if program_stopped {
                reason = reason::ROBOT_PROGRAM_STOPPED;
                let judged = verdict
                    .violation()
                    .map_or_else(|| "passed".to_string(), |v| v.to_string());
                detail = Some(format!(
                    "the robot's control program stopped at t = {t:.3} s (runtime state {}; \
                     the supervisor on that sample: {judged})",
                    cc.state.runtime_state
                ));
                break;
            }
            let intervention = match &verdict {
                Verdict::Passed => None,
                v => v.requirement().map(|r| r.id()),
            };
            if let Some(s) = stuck.update(
                t,
                cc.controller.phase(),
                cc.controller.task().target_q_rad(),
                &cc.state.actual_q,
                intervention,
                cc.controller.stats().otg_errors,
            ) {
                reason = reason::TASK_IMPOSSIBLE;
                detail = Some(s.describe(t));
                break;
            }
            k += 1;
        }
        Ok(())
    }));
    let mut failure: Option<Error> = match run {
        Ok(Ok(())) => None,
        Ok(Err(e)) => Some(e),
        Err(p) => Some(Error::panic("the trial loop", p.as_ref())),
    };
    if failure.is_some() {
        reason = reason::ERROR;
    }
    // Stop the robot through the supervisor.
    let t_end = match clock {
        Clock::Mock => k as f64 * CYCLE_S,
        Clock::Controller(_) => t + CYCLE_S,
    };
    let stopped = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        stop_robot(&mut cc.supervisor, &mut cc.state, &mut cc.world, t_end);
    }));
    if let Err(p) = stopped {
        let e = Error::panic("stopping the robot through the supervisor", p.as_ref());
        reason = reason::ERROR;
        failure = Some(chain(failure.take(), e));
    }
    LoopEnd {
        reason,
        detail,
        failure,
        t_end,
    }
}

/// The control loop on a thread of its own, the cue cycle on the caller's (real time).
///
/// - Control → cue: a [`RobotSnapshot`] each cycle (with the releases and the link state)
///   through a triple buffer: wait-free, the newest value wins.
/// - Cue → control: the newest [`CueOutput`] (and whether the cues are over), likewise.
/// - Control → log: the control cycle's records through a [`ControlLog`] (a wait-free ring),
///   drained into the trial log by the `log-writer` thread every [`WRITER_POLL_MS`], and by
///   the cue thread before each of its own log calls (both under one lock: the log stays in
///   time order, and the control thread never takes it).
///
/// The control thread never waits for the cue thread or the log and allocates nothing per
/// cycle; the cue thread polls every millisecond, runs the cue frames due at the robot's trial
/// time, as the inline link does on the mock clock, and takes the log only when it has
/// something to write.
mod threaded {
    use super::*;

    /// Control-rate records the ring holds [-]: 4 per cycle, ≈ 4 s of the control rate.
    const CONTROL_LOG_RECORDS: usize = 8192;
    /// How long the cue thread sleeps when nothing is due [ms].
    const CUE_POLL_MS: u64 = 1;
    /// How often the log-writer thread drains the ring [ms]: 10 ms is 20 records a cycle's
    /// worth at speedup 4, far from [`CONTROL_LOG_RECORDS`].
    const WRITER_POLL_MS: u64 = 10;

    #[derive(Debug, Clone, Copy, Default)]
    pub(super) struct ToCue {
        robot: RobotSnapshot,
        /// Releases confirmed so far, and the time of the last [s].
        released: u32,
        last_release_t_s: f64,
        link_down_s: Option<f64>,
        /// The control loop has ended (the robot is stopped).
        over: bool,
    }

    #[derive(Debug, Clone, Copy, Default)]
    pub(super) struct FromCue {
        /// Cue outputs published so far.
        frames: u64,
        out: Option<CueOutput>,
        /// The cues are over, and why.
        ended: Option<&'static str>,
    }

    /// The control loop's side of the handoffs.
    pub(super) struct ThreadedCues {
        to_cue: triple_buffer::Input<ToCue>,
        from_cue: triple_buffer::Output<FromCue>,
        mine: ToCue,
        seen_frames: u64,
    }

    impl CueLink<ControlLog> for ThreadedCues {
        fn exchange(
            &mut self,
            robot: &RobotSnapshot,
            _log: &mut ControlLog,
        ) -> crate::Result<CueExchange> {
            self.mine.robot = *robot;
            self.to_cue.write(self.mine);
            let from = *self.from_cue.read();
            if let Some(why) = from.ended {
                return Ok(CueExchange::Ended(why));
            }
            if from.frames > self.seen_frames {
                self.seen_frames = from.frames;
                if let Some(out) = from.out {
                    return Ok(CueExchange::New(out));
                }
            }
            Ok(CueExchange::Nothing)
        }

        fn released(&mut self, t_s: f64, _log: &mut ControlLog) -> crate::Result<()> {
            self.mine.released += 1;
            self.mine.last_release_t_s = t_s;
            self.to_cue.write(self.mine);
            Ok(())
        }

        fn link_down(&mut self, down_s: Option<f64>) {
            self.mine.link_down_s = down_s;
            self.to_cue.write(self.mine);
        }
    }

    /// The control loop's side of a fresh pair of handoffs, with the cue side's ends (tests).
    #[cfg(test)]
    pub(super) fn handoffs() -> (
        ThreadedCues,
        triple_buffer::Output<ToCue>,
        triple_buffer::Input<FromCue>,
    ) {
        let (to_cue, to_cue_out) = triple_buffer::triple_buffer(&ToCue::default());
        let (from_cue_in, from_cue) = triple_buffer::triple_buffer(&FromCue::default());
        let link = ThreadedCues {
            to_cue,
            from_cue,
            mine: ToCue::default(),
            seen_frames: 0,
        };
        (link, to_cue_out, from_cue_in)
    }

    /// The trial log and the reading end of the control thread's ring, shared by the
    /// log-writer thread (which drains the ring) and the cue thread (which drains it before
    /// each of its own log calls, so the log stays in time order).
    pub(super) struct LogSink<'a> {
        pub(super) log: &'a mut TrialLog,
        pub(super) reader: ControlLogReader,
    }

    impl LogSink<'_> {
        fn absorb(&mut self) -> crate::Result<()> {
            self.log.absorb(&mut self.reader)
        }
    }

    fn lock_sink<'a, 'b>(sink: &'a Mutex<LogSink<'b>>) -> MutexGuard<'a, LogSink<'b>> {
        // A panic while holding it is reported by the thread that panicked; the log itself
        // stays usable (every write is a whole record).
        sink.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The log-writer thread: drains the control thread's ring into the trial log every
    /// [`WRITER_POLL_MS`] (chunk compression and file writes happen here, off the control
    /// thread and off the cue cycle's frames) until `stop`, then once more.
    pub(super) fn log_writer(sink: &Mutex<LogSink<'_>>, stop: &AtomicBool) -> crate::Result<()> {
        crate::trial::priority::lower_this_thread();
        loop {
            let last = stop.load(Ordering::Acquire);
            lock_sink(sink).absorb()?;
            if last {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(WRITER_POLL_MS));
        }
    }

    pub(super) fn run<R: TrialRobot + Send>(
        plan: &LoopPlan<'_>,
        cc: &mut ControlCycle<R>,
        log: &mut TrialLog,
        cue: &mut CueCycle,
        stop: &AtomicBool,
        progress: &mut dyn FnMut(&Live),
    ) -> LoopEnd {
        let (to_cue_in, mut to_cue_out) = triple_buffer::triple_buffer(&ToCue::default());
        let (mut from_cue_in, from_cue_out) = triple_buffer::triple_buffer(&FromCue::default());
        let (mut control_log, reader) = ControlLog::new(CONTROL_LOG_RECORDS);
        let sink = Mutex::new(LogSink { log, reader });
        let writer_stop = AtomicBool::new(false);
        let failed_to_start = |name, source| LoopEnd {
            reason: reason::ERROR,
            detail: None,
            failure: Some(Error::Thread { name, source }),
            t_end: 0.0,
        };
        std::thread::scope(|scope| {
            let (sink, writer_stop) = (&sink, &writer_stop);
            let spawned = std::thread::Builder::new()
                .name("log-writer".into())
                .spawn_scoped(scope, move || {
                    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        log_writer(sink, writer_stop)
                    }))
                    .unwrap_or_else(|p| Err(Error::panic("the log-writer thread", p.as_ref())))
                });
            let writer = match spawned {
                Ok(handle) => handle,
                Err(e) => return failed_to_start("log-writer thread", e),
            };
            let spawned = std::thread::Builder::new()
                .name("control".into())
                .spawn_scoped(scope, move || {
                    crate::trial::priority::tighten_timer_slack();
                    let sched =
                        robot_io::realtime::set_current_thread_opt(plan.cfg.realtime.control());
                    crate::trial::priority::warn_if_refused("the control thread", &sched);
                    let _ = plan.control_scheduling.set(sched);
                    let mut link = ThreadedCues {
                        to_cue: to_cue_in,
                        from_cue: from_cue_out,
                        mine: ToCue::default(),
                        seen_frames: 0,
                    };
                    let end = control_loop(plan, cc, &mut control_log, &mut link, stop);
                    link.mine.over = true;
                    link.to_cue.write(link.mine);
                    end
                });
            let control = match spawned {
                Ok(handle) => handle,
                Err(e) => {
                    writer_stop.store(true, Ordering::Release);
                    return failed_to_start("control thread", e);
                }
            };
            let mut runner = CueRunner::new(plan.cfg.cue_rate_hz, plan.n_handovers);
            let cued =
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> crate::Result<()> {
                    let (mut frames, mut handled) = (0u64, 0u32);
                    let mut ended = false;
                    loop {
                        if writer.is_finished() {
                            // Its own error is chained in after the join, below.
                            return Err(Error::Internal {
                                reason: "the log-writer thread ended before the trial".into(),
                            });
                        }
                        let to = *to_cue_out.read();
                        // Over, or the control thread is gone without saying so (a panic
                        // outside its own catch): never wait for it.
                        if to.over || control.is_finished() {
                            return Ok(());
                        }
                        runner.link_down(to.link_down_s, progress);
                        let due = !ended && runner.is_due(&to.robot);
                        if !due && handled >= to.released {
                            std::thread::sleep(Duration::from_millis(CUE_POLL_MS));
                            continue;
                        }
                        // Something to log: the control thread's records first, so that the
                        // log stays in time order.
                        let mut guard = lock_sink(sink);
                        guard.absorb()?;
                        let log = &mut *guard.log;
                        while handled < to.released {
                            cue.source.released(to.last_release_t_s, log)?;
                            handled += 1;
                        }
                        let step = if due {
                            runner.run_due(cue, &to.robot, log, progress)?
                        } else {
                            CueExchange::Nothing
                        };
                        drop(guard);
                        match step {
                            CueExchange::Nothing => {
                                std::thread::sleep(Duration::from_millis(CUE_POLL_MS));
                            }
                            CueExchange::Ended(why) => {
                                ended = true;
                                from_cue_in.write(FromCue {
                                    frames,
                                    out: None,
                                    ended: Some(why),
                                });
                            }
                            CueExchange::New(out) => {
                                frames += 1;
                                from_cue_in.write(FromCue {
                                    frames,
                                    out: Some(out),
                                    ended: None,
                                });
                            }
                        }
                    }
                }));
            let cue_failure = match cued {
                Ok(Ok(())) => None,
                Ok(Err(e)) => Some(e.context("the cue cycle failed")),
                Err(p) => Some(Error::panic("the cue cycle", p.as_ref())),
            };
            if cue_failure.is_some() {
                // End the control loop (it stops the robot), keeping its log flowing meanwhile
                // (here too, in case the log writer is the one that failed).
                from_cue_in.write(FromCue {
                    ended: Some(reason::ERROR),
                    ..FromCue::default()
                });
                while !to_cue_out.read().over && !control.is_finished() {
                    let _ = lock_sink(sink).absorb();
                    std::thread::sleep(Duration::from_millis(CUE_POLL_MS));
                }
            }
            let mut end = match control.join() {
                Ok(end) => end,
                Err(p) => LoopEnd {
                    reason: reason::ERROR,
                    detail: None,
                    failure: Some(Error::panic("the control thread", p.as_ref())),
                    t_end: 0.0,
                },
            };
            writer_stop.store(true, Ordering::Release);
            let written = writer
                .join()
                .unwrap_or_else(|p| Err(Error::panic("the log-writer thread", p.as_ref())));
            // The writer's last drain, or (when it failed) one here: nothing the control
            // thread queued is left behind.
            let drained = written.and_then(|()| lock_sink(sink).absorb());
            if let Err(e) = drained {
                end.reason = reason::ERROR;
                end.failure = Some(chain(end.failure.take(), e));
            }
            if let Some(e) = cue_failure {
                end.reason = reason::ERROR;
                end.failure = Some(chain(end.failure.take(), e));
            }
            end
        })
    }
}

/// The trial's control cycle on `robot`: the UR5e supervisor, and the controller of `ctl_cfg`
/// planning inside the supervisor's own limits (the same numbers, checked independently by
/// each).
fn control_cycle<R: TrialRobot>(
    robot: R,
    mut ctl_cfg: ControllerConfig,
) -> crate::Result<ControlCycle<R>> {
    let mut supervisor_cfg = SupervisorConfig::ur5e();
    if let Some(bound_s) = robot.servo_extrapolation_s() {
        supervisor_cfg.command_period_cycles =
            CatchUpCycles::for_extrapolation(bound_s, supervisor_cfg.cycle.seconds());
    }
    ctl_cfg.envelope = planner_envelope(&supervisor_cfg)?;
    Ok(ControlCycle::new(
        Supervisor::new(robot, supervisor_cfg)?,
        Controller::new(ctl_cfg)?,
    ))
}

/// The planner's [`SafetyEnvelope`]: the supervisor's joint, TCP, collaboration and
/// staleness limits, its stop deceleration, its separation, arm and body models, and the
/// longest period it judges a servo step over (the planner's catch-up bound).
pub(crate) fn planner_envelope(cfg: &SupervisorConfig) -> crate::Result<SafetyEnvelope> {
    SafetyEnvelope::new(
        cfg.joint_rates.max_speed_rad_s(),
        cfg.joint_rates.max_acc_rad_s2(),
        cfg.joint_rates.stop_decel_rad_s2(),
        cfg.tcp_speed.m_s(),
        cfg.collaboration_tcp_speed.m_s(),
        cfg.stale_perception_scale.get(),
        cfg.staleness.perception_reduce_after_s(),
        cfg.separation,
        cfg.arm,
        cfg.body,
    )
    .and_then(|e| e.with_catch_up_cycles(cfg.command_period_cycles.get()))
    .context("the supervisor's limits do not make a planning envelope")
}

/// A robot clock this far behind trial time [s] was restarted (a new controller): trial time
/// is re-based on it. Less is the lead of predicted (missed) cycles, which the robot's clock
/// catches up.
const CLOCK_RESTART_S: f64 = 1.0;

/// Joint speed [rad/s] under which the arm counts as at rest (to resume after a link loss).
const REST_RAD_S: f64 = 0.01;

/// A stretch without a new robot state (controller clock).
#[derive(Debug, Clone, Copy)]
struct Outage {
    /// When the last fresh sample was followed by none.
    since: Instant,
    /// Longer than `[link] lost_after_s`: a link loss (the trial is paused).
    declared: bool,
    /// The last program restart asked for.
    last_restart: Option<Instant>,
    /// Paused cycles so far.
    holds: u64,
}

impl Outage {
    fn new(now: Instant) -> Self {
        Self {
            since: now,
            declared: false,
            last_restart: None,
            holds: 0,
        }
    }

    /// Whether to ask for a program restart now (at most once a second).
    fn restart_due(&mut self, now: Instant) -> bool {
        let due = self
            .last_restart
            .is_none_or(|l| now.duration_since(l) >= Duration::from_secs(1));
        if due {
            self.last_restart = Some(now);
        }
        due
    }
}

impl Stuck {
    /// The error message of a `task_impossible` ending at trial time `t_s` [s].
    fn describe(&self, t_s: f64) -> String {
        let why = match self.cause {
            "trajectory" => "the trajectory generator could not plan a motion to it".to_owned(),
            "no_progress" => "the planner held the robot".to_owned(),
            id => format!(
                "the safety supervisor intervened {} times for {id} meanwhile",
                self.interventions
            ),
        };
        format!(
            "task impossible ({}): in {}, the robot got no closer to its target for {:.1} s \
             (until t = {t_s:.3} s); {why}",
            self.cause,
            phase_name(self.phase),
            self.for_s
        )
    }
}

/// Stops the robot through the supervisor: stop commands until a fresh state shows the arm at
/// rest, for at most 250 cycles, or until 25 cycles in a row bring no fresh state (the link is
/// gone: nothing more can be done from here).
fn stop_robot<R: Robot>(
    supervisor: &mut Supervisor<R>,
    state: &mut RobotState,
    world: &mut WorldView,
    t_end: f64,
) {
    let stop_cmd = JointCommand::Stop { decel: 3.0 };
    let mut last_ts = state.timestamp_s;
    let mut missing = 0u32;
    for j in 0..250u64 {
        let fresh = supervisor.read_state(state).is_ok() && state.timestamp_s > last_ts;
        if fresh {
            last_ts = state.timestamp_s;
            missing = 0;
        } else {
            missing += 1;
        }
        world.now_s = t_end + j as f64 * CYCLE_S;
        let _ = supervisor.step(&stop_cmd, world);
        if (fresh && state.actual_qd.iter().all(|q| q.abs() < 1e-6)) || missing >= 25 {
            break;
        }
    }
}

/// Run one simulated trial (simulated operator, in-process `SimRobot`, mock clock) into
/// `out_dir` and return it. Thread-safe: each call owns all its state.
#[allow(dead_code)] // called by the experiment runner
pub fn run_simulated(
    spec: &TrialSpec,
    out_dir: &Path,
    show_progress: bool,
) -> crate::Result<PathBuf> {
    let stop = AtomicBool::new(false);
    let bar = progress_bar(show_progress);
    let dir = run_simulated_with(spec, out_dir, &stop, &mut |l| update_bar(&bar, l))?;
    bar.finish_and_clear();
    Ok(dir)
}

/// A progress spinner on stderr (hidden when `show` is false or stderr is not a terminal).
pub(crate) fn progress_bar(show: bool) -> indicatif::ProgressBar {
    if show {
        let bar = indicatif::ProgressBar::new_spinner();
        bar.set_style(
            indicatif::ProgressStyle::with_template("{spinner} {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
        );
        bar
    } else {
        indicatif::ProgressBar::hidden()
    }
}

/// Shows the live values (every 30th call: once per simulated second at 30 Hz).
pub(crate) fn update_bar(bar: &indicatif::ProgressBar, l: &Live) {
    if let Some(down) = l.link_down_s
        && !bar.is_hidden()
    {
        bar.set_message(format!(
            "robot link lost {down:.1} s ago at t = {:.1} s: robot stopped, waiting for it to \
             come back",
            l.t_s
        ));
        bar.tick();
        return;
    }
    if bar.is_hidden() || !((l.t_s * 30.0).round() as u64).is_multiple_of(30) {
        return;
    }
    bar.set_message(format!(
        "[simulation] t = {:6.1} s  handovers {}/{}  HRC-CWL {:.3}  dominant {}",
        l.t_s, l.handovers_done, l.handovers, l.hrc_cwl, l.dominant
    ));
    bar.tick();
}

/// Held by every test that runs a trial on the in-process emulator: they run one at a time
/// (several real-time emulators at once on two cores starve each other's control loop).
#[cfg(test)]
pub(crate) static EMULATOR_TESTS: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Asserts every file a trial leaves (ARCHITECTURE.md, "Files a trial leaves").
#[cfg(test)]
pub(crate) fn assert_trial_files(out: &Path) {
    for f in [
        "trial.mcap",
        "indicators.csv",
        "robot.csv",
        "summary.json",
        "report.html",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
}

/// A test trial: P01, adaptive, the shipped configuration cut to `max_s` [s].
#[cfg(test)]
pub(crate) fn test_spec(condition: Level, seed: u64, max_s: f64) -> TrialSpec {
    let mut config = TrialConfig::shipped().unwrap();
    config.max_duration_s = max_s;
    TrialSpec {
        participant: "P01".into(),
        condition,
        policy: PolicyKind::Adaptive,
        seed,
        config,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The planner plans under exactly the supervisor's numbers (issue 10: "the allowed speed
    /// comes from the same SSM/PFL formulas and caps that the supervisor checks").
    #[test]
    fn the_planner_envelope_is_the_supervisors_limits() {
        let env = planner_envelope(&SupervisorConfig::ur5e()).unwrap();
        assert_eq!(env, SafetyEnvelope::ur5e());
        let mut cfg = SupervisorConfig::ur5e();
        cfg.collaboration_tcp_speed = safety::SpeedLimit::new(0.2).unwrap();
        let env = planner_envelope(&cfg).unwrap();
        assert_eq!(env.collaboration_tcp_speed_m_s(), 0.2);
    }

    #[test]
    fn safety_events_are_debounced_pair_changes() {
        let stop = ("stopped", "SAF-REQ-007");
        let reduce = ("reduced", "SAF-REQ-004");
        let mut d = super::super::control::SafetyDebounce::new(0.05);
        let mut events = Vec::new();
        // 2 ms cycles: 30 ms stop / 30 ms reduce flicker for 0.6 s, then 100 ms reduce, then
        // 100 ms passed, then 100 ms reduce again.
        let mut feed = |from: u32, to: u32, pair, events: &mut Vec<_>| {
            for k in from..to {
                if let Some(e) = d.update(f64::from(k) * 0.002, pair) {
                    events.push(e);
                }
            }
        };
        for i in 0..10u32 {
            feed(i * 30, i * 30 + 15, stop, &mut events);
            feed(i * 30 + 15, i * 30 + 30, reduce, &mut events);
        }
        assert!(events.is_empty(), "flicker below 50 ms is not an event");
        feed(300, 350, reduce, &mut events);
        feed(350, 400, ("passed", "none"), &mut events);
        feed(400, 450, reduce, &mut events);
        assert_eq!(events.len(), 2, "{events:?}");
        assert!(
            (events[0].0 - 0.570).abs() < 1e-9,
            "stamped at onset: {events:?}"
        );
        assert_eq!(events[0].1, reduce);
        assert!((events[1].0 - 0.800).abs() < 1e-9);
    }

    // The whole-trial tests (sim, emulator, recorded cues, the motion acceptance) run the
    // binary as a user does: `tests/cli/trials.rs`.
}

#[cfg(test)]
#[path = "runtime_exit_tests.rs"]
mod exit_tests;

#[cfg(test)]
#[path = "control_tests.rs"]
mod control_tests;
