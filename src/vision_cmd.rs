//! Binary-side camera plumbing shared by `hrc-adapt assess --cues <video | images | .bag |
//! camera | webcam:N>`, `hrc-adapt trial --cues camera` and `hrc-adapt calibrate --camera`: what
//! a `--cues` / `--camera` argument names, the camera options, and (feature `vision`) turning
//! them into `assess::vision`'s frame source, intrinsics and pipeline settings. The perception
//! stack (landmarks → cues), the privacy-preserving output (`landmarks.csv`) and the opt-in
//! image outputs (annotated monitoring view, stored video) are `assess::vision`'s.
//!
//! **Privacy.** By default nothing derived from the camera image except landmarks and cues is
//! written. Images are written only where the user asked for them by a flag
//! (`assess --annotate`, `trial --store-video`).

use std::ffi::OsStr;
use std::fs;
use std::path::{Path, PathBuf};

use clap::Args;

use crate::Error;

/// Video file extensions taken by `--cues` (compared case-insensitively).
pub(crate) const VIDEO_EXTENSIONS: [&str; 4] = ["mp4", "avi", "mkv", "mov"];
/// Image file extensions that make a folder an image folder (compared case-insensitively).
const IMAGE_EXTENSIONS: [&str; 7] = ["png", "jpg", "jpeg", "bmp", "tif", "tiff", "webp"];

/// What a `--cues` argument names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum CueInput {
    /// A cue CSV (`assess::io::cue_csv`).
    CueCsv(PathBuf),
    /// A folder in the KTH handover layout.
    Kth(PathBuf),
    /// A video file (`.mp4 .avi .mkv .mov`).
    Video(PathBuf),
    /// A folder of images (frames in file-name order).
    Images(PathBuf),
    /// A RealSense `.bag` recording (feature `realsense`).
    Bag(PathBuf),
    /// `camera`: a RealSense camera if one is found (feature `realsense`), else webcam 0.
    Camera,
    /// `webcam:N[:WxH]`: the N-th webcam (`/dev/videoN`), optionally asking the driver for a
    /// frame size.
    Webcam {
        /// Device number (`/dev/videoN`).
        device: u32,
        /// Requested frame size (width, height) [px]; the driver may pick another.
        size: Option<(u32, u32)>,
    },
}

impl CueInput {
    /// Classifies a `--cues` argument. `camera` and `webcam:N[:WxH]` are keywords; a path is
    /// classified by its extension (files) or contents (folders: images, else KTH).
    pub(crate) fn parse(arg: &Path) -> crate::Result<Self> {
        Self::parse_flag(arg, "--cues")
    }

    /// [`Self::parse`] for the command-line flag `flag` (named in the errors).
    pub(crate) fn parse_flag(arg: &Path, flag: &str) -> crate::Result<Self> {
        if let Some(s) = arg.to_str() {
            if s == "camera" {
                return Ok(Self::Camera);
            }
            if let Some(rest) = s.strip_prefix("webcam:") {
                return parse_webcam(rest)
                    .ok_or_else(|| {
                        Error::usage(
                            flag,
                            format!(
                                "{flag} {s}: expected webcam:N[:WxH] with N a device number and \
                                 an optional frame size in px (webcam:0, webcam:1:1280x720)"
                            ),
                        )
                    })
                    .map(|(device, size)| Self::Webcam { device, size });
            }
        }
        let meta = fs::metadata(arg).map_err(|source| Error::Input {
            arg: flag.to_owned(),
            path: arg.to_path_buf(),
            source,
        })?;
        if meta.is_dir() {
            return Ok(if folder_has_images(arg)? {
                Self::Images(arg.to_path_buf())
            } else {
                Self::Kth(arg.to_path_buf())
            });
        }
        let ext = arg
            .extension()
            .and_then(OsStr::to_str)
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        Ok(match ext.as_str() {
            "csv" => Self::CueCsv(arg.to_path_buf()),
            "bag" => Self::Bag(arg.to_path_buf()),
            e if VIDEO_EXTENSIONS.contains(&e) => Self::Video(arg.to_path_buf()),
            _ => {
                return Err(Error::usage(
                    flag,
                    format!(
                        "{flag} {}: unsupported input; expected a cue CSV (.csv), a KTH handover \
                         folder, a video (.mp4 .avi .mkv .mov), an image folder, a RealSense \
                         .bag, `camera` or `webcam:N[:WxH]`",
                        arg.display()
                    ),
                ));
            }
        })
    }

