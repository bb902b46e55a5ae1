//! Intel RealSense cameras (D435i) and `.bag` recordings (feature `realsense`).
//!
//! [`RealSenseSource`] streams colour (RGB8) and depth (Z16) through librealsense2's pipeline,
//! from a live camera ([`RealSenseSource::open_camera`]) or a `.bag` file
//! ([`RealSenseSource::open_bag`]), and yields [`CameraFrame`]s:
//!
//! - **Depth is aligned to colour here**, not by librealsense2's `align` block: each depth
//!   pixel's corners are deprojected with the depth intrinsics at its depth, moved into the
//!   colour camera with the device's depth → colour extrinsics, projected with the colour
//!   intrinsics, and the colour pixels between them get the point's colour-camera z (the nearest
//!   surface wins where several land) — librealsense2's own algorithm (`align_z_to_other`).
//!   The align block only aligns the depth frame the pipeline's syncer happened to put next to
//!   a colour frame, and in `.bag` playback the syncer sometimes pairs a colour frame with the
//!   *next* depth frame; aligning ourselves lets us pair each colour frame with the depth frame
//!   of the same timestamp (within half a frame period). Distortion is not modelled: the D435i
//!   reports zero coefficients for both streams, and a stream with non-zero ones is refused.
//! - **Depth scale** [m per unit] is the depth sensor's `DEPTH_UNITS` option (0.001 on a
//!   D435i by default), read once when the stream starts.
//! - **Intrinsics** are the colour stream's (fx, fy, ppx, ppy). The D435i colour stream is
//!   rectified with (inverse) Brown–Conrady coefficients that are zero, so the pinhole model of
//!   [`Intrinsics`] is exact.
//! - **Time**: [`CameraFrame::t`] is the colour frame's camera timestamp [ms] / 1000 [s]. The
//!   pipeline's frame syncer hands out the same colour frame more than once (once per new depth
//!   frame); a colour frame whose timestamp does not increase is skipped and counted
//!   ([`RealSenseSource::skipped_duplicates`]), so `t` is strictly increasing. A colour frame
//!   with no depth frame within half a frame period gets `depth: None` and is counted
//!   ([`RealSenseSource::frames_without_depth`]).
//! - **`.bag` playback** is not real time: librealsense2 waits for each frame to be consumed, so
//!   no frame is dropped however slow the consumer is. The end of the file is `Ok(None)`.
//!
//! realsense-rust 1.3 does not expose the playback device (real-time switch, status), so this
//! module declares those few librealsense2 C functions itself (see `playback`); they are in the
//! same library realsense-sys links.
//!
//! ```no_run
//! use assess::vision::FrameSource;
//! use assess::vision::source::realsense::{RealSenseConfig, RealSenseSource, list_devices};
//!
//! for device in list_devices()? {
//!     println!("{device}");
//! }
//! let mut camera = RealSenseSource::open_camera(&RealSenseConfig::default())?;
//! let frame = camera.next_frame()?.expect("live cameras never end");
//! if let Some(depth) = &frame.depth {
//!     let (u, v) = (320, 240);
//!     if let Some(z) = depth.depth_m(u, v) {
//!         let p = frame.intrinsics.deproject(f64::from(u), f64::from(v), z);
//!         println!("t = {:.3} s: the image centre is at {p} [m]", frame.t);
//!     }
//! }
//! # Ok::<(), assess::AssessError>(())
//! ```

use std::collections::{HashSet, VecDeque};
use std::ffi::CString;
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use realsense_rust::base::Rs2Intrinsics;
use realsense_rust::config::Config;
use realsense_rust::context::Context;
use realsense_rust::device::Device;
use realsense_rust::frame::{ColorFrame, CompositeFrame, DepthFrame, PixelKind};
use realsense_rust::kind::{Rs2CameraInfo, Rs2Format, Rs2Option, Rs2StreamKind};
use realsense_rust::pipeline::{ActivePipeline, FrameWaitError, InactivePipeline};
use realsense_rust::prelude::FrameEx;

use super::FrameSource;
use nalgebra::{Matrix3, Point3, Vector3};

use crate::vision::frame::{CameraFrame, DepthImage, Intrinsics, RgbImage};
use crate::{AssessError, Result};

/// How long one wait for a frame lasts before a `.bag` source checks whether playback ended [s].
const BAG_POLL: Duration = Duration::from_millis(200);
/// How long a `.bag` source waits for a frame while playback still runs before giving up [s].
const BAG_STALL: Duration = Duration::from_secs(10);
/// How long a live camera may stay silent before `next_frame` fails [s].
const LIVE_TIMEOUT: Duration = Duration::from_secs(5);

