//! `hrc-adapt`: the command-line front of the workspace. Thin: each subcommand lives in its own
//! module and calls into the library crates.

mod assess_cmd;
#[cfg(feature = "vision")]
mod calibrate_cmd;
mod experiment;
mod report;
mod robot_cmd;
mod stats;
mod trial;
mod vision_cmd;

use clap::{Parser, Subcommand};

/// Adapts a UR5e cobot to its human operator from vision-based cognitive-workload assessment.
#[derive(Debug, Parser)]
#[command(name = "hrc-adapt", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Assess a recording offline: cues → indicators.csv and plots.
    Assess(assess_cmd::AssessArgs),
    /// Calibrate the camera against the ChArUco board (extrinsics file), or print the board.
    #[cfg(feature = "vision")]
    Calibrate(calibrate_cmd::CalibrateArgs),
    /// Record a live UR controller (or the emulator) over RTDE into a CSV trace.
    Record(robot_cmd::RecordArgs),
    /// Serve a UR controller emulator (RTDE, dashboard, script ports) on loopback.
    Emulate(robot_cmd::EmulateArgs),
    /// Run one adaptive handover trial (simulated operator + emulator by default).
    Trial(trial::TrialArgs),
    /// Run a policy A/B experiment from a schedule and report its statistics.
    Experiment(experiment::ExperimentArgs),
    /// Print configuration files.
    Config(ConfigArgs),
}

#[derive(Debug, clap::Args)]
struct ConfigArgs {
    /// Print the assessment model's default configuration (MODEL.md) as TOML.
    #[arg(long)]
    print_default: bool,
}

/// Runs the command; an error is printed as anyhow prints it, and the exit code says how a
/// trial ended (README, "Exit codes"): 1 for other errors, 2 for usage errors (clap).
fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("Error: {e:?}");
            std::process::ExitCode::from(trial::exit_code(&e))
        }
    }
}

fn run() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    match cli.command {
        Command::Assess(args) => assess_cmd::run(args),
        #[cfg(feature = "vision")]
        Command::Calibrate(args) => calibrate_cmd::run(args),
        Command::Record(args) => robot_cmd::record(args),
        Command::Emulate(args) => robot_cmd::emulate(args),
        Command::Trial(args) => trial::run(args),
        Command::Experiment(args) => experiment::run(args),
        Command::Config(args) => {
            anyhow::ensure!(args.print_default, "nothing to do: pass --print-default");
            print!("{}", assess::AssessConfig::default().to_toml_string()?);
            Ok(())
        }
    }
}
