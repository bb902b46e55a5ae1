//! Binary-side camera plumbing shared by `hrc-adapt assess --cues <video | images | .bag |
//! camera | webcam:N>`, `hrc-adapt trial --cues camera` and `hrc-adapt calibrate --camera`: what
//! a `--cues` / `--camera` argument names, the camera options, and (feature `vision`) opening the
//! frame source, the perception stack
//! (landmarks → cues), the privacy-preserving outputs (`landmarks.csv`) and the opt-in image
//! outputs (annotated monitoring view, stored video).
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

#[cfg(feature = "vision")]
mod camera {
    use std::fmt::Write as _;
    use std::fs::File;
    use std::io::{BufWriter, Write};
    use std::path::{Path, PathBuf};

    use crate::Error;
    use crate::error::ResultExt as _;
    use assess::vision::cues::{CueConfig, CueExtractor, PerceivedCues, load_canonical_face};
    use assess::vision::pipeline::{Mode, Pipeline, PipelineConfig, StationView, Variant};
    use assess::vision::source::capture::{
        VideoFileOptions, VideoFileSource, VideoSink, WebcamOptions, WebcamSource,
    };
    use assess::vision::source::folder::{ImageFolderOptions, ImageFolderSource};
    use assess::vision::{
        CameraFrame, Extrinsics, FrameSource, Intrinsics, Landmarks, RgbImage, draw, models,
    };
    use assess::{Assessment, Station, Workspace};

    use super::{CameraArgs, CueInput, IntrinsicsArg};

    /// `--intrinsics` applied to the frames of one source: they hold for one camera, so the
    /// first frame fixes the size and a frame of another size is an error.
    #[derive(Debug, Clone, Copy)]
    pub(crate) struct FixedIntrinsics {
        arg: IntrinsicsArg,
        /// The first frame's size (width, height) [px].
        size: Option<(u32, u32)>,
    }

    impl FixedIntrinsics {
        /// Nothing seen yet.
        pub(crate) fn new(arg: IntrinsicsArg) -> Self {
            Self { arg, size: None }
        }

        /// The intrinsics of frame `index`, an image of `width` × `height` [px].
        pub(crate) fn at(
            &mut self,
            index: u64,
            width: u32,
            height: u32,
        ) -> crate::Result<Intrinsics> {
            match *self.size.get_or_insert((width, height)) {
                (w, h) if (w, h) == (width, height) => Ok(self.arg.at_size(width, height)),
                (w, h) => Err(Error::usage(
                    "--intrinsics",
                    format!(
                        "frame {index} is {width} x {height} px but the first frame was {w} x {h} \
                         px: --intrinsics hold for one camera (without it, each image of a \
                         folder gets intrinsics from --hfov for its own size)"
                    ),
                )),
            }
        }
    }

    impl IntrinsicsArg {
        /// As [`Intrinsics`] of a `width` × `height` image [px].
        pub(crate) fn at_size(self, width: u32, height: u32) -> Intrinsics {
            Intrinsics {
                width,
                height,
                fx: self.fx,
                fy: self.fy,
                cx: self.cx,
                cy: self.cy,
            }
        }
    }

    /// An opened frame source, its nominal frame rate and, when known, how many frames it
    /// holds.
    pub(crate) struct Opened {
        /// The source.
        pub(crate) source: Box<dyn FrameSource>,
        /// The number of frames, for recordings that know it.
        pub(crate) len: Option<u64>,
        /// The source's nominal frame rate [1/s] (the container's, the folder's, the
        /// driver's); the rate of a video written from its frames.
        pub(crate) fps: f64,
        /// Whether the source carries its own calibrated intrinsics (RealSense cameras and
        /// `.bag` files), which `--intrinsics` must not override.
        pub(crate) own_intrinsics: bool,
    }

    impl Opened {
        /// `--intrinsics` for this source: refused where the source carries its own.
        pub(crate) fn intrinsics_override(
            &self,
            arg: Option<IntrinsicsArg>,
        ) -> crate::Result<Option<IntrinsicsArg>> {
            if arg.is_some() && self.own_intrinsics {
                return Err(Error::usage(
                    "--intrinsics",
                    format!(
                        "--intrinsics: {} carries its own calibrated intrinsics; drop the flag",
                        self.source.describe()
                    ),
                ));
            }
            Ok(arg)
        }
    }

