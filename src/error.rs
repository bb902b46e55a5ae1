//! The library's error type: one enum, [`Error`], with structured fields.
//!
//! Each variant's message says what failed at its own level and names the file, field or
//! argument; the cause is its [`source`](std::error::Error::source), so the binary prints the
//! whole chain, one cause per line. [`Error::with_causes`] writes the chain on one
//! line (`a: b: c`), for logs, reports and tests.
//!
//! A trial that did not end normally is [`Error::Trial`]: its [`TrialEnded`] carries the
//! `finish_reason` and the run folder, and [`Error::exit_code`] maps it onto the process exit
//! code (README, "Exit codes"), also through [`Error::Context`] and [`Error::InFile`].

use std::path::{Path, PathBuf};

use crate::trial::runtime::TrialEnded;

/// Errors of the `hrc_adapt` library. Messages are lowercase and name the file, the field or
/// the argument at fault.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A command-line argument, or a combination of them, is not usable.
    #[error("{reason}")]
    Usage {
        /// The argument(s) at fault (`--jobs`, `--image, --camera`).
        arg: String,
        /// The whole message, naming the argument(s) and what to pass instead.
        reason: String,
    },
    /// A configuration value breaks a rule (the file, if known, is an [`Error::InFile`]
    /// around it).
    #[error("`{field}` {reason}")]
    Config {
        /// The key, dotted (`link.lost_after_s`).
        field: String,
        /// The rule it breaks, with the offending value.
        reason: String,
    },
    /// An input (a file, a recording, a `summary.json`) holds something it must not, or lacks
    /// something it needs.
    #[error("{what}: {reason}")]
    Data {
        /// The input (a path, or a name like `summary.json`).
        what: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A file or folder could not be read, written, created, listed, opened or moved.
    #[error("cannot {action} {}", path.display())]
    Io {
        /// What was being done (`read`, `create`, `write`, `list`, ...).
        action: &'static str,
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file or folder a command-line argument names cannot be read.
    #[error("cannot read {arg} {}", path.display())]
    Input {
        /// The argument (`--cues`).
        arg: String,
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A TOML document could not be parsed.
    #[error("cannot parse {what}")]
    Toml {
        /// The document (a file, or what it configures).
        what: String,
        /// The parser's error, with line and column.
        source: toml::de::Error,
    },
    /// A CSV file could not be read or written.
    #[error("cannot {action} {}", path.display())]
    Csv {
        /// What was being done (`write`, `start`, `finish`, ...).
        action: &'static str,
        /// The file.
        path: PathBuf,
        /// The cause.
        source: csv::Error,
    },
    /// JSON could not be read or written.
    #[error("cannot {action} {what} as json")]
    Json {
        /// What was being done (`read`, `write`).
        action: &'static str,
        /// The document (a file, or what it describes).
        what: String,
        /// The cause.
        source: serde_json::Error,
    },
    /// The MCAP trial log could not be written or read.
    #[error("cannot {action} {}", path.display())]
    Mcap {
        /// What was being done (`start`, `write`, `finish`, `read`).
        action: &'static str,
        /// The file.
        path: PathBuf,
        /// The cause.
        source: mcap::McapError,
    },
    /// A plot could not be drawn or written.
    #[error("cannot plot {}: {reason}", path.display())]
    Plot {
        /// The image file.
        path: PathBuf,
        /// The plotting library's message.
        reason: String,
    },
    /// A camera (or another frame source) cannot serve the command.
    #[error("{camera} {reason}")]
    Camera {
        /// The camera as the user named it, or as it describes itself.
        camera: String,
        /// What is wrong (follows the camera's name), and what to do about it.
        reason: String,
    },
    /// The console (stdin, stdout) of a guided session could not be read or written.
    #[error("cannot {action} the console")]
    Console {
        /// What was being done (`read an answer from`, `write a prompt to`).
        action: &'static str,
        /// The cause (a Ctrl-C at a prompt is in here: `trial::prompt::is_interrupted`).
        source: std::io::Error,
    },
    /// A thread (or the tokio runtime's threads) could not be started.
    #[error("cannot start the {name}")]
    Thread {
        /// The thread (`perception thread`, `tokio runtime`).
        name: &'static str,
        /// The cause.
        source: std::io::Error,
    },
    /// A thread or a section run under `catch_unwind` panicked.
    #[error("{what} panicked: {message}")]
    Panic {
        /// What panicked (`the perception thread`, `the control loop`).
        what: &'static str,
        /// The panic message.
        message: String,
    },
    /// Ctrl-C (the stop flag) ended a prompt before its answer came.
    #[error("interrupted (Ctrl-C) at {at}; nothing moved")]
    Interrupted {
        /// The prompt (`the confirmation prompt`).
        at: &'static str,
    },
    /// The robot's operator did not confirm the start with `yes`.
    #[error("not confirmed ({answer:?} is not `yes`); nothing moved")]
    NotConfirmed {
        /// The answer given, trimmed.
        answer: String,
    },
    /// The robot is not in a state a trial can start from (no remote control, the safety
    /// status, the control program not playing).
    #[error("the robot at {host}: {reason}")]
    RobotNotReady {
        /// The robot's address.
        host: String,
        /// What is wrong, and what to do about it.
        reason: String,
    },
    /// Why a trial ended abnormally without an error (`link_lost`, `task_impossible`, ...), as
    /// the runtime saw it: the cause of its [`Error::Trial`].
    #[error("{why}")]
    Ending {
        /// What happened (`no new robot state for 1.0 s`), or the reason alone.
        why: String,
    },
    /// The control thread's log ring overflowed: the trial's logs miss records.
    #[error(
        "{dropped} control-rate log records were lost (the log ring was full); the logs in {} \
         are incomplete",
        dir.display()
    )]
    LogIncomplete {
        /// Records lost.
        dropped: u64,
        /// The run folder.
        dir: PathBuf,
    },
    /// An experiment ran, and wrote its report, but some of its trials failed.
    #[error(
        "{failed} of {trials} trials failed (each error is in {}); the trial logs are in {}",
        report.display(),
        dir.display()
    )]
    ExperimentFailed {
        /// Trials that failed.
        failed: usize,
        /// Trials run.
        trials: usize,
        /// `experiment_report.html`, which holds each error.
        report: PathBuf,
        /// The experiment folder.
        dir: PathBuf,
    },
    /// A guided session ended, but some of its trials failed.
    #[error(
        "{failed} of {trials} trials of the session failed; their logs and everything entered \
         are in {}",
        dir.display()
    )]
    SessionFailed {
        /// Trials that failed.
        failed: usize,
        /// Trials of the session.
        trials: usize,
        /// The session folder.
        dir: PathBuf,
    },
    /// The `assess` crate failed (configuration, cue files, the camera front-end).
    #[error(transparent)]
    Assess {
        /// The cause.
        source: assess::AssessError,
    },
    /// The `adapt` crate failed (the controller's configuration, kinematics, planning).
    #[error(transparent)]
    Adapt {
        /// The cause.
        source: adapt::AdaptError,
    },
    /// The `policies` crate failed (a rule table, an experiment design).
    #[error(transparent)]
    Policy {
        /// The cause.
        source: policies::PolicyError,
    },
    /// The `robot-io` crate failed (RTDE, the dashboard, the emulator, a trace).
    #[error(transparent)]
    Robot {
        /// The cause.
        source: robot_io::RobotIoError,
    },
    /// The `safety` crate failed (the supervisor's configuration, reading the robot).
    #[error(transparent)]
    Safety {
        /// The cause.
        source: safety::SafetyError,
    },
    /// A trial that did not end normally: its reason, its run folder and what went wrong
    /// ([`Error::exit_code`]).
    #[error(transparent)]
    Trial(Box<TrialEnded>),
    /// A bug: something the code relies on did not hold.
    #[error("internal: {reason}")]
    Internal {
        /// What did not hold.
        reason: String,
    },
    /// An error inside a file: the file, then the error.
    #[error("in {}", path.display())]
    InFile {
        /// The file.
        path: PathBuf,
        /// The error.
        source: Box<Error>,
    },
    /// An error with what was being done when it happened (where no other variant names it).
    #[error("{what}")]
    Context {
        /// What was being done, or what it means for the caller.
        what: String,
        /// The error.
        source: Box<Error>,
    },
}