    /// Whether the cues come from camera frames (landmark inference) rather than a cue file.
    pub(crate) fn is_camera(&self) -> bool {
        !matches!(self, Self::CueCsv(_) | Self::Kth(_))
    }

    /// Whether the source is live (never ends by itself).
    #[cfg_attr(not(feature = "vision"), allow(dead_code))]
    pub(crate) fn is_live(&self) -> bool {
        matches!(self, Self::Camera | Self::Webcam { .. })
    }

    /// The input's file or folder, if it has one.
    pub(crate) fn path(&self) -> Option<&Path> {
        match self {
            Self::CueCsv(p) | Self::Kth(p) | Self::Video(p) | Self::Images(p) | Self::Bag(p) => {
                Some(p)
            }
            Self::Camera | Self::Webcam { .. } => None,
        }
    }
}

/// `N` or `N:WxH` (after `webcam:`): the device number and the optional frame size [px].
fn parse_webcam(s: &str) -> Option<(u32, Option<(u32, u32)>)> {
    let (device, size) = match s.split_once(':') {
        Some((device, size)) => {
            let (w, h) = size.split_once('x')?;
            let (w, h) = (w.parse::<u32>().ok()?, h.parse::<u32>().ok()?);
            if w == 0 || h == 0 {
                return None;
            }
            (device, Some((w, h)))
        }
        None => (s, None),
    };
    Some((device.parse().ok()?, size))
}

/// Whether a folder holds at least one image file (subfolders are not looked into).
fn folder_has_images(dir: &Path) -> crate::Result<bool> {
    for entry in fs::read_dir(dir).map_err(Error::io("list", dir))? {
        let path = entry.map_err(Error::io("list", dir))?.path();
        let is_image = path
            .extension()
            .and_then(OsStr::to_str)
            .is_some_and(|e| IMAGE_EXTENSIONS.iter().any(|x| x.eq_ignore_ascii_case(e)));
        if is_image && path.is_file() {
            return Ok(true);
        }
    }
    Ok(false)
}

/// Pinhole intrinsics given on the command line as `fx,fy,cx,cy` [px].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct IntrinsicsArg {
    /// Focal length along x [px].
    pub(crate) fx: f64,
    /// Focal length along y [px].
    pub(crate) fy: f64,
    /// Principal point x [px].
    pub(crate) cx: f64,
    /// Principal point y [px].
    pub(crate) cy: f64,
}

/// Parses `fx,fy,cx,cy` [px]: four finite numbers, focal lengths > 0.
pub(crate) fn parse_intrinsics(s: &str) -> Result<IntrinsicsArg, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("expected fx,fy,cx,cy in pixels (four numbers), got `{s}`"))?;
    let [fx, fy, cx, cy] = v[..] else {
        return Err(format!(
            "expected fx,fy,cx,cy in pixels (four numbers), got {} in `{s}`",
            v.len()
        ));
    };
    if !(v.iter().all(|x| x.is_finite()) && fx > 0.0 && fy > 0.0) {
        return Err(format!(
            "intrinsics `{s}`: all four must be finite and fx, fy > 0"
        ));
    }
    Ok(IntrinsicsArg { fx, fy, cx, cy })
}

/// Parses a horizontal field of view [deg] in (0, 180).
pub(crate) fn parse_hfov(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("expected an angle in degrees, got `{s}`"))?;
    if v.is_finite() && v > 0.0 && v < 180.0 {
        Ok(v)
    } else {
        Err(format!(
            "the field of view must be in (0, 180) degrees, got {v}"
        ))
    }
}