/// Stream settings for a live camera.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RealSenseConfig {
    /// The camera's serial number; `None` takes the first camera found.
    pub serial: Option<String>,
    /// Colour and depth width [px] (depth is aligned to colour, so both are streamed at this size).
    pub width: u32,
    /// Colour and depth height [px].
    pub height: u32,
    /// Frame rate [frames/s].
    pub fps: u32,
}

impl Default for RealSenseConfig {
    /// 640 × 480 px at 30 frames/s, the first camera found.
    fn default() -> Self {
        Self {
            serial: None,
            width: 640,
            height: 480,
            fps: 30,
        }
    }
}

/// A connected RealSense device, as [`list_devices`] reports it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceInfo {
    /// Product name ("Intel RealSense D435I").
    pub name: String,
    /// Serial number (what [`RealSenseConfig::serial`] selects).
    pub serial: String,
    /// Firmware version, when the device reports it.
    pub firmware: Option<String>,
    /// USB type ("3.2"), when the device reports it; 2.x ports limit the streams.
    pub usb: Option<String>,
}

impl fmt::Display for DeviceInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} (serial {}", self.name, self.serial)?;
        if let Some(fw) = &self.firmware {
            write!(f, ", firmware {fw}")?;
        }
        if let Some(usb) = &self.usb {
            write!(f, ", USB {usb}")?;
        }
        write!(f, ")")
    }
}

fn info(device: &Device, what: Rs2CameraInfo) -> Option<String> {
    device.info(what).map(|s| s.to_string_lossy().into_owned())
}

fn device_info(device: &Device) -> DeviceInfo {
    DeviceInfo {
        name: info(device, Rs2CameraInfo::Name).unwrap_or_else(|| "RealSense device".into()),
        serial: info(device, Rs2CameraInfo::SerialNumber).unwrap_or_else(|| "?".into()),
        firmware: info(device, Rs2CameraInfo::FirmwareVersion),
        usb: info(device, Rs2CameraInfo::UsbTypeDescriptor),
    }
}

fn source_error(source_name: &str, message: impl Into<String>) -> AssessError {
    AssessError::Source {
        source_name: source_name.to_string(),
        message: message.into(),
    }
}

fn new_context(source_name: &str) -> Result<Context> {
    Context::new().map_err(|e| {
        source_error(
            source_name,
            format!("cannot create a librealsense2 context: {e}"),
        )
    })
}

/// The RealSense devices connected now (empty when there are none).
///
/// # Errors
/// [`AssessError::Source`] when librealsense2 cannot create its context.
pub fn list_devices() -> Result<Vec<DeviceInfo>> {
    let context = new_context("realsense")?;
    Ok(context
        .query_devices(HashSet::new())
        .iter()
        .map(device_info)
        .collect())
}

fn connected_list(devices: &[DeviceInfo]) -> String {
    if devices.is_empty() {
        "none".to_string()
    } else {
        devices
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Frames from a RealSense camera or a `.bag` recording; see the [module docs](self).
pub struct RealSenseSource {
    /// What the user named: the serial (or "realsense") or the `.bag` path.
    name: String,
    /// A one-line description for logs.
    description: String,
    pipeline: ActivePipeline,
    /// Depth → colour geometry for the alignment.
    aligner: Aligner,
    /// The playback device of a `.bag` source (`None` for cameras).
    playback: Option<playback::Playback>,
    /// Whether this is a `.bag` source.
    is_bag: bool,
    intrinsics: Intrinsics,
    depth_scale_m: f64,
    /// Half the nominal frame period [ms]: the largest colour–depth timestamp gap of a pair.
    pair_tolerance_ms: f64,
    /// Timestamp of the newest colour frame taken from the pipeline [ms].
    last_color_ms: Option<f64>,
    /// Timestamp of the newest depth frame taken from the pipeline [ms].
    last_depth_ms: Option<f64>,
    /// Colour frames waiting for their depth frame, oldest first.
    pending: VecDeque<PendingColor>,
    /// Recent depth frames, oldest first.
    depths: VecDeque<RawDepth>,
    next_index: u64,
    skipped_duplicates: u64,
    frames_without_depth: u64,
    ended: bool,
}

impl fmt::Debug for RealSenseSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("RealSenseSource")
            .field("description", &self.description)
            .field("intrinsics", &self.intrinsics)
            .field("depth_scale_m", &self.depth_scale_m)
            .field("next_index", &self.next_index)
            .finish_non_exhaustive()
    }
}

