//! What the supervisor decided in a cycle, why, and the running counts.

use std::fmt;

use robot_io::geometry::{ArmLink, BodyPart};

use crate::points::ArmPoint;

/// A safety requirement (see the table in the crate docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Requirement {
    /// SAF-REQ-001: non-finite or malformed command or input.
    Saf001Malformed,
    /// SAF-REQ-002: joint position limits with a margin.
    Saf002JointPosition,
    /// SAF-REQ-003: joint speed limit.
    Saf003JointSpeed,
    /// SAF-REQ-004: joint acceleration limit.
    Saf004JointAcceleration,
    /// SAF-REQ-005: TCP speed limit (lower during collaboration).
    Saf005TcpSpeed,
    /// SAF-REQ-006: workspace box for TCP, wrist and elbow.
    Saf006Workspace,
    /// SAF-REQ-007: protective separation distance.
    Saf007Separation,
    /// SAF-REQ-008: perception staleness.
    Saf008PerceptionStale,
    /// SAF-REQ-009: robot-state staleness.
    Saf009RobotStateStale,
    /// SAF-REQ-010: the robot's own safety stop (halt and latch).
    Saf010RobotSafetyStop,
    /// SAF-REQ-011: latched faults clear only through `reset()` once the cause is gone.
    Saf011Latch,
    /// SAF-REQ-012: a failed send halts and latches.
    Saf012SendFailed,
}

impl Requirement {
    /// Number of requirements.
    pub const COUNT: usize = 12;

    /// All requirements, in ID order.
    pub const ALL: [Requirement; Requirement::COUNT] = [
        Requirement::Saf001Malformed,
        Requirement::Saf002JointPosition,
        Requirement::Saf003JointSpeed,
        Requirement::Saf004JointAcceleration,
        Requirement::Saf005TcpSpeed,
        Requirement::Saf006Workspace,
        Requirement::Saf007Separation,
        Requirement::Saf008PerceptionStale,
        Requirement::Saf009RobotStateStale,
        Requirement::Saf010RobotSafetyStop,
        Requirement::Saf011Latch,
        Requirement::Saf012SendFailed,
    ];

    /// The requirement's ID, `SAF-REQ-nnn`.
    pub fn id(self) -> &'static str {
        match self {
            Requirement::Saf001Malformed => "SAF-REQ-001",
            Requirement::Saf002JointPosition => "SAF-REQ-002",
            Requirement::Saf003JointSpeed => "SAF-REQ-003",
            Requirement::Saf004JointAcceleration => "SAF-REQ-004",
            Requirement::Saf005TcpSpeed => "SAF-REQ-005",
            Requirement::Saf006Workspace => "SAF-REQ-006",
            Requirement::Saf007Separation => "SAF-REQ-007",
            Requirement::Saf008PerceptionStale => "SAF-REQ-008",
            Requirement::Saf009RobotStateStale => "SAF-REQ-009",
            Requirement::Saf010RobotSafetyStop => "SAF-REQ-010",
            Requirement::Saf011Latch => "SAF-REQ-011",
            Requirement::Saf012SendFailed => "SAF-REQ-012",
        }
    }

    /// Index into [`Requirement::ALL`] (0-based).
    pub fn index(self) -> usize {
        match self {
            Requirement::Saf001Malformed => 0,
            Requirement::Saf002JointPosition => 1,
            Requirement::Saf003JointSpeed => 2,
            Requirement::Saf004JointAcceleration => 3,
            Requirement::Saf005TcpSpeed => 4,
            Requirement::Saf006Workspace => 5,
            Requirement::Saf007Separation => 6,
            Requirement::Saf008PerceptionStale => 7,
            Requirement::Saf009RobotStateStale => 8,
            Requirement::Saf010RobotSafetyStop => 9,
            Requirement::Saf011Latch => 10,
            Requirement::Saf012SendFailed => 11,
        }
    }
}

impl fmt::Display for Requirement {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.id())
    }
}

/// Which input carried a non-finite or out-of-range value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MalformedInput {
    /// A value of the command (target, velocity, acceleration, deceleration).
    CommandValue,
    /// servoj lookahead [s] outside [0.03, 0.2] or gain outside [100, 2000].
    ServoParameter,
    /// The robot state (positions, velocities, timestamp).
    RobotState,
    /// The world view (time, perception age, a body point or torso normal).
    WorldView,
}

