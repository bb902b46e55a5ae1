//! A UR controller emulator: RTDE (30004), dashboard (29999) and script (30002, 30003) servers
//! on configurable ports, backed by [`SimBackend`] (the in-process [`SimRobot`], driven by our
//! register protocol) or [`TraceBackend`] (a recorded [`Trace`]).
//!
//! One clock (a tokio task, or at speedup 3 and up an OS thread) steps the backend in 2 ms
//! controller cycles on a virtual clock: one cycle every 2 ms / `speedup` of wall time (1 = real time; tests speed it up). The clock keeps
//! absolute cycles (cycle n is due at start + n · 2 ms / speedup) and catches up after missed
//! ones: up to 20 ms of wall time by running a little faster for a while ([`Slew`]), beyond
//! that in a burst within a bound per wake ([`plan_ticks`]); [`Emulator::clock_stats`] reports
//! how far it fell behind. Each RTDE session
//! is sampled from the virtual clock at its requested frequency, so what a client receives
//! depends on virtual cycles only, not on scheduling jitter.
//!
//! Enforced like a controller: protocol version 2 only, unknown fields answered `NOT_FOUND`
//! (a trailing comma after the last name is ignored, as ur_rtde sends it), one writer per
//! input (`IN_USE`), and a client whose queue stays full for
//! [`EmulatorConfig::stall_timeout`] is dropped.
//!
//! The script ports (30002, 30003) keep a client's connection open and take each program at
//! its top-level `end` ([`split_program`]). [`SimBackend`] runs two programs: our
//! `hrc_control` register protocol ([`crate::script::RegisterMap`]) and SDU ur_rtde 1.6.5's
//! `rtde_control.script`, which `RTDEControlInterface` uploads ([`ur_rtde_control`]: servoJ,
//! speedJ, moveJ, stopJ, servoStop, speedStop, the watchdog, the async progress register and
//! the joint-space getters; other commands stop the script as a script error would).
//!
//! Not emulated: the primary/secondary interfaces' state packages (the script ports only
//! receive), URScript itself (the emulator recognises the two programs and executes their
//! protocols natively).

use std::any::Any;
use std::collections::HashMap;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Notify, mpsc, watch};
use tokio::task::JoinHandle;

use crate::codec::{
    ClientPackage, ControllerPackage, ControllerVersion, FieldType, MAX_FREQUENCY_HZ,
    PROTOCOL_VERSION, TextMessage, Value, encode_data_package, known_field_type, level,
};
use crate::dashboard::{DashboardCommand, robot_mode_name, safety_status_name};
use crate::script::{DOUBLE_REGISTERS, INT_REGISTERS, RegisterMap, ServoFeedforward};
use crate::sim::SimRobot;
use crate::trace::Trace;
use crate::types::{JointCommand, Joints, Robot, RobotState};
use crate::{Result, RobotIoError};

#[path = "dashboard_budget.rs"]
pub mod dashboard_budget;
#[path = "sim_fields.rs"]
pub mod sim_fields;
#[path = "emulator_ur_rtde.rs"]
pub mod ur_rtde_control;
use dashboard_budget::{LineBudget, MAX_DASHBOARD_CONNECTIONS};
use sim_fields::{IoEcho, SimFields};
use ur_rtde_control::{OutputRegisters, UrRtdeControl, UrRtdeScript, Verdict};

/// Controller cycle \[s\].
pub const CYCLE_S: f64 = 0.002;
/// Input registers per kind on e-Series (0..=47).
pub const REGISTERS: usize = 48;

/// Emulator settings.
#[derive(Debug, Clone, PartialEq)]
pub struct EmulatorConfig {
    /// Address to bind (loopback by default).
    pub bind: IpAddr,
    /// RTDE port (30004; 0 = ephemeral).
    pub rtde_port: u16,
    /// Dashboard port (29999; 0 = ephemeral).
    pub dashboard_port: u16,
    /// Secondary interface port (30002; 0 = ephemeral).
    pub secondary_port: u16,
    /// Real-time interface port (30003; 0 = ephemeral).
    pub realtime_port: u16,
    /// Controller version reported to RTDE clients.
    pub controller_version: ControllerVersion,
    /// Virtual controller cycles run per 2 ms of wall time [-], in [1, [`MAX_SPEEDUP`]]
    /// (1 = real time).
    pub speedup: u32,
    /// A client whose outgoing queue stays full this long is dropped (a controller drops a
    /// client that stops reading after about 10 s).
    pub stall_timeout: Duration,
    /// Outgoing packages queued per client before it counts as stalled [-].
    pub queue_packages: usize,
    /// Inputs claimed by "another writer" from the start (as fieldbus adapters claim
    /// registers 0–23 on some cells); clients asking for them get `IN_USE`.
    pub preclaimed_inputs: Vec<String>,
    /// Run the clock on its own thread under `SCHED_FIFO` at this priority, as a controller's
    /// real-time clock ([`crate::realtime`]; `None`: normal scheduling, and at speedups below
    /// 3 a tokio task). Refused by the OS, the clock runs at normal priority and
    /// [`Emulator::clock_scheduling`] says why.
    pub clock_priority: Option<crate::realtime::RtPriority>,
    /// A sped-up clock (`speedup` > 1) waits for a late client at most this long [wall time]
    /// before it runs on (`None`: never waits, as a controller; see [`ClientWait`]). Refused
    /// at speedup 1: a real-time clock never waits.
    pub wait_for_client: Option<Duration>,
}

/// The largest [`EmulatorConfig::speedup`] [-]: 100. The clock runs one controller cycle
/// every 2 ms / `speedup` of wall time (20 µs at 100), each while holding the emulator's
/// state, and a client reading every sample (500 × speedup per second) already skips most of
/// them; a huge value kept the emulator busy for ever (issue 10: 4294967295 hung it).
pub const MAX_SPEEDUP: u32 = 100;

/// The most controller cycles one wake of the emulator's clock runs when catching up [-]:
/// 1000 (2 s of virtual time). See [`max_cycles_per_wake`].
pub const MAX_CATCH_UP_CYCLES: u64 = 1000;

/// The most wall time one wake of the emulator's clock catches up [ms]: 100. See
/// [`max_cycles_per_wake`].
pub const MAX_CATCH_UP_WALL_MS: u64 = 100;

/// The bound on cycles run in one wake of the clock at `speedup` [cycles]: those due in
/// [`MAX_CATCH_UP_WALL_MS`] of wall time (50 × speedup), at most [`MAX_CATCH_UP_CYCLES`], at
/// least 1. So at speedup 1 a stall of up to 100 ms is caught up in one burst of at most 50
/// cycles, at speedup 100 one of up to 20 ms in at most 1000 cycles; cycles due beyond the
/// bound are dropped (counted in [`ClockStats::cycles_dropped`]), so a long stall (a stopped
/// process, a loaded CI machine) never runs thousands of cycles while holding the emulator's
/// state and flooding every client's queue.
pub fn max_cycles_per_wake(speedup: u32) -> u64 {
    let wall = MAX_CATCH_UP_WALL_MS * 1_000_000 / CYCLE_NS;
    wall.saturating_mul(u64::from(speedup.max(1)))
        .clamp(1, MAX_CATCH_UP_CYCLES)
}

/// What one wake of the emulator's clock does ([`plan_ticks`]), in controller cycles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TickPlan {
    /// Cycles to run now [cycles].
    pub run: u64,
    /// Of those, cycles run late in a burst: all but the last of this wake [cycles].
    pub late: u64,
    /// Cycles due beyond the per-wake bound: skipped, never run [cycles].
    pub dropped: u64,
    /// Cycles left due after this wake, within the slew allowance: the clock runs them one
    /// per wake, a little faster than its period ([`Slew`]) [cycles].
    pub behind: u64,
}

/// The clock's schedule for one wake: `due` cycles are due since the start (wall time elapsed
/// × speedup / 2 ms, rounded down), `done` have been run or dropped before, up to `allowance`
/// of the backlog may stay behind (slewed, [`Slew`]) and at most `max_per_wake` (taken as at
/// least 1) run now. Whenever a cycle is due at least one runs; what the allowance and the
/// bound leave is dropped, so after this wake `done + run + dropped + behind == due` whenever
/// `due >= done`.
pub fn plan_ticks(due: u64, done: u64, max_per_wake: u64, allowance: u64) -> TickPlan {
    let backlog = due.saturating_sub(done);
    let behind = allowance.min(backlog.saturating_sub(1));
    let wanted = backlog - behind;
    let run = wanted.min(max_per_wake.max(1));
    TickPlan {
        run,
        late: run.saturating_sub(1),
        dropped: wanted - run,
        behind,
    }
}

/// How fast the emulator's clock works off a backlog [-]: 0.25, i.e. after its thread ran late
/// it runs its cycles at up to 1.25 × its rate until it is back on wall time ([`Slew`]).
pub const SLEW_RATE: f64 = 0.25;

/// The largest backlog the clock slews [ms of wall time]: 20 ms (10 × speedup cycles,
/// [`slew_window`]). A longer stall (a stopped process) runs the excess at once, as a burst,
/// within [`max_cycles_per_wake`].
pub const SLEW_WINDOW_WALL_MS: u64 = 20;

/// [`SLEW_WINDOW_WALL_MS`] at `speedup` [cycles]: 10 × speedup (speedup 0 counts as 1).
pub fn slew_window(speedup: u32) -> u64 {
    (SLEW_WINDOW_WALL_MS * 1_000_000 / CYCLE_NS).saturating_mul(u64::from(speedup.max(1)))
}

/// The emulator clock's slew: how many cycles it may trail wall time, in controller cycles.
///
/// A controller's clock never stops, but the emulator's thread does (a busy or virtual machine
/// preempts it for milliseconds). Running the missed cycles in one burst, as the clock did
/// before, handed the client several samples at once with no time to answer them: the
/// program then extrapolated, and past its bound held, although the client had not been late
/// (issue 10: 4 of 6 and 9 of 14 holds in two speedup-4 trials began in such a burst). Like
/// an NTP daemon slewing a system clock instead of stepping it, the clock instead keeps the
/// backlog as a lag (at most [`slew_window`]), runs one cycle per wake, and wakes early
/// enough to work the lag off at [`SLEW_RATE`] of wall time: the client sees one sample at a
/// time, on a clock that runs 25 % fast for a while. The virtual clock stays on wall time in
/// the long run (issue 11).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Slew {
    /// The lag set at the last stall [cycles].
    lag0: f64,
    /// When it was set, in cycles elapsed by wall time [cycles].
    since: f64,
}

impl Slew {
    /// The lag allowed at `v` cycles elapsed by wall time (fractional) [cycles]: the last
    /// stall's, less [`SLEW_RATE`] per cycle since, never below 0.
    pub fn lag(&self, v: f64) -> f64 {
        (self.lag0 - SLEW_RATE * (v - self.since)).max(0.0)
    }

    /// A wake at `v` cycles elapsed (fractional) with `done` cycles run, dropped or paused
    /// before: a backlog (beyond the cycle run now) larger than the allowed lag is a new
    /// stall and becomes the lag, at most `window`. Returns the allowance for
    /// [`plan_ticks`] in whole cycles.
    pub fn on_wake(&mut self, v: f64, done: u64, window: u64) -> u64 {
        let backlog = (v.floor() - done as f64 - 1.0).max(0.0);
        if backlog > self.lag(v) {
            self.lag0 = backlog.min(window as f64);
            self.since = v;
        }
        // In [0, window]: the cast neither wraps nor saturates.
        self.lag(v).floor() as u64
    }

    /// No lag (after a pause, whose cycles are not made up).
    pub fn reset(&mut self) {
        *self = Slew::default();
    }

    /// When cycle `done + 1` is due on the slewed clock, in cycles elapsed by wall time
    /// (fractional): where `v − lag(v)` reaches `done + 1`. Without a lag that is `done + 1`
    /// itself, the cycle's own time.
    pub fn next_due(&self, done: u64) -> f64 {
        let n = done as f64 + 1.0;
        let expires = self.since + self.lag0 / SLEW_RATE;
        if n >= expires {
            n
        } else {
            (n + self.lag0 + SLEW_RATE * self.since) / (1.0 + SLEW_RATE)
        }
    }
}

