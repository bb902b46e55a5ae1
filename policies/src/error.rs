//! The crate's error type.

use std::path::PathBuf;

/// Errors of the `policies` crate. Messages are lowercase and name the offending key.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PolicyError {
    /// A value breaks a rule (range, finiteness).
    #[error("invalid value for `{key}`: {rule}, got {value}")]
    InvalidValue {
        /// The dotted TOML key (`rules.OHD.speed_scale`, `limits.min_hold_s`), or the name of the
        /// quantity for values built in code (`speed_scale`).
        key: String,
        /// The rule it breaks.
        rule: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A rule table names a rule that is not an indicator.
    #[error("unknown rule `rules.{key}`: expected one of none, AED, TID, ICD, ASD_ctx, OHD")]
    UnknownRule {
        /// The key as written.
        key: String,
    },
    /// A rule table lacks one of the six rules (`none` and the five indicators).
    #[error("missing rule `rules.{key}`: the table needs none, AED, TID, ICD, ASD_ctx and OHD")]
    MissingRule {
        /// The missing key.
        key: &'static str,
    },
    /// A rule's `rationale` is empty.
    #[error("empty `rules.{key}.rationale`: every rule must say why")]
    EmptyRationale {
        /// The rule's key.
        key: String,
    },
    /// A TOML document could not be parsed (syntax, unknown key, wrong type).
    #[error("{origin}: {message}")]
    Parse {
        /// The file, or `<string>` for in-memory documents.
        origin: String,
        /// The parser's message, with line, column and the offending key.
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
    /// A policy name that is neither `fixed` nor `adaptive`.
    #[error("unknown policy `{name}`: expected fixed or adaptive")]
    UnknownPolicy {
        /// The name as given.
        name: String,
    },
    /// An experiment design that cannot be scheduled.
    #[error("invalid experiment design: {reason}")]
    InvalidDesign {
        /// What is wrong.
        reason: String,
    },
}

/// Result alias of this crate.
pub type Result<T, E = PolicyError> = std::result::Result<T, E>;

impl PolicyError {
    pub(crate) fn invalid(key: impl Into<String>, rule: &'static str, value: f64) -> Self {
        PolicyError::InvalidValue {
            key: key.into(),
            rule,
            value,
        }
    }
}
