//! `hrc-adapt experiment`: a simulated policy A/B experiment (issue 5).
//!
//! 1. Reads the experiment TOML ([`ExperimentConfig`], `config/experiment-ab.toml`).
//! 2. Draws the counterbalanced schedule with [`policies::ExperimentDesign`] (a Williams design
//!    over the condition × policy cells, from the seed) and writes it as `schedule.csv` into
//!    `<out-root>/<timestamp>-experiment/` (a new folder: `-2`, `-3`, … when that exists).
//! 3. Runs every trial with the simulated operator ([`crate::trial::run_simulated`]), one trial
//!    folder each under the experiment folder. A participant's session is one job: its trials
//!    run in schedule order on one worker; `--jobs` workers take sessions from a shared queue.
//!    Trial seeds are [`trial_seed`] of the experiment seed, the participant number and the
//!    trial's position, so a run is reproducible whatever the number of workers. A failed trial
//!    (error or panic) is recorded and the experiment goes on.
//! 4. Reads the trial folders' `summary.json` ([`aggregate`]), computes the statistics and writes
//!    `experiment_summary.json` and the self-contained `experiment_report.html` ([`report`]).
//! 5. Exits non-zero when any trial failed, after everything above is written, naming how many
//!    and where their errors and logs are.
//!
//! With `--replicate N` it runs N seeded replications and a power table ([`replicate`]); with
//! `--sensitivity <file.toml>` the experiment once per variant of the simulated operator's
//! response to the robot and a sensitivity table ([`sensitivity`]).
//!
//! With `--participant P03 --robot <ip|emulator>` it instead guides one participant's real
//! session, trial by trial, with start / pause / skip / quit prompts and the NASA-TLX ratings
//! after each trial ([`session`]).

pub(crate) mod aggregate;
pub(crate) mod replicate;
pub(crate) mod report;
pub(crate) mod sensitivity;
pub(crate) mod session;

use std::collections::VecDeque;
use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, mpsc};

use clap::Args;
use policies::{Condition, ExperimentDesign, PolicyKind, Schedule, SplitMix64};
use serde::Deserialize;

use crate::Error;
use crate::error::ResultExt as _;
use crate::trial::config::{OperatorResponse, TrialConfig};
use crate::trial::{CueSource, TrialSpec, run_simulated};

/// Arguments of `hrc-adapt experiment`.
#[derive(Debug, Args)]
pub struct ExperimentArgs {
    /// The experiment TOML (participants, conditions, policies, seed, trial config).
    #[arg(long)]
    config: PathBuf,
    /// Folder under which `<timestamp>-experiment/` is created.
    #[arg(long, default_value = "runs")]
    out_root: PathBuf,
    /// Trials run in parallel (default: the available cores), 1..=256 (one thread each).
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=256))]
    jobs: Option<usize>,
    /// Run N seeded replications of the simulated experiment (2..=1000), each a whole
    /// experiment in `rep-XX/`, and write a power table (`power.csv`, `power.md`): per metric
    /// the distribution of the policy effect and the share of replications in which the
    /// Wilcoxon test is significant at α = 0.05. Replication 1 uses the file's seed.
    #[arg(long, conflicts_with = "participant", value_name = "N",
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(2..=1000))]
    replicate: Option<usize>,
    /// Run the simulated experiment once per variant of the simulated operator's response to
    /// the robot listed in this TOML file (`config/sensitivity.toml`), each a whole experiment
    /// in `<variant>/`, and write a sensitivity table (`sensitivity.csv`, `sensitivity.md`):
    /// per variant and metric the median paired difference, rank-biserial r, p and Holm p.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["participant", "replicate"])]
    sensitivity: Option<PathBuf>,
    /// Guide this participant's real session (their schedule rows, trial by trial, with
    /// prompts and NASA-TLX) instead of running the simulated experiment. An id of the
    /// schedule (`P01`, …; [A-Za-z0-9_-]{1,32}, as it names the session folder).
    #[arg(long, value_parser = crate::trial::participant_id)]
    participant: Option<String>,
    /// Real session: the robot, `emulator` (in-process controller emulator over loopback RTDE),
    /// `sim` (in-process, for a rehearsal) or a UR5e's address.
    #[arg(long, requires = "participant")]
    robot: Option<String>,
    /// Real session: how the robot is driven, `native` or `ur_rtde` (see `trial
    /// --robot-backend`).
    #[arg(long, requires = "participant", default_value = "native", value_parser = ["native", "ur_rtde"])]
    robot_backend: String,
    /// Real session with `--robot emulator`: controller cycles per 2 ms of wall time
    /// (default 4; a live camera needs 1, its default then), 1..=100: one cycle every
    /// 2 ms / N of wall time, and the trial loop already skips most samples far below 100.
    #[arg(long, requires = "participant", value_parser = crate::trial::speedup_parser())]
    speedup: Option<u32>,
    /// Real session: take each trial's cues from a live camera (`camera`: a RealSense with
    /// feature `realsense`, else the first webcam; or `webcam:N`) instead of the simulated
    /// operator. Each trial folder then holds cues and landmarks, no images.
    #[arg(long, requires = "participant", value_name = "camera|webcam:N")]
    cues: Option<PathBuf>,
    /// Live camera options (with `--cues`).
    #[command(flatten)]
    camera: crate::vision_cmd::CameraArgs,
}