impl RealSenseSource {
    /// Opens a live camera: colour RGB8 and depth Z16 at `config`'s size [px] and rate
    /// [frames/s], on the camera with `config.serial` or the first one found.
    ///
    /// # Errors
    /// [`AssessError::Source`] when no (matching) camera is connected — the message lists the
    /// connected ones — or the camera cannot stream the requested profile.
    pub fn open_camera(config: &RealSenseConfig) -> Result<Self> {
        let name = config
            .serial
            .clone()
            .unwrap_or_else(|| "realsense".to_string());
        let context = new_context(&name)?;
        let devices: Vec<DeviceInfo> = context
            .query_devices(HashSet::new())
            .iter()
            .map(device_info)
            .collect();
        let chosen = match &config.serial {
            Some(serial) => devices.iter().find(|d| &d.serial == serial),
            None => devices.first(),
        };
        let Some(chosen) = chosen.cloned() else {
            let wanted = match &config.serial {
                Some(serial) => format!("no RealSense device with serial {serial} found"),
                None => "no RealSense device found".to_string(),
            };
            return Err(source_error(
                &name,
                format!("{wanted}; connected: {}", connected_list(&devices)),
            ));
        };
        let serial = CString::new(chosen.serial.clone()).map_err(|_| {
            source_error(
                &name,
                format!("serial {:?} contains a NUL byte", chosen.serial),
            )
        })?;
        let mut rs_config = Config::new();
        let (w, h, fps) = (
            config.width as usize,
            config.height as usize,
            config.fps as usize,
        );
        rs_config
            .enable_device_from_serial(&serial)
            .and_then(|c| c.enable_stream(Rs2StreamKind::Color, None, w, h, Rs2Format::Rgb8, fps))
            .and_then(|c| c.enable_stream(Rs2StreamKind::Depth, None, w, h, Rs2Format::Z16, fps))
            .map_err(|e| source_error(&name, format!("cannot configure {chosen}: {e}")))?;
        let pipeline = InactivePipeline::try_from(&context)
            .map_err(|e| source_error(&name, format!("cannot create a pipeline: {e}")))?;
        let pipeline = pipeline.start(Some(rs_config)).map_err(|e| {
            source_error(
                &name,
                format!(
                    "cannot start {chosen} with colour RGB8 and depth Z16 at {}x{} px, {} fps: {e}",
                    config.width, config.height, config.fps
                ),
            )
        })?;
        let description = format!(
            "RealSense {} {} ({}x{} px, {} fps)",
            chosen.name, chosen.serial, config.width, config.height, config.fps
        );
        Self::from_pipeline(name, description, pipeline, false)
    }

    /// Opens a `.bag` recording (made by the RealSense Viewer, `rs-record`, or a recorder) for
    /// non-real-time playback of its colour and depth streams.
    ///
    /// # Errors
    /// [`AssessError::Source`] (`cannot open bag …`) when the file is missing, is not a
    /// RealSense recording, or has no colour and depth streams.
    pub fn open_bag(path: impl AsRef<Path>) -> Result<Self> {
        let path: PathBuf = path.as_ref().to_path_buf();
        let name = path.display().to_string();
        let cannot = |why: String| source_error(&name, format!("cannot open bag {name}: {why}"));
        if !path.is_file() {
            return Err(cannot("no such file".to_string()));
        }
        let context = new_context(&name)?;
        let mut rs_config = Config::new();
        rs_config
            .enable_device_from_file(&path, false)
            .map_err(|e| cannot(e.to_string()))?;
        rs_config
            .enable_stream(Rs2StreamKind::Color, None, 0, 0, Rs2Format::Any, 0)
            .and_then(|c| c.enable_stream(Rs2StreamKind::Depth, None, 0, 0, Rs2Format::Any, 0))
            .map_err(|e| cannot(e.to_string()))?;
        let pipeline = InactivePipeline::try_from(&context)
            .map_err(|e| cannot(format!("cannot create a pipeline: {e}")))?;
        let pipeline = pipeline
            .start(Some(rs_config))
            .map_err(|e| cannot(format!("{e} (does it hold a colour and a depth stream?)")))?;
        let description = format!("RealSense recording {name}");
        let mut source = Self::from_pipeline(name, description, pipeline, true)?;
        // Switch the playback to non-real-time now, not at the first `next_frame`: a caller
        // that loads models between opening and reading (half a second) would otherwise find
        // the whole recording played past in real time.
        while source.playback.is_none() && !source.ended {
            match source.wait_frameset()? {
                Some(frames) => source.ingest(&frames)?,
                None => source.ended = true,
            }
        }
        Ok(source)
    }

