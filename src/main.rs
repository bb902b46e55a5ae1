//! `hrc-adapt`: the command-line front of the workspace. Thin: the CLI ([`Cli`]), the dispatch
//! onto the `hrc_adapt` library's commands, and the exit codes. The only place `anyhow` is
//! used: it prints the library's [`hrc_adapt::Error`] with its whole chain of causes.

use clap::{Parser, Subcommand};
use hrc_adapt::{assess_cmd, episodes_cmd, experiment, robot_cmd, trial};

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
    Calibrate(hrc_adapt::calibrate_cmd::CalibrateArgs),
    /// Record a live UR controller (or the emulator) over RTDE into a CSV trace.
    Record(robot_cmd::RecordArgs),
    /// Serve a UR controller emulator (RTDE, dashboard, script ports) on loopback.
    Emulate(robot_cmd::EmulateArgs),
    /// Run one adaptive handover trial (simulated operator + emulator by default).
    Trial(trial::TrialArgs),
    /// Run a policy A/B experiment from a schedule and report its statistics.
    Experiment(experiment::ExperimentArgs),
    /// Measure the assessed against the simulated hesitation, episode by episode, over seeds ×
    /// conditions (SIMULATED ground truth).
    Episodes(episodes_cmd::EpisodesArgs),
    /// Print configuration files.
    Config(ConfigArgs),
}

#[derive(Debug, clap::Args)]
struct ConfigArgs {
    /// Print the assessment model's default configuration (the `assess` crate's spec) as TOML.
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
            std::process::ExitCode::from(exit_code(&e))
        }
    }
}

/// The process exit code of an error: the library's ([`hrc_adapt::Error::exit_code`]: how a
/// trial ended, README "Exit codes"), 1 for any other.
fn exit_code(e: &anyhow::Error) -> u8 {
    e.downcast_ref::<hrc_adapt::Error>()
        .map_or(1, hrc_adapt::Error::exit_code)
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
        Command::Assess(args) => assess_cmd::run(args)?,
        #[cfg(feature = "vision")]
        Command::Calibrate(args) => hrc_adapt::calibrate_cmd::run(args)?,
        Command::Record(args) => robot_cmd::record(args)?,
        Command::Emulate(args) => robot_cmd::emulate(args)?,
        Command::Trial(args) => trial::run(args)?,
        Command::Experiment(args) => experiment::run(args)?,
        Command::Episodes(args) => episodes_cmd::run(args)?,
        Command::Config(args) => {
            anyhow::ensure!(args.print_default, "nothing to do: pass --print-default");
            print!("{}", assess::AssessConfig::default().to_toml_string()?);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speedup_and_jobs_are_bounded_on_every_command_that_takes_them() {
        // Issue 10: `--speedup 4294967295` was accepted and hung the emulator.
        let parse = |args: &[&str]| {
            Cli::try_parse_from(["hrc-adapt"].iter().chain(args))
                .map(|_| ())
                .map_err(|e| e.to_string())
        };
        let experiment = ["experiment", "--config", "x.toml", "--participant", "P01"];
        for command in [&["trial"][..], &experiment[..], &["emulate", "--sim"][..]] {
            for ok in ["1", "100"] {
                let args = [command, &["--speedup", ok]].concat();
                assert!(parse(&args).is_ok(), "{args:?}: {:?}", parse(&args));
            }
            for bad in ["0", "101", "4294967295"] {
                let args = [command, &["--speedup", bad]].concat();
                let e = parse(&args).unwrap_err();
                assert!(e.contains("1..=100"), "{args:?}: {e}");
            }
        }
        // --jobs starts one thread per job.
        let jobs = |n: &str| parse(&["experiment", "--config", "x.toml", "--jobs", n]);
        assert!(jobs("256").is_ok());
        for bad in ["0", "257", "18446744073709551615"] {
            assert!(jobs(bad).unwrap_err().contains("1..=256"), "--jobs {bad}");
        }
    }

    #[test]
    fn participant_ids_that_could_leave_the_run_folder_are_refused_before_anything_starts() {
        // Issue 10: `--participant ../../x` was not checked (it names the run folder).
        let parse = |args: &[&str]| {
            Cli::try_parse_from(["hrc-adapt"].iter().chain(args))
                .map(|_| ())
                .map_err(|e| e.to_string())
        };
        let session = ["experiment", "--config", "x.toml", "--participant"];
        for command in [&["trial", "--participant"][..], &session[..]] {
            for ok in ["P01", "lab_3-b", &"x".repeat(32)] {
                let args = [command, &[ok]].concat();
                assert!(parse(&args).is_ok(), "{args:?}: {:?}", parse(&args));
            }
            let long = "x".repeat(33);
            for bad in ["../../x", "a/b", "..", "", "P 01", "P01\n", "Ü1", &long] {
                let args = [command, &[bad]].concat();
                let e = parse(&args).unwrap_err();
                assert!(e.contains("[A-Za-z0-9_-]{1,32}"), "{args:?}: {e}");
            }
        }
    }
}
