//! Frame sources: where [`CameraFrame`]s come from.
//!
//! Every source yields frames with strictly increasing camera timestamps and ends with
//! `Ok(None)`. A frame that cannot be decoded is an error naming the source and the frame.

use std::path::{Path, PathBuf};

use super::frame::CameraFrame;
use crate::{AssessError, Result};

/// A stream of camera frames.
pub trait FrameSource {
    /// The next frame, `Ok(None)` at the end of a recording (live sources never end).
    fn next_frame(&mut self) -> Result<Option<CameraFrame>>;

    /// A one-line description for logs ("RealSense D435i 123456", "video run3.mp4 (30 fps)").
    fn describe(&self) -> String;

    /// Whether frames carry depth (false: cues are 2-D-only, see `CueQuality`).
    fn has_depth(&self) -> bool;
}

pub mod capture;
pub mod folder;
#[cfg(feature = "realsense")]
pub mod realsense;

use capture::{VideoFileOptions, VideoFileSource, WebcamOptions, WebcamSource};
use folder::{ImageFolderOptions, ImageFolderSource};

/// A frame source, as a user names it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SourceSpec {
    /// A video file (`.mp4 .avi .mkv .mov`), with an optional aligned 16-bit depth PNG folder
    /// ([`capture::DepthSequence`]).
    Video {
        /// The file.
        path: PathBuf,
        /// The depth folder.
        depth: Option<PathBuf>,
    },
    /// A folder of images (frames in file-name order), with an optional depth folder.
    Images {
        /// The folder.
        path: PathBuf,
        /// The depth folder.
        depth: Option<PathBuf>,
    },
    /// A RealSense `.bag` recording (feature `realsense`).
    Bag(PathBuf),
    /// The first RealSense camera (feature `realsense`), else webcam 0.
    Camera,
    /// The N-th webcam (`/dev/videoN`).
    Webcam {
        /// Device number (`/dev/videoN`).
        device: u32,
        /// Requested frame size (width, height) [px]; the driver may pick another.
        size: Option<(u32, u32)>,
    },
}

/// An opened frame source, its nominal frame rate and, when known, how many frames it holds.
pub struct OpenedSource {
    /// The source.
    pub source: Box<dyn FrameSource>,
    /// The number of frames, for recordings that know it.
    pub len: Option<u64>,
    /// The source's nominal frame rate [1/s] (the container's, the folder's, the driver's);
    /// the rate of a video written from its frames.
    pub fps: f64,
    /// Whether the source carries its own calibrated intrinsics (RealSense cameras and `.bag`
    /// files), which a user's intrinsics must not override.
    pub own_intrinsics: bool,
}

impl std::fmt::Debug for OpenedSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OpenedSource")
            .field("source", &self.source.describe())
            .field("len", &self.len)
            .field("fps", &self.fps)
            .field("own_intrinsics", &self.own_intrinsics)
            .finish()
    }
}

/// Opens the source `spec` names. Sources without their own calibration get intrinsics from
/// the horizontal field of view `hfov_deg` [deg] for each frame's size (a depth folder's
/// `depth.toml` may give them instead).
pub fn open(spec: &SourceSpec, hfov_deg: f64) -> Result<OpenedSource> {
    Ok(match spec {
        SourceSpec::Video { path, depth } => {
            let source = VideoFileSource::open(
                path,
                VideoFileOptions {
                    intrinsics: None,
                    hfov_deg,
                    fps: None,
                    depth: depth.clone(),
                },
            )?;
            let (len, fps) = (source.frame_count(), source.fps());
            OpenedSource {
                source: Box::new(source),
                len,
                fps,
                own_intrinsics: false,
            }
        }
        SourceSpec::Images { path, depth } => {
            let source = ImageFolderSource::open(
                path,
                ImageFolderOptions {
                    hfov_deg,
                    depth: depth.clone(),
                    ..ImageFolderOptions::default()
                },
            )?;
            let (len, fps) = (Some(source.files().len() as u64), source.fps());
            OpenedSource {
                source: Box::new(source),
                len,
                fps,
                own_intrinsics: false,
            }
        }
        SourceSpec::Bag(path) => open_bag(path)?,
        SourceSpec::Camera => open_camera(hfov_deg)?,
        SourceSpec::Webcam { device, size } => open_webcam(*device, *size, hfov_deg)?,
    })
}

fn open_webcam(device: u32, size: Option<(u32, u32)>, hfov_deg: f64) -> Result<OpenedSource> {
    let source = WebcamSource::open(
        device,
        WebcamOptions {
            size,
            hfov_deg,
            ..WebcamOptions::default()
        },
    )?;
    Ok(OpenedSource {
        fps: source.fps(),
        source: Box::new(source),
        len: None,
        own_intrinsics: false,
    })
}

#[cfg(feature = "realsense")]
fn open_bag(path: &Path) -> Result<OpenedSource> {
    Ok(OpenedSource {
        source: Box::new(realsense::RealSenseSource::open_bag(path)?),
        len: None,
        fps: capture::DEFAULT_FPS,
        own_intrinsics: true,
    })
}

#[cfg(not(feature = "realsense"))]
fn open_bag(path: &Path) -> Result<OpenedSource> {
    Err(AssessError::Source {
        source_name: path.display().to_string(),
        message: "RealSense .bag files need the `realsense` feature; this build lacks it \
                  (cargo build --release --features realsense, with librealsense2 from \
                  scripts/setup)"
            .into(),
    })
}

/// The first RealSense device (feature `realsense`), else webcam 0; an error naming both when
/// neither is there.
fn open_camera(hfov_deg: f64) -> Result<OpenedSource> {
    #[cfg(feature = "realsense")]
    let realsense_note = {
        use realsense::{RealSenseConfig, RealSenseSource, list_devices};
        match list_devices() {
            Ok(devices) if !devices.is_empty() => {
                let config = RealSenseConfig::default();
                let source = RealSenseSource::open_camera(&config)?;
                return Ok(OpenedSource {
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
    open_webcam(0, None, hfov_deg).map_err(|e| AssessError::Source {
        source_name: "camera".into(),
        message: format!(
            "found no camera: {realsense_note}, and webcam 0 cannot be opened ({e}); connect a \
             camera, or pass a recording"
        ),
    })
}
