//! `hrc-adapt experiment`: policy A/B experiments (issue 5; being written).

use std::path::PathBuf;

use clap::Args;

/// Arguments of `hrc-adapt experiment`.
#[derive(Debug, Args)]
pub(crate) struct ExperimentArgs {
    /// The experiment TOML (participants, conditions, policies, seed).
    #[arg(long)]
    config: PathBuf,
}

pub(crate) fn run(args: ExperimentArgs) -> anyhow::Result<()> {
    anyhow::bail!("`experiment` is not implemented yet (issue 5); config {}", args.config.display())
}