/// Returns `Err($err.into())` from the enclosing function unless `$cond` holds (the library's
/// `ensure!`: the error is an [`Error`] built by the caller, not a message).
macro_rules! ensure {
    ($cond:expr, $err:expr $(,)?) => {
        if !$cond {
            return Err($err.into());
        }
    };
}

/// Result alias of this library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// A [`Error::Usage`] for `arg`, with the whole message `reason`.
    pub(crate) fn usage(arg: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Usage {
            arg: arg.into(),
            reason: reason.into(),
        }
    }

    /// A [`Error::Config`] for `field`: `reason` follows the field's name.
    pub(crate) fn config(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Config {
            field: field.into(),
            reason: reason.into(),
        }
    }

    /// A [`Error::Data`] about `what`.
    pub(crate) fn data(what: impl std::fmt::Display, reason: impl Into<String>) -> Self {
        Self::Data {
            what: what.to_string(),
            reason: reason.into(),
        }
    }

    /// The [`Error::Io`] of an `action` on `path`, for `map_err`.
    pub(crate) fn io(action: &'static str, path: &Path) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.to_path_buf();
        move |source| Self::Io {
            action,
            path,
            source,
        }
    }

    /// The [`Error::Csv`] of an `action` on `path`, for `map_err`.
    pub(crate) fn csv(action: &'static str, path: &Path) -> impl FnOnce(csv::Error) -> Self {
        let path = path.to_path_buf();
        move |source| Self::Csv {
            action,
            path,
            source,
        }
    }

    /// The [`Error::Mcap`] of an `action` on `path`, for `map_err`.
    pub(crate) fn mcap(action: &'static str, path: &Path) -> impl FnOnce(mcap::McapError) -> Self {
        let path = path.to_path_buf();
        move |source| Self::Mcap {
            action,
            path,
            source,
        }
    }

    /// The [`Error::Json`] of an `action` on `what`, for `map_err`.
    pub(crate) fn json(
        action: &'static str,
        what: impl std::fmt::Display,
    ) -> impl FnOnce(serde_json::Error) -> Self {
        let what = what.to_string();
        move |source| Self::Json {
            action,
            what,
            source,
        }
    }

    /// The [`Error::Toml`] of parsing `what`, for `map_err`.
    pub(crate) fn toml(what: impl std::fmt::Display) -> impl FnOnce(toml::de::Error) -> Self {
        let what = what.to_string();
        move |source| Self::Toml { what, source }
    }

    /// A [`Error::Panic`] of `what` from the payload of a caught panic.
    pub(crate) fn panic(what: &'static str, payload: &(dyn std::any::Any + Send)) -> Self {
        let message = payload
            .downcast_ref::<&str>()
            .copied()
            .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
            .unwrap_or("(no message)")
            .to_owned();
        Self::Panic { what, message }
    }

    /// This error inside `path` ([`Error::InFile`]).
    pub(crate) fn in_file(self, path: &Path) -> Self {
        Self::InFile {
            path: path.to_path_buf(),
            source: Box::new(self),
        }
    }

    /// This error with what was being done ([`Error::Context`]).
    pub(crate) fn context(self, what: impl Into<String>) -> Self {
        Self::Context {
            what: what.into(),
            source: Box::new(self),
        }
    }

    /// The trial ending this error is, or wraps in [`Error::Context`] or [`Error::InFile`].
    pub fn trial_ended(&self) -> Option<&TrialEnded> {
        match self {
            Self::Trial(t) => Some(t),
            Self::Context { source, .. } | Self::InFile { source, .. } => source.trial_ended(),
            _ => None,
        }
    }

    /// The process exit code of this error (README, "Exit codes"): the trial's
    /// ([`TrialEnded::exit_code`]) when a trial ended abnormally, else 1.
    pub fn exit_code(&self) -> u8 {
        self.trial_ended().map_or(1, TrialEnded::exit_code)
    }

    /// The error and its causes on one line, `error: cause: cause`.
    pub fn with_causes(&self) -> WithCauses<'_> {
        WithCauses(self)
    }
}

