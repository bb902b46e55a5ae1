//! The robot's state and commands: the contract between robot-io and its users.

/// Joint-space data of a 6-axis UR arm, base to wrist 3.
pub type Joints = [f64; 6];

/// UR `robot_mode` values (from UR's client library).
pub mod robot_mode {
    /// The arm has no power.
    pub const POWER_OFF: i32 = 3;
    /// Powered, brakes engaged or idle.
    pub const IDLE: i32 = 5;
    /// Brakes released, ready to move.
    pub const RUNNING: i32 = 7;
}

/// UR `safety_mode` values.
pub mod safety_mode {
    /// Normal operation.
    pub const NORMAL: i32 = 1;
    /// Reduced mode (lower safety limits in force).
    pub const REDUCED: i32 = 2;
    /// Protective stop.
    pub const PROTECTIVE_STOP: i32 = 3;
    /// Safeguard stop.
    pub const SAFEGUARD_STOP: i32 = 5;
    /// System emergency stop.
    pub const SYSTEM_EMERGENCY_STOP: i32 = 6;
    /// Robot emergency stop.
    pub const ROBOT_EMERGENCY_STOP: i32 = 7;
    /// Fault.
    pub const FAULT: i32 = 9;
}

/// UR `runtime_state` values (the program's state).
pub mod runtime_state {
    /// The program is stopping.
    pub const STOPPING: u32 = 0;
    /// No program runs.
    pub const STOPPED: u32 = 1;
    /// The program runs.
    pub const PLAYING: u32 = 2;
    /// The program is pausing.
    pub const PAUSING: u32 = 3;
    /// The program is paused.
    pub const PAUSED: u32 = 4;
    /// The program is resuming.
    pub const RESUMING: u32 = 5;
}

/// Bits of UR `safety_status_bits`.
pub mod safety_status_bits {
    /// Bit 2: protective stop.
    pub const PROTECTIVE_STOP: u32 = 1 << 2;
    /// Bit 7: emergency stop.
    pub const EMERGENCY_STOP: u32 = 1 << 7;
    /// Bit 10: stopped due to safety.
    pub const STOPPED_DUE_TO_SAFETY: u32 = 1 << 10;
}

/// The robot's state as read each control cycle. Caller-owned; `Robot::read_state` fills it in
/// place.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotState {
    /// Controller timestamp: time since the controller started [s].
    pub timestamp_s: f64,
    /// Actual joint positions [rad].
    pub actual_q: Joints,
    /// Actual joint velocities [rad/s].
    pub actual_qd: Joints,
    /// Target joint positions [rad].
    pub target_q: Joints,
    /// Target joint velocities [rad/s].
    pub target_qd: Joints,
    /// Actual TCP pose: position [m] and rotation vector [rad], in the base frame.
    pub actual_tcp_pose: [f64; 6],
    /// Actual TCP speed: linear [m/s] and angular [rad/s].
    pub actual_tcp_speed: [f64; 6],
    /// Speed scaling applied by the controller (trajectory limiting, safety) [-] in [0, 1].
    pub speed_scaling: f64,
    /// The speed slider fraction [-] in [0, 1].
    pub target_speed_fraction: f64,
    /// `robot_mode` (see [`robot_mode`]).
    pub robot_mode: i32,
    /// `safety_mode` (see [`safety_mode`]).
    pub safety_mode: i32,
    /// `runtime_state` (see [`runtime_state`]).
    pub runtime_state: u32,
    /// `robot_status_bits`.
    pub robot_status_bits: u32,
    /// `safety_status_bits` (see [`safety_status_bits`]).
    pub safety_status_bits: u32,
}

impl Default for RobotState {
    fn default() -> Self {
        Self {
            timestamp_s: 0.0,
            actual_q: [0.0; 6],
            actual_qd: [0.0; 6],
            target_q: [0.0; 6],
            target_qd: [0.0; 6],
            actual_tcp_pose: [0.0; 6],
            actual_tcp_speed: [0.0; 6],
            speed_scaling: 1.0,
            target_speed_fraction: 1.0,
            robot_mode: robot_mode::RUNNING,
            safety_mode: safety_mode::NORMAL,
            runtime_state: runtime_state::PLAYING,
            robot_status_bits: 0,
            safety_status_bits: 0,
        }
    }
}

impl RobotState {
    /// Whether the controller reports a protective or emergency stop, or a safety mode other
    /// than NORMAL or REDUCED.
    pub fn is_safety_stopped(&self) -> bool {
        let stop_bits = safety_status_bits::PROTECTIVE_STOP
            | safety_status_bits::EMERGENCY_STOP
            | safety_status_bits::STOPPED_DUE_TO_SAFETY;
        self.safety_status_bits & stop_bits != 0
            || !(self.safety_mode == safety_mode::NORMAL
                || self.safety_mode == safety_mode::REDUCED)
    }
}

/// One joint command for the robot's control program.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JointCommand {
    /// servoJ towards `q`.
    Servo {
        /// Target joint positions [rad].
        q: Joints,
        /// servoj lookahead time [s], in [0.03, 0.2].
        lookahead_s: f64,
        /// servoj proportional gain [-], in [100, 2000].
        gain: f64,
    },
    /// speedJ at `qd`.
    Speed {
        /// Joint velocities [rad/s].
        qd: Joints,
        /// Joint acceleration used to reach them [rad/s²].
        acc: f64,
    },
    /// stopJ.
    Stop {
        /// Joint deceleration [rad/s²].
        decel: f64,
    },
}

/// A UR arm, real or simulated, seen once per control cycle.
///
/// Implementations: `RtdeRobot` (a real UR5e or URSim over RTDE), `SimRobot` (an in-process
/// UR5e model on a mock clock) and `ReplayRobot` (a recorded trace).
pub trait Robot {
    /// Fill `out` with the latest state.
    ///
    /// # Implementation
    /// Must not allocate, and must not block longer than about one control period (2 ms).
    /// An implementation paced on the robot's own samples may wait for the next sample, at
    /// most one period, without waiting for another thread; without one it returns the
    /// previous state again (same `timestamp_s`), so the caller's robot-state staleness check
    /// (the supervisor's SAF-REQ-009) sees the missed cycle. A link that is known to be down
    /// is an error, after the same bounded wait.
    fn read_state(&mut self, out: &mut RobotState) -> crate::Result<()>;

    /// Send one command; it takes effect on the robot's next cycle.
    ///
    /// # Implementation
    /// Must not block and must not allocate. Validating limits is the supervisor's job, not
    /// the robot's; implementations only reject values the wire cannot carry.
    fn send(&mut self, cmd: &JointCommand) -> crate::Result<()>;
}