    /// Reads what every source needs from a started pipeline.
    fn from_pipeline(
        name: String,
        description: String,
        pipeline: ActivePipeline,
        is_bag: bool,
    ) -> Result<Self> {
        let profile = pipeline.profile();
        let color = profile
            .streams()
            .iter()
            .find(|s| s.kind() == Rs2StreamKind::Color)
            .ok_or_else(|| source_error(&name, "the device has no colour stream"))?;
        let color_format = color.format();
        if !matches!(
            color_format,
            Rs2Format::Rgb8 | Rs2Format::Bgr8 | Rs2Format::Rgba8 | Rs2Format::Bgra8
        ) {
            return Err(source_error(
                &name,
                format!(
                    "colour format {color_format:?} is not supported (RGB8, BGR8, RGBA8, BGRA8 are)"
                ),
            ));
        }
        let fps = color.framerate();
        let ci = color
            .intrinsics()
            .map_err(|e| source_error(&name, format!("cannot read the colour intrinsics: {e}")))?;
        let intrinsics = pinhole(&ci, "colour", &name)?;
        let depth = profile
            .streams()
            .iter()
            .find(|s| s.kind() == Rs2StreamKind::Depth)
            .ok_or_else(|| source_error(&name, "the device has no depth stream"))?;
        if depth.format() != Rs2Format::Z16 {
            return Err(source_error(
                &name,
                format!(
                    "depth format {:?} is not supported (Z16 is)",
                    depth.format()
                ),
            ));
        }
        let di = depth
            .intrinsics()
            .map_err(|e| source_error(&name, format!("cannot read the depth intrinsics: {e}")))?;
        let depth_intrinsics = pinhole(&di, "depth", &name)?;
        let ext = depth.extrinsics(color).map_err(|e| {
            source_error(
                &name,
                format!("cannot read the depth-to-colour extrinsics: {e}"),
            )
        })?;
        // librealsense2 stores the rotation column-major.
        let r = ext.rotation().map(f64::from);
        let t = ext.translation().map(f64::from);
        let aligner = Aligner {
            depth: depth_intrinsics,
            color: intrinsics,
            rotation: Matrix3::from_column_slice(&r),
            translation: Vector3::new(t[0], t[1], t[2]),
        };
        // The depth sensor is the one with a DEPTH_UNITS option.
        let depth_scale_m = profile
            .device()
            .sensors()
            .iter()
            .find_map(|s| s.get_option(Rs2Option::DepthUnits))
            .map(f64::from)
            .filter(|s| s.is_finite() && *s > 0.0)
            .ok_or_else(|| {
                source_error(
                    &name,
                    "the device reports no depth scale (DEPTH_UNITS option)",
                )
            })?;
        Ok(Self {
            name,
            description,
            pipeline,
            aligner,
            playback: None,
            is_bag,
            intrinsics,
            depth_scale_m,
            pair_tolerance_ms: if fps > 0 {
                500.0 / f64::from(fps)
            } else {
                500.0 / 30.0
            },
            last_color_ms: None,
            last_depth_ms: None,
            pending: VecDeque::new(),
            depths: VecDeque::new(),
            next_index: 0,
            skipped_duplicates: 0,
            frames_without_depth: 0,
            ended: false,
        })
    }

    /// The colour camera's intrinsics (those of every frame).
    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    /// Metres per depth unit [m] (the device's depth scale).
    pub fn depth_scale_m(&self) -> f64 {
        self.depth_scale_m
    }

    /// Framesets skipped because their colour timestamp did not increase.
    pub fn skipped_duplicates(&self) -> u64 {
        self.skipped_duplicates
    }

    /// Frames handed out without depth (no depth frame within half a frame period).
    pub fn frames_without_depth(&self) -> u64 {
        self.frames_without_depth
    }

    /// The next frameset from the pipeline; `None` at the end of a `.bag` file.
    fn wait_frameset(&mut self) -> Result<Option<CompositeFrame>> {
        if !self.is_bag {
            return self
                .pipeline
                .wait(Some(LIVE_TIMEOUT))
                .map(Some)
                .map_err(|e| source_error(&self.name, format!("no frame from the camera: {e}")));
        }
        let started = Instant::now();
        loop {
            match self.pipeline.wait(Some(BAG_POLL)) {
                Ok(frames) => return Ok(Some(frames)),
                Err(FrameWaitError::DidTimeoutBeforeFrameArrival) => {
                    // Before the first frame there is no playback handle yet, so the end of
                    // the file can only be seen after it.
                    if let Some(p) = &self.playback
                        && p.is_stopped(&self.name)?
                    {
                        return Ok(None);
                    }
                    if started.elapsed() >= BAG_STALL {
                        return Err(source_error(
                            &self.name,
                            format!(
                                "playback stalled: no frame for {} s and the file has not ended",
                                BAG_STALL.as_secs()
                            ),
                        ));
                    }
                }
                Err(e) => {
                    return Err(source_error(
                        &self.name,
                        format!("cannot read a frame: {e}"),
                    ));
                }
            }
        }
    }
}