/// How the emulator's clock kept up with wall time ([`Emulator::clock_stats`]), in controller
/// cycles. As of the clock's last wake,
/// `cycles_run + cycles_dropped + cycles_paused + cycles_waited + cycles_behind ==
/// cycles_elapsed` exactly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ClockStats {
    /// Cycles due since the start (wall time × speedup / 2 ms), as of the clock's last wake
    /// [cycles].
    pub cycles_elapsed: u64,
    /// Cycles run [cycles] (the virtual clock, [`Emulator::cycle`]).
    pub cycles_run: u64,
    /// Cycles run late, in a catch-up burst after a late wake [cycles].
    pub cycles_late: u64,
    /// Cycles due beyond the per-wake bound ([`max_cycles_per_wake`]) and never run: how far
    /// the virtual clock fell behind wall time × speedup for good [cycles].
    pub cycles_dropped: u64,
    /// Cycles not run because the emulator was paused ([`Emulator::pause`]; by design, not
    /// lateness) [cycles].
    pub cycles_paused: u64,
    /// The largest backlog seen at one wake, before catching up [cycles] (speedup on time).
    pub max_behind_cycles: u64,
    /// Cycles due and not yet run, as of the last wake: the lag being slewed ([`Slew`])
    /// [cycles].
    pub cycles_behind: u64,
    /// Cycles run one per wake while the clock trailed wall time, slewing [cycles].
    pub cycles_slewed: u64,
    /// Wakes that ran more than one cycle: the clock itself was late (its thread not run in
    /// time) beyond what it slews, so the client saw those samples only together [-].
    pub bursts: u64,
    /// Servo holds ([`ServoStats::holds`]) that began in such a burst: the program ran past its
    /// extrapolation bound while the emulator, not the client, was late [-].
    pub holds_in_bursts: u64,
    /// Cycles not run because the sped-up clock waited for a late client ([`ClientWait`];
    /// virtual time stood still, as while paused) [cycles].
    pub cycles_waited: u64,
    /// Times the clock began to wait for a late client [-].
    pub waits: u64,
    /// Waits that reached [`EmulatorConfig::wait_for_client`]: the clock then ran on as a
    /// controller's does (the program extrapolated, held, or its watchdog fired) [-].
    pub waits_timed_out: u64,
}

/// How a sped-up emulator clock waits for a late client ([`EmulatorConfig::wait_for_client`]).
///
/// A real controller never waits: a servo command that misses its cycle is extrapolated for
/// a few cycles, then held, and the arm brakes. At speedup 1 the emulator does the same. At
/// speedup N a client must answer N times as fast as a real controller asks; a 2 ms stall of
/// a busy 2-core machine is then 4 missed cycles at speedup 4, where a UR5e would see one.
/// So a sped-up clock, a virtual clock with no wall-time meaning, waits instead, as a
/// lockstep simulator does: at a wake where the program would have to extrapolate a moving
/// servo target because no newer command came ([`EmulatorBackend::awaits_command`]), no cycle
/// runs and virtual time stands still, until the command comes or `max` has passed. After
/// `max` the clock runs on (the client counts as late, as on a controller) and waits again only
/// once the client has caught up. Cycles not run are counted ([`ClockStats::cycles_waited`]),
/// never hidden.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClientWait {
    max: Duration,
    /// When the current wait began (`None`: not waiting).
    since: Option<Instant>,
    /// The current wait reached `max`: run on until the client is current again.
    timed_out: bool,
}

/// What the clock does at one wake with a [`ClientWait`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitDecision {
    /// Run the cycles due.
    Run,
    /// Run no cycle now; `began` is true at the first wake of this wait.
    Wait {
        /// The first wake of this wait.
        began: bool,
    },
    /// The wait reached its bound at this wake: run the cycles due.
    TimedOut,
}

impl ClientWait {
    /// Waits of at most `max` [wall time].
    pub fn new(max: Duration) -> Self {
        Self {
            max,
            since: None,
            timed_out: false,
        }
    }

    /// The decision at a wake at `now` where the program `awaits` a command.
    pub fn decide(&mut self, awaits: bool, now: Instant) -> WaitDecision {
        if !awaits {
            self.since = None;
            self.timed_out = false;
            return WaitDecision::Run;
        }
        if self.timed_out {
            return WaitDecision::Run;
        }
        let since = *self.since.get_or_insert(now);
        if now.saturating_duration_since(since) >= self.max {
            self.timed_out = true;
            return WaitDecision::TimedOut;
        }
        WaitDecision::Wait {
            began: since == now,
        }
    }
}

/// How our control program's servo commands reached it and what it did with them, counted
/// every cycle by [`SimBackend`] ([`Emulator::servo_stats`]). It tells, for a client such as
/// the trial's control loop, how much of its motion the program had to extrapolate or hold:
/// a command arriving late is extrapolated from the tick it was meant for, and beyond the
/// program's bound (`extrapolate_max_s`) the target holds and the arm brakes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ServoStats {
    /// Servo commands received (new sequence numbers) [-].
    pub commands: u64,
    /// `late[k]`: commands that arrived `k` program cycles after the tick they were meant for
    /// (`late[0]`: on time or early; the last entry: [`SERVO_LATE_BINS`] − 1 cycles or more)
    /// [-].
    pub late: [u64; SERVO_LATE_BINS],
    /// Cycles in which the program extrapolated the target in force within its bound
    /// (its tick past the target's valid tick) [cycles].
    pub extrapolated_cycles: u64,
    /// Cycles in which the target in force was meant for a later tick (it came early: the
    /// client predicted ahead while a sample was late), so the program evaluated it back to
    /// its tick [cycles].
    pub early_cycles: u64,
    /// Cycles in which a moving target (non-zero feedforward velocity) in force was older than
    /// the bound, so the program held it (the arm then brakes towards it) [cycles].
    pub held_cycles: u64,
    /// Separate holds: runs of consecutive held cycles [-].
    pub holds: u64,
}

/// Bins of [`ServoStats::late`] [-].
pub const SERVO_LATE_BINS: usize = 17;

impl Default for EmulatorConfig {
    fn default() -> Self {
        Self {
            bind: IpAddr::V4(Ipv4Addr::LOCALHOST),
            rtde_port: crate::client::RTDE_PORT,
            dashboard_port: crate::dashboard::DASHBOARD_PORT,
            secondary_port: crate::script::SECONDARY_PORT,
            realtime_port: crate::script::REALTIME_PORT,
            controller_version: ControllerVersion {
                major: 5,
                minor: 15,
                bugfix: 0,
                build: 0,
            },
            speedup: 1,
            stall_timeout: Duration::from_secs(10),
            queue_packages: 1000,
            preclaimed_inputs: Vec::new(),
            clock_priority: None,
            wait_for_client: None,
        }
    }
}

impl EmulatorConfig {
    /// Loopback with every port ephemeral (for tests running in parallel).
    pub fn ephemeral() -> Self {
        Self {
            rtde_port: 0,
            dashboard_port: 0,
            secondary_port: 0,
            realtime_port: 0,
            ..Self::default()
        }
    }
}

/// The input registers as clients last wrote them, and when (in virtual cycles).
#[derive(Debug, Clone)]
pub struct InputRegisters {
    /// `input_int_register_N`.
    pub int: [i32; REGISTERS],
    /// `input_double_register_N`.
    pub double: [f64; REGISTERS],
    /// `input_bit_register_N` for N in 64..=127, bit N−64.
    pub bits: u64,
    /// Cycle of the last write of each int register (0 = never).
    pub int_written: [u64; REGISTERS],
    /// Current virtual cycle (1 for the first step).
    pub cycle: u64,
    /// Digital and analog outputs and input bit registers 0–63 as clients last wrote them
    /// (echoed in the outputs).
    pub io: IoEcho,
}

impl Default for InputRegisters {
    fn default() -> Self {
        Self {
            int: [0; REGISTERS],
            double: [0.0; REGISTERS],
            bits: 0,
            int_written: [0; REGISTERS],
            cycle: 0,
            io: IoEcho::default(),
        }
    }
}

/// Opaque handle of a backend output field, resolved once at recipe setup.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputHandle(pub usize);

/// What stands behind the emulator: a model or a recording.
pub trait EmulatorBackend: Send + std::fmt::Debug + 'static {
    /// A short description for logs and the message sent at stream start.
    fn describe(&self) -> String;
    /// Resolves output field `name` (called at setup). `None`: the controller answers
    /// `NOT_FOUND`.
    fn output_handle(&mut self, name: &str) -> Option<(OutputHandle, FieldType)>;
    /// The current value behind `handle` (called for every package sent).
    fn read_output(&self, handle: OutputHandle) -> Value;
    /// Advances one 2 ms controller cycle, seeing the input registers as they are now.
    fn step(&mut self, inputs: &InputRegisters);
    /// A client started streaming (a trace backend starts playing at the first one).
    fn stream_started(&mut self) {}
    /// A script arrived on a script port; returns whether it was accepted as a program.
    fn load_program(&mut self, script: &str) -> bool;
    /// A dashboard command; returns the reply line (without newline).
    fn dashboard(&mut self, cmd: DashboardCommand) -> String;
    /// The program's runtime state now (`runtime_state` values), for the dashboard's
    /// `programState` and `running`.
    fn runtime_state(&self) -> u32 {
        crate::types::runtime_state::STOPPED
    }
    /// Dashboard `load <program>`: whether the program was loaded (default: refused).
    fn load_urp(&mut self, _path: &str) -> bool {
        false
    }
    /// The program loaded through the dashboard, if any.
    fn loaded_program(&self) -> Option<&str> {
        None
    }
    /// Dashboard `restart safety`: clears safety faults and stops (powered off, as a
    /// controller leaves the arm); whether it was done (default: refused).
    fn restart_safety(&mut self) -> bool {
        false
    }
    /// A client's input recipe set the speed slider to `fraction` [-] (default: ignored).
    fn speed_slider(&mut self, _fraction: f64) {}
    /// What happened to our control program's servo commands, for a backend that runs it
    /// ([`SimBackend`]; default: `None`).
    fn servo_stats(&self) -> Option<ServoStats> {
        None
    }
    /// Whether the program's next cycle would have to extrapolate a moving servo target
    /// because no newer command has been written since the last cycle ([`ClientWait`];
    /// default: never).
    fn awaits_command(&self, _inputs: &InputRegisters) -> bool {
        false
    }
    /// For tests and tools that need the concrete backend.
    fn as_any_mut(&mut self) -> &mut dyn Any;
}

// ---------------------------------------------------------------------------------------------
// SimRobot-backed.

/// Handle of the constant-zero output registers a SimBackend serves (our program writes none).
const SIM_ZERO_BASE: usize = 1000;
/// Handles of `output_int_register_0..=47`: this base + the register number.
const SIM_OUTPUT_INT_BASE: usize = 2000;
/// Handles of `output_double_register_0..=47`: this base + the register number.
const SIM_OUTPUT_DOUBLE_BASE: usize = 3000;

/// Backend executing our register protocol on a [`SimRobot`].
///
/// The SimRobot starts with its program stopped. A script containing our control program
/// (recognised by [`RegisterMap::from_program`]) starts it; from then on each cycle the
/// registers are decoded like the program does and a new command (new sequence number) is
/// sent to the SimRobot. While a servo command is in force, every cycle (each cycle of a
/// catch-up burst too) sends the SimRobot its extrapolated target,
/// [`ServoFeedforward::target`] at the program's tick, as the URScript program does (see
/// [`crate::script`]; the emulator runs one program iteration per cycle, servoj time t = one
/// cycle, and serves the tick as `output_int_register_<int_base>`). The watchdog is armed at the first write of the command register
/// after the program starts: when no write arrives for `1 / watchdog_hz` seconds of virtual
/// time, the program is stopped (the arm brakes to rest, `runtime_state` goes STOPPED).
#[derive(Debug)]
pub struct SimBackend {
    robot: SimRobot,
    published: RobotState,
    program: Option<RegisterMap>,
    program_start_cycle: u64,
    last_seq: Option<i32>,
    /// The program's loop iterations (its tick), counted from 1 at its first cycle.
    tick: i32,
    /// The servo command in force, for the per-cycle extrapolation.
    servo: Option<ServoInForce>,
    watchdog_trips: u64,
    commands_executed: u64,
    remote_control: bool,
    /// The derived output fields' model (every RTDE guide output field).
    fields: SimFields,
    /// The echoed inputs as of the last cycle.
    io: IoEcho,
    /// A `.urp` loaded through the dashboard (played as a program that holds the arm).
    urp: Option<String>,
    /// What happened to the servo commands ([`ServoStats`]).
    servo_stats: ServoStats,
    /// The last cycle held the target (for [`ServoStats::holds`]).
    holding: bool,
    /// Last speed slider fraction applied [-].
    slider: Option<f64>,
    /// ur_rtde's control script, when it is the program that runs ([`ur_rtde_control`]).
    ur_rtde: Option<UrRtdeControl>,
    /// ur_rtde's script arrived while the previous program was still stopping: it starts
    /// once the arm is STOPPED.
    pending_ur_rtde: Option<UrRtdeScript>,
    /// The output registers as the running program wrote them (zero when none runs).
    outputs: OutputRegisters,
}

/// A servo command the program executes, and how long it has been in force.
#[derive(Debug, Clone, Copy)]
struct ServoInForce {
    /// The target as written [rad].
    q: Joints,
    lookahead_s: f64,
    gain: f64,
    feedforward: ServoFeedforward,
    /// The target last sent to the SimRobot [rad].
    sent: Option<Joints>,
}

impl ServoInForce {
    /// Whether the target moves: a joint velocity in its (clamped) feedforward. A target at
    /// rest is never extrapolated, so it is neither held nor awaited.
    fn moving(&self) -> bool {
        self.feedforward.clamped().qd.iter().any(|v| *v != 0.0)
    }
}

