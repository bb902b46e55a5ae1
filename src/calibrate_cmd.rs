//! `hrc-adapt calibrate`: camera-to-workspace extrinsics from a ChArUco board
//! (`assess::vision::calib`), and the printable board.
//!
//! - `--print-board board.png` writes the board (`--board`, default `config/board.toml`) at
//!   `--dpi` and prints its physical size and the frame it defines.
//! - `--image board.jpg` or `--camera <source>` gives the colour image(s) of the board lying on
//!   the table. A source is anything `assess --cues` reads frames from, opened the same way
//!   (`crate::vision_cmd::open_source`): a video file, an image folder, a RealSense `.bag`
//!   (feature `realsense`), `camera` (a RealSense camera with that feature, else webcam 0) or
//!   `webcam:N[:WxH]`. From a source, `--skip` frames are dropped (exposure settling), then up
//!   to `--frames` frames are calibrated and the one with the most corners (then the lowest
//!   reprojection RMS) is kept; the spread of the others shows how stable the pose is.
//! - The intrinsics are `--intrinsics fx,fy,cx,cy` [px], else the source's: a RealSense
//!   camera's or `.bag`'s own, or a pinhole model with `--hfov-deg` (a guess; the pose is then
//!   only as good as it).
//! - `--out` (default `extrinsics.toml`, refused if it exists unless `--force`) receives the
//!   extrinsics with their provenance; `--check check.png` the image with the workspace areas
//!   (`--workspace`), the board and the axes projected, to check by eye.

use std::path::{Path, PathBuf};

use assess::Workspace;
use assess::vision::calib::{self, BoardCalibration, BoardSpec, CalibrationInfo, ExtrinsicsFile};
use assess::vision::source::capture::DEFAULT_HFOV_DEG;
use assess::vision::source::folder;
use assess::vision::{Intrinsics, RgbImage};
use clap::Args;

use crate::Error;
use crate::error::ResultExt as _;
use crate::vision_cmd::{
    CameraArgs, CueInput, FixedIntrinsics, IntrinsicsArg, intrinsics_override, open_source,
    parse_hfov, parse_intrinsics,
};

/// Arguments of `hrc-adapt calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// A colour image (PNG, JPEG, ...) of the board lying on the table.
    #[arg(long, conflicts_with = "camera")]
    image: Option<PathBuf>,
    /// A frame source showing the board: a video file, an image folder, a RealSense .bag
    /// (feature `realsense`), `camera` (a RealSense camera if built with `realsense` and one is
    /// connected, else the first webcam) or `webcam:N[:WxH]` (device N, optionally asking for
    /// a W x H px frame).
    #[arg(long)]
    camera: Option<PathBuf>,
    /// Colour intrinsics `fx,fy,cx,cy` [px]; default: the source's (see --hfov-deg).
    #[arg(long, value_name = "FX,FY,CX,CY", value_parser = parse_intrinsics)]
    intrinsics: Option<IntrinsicsArg>,
    /// Horizontal field of view [deg] assumed when no intrinsics are known.
    #[arg(long, value_name = "DEG", default_value_t = DEFAULT_HFOV_DEG, value_parser = parse_hfov)]
    hfov_deg: f64,
    /// The board description.
    #[arg(long, default_value = "config/board.toml")]
    board: PathBuf,
    /// Workspace areas to draw on the check image.
    #[arg(long)]
    workspace: Option<PathBuf>,
    /// Where to write the extrinsics.
    #[arg(long, default_value = "extrinsics.toml")]
    out: PathBuf,
    /// Replace an existing --out file.
    #[arg(long)]
    force: bool,
    /// Write a check image (areas, board and axes projected onto the frame) as PNG.
    #[arg(long)]
    check: Option<PathBuf>,
    /// Frames to calibrate from --camera (the best is kept).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..=1000))]
    frames: u32,
    /// Frames to drop first from --camera (exposure settling).
    #[arg(long, default_value_t = 5)]
    skip: u32,
    /// Write the printable board as PNG (with its print resolution) and report its size.
    #[arg(long)]
    print_board: Option<PathBuf>,
    /// Print resolution of --print-board [dpi].
    #[arg(long, default_value_t = 300.0)]
    dpi: f64,
}