/// How many colour frames may wait for depth, and depth frames for colour.
const MAX_QUEUED: usize = 4;

/// A colour frame waiting for its depth frame.
#[derive(Debug)]
struct PendingColor {
    /// Camera timestamp [ms].
    t_ms: f64,
    image: RgbImage,
}

/// A depth frame as streamed (depth camera's pixel grid).
#[derive(Debug)]
struct RawDepth {
    /// Camera timestamp [ms].
    t_ms: f64,
    image: DepthImage,
}

/// Pinhole intrinsics of a stream; refuses non-zero distortion coefficients.
fn pinhole(i: &Rs2Intrinsics, stream: &str, name: &str) -> Result<Intrinsics> {
    let coeffs = i.distortion().coeffs;
    if coeffs.iter().any(|k| k.abs() > 1e-6) {
        return Err(source_error(
            name,
            format!(
                "the {stream} stream has distortion coefficients {coeffs:?}; only undistorted streams are supported"
            ),
        ));
    }
    let out = Intrinsics {
        width: u32::try_from(i.width()).unwrap_or(0),
        height: u32::try_from(i.height()).unwrap_or(0),
        fx: f64::from(i.fx()),
        fy: f64::from(i.fy()),
        cx: f64::from(i.ppx()),
        cy: f64::from(i.ppy()),
    };
    if out.width == 0 || out.height == 0 || !(out.fx > 0.0 && out.fy > 0.0) {
        return Err(source_error(
            name,
            format!("the {stream} stream has unusable intrinsics {out:?}"),
        ));
    }
    Ok(out)
}

/// Depth → colour alignment (librealsense2's `align_z_to_other`, with colour-camera z).
#[derive(Debug, Clone, Copy)]
struct Aligner {
    /// Depth stream intrinsics.
    depth: Intrinsics,
    /// Colour stream intrinsics (the output grid).
    color: Intrinsics,
    /// Rotation depth → colour [-].
    rotation: Matrix3<f64>,
    /// Translation depth → colour [m].
    translation: Vector3<f64>,
}

impl Aligner {
    /// The colour pixel (column, row) nearest to where a depth-camera point [m] projects.
    fn color_px(&self, p_depth: &Point3<f64>) -> Option<(i64, i64, f64)> {
        let p = self.rotation * p_depth.coords + self.translation;
        let (u, v) = self.color.project(&Point3::from(p))?;
        Some(((u + 0.5).floor() as i64, (v + 0.5).floor() as i64, p.z))
    }

    /// `depth` (depth camera grid) resampled onto the colour grid.
    fn align(&self, depth: &DepthImage) -> DepthImage {
        let (cw, ch) = (self.color.width as usize, self.color.height as usize);
        let mut out = vec![0u16; cw * ch];
        let scale = depth.scale_m;
        for dv in 0..depth.height {
            for du in 0..depth.width {
                let raw = depth.data[dv as usize * depth.width as usize + du as usize];
                if raw == 0 {
                    continue;
                }
                let z = f64::from(raw) * scale;
                let (u, v) = (f64::from(du), f64::from(dv));
                let corner0 = self.depth.deproject(u - 0.5, v - 0.5, z);
                let corner1 = self.depth.deproject(u + 0.5, v + 0.5, z);
                let (Some((u0, v0, _)), Some((u1, v1, _))) =
                    (self.color_px(&corner0), self.color_px(&corner1))
                else {
                    continue;
                };
                let (x0, x1, y0, y1) = (u0.min(u1), u0.max(u1), v0.min(v1), v0.max(v1));
                if x0 < 0 || y0 < 0 || x1 >= cw as i64 || y1 >= ch as i64 {
                    continue;
                }
                // The pixel centre's z in the colour camera, in depth units.
                let Some((_, _, zc)) = self.color_px(&self.depth.deproject(u, v, z)) else {
                    continue;
                };
                let units = (zc / scale).round().clamp(1.0, f64::from(u16::MAX)) as u16;
                for y in y0..=y1 {
                    for x in x0..=x1 {
                        let cell = &mut out[y as usize * cw + x as usize];
                        if *cell == 0 || units < *cell {
                            *cell = units;
                        }
                    }
                }
            }
        }
        DepthImage {
            width: self.color.width,
            height: self.color.height,
            data: out,
            scale_m: scale,
        }
    }
}