/// The experiment file (every key is documented in `config/experiment-ab.toml`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct ExperimentConfig {
    /// Number of simulated participants (named P01, P02, …).
    pub(crate) participants: usize,
    /// Task conditions (L1, L2, L3).
    pub(crate) conditions: Vec<Condition>,
    /// The two policies compared, treatment first: the Wilcoxon test is of `policies[0]` −
    /// `policies[1]`.
    pub(crate) policies: Vec<String>,
    /// Seed of the schedule and of every trial's simulated operator.
    pub(crate) seed: u64,
    /// The trial configuration, relative to the experiment file.
    pub(crate) trial_config: PathBuf,
}

impl ExperimentConfig {
    /// Reads and checks an experiment file; `trial_config` becomes relative to the process.
    pub(crate) fn from_file(path: &Path) -> crate::Result<ExperimentConfig> {
        let text = std::fs::read_to_string(path).map_err(Error::io("read", path))?;
        let mut cfg: ExperimentConfig =
            toml::from_str(&text).map_err(Error::toml(path.display()))?;
        cfg.trial_config = path
            .parent()
            .unwrap_or(Path::new("."))
            .join(&cfg.trial_config);
        ensure!(
            cfg.policies.len() == 2,
            Error::config(
                "policies",
                format!(
                    "must name exactly two policies (treatment, baseline), got {}",
                    cfg.policies.len()
                )
            )
            .in_file(path)
        );
        for p in &cfg.policies {
            p.parse::<PolicyKind>()
                .map_err(|e| Error::from(e).context("`policies`").in_file(path))?;
        }
        Ok(cfg)
    }

    /// The design handed to [`ExperimentDesign::schedule`].
    pub(crate) fn design(&self) -> ExperimentDesign {
        ExperimentDesign {
            participants: self.participants,
            conditions: self.conditions.clone(),
            policies: self.policies.clone(),
            seed: self.seed,
        }
    }
}

/// The simulated operator's seed of participant `participant` (0-based) at 1-based session
/// position `position`: the first SplitMix64 output seeded with the experiment seed mixed with
/// both (participant in the high 32 bits, position in the low 32 bits, times the golden-ratio
/// constant). Depends on nothing else, so a trial's seed is the same with any `--jobs`.
pub(crate) fn trial_seed(seed: u64, participant: usize, position: usize) -> u64 {
    let key = ((participant as u64) << 32) | position as u64;
    SplitMix64::new(seed ^ key.wrapping_mul(0x9e37_79b9_7f4a_7c15)).next_u64()
}

/// One scheduled trial, ready to run.
#[derive(Debug, Clone)]
pub(crate) struct PlannedTrial {
    /// Participant id (`P01`, …).
    pub(crate) participant: String,
    /// 1-based position in the participant's session.
    pub(crate) position: usize,
    /// Task condition.
    pub(crate) condition: Condition,
    /// Policy.
    pub(crate) policy: PolicyKind,
    /// Williams square row of the session.
    pub(crate) square_row: usize,
    /// Simulated operator seed ([`trial_seed`]).
    pub(crate) seed: u64,
    /// The trial folder's name under the experiment folder.
    pub(crate) folder: String,
}