/// White margin around the printed board [m].
const PRINT_MARGIN_M: f64 = 0.01;

/// What a run produced, for the summary.
#[derive(Debug)]
struct Outcome {
    source: String,
    intrinsics: Intrinsics,
    guessed_intrinsics: bool,
    calibration: BoardCalibration,
    tried: usize,
    succeeded: usize,
    spread_m: f64,
}

/// Runs `hrc-adapt calibrate`: prints the board, or writes the extrinsics file.
pub fn run(args: CalibrateArgs) -> crate::Result<()> {
    let board = BoardSpec::from_toml_file(&args.board)
        .with_context(|| format!("loading the board {}", args.board.display()))?;
    if let Some(png) = &args.print_board {
        print!("{}", print_board(&board, png, args.dpi)?);
        if args.image.is_none() && args.camera.is_none() {
            return Ok(());
        }
    }
    let outcome = calibrate(&args, &board)?;
    print!("{}", summary(&args, &outcome));
    Ok(())
}

fn print_board(board: &BoardSpec, png: &Path, dpi: f64) -> crate::Result<String> {
    let print = calib::write_board_png(board, png, dpi, PRINT_MARGIN_M)
        .with_context(|| format!("writing the board to {}", png.display()))?;
    let (w, h) = print.paper_m;
    let (bw, bh) = board.size_m();
    let paper = if w <= 0.200 && h <= 0.287 {
        "fits A4 (portrait)"
    } else if w <= 0.287 && h <= 0.410 {
        "needs A3 (portrait); on A4 it would be scaled down"
    } else {
        "larger than A3; print in tiles or at a print shop"
    };
    Ok(format!(
        "wrote {}: {board}\n\
         print at 100 % / actual size ({:.1} dpi, stored in the PNG): {:.1} x {:.1} mm with the \
         {:.0} mm margin, squares area {:.1} x {:.1} mm; {paper}\n\
         after printing, measure a square: it must be {:.1} mm (else put the measured size in the \
         board file)\n\
         frame: origin at the outer corner of the bottom-left square (board upright), x right \
         along the bottom edge, y up the left edge, z out of the printed face (up on the table)\n",
        png.display(),
        print.px_per_m * 0.0254,
        w * 1e3,
        h * 1e3,
        print.margin_m * 1e3,
        bw * 1e3,
        bh * 1e3,
        board.square_m() * 1e3,
    ))
}

/// The usage error of a `calibrate` without an image, a camera or `--print-board`.
fn nothing_to_do() -> Error {
    Error::usage(
        "--image, --camera, --print-board",
        "nothing to do: pass --image, --camera or --print-board",
    )
}

