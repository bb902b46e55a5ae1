//! A guided real session: `hrc-adapt experiment --config <ab.toml> --participant P03 --robot
//! <ip|emulator>` runs one participant's schedule rows, trial by trial, with the experimenter at
//! the keyboard.
//!
//! For each trial in schedule order it prints what comes next (trial n of m, condition, policy,
//! folder) and prompts `start / pause / skip / quit`:
//! - `start` runs the trial (the runner is injected: [`run_session`] takes it as a closure, the
//!   binary passes one that calls [`crate::trial::runtime::run_trial_with`] on the requested
//!   robot) and then asks the six raw NASA-TLX ratings (0–20 each, checked with
//!   [`crate::stats::raw_tlx`]; a bad answer is asked again);
//! - `pause` waits for Enter, then asks again;
//! - `skip` leaves the trial out and goes on;
//! - `quit` (or the end of the input) ends the session;
//! - Ctrl-C at any prompt ends it too, with an error that says "interrupted": the binary reads
//!   the answers through [`crate::trial::prompt::PromptInput`], whose reads fail once the stop
//!   flag is set, and that error ends [`run_session`] before anything else runs.
//!
//! Every rating row is appended to `nasa_tlx.csv` in the session folder and flushed at once, so
//! a quit (or a crash) keeps everything entered. A failed trial is reported, gets no ratings and
//! the session goes on. The prompting takes any `BufRead` + `Write`, so it is tested with
//! scripted answers (`tests.rs`).

use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};

use crate::Error;

use super::PlannedTrial;
use crate::stats;

/// The six NASA-TLX subscales in the order of the CSV columns: column name and prompt.
pub(crate) const TLX_SCALES: [(&str, &str); 6] = [
    ("mental", "Mental demand"),
    ("physical", "Physical demand"),
    ("temporal", "Temporal demand"),
    ("performance", "Performance"),
    ("effort", "Effort"),
    ("frustration", "Frustration"),
];

/// The file the ratings are appended to, in the session folder.
pub(crate) const TLX_FILE: &str = "nasa_tlx.csv";

/// What became of one trial of the session.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum StepOutcome {
    /// Ran; its raw TLX (the mean of the six ratings).
    Done {
        /// Raw TLX.
        raw_tlx: f64,
    },
    /// The trial runner returned an error (no ratings asked).
    Failed(String),
    /// Skipped by the experimenter.
    Skipped,
}

/// The session's record: the trials reached, in order, and whether it was quit early.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct SessionRecord {
    /// `(folder, outcome)` of every trial reached.
    pub(crate) steps: Vec<(String, StepOutcome)>,
    /// `quit` (or end of input) before the last trial.
    pub(crate) quit: bool,
}

/// The experimenter's answer at the trial prompt.
enum Command {
    Start,
    Pause,
    Skip,
    Quit,
}

/// Prints `prompt` and reads one trimmed line; `None` at the end of the input.
fn ask(
    input: &mut impl BufRead,
    out: &mut impl Write,
    prompt: &str,
) -> crate::Result<Option<String>> {
    write!(out, "{prompt}").map_err(to_console)?;
    out.flush().map_err(to_console)?;
    let mut line = String::new();
    if input.read_line(&mut line).map_err(from_console)? == 0 {
        writeln!(out).map_err(to_console)?;
        return Ok(None);
    }
    Ok(Some(line.trim().to_owned()))
}

/// Asks `start / pause / skip / quit` until a valid answer (`None` input = quit).
fn ask_command(input: &mut impl BufRead, out: &mut impl Write) -> crate::Result<Command> {
    loop {
        let Some(a) = ask(input, out, "start / pause / skip / quit > ")? else {
            return Ok(Command::Quit);
        };
        match a.to_ascii_lowercase().as_str() {
            "start" | "s" => return Ok(Command::Start),
            "pause" | "p" => return Ok(Command::Pause),
            "skip" => return Ok(Command::Skip),
            "quit" | "q" => return Ok(Command::Quit),
            other => writeln!(
                out,
                "unknown answer {other:?}: type start, pause, skip or quit"
            )
            .map_err(to_console)?,
        }
    }
}

/// Asks the six ratings, each until it is a number in [0, 20]; `None` at the end of the input.
fn ask_tlx(input: &mut impl BufRead, out: &mut impl Write) -> crate::Result<Option<[f64; 6]>> {
    writeln!(
        out,
        "NASA-TLX: rate each scale from 0 (very low) to 20 (very high)"
    )
    .map_err(to_console)?;
    let mut ratings = [0.0; 6];
    for (slot, (_, label)) in ratings.iter_mut().zip(TLX_SCALES) {
        loop {
            let Some(a) = ask(input, out, &format!("  {label} (0-20): "))? else {
                return Ok(None);
            };
            // One rating is valid when the raw TLX of six copies of it is.
            match a.parse::<f64>() {
                Ok(r) if stats::raw_tlx([r; 6]).is_ok() => {
                    *slot = r;
                    break;
                }
                _ => writeln!(out, "  {a:?} is not a rating: enter a number from 0 to 20")
                    .map_err(to_console)?,
            }
        }
    }
    Ok(Some(ratings))
}