/// What became of one trial.
#[derive(Debug, Clone)]
pub(crate) struct TrialRun {
    /// The trial.
    pub(crate) trial: PlannedTrial,
    /// Wall time [s].
    pub(crate) wall_s: f64,
    /// The error, if it failed.
    pub(crate) error: Option<String>,
}

/// Every trial of `schedule`, session by session in running order.
pub(crate) fn plan(schedule: &Schedule, seed: u64) -> crate::Result<Vec<Vec<PlannedTrial>>> {
    schedule
        .sessions
        .iter()
        .enumerate()
        .map(|(p, s)| {
            s.trials
                .iter()
                .enumerate()
                .map(|(i, t)| {
                    let position = i + 1;
                    Ok(PlannedTrial {
                        participant: s.participant.clone(),
                        position,
                        condition: t.condition,
                        policy: t.policy.parse()?,
                        square_row: s.square_row,
                        seed: trial_seed(seed, p, position),
                        folder: format!(
                            "{}-{position:02}-{}-{}",
                            s.participant, t.condition, t.policy
                        ),
                    })
                })
                .collect()
        })
        .collect()
}

/// Writes `schedule.csv`: one row per trial, session by session in running order.
pub(crate) fn write_schedule(path: &Path, sessions: &[Vec<PlannedTrial>]) -> crate::Result<()> {
    let mut w = csv::Writer::from_path(path).map_err(Error::csv("create", path))?;
    w.write_record([
        "participant",
        "position",
        "condition",
        "policy",
        "square_row",
        "seed",
        "folder",
    ])
    .map_err(Error::csv("write", path))?;
    for t in sessions.iter().flatten() {
        w.write_record([
            t.participant.clone(),
            t.position.to_string(),
            t.condition.to_string(),
            t.policy.to_string(),
            t.square_row.to_string(),
            t.seed.to_string(),
            t.folder.clone(),
        ])
        .map_err(Error::csv("write", path))?;
    }
    w.flush().map_err(Error::io("write", path))?;
    Ok(())
}

/// Runs every session on `jobs` worker threads (a session's trials in order on one worker) and
/// returns every trial's outcome in schedule order. `on_done` is called on this thread after each
/// trial.
pub(crate) fn run_trials(
    sessions: Vec<Vec<PlannedTrial>>,
    trial_config: &TrialConfig,
    dir: &Path,
    jobs: usize,
    on_done: &mut dyn FnMut(&TrialRun),
) -> Vec<TrialRun> {
    let order: Vec<(String, usize)> = sessions
        .iter()
        .flatten()
        .map(|t| (t.participant.clone(), t.position))
        .collect();
    let queue = Arc::new(Mutex::new(VecDeque::from(sessions)));
    let (tx, rx) = mpsc::channel::<TrialRun>();
    let mut runs = Vec::with_capacity(order.len());
    std::thread::scope(|scope| {
        for _ in 0..jobs.max(1) {
            let (queue, tx) = (queue.clone(), tx.clone());
            scope.spawn(move || {
                // Many trials' per-cycle supervisor messages would bury the progress bar:
                // workers log errors only unless RUST_LOG says otherwise (safety events are in
                // each trial's log and summary.json).
                let _log = crate::trial::scoped_log("error");
                while let Some(session) = queue.lock().map_or(None, |mut q| q.pop_front()) {
                    for trial in session {
                        let run = run_one(trial, trial_config, dir);
                        if tx.send(run).is_err() {
                            return;
                        }
                    }
                }
            });
        }
        drop(tx);
        for run in rx {
            on_done(&run);
            runs.push(run);
        }
    });
    runs.sort_by_key(|r| {
        order
            .iter()
            .position(|(p, i)| *p == r.trial.participant && *i == r.trial.position)
    });
    runs
}

