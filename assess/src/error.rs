//! The crate's error type.

use std::path::PathBuf;

/// Errors of the `assess` crate. Messages are lowercase and name the offending key or file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AssessError {
    /// A configuration or calibration value breaks a rule of the model.
    #[error("invalid value for `{key}`: {rule}")]
    InvalidValue {
        /// The TOML key, dotted (`switching.cost_high`, `area[2].size_m`).
        key: String,
        /// The rule it breaks, with the offending value.
        rule: String,
    },
    /// A TOML document could not be parsed (syntax, unknown key, wrong type).
    #[error("{}: {message}", origin.display())]
    Parse {
        /// The file (or `<string>` for in-memory documents).
        origin: PathBuf,
        /// The parser's message, including line and column and, for unknown keys, the key.
        message: String,
    },
    /// A file could not be read.
    #[error("cannot read {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A data file (a cue CSV) is malformed at a known place.
    #[error("{}:{line}:{column}: {message}", path.display())]
    Csv {
        /// The file.
        path: PathBuf,
        /// 1-based line of the offending record.
        line: u64,
        /// 1-based column (field index) of the offending cell; the first column when the whole
        /// record is at fault.
        column: usize,
        /// What is wrong, naming the column and quoting the cell.
        message: String,
    },
    /// A file could not be written.
    #[error("cannot write {}: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A value could not be written as TOML.
    #[error("cannot write the {what} as toml: {message}")]
    Serialize {
        /// What was being written.
        what: &'static str,
        /// The serializer's message.
        message: String,
    },
    /// A model file, or the ONNX Runtime library, could not be loaded or run.
    #[error("model {}: {message}", path.display())]
    Model {
        /// The model (or runtime library) file.
        path: PathBuf,
        /// What failed, with the runtime's message.
        message: String,
    },
    /// A frame source (camera, `.bag`, video, image folder) failed.
    #[error("{source_name}: {message}")]
    Source {
        /// The source as the user named it (device serial, file path).
        source_name: String,
        /// What failed.
        message: String,
    },
    /// An output (a landmark file, an image folder, a video) was refused so that nothing is
    /// overwritten, or cannot hold what it was given.
    #[error("{}: {message}", path.display())]
    Output {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// Processing one camera frame failed.
    #[error("frame {index}: {source}")]
    Frame {
        /// The source's frame number.
        index: u64,
        /// What failed.
        source: Box<AssessError>,
    },
    /// An image-processing or calibration step failed.
    #[error("{operation}: {message}")]
    Vision {
        /// The step ("warp", "solvePnP", "ArUco detection", ...).
        operation: &'static str,
        /// What failed.
        message: String,
    },
}

/// Result alias of this crate.
pub type Result<T, E = AssessError> = std::result::Result<T, E>;

/// Reads a whole text file; a failure is [`AssessError::Io`] naming the file.
pub(crate) fn read_text(path: &std::path::Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|source| AssessError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Parses a TOML document; a failure is [`AssessError::Parse`] naming `origin` (the file, or
/// `<string>`), with the parser's line, column and key.
pub(crate) fn parse_toml<T: serde::de::DeserializeOwned>(
    text: &str,
    origin: &std::path::Path,
) -> Result<T> {
    toml::from_str(text).map_err(|e| AssessError::Parse {
        origin: origin.to_path_buf(),
        message: e.to_string(),
    })
}

impl AssessError {
    pub(crate) fn invalid(key: impl Into<String>, rule: impl Into<String>) -> Self {
        Self::InvalidValue {
            key: key.into(),
            rule: rule.into(),
        }
    }
}
