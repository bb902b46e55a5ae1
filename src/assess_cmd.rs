//! `hrc-adapt assess`: offline assessment of a recording.
//!
//! Reads a cue CSV (`assess::io::cue_csv`) or a KTH handover folder (`assess::io::kth`), or
//! (feature `vision`) streams camera frames from a video file, an image folder, a RealSense
//! `.bag` or a live camera through the landmark pipeline and the cue extractor
//! (`crate::vision_cmd`). It runs the [`Assessor`] over every frame, and writes into `--out`:
//! - `indicators.csv`, one row per frame (columns in [`report::table`]; reals with 6 decimals,
//!   or with `--precision full` the shortest text that reads back bit for bit);
//! - the indicator-dynamics plots, four panels and a combined figure ([`report::plot`]);
//! - `assess_config.toml`, the model configuration in force (every key);
//! - `cues.csv`, the cues assessed, for every input (the `assess::io::cue_csv` format at full
//!   precision: `assess --cues <out>/cues.csv` with the same workspace and config reproduces
//!   `indicators.csv` byte for byte; a KTH folder's derived cues, a video's extracted ones);
//! - for camera inputs: `landmarks.csv` (`assess::vision::output::LandmarkCsv`).
//!   **Privacy**: these hold landmarks and cues only; the camera image is written only to the
//!   `--annotate` path, and only when it is given.
//!
//! Everything is written into a temporary folder next to `--out` and renamed into place at the
//! end, so a failed run leaves no partial results. An existing non-empty `--out` is replaced only
//! with `--force`.

use crate::Error;
use crate::error::ResultExt as _;
use crate::report;
use crate::vision_cmd::{CameraArgs, CueInput};

use std::fmt::Write as _;
use std::fs;
use std::io::{BufWriter, IsTerminal as _, Write as _};
use std::path::{Path, PathBuf};

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
/// The cues assessed (every input), in the cue CSV format, inside `--out`.
const CUES_FILE: &str = "cues.csv";
/// Camera inputs: the landmarks, inside `--out`.
#[cfg(feature = "vision")]
const LANDMARKS_FILE: &str = "landmarks.csv";

/// Arguments of `hrc-adapt assess`.
#[derive(Debug, Args)]
pub struct AssessArgs {
    /// Cues: a cue CSV file, a KTH handover folder, a video file (.mp4 .avi .mkv .mov), an
    /// image folder, a RealSense .bag (feature `realsense`), `camera` (a RealSense camera if
    /// built with `realsense` and one is connected, else the first webcam) or `webcam:N`.
    /// Every input writes the cues assessed to cues.csv; camera inputs also landmarks.csv, never
    /// images, unless --annotate is given.
    #[arg(long)]
    cues: PathBuf,
    /// Workspace calibration TOML.
    #[arg(long)]
    workspace: PathBuf,
    /// Model configuration TOML (default: the values of the spec in the `assess` crate docs).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output folder; created, and refused if it exists and is not empty (see --force).
    #[arg(long)]
    out: PathBuf,
    /// Replace an existing non-empty output folder.
    #[arg(long)]
    force: bool,
    /// Real values in indicators.csv: `6` decimals (default) or `full`, the shortest text
    /// that reads back to the same f64 (to check the model to the last bit).
    #[arg(long, value_enum, default_value = "6")]
    precision: crate::report::table::Precision,
    /// Options for camera inputs (video, images, .bag, camera).
    #[command(flatten)]
    vision: VisionArgs,
}

/// `assess` options for camera inputs.
#[derive(Debug, Clone, Default, Args)]
#[command(next_help_heading = "Camera inputs (video, image folder, .bag, camera, webcam:N)")]
pub(crate) struct VisionArgs {
    /// Extrinsics, intrinsics, field of view, model variant.
    #[command(flatten)]
    camera: CameraArgs,
    /// A folder of 16-bit PNG depth images aligned to the video or image folder (with a
    /// depth.toml giving the scale; see assess::vision::source::capture).
    #[arg(long, value_name = "FOLDER")]
    depth: Option<PathBuf>,
    /// Detect on every frame independently (for folders of unrelated photos) instead of
    /// tracking from frame to frame.
    #[arg(long = "static")]
    still: bool,
    /// Stop after this many frames (a live camera otherwise runs until Ctrl-C).
    #[arg(long, value_name = "N")]
    max_frames: Option<u64>,
    /// ALSO WRITE THE CAMERA IMAGE: the monitoring view (landmarks, head ray, workspace areas
    /// with the confirmed one highlighted, live indicators) as an MJPG .avi at the source's
    /// frame rate (one frame size) or, for a path without extension, a folder of PNGs (any
    /// sizes). Without this flag no image is written (privacy: only landmarks and cues are
    /// kept).
    #[arg(long, value_name = "PATH")]
    annotate: Option<PathBuf>,
}

impl VisionArgs {
    /// The flags given that apply to camera inputs only.
    fn given(&self) -> Vec<&'static str> {
        let c = &self.camera;
        [
            (c.extrinsics.is_some(), "--extrinsics"),
            (c.intrinsics.is_some(), "--intrinsics"),
            (c.lite, "--lite"),
            (self.depth.is_some(), "--depth"),
            (self.still, "--static"),
            (self.max_frames.is_some(), "--max-frames"),
            (self.annotate.is_some(), "--annotate"),
        ]
        .into_iter()
        .filter_map(|(given, name)| given.then_some(name))
        .collect()
    }
}