/// Runs one trial; an error or a panic becomes [`TrialRun::error`].
fn run_one(trial: PlannedTrial, trial_config: &TrialConfig, dir: &Path) -> TrialRun {
    let started = std::time::Instant::now();
    let spec = TrialSpec {
        participant: trial.participant.clone(),
        condition: trial.condition.as_str().parse().expect("L1..L3 parse"),
        policy: trial.policy,
        seed: trial.seed,
        config: trial_config.clone(),
    };
    let out = dir.join(&trial.folder);
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        run_simulated(&spec, &out, false)
    }));
    let error = match result {
        Ok(Ok(_)) => None,
        Ok(Err(e)) => Some(e.with_causes().to_string()),
        Err(panic) => Some(format!(
            "panicked: {}",
            panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("(no message)")
        )),
    };
    TrialRun {
        trial,
        wall_s: started.elapsed().as_secs_f64(),
        error,
    }
}

/// Runs `hrc-adapt experiment`.
pub fn run(args: ExperimentArgs) -> crate::Result<()> {
    if let Some(participant) = &args.participant {
        return run_real_session(&args, participant);
    }
    let jobs = args.jobs.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    ensure!(
        jobs >= 1,
        Error::usage("--jobs", "--jobs must be at least 1")
    );
    let show = std::io::stderr().is_terminal();
    if let Some(file) = &args.sensitivity {
        let wanted = args
            .out_root
            .join(format!("{}-sensitivity", crate::trial::wall_stamp()));
        let out = sensitivity::run_sensitivity(&args.config, file, &wanted, jobs, show)?;
        eprintln!(
            "[simulation] {} variants: {} trials ({} failed); sensitivity table in {}",
            out.variants.len(),
            out.trials,
            out.failed,
            out.dir.join("sensitivity.md").display()
        );
        for metric in aggregate::METRICS {
            let effects: Vec<String> = out
                .rows
                .iter()
                .filter(|r| r.metric == metric)
                .map(|r| {
                    format!(
                        "{} {:.3} (p {:.3})",
                        r.variant, r.effect.median_difference, r.effect.p_value
                    )
                })
                .collect();
            eprintln!("  {metric:<18} {}", effects.join(", "));
        }
        println!("{}", out.dir.display());
        ensure!(
            out.failed == 0,
            Error::ExperimentFailed {
                failed: out.failed,
                trials: out.trials,
                report: out.dir.join("sensitivity.md"),
                dir: out.dir,
            }
        );
        return Ok(());
    }
    if let Some(n) = args.replicate {
        let wanted = args
            .out_root
            .join(format!("{}-replicate", crate::trial::wall_stamp()));
        let out = replicate::run_replications(&args.config, &wanted, jobs, n, show)?;
        eprintln!(
            "[simulation] {n} replications: {} trials ({} failed); power table in {}",
            out.trials,
            out.failed,
            out.dir.join("power.md").display()
        );
        for t in &out.table {
            eprintln!(
                "  {:<18} power {:.2} (Holm {:.2}), effect median {:.3}",
                t.metric, t.power_raw, t.power_holm, t.effect[0]
            );
        }
        println!("{}", out.dir.display());
        ensure!(
            out.failed == 0,
            Error::ExperimentFailed {
                failed: out.failed,
                trials: out.trials,
                report: out.dir.join("power.md"),
                dir: out.dir,
            }
        );
        return Ok(());
    }
    let wanted = args
        .out_root
        .join(format!("{}-experiment", crate::trial::wall_stamp()));
    let out = run_experiment(&args.config, &wanted, jobs, show)?;
    eprintln!(
        "[simulation] {} trials ({} failed) in {:.1} s wall time on {jobs} worker(s)",
        out.trials, out.failed, out.wall_s
    );
    println!("{}", out.report.display());
    // Everything that could be written is; a failed trial still fails the command.
    ensure!(
        out.failed == 0,
        Error::ExperimentFailed {
            failed: out.failed,
            trials: out.trials,
            report: out.report,
            dir: out.dir,
        }
    );
    Ok(())
}

/// The schedule rows of `participant` (e.g. `P03`) in the experiment file's design.
pub(crate) fn participant_trials(
    cfg: &ExperimentConfig,
    participant: &str,
) -> crate::Result<Vec<PlannedTrial>> {
    let schedule = cfg.design().schedule().context("invalid design")?;
    let sessions = plan(&schedule, cfg.seed)?;
    let known: Vec<&str> = schedule
        .sessions
        .iter()
        .map(|s| s.participant.as_str())
        .collect();
    sessions
        .into_iter()
        .find(|s| s.first().is_some_and(|t| t.participant == participant))
        .ok_or_else(|| {
            Error::usage(
                "--participant",
                format!(
                    "participant {participant} is not in the schedule ({})",
                    known.join(", ")
                ),
            )
        })
}

