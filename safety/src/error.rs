//! The crate's error type.

use crate::verdict::Violation;

/// Errors of the `safety` crate: invalid configuration, a refused reset, or a robot failure
/// while reading its state. Outcomes of a control cycle are not errors; they are
/// [`Verdict`](crate::Verdict)s.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SafetyError {
    /// A configuration value is out of its valid range.
    #[error("invalid safety setting `{field}`: {reason}")]
    InvalidConfig {
        /// The setting.
        field: &'static str,
        /// Why it is invalid.
        reason: &'static str,
    },
    /// `reset()` was called while the cause of the latched fault is still present.
    #[error("cannot reset: the cause of the latched fault is still present ({cause})")]
    ResetRefused {
        /// The fault still present.
        cause: Violation,
    },
    /// The robot failed to deliver its state.
    #[error("reading the robot state failed: {0}")]
    Robot(#[from] robot_io::RobotIoError),
}

/// Result alias of this crate.
pub type Result<T, E = SafetyError> = std::result::Result<T, E>;
