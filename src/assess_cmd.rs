//! `hrc-adapt assess`: offline assessment of a recording.
//!
//! Reads a cue CSV (`assess::io::cue_csv`) or a KTH handover folder (`assess::io::kth`), runs the
//! [`Assessor`] over every frame, and writes into `--out`:
//! - `indicators.csv`, one row per frame (columns in [`report::table`]);
//! - the indicator-dynamics plots, four panels and a combined figure ([`report::plot`]);
//! - `assess_config.toml`, the model configuration in force (every key).
//!
//! Everything is written into a temporary folder next to `--out` and renamed into place at the
//! end, so a failed run leaves no partial results. An existing non-empty `--out` is replaced only
//! with `--force`.

use crate::report;

use std::fmt::Write as _;
use std::fs;
use std::io::{BufWriter, IsTerminal as _, Write as _};
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use assess::{AssessConfig, Assessment, Assessor, CueFrame, Indicators, Workspace};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use report::Sample;
use report::plot::{self, Figure};
use report::table::IndicatorTable;

/// The per-frame table, inside `--out`.
const TABLE_FILE: &str = "indicators.csv";
/// The configuration in force, inside `--out`.
const CONFIG_FILE: &str = "assess_config.toml";

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
    /// Output folder; created, and refused if it exists and is not empty (see --force).
    #[arg(long)]
    out: PathBuf,
    /// Replace an existing non-empty output folder.
    #[arg(long)]
    force: bool,
}

/// What a run produced, for the summary.
#[derive(Debug)]
struct Report {
    cues: PathBuf,
    frames: usize,
    rejected: u64,
    duration_s: f64,
    switches: u64,
    cumulative: Indicators,
    out: PathBuf,
    files: Vec<PathBuf>,
}

pub(crate) fn run(args: AssessArgs) -> anyhow::Result<()> {
    let report = assess(&args)?;
    print!("{}", report.summary());
    Ok(())
}

/// The whole command, without printing.
fn assess(args: &AssessArgs) -> anyhow::Result<Report> {
    check_out(&args.out, args.force)?;
    let mut inputs = vec![args.cues.as_path(), args.workspace.as_path()];
    inputs.extend(args.config.as_deref());
    refuse_inputs_inside(&args.out, &inputs)?;

    let workspace = Workspace::from_toml_file(&args.workspace).with_context(|| {
        format!(
            "cannot load the workspace calibration {}",
            args.workspace.display()
        )
    })?;
    let cfg = match &args.config {
        Some(path) => AssessConfig::from_toml_file(path)
            .with_context(|| format!("cannot load the model configuration {}", path.display()))?,
        None => AssessConfig::default(),
    };
    let frames = read_cues(&args.cues)?;
    if frames.is_empty() {
        bail!("{} holds no frames", args.cues.display());
    }
    // The assessor owns its workspace; the table needs the area names while `update`'s result is borrowed.
    let names = workspace.clone();
    let mut assessor =
        Assessor::new(workspace, cfg).context("the model configuration is invalid")?;

    let staging = Staging::new(&args.out)?;
    let table_path = staging.path().join(TABLE_FILE);
    let file = fs::File::create(&table_path)
        .with_context(|| format!("cannot create {}", table_path.display()))?;
    let mut table = IndicatorTable::new(BufWriter::new(file))
        .with_context(|| format!("cannot write {}", table_path.display()))?;

    let progress = progress_bar(frames.len() as u64);
    let mut samples = Vec::with_capacity(frames.len());
    for frame in &frames {
        let a = assessor.update(frame);
        progress.inc(1);
        if a.last_rejected {
            continue;
        }
        table
            .write(&names, a)
            .with_context(|| format!("cannot write {}", table_path.display()))?;
        samples.push(Sample::of(a));
    }
    table
        .finish()
        .and_then(|mut w| w.flush())
        .with_context(|| format!("cannot write {}", table_path.display()))?;
    let last: &Assessment = assessor.assessment();
    if samples.is_empty() {
        bail!(
            "every frame of {} was rejected (times not finite or not increasing)",
            args.cues.display()
        );
    }

    progress.set_message("plotting");
    let cfg = assessor.config();
    let figure = Figure {
        samples: &samples,
        medium_from: cfg.composite.medium_from,
        high_from: cfg.composite.high_from,
        horizon_s: cfg.window.horizon_s,
    };
    let plots = plot::render(staging.path(), &figure)?;
    let config_path = staging.path().join(CONFIG_FILE);
    fs::write(&config_path, cfg.to_toml_string()?)
        .with_context(|| format!("cannot write {}", config_path.display()))?;

    let mut files = vec![args.out.join(TABLE_FILE)];
    files.extend(
        plots
            .iter()
            .filter_map(|p| p.file_name())
            .map(|n| args.out.join(n)),
    );
    files.push(args.out.join(CONFIG_FILE));
    let report = Report {
        cues: args.cues.clone(),
        frames: samples.len(),
        rejected: last.rejected_frames,
        duration_s: samples.last().map_or(0.0, |s| s.t) - samples.first().map_or(0.0, |s| s.t),
        switches: last.switches,
        cumulative: last.cumulative,
        out: args.out.clone(),
        files,
    };
    drop(progress);
    staging.install(&args.out, args.force)?;
    Ok(report)
}

