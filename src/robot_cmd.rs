//! `hrc-adapt record` and `hrc-adapt emulate` (issue 3).

use clap::Args;

/// Arguments of `hrc-adapt record`.
#[derive(Debug, Args)]
pub(crate) struct RecordArgs {
    /// Controller host (a UR5e, URSim, or the emulator).
    #[arg(long)]
    robot: String,
}

/// Arguments of `hrc-adapt emulate`.
#[derive(Debug, Args)]
pub(crate) struct EmulateArgs {
    /// Back the emulator with the in-process UR5e model.
    #[arg(long)]
    sim: bool,
}

pub(crate) fn record(args: RecordArgs) -> anyhow::Result<()> {
    anyhow::bail!("`record` is not implemented yet (issue 3); asked to record {}", args.robot)
}

pub(crate) fn emulate(args: EmulateArgs) -> anyhow::Result<()> {
    anyhow::bail!("`emulate` is not implemented yet (issue 3); sim = {}", args.sim)
}