/// What a run produced, for the summary.
#[derive(Debug)]
struct Report {
    cues: String,
    frames: usize,
    rejected: u64,
    duration_s: f64,
    switches: u64,
    cumulative: Indicators,
    out: PathBuf,
    files: Vec<PathBuf>,
}

/// Runs `hrc-adapt assess`: assesses the recording and writes the results into `--out`.
pub fn run(args: AssessArgs) -> crate::Result<()> {
    let report = assess(&args)?;
    print!("{}", report.summary());
    Ok(())
}

/// The assessment of a stream of cue frames into a staging folder.
struct Run {
    names: Workspace,
    assessor: Assessor,
    staging: Staging,
    table_path: PathBuf,
    table: IndicatorTable<BufWriter<fs::File>>,
    samples: Vec<Sample>,
}

impl std::fmt::Debug for Run {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Run")
            .field("staging", &self.staging)
            .field("samples", &self.samples.len())
            .finish()
    }
}

impl Run {
    fn new(
        workspace: Workspace,
        cfg: AssessConfig,
        out: &Path,
        precision: crate::report::table::Precision,
    ) -> crate::Result<Self> {
        // The assessor owns its workspace; the table needs the area names while `update`'s
        // result is borrowed.
        let names = workspace.clone();
        let assessor =
            Assessor::new(workspace, cfg).context("the model configuration is invalid")?;
        let staging = Staging::new(out)?;
        let table_path = staging.path().join(TABLE_FILE);
        let file = fs::File::create(&table_path).map_err(Error::io("create", &table_path))?;
        let table = IndicatorTable::with_precision(BufWriter::new(file), precision)
            .map_err(Error::csv("write", &table_path))?;
        Ok(Self {
            names,
            assessor,
            staging,
            table_path,
            table,
            samples: Vec::new(),
        })
    }

    /// Assesses one frame and writes its row; `None` when the assessor rejected the frame
    /// (time not finite or not increasing).
    fn push(&mut self, frame: &CueFrame) -> crate::Result<Option<&Assessment>> {
        let a = self.assessor.update(frame);
        if a.last_rejected {
            return Ok(None);
        }
        self.table
            .write(&self.names, a)
            .map_err(Error::csv("write", &self.table_path))?;
        self.samples.push(Sample::of(a));
        Ok(Some(a))
    }