/// The RGB8 pixels of a colour frame.
fn color_image(frame: &ColorFrame, name: &str, index: u64) -> Result<RgbImage> {
    let (w, h) = (frame.width(), frame.height());
    let mut data = Vec::with_capacity(w * h * 3);
    for row in 0..h {
        for col in 0..w {
            // realsense-rust 1.3 returns `PixelKind::Bgr8` for RGB8 frames (and `Bgra8` for
            // RGBA8) although the bytes are R, G, B: the variant's name is wrong, but its `r`,
            // `g`, `b` fields point at the right bytes for both RGB8 and BGR8 frames. So we read
            // the fields by name and never rely on the variant (the synthetic-bag test checks a
            // pure red patch).
            match frame.get(col, row) {
                Some(
                    PixelKind::Bgr8 { r, g, b }
                    | PixelKind::Rgb8 { r, g, b }
                    | PixelKind::Bgra8 { r, g, b, .. }
                    | PixelKind::Rgba8 { r, g, b, .. },
                ) => data.extend_from_slice(&[*r, *g, *b]),
                _ => {
                    return Err(source_error(
                        name,
                        format!("frame {index}: colour pixel ({col}, {row}) is not RGB/BGR"),
                    ));
                }
            }
        }
    }
    Ok(RgbImage {
        width: u32::try_from(w).unwrap_or(0),
        height: u32::try_from(h).unwrap_or(0),
        data,
    })
}

/// Raw Z16 units of an (aligned) depth frame.
fn depth_image(frame: &DepthFrame, scale_m: f64, name: &str, index: u64) -> Result<DepthImage> {
    let (w, h) = (frame.width(), frame.height());
    let mut data = Vec::with_capacity(w * h);
    for row in 0..h {
        for col in 0..w {
            match frame.get(col, row) {
                Some(PixelKind::Z16 { depth }) => data.push(*depth),
                _ => {
                    return Err(source_error(
                        name,
                        format!("frame {index}: depth pixel ({col}, {row}) is not Z16"),
                    ));
                }
            }
        }
    }
    Ok(DepthImage {
        width: u32::try_from(w).unwrap_or(0),
        height: u32::try_from(h).unwrap_or(0),
        data,
        scale_m,
    })
}

impl RealSenseSource {
    /// Takes a frameset's new colour and depth frames into the queues.
    fn ingest(&mut self, frames: &CompositeFrame) -> Result<()> {
        if self.is_bag && self.playback.is_none() {
            // The first frameset leads to the playback device. It started in real time, where
            // frames a slow consumer misses are dropped: switch it to non-real-time and go
            // back to the start, so every frame is played (again) and waits for us. The
            // frames seen twice are skipped as duplicates.
            let Some(frame) = frames.frames_of_type::<ColorFrame>().into_iter().next() else {
                return Ok(()); // a depth-only frameset: it will be played again
            };
            let playback = playback::Playback::from_frame(frame, &self.name)?;
            playback.set_real_time(false, &self.name)?;
            playback.seek_to_start(&self.name)?;
            self.playback = Some(playback);
        }
        let index = self.next_index + self.pending.len() as u64;
        for depth in frames.frames_of_type::<DepthFrame>() {
            let t_ms = depth.timestamp();
            if !t_ms.is_finite() || self.last_depth_ms.is_some_and(|last| t_ms <= last) {
                continue; // the syncer repeats depth frames too
            }
            self.last_depth_ms = Some(t_ms);
            let raw = depth_image(&depth, self.depth_scale_m, &self.name, index)?;
            self.depths.push_back(RawDepth { t_ms, image: raw });
            while self.depths.len() > MAX_QUEUED {
                self.depths.pop_front();
            }
        }
        for color in frames.frames_of_type::<ColorFrame>() {
            let t_ms = color.timestamp();
            if !t_ms.is_finite() || self.last_color_ms.is_some_and(|last| t_ms <= last) {
                self.skipped_duplicates += 1;
                continue;
            }
            self.last_color_ms = Some(t_ms);
            let image = color_image(&color, &self.name, index)?;
            if image.width != self.intrinsics.width || image.height != self.intrinsics.height {
                return Err(source_error(
                    &self.name,
                    format!(
                        "frame {index}: colour image is {}x{} px, the stream's intrinsics say {}x{}",
                        image.width, image.height, self.intrinsics.width, self.intrinsics.height
                    ),
                ));
            }
            self.pending.push_back(PendingColor { t_ms, image });
        }
        Ok(())
    }