impl SimBackend {
    /// Wraps `robot`; its program is stopped until our control program arrives.
    pub fn new(mut robot: SimRobot) -> Self {
        robot.stop_program();
        // One cycle so that an arm at rest is STOPPED (not STOPPING) before any program can
        // arrive: `play` is refused while stopping.
        robot.step();
        let mut published = RobotState::default();
        let _ = robot.read_state(&mut published);
        Self {
            robot,
            published,
            program: None,
            program_start_cycle: 0,
            last_seq: None,
            tick: 0,
            servo: None,
            watchdog_trips: 0,
            commands_executed: 0,
            remote_control: true,
            fields: SimFields::default(),
            io: IoEcho::default(),
            urp: None,
            slider: None,
            servo_stats: ServoStats::default(),
            holding: false,
            ur_rtde: None,
            pending_ur_rtde: None,
            outputs: OutputRegisters::default(),
        }
    }

    /// The simulated robot (for fault injection).
    pub fn robot_mut(&mut self) -> &mut SimRobot {
        &mut self.robot
    }

    /// The state published to clients after the last cycle.
    pub fn published(&self) -> &RobotState {
        &self.published
    }

    /// The target of the servo command our program executes, as the client wrote it (before
    /// the per-cycle extrapolation) [rad]; `None` while no servo command is in force.
    pub fn servo_target(&self) -> Option<Joints> {
        self.servo.as_ref().map(|s| s.q)
    }

    /// Whether a control program runs: ours, or ur_rtde's control script.
    pub fn program_running(&self) -> bool {
        self.program.is_some() || self.ur_rtde.is_some()
    }

    /// ur_rtde's control script, while it runs.
    pub fn ur_rtde_control(&self) -> Option<&UrRtdeControl> {
        self.ur_rtde.as_ref()
    }

    /// The output registers as the running program wrote them.
    pub fn output_registers(&self) -> &OutputRegisters {
        &self.outputs
    }

    /// Forgets every program (the arm's program state is the caller's business).
    fn clear_programs(&mut self) {
        self.program = None;
        self.ur_rtde = None;
        self.pending_ur_rtde = None;
        self.outputs = OutputRegisters::default();
    }

    /// Starts ur_rtde's control script (the arm is STOPPED or PLAYING): `false` when the arm
    /// cannot play.
    fn start_ur_rtde(&mut self, script: UrRtdeScript) -> bool {
        if !self.robot.play() {
            tracing::warn!(
                "emulator: ur_rtde's control script received but the robot cannot play \
                 (not running, or safety stop)"
            );
            return false;
        }
        tracing::info!(
            "emulator: ur_rtde control script started (register offset {})",
            script.reg_offset
        );
        self.outputs = OutputRegisters::default();
        self.ur_rtde = Some(UrRtdeControl::start(script, &mut self.outputs));
        true
    }

    /// One cycle of ur_rtde's control script, if it runs.
    fn run_ur_rtde(&mut self, inputs: &InputRegisters) {
        if let Some(script) = self.pending_ur_rtde
            && self.robot.runtime_state() != crate::types::runtime_state::STOPPING
        {
            self.pending_ur_rtde = None;
            self.start_ur_rtde(script);
        }
        let Some(ctl) = &mut self.ur_rtde else { return };
        let before = ctl.commands();
        let verdict = ctl.cycle(inputs, &mut self.robot, &mut self.outputs);
        self.commands_executed += ctl.commands().saturating_sub(before);
        let reason = match verdict {
            Verdict::Running => return,
            Verdict::Stopped(reason) => reason,
            Verdict::WatchdogExpired(reason) => {
                self.watchdog_trips += 1;
                reason
            }
        };
        tracing::warn!("emulator: ur_rtde control script stopped: {reason}");
        self.clear_programs();
        self.robot.stop_program();
    }

    /// Times the watchdog stopped the program.
    pub fn watchdog_trips(&self) -> u64 {
        self.watchdog_trips
    }

    /// Commands (new sequence numbers) passed to the SimRobot.
    pub fn commands_executed(&self) -> u64 {
        self.commands_executed
    }

    /// Sets the reply of `is in remote control`.
    pub fn set_remote_control(&mut self, remote: bool) {
        self.remote_control = remote;
    }

    fn run_program(&mut self, inputs: &InputRegisters) {
        let Some(map) = self.program else { return };
        self.tick = self.tick.wrapping_add(1);
        let ib = usize::from(map.int_base);
        let db = usize::from(map.double_base);
        let written = inputs.int_written.get(ib).copied().unwrap_or(0);
        if written > self.program_start_cycle {
            let limit = (1.0 / (map.watchdog_hz * CYCLE_S)).ceil() as u64;
            if inputs.cycle.saturating_sub(written) > limit {
                tracing::warn!(
                    "emulator: rtde watchdog expired on input_int_register_{ib}: stopping the program"
                );
                self.watchdog_trips += 1;
                self.program = None;
                self.robot.stop_program();
                return;
            }
        }
        let (Some(ints), Some(doubles)) = (
            inputs.int.get(ib..ib + INT_REGISTERS),
            inputs.double.get(db..db + DOUBLE_REGISTERS),
        ) else {
            return;
        };
        let (Ok(ints), Ok(doubles)) = (
            <[i32; INT_REGISTERS]>::try_from(ints),
            <[f64; DOUBLE_REGISTERS]>::try_from(doubles),
        ) else {
            return;
        };
        let seq = ints.get(1).copied();
        if seq == self.last_seq {
            self.send_servo_target(map.extrapolate_max_s);
            return;
        }
        self.last_seq = seq;
        self.servo = None;
        self.holding = false;
        let Some(decoded) = RegisterMap::decode(&ints, &doubles) else {
            return;
        };
        self.commands_executed += 1;
        match decoded.command {
            JointCommand::Servo {
                q,
                lookahead_s,
                gain,
            } => {
                let st = &mut self.servo_stats;
                st.commands = st.commands.saturating_add(1);
                let late = self
                    .tick
                    .wrapping_sub(decoded.feedforward.valid_tick)
                    .max(0);
                let bin = usize::try_from(late)
                    .unwrap_or(usize::MAX)
                    .min(SERVO_LATE_BINS - 1);
                if let Some(n) = st.late.get_mut(bin) {
                    *n = n.saturating_add(1);
                }
                self.servo = Some(ServoInForce {
                    q,
                    lookahead_s,
                    gain,
                    feedforward: decoded.feedforward,
                    sent: None,
                });
                self.send_servo_target(map.extrapolate_max_s);
            }
            cmd => {
                if let Err(e) = self.robot.send(&cmd) {
                    tracing::warn!("emulator: simulated robot refused {cmd:?}: {e}");
                }
            }
        }
    }

    /// Sends the servo command in force with its extrapolated target, unless that is the
    /// target sent last (a held target is latched already).
    fn send_servo_target(&mut self, extrapolate_max_s: f64) {
        let Some(servo) = &mut self.servo else {
            self.holding = false;
            return;
        };
        let since_s = servo.feedforward.since_valid_s(self.tick, CYCLE_S);
        let st = &mut self.servo_stats;
        let moving = servo.moving();
        // A small tolerance: since_s is a whole number of cycles × 2 ms.
        let held = moving && since_s > extrapolate_max_s + 1e-9;
        if held {
            st.held_cycles = st.held_cycles.saturating_add(1);
            if !self.holding {
                st.holds = st.holds.saturating_add(1);
            }
        } else if since_s > 0.0 {
            st.extrapolated_cycles = st.extrapolated_cycles.saturating_add(1);
        } else if since_s < 0.0 {
            st.early_cycles = st.early_cycles.saturating_add(1);
        }
        self.holding = held;
        let target = servo
            .feedforward
            .target(&servo.q, since_s, extrapolate_max_s);
        if servo.sent == Some(target) {
            return;
        }
        servo.sent = Some(target);
        let cmd = JointCommand::Servo {
            q: target,
            lookahead_s: servo.lookahead_s,
            gain: servo.gain,
        };
        if let Err(e) = self.robot.send(&cmd) {
            tracing::warn!("emulator: simulated robot refused {cmd:?}: {e}");
        }
    }
}

impl EmulatorBackend for SimBackend {
    fn awaits_command(&self, inputs: &InputRegisters) -> bool {
        let (Some(map), Some(servo)) = (self.program, &self.servo) else {
            return false;
        };
        let seq = inputs.int.get(usize::from(map.int_base) + 1).copied();
        servo.moving()
            && seq == self.last_seq
            && servo
                .feedforward
                .since_valid_s(self.tick.wrapping_add(1), CYCLE_S)
                > 0.0
    }

    fn servo_stats(&self) -> Option<ServoStats> {
        Some(self.servo_stats)
    }

    fn describe(&self) -> String {
        "simulated ur5e (SimRobot), register protocol (hrc_control or ur_rtde's control script)"
            .into()
    }

    fn output_handle(&mut self, name: &str) -> Option<(OutputHandle, FieldType)> {
        if let Some((i, t)) = self.fields.handle(name) {
            return Some((OutputHandle(i), t));
        }
        if let Some(n) = name
            .strip_prefix("output_int_register_")
            .and_then(|n| n.parse::<usize>().ok())
            .filter(|n| *n < 48)
        {
            // Our program's tick goes to output_int_register_<int_base>; ur_rtde's script
            // writes its own.
            return Some((OutputHandle(SIM_OUTPUT_INT_BASE + n), FieldType::Int32));
        }
        if let Some(n) = name
            .strip_prefix("output_double_register_")
            .and_then(|n| n.parse::<usize>().ok())
            .filter(|n| *n < 48)
        {
            return Some((OutputHandle(SIM_OUTPUT_DOUBLE_BASE + n), FieldType::Double));
        }
        let is_output_register = name.starts_with("output_int_register_")
            || name.starts_with("output_double_register_")
            || name.starts_with("output_bit_register");
        if is_output_register {
            let ty = known_field_type(name)?;
            let k = FieldType::ALL.iter().position(|t| *t == ty).unwrap_or(0);
            return Some((OutputHandle(SIM_ZERO_BASE + k), ty));
        }
        None
    }

    fn read_output(&self, handle: OutputHandle) -> Value {
        if handle.0 < SIM_ZERO_BASE {
            return self.fields.read(handle.0, &self.published, &self.io);
        }
        let h = handle.0;
        if (SIM_OUTPUT_INT_BASE..SIM_OUTPUT_INT_BASE + 48).contains(&h) {
            let ours = self
                .program
                .is_some_and(|m| usize::from(m.int_base) + SIM_OUTPUT_INT_BASE == h);
            let written = self
                .outputs
                .int
                .get(h - SIM_OUTPUT_INT_BASE)
                .copied()
                .unwrap_or(0);
            return Value::Int32(if ours { self.tick } else { written });
        }
        if (SIM_OUTPUT_DOUBLE_BASE..SIM_OUTPUT_DOUBLE_BASE + 48).contains(&h) {
            return Value::Double(
                self.outputs
                    .double
                    .get(h - SIM_OUTPUT_DOUBLE_BASE)
                    .copied()
                    .unwrap_or(0.0),
            );
        }
        Value::zero(
            FieldType::ALL
                .get(handle.0 - SIM_ZERO_BASE)
                .copied()
                .unwrap_or(FieldType::Double),
        )
    }

    fn step(&mut self, inputs: &InputRegisters) {
        self.run_program(inputs);
        self.run_ur_rtde(inputs);
        self.robot.step();
        let _ = self.robot.read_state(&mut self.published);
        self.io = inputs.io;
        self.fields.update(&self.published);
    }

    fn speed_slider(&mut self, fraction: f64) {
        if self.slider == Some(fraction) {
            return;
        }
        self.slider = Some(fraction);
        if let Err(e) = self.robot.set_target_speed_fraction(fraction) {
            tracing::warn!("emulator: speed slider {fraction} refused: {e}");
        }
    }

    fn load_program(&mut self, script: &str) -> bool {
        let Some(map) = RegisterMap::from_program(script) else {
            if let Some(ur_rtde) = UrRtdeScript::recognise(script) {
                // As on a controller, a new program replaces the one that runs; it starts
                // once the arm has stopped.
                if self.program_running() {
                    self.clear_programs();
                    self.robot.stop_program();
                }
                if self.robot.runtime_state() == crate::types::runtime_state::STOPPING {
                    self.pending_ur_rtde = Some(ur_rtde);
                    return true;
                }
                return self.start_ur_rtde(ur_rtde);
            }
            tracing::info!(
                "emulator: script is neither the hrc_control program nor ur_rtde's control \
                 script; ignored ({} bytes)",
                script.len()
            );
            return false;
        };
        self.ur_rtde = None;
        self.pending_ur_rtde = None;
        self.outputs = OutputRegisters::default();
        if !self.robot.play() {
            tracing::warn!(
                "emulator: program received but the robot cannot play (not running, or safety stop)"
            );
            return false;
        }
        tracing::info!("emulator: hrc_control program started ({map:?})");
        self.program = Some(map);
        self.program_start_cycle = self.robot.cycles();
        self.tick = 0;
        self.last_seq = None;
        self.servo = None;
        true
    }