/// `hrc-adapt experiment --participant P03 --robot …`: the guided real session of one
/// participant into `<out-root>/<timestamp>-session-P03/` ([`session`]).
fn run_real_session(args: &ExperimentArgs, participant: &str) -> crate::Result<()> {
    use crate::trial::runtime;
    let cfg = ExperimentConfig::from_file(&args.config)?;
    let trial_config = TrialConfig::from_file(&cfg.trial_config)?;
    let trials = participant_trials(&cfg, participant).map_err(|e| e.in_file(&args.config))?;
    let robot_name = args.robot.clone().unwrap_or_else(|| "emulator".into());
    let cues = crate::trial::cue_source(args.cues.as_deref(), &args.camera, None)?;
    ensure!(
        matches!(cues, CueSource::Simulated | CueSource::Camera(_)),
        Error::usage(
            "--cues",
            "--cues in a session takes `camera` or `webcam:N` (a live camera), not a recorded \
             file"
        )
    );
    let live = matches!(cues, CueSource::Camera(_));
    let robot = crate::trial::robot_choice(&robot_name, args.speedup, live)?;
    let robot = crate::trial::with_backend(robot, &args.robot_backend, args.speedup)?;
    let dir = crate::trial::create_run_dir(&args.out_root.join(format!(
        "{}-session-{participant}",
        crate::trial::wall_stamp()
    )))?;
    write_schedule(&dir.join("schedule.csv"), std::slice::from_ref(&trials))?;
    eprintln!(
        "session of {participant} on {robot_name}: {} trials, folder {}",
        trials.len(),
        dir.display()
    );
    // Trial logs: errors and the trial's own warnings only, as `hrc-adapt trial` does.
    let _log = crate::trial::scoped_log(crate::trial::TRIAL_LOG);
    // Ctrl-C during a trial stops that trial through the supervisor (the flag is cleared
    // before and after each trial); at a prompt it ends the session (nothing moves, every
    // rating entered is kept).
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    crate::trial::install_ctrl_c(stop.clone());
    let show = std::io::stderr().is_terminal();
    let mut run_trial = |t: &PlannedTrial, out: &Path| -> crate::Result<PathBuf> {
        stop.store(false, std::sync::atomic::Ordering::Relaxed);
        let spec = TrialSpec {
            participant: t.participant.clone(),
            condition: t.condition.as_str().parse()?,
            policy: t.policy,
            seed: t.seed,
            config: trial_config.clone(),
        };
        let bar = runtime::progress_bar(show);
        let result = runtime::run_trial_with_cues(&spec, &robot, &cues, out, &stop, &mut |l| {
            runtime::update_bar(&bar, l)
        });
        bar.finish_and_clear();
        if stop.swap(false, std::sync::atomic::Ordering::Relaxed) {
            eprintln!("interrupted: robot stopped, logs closed");
        }
        result
    };
    // The prompts read stdin through the process's one prompt reader (the UR5e backend's
    // `yes` too), and a Ctrl-C ends them.
    let mut input = crate::trial::prompt::PromptInput::stdin(&stop);
    let record = session::run_session(
        &trials,
        &dir,
        &mut input,
        &mut std::io::stdout(),
        &mut run_trial,
    )
    .map_err(|e| {
        if crate::trial::prompt::is_interrupted(&e) {
            // Exit code 130, as a trial's Ctrl-C (README, "Exit codes").
            runtime::TrialEnded::before_start(
                runtime::reason::INTERRUPTED,
                e.context(format!(
                    "session interrupted at a prompt; nothing moved; everything entered is \
                     in {}",
                    dir.display()
                )),
            )
            .into()
        } else {
            e
        }
    })?;
    if record.quit {
        eprintln!(
            "session quit early; everything entered is in {}",
            dir.display()
        );
    }
    println!("{}", dir.display());
    let failed = record
        .steps
        .iter()
        .filter(|(_, o)| matches!(o, session::StepOutcome::Failed(_)))
        .count();
    ensure!(
        failed == 0,
        Error::SessionFailed {
            failed,
            trials: trials.len(),
            dir,
        }
    );
    Ok(())
}