fn calibrate(args: &CalibrateArgs, board: &BoardSpec) -> crate::Result<Outcome> {
    if args.image.is_none() && args.camera.is_none() {
        return Err(nothing_to_do());
    }
    if args.out.exists() && !args.force {
        return Err(Error::usage(
            "--out",
            format!("{} exists; pass --force to replace it", args.out.display()),
        ));
    }
    let workspace = args
        .workspace
        .as_ref()
        .map(|p| {
            Workspace::from_toml_file(p)
                .with_context(|| format!("loading the workspace {}", p.display()))
        })
        .transpose()?;
    let (source, frames) = match (&args.image, &args.camera) {
        (Some(path), None) => {
            let image = folder::read_image(path)?;
            let k = args
                .intrinsics
                .map(|k| k.pinhole().at_size(image.width, image.height));
            let guessed = k.is_none();
            let k = k
                .unwrap_or_else(|| Intrinsics::from_hfov(image.width, image.height, args.hfov_deg));
            (
                format!("image {}", path.display()),
                vec![(image, k, guessed)],
            )
        }
        (None, Some(spec)) => grab_frames(args, spec)?,
        (Some(_), Some(_)) => {
            return Err(Error::usage(
                "--image, --camera",
                "pass either --image or --camera, not both",
            ));
        }
        (None, None) => return Err(nothing_to_do()),
    };
    let tried = frames.len();
    let mut results = Vec::new();
    let mut last_err = None;
    for (image, k, guessed) in frames {
        match calib::calibrate(board, &image, &k) {
            Ok(c) => results.push((c, image, k, guessed)),
            Err(e) => last_err = Some(e),
        }
    }
    let succeeded = results.len();
    let best = results
        .iter()
        .enumerate()
        .min_by(|(_, a), (_, b)| {
            b.0.detection
                .corners
                .len()
                .cmp(&a.0.detection.corners.len())
                .then(a.0.reprojection_rms_px.total_cmp(&b.0.reprojection_rms_px))
        })
        .map(|(i, _)| i);
    let Some(best) = best else {
        let err = last_err.map_or_else(|| "no frame".to_string(), |e| e.to_string());
        return Err(Error::data(
            source,
            format!("calibration failed on all {tried} frame(s): {err}"),
        ));
    };
    let spread_m = results
        .iter()
        .map(|r| {
            (r.0.extrinsics.world_from_camera.translation.vector
                - results[best]
                    .0
                    .extrinsics
                    .world_from_camera
                    .translation
                    .vector)
                .norm()
        })
        .fold(0.0, f64::max);
    let (calibration, image, intrinsics, guessed) = results.swap_remove(best);

    let file = ExtrinsicsFile {
        extrinsics: calibration.extrinsics,
        info: Some(CalibrationInfo {
            board: board.to_string(),
            source: source.clone(),
            date: crate::trial::utc_now_iso(),
            reprojection_rms_px: calibration.reprojection_rms_px,
            corners: calibration.detection.corners.len(),
            intrinsics,
        }),
    };
    file.save(&args.out)?;
    if let Some(check) = &args.check {
        let out = calib::check_image(
            &image,
            &intrinsics,
            &calibration.extrinsics,
            board,
            workspace.as_ref(),
            Some(&calibration),
        )?;
        calib::write_png(&out, check)?;
    }
    Ok(Outcome {
        source,
        intrinsics,
        guessed_intrinsics: guessed,
        calibration,
        tried,
        succeeded,
        spread_m,
    })
}

type Frames = (String, Vec<(RgbImage, Intrinsics, bool)>);

fn grab_frames(args: &CalibrateArgs, spec: &Path) -> crate::Result<Frames> {
    let input = CueInput::parse_flag(spec, "--camera")?;
    if !input.is_camera() {
        return Err(Error::usage(
            "--camera",
            format!(
                "--camera {}: a cue file or KTH folder holds no images; expected a video, an \
                 image folder, a RealSense .bag, `camera` or `webcam:N[:WxH]`",
                spec.display()
            ),
        ));
    }
    let cam = CameraArgs {
        hfov: args.hfov_deg,
        ..CameraArgs::default()
    };
    let opened = open_source(&input, &cam, None)?;
    let mut explicit = intrinsics_override(&opened, args.intrinsics)?.map(FixedIntrinsics::new);
    let mut src = opened.source;
    let mut frames = Vec::new();
    let mut seen = 0u32;
    while frames.len() < args.frames as usize {
        let Some(frame) = src.next_frame()? else {
            break;
        };
        seen += 1;
        if seen <= args.skip {
            continue;
        }
        let (k, guessed) = match explicit.as_mut() {
            Some(fixed) => (
                fixed.at(frame.index, frame.color.width, frame.color.height)?,
                false,
            ),
            // Colour-only sources guess theirs from --hfov-deg; RealSense ones carry their own.
            None => (frame.intrinsics, !src.has_depth()),
        };
        frames.push((frame.color, k, guessed));
    }
    if frames.is_empty() {
        return Err(Error::Camera {
            camera: src.describe(),
            reason: format!("gave no frame after skipping {} (see --skip)", args.skip),
        });
    }
    Ok((src.describe(), frames))
}