/// A violated requirement with the measured value and the limit it broke.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Violation {
    /// SAF-REQ-001: a non-finite or out-of-range value.
    Malformed {
        /// Where.
        input: MalformedInput,
    },
    /// SAF-REQ-002: a joint position (target or stopping position) outside its limits.
    JointOutOfLimit {
        /// Joint (0-based).
        joint: usize,
        /// Position [rad].
        value_rad: f64,
        /// The limit it crossed, margin applied [rad].
        limit_rad: f64,
    },
    /// SAF-REQ-003: a joint speed over the limit.
    JointSpeed {
        /// Joint (0-based).
        joint: usize,
        /// Speed [rad/s].
        value_rad_s: f64,
        /// Limit in force [rad/s].
        limit_rad_s: f64,
    },
    /// SAF-REQ-004: a joint acceleration over the limit.
    JointAcceleration {
        /// Joint (0-based).
        joint: usize,
        /// Acceleration [rad/s²].
        value_rad_s2: f64,
        /// Limit [rad/s²].
        limit_rad_s2: f64,
    },
    /// SAF-REQ-005: TCP speed over the limit in force.
    TcpSpeed {
        /// Speed [m/s].
        value_m_s: f64,
        /// Limit in force [m/s].
        limit_m_s: f64,
    },
    /// SAF-REQ-006: a watched point outside the workspace box.
    OutsideWorkspace {
        /// Which point.
        point: ArmPoint,
        /// Its position [m].
        position_m: [f64; 3],
    },
    /// SAF-REQ-007: a tracked body part closer to the arm than the protective separation
    /// distance (surface to surface).
    Separation {
        /// Which body part.
        part: BodyPart,
        /// The arm link (capsule) nearest to it.
        link: ArmLink,
        /// Surface-to-surface distance [m] (NaN if an input was not finite).
        distance_m: f64,
        /// Required S_p [m].
        required_m: f64,
    },
    /// SAF-REQ-008: perception older than a threshold.
    PerceptionStale {
        /// Age [s].
        age_s: f64,
        /// Threshold crossed [s].
        limit_s: f64,
    },
    /// SAF-REQ-009: no new controller timestamp for too many cycles.
    RobotStateStale {
        /// Consecutive cycles without a new timestamp.
        cycles: u32,
        /// Tolerated cycles.
        limit_cycles: u32,
    },
    /// SAF-REQ-010: the robot reports a safety stop or a safety mode other than NORMAL.
    RobotSafetyStop {
        /// `safety_mode` as reported.
        safety_mode: i32,
        /// `safety_status_bits` as reported.
        safety_status_bits: u32,
    },
    /// SAF-REQ-012: the robot refused a command or the link failed while sending.
    SendFailed,
}

impl Violation {
    /// The requirement this violation breaks.
    pub fn requirement(&self) -> Requirement {
        match self {
            Violation::Malformed { .. } => Requirement::Saf001Malformed,
            Violation::JointOutOfLimit { .. } => Requirement::Saf002JointPosition,
            Violation::JointSpeed { .. } => Requirement::Saf003JointSpeed,
            Violation::JointAcceleration { .. } => Requirement::Saf004JointAcceleration,
            Violation::TcpSpeed { .. } => Requirement::Saf005TcpSpeed,
            Violation::OutsideWorkspace { .. } => Requirement::Saf006Workspace,
            Violation::Separation { .. } => Requirement::Saf007Separation,
            Violation::PerceptionStale { .. } => Requirement::Saf008PerceptionStale,
            Violation::RobotStateStale { .. } => Requirement::Saf009RobotStateStale,
            Violation::RobotSafetyStop { .. } => Requirement::Saf010RobotSafetyStop,
            Violation::SendFailed => Requirement::Saf012SendFailed,
        }
    }
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let id = self.requirement().id();
        match *self {
            Violation::Malformed { input } => write!(f, "{id}: malformed {input:?}"),
            Violation::JointOutOfLimit {
                joint,
                value_rad,
                limit_rad,
            } => write!(
                f,
                "{id}: joint {joint} at {value_rad:.4} rad beyond limit {limit_rad:.4} rad"
            ),
            Violation::JointSpeed {
                joint,
                value_rad_s,
                limit_rad_s,
            } => write!(
                f,
                "{id}: joint {joint} speed {value_rad_s:.4} rad/s over {limit_rad_s:.4} rad/s"
            ),
            Violation::JointAcceleration {
                joint,
                value_rad_s2,
                limit_rad_s2,
            } => write!(
                f,
                "{id}: joint {joint} acceleration {value_rad_s2:.4} rad/s² over {limit_rad_s2:.4} rad/s²"
            ),
            Violation::TcpSpeed {
                value_m_s,
                limit_m_s,
            } => write!(
                f,
                "{id}: tcp speed {value_m_s:.4} m/s over {limit_m_s:.4} m/s"
            ),
            Violation::OutsideWorkspace { point, position_m } => {
                write!(
                    f,
                    "{id}: {point:?} at {position_m:?} m outside the workspace"
                )
            }
            Violation::Separation {
                part,
                link,
                distance_m,
                required_m,
            } => write!(
                f,
                "{id}: {part} {distance_m:.3} m from the {link}, needs {required_m:.3} m"
            ),
            Violation::PerceptionStale { age_s, limit_s } => {
                write!(f, "{id}: perception {age_s:.3} s old, limit {limit_s:.3} s")
            }
            Violation::RobotStateStale {
                cycles,
                limit_cycles,
            } => write!(
                f,
                "{id}: robot state unchanged for {cycles} cycles, limit {limit_cycles}"
            ),
            Violation::RobotSafetyStop {
                safety_mode,
                safety_status_bits,
            } => write!(
                f,
                "{id}: robot safety mode {safety_mode}, status bits {safety_status_bits:#x}"
            ),
            Violation::SendFailed => write!(f, "{id}: sending to the robot failed"),
        }
    }
}

