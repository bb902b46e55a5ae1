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
    /// No inverse-kinematics branch reaches the flange pose.
    #[error("flange pose at ({x_m}, {y_m}, {z_m}) m is unreachable")]
    Unreachable {
        /// Requested flange x in the base frame [m].
        x_m: f64,
        /// Requested flange y in the base frame [m].
        y_m: f64,
        /// Requested flange z in the base frame [m].
        z_m: f64,
    },
    /// A motion limit, scale, duration or target is not finite or out of its range.
    #[error("invalid trajectory parameter `{name}` (joint {joint}) = {value}: {rule}")]
    InvalidTrajectoryParameter {
        /// Parameter name with its unit suffix (e.g. `max_velocity_rad_s`).
        name: &'static str,
        /// Joint index 0–5 (0 for scalar parameters).
        joint: usize,
        /// The offending value, in the parameter's unit.
        value: f64,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// Ruckig could not compute a trajectory.
    #[error("trajectory generation failed: {reason}")]
    TrajectoryGeneration {
        /// What rsruckig reported (its message or result code).
        reason: String,
    },

    // --- separation monitoring and QP speed scaling (ssm, qp) ---
    /// A separation-monitoring or speed-scaling parameter is not finite, or out of its range.
    #[error("invalid separation or speed-scaling parameter `{name}` = {value}: {rule}")]
    InvalidSafetyParameter {
        /// Parameter name, with its unit suffix (e.g. `reaction_time_s`).
        name: &'static str,
        /// The offending value, in the parameter's unit.
        value: f64,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// The QP solver (clarabel) could not be set up.
    #[error("qp solver setup failed: {reason}")]
    QpSetup {
        /// What clarabel reported.
        reason: String,
    },

    // --- handover task and controller (task, controller) ---
    /// A Cartesian pose of the task config has no inverse-kinematics solution.
    #[error("pose `{pose}` is unreachable: no inverse-kinematics solution")]
    UnreachablePose {
        /// The config key of the pose.
        pose: &'static str,
    },
}

/// Result alias of this crate.
pub type Result<T, E = AdaptError> = std::result::Result<T, E>;

/// `v` if it is finite and > 0, else [`AdaptError::InvalidValue`] naming `key` and the value.
pub(crate) fn positive(key: &str, v: f64) -> Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(AdaptError::InvalidValue {
            key: key.to_owned(),
            rule: format!("must be finite and > 0, got {v}"),
        })
    }
}

/// `v` if it is finite and ≥ 0, else [`AdaptError::InvalidValue`] naming `key` and the value.
pub(crate) fn non_negative(key: &str, v: f64) -> Result<f64> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(AdaptError::InvalidValue {
            key: key.to_owned(),
            rule: format!("must be finite and >= 0, got {v}"),
        })
    }
}