/// A cue CSV file, or a KTH handover folder.
fn read_cues(path: &Path) -> anyhow::Result<Vec<CueFrame>> {
    let meta =
        fs::metadata(path).with_context(|| format!("cannot read the cues {}", path.display()))?;
    if meta.is_dir() {
        Ok(assess::io::kth::read_taker(
            path,
            &assess::io::kth::KthOptions::default(),
        )?)
    } else {
        // The error already names the file, line and column.
        Ok(assess::io::cue_csv::read(path)?)
    }
}

/// A progress bar that is cleared from the terminal when dropped, also on an early error.
#[derive(Debug)]
struct Progress(ProgressBar);

impl std::ops::Deref for Progress {
    type Target = ProgressBar;
    fn deref(&self) -> &ProgressBar {
        &self.0
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.0.finish_and_clear();
    }
}

/// A progress bar on stderr, hidden when stderr is not a terminal.
fn progress_bar(len: u64) -> Progress {
    if !std::io::stderr().is_terminal() {
        return Progress(ProgressBar::hidden());
    }
    let bar = ProgressBar::new(len);
    if let Ok(style) =
        ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} frames ({eta})")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message("assessing");
    Progress(bar)
}

/// Refuses an `--out` that is a file, or a non-empty folder without `--force`.
fn check_out(out: &Path, force: bool) -> anyhow::Result<()> {
    match fs::metadata(out) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => {
            Err(e).with_context(|| format!("cannot inspect the output folder {}", out.display()))
        }
        Ok(m) if !m.is_dir() => bail!(
            "--out {} exists and is not a folder; choose another path",
            out.display()
        ),
        Ok(_) => {
            let non_empty = fs::read_dir(out)
                .with_context(|| format!("cannot list the output folder {}", out.display()))?
                .next()
                .is_some();
            if non_empty && !force {
                bail!(
                    "the output folder {} exists and is not empty; pass --force to replace it, or choose another --out",
                    out.display()
                );
            }
            Ok(())
        }
    }
}