    impl std::fmt::Debug for Opened {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.debug_struct("Opened")
                .field("source", &self.source.describe())
                .field("len", &self.len)
                .field("fps", &self.fps)
                .field("own_intrinsics", &self.own_intrinsics)
                .finish()
        }
    }

    /// Opens the frame source `input` names. `depth` is an aligned 16-bit PNG folder for a
    /// video file or an image folder.
    pub(crate) fn open_source(
        input: &CueInput,
        cam: &CameraArgs,
        depth: Option<&Path>,
    ) -> crate::Result<Opened> {
        // Intrinsics given on the command line are not passed to the sources: the frame size
        // is not known here, so they are applied per frame by the caller ([`FixedIntrinsics`],
        // which refuses a size change); the sources give their own (a RealSense's, a depth.toml's,
        // else from the hfov for each frame's size).
        if depth.is_some() && !matches!(input, CueInput::Video(_) | CueInput::Images(_)) {
            return Err(Error::usage(
                "--depth",
                "--depth applies to a video file or an image folder only",
            ));
        }
        let opened = match input {
            CueInput::CueCsv(_) | CueInput::Kth(_) => {
                return Err(Error::Internal {
                    reason: format!("{input:?} is a cue file, not a frame source"),
                });
            }
            CueInput::Video(p) => {
                let source = VideoFileSource::open(
                    p,
                    VideoFileOptions {
                        intrinsics: None,
                        hfov_deg: cam.hfov,
                        fps: None,
                        depth: depth.map(Path::to_path_buf),
                    },
                )?;
                let (len, fps) = (source.frame_count(), source.fps());
                Opened {
                    source: Box::new(source),
                    len,
                    fps,
                    own_intrinsics: false,
                }
            }
            CueInput::Images(p) => {
                let source = ImageFolderSource::open(
                    p,
                    ImageFolderOptions {
                        hfov_deg: cam.hfov,
                        depth: depth.map(Path::to_path_buf),
                        ..ImageFolderOptions::default()
                    },
                )?;
                let (len, fps) = (Some(source.files().len() as u64), source.fps());
                Opened {
                    source: Box::new(source),
                    len,
                    fps,
                    own_intrinsics: false,
                }
            }
            CueInput::Bag(p) => open_bag(p)?,
            CueInput::Camera => open_camera(cam)?,
            CueInput::Webcam { device, size } => open_webcam(*device, *size, cam)?,
        };
        Ok(opened)
    }

    fn open_webcam(n: u32, size: Option<(u32, u32)>, cam: &CameraArgs) -> crate::Result<Opened> {
        let source = WebcamSource::open(
            n,
            WebcamOptions {
                size,
                hfov_deg: cam.hfov,
                ..WebcamOptions::default()
            },
        )
        .with_context(|| format!("cannot open webcam {n} (/dev/video{n})"))?;
        Ok(Opened {
            fps: source.fps(),
            source: Box::new(source),
            len: None,
            own_intrinsics: false,
        })
    }

    #[cfg(feature = "realsense")]
    fn open_bag(p: &Path) -> crate::Result<Opened> {
        use assess::vision::source::realsense::RealSenseSource;
        Ok(Opened {
            source: Box::new(RealSenseSource::open_bag(p)?),
            len: None,
            fps: assess::vision::source::capture::DEFAULT_FPS,
            own_intrinsics: true,
        })
    }

    #[cfg(not(feature = "realsense"))]
    fn open_bag(p: &Path) -> crate::Result<Opened> {
        Err(Error::usage(
            "--cues",
            format!(
                "--cues {}: RealSense .bag files need the `realsense` feature; this hrc-adapt \
                 was built without it (cargo build --release --features realsense, with \
                 librealsense2 from scripts/setup)",
                p.display()
            ),
        ))
    }

    /// `camera`: the first RealSense device (feature `realsense`), else webcam 0; an error
    /// naming both when neither is there.
    fn open_camera(cam: &CameraArgs) -> crate::Result<Opened> {
        #[cfg(feature = "realsense")]
        let realsense_note = {
            use assess::vision::source::realsense::{
                RealSenseConfig, RealSenseSource, list_devices,
            };
            match list_devices() {
                Ok(devices) if !devices.is_empty() => {
                    let config = RealSenseConfig::default();
                    let source = RealSenseSource::open_camera(&config)?;
                    return Ok(Opened {
                        source: Box::new(source),
                        len: None,
                        fps: f64::from(config.fps),
                        own_intrinsics: true,
                    });
                }
                Ok(_) => "no RealSense device is connected".to_string(),
                Err(e) => format!("RealSense devices cannot be listed ({e})"),
            }
        };
        #[cfg(not(feature = "realsense"))]
        let realsense_note =
            "RealSense cameras need the `realsense` feature, which this build lacks".to_string();
        match open_webcam(0, None, cam) {
            Ok(opened) => Ok(opened),
            Err(e) => Err(Error::Camera {
                camera: "--cues camera".into(),
                reason: format!(
                    "found no camera: {realsense_note}, and webcam 0 cannot be opened ({}); \
                     connect a camera, or pass a recording to --cues",
                    e.with_causes()
                ),
            }),
        }
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

    /// Landmarks → cues for one camera: the landmark pipeline and the cue extractor.
    #[derive(Debug)]
    pub(crate) struct Perception {
        pipeline: Pipeline,
        extractor: CueExtractor,
        intrinsics: Option<FixedIntrinsics>,
        /// The operator's station (workspace frame).
        station: Option<Station>,
    }

    /// One frame's perception result.
    #[derive(Debug)]
    pub(crate) struct Perceived {
        /// The landmarks [px].
        pub(crate) landmarks: Landmarks,
        /// The cues (workspace frame) and their quality.
        pub(crate) cues: PerceivedCues,
        /// The intrinsics used.
        pub(crate) intrinsics: Intrinsics,
    }

    impl Perception {
        /// Initialises ONNX Runtime, loads the models from [`models::model_dir`] and the
        /// canonical face. `intrinsics` overrides the sources' (video, images, webcams).
        /// `station` (the workspace's) makes a person there the preferred operator
        /// ([`assess::vision::pipeline::rank_operators`]).
        pub(crate) fn load(
            config: PipelineConfig,
            extrinsics: Extrinsics,
            intrinsics: Option<IntrinsicsArg>,
            station: Option<&Station>,
        ) -> crate::Result<Self> {
            models::init_runtime(None).context("cannot load ONNX Runtime")?;
            let dir = models::model_dir();
            let pipeline = Pipeline::load(&dir, config).with_context(|| {
                format!("cannot load the landmark models from {}", dir.display())
            })?;
            let canonical = load_canonical_face(&dir.join("canonical_face_model.csv"))?;
            let extractor = CueExtractor::new(CueConfig::default(), extrinsics, canonical)?;
            Ok(Self {
                pipeline,
                extractor,
                intrinsics: intrinsics.map(FixedIntrinsics::new),
                station: station.copied(),
            })
        }

        /// Landmarks and cues of one frame (cue time = camera time). With `--intrinsics`, a
        /// frame whose size differs from the first is an error.
        pub(crate) fn step(&mut self, frame: &CameraFrame) -> crate::Result<Perceived> {
            let intrinsics = match &mut self.intrinsics {
                Some(fixed) => fixed.at(frame.index, frame.color.width, frame.color.height)?,
                None => frame.intrinsics,
            };
            let station = self.station.as_ref().and_then(|st| {
                StationView::from_workspace(st, self.extractor.extrinsics(), intrinsics)
            });
            self.pipeline.set_station(station);
            let landmarks = self
                .pipeline
                .process_at(frame.t, &frame.color, frame.depth.as_ref())
                .with_context(|| format!("landmarks of frame {}", frame.index))?;
            let cues =
                self.extractor
                    .extract(frame.t, &landmarks, frame.depth.as_ref(), &intrinsics);
            Ok(Perceived {
                landmarks,
                cues,
                intrinsics,
            })
        }

        /// The extrinsics in use.
        pub(crate) fn extrinsics(&self) -> &Extrinsics {
            self.extractor.extrinsics()
        }
    }

    /// `landmarks.csv`: one row per landmark, `frame,t,set,index,x_px,y_px,score`.
    ///
    /// - `frame`: the source's frame number; `t`: camera time [s];
    /// - `set`: `pose` (33), `face` (468), `hand0` / `hand1` (21 each, in the pipeline's
    ///   order; which hand is left or right is in the cues);
    /// - `x_px`, `y_px`: image position [px] (MediaPipe's continuous coordinates: pixel
    ///   (u, v) spans [u, u + 1));
    /// - `score` [-]: a pose landmark's visibility; for face and hands, the set's presence
    ///   score.
    #[derive(Debug)]
    pub(crate) struct LandmarkCsv {
        path: PathBuf,
        out: BufWriter<File>,
        line: String,
    }

    /// The header of `landmarks.csv`.
    pub(crate) const LANDMARK_HEADER: &str = "frame,t,set,index,x_px,y_px,score";

    impl LandmarkCsv {
        /// Creates the file and writes the header.
        pub(crate) fn create(path: &Path) -> crate::Result<Self> {
            let file = File::create(path).map_err(Error::io("create", path))?;
            let mut out = BufWriter::new(file);
            writeln!(out, "{LANDMARK_HEADER}").map_err(Error::io("write", path))?;
            Ok(Self {
                path: path.to_path_buf(),
                out,
                line: String::with_capacity(64),
            })
        }

        /// Appends one frame's landmarks.
        pub(crate) fn write(&mut self, frame: u64, t: f64, lm: &Landmarks) -> crate::Result<()> {
            if let Some(pose) = &lm.pose {
                for (i, p) in pose.points.iter().enumerate() {
                    self.row(frame, t, "pose", i, p.x, p.y, p.visibility)?;
                }
            }
            if let Some(face) = &lm.face {
                for (i, p) in face.points.iter().enumerate() {
                    self.row(frame, t, "face", i, p.x, p.y, face.score)?;
                }
            }
            for (h, hand) in lm.hands.iter().enumerate() {
                let set = if h == 0 { "hand0" } else { "hand1" };
                for (i, p) in hand.points.iter().enumerate() {
                    self.row(frame, t, set, i, p.x, p.y, hand.score)?;
                }
            }
            Ok(())
        }

        #[allow(clippy::too_many_arguments)]
        fn row(
            &mut self,
            frame: u64,
            t: f64,
            set: &str,
            index: usize,
            x: f64,
            y: f64,
            score: f64,
        ) -> crate::Result<()> {
            self.line.clear();
            let _ = writeln!(
                self.line,
                "{frame},{t:.6},{set},{index},{x:.2},{y:.2},{score:.4}"
            );
            self.out
                .write_all(self.line.as_bytes())
                .map_err(Error::io("write", &self.path))
        }

        /// Flushes the file.
        pub(crate) fn finish(mut self) -> crate::Result<()> {
            self.out.flush().map_err(Error::io("write", &self.path))
        }
    }

    /// Where camera images go when the user asked for them: an MJPG `.avi` video
    /// ([`VideoSink`]) or, for a path without extension, a folder of numbered PNGs
    /// (`000000.png`, ...). A video needs every frame at one size; a PNG folder does not.
    #[derive(Debug)]
    pub(crate) enum ImageSink {
        /// A PNG folder.
        Pngs {
            /// The folder.
            dir: PathBuf,
            /// Frames written.
            n: u64,
        },
        /// An MJPG `.avi` file.
        Avi(VideoSink),
    }

    impl ImageSink {
        /// Creates the sink for `path`: `.avi` → video at `fps` [1/s] (the source's nominal
        /// rate), no extension → PNG folder (created; it must not exist or be empty); other
        /// extensions are refused. `flag` names the option in the errors.
        pub(crate) fn create(path: &Path, flag: &str, fps: f64) -> crate::Result<Self> {
            match path.extension().and_then(|e| e.to_str()) {
                None => {
                    if path.exists()
                        && std::fs::read_dir(path)
                            .map_err(Error::io("list", path))?
                            .next()
                            .is_some()
                    {
                        return Err(Error::usage(
                            flag,
                            format!(
                                "{flag} {}: the folder exists and is not empty",
                                path.display()
                            ),
                        ));
                    }
                    std::fs::create_dir_all(path).map_err(Error::io("create", path))?;
                    Ok(Self::Pngs {
                        dir: path.to_path_buf(),
                        n: 0,
                    })
                }
                Some(e) if e.eq_ignore_ascii_case("avi") => {
                    if path.exists() {
                        return Err(Error::usage(
                            flag,
                            format!("{flag} {}: the file exists", path.display()),
                        ));
                    }
                    Ok(Self::Avi(
                        VideoSink::create(path, fps)
                            .with_context(|| format!("{flag} {}", path.display()))?,
                    ))
                }
                Some(_) => Err(Error::usage(
                    flag,
                    format!(
                        "{flag} {}: expected an .avi file, or a path without extension for a \
                         PNG folder",
                        path.display()
                    ),
                )),
            }
        }

        /// Appends one image.
        pub(crate) fn push(&mut self, image: &RgbImage) -> crate::Result<()> {
            match self {
                Self::Pngs { dir, n } => {
                    let p = dir.join(format!("{:06}.png", *n));
                    assess::vision::calib::write_png(image, &p)
                        .with_context(|| format!("cannot write {}", p.display()))?;
                    *n += 1;
                    Ok(())
                }
                Self::Avi(v) => {
                    if v.size().is_some_and(|s| s != (image.width, image.height)) {
                        return Err(Error::data(
                            v.path().display(),
                            format!(
                                "a video holds frames of one size, and this one is {} x {} px; \
                                 for images of several sizes write a PNG folder (a path without \
                                 extension)",
                                image.width, image.height
                            ),
                        ));
                    }
                    Ok(v.write(image)?)
                }
            }
        }

        /// Closes the sink (a video's index is written here).
        pub(crate) fn finish(self) -> crate::Result<()> {
            match self {
                Self::Pngs { .. } => Ok(()),
                Self::Avi(v) => Ok(v.finish()?),
            }
        }
    }

    /// Draws the monitoring view on a copy of the frame: landmarks, the workspace areas
    /// projected with the extrinsics (the confirmed area highlighted), the head ray and the
    /// live indicator values.
    pub(crate) fn annotate(
        frame: &CameraFrame,
        p: &Perceived,
        extrinsics: &Extrinsics,
        workspace: &Workspace,
        a: Option<&Assessment>,
    ) -> crate::Result<RgbImage> {
        let mut img = frame.color.clone();
        let proj = draw::Projector::new(p.intrinsics, extrinsics);
        draw::areas(&mut img, &proj, workspace, a.and_then(|a| a.confirmed))?;
        draw::landmarks(&mut img, &p.landmarks)?;
        if let Some(head) = &p.cues.frame.head {
            draw::head_ray(&mut img, &proj, &head.position, &head.facing, 0.8)?;
        }
        let name = |id: Option<assess::AreaId>| {
            id.and_then(|i| workspace.areas().get(i.0))
                .map_or("none", |a| a.name.as_str())
        };
        let mut lines = vec![format!(
            "t {:.3} s  frame {}  cues: {}",
            frame.t,
            frame.index,
            p.cues.quality.name()
        )];
        if let Some(a) = a {
            let w = &a.windowed;
            lines.push(format!(
                "F {}  (perceptual {}, action {})",
                name(a.confirmed),
                name(a.perceptual.0),
                name(a.action.0)
            ));
            lines.push(format!(
                "AED {:.2}  TID {:.2}  ICD {:.2}  ASD {:.2}/s  OHD {:.2}",
                w.aed, w.tid, w.icd, w.asd_ctx, w.ohd
            ));
            lines.push(format!(
                "HRC-CWL {:.2} ({})  dominant {}",
                w.hrc_cwl,
                w.category.name(),
                a.dominant.indicator.map_or("none", |i| i.name())
            ));
        }
        draw::text_lines(&mut img, &lines, draw::WHITE)?;
        Ok(img)
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
        let bag = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("data/bag/synthetic_plane.bag");
        let opened = open_source(&CueInput::Bag(bag), &CameraArgs::default(), None).unwrap();
        assert!(opened.own_intrinsics);
        let arg = parse_intrinsics("600,610,320,240").unwrap();
        let e = opened
            .intrinsics_override(Some(arg))
            .unwrap_err()
            .to_string();
        assert!(e.contains("its own calibrated intrinsics"), "{e}");
        assert!(opened.intrinsics_override(None).unwrap().is_none());
    }

    #[cfg(feature = "vision")]
    #[test]
    fn fixed_intrinsics_take_the_frame_size_and_refuse_another() {
        let arg = parse_intrinsics("600,610,320,240").unwrap();
        let mut fixed = FixedIntrinsics::new(arg);
        let k = fixed.at(0, 640, 480).unwrap();
        assert_eq!(
            (k.width, k.height, k.fx, k.fy, k.cx, k.cy),
            (640, 480, 600.0, 610.0, 320.0, 240.0)
        );
        assert_eq!(fixed.at(1, 640, 480).unwrap(), k);
        let e = fixed.at(2, 320, 240).unwrap_err().to_string();
        assert!(
            e.starts_with("frame 2 is 320 x 240 px but the first frame was 640 x 480 px"),
            "{e}"
        );
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