/// `e` and its causes, outermost first.
pub(crate) fn causes<'a>(
    e: &'a (dyn std::error::Error + 'static),
) -> impl Iterator<Item = &'a (dyn std::error::Error + 'static)> {
    std::iter::successors(Some(e), |e| e.source())
}

/// An error and its causes on one line ([`Error::with_causes`]).
#[derive(Debug, Clone, Copy)]
pub struct WithCauses<'a>(&'a Error);

impl std::fmt::Display for WithCauses<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (i, c) in causes(self.0).enumerate() {
            if i > 0 {
                f.write_str(": ")?;
            }
            write!(f, "{c}")?;
        }
        Ok(())
    }
}

impl From<assess::AssessError> for Error {
    fn from(source: assess::AssessError) -> Self {
        Self::Assess { source }
    }
}

impl From<adapt::AdaptError> for Error {
    fn from(source: adapt::AdaptError) -> Self {
        Self::Adapt { source }
    }
}

impl From<policies::PolicyError> for Error {
    fn from(source: policies::PolicyError) -> Self {
        Self::Policy { source }
    }
}

impl From<robot_io::RobotIoError> for Error {
    fn from(source: robot_io::RobotIoError) -> Self {
        Self::Robot { source }
    }
}

impl From<safety::SafetyError> for Error {
    fn from(source: safety::SafetyError) -> Self {
        Self::Safety { source }
    }
}