    fn dashboard(&mut self, cmd: DashboardCommand) -> String {
        let failed = |c: DashboardCommand| format!("Failed to execute: {}", c.as_str());
        match cmd {
            DashboardCommand::PowerOn => {
                if self.robot.power_on() {
                    "Powering on".into()
                } else {
                    failed(cmd)
                }
            }
            DashboardCommand::PowerOff => {
                // As on a controller: the arm brakes to rest and a running program stops.
                self.robot.power_off();
                self.clear_programs();
                "Powering off".into()
            }
            DashboardCommand::BrakeRelease => {
                if self.robot.brake_release() {
                    "Brake releasing".into()
                } else {
                    failed(cmd)
                }
            }
            DashboardCommand::Play => {
                if (self.program_running() || self.urp.is_some()) && self.robot.play() {
                    "Starting program".into()
                } else {
                    failed(cmd)
                }
            }
            DashboardCommand::Pause => {
                self.robot.pause();
                "Pausing program".into()
            }
            DashboardCommand::Stop => {
                self.robot.stop_program();
                self.clear_programs();
                "Stopped".into()
            }
            DashboardCommand::SafetyStatus => {
                format!(
                    "Safetystatus: {}",
                    safety_status_name(self.published.safety_mode)
                )
            }
            DashboardCommand::RobotMode => {
                format!("Robotmode: {}", robot_mode_name(self.published.robot_mode))
            }
            DashboardCommand::UnlockProtectiveStop => {
                if self.robot.clear_protective_stop() {
                    "Protective stop releasing".into()
                } else {
                    "Cannot unlock protective stop: no protective stop active".into()
                }
            }
            DashboardCommand::CloseSafetyPopup => "closing safety popup".into(),
            DashboardCommand::IsInRemoteControl => self.remote_control.to_string(),
            DashboardCommand::Quit => "Disconnected".into(),
        }
    }

    fn runtime_state(&self) -> u32 {
        self.published.runtime_state
    }

    fn load_urp(&mut self, path: &str) -> bool {
        // As on a controller: loading is refused while a program plays.
        if self.published.runtime_state == crate::types::runtime_state::PLAYING {
            return false;
        }
        self.clear_programs();
        self.urp = Some(path.to_owned());
        true
    }

    fn loaded_program(&self) -> Option<&str> {
        self.urp.as_deref()
    }

    fn restart_safety(&mut self) -> bool {
        self.robot.clear_protective_stop();
        self.robot.clear_emergency_stop();
        self.robot.power_off();
        self.clear_programs();
        true
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

// ---------------------------------------------------------------------------------------------
// Trace-backed.

/// How a trace is resampled to the requested output frequency.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReplayMode {
    /// Each package carries the last recorded row at or before the virtual time, bit for bit
    /// (repeated when sampling faster than recorded).
    Hold,
    /// DOUBLE and vector-of-double fields are interpolated linearly between rows, and
    /// `timestamp` is the virtual time; integer fields are held.
    Interpolate,
}

#[derive(Debug, Clone, Copy)]
struct TraceColumn {
    ty: FieldType,
    cols: [usize; 6],
    /// An output register the trace did not record: served as 0, as a controller serves a
    /// register nothing writes.
    unrecorded_register: bool,
}

/// Backend streaming a recorded [`Trace`].
///
/// Playback starts at the first row when the first client starts streaming (the first
/// package that client receives is the first row), advances 2 ms per cycle, and holds the
/// last row after the end. Fields whose columns the trace lacks
/// (`name`, or `name_0..name_k` for vectors) are answered `NOT_FOUND`; so are names unknown
/// to RTDE. Commands, programs and inputs are ignored: the state evolves as recorded.
#[derive(Debug)]
pub struct TraceBackend {
    trace: Trace,
    mode: ReplayMode,
    columns: Vec<TraceColumn>,
    playing: bool,
    /// Set when playback starts: the next cycle (the one the first package is sampled in)
    /// shows the first row instead of advancing past it.
    at_start: bool,
    t: f64,
    row: usize,
}

impl TraceBackend {
    /// Plays `trace` (at least one row) in `mode`.
    pub fn new(trace: Trace, mode: ReplayMode) -> Result<Self> {
        let t = trace
            .timestamp(0)
            .ok_or_else(|| RobotIoError::InvalidConfig {
                reason: format!("trace {} has no rows", trace.source().display()),
            })?;
        Ok(Self {
            trace,
            mode,
            columns: Vec::new(),
            playing: false,
            at_start: false,
            t,
            row: 0,
        })
    }

    /// The replay mode.
    pub fn mode(&self) -> ReplayMode {
        self.mode
    }

    /// The trace played.
    pub fn trace(&self) -> &Trace {
        &self.trace
    }

    /// The row in force now.
    pub fn row(&self) -> usize {
        self.row
    }

    /// Whether the last row has been reached.
    pub fn finished(&self) -> bool {
        self.row + 1 >= self.trace.len()
    }

    fn value_at(&self, row: usize, col: usize) -> f64 {
        self.trace.value_at(row, col).unwrap_or(0.0)
    }
}

impl EmulatorBackend for TraceBackend {
    fn describe(&self) -> String {
        let mode = match self.mode {
            ReplayMode::Hold => "hold (recorded values repeated between rows, bit for bit)",
            ReplayMode::Interpolate => "interpolate (doubles linear between rows, integers held)",
        };
        format!(
            "trace replay of {} ({} rows): {mode}",
            self.trace.source().display(),
            self.trace.len()
        )
    }

    /// A recorded field, or an output register the trace lacks (0, as on a controller where
    /// nothing writes it: `RtdeRobot` subscribes to our program's tick register, which a
    /// replayed trace has no program to write). Any other field missing from the trace is
    /// `NOT_FOUND`.
    fn output_handle(&mut self, name: &str) -> Option<(OutputHandle, FieldType)> {
        let ty = known_field_type(name)?;
        let mut cols = [0usize; 6];
        let recorded = if ty.width() == 1 {
            self.trace.column_index(name).map(|c| cols[0] = c)
        } else {
            cols.iter_mut()
                .take(ty.width())
                .enumerate()
                .try_for_each(|(i, c)| {
                    *c = self.trace.column_index(&format!("{name}_{i}"))?;
                    Some(())
                })
        };
        let unrecorded_register = recorded.is_none();
        if unrecorded_register && !name.starts_with("output_") {
            return None;
        }
        self.columns.push(TraceColumn {
            ty,
            cols,
            unrecorded_register,
        });
        Some((OutputHandle(self.columns.len() - 1), ty))
    }

    fn read_output(&self, handle: OutputHandle) -> Value {
        let Some(c) = self.columns.get(handle.0) else {
            return Value::Double(0.0);
        };
        if c.unrecorded_register {
            return Value::zero(c.ty);
        }
        let w = c.ty.width();
        let mut v = [0.0f64; 6];
        let interpolate = self.mode == ReplayMode::Interpolate
            && matches!(
                c.ty,
                FieldType::Double | FieldType::Vector3d | FieldType::Vector6d
            );
        let next = self.row + 1;
        let t0 = self.trace.timestamp(self.row).unwrap_or(self.t);
        let alpha = match self.trace.timestamp(next) {
            Some(t1) if interpolate && t1 > t0 => ((self.t - t0) / (t1 - t0)).clamp(0.0, 1.0),
            _ => 0.0,
        };
        for (i, x) in v.iter_mut().take(w).enumerate() {
            let col = c.cols.get(i).copied().unwrap_or(0);
            let a = self.value_at(self.row, col);
            *x = if alpha > 0.0 {
                if col == 0 {
                    self.t
                } else {
                    a + alpha * (self.value_at(next, col) - a)
                }
            } else {
                a
            };
        }
        Value::from_components(c.ty, &v)
    }

    fn step(&mut self, _inputs: &InputRegisters) {
        if !self.playing {
            return;
        }
        if self.at_start {
            // The first cycle after the start is the trace's first row: a stream's first
            // package is sampled in this cycle, so advancing here skipped row 0.
            self.at_start = false;
            return;
        }
        self.t += CYCLE_S;
        while let Some(ts) = self.trace.timestamp(self.row + 1) {
            // Tolerance: recorded periods carry float noise (0.0999999999999 s).
            if ts <= self.t + 1e-9 {
                self.row += 1;
            } else {
                break;
            }
        }
    }

    fn stream_started(&mut self) {
        if !self.playing {
            tracing::info!("emulator: {}", self.describe());
            self.at_start = true;
        }
        self.playing = true;
    }

    fn load_program(&mut self, script: &str) -> bool {
        tracing::info!(
            "emulator: trace replay ignores scripts ({} bytes received)",
            script.len()
        );
        false
    }

    fn dashboard(&mut self, cmd: DashboardCommand) -> String {
        let field = |name: &str| self.trace.value(self.row, name).map(|v| v as i32);
        match cmd {
            DashboardCommand::SafetyStatus => {
                let mode = field("safety_mode")
                    .or_else(|| field("safety_status"))
                    .unwrap_or(1);
                format!("Safetystatus: {}", safety_status_name(mode))
            }
            DashboardCommand::RobotMode => {
                format!(
                    "Robotmode: {}",
                    robot_mode_name(field("robot_mode").unwrap_or(7))
                )
            }
            DashboardCommand::CloseSafetyPopup => "closing safety popup".into(),
            DashboardCommand::IsInRemoteControl => "true".into(),
            DashboardCommand::Quit => "Disconnected".into(),
            other => format!(
                "Failed to execute: {} (trace replay is read-only)",
                other.as_str()
            ),
        }
    }

