//! The crate's error type.

use std::borrow::Cow;
use std::sync::Arc;

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
    /// A package or field was cut short.
    #[error("truncated {what}: need {needed} bytes, have {available}")]
    Truncated {
        /// What was being decoded.
        what: &'static str,
        /// Bytes needed \[B\].
        needed: usize,
        /// Bytes available \[B\].
        available: usize,
    },
    /// A package violates the RTDE wire format.
    #[error("malformed rtde package: {reason}")]
    Malformed {
        /// What is wrong.
        reason: &'static str,
    },
    /// An RTDE package type this side does not accept.
    #[error("unexpected rtde package type {kind:#04x}")]
    UnexpectedPackage {
        /// The package type byte.
        kind: u8,
    },
    /// A type string that is not one of RTDE's field types.
    #[error("unknown rtde field type `{name}`")]
    UnknownFieldType {
        /// The type string as received.
        name: String,
    },
    /// A value does not match its recipe field's type, or a field is not in the recipe.
    #[error("recipe field mismatch: {reason}")]
    RecipeMismatch {
        /// What does not match.
        reason: String,
    },
    /// The controller does not know these fields (it answered NOT_FOUND).
    #[error("the controller does not know these rtde fields: {}", fields.join(", "))]
    FieldsNotFound {
        /// The unknown field names.
        fields: Vec<String>,
    },
    /// Another writer (fieldbus adapter, URCap or another RTDE client) owns these inputs.
    #[error("rtde inputs already in use by another writer: {} (use registers 24 and up)", fields.join(", "))]
    InputsInUse {
        /// The input names already claimed.
        fields: Vec<String>,
    },
    /// The TCP connection was refused: nothing listens there.
    #[error("connection refused by {addr} (is the controller or emulator running?)")]
    ConnectionRefused {
        /// The address tried.
        addr: String,
    },
    /// The controller refused the requested RTDE protocol version.
    #[error("the controller refused rtde protocol version {requested}")]
    ProtocolVersionRejected {
        /// The version asked for.
        requested: u16,
    },
    /// The controller's software is older than this client supports.
    #[error(
        "controller version {major}.{minor} is not supported (need {min_major}.{min_minor} or newer)"
    )]
    ControllerVersionUnsupported {
        /// Controller major version.
        major: u32,
        /// Controller minor version.
        minor: u32,
        /// Oldest supported major version.
        min_major: u32,
        /// Oldest supported minor version.
        min_minor: u32,
    },
    /// The controller refused a request (start, pause, setup).
    #[error("the controller refused {what}")]
    Refused {
        /// The request that was refused.
        what: &'static str,
    },
    /// No answer in time.
    #[error("timed out after {after_ms} ms waiting for {what}")]
    Timeout {
        /// What was awaited.
        what: &'static str,
        /// How long we waited \[ms\].
        after_ms: u64,
    },
    /// The RTDE link is down for now: lost and being re-established, or no sample received
    /// yet. Built without allocating (the real-time path returns it), so `reason` is a static
    /// text in the hot path.
    #[error("rtde link down: {reason}")]
    LinkDown {
        /// Why.
        reason: Cow<'static, str>,
    },
    /// The RTDE client is closed for good: closed by its owner, lost with reconnecting
    /// disabled, or a reconnect that cannot succeed (the fields or versions changed). The
    /// reason is shared, so returning this error again does not allocate.
    #[error("rtde link closed: {reason}")]
    LinkClosed {
        /// Why.
        reason: Arc<str>,
    },
    /// Two threads wrote the same input recipe at the same moment: both of its package
    /// buffers were being written, and the write was not taken ([`crate::client::RtdeClient::send_inputs`]
    /// never waits for another writer). One writer per recipe never sees it.
    #[error("input recipe {index} is being written by another thread; the write was not taken")]
    InputsContended {
        /// The input recipe's index [-].
        index: usize,
    },
    /// A configuration value is out of range.
    #[error("invalid configuration: {reason}")]
    InvalidConfig {
        /// What is wrong.
        reason: String,
    },
    /// The dashboard server answered something unexpected.
    #[error("dashboard command `{command}` failed: {reply}")]
    Dashboard {
        /// The command sent.
        command: String,
        /// The server's reply.
        reply: String,
    },

    // --- the ur_rtde backend (feature `ur-rtde`) ---
    /// A ur_rtde call failed: it threw a C++ exception (caught in our shim, its message
    /// kept) or returned false. Building it allocates the message (an error path only).
    #[error("ur_rtde {call} failed (status {status}): {message}")]
    UrRtde {
        /// The ur_rtde call, e.g. `RTDEControlInterface::servoJ`.
        call: &'static str,
        /// The shim's status code (negative).
        status: i32,
        /// ur_rtde's message.
        message: String,
    },

    // --- simulation and traces ---
    /// A trace file could not be parsed; names the file, the 1-based line and the 1-based column
    /// (field number, counting every column of the file).
    #[error("{file}:{line}:{column}: {kind}")]
    TraceParse {
        /// The file (or the source name given to `Trace::parse`).
        file: std::path::PathBuf,
        /// 1-based physical line (CR, LF and CRLF each end a line).
        line: usize,
        /// 1-based column (field number in the line).
        column: usize,
        /// What is wrong.
        kind: crate::trace::TraceParseErrorKind,
    },
    /// A row index past the end of a trace.
    #[error("row {row} is out of range: the trace has {rows} rows")]
    TraceRowOutOfRange {
        /// The requested row (0-based).
        row: usize,
        /// Rows in the trace.
        rows: usize,
    },
    /// A row or writer call with the wrong number of values.
    #[error("expected {expected} values per row, got {found}")]
    TraceRowLength {
        /// Fields of the trace.
        expected: usize,
        /// Values given.
        found: usize,
    },
    /// A field name the trace does not hold.
    #[error("the trace has no field `{field}`")]
    TraceUnknownField {
        /// The field asked for.
        field: String,
    },
    /// A field name given twice when building a trace.
    #[error("field `{field}` appears twice")]
    TraceDuplicateField {
        /// The repeated name.
        field: String,
    },
    /// Rows added to a trace must have strictly increasing timestamps.
    #[error("timestamp {found} s does not follow {previous} s")]
    TraceTimestampOrder {
        /// The last timestamp in the trace \[s\].
        previous: f64,
        /// The timestamp of the rejected row \[s\].
        found: f64,
    },
    /// A `ReplayRobot` was read past the end of its trace.
    #[error("the replayed trace ended after {rows} rows")]
    TraceEnded {
        /// Rows in the trace.
        rows: usize,
    },
    /// A `SimConfig` value or a `SimRobot` setting is invalid.
    #[error("invalid simulator setting `{field}`: {reason}")]
    InvalidSimConfig {
        /// The setting.
        field: &'static str,
        /// Why it is invalid.
        reason: &'static str,
    },
    // --- separation geometry and parameters ---
    /// An arm or body model size is invalid (`robot_io::geometry`).
    #[error("invalid geometry setting `{field}`: {reason}")]
    InvalidGeometry {
        /// The setting.
        field: &'static str,
        /// Why it is invalid.
        reason: &'static str,
    },
    /// A protective separation distance parameter is invalid (`robot_io::separation`).
    #[error("invalid separation setting `{field}`: {reason}")]
    InvalidSeparation {
        /// The setting.
        field: &'static str,
        /// Why it is invalid.
        reason: &'static str,
    },
    /// A command the simulated controller refuses (non-finite values, or servoj parameters
    /// outside the ranges UR's controller accepts).
    #[error("invalid command: {reason}")]
    InvalidCommand {
        /// Why it is invalid.
        reason: &'static str,
    },
}

impl RobotIoError {
    /// The error of a failed TCP connect to `addr`: [`RobotIoError::ConnectionRefused`] when
    /// nothing listens there, [`RobotIoError::Io`] otherwise.
    pub(crate) fn connecting(e: std::io::Error, addr: &str) -> Self {
        if e.kind() == std::io::ErrorKind::ConnectionRefused {
            Self::ConnectionRefused {
                addr: addr.to_owned(),
            }
        } else {
            Self::Io {
                context: format!("connecting to {addr}"),
                source: e,
            }
        }
    }
}

/// Result alias of this crate.
pub type Result<T, E = RobotIoError> = std::result::Result<T, E>;

/// `v` if it is finite and > 0 (`strict`) or ≥ 0, else the rule it breaks (for the
/// structured config errors, which name the field).
pub(crate) fn finite_bound(v: f64, strict: bool) -> std::result::Result<f64, &'static str> {
    match (v.is_finite(), strict) {
        (true, true) if v > 0.0 => Ok(v),
        (true, false) if v >= 0.0 => Ok(v),
        (_, true) => Err("must be finite and > 0"),
        (_, false) => Err("must be finite and >= 0"),
    }
}