fn summary(args: &CalibrateArgs, o: &Outcome) -> String {
    let c = &o.calibration;
    let iso = c.extrinsics.world_from_camera;
    let p = iso.translation.vector;
    let axis = iso.rotation * assess::Vec3::z();
    let down_deg = (-axis.z).clamp(-1.0, 1.0).asin().to_degrees();
    let k = &o.intrinsics;
    let mut s = format!(
        "calibrated from {} ({} of {} frame(s) usable)\n\
         {} corners from {} markers, reprojection RMS {:.3} px\n\
         camera at ({:.3}, {:.3}, {:.3}) m in the workspace frame, looking {:.1} deg below \
         horizontal\n\
         intrinsics {} x {} px: fx {:.1}, fy {:.1}, cx {:.1}, cy {:.1}{}\n\
         wrote {}\n",
        o.source,
        o.succeeded,
        o.tried,
        c.detection.corners.len(),
        c.detection.markers,
        c.reprojection_rms_px,
        p.x,
        p.y,
        p.z,
        down_deg,
        k.width,
        k.height,
        k.fx,
        k.fy,
        k.cx,
        k.cy,
        if o.guessed_intrinsics {
            format!(
                " (GUESSED from a {:.0} deg field of view: pass --intrinsics)",
                args.hfov_deg
            )
        } else {
            String::new()
        },
        args.out.display(),
    );
    if o.succeeded > 1 {
        s.push_str(&format!(
            "camera position spread over the usable frames: {:.1} mm\n",
            o.spread_m * 1e3
        ));
    }
    if c.reprojection_rms_px > 1.0 {
        s.push_str(
            "warning: reprojection RMS above 1 px: check the intrinsics and the board size\n",
        );
    }
    if let Some(check) = &args.check {
        s.push_str(&format!("wrote {} (check it by eye)\n", check.display()));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(dir: &Path) -> CalibrateArgs {
        CalibrateArgs {
            image: None,
            camera: None,
            intrinsics: None,
            hfov_deg: DEFAULT_HFOV_DEG,
            board: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config/board.toml"),
            workspace: None,
            out: dir.join("extrinsics.toml"),
            force: false,
            check: Some(dir.join("check.png")),
            frames: 3,
            skip: 0,
            print_board: None,
            dpi: 100.0,
        }
    }

    #[test]
    fn the_command_line_takes_the_shared_camera_spellings() {
        #[derive(Debug, clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: CalibrateArgs,
        }
        let parse = |extra: &[&str]| {
            let argv = ["calibrate"].iter().chain(extra).copied();
            <Cli as clap::Parser>::try_parse_from(argv).map(|c| c.args)
        };
        let a = parse(&[
            "--camera",
            "webcam:1:1280x720",
            "--intrinsics",
            "910, 905.5,640,360",
            "--hfov-deg",
            "60",
        ])
        .expect("parses");
        assert_eq!(
            a.intrinsics,
            Some(IntrinsicsArg {
                fx: 910.0,
                fy: 905.5,
                cx: 640.0,
                cy: 360.0
            })
        );
        assert_eq!(a.hfov_deg, 60.0);
        let camera = a.camera.expect("camera");
        assert_eq!(
            CueInput::parse_flag(&camera, "--camera").expect("webcam"),
            CueInput::Webcam {
                device: 1,
                size: Some((1280, 720))
            }
        );
        for bad in [
            ["--intrinsics", "910,905,640"],
            ["--intrinsics", "0,905,640,360"],
            ["--hfov-deg", "180"],
        ] {
            assert!(parse(&bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn prints_the_board_then_calibrates_from_it_and_from_a_folder() {
        let dir = tempfile::tempdir().expect("tempdir");
        let board = BoardSpec::default();
        let png = dir.path().join("board.png");
        let text = print_board(&board, &png, 300.0).expect("print");
        assert!(text.contains("220.0 x 300.0 mm"), "{text}");
        assert!(text.contains("needs A3"), "{text}");

        // The print itself, seen head-on by a camera with a 60 deg field of view.
        let mut a = args(dir.path());
        a.image = Some(png.clone());
        a.hfov_deg = 60.0;
        let o = calibrate(&a, &board).expect("calibrate");
        assert_eq!(o.calibration.detection.corners.len(), 24);
        assert!(o.guessed_intrinsics);
        let f = ExtrinsicsFile::load(&a.out).expect("extrinsics");
        let info = f.info.expect("info");
        assert_eq!(info.corners, 24);
        assert!(info.source.contains("board.png"));
        // Head-on: the optical axis points down the board's z axis (into the page).
        let axis = f.extrinsics.world_from_camera.rotation * assess::Vec3::z();
        assert!(axis.z < -0.999, "{axis}");
        assert!(a.check.as_ref().expect("check").is_file());
        assert!(summary(&a, &o).contains("GUESSED"));

        // The file exists now: refused without --force.
        let err = calibrate(&a, &board).expect_err("exists").to_string();
        assert!(err.contains("--force"), "{err}");

        // An image folder as the camera: the print twice and a blank image.
        let frames = dir.path().join("frames");
        std::fs::create_dir_all(&frames).expect("dir");
        std::fs::copy(&png, frames.join("000000.png")).expect("copy");
        std::fs::copy(&png, frames.join("000001.png")).expect("copy");
        let blank = RgbImage::black(o.intrinsics.width, o.intrinsics.height);
        calib::write_png(&blank, frames.join("000002.png")).expect("blank");
        let mut a = args(dir.path());
        a.camera = Some(frames.clone());
        a.force = true;
        a.intrinsics = Some(IntrinsicsArg {
            fx: o.intrinsics.fx,
            fy: o.intrinsics.fy,
            cx: o.intrinsics.cx,
            cy: o.intrinsics.cy,
        });
        let o2 = calibrate(&a, &board).expect("folder");
        assert_eq!((o2.tried, o2.succeeded), (3, 2));
        assert!(o2.spread_m < 1e-9);
        assert!(!o2.guessed_intrinsics);
    }

    #[test]
    fn a_board_less_image_fails_clearly() {
        let dir = tempfile::tempdir().expect("tempdir");
        let fails = |a: &CalibrateArgs| {
            let e = calibrate(a, &BoardSpec::default()).expect_err("must fail");
            assert!(!a.out.exists());
            e.with_causes().to_string()
        };
        let path = dir.path().join("blank.png");
        calib::write_png(&RgbImage::black(320, 240), &path).expect("png");
        let mut a = args(dir.path());
        a.image = Some(path);
        let err = fails(&a);
        assert!(err.contains("no DICT_4X4_50 marker found"), "{err}");
        let mut a = args(dir.path());
        a.camera = Some("webcam:x".into());
        let err = fails(&a);
        assert!(
            err.starts_with("--camera webcam:x: expected webcam:N"),
            "{err}"
        );
        a.camera = Some(dir.path().join("nothing-here"));
        let err = fails(&a);
        assert!(err.starts_with("cannot read --camera"), "{err}");
        // A cue file has no images.
        let csv = dir.path().join("cues.csv");
        std::fs::write(&csv, "t\n").expect("csv");
        a.camera = Some(csv);
        let err = fails(&a);
        assert!(err.contains("holds no images"), "{err}");
    }
}
