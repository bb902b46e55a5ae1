//! The crate's error type.

/// Errors of the `adapt` crate. Messages are lowercase.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AdaptError {
    /// A configuration value breaks a rule.
    #[error("invalid value for `{key}`: {rule}")]
    InvalidValue {
        /// The key or parameter name.
        key: String,
        /// The rule it breaks, with the offending value.
        rule: String,
    },
    // --- kinematics and trajectory generation (ik, otg) ---

    // --- separation monitoring and QP speed scaling (ssm, qp) ---

    // --- handover task and controller (task, controller) ---
}

/// Result alias of this crate.
pub type Result<T, E = AdaptError> = std::result::Result<T, E>;