    fn runtime_state(&self) -> u32 {
        self.trace
            .value(self.row, "runtime_state")
            .map_or(crate::types::runtime_state::STOPPED, |v| v as u32)
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

// ---------------------------------------------------------------------------------------------
// The world and the servers.

/// Where an output value comes from.
#[derive(Debug, Clone, Copy)]
enum Source {
    Backend(OutputHandle),
    InputInt(usize),
    InputDouble(usize),
    InputBit(usize),
}

/// Where an input value goes.
#[derive(Debug, Clone, Copy)]
enum Target {
    Int(usize),
    Double(usize),
    Bit(usize),
    /// `*_digital_output_mask` of a group (the bit offset in `actual_digital_output_bits`:
    /// 0 standard, 8 configurable, 16 tool).
    DigitalMask(u8),
    /// `*_digital_output` of a group (as [`Target::DigitalMask`]).
    DigitalValue(u8),
    /// `standard_analog_output_mask`.
    AnalogMask,
    /// `standard_analog_output_type`.
    AnalogType,
    /// `standard_analog_output_0` / `_1` [ratio].
    AnalogValue(usize),
    /// `speed_slider_mask`.
    SliderMask,
    /// `speed_slider_fraction` [-].
    SliderFraction,
    /// `input_bit_registers0_to_31` (0) / `32_to_63` (1).
    BitsLow(u8),
    /// A valid input the emulator accepts and ignores (external force/torque).
    Ignored,
}

/// The mask/value pairs of one input package, applied together after it is decoded.
#[derive(Debug, Clone, Copy, Default)]
struct PendingIo {
    digital_mask: [Option<u8>; 3],
    digital_value: [Option<u8>; 3],
    analog_mask: Option<u8>,
    analog_type: Option<u8>,
    analog_value: [Option<f64>; 2],
    slider_mask: Option<u32>,
    slider_fraction: Option<f64>,
}

#[derive(Debug)]
struct Stream {
    session: u64,
    recipe_id: u8,
    /// Protocol version 1: data packages carry no recipe id.
    v1: bool,
    sources: Vec<Source>,
    values: Vec<Value>,
    period_cycles: f64,
    next_cycle: f64,
    streaming: bool,
    tx: mpsc::Sender<Vec<u8>>,
    stalled_since: Option<Instant>,
}

#[derive(Debug)]
struct World {
    backend: Box<dyn EmulatorBackend>,
    inputs: InputRegisters,
    owners: HashMap<String, u64>,
    streams: Vec<Stream>,
    sessions: HashMap<u64, Arc<Notify>>,
    cycle: u64,
    silent: bool,
    /// Frozen by [`Emulator::pause`]: no cycle runs, nothing is sent.
    paused: bool,
    /// The clock's bookkeeping (cycles run, late, dropped, paused).
    clock: ClockStats,
    stall_timeout: Duration,
    /// The controller version (RTDE `v` and the dashboard's `PolyscopeVersion`).
    version: ControllerVersion,
    /// The dashboard server's own state.
    dash: DashboardState,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn register_index(name: &str, prefix: &str) -> Option<usize> {
    name.strip_prefix(prefix)?.parse().ok()
}

impl World {
    fn step(&mut self) {
        self.cycle += 1;
        self.inputs.cycle = self.cycle;
        self.backend.step(&self.inputs);
        let cycle = self.cycle as f64;
        let now = Instant::now();
        let mut dead = Vec::new();
        for s in self.streams.iter_mut().filter(|s| s.streaming) {
            if cycle < s.next_cycle {
                continue;
            }
            s.next_cycle += s.period_cycles;
            if self.silent {
                continue;
            }
            for (v, src) in s.values.iter_mut().zip(&s.sources) {
                *v = match *src {
                    Source::Backend(h) => self.backend.read_output(h),
                    Source::InputInt(i) => {
                        Value::Int32(self.inputs.int.get(i).copied().unwrap_or(0))
                    }
                    Source::InputDouble(i) => {
                        Value::Double(self.inputs.double.get(i).copied().unwrap_or(0.0))
                    }
                    Source::InputBit(i) => {
                        Value::Bool(self.inputs.bits >> (i.saturating_sub(64) & 63) & 1 == 1)
                    }
                };
            }
            let mut pkg = Vec::with_capacity(
                4 + s
                    .values
                    .iter()
                    .map(|v| v.field_type().size())
                    .sum::<usize>(),
            );
            if encode_data_package(s.recipe_id, &s.values, &mut pkg).is_err() {
                continue;
            }
            if s.v1 {
                strip_recipe_id(&mut pkg);
            }
            match s.tx.try_send(pkg) {
                Ok(()) => s.stalled_since = None,
                Err(mpsc::error::TrySendError::Full(_)) => {
                    let since = *s.stalled_since.get_or_insert(now);
                    if now.duration_since(since) > self.stall_timeout {
                        tracing::warn!(
                            "emulator: rtde client {} stopped reading; dropping it",
                            s.session
                        );
                        dead.push(s.session);
                    }
                }
                Err(mpsc::error::TrySendError::Closed(_)) => dead.push(s.session),
            }
        }
        for id in dead {
            self.end_session(id);
        }
    }

    fn end_session(&mut self, id: u64) {
        self.streams.retain(|s| s.session != id);
        self.owners.retain(|_, owner| *owner != id);
        if let Some(kill) = self.sessions.remove(&id) {
            kill.notify_one();
        }
    }

    fn output_source(&mut self, name: &str) -> Option<(Source, FieldType)> {
        if let Some(i) = register_index(name, "input_int_register_").filter(|i| *i < REGISTERS) {
            return Some((Source::InputInt(i), FieldType::Int32));
        }
        if let Some(i) = register_index(name, "input_double_register_").filter(|i| *i < REGISTERS) {
            return Some((Source::InputDouble(i), FieldType::Double));
        }
        if let Some(i) =
            register_index(name, "input_bit_register_").filter(|i| (64..128).contains(i))
        {
            return Some((Source::InputBit(i), FieldType::Bool));
        }
        self.backend
            .output_handle(name)
            .map(|(h, t)| (Source::Backend(h), t))
    }

    fn write_input(&mut self, target: Target, value: Value) {
        match (target, value) {
            (Target::Int(i), Value::Int32(v)) => {
                if let Some(r) = self.inputs.int.get_mut(i) {
                    *r = v;
                }
                if let Some(w) = self.inputs.int_written.get_mut(i) {
                    *w = self.cycle.max(1);
                }
            }
            (Target::Double(i), Value::Double(v)) => {
                if let Some(r) = self.inputs.double.get_mut(i) {
                    *r = v;
                }
            }
            (Target::Bit(i), Value::Bool(b)) => {
                let bit = 1u64 << (i.saturating_sub(64) & 63);
                if b {
                    self.inputs.bits |= bit;
                } else {
                    self.inputs.bits &= !bit;
                }
            }
            (Target::BitsLow(half), Value::Uint32(v)) => {
                let shift = if half == 0 { 0 } else { 32 };
                let low = &mut self.inputs.io.input_bits_low;
                *low = (*low & !(0xffff_ffffu64 << shift)) | (u64::from(v) << shift);
            }
            _ => {}
        }
    }

    /// Writes one decoded input package: registers at once, mask/value pairs together (a
    /// value without its mask in the same package changes nothing, as on a controller).
    fn write_package(&mut self, targets: &[(Target, FieldType)], values: &[Value]) {
        let mut p = PendingIo::default();
        let group = |g: u8| usize::from(g / 8).min(2);
        for ((t, _), v) in targets.iter().zip(values) {
            match (*t, *v) {
                (Target::DigitalMask(g), Value::Uint8(m)) => {
                    if let Some(x) = p.digital_mask.get_mut(group(g)) {
                        *x = Some(m);
                    }
                }
                (Target::DigitalValue(g), Value::Uint8(m)) => {
                    if let Some(x) = p.digital_value.get_mut(group(g)) {
                        *x = Some(m);
                    }
                }
                (Target::AnalogMask, Value::Uint8(m)) => p.analog_mask = Some(m),
                (Target::AnalogType, Value::Uint8(m)) => p.analog_type = Some(m),
                (Target::AnalogValue(i), Value::Double(x)) => {
                    if let Some(a) = p.analog_value.get_mut(i) {
                        *a = Some(x);
                    }
                }
                (Target::SliderMask, Value::Uint32(m)) => p.slider_mask = Some(m),
                (Target::SliderFraction, Value::Double(x)) => p.slider_fraction = Some(x),
                (t, v) => self.write_input(t, v),
            }
        }
        let io = &mut self.inputs.io;
        for (g, (m, v)) in p.digital_mask.iter().zip(&p.digital_value).enumerate() {
            if let (Some(m), Some(v)) = (m, v) {
                let shift = 8 * g;
                let (m, v) = (u64::from(*m) << shift, u64::from(*v) << shift);
                io.digital_outputs = (io.digital_outputs & !m) | (v & m);
            }
        }
        if let Some(mask) = p.analog_mask {
            for i in 0..2usize {
                if mask >> i & 1 == 0 {
                    continue;
                }
                if let Some(ty) = p.analog_type {
                    let bit = 1u8 << i;
                    io.analog_output_voltage = (io.analog_output_voltage & !bit) | (ty & bit);
                }
                if let (Some(x), Some(r)) = (
                    p.analog_value.get(i).copied().flatten(),
                    io.analog_output_ratio.get_mut(i),
                ) {
                    *r = x.clamp(0.0, 1.0);
                }
            }
        }
        if let (Some(m), Some(f)) = (p.slider_mask, p.slider_fraction)
            && m & 1 == 1
            && (0.0..=1.0).contains(&f)
        {
            self.backend.speed_slider(f);
        }
    }
}

fn input_target(name: &str) -> Option<(Target, FieldType)> {
    if let Some(i) = register_index(name, "input_int_register_").filter(|i| *i < REGISTERS) {
        return Some((Target::Int(i), FieldType::Int32));
    }
    if let Some(i) = register_index(name, "input_double_register_").filter(|i| *i < REGISTERS) {
        return Some((Target::Double(i), FieldType::Double));
    }
    if let Some(i) = register_index(name, "input_bit_register_").filter(|i| (64..128).contains(i)) {
        return Some((Target::Bit(i), FieldType::Bool));
    }
    let target = match name {
        "speed_slider_mask" => Target::SliderMask,
        "speed_slider_fraction" => Target::SliderFraction,
        "standard_digital_output_mask" => Target::DigitalMask(0),
        "standard_digital_output" => Target::DigitalValue(0),
        "configurable_digital_output_mask" => Target::DigitalMask(8),
        "configurable_digital_output" => Target::DigitalValue(8),
        "tool_digital_output_mask" => Target::DigitalMask(16),
        "tool_digital_output" => Target::DigitalValue(16),
        "standard_analog_output_mask" => Target::AnalogMask,
        "standard_analog_output_type" => Target::AnalogType,
        "standard_analog_output_0" => Target::AnalogValue(0),
        "standard_analog_output_1" => Target::AnalogValue(1),
        "input_bit_registers0_to_31" => Target::BitsLow(0),
        "input_bit_registers32_to_63" => Target::BitsLow(1),
        "external_force_torque" => Target::Ignored,
        _ => return None,
    };
    known_field_type(name).map(|t| (target, t))
}

/// A running emulator. Dropping it stops every server.
#[derive(Debug)]
pub struct Emulator {
    world: Arc<Mutex<World>>,
    tasks: Vec<JoinHandle<()>>,
    /// The clock thread, when it has one ([`clock_on_own_thread`]), joined by
    /// [`Emulator::shutdown`].
    clock: Mutex<Option<std::thread::JoinHandle<()>>>,
    /// Tells the clock thread to end.
    clock_stop: Arc<AtomicBool>,
    /// `true` while paused ([`Emulator::pause`]); every server waits on it.
    pause: watch::Sender<bool>,
    rtde: SocketAddr,
    dashboard: SocketAddr,
    secondary: SocketAddr,
    realtime: SocketAddr,
    programs: Arc<AtomicU64>,
    /// How the clock thread runs, once it has started (`None` for a tokio-task clock).
    clock_scheduling: Arc<std::sync::OnceLock<crate::realtime::Scheduling>>,
}

async fn bind(ip: IpAddr, port: u16, what: &str) -> Result<TcpListener> {
    TcpListener::bind(SocketAddr::new(ip, port))
        .await
        .map_err(|source| RobotIoError::Io {
            context: format!("binding the {what} port {ip}:{port}"),
            source,
        })
}

fn local(l: &TcpListener) -> Result<SocketAddr> {
    l.local_addr().map_err(|source| RobotIoError::Io {
        context: "reading a bound address".into(),
        source,
    })
}

impl Emulator {
    /// Binds every port and starts serving. Must be called inside a tokio runtime.
    pub async fn start(cfg: EmulatorConfig, backend: Box<dyn EmulatorBackend>) -> Result<Emulator> {
        if cfg.speedup == 0 || cfg.queue_packages == 0 {
            return Err(RobotIoError::InvalidConfig {
                reason: "speedup and queue_packages must be at least 1".into(),
            });
        }
        if cfg.speedup == 1 && cfg.wait_for_client.is_some() {
            return Err(RobotIoError::InvalidConfig {
                reason: "wait_for_client needs speedup > 1: at speedup 1 the clock is a \
                         controller's real-time clock, which never waits for a client"
                    .into(),
            });
        }
        if cfg.speedup > MAX_SPEEDUP {
            return Err(RobotIoError::InvalidConfig {
                reason: format!(
                    "speedup must be at most {MAX_SPEEDUP}, got {}: each 2 ms tick runs that \
                     many controller cycles",
                    cfg.speedup
                ),
            });
        }
        let rtde = bind(cfg.bind, cfg.rtde_port, "rtde").await?;
        let dash = bind(cfg.bind, cfg.dashboard_port, "dashboard").await?;
        let sec = bind(cfg.bind, cfg.secondary_port, "secondary").await?;
        let rt = bind(cfg.bind, cfg.realtime_port, "real-time").await?;
        let (rtde_addr, dash_addr, sec_addr, rt_addr) =
            (local(&rtde)?, local(&dash)?, local(&sec)?, local(&rt)?);
        let mut owners = HashMap::new();
        for name in &cfg.preclaimed_inputs {
            owners.insert(name.clone(), 0);
        }
        let world = Arc::new(Mutex::new(World {
            backend,
            inputs: InputRegisters::default(),
            owners,
            streams: Vec::new(),
            sessions: HashMap::new(),
            cycle: 0,
            silent: false,
            paused: false,
            clock: ClockStats::default(),
            stall_timeout: cfg.stall_timeout,
            version: cfg.controller_version,
            dash: DashboardState::default(),
        }));
        let cfg = Arc::new(cfg);
        let programs = Arc::new(AtomicU64::new(0));
        let (pause, paused) = watch::channel(false);
        let clock_stop = Arc::new(AtomicBool::new(false));
        let mut ticker = Clock::new(world.clone(), cfg.speedup);
        ticker.wait = cfg.wait_for_client.map(ClientWait::new);
        let clock_scheduling = Arc::new(std::sync::OnceLock::new());
        let (clock, clock_task) =
            if cfg.clock_priority.is_some() || clock_on_own_thread(cfg.speedup) {
                let stop = clock_stop.clone();
                let (priority, scheduling) = (cfg.clock_priority, clock_scheduling.clone());
                let thread = std::thread::Builder::new()
                    .name("emulator-clock".into())
                    .spawn(move || {
                        let got = crate::realtime::set_current_thread_opt(priority);
                        if let crate::realtime::Scheduling::Refused { .. } = got {
                            tracing::warn!("emulator clock: {got}");
                        }
                        let _ = scheduling.set(got);
                        clock_thread(ticker, stop)
                    })
                    .map_err(|source| RobotIoError::Io {
                        context: "starting the emulator's clock thread".into(),
                        source,
                    })?;
                (Some(thread), None)
            } else {
                (None, Some(tokio::spawn(clock_task(ticker))))
            };
        let mut tasks = vec![
            tokio::spawn(serve_rtde(rtde, world.clone(), cfg.clone(), paused.clone())),
            tokio::spawn(serve_dashboard(dash, world.clone(), paused.clone())),
            tokio::spawn(serve_script(
                sec,
                world.clone(),
                programs.clone(),
                paused.clone(),
            )),
            tokio::spawn(serve_script(rt, world.clone(), programs.clone(), paused)),
        ];
        tasks.extend(clock_task);
        tracing::info!(
            "emulator: rtde {rtde_addr}, dashboard {dash_addr}, script {sec_addr} / {rt_addr}: {}",
            lock(&world).backend.describe()
        );
        Ok(Emulator {
            world,
            tasks,
            clock: Mutex::new(clock),
            clock_stop,
            pause,
            rtde: rtde_addr,
            dashboard: dash_addr,
            secondary: sec_addr,
            realtime: rt_addr,
            programs,
            clock_scheduling,
        })
    }

    /// How the clock thread is scheduled ([`EmulatorConfig::clock_priority`]); `None` while it
    /// has not started yet, or when the clock is a tokio task.
    pub fn clock_scheduling(&self) -> Option<crate::realtime::Scheduling> {
        self.clock_scheduling.get().cloned()
    }

    /// Bound RTDE address.
    pub fn rtde_addr(&self) -> SocketAddr {
        self.rtde
    }

    /// Bound dashboard address.
    pub fn dashboard_addr(&self) -> SocketAddr {
        self.dashboard
    }

    /// Bound secondary-interface (script) address.
    pub fn secondary_addr(&self) -> SocketAddr {
        self.secondary
    }

    /// Bound real-time-interface (script) address.
    pub fn realtime_addr(&self) -> SocketAddr {
        self.realtime
    }

    /// Virtual controller cycles run so far.
    pub fn cycle(&self) -> u64 {
        lock(&self.world).cycle
    }

    /// How the virtual clock kept up with wall time: cycles run, run late (catching up),
    /// dropped (beyond the per-wake bound) and skipped while paused, all read at once.
    pub fn clock_stats(&self) -> ClockStats {
        lock(&self.world).clock
    }

    /// What happened to our control program's servo commands so far ([`ServoStats`]); `None`
    /// when the backend does not run the program (trace replay).
    pub fn servo_stats(&self) -> Option<ServoStats> {
        lock(&self.world).backend.servo_stats()
    }

    /// Scripts received on the script ports so far.
    pub fn scripts_received(&self) -> u64 {
        self.programs.load(Ordering::Relaxed)
    }

    /// Open RTDE sessions.
    pub fn rtde_sessions(&self) -> usize {
        lock(&self.world).sessions.len()
    }

    /// Closes every RTDE connection (a cut link, as seen by clients).
    pub fn cut_rtde_links(&self) {
        let mut w = lock(&self.world);
        let ids: Vec<u64> = w.sessions.keys().copied().collect();
        for id in ids {
            w.end_session(id);
        }
    }

    /// While `silent`, no data package is sent (connections stay open): a link that stalls.
    pub fn set_rtde_silent(&self, silent: bool) {
        lock(&self.world).silent = silent;
    }

    /// The input registers as clients last wrote them (a copy).
    pub fn inputs(&self) -> InputRegisters {
        lock(&self.world).inputs.clone()
    }

    /// Runs `f` on the backend (under the world lock: keep it short).
    pub fn with_backend<R>(&self, f: impl FnOnce(&mut dyn EmulatorBackend) -> R) -> R {
        f(lock(&self.world).backend.as_mut())
    }

    /// Runs `f` on the [`SimBackend`], if that is the backend.
    pub fn with_sim<R>(&self, f: impl FnOnce(&mut SimBackend) -> R) -> Option<R> {
        self.with_backend(|b| b.as_any_mut().downcast_mut::<SimBackend>().map(f))
    }

    /// Runs `f` on the [`TraceBackend`], if that is the backend.
    pub fn with_trace<R>(&self, f: impl FnOnce(&mut TraceBackend) -> R) -> Option<R> {
        self.with_backend(|b| b.as_any_mut().downcast_mut::<TraceBackend>().map(f))
    }

    /// Freezes the controller, as `kill -STOP` would (a test hook for link loss): no cycle
    /// runs (the virtual clock, the watchdog and the arm stand still) and nothing is sent;
    /// connections stay open, and what clients send (inputs, handshakes, scripts, dashboard
    /// commands) waits, unanswered, until [`Emulator::resume`]. New connections are accepted
    /// (by the kernel, as for a stopped process) but not served.
    pub fn pause(&self) {
        lock(&self.world).paused = true;
        self.pause.send_replace(true);
    }

    /// Ends a [`Emulator::pause`]: the clock runs on from where it stopped and waiting
    /// requests are served in order.
    pub fn resume(&self) {
        lock(&self.world).paused = false;
        self.pause.send_replace(false);
    }

    /// Whether the emulator is paused.
    pub fn is_paused(&self) -> bool {
        *self.pause.borrow()
    }

    /// Stops every server and closes every connection (a killed controller: the ports close,
    /// reconnects are refused). Idempotent.
    pub fn shutdown(&self) {
        self.cut_rtde_links();
        for t in &self.tasks {
            t.abort();
        }
        self.clock_stop.store(true, Ordering::Release);
        let handle = self.clock.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(h) = handle {
            // The clock thread sleeps at most one cycle (< 1 ms) before it sees the flag.
            let _ = h.join();
        }
    }
}

/// Waits until the emulator is not paused.
async fn running(paused: &mut watch::Receiver<bool>) {
    // An error means the emulator is gone: nothing to wait for.
    let _ = paused.wait_for(|p| !*p).await;
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// One controller cycle [ns] (at speedup 1).
const CYCLE_NS: u64 = 2_000_000;

/// Wall time since the start at which cycle `n` is due at `speedup`: n · 2 ms / speedup.
fn cycle_due_at(n: u64, speedup: u64) -> Duration {
    let ns = u128::from(n) * u128::from(CYCLE_NS) / u128::from(speedup.max(1));
    Duration::from_nanos(u64::try_from(ns).unwrap_or(u64::MAX))
}

/// Cycle periods at least this long [ns] are slept on tokio's timer (its resolution is 1 ms);
/// shorter ones on an OS thread.
const TOKIO_TIMER_NS: u64 = 1_000_000;

/// Whether the clock at `speedup` needs its own OS thread: a cycle period (2 ms / speedup)
/// shorter than tokio's 1 ms timer resolution, i.e. speedup 3 and up.
pub fn clock_on_own_thread(speedup: u32) -> bool {
    CYCLE_NS / u64::from(speedup.max(1)) < TOKIO_TIMER_NS
}

/// The emulator's clock: cycle n is due at start + n · 2 ms / speedup (absolute, so lateness
/// does not accumulate as it did with a delayed interval: under load the virtual clock ran at
/// 0.56–0.85 of wall time). Each wake runs one cycle; a backlog after a late wake is worked
/// off by waking a little early ([`Slew`]), and only what exceeds [`slew_window`] runs at
/// once, within [`max_cycles_per_wake`]; while paused, due cycles are skipped and counted as
/// paused.
///
/// One cycle per wake is what a client sees from a real controller: one sample every cycle
/// period and the rest of the period to answer. Until issue 10 the clock ran `speedup` cycles
/// in a burst every 2 ms on tokio's 1 ms timer, so at `--speedup 4` every command met 0–3
/// cycles the program had already run without it, varying from command to command (the
/// executed jerk showed it; `BENCHMARKS.md`, emulator clock). It sleeps on tokio's timer
/// where that resolves the period (speedup 1 and 2: the timer wakes a worker that then sends
/// the samples itself) and on its own OS thread (`emulator-clock`) where it does not
/// ([`clock_on_own_thread`]; one more thread wake per cycle, which at speedup 1 measurably
/// delayed the samples: BENCHMARKS.md).
struct Clock {
    world: Arc<Mutex<World>>,
    per: u64,
    max: u64,
    window: u64,
    start: Instant,
    /// Cycles run, dropped, paused or waited [cycles].
    done: u64,
    slew: Slew,
    /// Waiting for a late client (sped-up clocks only; `None`: never).
    wait: Option<ClientWait>,
}

impl Clock {
    fn new(world: Arc<Mutex<World>>, speedup: u32) -> Clock {
        Clock {
            world,
            per: u64::from(speedup.max(1)),
            max: max_cycles_per_wake(speedup),
            window: slew_window(speedup),
            start: Instant::now(),
            done: 0,
            slew: Slew::default(),
            wait: None,
        }
    }

    /// When the next cycle is due: its own time, or earlier while slewing a lag.
    fn next_due(&self) -> Instant {
        let v = self.slew.next_due(self.done);
        let secs = v * (CYCLE_NS as f64 / 1e9) / self.per as f64;
        // Out of range only after centuries; waking now is then harmless (wake runs what is
        // due, if anything).
        Duration::try_from_secs_f64(secs)
            .ok()
            .and_then(|d| self.start.checked_add(d))
            .unwrap_or_else(Instant::now)
    }

    /// Runs the cycles due now (see [`Clock`]).
    fn wake(&mut self) {
        let elapsed = self.start.elapsed().as_nanos();
        let scaled = elapsed.saturating_mul(u128::from(self.per));
        let due = u64::try_from(scaled / u128::from(CYCLE_NS))
            .unwrap_or(u64::MAX)
            .max(self.done);
        // Fractional cycles elapsed, for the slew (f64 holds them exactly enough: 2^53 cycles).
        let v = scaled as f64 / CYCLE_NS as f64;
        let done = self.done;
        let mut w = lock(&self.world);
        w.clock.cycles_elapsed = due;
        if w.paused {
            w.clock.cycles_paused += due - done;
            w.clock.cycles_behind = 0;
            self.done = due;
            self.slew.reset();
            return;
        }
        if let Some(wait) = self.wait.as_mut().filter(|_| due > done) {
            let awaits = w.backend.awaits_command(&w.inputs);
            match wait.decide(awaits, Instant::now()) {
                WaitDecision::Run => {}
                WaitDecision::TimedOut => w.clock.waits_timed_out += 1,
                WaitDecision::Wait { began } => {
                    // As while paused: the due cycles are not run, virtual time stands still.
                    w.clock.waits += u64::from(began);
                    w.clock.cycles_waited += due - done;
                    w.clock.cycles_behind = 0;
                    self.done = due;
                    self.slew.reset();
                    return;
                }
            }
        }
        let allowance = self.slew.on_wake(v, done, self.window);
        let plan = plan_ticks(due, done, self.max, allowance);
        self.done = due - plan.behind;
        w.clock.max_behind_cycles = w.clock.max_behind_cycles.max(due - done);
        let burst = plan.run > 1;
        let holds = |w: &World| w.backend.servo_stats().map_or(0, |s| s.holds);
        let holds_before = if burst { holds(&w) } else { 0 };
        for _ in 0..plan.run {
            w.step();
        }
        if burst {
            w.clock.bursts += 1;
            w.clock.holds_in_bursts += holds(&w).saturating_sub(holds_before);
        }
        w.clock.cycles_run += plan.run;
        w.clock.cycles_late += plan.late;
        w.clock.cycles_dropped += plan.dropped;
        w.clock.cycles_behind = plan.behind;
        if plan.behind > 0 {
            w.clock.cycles_slewed += plan.run;
        }
        if plan.dropped > 0 {
            tracing::warn!(
                "emulator: clock {} ms behind wall time; dropped {} cycles (at most {} \
                 cycles caught up per wake)",
                cycle_due_at(due - done, self.per).as_millis(),
                plan.dropped,
                self.max
            );
        }
    }
}

/// The clock on its own OS thread, until `stop`.
fn clock_thread(mut clock: Clock, stop: Arc<AtomicBool>) {
    while !stop.load(Ordering::Acquire) {
        if let Some(wait) = clock.next_due().checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        clock.wake();
    }
}

/// The clock as a tokio task (aborted with the emulator's other tasks).
async fn clock_task(mut clock: Clock) {
    loop {
        tokio::time::sleep_until(tokio::time::Instant::from_std(clock.next_due())).await;
        clock.wake();
    }
}

async fn serve_rtde(
    listener: TcpListener,
    world: Arc<Mutex<World>>,
    cfg: Arc<EmulatorConfig>,
    paused: watch::Receiver<bool>,
) {
    let next_id = AtomicU64::new(1);
    loop {
        let Ok((stream, peer)) = listener.accept().await else {
            continue;
        };
        let id = next_id.fetch_add(1, Ordering::Relaxed);
        tracing::debug!("emulator: rtde client {id} from {peer}");
        tokio::spawn(rtde_session(
            stream,
            id,
            world.clone(),
            cfg.clone(),
            paused.clone(),
        ));
    }
}

async fn read_client_package(
    r: &mut BufReader<tokio::net::tcp::OwnedReadHalf>,
    buf: &mut Vec<u8>,
) -> std::io::Result<()> {
    let mut size = [0u8; 2];
    r.read_exact(&mut size).await?;
    let n = usize::from(u16::from_be_bytes(size));
    buf.clear();
    buf.extend_from_slice(&size);
    buf.resize(n.max(2), 0);
    if let Some(rest) = buf.get_mut(2..) {
        r.read_exact(rest).await?;
    }
    Ok(())
}

/// Protocol version 1's output frequency [Hz] (version 1 has no frequency field).
pub const V1_FREQUENCY_HZ: f64 = 125.0;

/// Removes the recipe id (byte 3) from an encoded package and fixes its size: protocol
/// version 1's data packages and output setup replies carry none.
fn strip_recipe_id(pkg: &mut Vec<u8>) {
    if pkg.len() > 3 {
        pkg.remove(3);
        let n = u16::try_from(pkg.len()).unwrap_or(u16::MAX).to_be_bytes();
        if let Some(size) = pkg.get_mut(..2) {
            size.copy_from_slice(&n);
        }
    }
}

/// A package sent as protocol version 1 encodes it: output setup request without
/// frequency, data packages without recipe id. Returns the package rewritten to version 2's
/// layout (so [`ClientPackage::decode`] reads it), with `last_input` as the recipe id of a
/// data package.
fn v1_to_v2(buf: &[u8], last_input: u8) -> Option<Vec<u8>> {
    let kind = *buf.get(2)?;
    let payload = buf.get(3..)?;
    let mut out = vec![0, 0, kind];
    match kind {
        crate::codec::kind::SETUP_OUTPUTS => {
            out.extend_from_slice(&V1_FREQUENCY_HZ.to_be_bytes());
        }
        crate::codec::kind::DATA_PACKAGE => out.push(last_input),
        _ => return None,
    }
    out.extend_from_slice(payload);
    let n = u16::try_from(out.len()).ok()?.to_be_bytes();
    out.get_mut(..2)?.copy_from_slice(&n);
    Some(out)
}

/// Encodes a text message as protocol version 1 does: level, then the message.
fn v1_text(message: &str, level: u8) -> Vec<u8> {
    let bytes = message.as_bytes();
    let body = bytes
        .get(..bytes.len().min(u16::MAX as usize - 4))
        .unwrap_or_default();
    let mut out = Vec::with_capacity(4 + body.len());
    let n = u16::try_from(4 + body.len()).unwrap_or(u16::MAX);
    out.extend_from_slice(&n.to_be_bytes());
    out.push(crate::codec::kind::TEXT_MESSAGE);
    out.push(level);
    out.extend_from_slice(body);
    out
}

/// The field names of a setup request's comma-separated list. One trailing comma is
/// ignored, as a controller ignores it: ur_rtde ends every list with one
/// (`"timestamp,actual_q,"`), and the reply has one type per real name. Any other empty name
/// (`"a,,b"`, an empty list) stays a name, answered `NOT_FOUND`.
fn field_names(names: &str) -> std::str::Split<'_, char> {
    names.strip_suffix(',').unwrap_or(names).split(',')
}

fn reply(tx: &mpsc::Sender<Vec<u8>>, pkg: ControllerPackage<'_>) -> bool {
    let mut out = Vec::new();
    pkg.encode(&mut out).is_ok() && tx.try_send(out).is_ok()
}

async fn rtde_session(
    stream: TcpStream,
    id: u64,
    world: Arc<Mutex<World>>,
    cfg: Arc<EmulatorConfig>,
    mut paused: watch::Receiver<bool>,
) {
    let _ = stream.set_nodelay(true);
    let (r, mut w) = stream.into_split();
    let mut r = BufReader::new(r);
    let (tx, mut rx) = mpsc::channel::<Vec<u8>>(cfg.queue_packages);
    let kill = Arc::new(Notify::new());
    lock(&world).sessions.insert(id, kill.clone());
    let mut writer = tokio::spawn(async move {
        while let Some(pkg) = rx.recv().await {
            if w.write_all(&pkg).await.is_err() {
                break;
            }
        }
        let _ = w.shutdown().await;
    });
    let mut buf = Vec::with_capacity(4096);
    // Output and input recipes are numbered separately, each from 1, as a controller numbers
    // them (ur_rtde expects its first input recipe to be 1 after an output recipe). A refused
    // recipe gets id 0 and consumes no id.
    let mut next_output_recipe: u8 = 1;
    let mut next_input_recipe: u8 = 1;
    let mut inputs: HashMap<u8, Vec<(Target, FieldType)>> = HashMap::new();
    let mut decoded: Vec<Value> = Vec::new();
    // The protocol version negotiated (2 until a client asks for 1; both are served, as
    // UR's guide describes them).
    let mut version: u16 = PROTOCOL_VERSION;
    let mut last_input: u8 = 0;
    loop {
        tokio::select! {
            () = kill.notified() => break,
            r = read_client_package(&mut r, &mut buf) => if r.is_err() { break },
        }
        // Paused: the package waits, unanswered (a stopped controller process).
        tokio::select! {
            () = kill.notified() => break,
            () = running(&mut paused) => {}
        }
        let v1 = version == 1;
        let rewritten = if v1 { v1_to_v2(&buf, last_input) } else { None };
        let bytes: &[u8] = rewritten.as_deref().unwrap_or(&buf);
        let pkg = match ClientPackage::decode(bytes) {
            Ok(p) => p,
            Err(e) => {
                tracing::warn!("emulator: rtde client {id} sent a bad package ({e}); closing");
                break;
            }
        };
        let ok = match pkg {
            ClientPackage::RequestProtocolVersion { version: asked } => {
                let ok = asked == 1 || asked == PROTOCOL_VERSION;
                if ok {
                    version = asked;
                }
                reply(&tx, ControllerPackage::ProtocolVersionAccepted(ok))
            }
            ClientPackage::GetControllerVersion => reply(
                &tx,
                ControllerPackage::ControllerVersion(cfg.controller_version),
            ),
            ClientPackage::SetupOutputs {
                frequency_hz,
                names,
            } => {
                let mut w = lock(&world);
                let mut types = Vec::new();
                let mut sources = Vec::new();
                for name in field_names(names) {
                    match w.output_source(name) {
                        Some((s, t)) => {
                            sources.push(s);
                            types.push(t.as_str());
                        }
                        None => types.push("NOT_FOUND"),
                    }
                }
                let valid_freq = frequency_hz > 0.0 && frequency_hz <= MAX_FREQUENCY_HZ;
                let accepted = valid_freq && sources.len() == types.len();
                let recipe_id = if accepted { next_output_recipe } else { 0 };
                if accepted {
                    next_output_recipe = next_output_recipe.wrapping_add(1).max(1);
                    // Version 2: every accepted recipe streams (several on one connection);
                    // version 1 has one output recipe, which a new setup replaces.
                    if v1 {
                        w.streams.retain(|s| s.session != id);
                    }
                    let values = sources.iter().map(|_| Value::Double(0.0)).collect();
                    w.streams.push(Stream {
                        session: id,
                        recipe_id,
                        v1,
                        sources,
                        values,
                        period_cycles: 1.0 / (frequency_hz * CYCLE_S),
                        next_cycle: 0.0,
                        streaming: false,
                        tx: tx.clone(),
                        stalled_since: None,
                    });
                }
                drop(w);
                let types = types.join(",");
                let mut out = Vec::new();
                let pkg = ControllerPackage::SetupOutputsReply {
                    recipe_id,
                    types: &types,
                };
                if pkg.encode(&mut out).is_ok() {
                    if v1 {
                        strip_recipe_id(&mut out);
                    }
                    tx.try_send(out).is_ok()
                } else {
                    false
                }
            }
            ClientPackage::SetupInputs { names } => {
                let mut w = lock(&world);
                let mut types = Vec::new();
                let mut targets = Vec::new();
                let mut refused = false;
                for name in field_names(names) {
                    match (input_target(name), w.owners.get(name)) {
                        (None, _) => {
                            types.push("NOT_FOUND");
                            refused = true;
                        }
                        (Some(_), Some(owner)) if *owner != id => {
                            types.push("IN_USE");
                            refused = true;
                        }
                        (Some((t, ty)), _) => {
                            types.push(ty.as_str());
                            targets.push((t, ty));
                        }
                    }
                }
                let recipe_id = if refused { 0 } else { next_input_recipe };
                if !refused {
                    next_input_recipe = next_input_recipe.wrapping_add(1).max(1);
                    for name in field_names(names) {
                        w.owners.insert(name.to_owned(), id);
                    }
                    inputs.insert(recipe_id, targets);
                    last_input = recipe_id;
                }
                drop(w);
                let types = types.join(",");
                reply(
                    &tx,
                    ControllerPackage::SetupInputsReply {
                        recipe_id,
                        types: &types,
                    },
                )
            }
            ClientPackage::Start => {
                let mut w = lock(&world);
                let cycle = w.cycle as f64;
                let streams = w.streams.iter().any(|s| s.session == id);
                // A client with only input recipes (ur_rtde's RTDEIOInterface) starts too.
                let has = streams || !inputs.is_empty();
                // Reply first, so the client sees it before any data.
                let ok = reply(&tx, ControllerPackage::StartAccepted(has));
                if streams {
                    w.backend.stream_started();
                    let msg = w.backend.describe();
                    let cut = msg
                        .char_indices()
                        .map(|(i, c)| i + c.len_utf8())
                        .take_while(|e| *e <= 255)
                        .last()
                        .unwrap_or(0);
                    let trimmed = msg.get(..cut).unwrap_or("");
                    if v1 {
                        let _ = tx.try_send(v1_text(trimmed, level::INFO));
                    } else {
                        reply(
                            &tx,
                            ControllerPackage::Text(TextMessage {
                                message: trimmed,
                                source: "emulator",
                                level: level::INFO,
                            }),
                        );
                    }
                    for s in w.streams.iter_mut().filter(|s| s.session == id) {
                        s.streaming = true;
                        s.next_cycle = cycle + 1.0;
                    }
                }
                ok
            }
            ClientPackage::Pause => {
                let mut w = lock(&world);
                for s in w.streams.iter_mut().filter(|s| s.session == id) {
                    s.streaming = false;
                }
                reply(&tx, ControllerPackage::PauseAccepted(true))
            }
            ClientPackage::Data(d) => {
                if let Some(targets) = inputs.get(&d.recipe_id) {
                    decoded.clear();
                    let mut at = 0;
                    let mut ok = true;
                    for (_, ty) in targets {
                        match Value::decode(*ty, d.payload, at) {
                            Ok(v) => decoded.push(v),
                            Err(_) => ok = false,
                        }
                        at += ty.size();
                    }
                    if ok && at == d.payload.len() {
                        lock(&world).write_package(targets, &decoded);
                    } else {
                        tracing::warn!(
                            "emulator: rtde client {id} sent a malformed input package; ignored"
                        );
                    }
                } else {
                    tracing::warn!(
                        "emulator: rtde client {id} sent inputs for unknown recipe {}",
                        d.recipe_id
                    );
                }
                true
            }
            ClientPackage::Text(t) => {
                tracing::info!("emulator: rtde client {id} says: {}", t.message);
                true
            }
        };
        if !ok {
            tracing::warn!("emulator: rtde client {id} is not reading; closing");
            break;
        }
    }
    lock(&world).end_session(id);
    drop(tx);
    // The writer ends when every sender (ours and the world's stream) is gone.
    if tokio::time::timeout(Duration::from_secs(1), &mut writer)
        .await
        .is_err()
    {
        // Blocked on a client that does not read: give up on it.
        writer.abort();
    }
}

async fn serve_dashboard(
    listener: TcpListener,
    world: Arc<Mutex<World>>,
    paused: watch::Receiver<bool>,
) {
    // Shared by every connection: a per-connection budget does not bound a client that
    // reconnects (see `dashboard_budget`).
    let budget = Arc::new(Mutex::new(LineBudget::default()));
    let open = Arc::new(tokio::sync::Semaphore::new(MAX_DASHBOARD_CONNECTIONS));
    loop {
        let Ok((mut stream, _)) = listener.accept().await else {
            continue;
        };
        let Ok(permit) = open.clone().try_acquire_owned() else {
            tracing::debug!(
                "emulator: dashboard connection refused: {MAX_DASHBOARD_CONNECTIONS} open"
            );
            tokio::spawn(async move {
                let reply = format!(
                    "Too many dashboard connections ({MAX_DASHBOARD_CONNECTIONS} open); closing\n"
                );
                let _ = tokio::time::timeout(
                    Duration::from_millis(100),
                    stream.write_all(reply.as_bytes()),
                )
                .await;
            });
            continue;
        };
        let world = world.clone();
        let budget = budget.clone();
        let mut paused = paused.clone();
        tokio::spawn(async move {
            let _open = permit;
            running(&mut paused).await;
            let (r, mut w) = stream.into_split();
            let mut r = BufReader::new(r);
            let mut bytes = Vec::with_capacity(256);
            if w.write_all(b"Connected: Universal Robots Dashboard Server\n")
                .await
                .is_err()
            {
                return;
            }
            loop {
                let read = read_dashboard_line(&mut r, &mut bytes, MAX_DASHBOARD_LINE).await;
                running(&mut paused).await;
                let line = match read {
                    Ok(DashboardLine::Line) => String::from_utf8_lossy(&bytes),
                    Ok(DashboardLine::TooLong { ended }) => {
                        let reply = format!(
                            "could not understand: line longer than {MAX_DASHBOARD_LINE} bytes \
                             (discarded)\n"
                        );
                        if w.write_all(reply.as_bytes()).await.is_err() {
                            break;
                        }
                        if !ended && skip_dashboard_line(&mut r).await.is_err() {
                            break;
                        }
                        pipelined_wait(&r, &budget).await;
                        continue;
                    }
                    Ok(DashboardLine::Eof) | Err(_) => break,
                };
                let (reply, quit) = dashboard_reply(&mut lock(&world), &line);
                if w.write_all(format!("{reply}\n").as_bytes()).await.is_err() || quit {
                    break;
                }
                // One line, then the other tasks' turn: lines already buffered are read without
                // touching the socket, so a client streaming lines would keep a worker until
                // tokio's budget of socket operations ran out. With four clients streaming
                // garbage lines (BENCHMARKS.md, "The emulator under hostile clients"), a
                // well-behaved client's 200 round trips took at worst 4.8–6.7 × their quiet
                // time with this yield (three runs), 10.7 and 12 × without it (two runs).
                tokio::task::yield_now().await;
                pipelined_wait(&r, &budget).await;
            }
        });
    }
}

/// When the client's next line is already buffered (it was sent before the reply to the last
/// one was read: pipelined), waits for a token of the shared [`LineBudget`]. Meanwhile the
/// socket is not read, so a flooding client is held back by TCP's flow control; a
/// request/reply client, whose buffer is empty after each line, never waits here.
async fn pipelined_wait<R: tokio::io::AsyncRead>(r: &BufReader<R>, budget: &Mutex<LineBudget>) {
    if r.buffer().is_empty() {
        return;
    }
    loop {
        let wait = lock(budget).take(Instant::now());
        match wait {
            None => return,
            Some(d) => tokio::time::sleep(d).await,
        }
    }
}

/// The dashboard server's state beyond the backend's: what PolyScope keeps per controller.
#[derive(Debug, Clone, Default)]
struct DashboardState {
    /// `setUserRole` (PolyScope 3 command, still answered by PolyScope 5).
    user_role: Option<String>,
    /// `set operational mode` (`manual` / `automatic`); `None`: not controlled.
    operational_mode: Option<String>,
}

/// The serial number the emulated controller reports (`get serial number`).
pub const SERIAL_NUMBER: &str = "20235500001";

/// The robot model the emulated controller reports (`get robot model`: a PolyScope 5 UR5e
/// answers `UR5`).
pub const ROBOT_MODEL: &str = "UR5";

/// Splits `line` into a command (matched case-insensitively against `name`) and its
/// argument.
fn dash_arg<'a>(line: &'a str, name: &str) -> Option<&'a str> {
    let head = line.get(..name.len())?;
    if !head.eq_ignore_ascii_case(name) {
        return None;
    }
    let rest = line.get(name.len()..)?;
    if rest.is_empty() {
        return Some("");
    }
    rest.strip_prefix(' ').map(str::trim)
}

/// The reply to one dashboard line, in PolyScope 5's wording (UR's dashboard server
/// documentation, e-Series), and whether the connection ends after it (`quit`).
fn dashboard_reply(w: &mut World, line: &str) -> (String, bool) {
    let line = line.trim();
    if let Some(cmd) = DashboardCommand::parse(line) {
        return (w.backend.dashboard(cmd), cmd == DashboardCommand::Quit);
    }
    let v = w.version;
    let program_name = |w: &World| {
        w.backend
            .loaded_program()
            .map(|p| p.rsplit('/').next().unwrap_or(p).to_owned())
    };
    let lower = line.to_ascii_lowercase();
    let reply = match lower.as_str() {
        "polyscopeversion" => format!(
            "URSoftware {}.{}.{}.{}",
            v.major, v.minor, v.bugfix, v.build
        ),
        "version" => format!("{}.{}.{}.{}", v.major, v.minor, v.bugfix, v.build),
        "get serial number" => SERIAL_NUMBER.into(),
        "get robot model" => ROBOT_MODEL.into(),
        "running" => format!(
            "Program running: {}",
            w.backend.runtime_state() == crate::types::runtime_state::PLAYING
        ),
        "programstate" => {
            use crate::types::runtime_state as rs;
            let state = match w.backend.runtime_state() {
                rs::PLAYING | rs::RESUMING => "PLAYING",
                rs::PAUSED | rs::PAUSING => "PAUSED",
                _ => "STOPPED",
            };
            let name = program_name(w).unwrap_or_else(|| "<unnamed>".into());
            format!("{state} {name}")
        }
        "get loaded program" => match w.backend.loaded_program() {
            Some(p) => format!("Loaded program: {p}"),
            None => "No program loaded".into(),
        },
        "isprogramsaved" => match program_name(w) {
            // Nothing edits a program on the emulator: a loaded one is saved.
            Some(name) => format!("True {name}"),
            None => "False <unnamed>".into(),
        },
        "safetymode" => {
            let status = w.backend.dashboard(DashboardCommand::SafetyStatus);
            status.replacen("Safetystatus:", "Safetymode:", 1)
        }
        "close popup" => "closing popup".into(),
        "shutdown" => {
            // The emulator does not exit: the arm powers off, as before a shutdown.
            w.backend.dashboard(DashboardCommand::PowerOff);
            "Shutting down".into()
        }
        "restart safety" => {
            if w.backend.restart_safety() {
                "Restarting safety".into()
            } else {
                "Failed to execute: restart safety".into()
            }
        }
        "get operational mode" => w
            .dash
            .operational_mode
            .as_deref()
            .map_or("NONE".into(), str::to_ascii_uppercase),
        "clear operational mode" => {
            let mode = w.dash.operational_mode.take();
            format!(
                "No longer controlling the operational mode. Current operational mode: '{}'.",
                mode.as_deref().unwrap_or("none").to_ascii_uppercase()
            )
        }
        _ => {
            if let Some(path) = dash_arg(line, "load installation") {
                format!("Loading installation: {path}")
            } else if let Some(path) = dash_arg(line, "load") {
                if path.is_empty() {
                    "File not found: ".into()
                } else if w.backend.load_urp(path) {
                    format!("Loading program: {path}")
                } else {
                    format!("Error while loading program: {path}")
                }
            } else if let Some(text) = dash_arg(line, "popup") {
                let _ = text;
                "showing popup".into()
            } else if let Some(text) = dash_arg(line, "addToLog") {
                if text.is_empty() {
                    "No log message to add".into()
                } else {
                    tracing::info!("emulator: dashboard log: {text}");
                    "Added log message".into()
                }
            } else if let Some(role) = dash_arg(line, "setUserRole") {
                let known = ["programmer", "operator", "none", "locked", "restricted"];
                if known.iter().any(|r| r.eq_ignore_ascii_case(role)) {
                    w.dash.user_role = Some(role.to_ascii_lowercase());
                    format!("Setting user role: {role}")
                } else {
                    format!("Failed setting user role: {role}")
                }
            } else if let Some(mode) = dash_arg(line, "set operational mode") {
                if mode.eq_ignore_ascii_case("manual") || mode.eq_ignore_ascii_case("automatic") {
                    w.dash.operational_mode = Some(mode.to_ascii_lowercase());
                    format!("Operational mode '{}' is set", mode.to_ascii_lowercase())
                } else {
                    format!("Failed to set operational mode: '{mode}'")
                }
            } else {
                format!("could not understand: '{line}'")
            }
        }
    };
    (reply, false)
}

/// The longest dashboard command line the emulator reads [bytes], without its line end:
/// 4096 (a controller's commands are short; `load <program>` with a long path is the
/// longest). A longer line is answered `could not understand: line longer than 4096 bytes
/// (discarded)` as soon as it overflows, and the rest of it, up to its newline, is read and
/// dropped without being kept: a client sending 64 MiB without a newline costs the emulator
/// no memory beyond this bound and the reader's buffer.
pub const MAX_DASHBOARD_LINE: usize = 4096;

/// What [`read_dashboard_line`] read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DashboardLine {
    /// A whole line (or the last, unterminated one before the end of the stream).
    Line,
    /// A line longer than the bound; `ended`: its newline has been read too (otherwise the
    /// caller skips the rest with [`skip_dashboard_line`]).
    TooLong { ended: bool },
    /// The stream ended with no more bytes.
    Eof,
}

/// Reads one line into `line` (without its `\n` or `\r\n`), keeping at most `max` bytes
/// (a `\r` before the newline counts).
async fn read_dashboard_line<R: tokio::io::AsyncBufRead + Unpin>(
    r: &mut R,
    line: &mut Vec<u8>,
    max: usize,
) -> std::io::Result<DashboardLine> {
    line.clear();
    loop {
        let avail = r.fill_buf().await?;
        if avail.is_empty() {
            return Ok(if line.is_empty() {
                DashboardLine::Eof
            } else {
                DashboardLine::Line
            });
        }
        let newline = avail.iter().position(|b| *b == b'\n');
        let chunk = avail
            .get(..newline.unwrap_or(avail.len()))
            .unwrap_or_default();
        let used = newline.map_or(avail.len(), |i| i + 1);
        if line.len() + chunk.len() > max {
            r.consume(used);
            line.clear();
            return Ok(DashboardLine::TooLong {
                ended: newline.is_some(),
            });
        }
        line.extend_from_slice(chunk);
        r.consume(used);
        if newline.is_some() {
            if line.last() == Some(&b'\r') {
                line.pop();
            }
            return Ok(DashboardLine::Line);
        }
    }
}

/// Reads and drops bytes up to and including the next newline (or the end of the stream).
async fn skip_dashboard_line<R: tokio::io::AsyncBufRead + Unpin>(r: &mut R) -> std::io::Result<()> {
    loop {
        let avail = r.fill_buf().await?;
        if avail.is_empty() {
            return Ok(());
        }
        match avail.iter().position(|b| *b == b'\n') {
            Some(i) => {
                r.consume(i + 1);
                return Ok(());
            }
            None => {
                let n = avail.len();
                r.consume(n);
            }
        }
    }
}

async fn serve_script(
    listener: TcpListener,
    world: Arc<Mutex<World>>,
    count: Arc<AtomicU64>,
    paused: watch::Receiver<bool>,
) {
    loop {
        let Ok((mut stream, _)) = listener.accept().await else {
            continue;
        };
        let world = world.clone();
        let count = count.clone();
        let mut paused = paused.clone();
        tokio::spawn(async move {
            // The connection stays open, as on a controller: ur_rtde sends every script
            // (re-uploads too) over one connection. A program is complete at its top-level
            // `end` (see `split_program`); the bytes that remain form a script when the
            // sender closes or pauses for 500 ms. The buffer is bounded.
            let mut text: Vec<u8> = Vec::new();
            let mut chunk = [0u8; 4096];
            loop {
                let read =
                    tokio::time::timeout(Duration::from_millis(500), stream.read(&mut chunk)).await;
                let closed = match read {
                    Ok(Ok(0)) | Ok(Err(_)) => true,
                    Ok(Ok(n)) => {
                        text.extend_from_slice(chunk.get(..n).unwrap_or_default());
                        false
                    }
                    Err(_) => false,
                };
                let idle = read.is_err();
                let mut programs = Vec::new();
                while let Some(end) = split_program(&text) {
                    programs.push(text.drain(..end).collect::<Vec<u8>>());
                }
                if (closed || idle) && !text.iter().all(u8::is_ascii_whitespace) {
                    programs.push(std::mem::take(&mut text));
                }
                if text.len() > MAX_SCRIPT_BYTES {
                    tracing::warn!(
                        "emulator: script over {MAX_SCRIPT_BYTES} bytes without a complete \
                         program; dropped"
                    );
                    text.clear();
                }
                for program in programs {
                    running(&mut paused).await;
                    let program = String::from_utf8_lossy(&program);
                    lock(&world).backend.load_program(&program);
                    count.fetch_add(1, Ordering::Relaxed);
                }
                if closed {
                    return;
                }
                if idle {
                    text.clear();
                }
            }
        });
    }
}

/// Largest script the script ports buffer [bytes].
pub const MAX_SCRIPT_BYTES: usize = 1 << 20;

/// The length of the first complete program in `text`: from a `def`/`sec` line at column 0
/// through the next line that is exactly `end` at column 0, plus the complete top-level lines
/// after it up to the next `def`/`sec` line (our program's trailing `hrc_control()` call).
/// URScript programs as ur_rtde and our [`crate::script`] send them indent their body, so a
/// column-0 `end` closes the program. `None` while no program is complete.
pub fn split_program(text: &[u8]) -> Option<usize> {
    let mut at = 0;
    let mut open = false;
    let mut closed_at = None;
    while let Some(rest) = text.get(at..).filter(|r| !r.is_empty()) {
        let Some(nl) = rest.iter().position(|b| *b == b'\n') else {
            break;
        };
        let line = rest.get(..nl).unwrap_or_default();
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        let starts = line.starts_with(b"def ") || line.starts_with(b"sec ");
        if closed_at.is_some() && starts {
            break;
        }
        if !open && starts {
            open = true;
        } else if open && closed_at.is_none() && line.trim_ascii_end() == b"end" {
            closed_at = Some(at + nl + 1);
        }
        at += nl + 1;
        if closed_at.is_some() {
            closed_at = Some(at);
        }
    }
    closed_at
}

/// The command these registers hold, as the emulator's SimBackend decodes it (for tools that
/// inspect the register protocol): a servo target as written, before the program's
/// extrapolation ([`RegisterMap::decode`] also gives the feedforward).
pub fn decode_registers(inputs: &InputRegisters, map: &RegisterMap) -> Option<JointCommand> {
    let ib = usize::from(map.int_base);
    let db = usize::from(map.double_base);
    let ints = <[i32; INT_REGISTERS]>::try_from(inputs.int.get(ib..ib + INT_REGISTERS)?).ok()?;
    let doubles =
        <[f64; DOUBLE_REGISTERS]>::try_from(inputs.double.get(db..db + DOUBLE_REGISTERS)?).ok()?;
    RegisterMap::decode(&ints, &doubles).map(|d| d.command)
}
