//! `hrc-adapt trial`: one closed-loop adaptive handover trial (issue 5; being written).

mod events;
mod log;
mod operator;
mod report;
mod runtime;

use clap::Args;

/// Arguments of `hrc-adapt trial`.
#[derive(Debug, Args)]
pub(crate) struct TrialArgs {
    /// Participant id, used in the run folder name.
    #[arg(long, default_value = "P00")]
    participant: String,
}

pub(crate) fn run(args: TrialArgs) -> anyhow::Result<()> {
    anyhow::bail!("`trial` is not implemented yet (issue 5); participant {}", args.participant)
}
