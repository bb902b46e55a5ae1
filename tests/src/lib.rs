//! # hrc-adapt-tests: cross-crate, real-data and hardware-in-the-loop tests
//!
//! The tests live in `tests/tests/`. This library holds only shared helpers, such as locating the
//! data bundled in the repository's `data/` folder.

use std::path::PathBuf;

/// The repository's bundled `data/` folder (real recordings with their licences beside them).
pub fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("data")
}

/// The repository's `config/` folder (shipped calibration and configuration files).
pub fn config_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("config")
}