/// Appends one row to `nasa_tlx.csv` (writing the header first if the file is new or empty)
/// and flushes it.
fn append_tlx(path: &Path, trial: &PlannedTrial, ratings: [f64; 6], raw: f64) -> crate::Result<()> {
    let file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(Error::io("open", path))?;
    let new = file.metadata().map_err(Error::io("inspect", path))?.len() == 0;
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .from_writer(file);
    if new {
        let mut header = vec!["participant", "trial", "condition", "policy"];
        header.extend(TLX_SCALES.iter().map(|(c, _)| *c));
        header.push("raw_tlx");
        w.write_record(&header).map_err(Error::csv("write", path))?;
    }
    let mut row = vec![
        trial.participant.clone(),
        trial.position.to_string(),
        trial.condition.to_string(),
        trial.policy.to_string(),
    ];
    row.extend(ratings.iter().map(f64::to_string));
    row.push(format!("{raw:.4}"));
    w.write_record(&row).map_err(Error::csv("write", path))?;
    w.flush().map_err(Error::io("write", path))?;
    Ok(())
}

/// Guides one participant's `trials` (in schedule order) with the experimenter: see the module
/// docs. `run_trial(trial, folder)` runs one trial into `folder` (under `dir`). Ratings go to
/// `dir/nasa_tlx.csv`.
pub(crate) fn run_session(
    trials: &[PlannedTrial],
    dir: &Path,
    input: &mut impl BufRead,
    out: &mut impl Write,
    run_trial: &mut dyn FnMut(&PlannedTrial, &Path) -> crate::Result<PathBuf>,
) -> crate::Result<SessionRecord> {
    let tlx_path = dir.join(TLX_FILE);
    let mut record = SessionRecord::default();
    let m = trials.len();
    for (i, trial) in trials.iter().enumerate() {
        writeln!(out).map_err(to_console)?;
        writeln!(
            out,
            "Next: trial {} of {m} for {}: condition {}, policy {} (folder {})",
            i + 1,
            trial.participant,
            trial.condition,
            trial.policy,
            trial.folder
        )
        .map_err(to_console)?;
        let command = loop {
            match ask_command(input, out)? {
                Command::Pause => {
                    if ask(input, out, "paused; press Enter to continue ")?.is_none() {
                        break Command::Quit;
                    }
                }
                c => break c,
            }
        };
        match command {
            Command::Quit => {
                writeln!(out, "session quit before trial {} of {m}", i + 1).map_err(to_console)?;
                record.quit = true;
                break;
            }
            Command::Skip => {
                writeln!(out, "trial {} of {m} skipped", i + 1).map_err(to_console)?;
                record
                    .steps
                    .push((trial.folder.clone(), StepOutcome::Skipped));
                continue;
            }
            Command::Pause => unreachable!("handled above"),
            Command::Start => {}
        }
        writeln!(out, "running trial {} of {m} ...", i + 1).map_err(to_console)?;
        out.flush().map_err(to_console)?;
        if let Err(e) = run_trial(trial, &dir.join(&trial.folder)) {
            let e = e.with_causes().to_string();
            writeln!(out, "trial {} of {m} failed: {e}", i + 1).map_err(to_console)?;
            record
                .steps
                .push((trial.folder.clone(), StepOutcome::Failed(e)));
            continue;
        }
        writeln!(out, "trial {} of {m} finished", i + 1).map_err(to_console)?;
        let Some(ratings) = ask_tlx(input, out)? else {
            writeln!(
                out,
                "input ended before the ratings of trial {} were complete",
                i + 1
            )
            .map_err(to_console)?;
            record.quit = true;
            break;
        };
        let raw = stats::raw_tlx(ratings).map_err(|e| Error::Internal {
            reason: format!("NASA-TLX ratings checked above: {e}"),
        })?;
        append_tlx(&tlx_path, trial, ratings, raw)?;
        writeln!(out, "raw TLX {raw:.2} saved to {}", tlx_path.display()).map_err(to_console)?;
        record
            .steps
            .push((trial.folder.clone(), StepOutcome::Done { raw_tlx: raw }));
    }
    let count = |f: fn(&StepOutcome) -> bool| record.steps.iter().filter(|(_, o)| f(o)).count();
    writeln!(
        out,
        "session of {}: {} done, {} failed, {} skipped, {} not reached",
        trials.first().map_or("", |t| t.participant.as_str()),
        count(|o| matches!(o, StepOutcome::Done { .. })),
        count(|o| matches!(o, StepOutcome::Failed(_))),
        count(|o| matches!(o, StepOutcome::Skipped)),
        m - record.steps.len()
    )
    .map_err(to_console)?;
    Ok(record)
}

/// The [`Error::Console`] of writing a prompt.
fn to_console(source: std::io::Error) -> Error {
    Error::Console {
        action: "write a prompt to",
        source,
    }
}

/// The [`Error::Console`] of reading an answer (a Ctrl-C there is inside it).
fn from_console(source: std::io::Error) -> Error {
    Error::Console {
        action: "read an answer from",
        source,
    }
}