    /// Plots, the configuration, and the results moved into `out`. `extra` are further files
    /// already written into the staging folder (names relative to it) or elsewhere (absolute).
    fn finish(
        self,
        args: &AssessArgs,
        cues: String,
        progress: &Progress,
        extra: Vec<PathBuf>,
    ) -> crate::Result<Report> {
        let Self {
            assessor,
            staging,
            table_path,
            table,
            samples,
            ..
        } = self;
        table
            .finish()
            .and_then(|mut w| w.flush())
            .map_err(Error::io("write", &table_path))?;
        let last: &Assessment = assessor.assessment();
        if samples.is_empty() {
            if last.frames == 0 {
                return Err(Error::data(cues, "holds no frames"));
            }
            return Err(Error::data(
                cues,
                "every frame was rejected (times not finite or not increasing)",
            ));
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
        fs::write(&config_path, cfg.to_toml_string()?).map_err(Error::io("write", &config_path))?;

        let mut files = vec![args.out.join(TABLE_FILE)];
        files.extend(
            plots
                .iter()
                .filter_map(|p| p.file_name())
                .map(|n| args.out.join(n)),
        );
        files.push(args.out.join(CONFIG_FILE));
        files.extend(extra.iter().map(|p| args.out.join(p)));
        let report = Report {
            cues,
            frames: samples.len(),
            rejected: last.rejected_frames,
            duration_s: samples.last().map_or(0.0, |s| s.t) - samples.first().map_or(0.0, |s| s.t),
            switches: last.switches,
            cumulative: last.cumulative,
            out: args.out.clone(),
            files,
        };
        staging.install(&args.out, args.force)?;
        Ok(report)
    }
}

/// The whole command, without printing.
fn assess(args: &AssessArgs) -> crate::Result<Report> {
    check_out(&args.out, args.force)?;
    let input = CueInput::parse(&args.cues)?;
    if !input.is_camera() {
        let given = args.vision.given();
        if !given.is_empty() {
            return Err(Error::usage(
                given.join(", "),
                format!(
                    "{} appl{} to camera inputs only (video, image folder, .bag, camera), not to \
                     the cue file {}",
                    given.join(", "),
                    if given.len() == 1 { "ies" } else { "y" },
                    args.cues.display()
                ),
            ));
        }
    }
    let mut inputs: Vec<&Path> = vec![args.workspace.as_path()];
    inputs.extend(input.path());
    inputs.extend(args.config.as_deref());
    inputs.extend(args.vision.depth.as_deref());
    inputs.extend(args.vision.camera.extrinsics.as_deref());
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
    if input.is_camera() {
        return assess_camera(args, &input, workspace, cfg);
    }
    let frames = read_cues(&input)?;
    if frames.is_empty() {
        return Err(Error::data(args.cues.display(), "holds no frames"));
    }
    let mut run = Run::new(workspace, cfg, &args.out, args.precision)?;
    let progress = progress_bar(Some(frames.len() as u64));
    for frame in &frames {
        run.push(frame)?;
        progress.inc(1);
    }
    // The cues assessed, at full precision, for every input (a KTH folder's are derived here):
    // `assess --cues <out>/cues.csv` reproduces indicators.csv byte for byte.
    let cues_path = run.staging.path().join(CUES_FILE);
    assess::io::cue_csv::write(&cues_path, &frames)?;
    run.finish(
        args,
        args.cues.display().to_string(),
        &progress,
        vec![PathBuf::from(CUES_FILE)],
    )
}

#[cfg(not(feature = "vision"))]
fn assess_camera(
    _args: &AssessArgs,
    input: &CueInput,
    _workspace: Workspace,
    _cfg: AssessConfig,
) -> crate::Result<Report> {
    Err(crate::vision_cmd::vision_missing(input))
}

/// Camera inputs: frames → landmarks → cues → assessor, streamed.
#[cfg(feature = "vision")]
fn assess_camera(
    args: &AssessArgs,
    input: &CueInput,
    workspace: Workspace,
    cfg: AssessConfig,
) -> crate::Result<Report> {
    use crate::vision_cmd::{
        LandmarkCsv, Perception, annotate, image_sink, intrinsics_override, load_extrinsics,
        open_source, pipeline_config,
    };
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    let v = &args.vision;
    if v.max_frames == Some(0) {
        return Err(Error::usage(
            "--max-frames",
            "--max-frames must be at least 1",
        ));
    }
    if let Some(a) = &v.annotate {
        refuse_annotate_onto_inputs(a, &args.out, input)?;
    }
    let mut opened = open_source(input, &v.camera, v.depth.as_deref())?;
    let extrinsics = load_extrinsics(&v.camera)?;
    let described = opened.source.describe();
    let mut perception = Perception::load(
        pipeline_config(&v.camera, v.still),
        extrinsics,
        intrinsics_override(&opened, v.camera.intrinsics)?,
        workspace.station(),
    )?;
    let overlay_ws = workspace.clone();
    let mut run = Run::new(workspace, cfg, &args.out, args.precision)?;
    let mut landmarks = LandmarkCsv::create(&run.staging.path().join(LANDMARKS_FILE))?;
    // The annotated view goes into the staging folder when it is asked for inside `--out`.
    let annotate_path = v
        .annotate
        .as_ref()
        .map(|a| match a.strip_prefix(&args.out) {
            Ok(rel) => (run.staging.path().join(rel), args.out.join(rel)),
            Err(_) => (a.clone(), a.clone()),
        });
    let mut sink = match &annotate_path {
        Some((write_to, _)) => Some(image_sink(write_to, "--annotate", opened.fps)?),
        None => None,
    };

    let stop = Arc::new(AtomicBool::new(false));
    if input.is_live() {
        crate::trial::install_ctrl_c(stop.clone());
        eprintln!("reading {described}; Ctrl-C stops and writes the results");
    }
    let len = match (opened.len, v.max_frames) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    };
    let progress = progress_bar(len);
    // Everything from here on fails as a whole: the sink is closed (dropped) before the
    // annotated view of a failed run is removed below.
    let result = (|| {
        let mut cues: Vec<CueFrame> = Vec::new();
        let mut n: u64 = 0;
        while v.max_frames.is_none_or(|m| n < m) && !stop.load(Ordering::Relaxed) {
            let Some(frame) = opened
                .source
                .next_frame()
                .with_context(|| format!("reading {described}"))?
            else {
                break;
            };
            let p = perception.step(&frame)?;
            landmarks.write(frame.index, frame.t, &p.landmarks)?;
            cues.push(p.cues.frame);
            let a = run.push(&p.cues.frame)?;
            if let Some(sink) = sink.as_mut() {
                let img = annotate(&frame, &p, perception.extrinsics(), &overlay_ws, a)?;
                sink.push(&img)?;
            }
            n += 1;
            progress.inc(1);
        }
        landmarks.finish()?;
        let cues_path = run.staging.path().join(CUES_FILE);
        assess::io::cue_csv::write(&cues_path, &cues)?;
        if let Some(sink) = sink {
            sink.finish()?;
        }
        let mut extra = vec![PathBuf::from(CUES_FILE), PathBuf::from(LANDMARKS_FILE)];
        extra.extend(annotate_path.map(|(_, shown)| shown));
        run.finish(args, described, &progress, extra)
    })();
    if result.is_err()
        && let Some(a) = &v.annotate
        && !a.starts_with(&args.out)
    {
        // Nothing is half-written: the annotated view goes with the failed run.
        let _ = fs::remove_file(a).or_else(|_| fs::remove_dir_all(a));
    }
    result
}

/// `--annotate` must not be `--out` itself nor overwrite an input.
#[cfg(feature = "vision")]
fn refuse_annotate_onto_inputs(annotate: &Path, out: &Path, input: &CueInput) -> crate::Result<()> {
    if annotate == out {
        return Err(Error::usage(
            "--annotate",
            "--annotate must not be the --out folder itself; give a path inside or beside it",
        ));
    }
    if let Some(p) = input.path()
        && fs::canonicalize(p).ok() == fs::canonicalize(annotate).ok()
        && annotate.exists()
    {
        return Err(Error::usage(
            "--annotate",
            format!(
                "--annotate {} is the input; choose another path",
                annotate.display()
            ),
        ));
    }
    Ok(())
}