/// Camera options shared by `assess` and `trial` (used when the cues come from a camera,
/// video, image folder or `.bag`).
#[derive(Debug, Clone, PartialEq, Args)]
pub(crate) struct CameraArgs {
    /// Camera → workspace extrinsics TOML (written by `hrc-adapt calibrate`). Without it the
    /// identity is used and every position is in the CAMERA frame (z = optical axis), so the
    /// workspace areas will not match: a warning says so.
    #[arg(long, value_name = "TOML")]
    pub(crate) extrinsics: Option<PathBuf>,
    /// Colour intrinsics `fx,fy,cx,cy` [px] for video files, image folders and webcams
    /// (RealSense cameras and .bag files carry their own); every frame must then have the first
    /// one's size. Default: from --hfov, for each frame's own size.
    #[arg(long, value_name = "FX,FY,CX,CY", value_parser = parse_intrinsics)]
    pub(crate) intrinsics: Option<IntrinsicsArg>,
    /// Horizontal field of view [deg] for the default intrinsics (the D435i colour camera: 69).
    #[arg(long, value_name = "DEG", default_value_t = 69.0, value_parser = parse_hfov)]
    pub(crate) hfov: f64,
    /// Use the lite pose and hand models (faster, less accurate).
    #[arg(long)]
    pub(crate) lite: bool,
}

impl Default for CameraArgs {
    fn default() -> Self {
        Self {
            extrinsics: None,
            intrinsics: None,
            hfov: 69.0,
            lite: false,
        }
    }
}

/// The error for a camera input in a build without the `vision` feature.
#[cfg(not(feature = "vision"))]
pub(crate) fn vision_missing(input: &CueInput) -> Error {
    Error::usage(
        "--cues",
        format!(
            "--cues {}: camera inputs need the `vision` feature; this hrc-adapt was built \
             without it (rebuild with default features)",
            input
                .path()
                .map_or_else(|| format!("{input:?}"), |p| p.display().to_string())
        ),
    )
}

#[cfg(feature = "vision")]
pub(crate) use camera::*;

/// The binary's side of `assess::vision`: a `--cues` / `--camera` argument and the camera
/// options turned into the library's source, intrinsics and pipeline settings, with errors that
/// name the flags. The perception itself (`Perception`, the landmark CSV, the image sinks, the
/// overlay) is `assess::vision`'s.
#[cfg(feature = "vision")]
mod camera {
    use std::path::Path;

    use crate::Error;
    use crate::error::ResultExt as _;
    use assess::vision::Extrinsics;
    use assess::vision::pipeline::{Mode, PipelineConfig, Variant};
    use assess::vision::source::{self, OpenedSource, SourceSpec};

    pub(crate) use assess::vision::output::{ImageSink, LandmarkCsv};
    pub(crate) use assess::vision::{FixedIntrinsics, Perception, Pinhole, annotate};

    use super::{CameraArgs, CueInput, IntrinsicsArg};

    impl IntrinsicsArg {
        /// As the library's [`Pinhole`].
        pub(crate) fn pinhole(self) -> Pinhole {
            Pinhole {
                fx: self.fx,
                fy: self.fy,
                cx: self.cx,
                cy: self.cy,
            }
        }
    }