/// The outcome of one [`crate::Supervisor::step`]: what was sent and why.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// The command was sent unchanged.
    Passed,
    /// The command was sent with its velocities scaled by `scale` (and a speedj acceleration
    /// clamped to the limit); `violation` names the binding limit.
    Reduced {
        /// Scale applied to the command's velocity [-], > 0. Below 1 for a cap; above 1 only
        /// when a servo command decelerates harder than the acceleration limit allows and is
        /// slowed at the limit instead (`violation`: SAF-REQ-004) — still slower than the
        /// previous cycle on every joint.
        scale: f64,
        /// The limit that made the reduction necessary.
        violation: Violation,
    },
    /// The command was replaced by `JointCommand::Stop` at the configured deceleration. Not
    /// latched: the next cycle is judged afresh.
    Stopped {
        /// Why.
        violation: Violation,
    },
    /// A fault is latched: a stop was sent, and every cycle sends a stop until
    /// [`crate::Supervisor::reset`] succeeds.
    Halted {
        /// The latched fault.
        violation: Violation,
    },
}

impl Verdict {
    /// The violation behind a reduction, stop or halt; `None` when passed.
    pub fn violation(&self) -> Option<Violation> {
        match *self {
            Verdict::Passed => None,
            Verdict::Reduced { violation, .. }
            | Verdict::Stopped { violation }
            | Verdict::Halted { violation } => Some(violation),
        }
    }

    /// The requirement that fired; `None` when passed.
    pub fn requirement(&self) -> Option<Requirement> {
        self.violation().map(|v| v.requirement())
    }

    /// Whether the robot was sent a stop this cycle.
    pub fn is_stop(&self) -> bool {
        matches!(self, Verdict::Stopped { .. } | Verdict::Halted { .. })
    }
}

/// Running counts of verdicts [cycles].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    /// Cycles stepped.
    pub steps: u64,
    /// Commands passed unchanged.
    pub passed: u64,
    /// Commands passed with reduced speed.
    pub reduced: u64,
    /// Commands replaced by a stop.
    pub stopped: u64,
    /// Cycles halted by a latched fault.
    pub halted: u64,
    /// Resets that cleared a latched fault.
    pub resets: u64,
    /// Resets refused because the cause was still present.
    pub resets_refused: u64,
    by_requirement: [u64; Requirement::COUNT],
}

impl Counters {
    /// Cycles in which `requirement` fired (reduced, stopped or halted) [cycles]; for
    /// SAF-REQ-011, refused resets.
    pub fn fired(&self, requirement: Requirement) -> u64 {
        self.by_requirement
            .get(requirement.index())
            .copied()
            .unwrap_or(0)
    }

    pub(crate) fn record(&mut self, verdict: &Verdict) {
        self.steps = self.steps.saturating_add(1);
        let slot = match verdict {
            Verdict::Passed => &mut self.passed,
            Verdict::Reduced { .. } => &mut self.reduced,
            Verdict::Stopped { .. } => &mut self.stopped,
            Verdict::Halted { .. } => &mut self.halted,
        };
        *slot = slot.saturating_add(1);
        if let Some(requirement) = verdict.requirement() {
            self.bump(requirement);
        }
    }

    pub(crate) fn bump(&mut self, requirement: Requirement) {
        if let Some(n) = self.by_requirement.get_mut(requirement.index()) {
            *n = n.saturating_add(1);
        }
    }
}