    /// The oldest pending colour frame with its aligned depth, if it can be decided now: its
    /// depth frame has arrived, or a later one has (so it never will), or the input has ended,
    /// or too many colour frames wait.
    fn take_ready(&mut self, input_ended: bool) -> Option<CameraFrame> {
        let front = self.pending.front()?;
        let tol = self.pair_tolerance_ms;
        let matched = self
            .depths
            .iter()
            .position(|d| (d.t_ms - front.t_ms).abs() <= tol);
        let hopeless = self
            .depths
            .back()
            .is_some_and(|d| d.t_ms > front.t_ms + tol);
        if matched.is_none() && !hopeless && !input_ended && self.pending.len() <= MAX_QUEUED {
            return None;
        }
        let PendingColor { t_ms, image } = self.pending.pop_front()?;
        let depth = matched
            .and_then(|i| self.depths.get(i))
            .map(|d| self.aligner.align(&d.image));
        // Depth frames older than this colour frame can match no later one.
        while self.depths.front().is_some_and(|d| d.t_ms < t_ms - tol) {
            self.depths.pop_front();
        }
        if depth.is_none() {
            self.frames_without_depth += 1;
        }
        let index = self.next_index;
        self.next_index += 1;
        Some(CameraFrame {
            t: t_ms / 1000.0,
            index,
            color: image,
            depth,
            intrinsics: self.intrinsics,
        })
    }
}

impl FrameSource for RealSenseSource {
    fn next_frame(&mut self) -> Result<Option<CameraFrame>> {
        loop {
            if let Some(frame) = self.take_ready(self.ended) {
                return Ok(Some(frame));
            }
            if self.ended {
                return Ok(None);
            }
            match self.wait_frameset()? {
                Some(frames) => self.ingest(&frames)?,
                None => self.ended = true,
            }
        }
    }

    fn describe(&self) -> String {
        self.description.clone()
    }

    fn has_depth(&self) -> bool {
        true
    }
}

/// The playback device of a `.bag` source, through librealsense2's C API: realsense-rust 1.3
/// neither exposes `rs2_playback_*` nor the raw device of a pipeline, so the device is reached
/// from a frame (frame → sensor → device), as librealsense2's own wrappers do.
mod playback {
    use std::ffi::{CStr, c_char, c_int, c_uint, c_void};
    use std::ptr::NonNull;

    use realsense_rust::frame::ColorFrame;
    use realsense_rust::prelude::FrameEx;

    use super::source_error;
    use crate::Result;

    /// `RS2_EXTENSION_PLAYBACK` (rs_types.h).
    const RS2_EXTENSION_PLAYBACK: c_uint = 16;
    /// `RS2_PLAYBACK_STATUS_STOPPED` (rs_record_playback.h).
    const RS2_PLAYBACK_STATUS_STOPPED: c_uint = 3;

    // The signatures of librealsense2 2.56's C API (rs.h, rs_frame.h, rs_sensor.h, rs_device.h,
    // rs_record_playback.h), with the opaque handle types as `c_void`. The library is linked by
    // realsense-sys.
    unsafe extern "C" {
        fn rs2_get_frame_sensor(frame: *const c_void, error: *mut *mut c_void) -> *mut c_void;
        fn rs2_create_device_from_sensor(
            sensor: *const c_void,
            error: *mut *mut c_void,
        ) -> *mut c_void;
        fn rs2_delete_sensor(sensor: *mut c_void);
        fn rs2_delete_device(device: *mut c_void);
        fn rs2_release_frame(frame: *mut c_void);
        fn rs2_is_device_extendable_to(
            device: *const c_void,
            extension: c_uint,
            error: *mut *mut c_void,
        ) -> c_int;
        fn rs2_playback_device_set_real_time(
            device: *const c_void,
            real_time: c_int,
            error: *mut *mut c_void,
        );
        fn rs2_playback_device_get_current_status(
            device: *const c_void,
            error: *mut *mut c_void,
        ) -> c_uint;
        fn rs2_playback_seek(device: *const c_void, time: i64, error: *mut *mut c_void);
        fn rs2_get_error_message(error: *const c_void) -> *const c_char;
        fn rs2_free_error(error: *mut c_void);
    }

