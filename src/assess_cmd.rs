//! `hrc-adapt assess`: offline assessment of a recording.

use std::path::PathBuf;

use clap::Args;

/// Arguments of `hrc-adapt assess`.
#[derive(Debug, Args)]
pub(crate) struct AssessArgs {
    /// Cue CSV file, or a KTH handover folder.
    #[arg(long)]
    cues: PathBuf,
    /// Workspace calibration TOML.
    #[arg(long)]
    workspace: PathBuf,
    /// Model configuration TOML (default: MODEL.md's values).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
}

pub(crate) fn run(args: AssessArgs) -> anyhow::Result<()> {
    anyhow::bail!("`assess` is being built; got {args:?}")
}
