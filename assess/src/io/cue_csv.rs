//! The cue CSV format (see the README).