/// What [`run_experiment`] did.
#[derive(Debug)]
pub(crate) struct ExperimentOutcome {
    /// The experiment folder.
    pub(crate) dir: PathBuf,
    /// Trials run.
    pub(crate) trials: usize,
    /// Of which failed.
    pub(crate) failed: usize,
    /// Wall time of the whole experiment [s].
    pub(crate) wall_s: f64,
    /// `experiment_report.html`.
    pub(crate) report: PathBuf,
}

/// The whole experiment into a new folder: `wanted`, or `wanted-2`, … when that exists
/// ([`crate::trial::create_run_dir`]), created once the configuration has loaded.
pub(crate) fn run_experiment(
    config_path: &Path,
    wanted: &Path,
    jobs: usize,
    show_progress: bool,
) -> crate::Result<ExperimentOutcome> {
    run_experiment_seeded(config_path, wanted, jobs, show_progress, None)
}

/// [`run_experiment`] with the file's seed replaced by `seed` when given (a replication).
pub(crate) fn run_experiment_seeded(
    config_path: &Path,
    wanted: &Path,
    jobs: usize,
    show_progress: bool,
    seed: Option<u64>,
) -> crate::Result<ExperimentOutcome> {
    let overrides = Overrides {
        seed,
        response: None,
    };
    run_experiment_with(config_path, wanted, jobs, show_progress, &overrides)
}

/// What a replication or a sensitivity variant changes in an experiment's files.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Overrides {
    /// Replaces the experiment file's seed (a replication).
    pub(crate) seed: Option<u64>,
    /// Replaces the trial config's `[operator.response]` (a sensitivity variant; validated by
    /// the caller).
    pub(crate) response: Option<OperatorResponse>,
}

/// [`run_experiment`] with `overrides` applied to the files' values.
pub(crate) fn run_experiment_with(
    config_path: &Path,
    wanted: &Path,
    jobs: usize,
    show_progress: bool,
    overrides: &Overrides,
) -> crate::Result<ExperimentOutcome> {
    let started = std::time::Instant::now();
    let mut cfg = ExperimentConfig::from_file(config_path)?;
    if let Some(seed) = overrides.seed {
        cfg.seed = seed;
    }
    let mut trial_config = TrialConfig::from_file(&cfg.trial_config)?;
    if let Some(response) = overrides.response {
        trial_config.operator.response = response;
    }
    let schedule = cfg.design().schedule().map_err(|e| {
        Error::from(e)
            .context("invalid design")
            .in_file(config_path)
    })?;
    let sessions = plan(&schedule, cfg.seed)?;
    // Never an existing folder: experiments are not mixed.
    let dir = crate::trial::create_run_dir(wanted)?;
    let dir = dir.as_path();
    write_schedule(&dir.join("schedule.csv"), &sessions)?;

    let total = sessions.iter().map(Vec::len).sum::<usize>();
    let bar = if show_progress {
        indicatif::ProgressBar::new(total as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "[simulation] {bar:30} {pos}/{len} trials, {elapsed} elapsed, ETA {eta} {msg}",
        )
        .expect("valid template"),
    );
    let mut failed = 0;
    let runs = run_trials(sessions, &trial_config, dir, jobs, &mut |r| {
        if let Some(e) = &r.error {
            failed += 1;
            bar.println(format!("trial {} failed: {e}", r.trial.folder));
            bar.set_message(format!("({failed} failed)"));
        }
        bar.inc(1);
    });
    bar.finish_and_clear();

    let outcomes = aggregate::read_outcomes(dir)?;
    let report = report::write(
        dir,
        &report::Inputs {
            config: &cfg,
            schedule: &schedule,
            runs: &runs,
            outcomes: &outcomes,
            jobs,
            wall_s: started.elapsed().as_secs_f64(),
        },
    )?;
    Ok(ExperimentOutcome {
        dir: dir.to_path_buf(),
        trials: runs.len(),
        failed: runs.iter().filter(|r| r.error.is_some()).count(),
        wall_s: started.elapsed().as_secs_f64(),
        report,
    })
}

#[cfg(test)]
mod tests;