    /// Takes (and frees) a librealsense2 error: `Err(message)` if `error` is set.
    fn check(error: *mut c_void) -> std::result::Result<(), String> {
        if error.is_null() {
            return Ok(());
        }
        // SAFETY: `error` is a non-null rs2_error* that librealsense2 handed us; its message is
        // a NUL-terminated string owned by the error, copied before the error is freed.
        let message = unsafe {
            let m = rs2_get_error_message(error);
            let text = if m.is_null() {
                "unknown librealsense2 error".to_string()
            } else {
                CStr::from_ptr(m).to_string_lossy().into_owned()
            };
            rs2_free_error(error);
            text
        };
        Err(message)
    }

    /// An owned `rs2_device*` of a playback device; deleted on drop.
    #[derive(Debug)]
    pub(super) struct Playback {
        device: NonNull<c_void>,
    }

    // SAFETY: librealsense2 devices are thread-safe handles (realsense-rust's `Device` is
    // `Send` for the same reason).
    unsafe impl Send for Playback {}

    impl Drop for Playback {
        fn drop(&mut self) {
            // SAFETY: `device` came from rs2_create_device_from_sensor and is deleted once.
            unsafe { rs2_delete_device(self.device.as_ptr()) }
        }
    }

    impl Playback {
        /// The playback device that produced `frame`. The frame is consumed (released).
        pub(super) fn from_frame(frame: ColorFrame, name: &str) -> Result<Self> {
            // SAFETY: get_owned_raw hands us ownership of the frame reference, which we release
            // below; the sensor and device handles are created, checked and deleted (device:
            // on drop of `Playback`) exactly once.
            unsafe {
                let frame = frame.get_owned_raw().cast::<c_void>();
                let mut error: *mut c_void = std::ptr::null_mut();
                let sensor = rs2_get_frame_sensor(frame.as_ptr(), &mut error);
                rs2_release_frame(frame.as_ptr());
                check(error).map_err(|m| {
                    source_error(name, format!("cannot reach the playback sensor: {m}"))
                })?;
                let sensor = NonNull::new(sensor)
                    .ok_or_else(|| source_error(name, "the frame has no sensor"))?;
                let device = rs2_create_device_from_sensor(sensor.as_ptr(), &mut error);
                rs2_delete_sensor(sensor.as_ptr());
                check(error).map_err(|m| {
                    source_error(name, format!("cannot reach the playback device: {m}"))
                })?;
                let device = NonNull::new(device)
                    .ok_or_else(|| source_error(name, "the sensor has no device"))?;
                let playback = Self { device };
                let is_playback = rs2_is_device_extendable_to(
                    device.as_ptr(),
                    RS2_EXTENSION_PLAYBACK,
                    &mut error,
                );
                check(error).map_err(|m| source_error(name, m))?;
                if is_playback == 0 {
                    return Err(source_error(name, "the device is not a playback device"));
                }
                Ok(playback)
            }
        }

        /// Real-time playback (drops frames a slow consumer misses) or not (waits for them).
        pub(super) fn set_real_time(&self, real_time: bool, name: &str) -> Result<()> {
            let mut error: *mut c_void = std::ptr::null_mut();
            // SAFETY: `device` is a live playback device handle (checked in `from_frame`).
            unsafe {
                rs2_playback_device_set_real_time(
                    self.device.as_ptr(),
                    c_int::from(real_time),
                    &mut error,
                );
            }
            check(error)
                .map_err(|m| source_error(name, format!("cannot set real-time playback: {m}")))
        }

        /// Goes back to the start of the file.
        pub(super) fn seek_to_start(&self, name: &str) -> Result<()> {
            let mut error: *mut c_void = std::ptr::null_mut();
            // SAFETY: as in `set_real_time`; the time is in nanoseconds from the start.
            unsafe { rs2_playback_seek(self.device.as_ptr(), 0, &mut error) };
            check(error).map_err(|m| source_error(name, format!("cannot rewind the playback: {m}")))
        }

        /// Whether playback has stopped (the end of a non-looping file).
        pub(super) fn is_stopped(&self, name: &str) -> Result<bool> {
            let mut error: *mut c_void = std::ptr::null_mut();
            // SAFETY: as in `set_real_time`.
            let status =
                unsafe { rs2_playback_device_get_current_status(self.device.as_ptr(), &mut error) };
            check(error)
                .map_err(|m| source_error(name, format!("cannot read the playback status: {m}")))?;
            Ok(status == RS2_PLAYBACK_STATUS_STOPPED)
        }
    }
}