    /// Opens the frame source `input` names. `depth` (`--depth`) is an aligned 16-bit PNG
    /// folder for a video file or an image folder.
    pub(crate) fn open_source(
        input: &CueInput,
        cam: &CameraArgs,
        depth: Option<&Path>,
    ) -> crate::Result<OpenedSource> {
        let depth = depth.map(Path::to_path_buf);
        let spec = match input {
            CueInput::Video(path) => SourceSpec::Video {
                path: path.clone(),
                depth,
            },
            CueInput::Images(path) => SourceSpec::Images {
                path: path.clone(),
                depth,
            },
            _ if depth.is_some() => {
                return Err(Error::usage(
                    "--depth",
                    "--depth applies to a video file or an image folder only",
                ));
            }
            CueInput::Bag(path) => SourceSpec::Bag(path.clone()),
            CueInput::Camera => SourceSpec::Camera,
            CueInput::Webcam { device, size } => SourceSpec::Webcam {
                device: *device,
                size: *size,
            },
            CueInput::CueCsv(_) | CueInput::Kth(_) => {
                return Err(Error::Internal {
                    reason: format!("{input:?} is a cue file, not a frame source"),
                });
            }
        };
        // Intrinsics given on the command line are not passed to the source: the frame size
        // is not known here, so they are applied per frame ([`FixedIntrinsics`], which refuses
        // a size change); the sources give their own (a RealSense's, a depth.toml's, else from
        // the hfov for each frame's size).
        Ok(source::open(&spec, cam.hfov)?)
    }

    /// `--intrinsics` for this source: refused where the source carries its own.
    pub(crate) fn intrinsics_override(
        opened: &OpenedSource,
        arg: Option<IntrinsicsArg>,
    ) -> crate::Result<Option<Pinhole>> {
        if arg.is_some() && opened.own_intrinsics {
            return Err(Error::usage(
                "--intrinsics",
                format!(
                    "--intrinsics: {} carries its own calibrated intrinsics; drop the flag",
                    opened.source.describe()
                ),
            ));
        }
        Ok(arg.map(IntrinsicsArg::pinhole))
    }

    /// The image sink for `path`, given by the flag `flag` (named in the errors), at the
    /// source's rate `fps` [1/s].
    pub(crate) fn image_sink(path: &Path, flag: &str, fps: f64) -> crate::Result<ImageSink> {
        ImageSink::create(path, fps).with_context(|| flag.to_owned())
    }

    /// Loads `--extrinsics`, or returns the identity with a loud warning.
    pub(crate) fn load_extrinsics(cam: &CameraArgs) -> crate::Result<Extrinsics> {
        match &cam.extrinsics {
            Some(p) => Extrinsics::load(p)
                .with_context(|| format!("cannot load the extrinsics {}", p.display())),
            None => {
                eprintln!(
                    "WARNING: no --extrinsics given: using the identity, so every cue position \
                     is in the CAMERA frame (x right, y down, z along the optical axis [m]), not \
                     the workspace frame; the workspace areas will not line up. Calibrate with \
                     `hrc-adapt calibrate` and pass --extrinsics."
                );
                Ok(Extrinsics::identity())
            }
        }
    }