/// A cue CSV file, or a KTH handover folder.
fn read_cues(input: &CueInput) -> crate::Result<Vec<CueFrame>> {
    match input {
        CueInput::Kth(path) => Ok(assess::io::kth::read_taker(
            path,
            &assess::io::kth::KthOptions::default(),
        )?),
        // The error already names the file, line and column.
        CueInput::CueCsv(path) => Ok(assess::io::cue_csv::read(path)?),
        other => Err(Error::Internal {
            reason: format!("{other:?} is not a cue file"),
        }),
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

/// A progress bar on stderr, hidden when stderr is not a terminal: `len` frames, or a
/// counter with the frame rate when the length is unknown (live cameras).
fn progress_bar(len: Option<u64>) -> Progress {
    if !std::io::stderr().is_terminal() {
        return Progress(ProgressBar::hidden());
    }
    let (bar, template) = match len {
        Some(n) => (
            ProgressBar::new(n),
            "{msg:>10} [{bar:40}] {pos}/{len} frames, {per_sec} ({eta})",
        ),
        None => (
            ProgressBar::no_length(),
            "{msg:>10} {spinner} {pos} frames, {per_sec}",
        ),
    };
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message("assessing");
    Progress(bar)
}

/// Refuses an `--out` that is a file, or a non-empty folder without `--force`.
fn check_out(out: &Path, force: bool) -> crate::Result<()> {
    match fs::metadata(out) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(Error::io("inspect the output folder", out)(e)),
        Ok(m) if !m.is_dir() => Err(Error::usage(
            "--out",
            format!(
                "--out {} exists and is not a folder; choose another path",
                out.display()
            ),
        )),
        Ok(_) => {
            let non_empty = fs::read_dir(out)
                .map_err(Error::io("list the output folder", out))?
                .next()
                .is_some();
            if non_empty && !force {
                return Err(Error::usage(
                    "--out",
                    format!(
                        "the output folder {} exists and is not empty; pass --force to replace \
                         it, or choose another --out",
                        out.display()
                    ),
                ));
            }
            Ok(())
        }
    }
}

/// `--force` must never delete the inputs: refuses an `--out` that contains one of them.
fn refuse_inputs_inside(out: &Path, inputs: &[&Path]) -> crate::Result<()> {
    let Ok(out_abs) = fs::canonicalize(out) else {
        return Ok(()); // `out` does not exist yet, so it holds nothing.
    };
    for input in inputs {
        if fs::canonicalize(input).is_ok_and(|abs| abs.starts_with(&out_abs)) {
            return Err(Error::usage(
                "--out",
                format!(
                    "the output folder {} contains the input {}; choose another --out",
                    out.display(),
                    input.display()
                ),
            ));
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
    fn new(out: &Path) -> crate::Result<Self> {
        let path = sibling(out, "partial")?;
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent).map_err(Error::io("create", parent))?;
        }
        fs::create_dir(&path).map_err(Error::io("create", &path))?;
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
    fn install(mut self, out: &Path, force: bool) -> crate::Result<()> {
        check_out(out, force)?;
        if fs::symlink_metadata(out).is_ok() {
            let old = sibling(out, "old")?;
            fs::rename(out, &old).map_err(Error::io("move aside the old", out))?;
            if let Err(e) = fs::rename(&self.path, out) {
                let _ = fs::rename(&old, out);
                return Err(Error::io("move the results into", out)(e));
            }
            self.installed = true;
            fs::remove_dir_all(&old).map_err(|e| {
                Error::io("remove the old folder", &old)(e)
                    .context(format!("the results are in {}", out.display()))
            })?;
        } else {
            fs::rename(&self.path, out).map_err(Error::io("move the results into", out))?;
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
fn sibling(out: &Path, tag: &str) -> crate::Result<PathBuf> {
    let Some(name) = out.file_name() else {
        return Err(Error::usage(
            "--out",
            format!("--out {} must name a folder", out.display()),
        ));
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
        let _ = writeln!(s, "assessed {} frames from {}", self.frames, self.cues);
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
            precision: Default::default(),
            vision: VisionArgs::default(),
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

        let mut want = vec![
            TABLE_FILE.to_string(),
            CONFIG_FILE.to_string(),
            CUES_FILE.to_string(),
        ];
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
            precision: a.precision,
            vision: a.vision.clone(),
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
            precision: Default::default(),
            vision: VisionArgs::default(),
        };
        let report = assess(&args).unwrap();
        // 801 rows at 120 Hz.
        assert_eq!(report.frames, 801);
        assert!((report.duration_s - 800.0 / 120.0).abs() < 1e-9);
        let text = fs::read_to_string(args.out.join(TABLE_FILE)).unwrap();
        assert_eq!(text.lines().count(), 802);
    }

    /// Issue 13: `assess` writes the cues it assessed (here the ones it derived from a KTH
    /// folder), and `assess --cues <that cues.csv>` reproduces indicators.csv byte for byte,
    /// at 6 decimals and at full precision. Full precision writes what reads back bit for bit.
    #[test]
    fn its_cues_csv_reproduces_indicators_csv_byte_for_byte() {
        use crate::report::table::Precision;
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let dir = tempfile::tempdir().unwrap();
        for precision in [Precision::Fixed6, Precision::Full] {
            let first = AssessArgs {
                cues: root.join("data/human-motion/kth-handover"),
                workspace: root.join("config/kth-handover-workspace.toml"),
                config: None,
                out: dir.path().join(format!("kth-{precision:?}")),
                force: false,
                precision,
                vision: VisionArgs::default(),
            };
            assess(&first).unwrap();
            let again = AssessArgs {
                cues: first.out.join(CUES_FILE),
                out: dir.path().join(format!("again-{precision:?}")),
                ..clone_args(&first)
            };
            assess(&again).unwrap();
            let a = fs::read(first.out.join(TABLE_FILE)).unwrap();
            let b = fs::read(again.out.join(TABLE_FILE)).unwrap();
            assert!(a == b, "{precision:?}: indicators.csv differs");
            // And the cues read back are the frames the KTH reader derived, bit for bit.
            let derived =
                assess::io::kth::read_taker(&first.cues, &assess::io::kth::KthOptions::default())
                    .unwrap();
            let written = assess::io::cue_csv::read(&again.cues).unwrap();
            assert_eq!(derived, written);
        }
        // Full precision: the times of the 120 Hz recording are not 6-decimal numbers.
        let full = fs::read_to_string(dir.path().join("kth-Full").join(TABLE_FILE)).unwrap();
        let t1 = full.lines().nth(2).unwrap().split(',').next().unwrap();
        let six = fs::read_to_string(dir.path().join("kth-Fixed6").join(TABLE_FILE)).unwrap();
        let t1_six = six.lines().nth(2).unwrap().split(',').next().unwrap();
        assert_ne!(t1, t1_six, "full {t1} vs 6 decimals {t1_six}");
        let derived = assess::io::kth::read_taker(
            &root.join("data/human-motion/kth-handover"),
            &assess::io::kth::KthOptions::default(),
        )
        .unwrap();
        assert_eq!(t1.parse::<f64>().unwrap().to_bits(), derived[1].t.to_bits());
    }
}

/// `assess` on camera inputs (needs the models under `models/` and ONNX Runtime from
/// `scripts/setup`). The frames are copies of the bundled photo `data/images/pose_sitting.jpg`
/// (960 × 640 px, one seated person with face and both hands in view).
#[cfg(all(test, feature = "vision"))]
mod vision_tests {
    use super::*;
    use assess::vision::FrameSource as _;
    use assess::vision::RgbImage;
    use assess::vision::output::{ImageSink, LANDMARK_HEADER};
    use assess::vision::source::capture::{VideoFileOptions, VideoFileSource};

    const PHOTO: &str = "data/images/pose_sitting.jpg";

    fn root() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
    }

    /// A temporary folder with `images/` (three copies of the photo) and the example
    /// workspace.
    struct Setup {
        dir: tempfile::TempDir,
        images: PathBuf,
        workspace: PathBuf,
    }

    fn setup() -> Setup {
        let dir = tempfile::tempdir().unwrap();
        let images = dir.path().join("images");
        fs::create_dir(&images).unwrap();
        for i in 0..3 {
            fs::copy(root().join(PHOTO), images.join(format!("{i:06}.jpg"))).unwrap();
        }
        Setup {
            images,
            workspace: root().join("config/example-workspace.toml"),
            dir,
        }
    }

    fn args(cues: &Path, workspace: &Path, out: &Path, vision: VisionArgs) -> AssessArgs {
        AssessArgs {
            cues: cues.to_path_buf(),
            workspace: workspace.to_path_buf(),
            config: None,
            out: out.to_path_buf(),
            force: false,
            precision: Default::default(),
            vision,
        }
    }

    /// The error of a run that must fail, with its causes.
    fn fails(a: &AssessArgs) -> String {
        assess(a).unwrap_err().with_causes().to_string()
    }

    fn still() -> VisionArgs {
        VisionArgs {
            still: true,
            ..VisionArgs::default()
        }
    }

    /// Every file under `dir`, recursively, relative to it.
    fn files(dir: &Path) -> Vec<String> {
        let mut out = Vec::new();
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            for e in fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else {
                    out.push(p.strip_prefix(dir).unwrap().display().to_string());
                }
            }
        }
        out.sort();
        out
    }

    /// Landmark rows per (frame, set).
    fn landmark_counts(path: &Path) -> std::collections::BTreeMap<(u64, String), usize> {
        let text = fs::read_to_string(path).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some(LANDMARK_HEADER));
        let mut counts = std::collections::BTreeMap::new();
        for line in lines {
            let cells: Vec<&str> = line.split(',').collect();
            assert_eq!(cells.len(), 7, "{line}");
            let x: f64 = cells[4].parse().unwrap();
            let y: f64 = cells[5].parse().unwrap();
            let score: f64 = cells[6].parse().unwrap();
            assert!(
                x.is_finite() && y.is_finite() && (0.0..=1.0).contains(&score),
                "{line}"
            );
            *counts
                .entry((cells[0].parse().unwrap(), cells[2].to_string()))
                .or_insert(0) += 1;
        }
        counts
    }

    #[test]
    fn an_image_folder_gives_indicators_cues_and_landmarks_and_no_image() {
        let s = setup();
        let out = s.dir.path().join("results");
        let report = assess(&args(&s.images, &s.workspace, &out, still())).unwrap();
        assert_eq!(report.frames, 3);

        // Exactly the CSV path's files (cues.csv among them) plus landmarks.csv: no camera image
        // (the only PNGs are the plots).
        let mut want = vec![
            TABLE_FILE.to_string(),
            CONFIG_FILE.to_string(),
            CUES_FILE.to_string(),
            LANDMARKS_FILE.to_string(),
        ];
        want.extend(plot::FILES.iter().map(|f| f.to_string()));
        want.sort();
        assert_eq!(files(&out), want);
        assert_eq!(
            files(s.dir.path())
                .iter()
                .filter(|f| f.starts_with("results"))
                .count(),
            want.len()
        );

        // cues.csv reads back with the cue CSV reader: three frames with head, body and both
        // hands, at the folder's nominal 30 fps; the positions are in the camera frame
        // (identity extrinsics): the person is in front of the camera (z > 0).
        let cues = assess::io::cue_csv::read(&out.join(CUES_FILE)).unwrap();
        assert_eq!(cues.len(), 3);
        for (k, f) in cues.iter().enumerate() {
            assert!((f.t - k as f64 / 30.0).abs() < 1e-9);
            let head = f.head.expect("head cue");
            assert!(head.position.z > 0.3 && head.position.z < 5.0, "{head:?}");
            assert!(
                f.body.is_some() && f.hands.iter().all(Option::is_some),
                "{f:?}"
            );
        }
        // The same cues assessed again from cues.csv give the same table.
        let again = s.dir.path().join("again");
        assess(&args(
            &out.join(CUES_FILE),
            &s.workspace,
            &again,
            VisionArgs::default(),
        ))
        .unwrap();
        assert_eq!(
            fs::read(again.join(TABLE_FILE)).unwrap(),
            fs::read(out.join(TABLE_FILE)).unwrap()
        );

        // landmarks.csv: pose 33, face 468 and two hands of 21 on each frame.
        let counts = landmark_counts(&out.join(LANDMARKS_FILE));
        for frame in 0..3 {
            for (set, n) in [("pose", 33), ("face", 468), ("hand0", 21), ("hand1", 21)] {
                assert_eq!(
                    counts.get(&(frame, set.to_string())),
                    Some(&n),
                    "{frame} {set}"
                );
            }
        }
        assert_eq!(counts.len(), 12);
    }

    #[test]
    fn annotate_writes_a_png_folder_inside_out_or_an_avi_beside_it() {
        let s = setup();
        // A folder of PNGs inside --out: staged with the results.
        let out = s.dir.path().join("results");
        let v = VisionArgs {
            annotate: Some(out.join("view")),
            ..still()
        };
        let report = assess(&args(&s.images, &s.workspace, &out, v)).unwrap();
        assert!(report.files.contains(&out.join("view")));
        let pngs = files(&out.join("view"));
        assert_eq!(pngs, ["000000.png", "000001.png", "000002.png"]);
        let first = RgbImage::read(&out.join("view/000000.png")).unwrap();
        let photo = RgbImage::read(&root().join(PHOTO)).unwrap();
        assert_eq!((first.width, first.height), (photo.width, photo.height));
        // The overlay changed the image (landmarks, text).
        assert_ne!(first.data, photo.data);

        // An .avi beside it: it plays back through OpenCV with three frames of the photo's size.
        let avi = s.dir.path().join("view.avi");
        let v = VisionArgs {
            annotate: Some(avi.clone()),
            ..still()
        };
        assess(&args(&s.images, &s.workspace, &s.dir.path().join("r2"), v)).unwrap();
        let mut video = VideoFileSource::open(&avi, VideoFileOptions::default()).unwrap();
        let mut n = 0;
        while let Some(f) = video.next_frame().unwrap() {
            assert_eq!((f.color.width, f.color.height), (photo.width, photo.height));
            n += 1;
        }
        assert_eq!(n, 3);
    }

    #[test]
    fn a_generated_avi_is_assessed_with_tracking_and_max_frames() {
        let s = setup();
        // A 5-frame video of the photo, written with the same MJPG writer as --annotate.
        let avi = s.dir.path().join("clip.avi");
        let photo = RgbImage::read(&root().join(PHOTO)).unwrap();
        let mut sink = ImageSink::create(&avi, 30.0).unwrap();
        for _ in 0..5 {
            sink.push(&photo).unwrap();
        }
        sink.finish().unwrap();
        let out = s.dir.path().join("results");
        let v = VisionArgs {
            max_frames: Some(4),
            ..VisionArgs::default()
        };
        let report = assess(&args(&avi, &s.workspace, &out, v)).unwrap();
        assert_eq!(report.frames, 4);
        let cues = assess::io::cue_csv::read(&out.join(CUES_FILE)).unwrap();
        assert_eq!(cues.len(), 4);
        assert!(cues.iter().all(|f| f.head.is_some()));
        let counts = landmark_counts(&out.join(LANDMARKS_FILE));
        assert_eq!(counts.get(&(3, "pose".to_string())), Some(&33));
        assert!(!files(&out).iter().any(|f| f.ends_with(".avi")));
    }

    #[test]
    fn a_folder_of_photos_of_several_sizes_is_assessed_unless_intrinsics_are_fixed() {
        let s = setup();
        let photos = s.dir.path().join("photos");
        fs::create_dir(&photos).unwrap();
        fs::copy(root().join(PHOTO), photos.join("a.jpg")).unwrap();
        fs::copy(
            root().join("data/images/business-person.png"),
            photos.join("b.png"),
        )
        .unwrap();
        // Each photo gets intrinsics for its own size; the PNG view keeps each one's size.
        let out = s.dir.path().join("results");
        let v = VisionArgs {
            annotate: Some(s.dir.path().join("view")),
            ..still()
        };
        let report = assess(&args(&photos, &s.workspace, &out, v)).unwrap();
        assert_eq!(report.frames, 2);
        let sizes: Vec<(u32, u32)> = ["000000.png", "000001.png"]
            .iter()
            .map(|f| {
                let img = RgbImage::read(&s.dir.path().join("view").join(f)).unwrap();
                (img.width, img.height)
            })
            .collect();
        assert_eq!(sizes, [(960, 640), (958, 1358)]);
        let counts = landmark_counts(&out.join(LANDMARKS_FILE));
        assert_eq!(counts.get(&(1, "pose".to_string())), Some(&33));

        // An .avi holds one size: a clear error, and no video is left behind.
        let avi = s.dir.path().join("view.avi");
        let v = VisionArgs {
            annotate: Some(avi.clone()),
            ..still()
        };
        let e = fails(&args(&photos, &s.workspace, &s.dir.path().join("r2"), v));
        assert!(e.contains("write a PNG folder"), "{e}");
        assert!(!avi.exists() && !s.dir.path().join("r2").exists());

        // --intrinsics hold for one camera: the second size is refused.
        let v = VisionArgs {
            camera: crate::vision_cmd::CameraArgs {
                intrinsics: Some(crate::vision_cmd::IntrinsicsArg {
                    fx: 800.0,
                    fy: 800.0,
                    cx: 480.0,
                    cy: 320.0,
                }),
                ..Default::default()
            },
            ..still()
        };
        let r3 = s.dir.path().join("r3");
        let e = fails(&args(&photos, &s.workspace, &r3, v));
        assert!(
            e.contains("frame 1 is 958 x 1358 px but the first frame was 960 x 640 px"),
            "{e}"
        );
        assert!(!r3.exists());
    }

    /// The workspace's `[station]` reaches the pipeline: on a frame with two copies of the
    /// seated person side by side (1920 px wide), the operator is the copy at the station,
    /// whichever side it is on. No extrinsics, so the workspace frame is the camera frame; the
    /// station is 2 m out on the ray through the centre of that copy's pose-detector box
    /// (intrinsics from the default 69° field of view, as the image folder's).
    #[test]
    fn the_workspace_station_chooses_the_operator() {
        use assess::vision::pipeline::{Pipeline, PipelineConfig};
        use assess::vision::{Intrinsics, models};
        let s = setup();
        let img = RgbImage::read(&root().join(PHOTO)).unwrap();
        let mut both = RgbImage::black(1920, img.height);
        for x0 in [0usize, 960] {
            let (w, iw) = (1920 * 3, img.width as usize * 3);
            for y in 0..img.height as usize {
                let dst = y * w + x0 * 3;
                both.data[dst..dst + iw].copy_from_slice(&img.data[y * iw..(y + 1) * iw]);
            }
        }
        let frames = s.dir.path().join("two");
        fs::create_dir(&frames).unwrap();
        assess::vision::calib::write_png(&both, frames.join("000000.png")).unwrap();
        models::init_runtime(None).unwrap();
        let mut p = Pipeline::load(&models::model_dir(), PipelineConfig::static_images()).unwrap();
        let people = p.detect_people(&both).unwrap();
        let intrinsics = Intrinsics::from_hfov(1920, img.height, 69.0);
        let areas = fs::read_to_string(&s.workspace).unwrap();
        for left in [true, false] {
            let d = people
                .iter()
                .find(|d| (d.xmin + d.width / 2.0 < 0.5) == left)
                .unwrap_or_else(|| panic!("no person on the left = {left} side: {people:?}"));
            let u = f64::from(d.xmin + d.width / 2.0) * 1920.0;
            let v = f64::from(d.ymin + d.height / 2.0) * f64::from(img.height);
            let at = intrinsics.deproject(u, v, 2.0);
            let ws = s.dir.path().join(format!("ws-{left}.toml"));
            fs::write(
                &ws,
                format!(
                    "{areas}\n[station]\nposition_m = [{}, {}, {}]\nradius_m = 0.5\n",
                    at.x, at.y, at.z
                ),
            )
            .unwrap();
            let out = s.dir.path().join(format!("out-{left}"));
            assess(&args(&frames, &ws, &out, still())).unwrap();
            let text = fs::read_to_string(out.join(LANDMARKS_FILE)).unwrap();
            let nose_x: f64 = text
                .lines()
                .find(|l| l.starts_with("0,") && l.contains(",pose,0,"))
                .and_then(|l| l.split(',').nth(4))
                .unwrap_or_else(|| panic!("no pose on frame 0:\n{text}"))
                .parse()
                .unwrap();
            assert_eq!(
                nose_x < 960.0,
                left,
                "station on the left: {left}; nose at {nose_x}"
            );
        }
    }

    #[test]
    fn bad_camera_inputs_are_clear_errors_and_write_nothing() {
        let s = setup();
        let out = s.dir.path().join("results");
        let err = |cues: &Path, v: VisionArgs| fails(&args(cues, &s.workspace, &out, v));
        // Not a video, despite its name.
        let fake = s.dir.path().join("fake.mp4");
        fs::write(&fake, b"not a video").unwrap();
        let e = err(&fake, VisionArgs::default());
        assert!(e.contains(&fake.display().to_string()), "{e}");
        // An unsupported file.
        let txt = s.dir.path().join("notes.txt");
        fs::write(&txt, b"x").unwrap();
        assert!(err(&txt, VisionArgs::default()).contains("unsupported input"));
        // Camera options with a cue file.
        let csv = s.dir.path().join("c.csv");
        assess::io::cue_csv::write(&csv, &[CueFrame::empty(0.0)]).unwrap();
        let e = err(
            &csv,
            VisionArgs {
                annotate: Some(s.dir.path().join("a.avi")),
                ..still()
            },
        );
        assert!(
            e.starts_with("--static, --annotate apply to camera inputs only"),
            "{e}"
        );
        // --depth with a camera keyword, --max-frames 0, a bad --annotate extension.
        let e = err(
            &s.images,
            VisionArgs {
                max_frames: Some(0),
                ..still()
            },
        );
        assert_eq!(e, "--max-frames must be at least 1");
        let e = err(
            &s.images,
            VisionArgs {
                annotate: Some(s.dir.path().join("a.mp4")),
                ..still()
            },
        );
        assert!(e.contains("expected an .avi file"), "{e}");
        // A missing extrinsics file is named.
        let v = VisionArgs {
            camera: crate::vision_cmd::CameraArgs {
                extrinsics: Some(s.dir.path().join("missing.toml")),
                ..Default::default()
            },
            ..still()
        };
        let e = err(&s.images, v);
        assert!(
            e.contains("cannot load the extrinsics") && e.contains("missing.toml"),
            "{e}"
        );
        assert!(!out.exists());
        assert!(!s.dir.path().join("a.mp4").exists());
    }

    #[cfg(not(feature = "realsense"))]
    #[test]
    fn a_bag_without_the_realsense_feature_names_the_feature() {
        let s = setup();
        let bag = s.dir.path().join("foo.bag");
        fs::write(&bag, b"x").unwrap();
        let out = s.dir.path().join("results");
        let e = fails(&args(&bag, &s.workspace, &out, VisionArgs::default()));
        assert!(
            e.contains("RealSense .bag files need the `realsense` feature"),
            "{e}"
        );
        assert!(!out.exists());
    }

    /// The synthetic (simulated) `.bag` end to end: every recorded frame is assessed with
    /// depth, and `cues.csv` holds a head and a body cue on each.
    #[cfg(feature = "realsense")]
    #[test]
    fn a_bag_is_assessed_frame_by_frame_with_depth() {
        let _one = crate::REALSENSE_PLAYBACK
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let s = setup();
        let bag = root().join("data/bag/synthetic_plane.bag");
        let out = s.dir.path().join("results");
        let report = assess(&args(&bag, &s.workspace, &out, VisionArgs::default())).unwrap();
        assert_eq!(report.frames, 5);
        let cues = fs::read_to_string(out.join("cues.csv")).unwrap();
        let rows: Vec<&str> = cues
            .lines()
            .filter(|l| !l.starts_with('#') && !l.starts_with('t'))
            .collect();
        assert_eq!(rows.len(), 5, "{cues}");
        let header = cues.lines().find(|l| l.starts_with('t')).unwrap();
        let col = |name: &str| header.split(',').position(|c| c == name).unwrap();
        for r in rows {
            let f: Vec<&str> = r.split(',').collect();
            assert!(!f[col("head_x")].is_empty(), "no head cue: {r}");
            assert!(!f[col("body_x")].is_empty(), "no body cue: {r}");
        }
    }

    #[test]
    fn help_says_images_are_written_only_with_annotate() {
        use clap::CommandFactory as _;
        #[derive(Debug, clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: AssessArgs,
        }
        let help = Cli::command().render_long_help().to_string();
        assert!(
            help.contains("never images, unless --annotate is given"),
            "{help}"
        );
        assert!(
            help.contains("Without this flag no image is written"),
            "{help}"
        );
        let parsed = <Cli as clap::Parser>::try_parse_from([
            "assess",
            "--cues",
            "camera",
            "--workspace",
            "w.toml",
            "--out",
            "o",
            "--lite",
            "--intrinsics",
            "600,600,320,240",
            "--max-frames",
            "10",
        ])
        .unwrap();
        assert!(parsed.args.vision.camera.lite);
        assert_eq!(parsed.args.vision.max_frames, Some(10));
        let e = <Cli as clap::Parser>::try_parse_from([
            "assess",
            "--cues",
            "camera",
            "--workspace",
            "w",
            "--out",
            "o",
            "--intrinsics",
            "1,2",
        ])
        .unwrap_err()
        .to_string();
        assert!(e.contains("expected fx,fy,cx,cy"), "{e}");
    }
}
