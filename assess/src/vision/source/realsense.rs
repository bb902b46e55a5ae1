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
//!   a colour frame, and the syncer sometimes pairs a colour frame with the *next* depth frame;
//!   aligning ourselves lets us pair each colour frame with the depth frame nearest its
//!   timestamp (within half a frame period). Distortion is not modelled: the D435i
//!   reports zero coefficients for both streams, and a stream with non-zero ones is refused.
//! - **Depth scale** [m per unit] is the depth sensor's `DEPTH_UNITS` option (0.001 on a
//!   D435i by default), read once when the stream starts.
//! - **Intrinsics** are the colour stream's (fx, fy, ppx, ppy). The D435i colour stream is
//!   rectified with (inverse) Brown–Conrady coefficients that are zero, so the pinhole model of
//!   [`Intrinsics`] is exact.
//! - **Time**: [`CameraFrame::t`] is the colour frame's camera timestamp [ms] / 1000 [s]. A live
//!   camera's frame syncer hands out the same colour frame more than once (once per new depth
//!   frame); a colour frame whose timestamp does not increase is skipped and counted
//!   ([`RealSenseSource::skipped_duplicates`]), so `t` is strictly increasing. A colour frame
//!   with no depth frame within half a frame period gets `depth: None` and is counted
//!   ([`RealSenseSource::frames_without_depth`]).
//! - **`.bag` playback** is never real time: the file is loaded as a playback device, switched
//!   to non-real-time before it plays a frame, and its colour and depth sensors hand their
//!   frames to a bounded queue that the playback waits on, so no frame is dropped however slow
//!   the consumer is, and frames come in file order (no frame syncer). The end of the file is
//!   `Ok(None)`.
//!
//! realsense-rust 1.3 does not expose the playback device (real-time switch, status) nor raw
//! handles, so `.bag` playback is written against librealsense2's C API (realsense-sys, the
//! same library realsense-rust links; see `playback`).
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
use realsense_rust::pipeline::{ActivePipeline, InactivePipeline};
use realsense_rust::prelude::FrameEx;
use realsense_rust::stream_profile::StreamProfile;

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
    stream: Stream,
    /// Depth → colour geometry for the alignment.
    aligner: Aligner,
    intrinsics: Intrinsics,
    depth_scale_m: f64,
    /// Half the nominal frame period [ms]: the largest colour–depth timestamp gap of a pair.
    pair_tolerance_ms: f64,
    /// Timestamp of the last colour frame handed out [ms].
    last_color_ms: Option<f64>,
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
        Self::from_pipeline(name, description, Stream::Camera(pipeline))
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
        let bag = playback::BagPlayer::open(&path, cannot)?;
        let description = format!("RealSense recording {name}");
        Self::from_pipeline(name, description, Stream::Bag(bag))
    }

    /// Reads what every source needs from a started pipeline.
    fn from_pipeline(name: String, description: String, stream: Stream) -> Result<Self> {
        let setup = match &stream {
            Stream::Camera(pipeline) => {
                let profile = pipeline.profile();
                let find = |kind: Rs2StreamKind, what: &str| {
                    profile
                        .streams()
                        .iter()
                        .find(|s| s.kind() == kind)
                        .ok_or_else(|| {
                            source_error(&name, format!("the device has no {what} stream"))
                        })
                };
                StreamSetup::read(
                    &name,
                    find(Rs2StreamKind::Color, "colour")?,
                    find(Rs2StreamKind::Depth, "depth")?,
                    profile
                        .device()
                        .sensors()
                        .iter()
                        .find_map(|s| s.get_option(Rs2Option::DepthUnits)),
                )?
            }
            Stream::Bag(bag) => {
                let (color, depth) = bag.profiles(&name)?;
                StreamSetup::read(&name, &color, &depth, bag.depth_units(&name)?)?
            }
        };
        let StreamSetup {
            intrinsics,
            aligner,
            depth_scale_m,
            fps,
        } = setup;
        Ok(Self {
            name,
            description,
            stream,
            aligner,
            intrinsics,
            depth_scale_m,
            pair_tolerance_ms: if fps > 0 {
                500.0 / f64::from(fps)
            } else {
                500.0 / 30.0
            },
            last_color_ms: None,
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

    /// The next input from the camera or the file; `None` at the end of a `.bag` file.
    fn wait_input(&mut self) -> Result<Option<Input>> {
        let bag = match &mut self.stream {
            Stream::Camera(pipeline) => {
                return pipeline
                    .wait(Some(LIVE_TIMEOUT))
                    .map(|frames| Some(Input::Frames(frames)))
                    .map_err(|e| {
                        source_error(&self.name, format!("no frame from the camera: {e}"))
                    });
            }
            Stream::Bag(bag) => bag,
        };
        let started = Instant::now();
        loop {
            if let Some(input) = bag.wait(BAG_POLL, &self.name)? {
                return Ok(Some(input));
            }
            if bag.is_stopped(&self.name)? {
                // The last frames may have been queued just before the status changed.
                return bag.wait(Duration::ZERO, &self.name);
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
    }
}

/// One input of a source: a frameset from a camera's pipeline, or a single frame of a `.bag`.
enum Input {
    Frames(CompositeFrame),
    Color(ColorFrame),
    Depth(DepthFrame),
}

/// Where frames come from.
#[derive(Debug)]
enum Stream {
    /// A live camera, through realsense-rust's pipeline.
    Camera(ActivePipeline),
    /// A `.bag` file, played without dropping frames.
    Bag(playback::BagPlayer),
}

/// What a source reads once from its streams and device.
struct StreamSetup {
    /// The colour stream's intrinsics.
    intrinsics: Intrinsics,
    aligner: Aligner,
    /// [m per depth unit]
    depth_scale_m: f64,
    /// The colour stream's rate [frames/s] (0 if unknown).
    fps: i32,
}

impl StreamSetup {
    /// Checks the formats and reads intrinsics and extrinsics; `depth_units` is the depth
    /// sensor's `DEPTH_UNITS` option [m per unit].
    fn read(
        name: &str,
        color: &StreamProfile,
        depth: &StreamProfile,
        depth_units: Option<f32>,
    ) -> Result<Self> {
        let color_format = color.format();
        if !matches!(
            color_format,
            Rs2Format::Rgb8 | Rs2Format::Bgr8 | Rs2Format::Rgba8 | Rs2Format::Bgra8
        ) {
            return Err(source_error(
                name,
                format!(
                    "colour format {color_format:?} is not supported (RGB8, BGR8, RGBA8, BGRA8 are)"
                ),
            ));
        }
        let fps = color.framerate();
        let ci = color
            .intrinsics()
            .map_err(|e| source_error(name, format!("cannot read the colour intrinsics: {e}")))?;
        let intrinsics = pinhole(&ci, "colour", name)?;
        if depth.format() != Rs2Format::Z16 {
            return Err(source_error(
                name,
                format!(
                    "depth format {:?} is not supported (Z16 is)",
                    depth.format()
                ),
            ));
        }
        let di = depth
            .intrinsics()
            .map_err(|e| source_error(name, format!("cannot read the depth intrinsics: {e}")))?;
        let depth_intrinsics = pinhole(&di, "depth", name)?;
        let ext = depth.extrinsics(color).map_err(|e| {
            source_error(
                name,
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
        let depth_scale_m = depth_units
            .map(f64::from)
            .filter(|s| s.is_finite() && *s > 0.0)
            .ok_or_else(|| {
                source_error(
                    name,
                    "the device reports no depth scale (DEPTH_UNITS option)",
                )
            })?;
        Ok(Self {
            intrinsics,
            aligner,
            depth_scale_m,
            fps,
        })
    }
}

/// How many colour frames may wait for depth, and depth frames for colour.
const MAX_QUEUED: usize = 8;

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
        for depth in frames.frames_of_type::<DepthFrame>() {
            self.ingest_depth(&depth)?;
        }
        for color in frames.frames_of_type::<ColorFrame>() {
            self.ingest_color(&color)?;
        }
        Ok(())
    }

    /// Takes a depth frame into the queue, once per timestamp (the syncer repeats them).
    fn ingest_depth(&mut self, depth: &DepthFrame) -> Result<()> {
        let index = self.next_index + self.pending.len() as u64;
        let t_ms = depth.timestamp();
        let too_old = self
            .last_color_ms
            .is_some_and(|last| t_ms < last - self.pair_tolerance_ms);
        if !t_ms.is_finite() || too_old || self.depths.iter().any(|d| d.t_ms == t_ms) {
            return Ok(());
        }
        let raw = depth_image(depth, self.depth_scale_m, &self.name, index)?;
        let at = self.depths.partition_point(|d| d.t_ms < t_ms);
        self.depths.insert(at, RawDepth { t_ms, image: raw });
        while self.depths.len() > MAX_QUEUED {
            self.depths.pop_front();
        }
        Ok(())
    }

    /// Queues a colour frame to wait for its depth frame, unless its timestamp was seen.
    fn ingest_color(&mut self, color: &ColorFrame) -> Result<()> {
        let index = self.next_index + self.pending.len() as u64;
        let t_ms = color.timestamp();
        let handed_out = self.last_color_ms.is_some_and(|last| t_ms <= last);
        if !t_ms.is_finite() || handed_out || self.pending.iter().any(|c| c.t_ms == t_ms) {
            self.skipped_duplicates += 1;
            return Ok(());
        }
        let image = color_image(color, &self.name, index)?;
        if image.width != self.intrinsics.width || image.height != self.intrinsics.height {
            return Err(source_error(
                &self.name,
                format!(
                    "frame {index}: colour image is {}x{} px, the stream's intrinsics say {}x{}",
                    image.width, image.height, self.intrinsics.width, self.intrinsics.height
                ),
            ));
        }
        let at = self.pending.partition_point(|c| c.t_ms < t_ms);
        self.pending.insert(at, PendingColor { t_ms, image });
        Ok(())
    }

    /// The oldest pending colour frame with its aligned depth (the nearest in time), if it can
    /// be decided now: its depth frame has arrived, or a later one has (so it never will), or
    /// the input has ended, or too many colour frames wait.
    fn take_ready(&mut self, input_ended: bool) -> Option<CameraFrame> {
        let front = self.pending.front()?;
        let tol = self.pair_tolerance_ms;
        let matched = self
            .depths
            .iter()
            .enumerate()
            .map(|(i, d)| (i, (d.t_ms - front.t_ms).abs()))
            .filter(|&(_, dt)| dt <= tol)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i);
        let hopeless = self
            .depths
            .back()
            .is_some_and(|d| d.t_ms > front.t_ms + tol);
        if matched.is_none() && !hopeless && !input_ended && self.pending.len() <= MAX_QUEUED {
            return None;
        }
        let PendingColor { t_ms, image } = self.pending.pop_front()?;
        self.last_color_ms = Some(t_ms);
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
            match self.wait_input()? {
                Some(Input::Frames(frames)) => self.ingest(&frames)?,
                Some(Input::Color(color)) => self.ingest_color(&color)?,
                Some(Input::Depth(depth)) => self.ingest_depth(&depth)?,
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

/// `.bag` playback through librealsense2's C API (realsense-sys): realsense-rust 1.3 exposes
/// neither `rs2_playback_*` nor the raw handles of its devices and pipelines.
///
/// The file is loaded as a playback device of our own and switched to non-real-time playback
/// *before* it plays; no pipeline (and no frame syncer) is involved: the colour and depth
/// sensors are opened on their recorded profiles and started with a callback that hands each
/// frame to a bounded channel. Non-real-time playback waits for the callback, and the callback
/// waits for room in the channel, so the file plays as fast as it is read and no frame is
/// dropped; frames arrive in file order. (The earlier way — a pipeline, its playback device
/// reached from the first frame and switched and rewound then — raced with the real-time
/// start: frames played before the switch were dropped or queued ahead of the replayed ones.)
mod playback {
    use std::ffi::{CStr, CString, c_int, c_void};
    use std::path::Path;
    use std::ptr::NonNull;
    use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, sync_channel};
    use std::time::Duration;

    use realsense_rust::frame::{ColorFrame, DepthFrame};
    use realsense_rust::stream_profile::StreamProfile;
    use realsense_sys as sys;

    use super::{Input, source_error};
    use crate::{AssessError, Result};

    /// Frames the playback may run ahead of the reader.
    const CHANNEL_FRAMES: usize = 4;
    /// How long closing waits for the playback to stop.
    const STOP_WAIT: Duration = Duration::from_secs(2);

    /// Takes (and frees) a librealsense2 error: `Err(message)` if `error` is set.
    fn check(error: *mut sys::rs2_error) -> std::result::Result<(), String> {
        if error.is_null() {
            return Ok(());
        }
        // SAFETY: `error` is a non-null rs2_error* that librealsense2 handed us; its message is
        // a NUL-terminated string owned by the error, copied before the error is freed.
        let message = unsafe {
            let m = sys::rs2_get_error_message(error);
            let text = if m.is_null() {
                "unknown librealsense2 error".to_string()
            } else {
                CStr::from_ptr(m).to_string_lossy().into_owned()
            };
            sys::rs2_free_error(error);
            text
        };
        Err(message)
    }

    /// A frame reference handed over by the playback thread; released on drop unless taken
    /// (frames left in the channel when the source closes must be released too: a frame holds
    /// its sensor, and so the playback device and its threads, alive).
    struct RawFrame(NonNull<sys::rs2_frame>);

    impl RawFrame {
        /// The reference, now owned by the caller.
        fn take(self) -> NonNull<sys::rs2_frame> {
            let frame = std::mem::ManuallyDrop::new(self);
            frame.0
        }
    }

    impl Drop for RawFrame {
        fn drop(&mut self) {
            // SAFETY: we own this reference and nobody else releases it.
            unsafe { sys::rs2_release_frame(self.0.as_ptr()) }
        }
    }

    // SAFETY: librealsense2 frame references may be used and released on any thread.
    unsafe impl Send for RawFrame {}

    /// The sensors' frame callback: runs on librealsense2's playback thread and blocks it
    /// until the reader has room (that is what keeps non-real-time playback lossless).
    unsafe extern "C" fn on_frame(frame: *mut sys::rs2_frame, user: *mut c_void) {
        let Some(frame) = NonNull::new(frame) else {
            return;
        };
        // SAFETY: `user` is the `SyncSender` boxed in `BagPlayer::open`, freed only after the
        // sensors stopped (so after the last call of this callback).
        let sender = unsafe { &*user.cast::<SyncSender<RawFrame>>() };
        // If the reader is gone (the source is closing), the returned frame is released.
        let _ = sender.send(RawFrame(frame));
    }

    /// One opened sensor of the playback device and the streams it plays.
    struct OpenSensor {
        sensor: NonNull<sys::rs2_sensor>,
        /// The sensor's profile list, which owns `played`.
        profiles: NonNull<sys::rs2_stream_profile_list>,
        played: Vec<NonNull<sys::rs2_stream_profile>>,
        opened: bool,
        started: bool,
    }

    /// A `.bag` file played without dropping frames; owns every handle and releases them on
    /// drop (sensors stopped and closed first, the context last).
    pub(super) struct BagPlayer {
        context: NonNull<sys::rs2_context>,
        /// The file, as loaded into `context` (to unload it).
        file: CString,
        device: NonNull<sys::rs2_device>,
        sensor_list: NonNull<sys::rs2_sensor_list>,
        /// The sensors that play the colour and the depth stream (one or two).
        open: Vec<OpenSensor>,
        /// The colour and depth profiles played (owned by an `OpenSensor`'s list).
        color: Option<NonNull<sys::rs2_stream_profile>>,
        depth: Option<NonNull<sys::rs2_stream_profile>>,
        /// The sender the callbacks use (boxed: its address is their `user` pointer).
        sender: Option<NonNull<SyncSender<RawFrame>>>,
        receiver: Option<Receiver<RawFrame>>,
    }

    // SAFETY: librealsense2 handles may be used from any thread (realsense-rust's `Device`
    // and `Sensor` are `Send` for the same reason); the receiver and sender are `Send`.
    unsafe impl Send for BagPlayer {}

    impl std::fmt::Debug for BagPlayer {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.debug_struct("BagPlayer").finish_non_exhaustive()
        }
    }

    impl Drop for BagPlayer {
        fn drop(&mut self) {
            // Drop the reader first: a callback blocked on a full channel then returns.
            self.receiver = None;
            // SAFETY: every handle is ours, non-null and released exactly once; the sensors
            // stop before the callbacks' sender is freed, lists before their owners.
            unsafe {
                for open in &self.open {
                    let mut error: *mut sys::rs2_error = std::ptr::null_mut();
                    if open.started {
                        sys::rs2_stop(open.sensor.as_ptr(), &mut error);
                        let _ = check(error);
                    }
                    if open.opened {
                        sys::rs2_close(open.sensor.as_ptr(), &mut error);
                        let _ = check(error);
                    }
                }
                // The last sensor's stop makes the playback rewind its reader on its own thread;
                // wait for that to finish (the status turns to stopped), or the device would be
                // released — and a process could exit — while it still reads the file.
                let waited = std::time::Instant::now();
                while waited.elapsed() < STOP_WAIT {
                    let mut error: *mut sys::rs2_error = std::ptr::null_mut();
                    let status = sys::rs2_playback_device_get_current_status(
                        self.device.as_ptr(),
                        &mut error,
                    );
                    if check(error).is_err()
                        || status == sys::rs2_playback_status_RS2_PLAYBACK_STATUS_STOPPED
                    {
                        break;
                    }
                    std::thread::sleep(Duration::from_millis(5));
                }
                // Only then are the sensors released: the reader thread may still hand a frame
                // to a sensor until the playback has stopped. With the sensors deleted before
                // this wait, the reader thread crashed in 2 of 10 parallel and 1 of 30 serial
                // runs of the .bag tests under load; in this order, 0 of 32 parallel runs.
                for open in self.open.drain(..) {
                    sys::rs2_delete_stream_profiles_list(open.profiles.as_ptr());
                    sys::rs2_delete_sensor(open.sensor.as_ptr());
                }
                if let Some(sender) = self.sender.take() {
                    drop(Box::from_raw(sender.as_ptr()));
                }
                sys::rs2_delete_sensor_list(self.sensor_list.as_ptr());
                sys::rs2_delete_device(self.device.as_ptr());
                let mut error: *mut sys::rs2_error = std::ptr::null_mut();
                sys::rs2_context_remove_device(
                    self.context.as_ptr(),
                    self.file.as_ptr(),
                    &mut error,
                );
                let _ = check(error);
                sys::rs2_delete_context(self.context.as_ptr());
            }
        }
    }

    /// The first colour and the first depth profile of `sensor`, with the sensor's profile
    /// list (which owns them).
    ///
    /// # Safety
    /// `sensor` must be a live sensor handle.
    #[allow(clippy::type_complexity)]
    unsafe fn find_profiles(
        sensor: NonNull<sys::rs2_sensor>,
    ) -> std::result::Result<
        (
            Option<NonNull<sys::rs2_stream_profile_list>>,
            Option<NonNull<sys::rs2_stream_profile>>,
            Option<NonNull<sys::rs2_stream_profile>>,
        ),
        String,
    > {
        let mut error: *mut sys::rs2_error = std::ptr::null_mut();
        // SAFETY: the caller guarantees `sensor`; the list is returned (or deleted).
        unsafe {
            let list = sys::rs2_get_stream_profiles(sensor.as_ptr(), &mut error);
            check(error)?;
            let Some(list) = NonNull::new(list) else {
                return Ok((None, None, None));
            };
            let count = sys::rs2_get_stream_profiles_count(list.as_ptr(), &mut error);
            if let Err(m) = check(error) {
                sys::rs2_delete_stream_profiles_list(list.as_ptr());
                return Err(m);
            }
            let (mut color, mut depth) = (None, None);
            for i in 0..count {
                let profile = sys::rs2_get_stream_profile(list.as_ptr(), i, &mut error);
                if check(error).is_err() {
                    continue;
                }
                let Some(profile) = NonNull::new(profile.cast_mut()) else {
                    continue;
                };
                let (mut kind, mut format, mut index, mut uid, mut fps) = (0, 0, 0, 0, 0);
                sys::rs2_get_stream_profile_data(
                    profile.as_ptr(),
                    &mut kind,
                    &mut format,
                    &mut index,
                    &mut uid,
                    &mut fps,
                    &mut error,
                );
                if check(error).is_err() {
                    continue;
                }
                if kind == sys::rs2_stream_RS2_STREAM_COLOR && color.is_none() {
                    color = Some(profile);
                } else if kind == sys::rs2_stream_RS2_STREAM_DEPTH && depth.is_none() {
                    depth = Some(profile);
                }
            }
            Ok((Some(list), color, depth))
        }
    }

    impl BagPlayer {
        /// Loads `path`, switches it to non-real-time playback and starts its colour and depth
        /// sensors. `cannot` words the failures (`cannot open bag …`).
        pub(super) fn open(path: &Path, cannot: impl Fn(String) -> AssessError) -> Result<Self> {
            let file = CString::new(path.to_string_lossy().as_bytes())
                .map_err(|_| cannot("the path contains a NUL byte".to_string()))?;
            let mut error: *mut sys::rs2_error = std::ptr::null_mut();
            // SAFETY: calls into librealsense2 with valid arguments; every handle is checked
            // for an error and for null before use and owned by `player` (or released) at once,
            // so `Drop` releases it on every early return.
            unsafe {
                let context = sys::rs2_create_context(sys::RS2_API_VERSION as c_int, &mut error);
                check(error).map_err(|m| cannot(format!("cannot create a context: {m}")))?;
                let context = NonNull::new(context)
                    .ok_or_else(|| cannot("librealsense2 returned no context".to_string()))?;
                let device =
                    sys::rs2_context_add_device(context.as_ptr(), file.as_ptr(), &mut error);
                let device = match (check(error), NonNull::new(device)) {
                    (Ok(()), Some(device)) => device,
                    (result, _) => {
                        sys::rs2_delete_context(context.as_ptr());
                        return Err(cannot(
                            result.err().unwrap_or_else(|| "no device".to_string()),
                        ));
                    }
                };
                let sensor_list = sys::rs2_query_sensors(device.as_ptr(), &mut error);
                let sensor_list = match (check(error), NonNull::new(sensor_list)) {
                    (Ok(()), Some(list)) => list,
                    (result, _) => {
                        sys::rs2_delete_device(device.as_ptr());
                        sys::rs2_delete_context(context.as_ptr());
                        return Err(cannot(
                            result.err().unwrap_or_else(|| "no sensors".to_string()),
                        ));
                    }
                };
                let mut player = Self {
                    context,
                    file: file.clone(),
                    device,
                    sensor_list,
                    open: Vec::new(),
                    color: None,
                    depth: None,
                    sender: None,
                    receiver: None,
                };
                let is_playback = sys::rs2_is_device_extendable_to(
                    device.as_ptr(),
                    sys::rs2_extension_RS2_EXTENSION_PLAYBACK,
                    &mut error,
                );
                check(error).map_err(&cannot)?;
                if is_playback == 0 {
                    return Err(cannot("it is not a RealSense recording".to_string()));
                }
                sys::rs2_playback_device_set_real_time(device.as_ptr(), 0, &mut error);
                check(error)
                    .map_err(|m| cannot(format!("cannot switch off real-time playback: {m}")))?;

                // The first sensor with a colour stream plays it, and likewise for depth (a
                // D435i recording has two sensors; a synthetic one may have one for both).
                let count = sys::rs2_get_sensors_count(sensor_list.as_ptr(), &mut error);
                check(error).map_err(&cannot)?;
                for i in 0..count {
                    let sensor = sys::rs2_create_sensor(sensor_list.as_ptr(), i, &mut error);
                    check(error).map_err(&cannot)?;
                    let Some(sensor) = NonNull::new(sensor) else {
                        continue;
                    };
                    let (list, color, depth) = match find_profiles(sensor) {
                        Ok(found) => found,
                        Err(m) => {
                            sys::rs2_delete_sensor(sensor.as_ptr());
                            return Err(cannot(m));
                        }
                    };
                    let mut played = Vec::new();
                    if let Some(color) = color.filter(|_| player.color.is_none()) {
                        player.color = Some(color);
                        played.push(color);
                    }
                    if let Some(depth) = depth.filter(|_| player.depth.is_none()) {
                        player.depth = Some(depth);
                        played.push(depth);
                    }
                    match list {
                        Some(profiles) if !played.is_empty() => player.open.push(OpenSensor {
                            sensor,
                            profiles,
                            played,
                            opened: false,
                            started: false,
                        }),
                        _ => {
                            if let Some(list) = list {
                                sys::rs2_delete_stream_profiles_list(list.as_ptr());
                            }
                            sys::rs2_delete_sensor(sensor.as_ptr());
                        }
                    }
                }
                if player.color.is_none() || player.depth.is_none() {
                    return Err(cannot(
                        "it does not hold both a colour and a depth stream".to_string(),
                    ));
                }
                let (sender, receiver) = sync_channel::<RawFrame>(CHANNEL_FRAMES);
                let sender = NonNull::from(Box::leak(Box::new(sender)));
                player.sender = Some(sender);
                player.receiver = Some(receiver);
                for open in &mut player.open {
                    let profiles: Vec<*const sys::rs2_stream_profile> = open
                        .played
                        .iter()
                        .map(|p| p.as_ptr().cast_const())
                        .collect();
                    sys::rs2_open_multiple(
                        open.sensor.as_ptr(),
                        profiles.as_ptr().cast_mut(),
                        c_int::try_from(profiles.len()).unwrap_or(0),
                        &mut error,
                    );
                    check(error).map_err(|m| cannot(format!("cannot open a sensor: {m}")))?;
                    open.opened = true;
                }
                for open in &mut player.open {
                    sys::rs2_start(
                        open.sensor.as_ptr(),
                        Some(on_frame),
                        sender.as_ptr().cast::<c_void>(),
                        &mut error,
                    );
                    check(error).map_err(|m| cannot(format!("cannot start a sensor: {m}")))?;
                    open.started = true;
                }
                Ok(player)
            }
        }

        /// The played colour and depth profiles (valid while `self` lives).
        pub(super) fn profiles(&self, name: &str) -> Result<(StreamProfile, StreamProfile)> {
            let wrap = |profile: Option<NonNull<sys::rs2_stream_profile>>, what: &str| {
                let profile = profile.ok_or_else(|| {
                    source_error(name, format!("the recording has no {what} stream"))
                })?;
                StreamProfile::try_from(profile).map_err(|e| {
                    source_error(name, format!("cannot read the {what} stream profile: {e}"))
                })
            };
            Ok((wrap(self.color, "colour")?, wrap(self.depth, "depth")?))
        }

        /// The `DEPTH_UNITS` option of the first sensor that has one [m per unit].
        pub(super) fn depth_units(&self, name: &str) -> Result<Option<f32>> {
            let mut error: *mut sys::rs2_error = std::ptr::null_mut();
            // SAFETY: `sensor_list` is live; each sensor handle created here is deleted here.
            unsafe {
                let count = sys::rs2_get_sensors_count(self.sensor_list.as_ptr(), &mut error);
                check(error).map_err(|m| source_error(name, m))?;
                for i in 0..count {
                    let sensor = sys::rs2_create_sensor(self.sensor_list.as_ptr(), i, &mut error);
                    check(error).map_err(|m| source_error(name, m))?;
                    let Some(sensor) = NonNull::new(sensor) else {
                        continue;
                    };
                    let options = sensor.as_ptr().cast::<sys::rs2_options>().cast_const();
                    let option = sys::rs2_option_RS2_OPTION_DEPTH_UNITS;
                    let supported = sys::rs2_supports_option(options, option, &mut error);
                    let value = if check(error).is_ok() && supported != 0 {
                        let v = sys::rs2_get_option(options, option, &mut error);
                        check(error).ok().map(|()| v)
                    } else {
                        None
                    };
                    sys::rs2_delete_sensor(sensor.as_ptr());
                    if value.is_some() {
                        return Ok(value);
                    }
                }
                Ok(None)
            }
        }

        /// The next frame, or `None` if none arrived within `timeout`.
        pub(super) fn wait(&mut self, timeout: Duration, name: &str) -> Result<Option<Input>> {
            let Some(receiver) = &self.receiver else {
                return Ok(None);
            };
            let frame = match receiver.recv_timeout(timeout) {
                Ok(frame) => frame.take(),
                Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => return Ok(None),
            };
            let mut error: *mut sys::rs2_error = std::ptr::null_mut();
            // SAFETY: `frame` is a frame reference we own; it is handed to a frame wrapper that
            // releases it, or released here.
            unsafe {
                let is_depth = sys::rs2_is_frame_extendable_to(
                    frame.as_ptr(),
                    sys::rs2_extension_RS2_EXTENSION_DEPTH_FRAME,
                    &mut error,
                );
                if let Err(m) = check(error) {
                    sys::rs2_release_frame(frame.as_ptr());
                    return Err(source_error(name, format!("cannot read a frame: {m}")));
                }
                let input = if is_depth != 0 {
                    DepthFrame::try_from(frame).map(Input::Depth)
                } else {
                    ColorFrame::try_from(frame).map(Input::Color)
                };
                input
                    .map(Some)
                    .map_err(|e| source_error(name, format!("cannot read a frame: {e}")))
            }
        }

        /// Whether playback has stopped (the end of a non-looping file).
        pub(super) fn is_stopped(&self, name: &str) -> Result<bool> {
            let mut error: *mut sys::rs2_error = std::ptr::null_mut();
            // SAFETY: `device` is the live playback device we own.
            let status = unsafe {
                sys::rs2_playback_device_get_current_status(self.device.as_ptr(), &mut error)
            };
            check(error)
                .map_err(|m| source_error(name, format!("cannot read the playback status: {m}")))?;
            Ok(status == sys::rs2_playback_status_RS2_PLAYBACK_STATUS_STOPPED)
        }
    }
}