impl From<TrialEnded> for Error {
    fn from(t: TrialEnded) -> Self {
        Self::Trial(Box::new(t))
    }
}

/// `.context(..)` and `.with_context(..)` on results whose error converts into [`Error`]:
/// the error in an [`Error::Context`].
pub(crate) trait ResultExt<T> {
    /// The error with `what` was being done.
    fn context(self, what: impl Into<String>) -> Result<T>;
    /// The error with what was being done, computed only on an error.
    fn with_context<S: Into<String>>(self, what: impl FnOnce() -> S) -> Result<T>;
}

impl<T, E: Into<Error>> ResultExt<T> for std::result::Result<T, E> {
    fn context(self, what: impl Into<String>) -> Result<T> {
        self.map_err(|e| e.into().context(what))
    }

    fn with_context<S: Into<String>>(self, what: impl FnOnce() -> S) -> Result<T> {
        self.map_err(|e| e.into().context(what()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_chain_is_on_one_line_and_the_trial_ending_is_found_through_context() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let e = Error::io("read", Path::new("a.toml"))(io)
            .in_file(Path::new("trial.toml"))
            .context("the trial config");
        assert_eq!(
            e.with_causes().to_string(),
            "the trial config: in trial.toml: cannot read a.toml: no such file"
        );
        assert_eq!(e.exit_code(), 1);
        let ended = Error::from(TrialEnded::before_start(
            crate::trial::runtime::reason::INTERRUPTED,
            Error::usage("--x", "not confirmed"),
        ));
        assert_eq!(ended.exit_code(), 130);
        let wrapped = ended.context("participant P01, trial 3");
        assert_eq!(wrapped.exit_code(), 130, "{}", wrapped.with_causes());
    }
}
