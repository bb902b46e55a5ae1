//! The crate's error type.

/// Errors of the `robot-io` crate.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RobotIoError {
    /// An I/O error on a socket or file.
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: String,
        /// The underlying error.
        source: std::io::Error,
    },
    // --- RTDE side (codec, client, emulator, dashboard, script) ---

    // --- simulation and traces ---
}

/// Result alias of this crate.
pub type Result<T, E = RobotIoError> = std::result::Result<T, E>;