/// `--force` must never delete the inputs: refuses an `--out` that contains one of them.
fn refuse_inputs_inside(out: &Path, inputs: &[&Path]) -> anyhow::Result<()> {
    let Ok(out_abs) = fs::canonicalize(out) else {
        return Ok(()); // `out` does not exist yet, so it holds nothing.
    };
    for input in inputs {
        if fs::canonicalize(input).is_ok_and(|abs| abs.starts_with(&out_abs)) {
            bail!(
                "the output folder {} contains the input {}; choose another --out",
                out.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// A temporary folder next to the output folder; removed on drop unless installed.
#[derive(Debug)]
struct Staging {
    path: PathBuf,
    installed: bool,
}

impl Staging {
    /// Creates `.<out name>.partial-<pid>[-n]` in the parent of `out` (created if needed).
    fn new(out: &Path) -> anyhow::Result<Self> {
        let path = sibling(out, "partial")?;
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent)
                .with_context(|| format!("cannot create {}", parent.display()))?;
        }
        fs::create_dir(&path).with_context(|| format!("cannot create {}", path.display()))?;
        Ok(Self {
            path,
            installed: false,
        })
    }

    fn path(&self) -> &Path {
        &self.path
    }

    /// Renames the staged folder to `out`. An existing `out` (checked again: empty, or `force`)
    /// is moved aside first and deleted only once the new folder is in place.
    fn install(mut self, out: &Path, force: bool) -> anyhow::Result<()> {
        check_out(out, force)?;
        if fs::symlink_metadata(out).is_ok() {
            let old = sibling(out, "old")?;
            fs::rename(out, &old)
                .with_context(|| format!("cannot move the old {} aside", out.display()))?;
            if let Err(e) = fs::rename(&self.path, out) {
                let _ = fs::rename(&old, out);
                return Err(e)
                    .with_context(|| format!("cannot move the results into {}", out.display()));
            }
            self.installed = true;
            fs::remove_dir_all(&old).with_context(|| {
                format!(
                    "the results are in {}, but the old folder {} could not be removed",
                    out.display(),
                    old.display()
                )
            })?;
        } else {
            fs::rename(&self.path, out)
                .with_context(|| format!("cannot move the results into {}", out.display()))?;
            self.installed = true;
        }
        Ok(())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.installed {
            let _ = fs::remove_dir_all(&self.path);
        }
    }
}

/// A path next to `out` that does not exist yet: `.<name>.<tag>-<pid>[-n]`.
fn sibling(out: &Path, tag: &str) -> anyhow::Result<PathBuf> {
    let Some(name) = out.file_name() else {
        bail!("--out {} must name a folder", out.display());
    };
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let base = format!(".{}.{tag}-{}", name.to_string_lossy(), std::process::id());
    let mut candidate = parent.join(&base);
    let mut n = 1;
    while fs::symlink_metadata(&candidate).is_ok() {
        candidate = parent.join(format!("{base}-{n}"));
        n += 1;
    }
    Ok(candidate)
}

impl Report {
    /// The text printed at the end of a run.
    fn summary(&self) -> String {
        let c = &self.cumulative;
        let mut s = String::new();
        let share = if self.duration_s > 0.0 {
            format!(
                " ({:.1} % of {:.3} s)",
                100.0 * c.valid_time_s / self.duration_s,
                self.duration_s
            )
        } else {
            String::new()
        };
        let _ = writeln!(
            s,
            "assessed {} frames from {}",
            self.frames,
            self.cues.display()
        );
        if self.rejected > 0 {
            let _ = writeln!(
                s,
                "  skipped {} frames whose time did not increase",
                self.rejected
            );
        }
        let _ = writeln!(s, "valid time T_v: {:.3} s{share}", c.valid_time_s);
        let _ = writeln!(s, "cumulative indicators at the last frame:");
        let _ = writeln!(
            s,
            "  AED {:.3}   TID {:.3}   ICD {:.3}   COL {:.3}   ABI {:.3}",
            c.aed, c.tid, c.icd, c.col, c.abi
        );
        let _ = writeln!(
            s,
            "  ASD_ctx {:.3} /s ({} switches, ASD~ {:.3})   OHD {:.3} (T_hes {:.3} s of T_collab {:.3} s)",
            c.asd_ctx,
            self.switches,
            c.asd_norm,
            c.ohd,
            c.hesitation_time_s,
            c.collaboration_time_s
        );
        let _ = writeln!(s, "  HRC-CWL {:.3} ({})", c.hrc_cwl, c.category.name());
        let _ = writeln!(s, "wrote {}:", self.out.display());
        for f in &self.files {
            let _ = writeln!(s, "  {}", f.display());
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use assess::{HandCue, HeadCue, Vec3};

    /// Four areas in front of an operator standing at the origin, head at 1.5 m.
    const WORKSPACE: &str = r#"
        [[area]]
        name = "assembly"
        role = "assembly"
        min_m = [0.4, -0.3, 0.7]
        max_m = [0.8, 0.3, 0.9]
        [[area]]
        name = "storage"
        role = "tool_identification"
        min_m = [0.0, 0.8, 0.7]
        max_m = [0.4, 1.2, 1.0]
        [[area]]
        name = "instructions"
        role = "instruction"
        min_m = [0.0, -1.2, 1.2]
        max_m = [0.3, -0.8, 1.6]
        [[area]]
        name = "handover"
        role = "collaboration"
        min_m = [1.0, -0.2, 1.0]
        max_m = [1.4, 0.2, 1.3]
    "#;

    /// A scripted trial at 30 fps: the operator looks at assembly, storage, instructions and the
    /// handover in turn; the robot collaborates from 6 s to 9 s, and the hand waits still
    /// near the handover from 6.5 s to 8 s.
    fn trial() -> Vec<CueFrame> {
        let targets = [
            Vec3::new(0.6, 0.0, 0.8),
            Vec3::new(0.2, 1.0, 0.85),
            Vec3::new(0.15, -1.0, 1.4),
            Vec3::new(1.2, 0.0, 1.15),
        ];
        let head = Vec3::new(0.0, 0.0, 1.5);
        (0..300)
            .map(|k| {
                let t = f64::from(k) / 30.0;
                let target = match t {
                    t if t < 2.0 => targets[0],
                    t if t < 3.5 => targets[1],
                    t if t < 5.0 => targets[2],
                    t if t < 6.0 => targets[0],
                    t if t < 9.0 => targets[3],
                    _ => targets[0],
                };
                let mut f = CueFrame::empty(t);
                f.head = Some(HeadCue {
                    position: head,
                    facing: target - head,
                    confidence: 0.9,
                });
                let hand = if (6.5..8.0).contains(&t) {
                    Vec3::new(1.1, 0.0, 1.1)
                } else {
                    Vec3::new(0.6 + 0.1 * (3.0 * t).sin(), 0.1 * (2.0 * t).cos(), 0.8)
                };
                f.hands[1] = Some(HandCue {
                    position: hand,
                    confidence: 0.8,
                });
                f.robot.collaborating = (6.0..9.0).contains(&t);
                f.robot.incomplete = f.robot.collaborating;
                f
            })
            .collect()
    }

    struct Setup {
        dir: tempfile::TempDir,
        args: AssessArgs,
    }

    fn setup(frames: &[CueFrame]) -> Setup {
        let dir = tempfile::tempdir().unwrap();
        let cues = dir.path().join("cues.csv");
        assess::io::cue_csv::write(&cues, frames).unwrap();
        let workspace = dir.path().join("workspace.toml");
        fs::write(&workspace, WORKSPACE).unwrap();
        let args = AssessArgs {
            cues,
            workspace,
            config: None,
            out: dir.path().join("results"),
            force: false,
        };
        Setup { dir, args }
    }

    /// The names in a folder, sorted.
    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn writes_the_table_plots_and_config() {
        let frames = trial();
        let s = setup(&frames);
        let report = assess(&s.args).unwrap();
        assert_eq!(report.frames, 300);

        let mut want = vec![TABLE_FILE.to_string(), CONFIG_FILE.to_string()];
        want.extend(plot::FILES.iter().map(|f| f.to_string()));
        want.sort();
        assert_eq!(names(&s.args.out), want);
        // Nothing else is left next to the results (no staging folder).
        assert_eq!(
            names(s.dir.path()),
            ["cues.csv", "results", "workspace.toml"]
        );

        let text = fs::read_to_string(s.args.out.join(TABLE_FILE)).unwrap();
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        assert_eq!(header, report::table::header());
        let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
        assert_eq!(rows.len(), 300);
        assert!(rows.iter().all(|r| r.len() == header.len()));
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
        assert_eq!(rows[0][col("t")], "0.000000");
        assert_eq!(rows[299][col("t")], "9.966667");
        // The operator has looked at assembly for 2 s: it is confirmed by 1 s.
        assert_eq!(rows[30][col("F")], "assembly");
        assert_eq!(rows[30][col("valid")], "1");
        // The robot context comes through: C(t) = 1 from 6 s (frame 180).
        assert_eq!(rows[179][col("collaborating")], "0");
        assert_eq!(rows[180][col("collaborating")], "1");
        // The last row matches the final cumulative indicators of the report.
        let last = &rows[299];
        assert_eq!(
            last[col("cum_aed")],
            report::table::fixed(report.cumulative.aed)
        );
        assert_eq!(
            last[col("cum_hrc_cwl")],
            report::table::fixed(report.cumulative.hrc_cwl)
        );
        assert_eq!(last[col("cum_category")], report.cumulative.category.name());
        assert!(report.switches >= 4, "switches: {}", report.switches);

        let summary = report.summary();
        assert!(
            summary.starts_with("assessed 300 frames from "),
            "{summary}"
        );
        assert!(
            summary.contains(&format!("HRC-CWL {:.3}", report.cumulative.hrc_cwl)),
            "{summary}"
        );
        assert!(
            summary.contains(&s.args.out.join(TABLE_FILE).display().to_string()),
            "{summary}"
        );
    }

    #[test]
    fn output_is_deterministic() {
        let frames = trial();
        let s = setup(&frames);
        assess(&s.args).unwrap();
        let first = fs::read(s.args.out.join(TABLE_FILE)).unwrap();
        let first_png = fs::read(s.args.out.join(plot::FILES[4])).unwrap();
        let again = AssessArgs {
            out: s.dir.path().join("again"),
            ..clone_args(&s.args)
        };
        assess(&again).unwrap();
        assert_eq!(fs::read(again.out.join(TABLE_FILE)).unwrap(), first);
        assert_eq!(fs::read(again.out.join(plot::FILES[4])).unwrap(), first_png);
    }

    fn clone_args(a: &AssessArgs) -> AssessArgs {
        AssessArgs {
            cues: a.cues.clone(),
            workspace: a.workspace.clone(),
            config: a.config.clone(),
            out: a.out.clone(),
            force: a.force,
        }
    }

    #[test]
    fn a_non_empty_out_is_refused_without_force() {
        let s = setup(&trial());
        fs::create_dir(&s.args.out).unwrap();
        fs::write(s.args.out.join("keep.txt"), "old results").unwrap();
        let e = assess(&s.args).unwrap_err().to_string();
        assert_eq!(
            e,
            format!(
                "the output folder {} exists and is not empty; pass --force to replace it, or choose another --out",
                s.args.out.display()
            )
        );
        assert_eq!(
            fs::read_to_string(s.args.out.join("keep.txt")).unwrap(),
            "old results"
        );

        // With --force the old folder is replaced.
        let forced = AssessArgs {
            force: true,
            ..clone_args(&s.args)
        };
        assess(&forced).unwrap();
        assert!(!s.args.out.join("keep.txt").exists());
        assert!(s.args.out.join(TABLE_FILE).exists());
        assert_eq!(
            names(s.dir.path()),
            ["cues.csv", "results", "workspace.toml"]
        );
    }

    #[test]
    fn an_empty_out_is_used() {
        let s = setup(&trial());
        fs::create_dir(&s.args.out).unwrap();
        assess(&s.args).unwrap();
        assert!(s.args.out.join(TABLE_FILE).exists());
    }

    #[test]
    fn force_never_deletes_an_input() {
        let s = setup(&trial());
        // Results folder = the folder holding the cues.
        let args = AssessArgs {
            out: s.dir.path().to_path_buf(),
            force: true,
            ..clone_args(&s.args)
        };
        let e = assess(&args).unwrap_err().to_string();
        assert!(e.contains("contains the input"), "{e}");
        assert!(s.args.cues.exists());
    }

    #[test]
    fn malformed_cues_name_file_line_and_column_and_write_nothing() {
        let s = setup(&trial());
        let text = fs::read_to_string(&s.args.cues).unwrap();
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        // Line 17 (1-based) is frame 15; replace its head_x (column 2).
        let mut cells: Vec<&str> = lines[16].split(',').collect();
        cells[1] = "abc";
        lines[16] = cells.join(",");
        fs::write(&s.args.cues, lines.join("\n")).unwrap();
        let e = assess(&s.args).unwrap_err().to_string();
        assert_eq!(
            e,
            format!(
                "{}:17:2: expected a number in column `head_x`, got \"abc\"",
                s.args.cues.display()
            )
        );
        assert_eq!(names(s.dir.path()), ["cues.csv", "workspace.toml"]);
    }

    #[test]
    fn staging_is_removed_when_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("results");
        let staging = Staging::new(&out).unwrap();
        fs::write(staging.path().join(TABLE_FILE), "partial").unwrap();
        assert_eq!(names(dir.path()).len(), 1);
        drop(staging);
        assert!(names(dir.path()).is_empty());
        assert!(!out.exists());
    }

    #[test]
    fn an_out_that_is_a_file_is_refused() {
        let s = setup(&trial());
        fs::write(&s.args.out, "not a folder").unwrap();
        let args = AssessArgs {
            force: true,
            ..clone_args(&s.args)
        };
        let e = assess(&args).unwrap_err().to_string();
        assert!(
            e.ends_with("exists and is not a folder; choose another path"),
            "{e}"
        );
    }

    #[test]
    fn reads_the_bundled_kth_handover_folder() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let dir = tempfile::tempdir().unwrap();
        let args = AssessArgs {
            cues: root.join("data/human-motion/kth-handover"),
            workspace: root.join("config/kth-handover-workspace.toml"),
            config: None,
            out: dir.path().join("kth"),
            force: false,
        };
        let report = assess(&args).unwrap();
        // 801 rows at 120 Hz.
        assert_eq!(report.frames, 801);
        assert!((report.duration_s - 800.0 / 120.0).abs() < 1e-9);
        let text = fs::read_to_string(args.out.join(TABLE_FILE)).unwrap();
        assert_eq!(text.lines().count(), 802);
    }
}