    /// The pipeline settings for these options.
    pub(crate) fn pipeline_config(cam: &CameraArgs, still: bool) -> PipelineConfig {
        PipelineConfig {
            variant: if cam.lite {
                Variant::Lite
            } else {
                Variant::Full
            },
            mode: if still { Mode::Static } else { Mode::Tracking },
            ..PipelineConfig::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_are_classified_by_keyword_extension_and_contents() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        assert_eq!(
            CueInput::parse(Path::new("camera")).unwrap(),
            CueInput::Camera
        );
        assert_eq!(
            CueInput::parse(Path::new("webcam:2")).unwrap(),
            CueInput::Webcam {
                device: 2,
                size: None
            }
        );
        assert_eq!(
            CueInput::parse(Path::new("webcam:1:1280x720")).unwrap(),
            CueInput::Webcam {
                device: 1,
                size: Some((1280, 720))
            }
        );
        for bad in [
            "webcam:x",
            "webcam:",
            "webcam:1:1280",
            "webcam:1:0x720",
            "webcam:1:axb",
        ] {
            let e = CueInput::parse(Path::new(bad)).unwrap_err().to_string();
            assert!(
                e.starts_with(&format!("--cues {bad}: expected webcam:N")),
                "{e}"
            );
        }
        let e = CueInput::parse_flag(Path::new("webcam:x"), "--camera")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("--camera webcam:x: expected"), "{e}");
        for (name, want) in [
            ("c.csv", CueInput::CueCsv(d.join("c.csv"))),
            ("r.MP4", CueInput::Video(d.join("r.MP4"))),
            ("r.avi", CueInput::Video(d.join("r.avi"))),
            ("r.mkv", CueInput::Video(d.join("r.mkv"))),
            ("r.mov", CueInput::Video(d.join("r.mov"))),
            ("r.bag", CueInput::Bag(d.join("r.bag"))),
        ] {
            fs::write(d.join(name), b"x").unwrap();
            assert_eq!(CueInput::parse(&d.join(name)).unwrap(), want, "{name}");
        }
        fs::write(d.join("notes.txt"), b"x").unwrap();
        let e = CueInput::parse(&d.join("notes.txt"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("unsupported input"), "{e}");
        let e = CueInput::parse(&d.join("missing.mp4")).unwrap_err();
        assert!(
            e.with_causes().to_string().starts_with(&format!(
                "cannot read --cues {}",
                d.join("missing.mp4").display()
            )),
            "{e:#}"
        );
        let images = d.join("images");
        fs::create_dir(&images).unwrap();
        fs::write(images.join("a.JPG"), b"x").unwrap();
        assert_eq!(CueInput::parse(&images).unwrap(), CueInput::Images(images));
        let kth = d.join("kth");
        fs::create_dir(&kth).unwrap();
        fs::write(kth.join("taker_head_pose_saved.csv"), b"x").unwrap();
        assert_eq!(CueInput::parse(&kth).unwrap(), CueInput::Kth(kth));
        assert!(CueInput::Camera.is_live() && CueInput::Camera.is_camera());
        assert!(!CueInput::CueCsv(d.join("c.csv")).is_camera());
    }

    /// RealSense recordings carry their own calibration: `--intrinsics` is refused for them.
    #[cfg(feature = "realsense")]
    #[test]
    fn intrinsics_cannot_override_a_bags_own() {
        let _one = crate::REALSENSE_PLAYBACK
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let bag = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("data/bag/synthetic_plane.bag");
        let opened = open_source(&CueInput::Bag(bag), &CameraArgs::default(), None).unwrap();
        assert!(opened.own_intrinsics);
        let arg = parse_intrinsics("600,610,320,240").unwrap();
        let e = intrinsics_override(&opened, Some(arg))
            .unwrap_err()
            .to_string();
        assert!(e.contains("its own calibrated intrinsics"), "{e}");
        assert!(intrinsics_override(&opened, None).unwrap().is_none());
    }

    /// `--depth` with a source that is not a video or an image folder is a usage error.
    #[cfg(feature = "vision")]
    #[test]
    fn depth_is_refused_for_cameras_and_bags() {
        for input in [
            CueInput::Camera,
            CueInput::Bag(PathBuf::from("x.bag")),
            CueInput::Webcam {
                device: 0,
                size: None,
            },
        ] {
            let e = open_source(&input, &CameraArgs::default(), Some(Path::new("depth")))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("--depth applies to a video file or an image folder"),
                "{e}"
            );
        }
    }

    #[test]
    fn intrinsics_and_fov_are_validated() {
        assert_eq!(
            parse_intrinsics("600, 610,320,240.5").unwrap(),
            IntrinsicsArg {
                fx: 600.0,
                fy: 610.0,
                cx: 320.0,
                cy: 240.5
            }
        );
        assert!(
            parse_intrinsics("600,610,320")
                .unwrap_err()
                .contains("got 3")
        );
        assert!(
            parse_intrinsics("a,b,c,d")
                .unwrap_err()
                .contains("four numbers")
        );
        assert!(
            parse_intrinsics("0,610,320,240")
                .unwrap_err()
                .contains("fx, fy > 0")
        );
        assert_eq!(parse_hfov("69").unwrap(), 69.0);
        assert!(parse_hfov("180").is_err());
        assert!(parse_hfov("-3").is_err());
    }
}
