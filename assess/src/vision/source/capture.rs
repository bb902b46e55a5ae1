//! OpenCV `VideoCapture` sources: a video file ([`VideoFileSource`], with an optional aligned
//! depth sequence) and a plain webcam ([`WebcamSource`], colour only); and the writing side, an
//! MJPG `.avi` ([`VideoSink`]).
//!
//! # Depth sequences
//!
//! A depth sequence ([`DepthSequence`]) is a folder of 16-bit single-channel PNGs aligned to the
//! colour frames (same size and pixel grid), plus a `depth.toml`:
//!
//! ```toml
//! scale_m = 0.001                 # metres per depth unit [m] (0 = no depth)
//! # Optional: the colour intrinsics (depth is aligned to colour, so they are the depth's too).
//! image_size_px = [640, 480]
//! intrinsics = { fx_px = 615.0, fy_px = 615.0, cx_px = 320.0, cy_px = 240.0 }
//! ```
//!
//! For a video, frame `k` (0-based) has the depth image `NNNNNN.png` with `k` zero-padded to six
//! digits (`000000.png`, `000001.png`, ...); for an image folder, the depth image has the colour
//! image's file stem.
//!
//! # Intrinsics
//!
//! The colour intrinsics are, in order of precedence: those given in the options, those of the
//! depth sequence's `depth.toml`, or [`Intrinsics::from_hfov`] with the options' horizontal field
//! of view (default [`DEFAULT_HFOV_DEG`]). Given intrinsics must match the frame size.
//!
//! # Timestamps
//!
//! A video's frame times come from the container (`CAP_PROP_POS_MSEC`) while that is finite and
//! strictly increasing; from the first frame where it is not, they continue at 1 / fps per frame.
//! The fps is the container's (`CAP_PROP_FPS`), or the options' `fps` when given or when the
//! container has none. A webcam uses the same rule with the driver's buffer timestamps.
//!
//! # Failures
//!
//! Opening a missing, empty or undecodable file is an [`AssessError::Source`] naming it; so is a
//! video of which not even the first frame decodes. A video that stops decoding part-way (a
//! truncated file) ends there, like a complete one: OpenCV cannot tell the two apart. A missing or
//! undecodable depth PNG is an error naming the PNG. Nothing here panics on bad input.
//!
//! # Writing video
//!
//! [`VideoSink`] writes RGB images as Motion-JPEG in an AVI container (FourCC `MJPG`, OpenCV's
//! built-in encoder, so it needs no FFmpeg). The frame rate is given when the sink is created
//! and the frame size is fixed by the first frame; [`VideoFileSource`] reads the file back.

use std::path::{Path, PathBuf};

use opencv::core::{self, Mat};
use opencv::prelude::*;
use opencv::{imgcodecs, imgproc, videoio};
use serde::Deserialize;

use super::FrameSource;
use crate::vision::calib::{RawIntrinsics, bgr_mat, rgb_from_mat};
use crate::vision::frame::{CameraFrame, DepthImage, Intrinsics, RgbImage};
use crate::{AssessError, Result};

/// Horizontal field of view assumed for uncalibrated cameras [deg] (the D435i colour camera's).
pub const DEFAULT_HFOV_DEG: f64 = 69.0;

/// Frame rate assumed when neither the container nor the options give one [1/s].
pub const DEFAULT_FPS: f64 = 30.0;

/// Name of the depth sequence's description file.
pub const DEPTH_TOML: &str = "depth.toml";

pub(crate) fn source_err(
    source_name: impl Into<String>,
    message: impl Into<String>,
) -> AssessError {
    AssessError::Source {
        source_name: source_name.into(),
        message: message.into(),
    }
}

/// Decodes the image file `path` with OpenCV's `imread` `flags`; a missing or undecodable file
/// is an error naming it, with `what` ("image", "depth image") in the message.
pub(crate) fn read_mat(path: &Path, flags: i32, what: &str) -> Result<Mat> {
    let name = path.display().to_string();
    if !path.is_file() {
        return Err(source_err(&name, format!("no such {what} file")));
    }
    let mat = imgcodecs::imread(&name, flags).map_err(|e| source_err(&name, e.message))?;
    if mat.empty() {
        return Err(source_err(
            &name,
            format!("cannot read or decode the {what}"),
        ));
    }
    Ok(mat)
}

/// `", depth <folder>"` for a source's description, or nothing without depth.
pub(crate) fn depth_note(depth: Option<&DepthSequence>) -> String {
    depth.map_or_else(String::new, |d| format!(", depth {}", d.dir().display()))
}

/// An [`RgbImage`] from an 8-bit BGR, BGRA or grey `Mat` as OpenCV decodes it.
pub(crate) fn rgb_from_decoded(mat: &Mat, source_name: &str) -> Result<RgbImage> {
    let code = match (mat.depth(), mat.channels()) {
        (core::CV_8U, 3) => imgproc::COLOR_BGR2RGB,
        (core::CV_8U, 4) => imgproc::COLOR_BGRA2RGB,
        (core::CV_8U, 1) => imgproc::COLOR_GRAY2RGB,
        (d, c) => {
            return Err(source_err(
                source_name,
                format!("unsupported pixel format (depth code {d}, {c} channels); expected 8-bit"),
            ));
        }
    };
    rgb_from_mat(mat, code, "colour conversion").map_err(|e| source_err(source_name, e.to_string()))
}

/// The intrinsics of a frame of `width` × `height` [px]: those fixed by the first frame
/// (`slot`), which every later frame must match in size, else resolved now
/// ([`resolve_intrinsics`]) and fixed. `frame_name` names the frame in the size error.
pub(crate) fn frame_intrinsics(
    slot: &mut Option<Intrinsics>,
    source_name: &str,
    frame_name: &str,
    explicit: Option<Intrinsics>,
    depth: Option<&DepthSequence>,
    hfov_deg: f64,
    (width, height): (u32, u32),
) -> Result<Intrinsics> {
    match *slot {
        Some(k) if (k.width, k.height) == (width, height) => Ok(k),
        Some(k) => Err(source_err(
            frame_name,
            format!(
                "{width} x {height} px, earlier frames {} x {} px",
                k.width, k.height
            ),
        )),
        None => {
            let k = resolve_intrinsics(source_name, explicit, depth, hfov_deg, width, height)?;
            *slot = Some(k);
            Ok(k)
        }
    }
}

/// The colour intrinsics for a `width` × `height` [px] stream (precedence in the module docs).
pub(crate) fn resolve_intrinsics(
    source_name: &str,
    explicit: Option<Intrinsics>,
    depth: Option<&DepthSequence>,
    hfov_deg: f64,
    width: u32,
    height: u32,
) -> Result<Intrinsics> {
    let (k, origin) = match (explicit, depth.and_then(DepthSequence::intrinsics)) {
        (Some(k), _) => (k, "the given intrinsics"),
        (None, Some(k)) => (k, "the depth sequence's intrinsics"),
        (None, None) => {
            if !(hfov_deg.is_finite() && hfov_deg > 1.0 && hfov_deg < 179.0) {
                return Err(AssessError::invalid(
                    "hfov_deg",
                    format!("must be in (1, 179) deg (got {hfov_deg})"),
                ));
            }
            return Ok(Intrinsics::from_hfov(width, height, hfov_deg));
        }
    };
    if (k.width, k.height) != (width, height) {
        return Err(source_err(
            source_name,
            format!(
                "{origin} are for {} x {} px but the frames are {width} x {height} px",
                k.width, k.height
            ),
        ));
    }
    Ok(k)
}

// ---------------------------------------------------------------------------------------------
// Depth sequences.

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDepthToml {
    scale_m: f64,
    image_size_px: Option<[u32; 2]>,
    intrinsics: Option<RawIntrinsics>,
}

/// A folder of 16-bit depth PNGs aligned to colour, with its `depth.toml` (module docs).
#[derive(Debug, Clone)]
pub struct DepthSequence {
    dir: PathBuf,
    scale_m: f64,
    intrinsics: Option<Intrinsics>,
}

impl DepthSequence {
    /// Opens the folder and reads its `depth.toml`.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref().to_path_buf();
        let toml_path = dir.join(DEPTH_TOML);
        let text = crate::error::read_text(&toml_path)?;
        let raw: RawDepthToml = crate::error::parse_toml(&text, &toml_path)?;
        let in_file = |key: &str, rule: String| {
            AssessError::invalid(key, format!("{rule} (in {})", toml_path.display()))
        };
        if !(raw.scale_m.is_finite() && raw.scale_m > 0.0 && raw.scale_m < 1.0) {
            return Err(in_file(
                "scale_m",
                format!("must be in (0, 1) m per unit (got {})", raw.scale_m),
            ));
        }
        let intrinsics = match (raw.intrinsics, raw.image_size_px) {
            (None, _) => None,
            (Some(_), None) => {
                return Err(in_file(
                    "image_size_px",
                    "is required with intrinsics".into(),
                ));
            }
            (Some(k), Some([w, h])) => {
                Some(k.validate("intrinsics", w, h).map_err(|e| match e {
                    AssessError::InvalidValue { key, rule } => in_file(&key, rule),
                    other => other,
                })?)
            }
        };
        Ok(Self {
            dir,
            scale_m: raw.scale_m,
            intrinsics,
        })
    }

    /// Metres per depth unit [m].
    pub fn scale_m(&self) -> f64 {
        self.scale_m
    }

    /// The colour (= aligned depth) intrinsics, if `depth.toml` gives them.
    pub fn intrinsics(&self) -> Option<Intrinsics> {
        self.intrinsics
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The PNG of a video frame: `NNNNNN.png`, the index zero-padded to six digits.
    pub fn frame_path(&self, index: u64) -> PathBuf {
        self.dir.join(format!("{index:06}.png"))
    }

    /// Reads the depth PNG at `path`, which must be 16-bit single-channel and
    /// `width` × `height` [px].
    pub fn read(&self, path: &Path, width: u32, height: u32) -> Result<DepthImage> {
        let name = path.display().to_string();
        let mat = read_mat(path, imgcodecs::IMREAD_ANYDEPTH, "depth image")?;
        if mat.typ() != core::CV_16UC1 {
            return Err(source_err(
                &name,
                format!(
                    "depth must be a 16-bit single-channel PNG (got OpenCV type {})",
                    mat.typ()
                ),
            ));
        }
        let (w, h) = (mat.cols() as u32, mat.rows() as u32);
        if (w, h) != (width, height) {
            return Err(source_err(
                &name,
                format!("depth is {w} x {h} px but the colour frame is {width} x {height} px"),
            ));
        }
        let mat = if mat.is_continuous() {
            mat
        } else {
            mat.try_clone().map_err(|e| source_err(&name, e.message))?
        };
        let data = mat
            .data_typed::<u16>()
            .map_err(|e| source_err(&name, e.message))?
            .to_vec();
        Ok(DepthImage {
            width: w,
            height: h,
            data,
            scale_m: self.scale_m,
        })
    }
}

/// Writes a depth image as a 16-bit PNG (for recording sequences and tests).
pub fn write_depth_png(depth: &DepthImage, path: impl AsRef<Path>) -> Result<()> {
    let path = path.as_ref();
    let name = path.display().to_string();
    if depth.width == 0
        || depth.height == 0
        || depth.data.len() != depth.width as usize * depth.height as usize
    {
        return Err(source_err(&name, "malformed depth image"));
    }
    let mat =
        Mat::new_rows_cols_with_data::<u16>(depth.height as i32, depth.width as i32, &depth.data)
            .map_err(|e| source_err(&name, e.message))?;
    let ok = imgcodecs::imwrite(&name, &mat, &core::Vector::new())
        .map_err(|e| source_err(&name, e.message))?;
    if ok {
        Ok(())
    } else {
        Err(source_err(&name, "OpenCV could not write the PNG"))
    }
}

// ---------------------------------------------------------------------------------------------
// Timestamps.

/// Frame times from the capture position while valid, then from the frame rate.
#[derive(Debug, Clone)]
struct FrameClock {
    fps: f64,
    use_position: bool,
    last: Option<f64>,
}

impl FrameClock {
    fn new(fps: f64) -> Self {
        Self {
            fps,
            use_position: true,
            last: None,
        }
    }

    /// The time [s] of the frame just read, given the capture's `CAP_PROP_POS_MSEC` [ms].
    fn next(&mut self, pos_msec: Option<f64>) -> f64 {
        let step = 1.0 / self.fps;
        let t = match (self.use_position, pos_msec.map(|ms| ms / 1000.0), self.last) {
            (true, Some(t), None) if t.is_finite() && t >= 0.0 => t,
            (true, Some(t), Some(last)) if t.is_finite() && t > last => t,
            (_, _, last) => {
                self.use_position = false;
                last.map_or(0.0, |l| l + step)
            }
        };
        self.last = Some(t);
        t
    }
}

fn valid_fps(fps: f64) -> bool {
    fps.is_finite() && fps > 0.1 && fps <= 1000.0
}

// ---------------------------------------------------------------------------------------------
// Video files.

/// Options of a [`VideoFileSource`].
#[derive(Debug, Clone)]
pub struct VideoFileOptions {
    /// Colour intrinsics; default: the depth sequence's, or from `hfov_deg`.
    pub intrinsics: Option<Intrinsics>,
    /// Horizontal field of view for the default intrinsics [deg].
    pub hfov_deg: f64,
    /// Frame rate [1/s] overriding the container's (used for timestamps after the container's
    /// positions become invalid, or throughout when they are).
    pub fps: Option<f64>,
    /// An aligned depth sequence folder (module docs).
    pub depth: Option<PathBuf>,
}

impl Default for VideoFileOptions {
    fn default() -> Self {
        Self {
            intrinsics: None,
            hfov_deg: DEFAULT_HFOV_DEG,
            fps: None,
            depth: None,
        }
    }
}

/// Frames of any video file OpenCV can read, with an optional aligned depth sequence.
#[derive(Debug)]
pub struct VideoFileSource {
    path: PathBuf,
    name: String,
    cap: videoio::VideoCapture,
    clock: FrameClock,
    fps: f64,
    frame_count: Option<u64>,
    options: VideoFileOptions,
    depth: Option<DepthSequence>,
    intrinsics: Option<Intrinsics>,
    index: u64,
    finished: bool,
}

impl VideoFileSource {
    /// Opens the video (and the depth sequence, if any).
    pub fn open(path: impl AsRef<Path>, options: VideoFileOptions) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let name = path.display().to_string();
        match std::fs::metadata(&path) {
            Err(e) => return Err(source_err(&name, format!("cannot open: {e}"))),
            Ok(m) if !m.is_file() => return Err(source_err(&name, "not a file")),
            Ok(m) if m.len() == 0 => return Err(source_err(&name, "empty file")),
            Ok(_) => {}
        }
        if let Some(f) = options.fps
            && !valid_fps(f)
        {
            return Err(AssessError::invalid(
                "fps",
                format!("must be in (0.1, 1000] (got {f})"),
            ));
        }
        // FFmpeg, then OpenCV's own MJPEG reader; never CAP_ANY: its GStreamer and image-
        // sequence backends crashed (SIGSEGV) on garbage files with several captures open in
        // parallel threads (Debian's OpenCV 4.6).
        let mut cap = videoio::VideoCapture::from_file(&name, videoio::CAP_FFMPEG)
            .map_err(|e| source_err(&name, e.message))?;
        if !cap.is_opened().map_err(|e| source_err(&name, e.message))? {
            cap = videoio::VideoCapture::from_file(&name, videoio::CAP_OPENCV_MJPEG)
                .map_err(|e| source_err(&name, e.message))?;
        }
        if !cap.is_opened().map_err(|e| source_err(&name, e.message))? {
            return Err(source_err(
                &name,
                "OpenCV cannot open it as a video (unsupported format or corrupt file)",
            ));
        }
        let prop = |id| cap.get(id).unwrap_or(f64::NAN);
        let container_fps = prop(videoio::CAP_PROP_FPS);
        let fps = options
            .fps
            .or(valid_fps(container_fps).then_some(container_fps))
            .unwrap_or(DEFAULT_FPS);
        let count = prop(videoio::CAP_PROP_FRAME_COUNT);
        let frame_count = (count.is_finite() && count >= 1.0).then_some(count as u64);
        let depth = options
            .depth
            .as_ref()
            .map(DepthSequence::open)
            .transpose()?;
        Ok(Self {
            path,
            name,
            cap,
            clock: FrameClock::new(fps),
            fps,
            frame_count,
            options,
            depth,
            intrinsics: None,
            index: 0,
            finished: false,
        })
    }

    /// The frame rate used for timestamps [1/s].
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// The container's frame count, when it states one (may be approximate).
    pub fn frame_count(&self) -> Option<u64> {
        self.frame_count
    }

    /// The video file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl FrameSource for VideoFileSource {
    fn next_frame(&mut self) -> Result<Option<CameraFrame>> {
        if self.finished {
            return Ok(None);
        }
        let mut mat = Mat::default();
        let ok = self
            .cap
            .read(&mut mat)
            .map_err(|e| source_err(&self.name, format!("frame {}: {}", self.index, e.message)))?;
        if !ok || mat.empty() {
            self.finished = true;
            if self.index == 0 {
                return Err(source_err(
                    &self.name,
                    "no frame could be decoded (truncated or corrupt video?)",
                ));
            }
            return Ok(None);
        }
        let pos = self.cap.get(videoio::CAP_PROP_POS_MSEC).ok();
        let t = self.clock.next(pos);
        let color = rgb_from_decoded(&mat, &format!("{} frame {}", self.name, self.index))?;
        let intrinsics = frame_intrinsics(
            &mut self.intrinsics,
            &self.name,
            &format!("{} frame {}", self.name, self.index),
            self.options.intrinsics,
            self.depth.as_ref(),
            self.options.hfov_deg,
            (color.width, color.height),
        )?;
        let depth = match &self.depth {
            Some(seq) => Some(seq.read(&seq.frame_path(self.index), color.width, color.height)?),
            None => None,
        };
        let frame = CameraFrame {
            t,
            index: self.index,
            color,
            depth,
            intrinsics,
        };
        self.index += 1;
        Ok(Some(frame))
    }

    fn describe(&self) -> String {
        format!(
            "video {} ({:.3} fps{})",
            self.name,
            self.fps,
            depth_note(self.depth.as_ref())
        )
    }

    fn has_depth(&self) -> bool {
        self.depth.is_some()
    }
}

// ---------------------------------------------------------------------------------------------
// Webcams.

/// Options of a [`WebcamSource`].
#[derive(Debug, Clone)]
pub struct WebcamOptions {
    /// Requested frame size [px] (width, height); the driver may pick another.
    pub size: Option<(u32, u32)>,
    /// Requested frame rate [1/s]; also the rate for timestamps when the driver gives none.
    pub fps: Option<f64>,
    /// Colour intrinsics; default from `hfov_deg`.
    pub intrinsics: Option<Intrinsics>,
    /// Horizontal field of view for the default intrinsics [deg].
    pub hfov_deg: f64,
}

impl Default for WebcamOptions {
    fn default() -> Self {
        Self {
            size: None,
            fps: None,
            intrinsics: None,
            hfov_deg: DEFAULT_HFOV_DEG,
        }
    }
}

/// A plain webcam through OpenCV (V4L2 on Linux): colour only, never ends.
#[derive(Debug)]
pub struct WebcamSource {
    device: u32,
    name: String,
    cap: videoio::VideoCapture,
    clock: FrameClock,
    fps: f64,
    options: WebcamOptions,
    intrinsics: Option<Intrinsics>,
    index: u64,
}

impl WebcamSource {
    /// Opens camera `device` (0 = `/dev/video0`) and requests the options' size and rate.
    pub fn open(device: u32, options: WebcamOptions) -> Result<Self> {
        let name = format!("webcam {device}");
        if let Some(f) = options.fps
            && !valid_fps(f)
        {
            return Err(AssessError::invalid(
                "fps",
                format!("must be in (0.1, 1000] (got {f})"),
            ));
        }
        let index =
            i32::try_from(device).map_err(|_| source_err(&name, "device index too large"))?;
        // V4L2 directly (not CAP_ANY's GStreamer first; see `VideoFileSource::open`).
        let mut cap = videoio::VideoCapture::new(index, videoio::CAP_V4L2)
            .map_err(|e| source_err(&name, e.message))?;
        if !cap.is_opened().map_err(|e| source_err(&name, e.message))? {
            return Err(source_err(
                &name,
                format!("cannot open the camera (is /dev/video{device} present and free?)"),
            ));
        }
        // Requests; the driver may refuse them, so the results are read back from the frames.
        if let Some((w, h)) = options.size {
            let _ = cap.set(videoio::CAP_PROP_FRAME_WIDTH, f64::from(w));
            let _ = cap.set(videoio::CAP_PROP_FRAME_HEIGHT, f64::from(h));
        }
        if let Some(f) = options.fps {
            let _ = cap.set(videoio::CAP_PROP_FPS, f);
        }
        let driver_fps = cap.get(videoio::CAP_PROP_FPS).unwrap_or(f64::NAN);
        let fps = options
            .fps
            .or(valid_fps(driver_fps).then_some(driver_fps))
            .unwrap_or(DEFAULT_FPS);
        Ok(Self {
            device,
            name,
            cap,
            clock: FrameClock::new(fps),
            fps,
            options,
            intrinsics: None,
            index: 0,
        })
    }

    /// The frame rate the driver reports (else the requested or default one) [1/s].
    pub fn fps(&self) -> f64 {
        self.fps
    }
}

impl FrameSource for WebcamSource {
    fn next_frame(&mut self) -> Result<Option<CameraFrame>> {
        let mut mat = Mat::default();
        let ok = self
            .cap
            .read(&mut mat)
            .map_err(|e| source_err(&self.name, e.message))?;
        if !ok || mat.empty() {
            return Err(source_err(
                &self.name,
                format!("no frame after {} frames (camera unplugged?)", self.index),
            ));
        }
        let pos = self.cap.get(videoio::CAP_PROP_POS_MSEC).ok();
        let t = self.clock.next(pos);
        let color = rgb_from_decoded(&mat, &self.name)?;
        let intrinsics = match self.intrinsics {
            Some(k) => k,
            None => {
                let k = resolve_intrinsics(
                    &self.name,
                    self.options.intrinsics,
                    None,
                    self.options.hfov_deg,
                    color.width,
                    color.height,
                )?;
                self.intrinsics = Some(k);
                k
            }
        };
        if (intrinsics.width, intrinsics.height) != (color.width, color.height) {
            return Err(source_err(&self.name, "the frame size changed"));
        }
        let frame = CameraFrame {
            t,
            index: self.index,
            color,
            depth: None,
            intrinsics,
        };
        self.index += 1;
        Ok(Some(frame))
    }

    fn describe(&self) -> String {
        match self.intrinsics {
            Some(k) => format!(
                "webcam {} ({} x {} px, {:.1} fps)",
                self.device, k.width, k.height, self.fps
            ),
            None => format!("webcam {} ({:.1} fps)", self.device, self.fps),
        }
    }

    fn has_depth(&self) -> bool {
        false
    }
}

// ---------------------------------------------------------------------------------------------
// Writing video.

/// MJPG quality of [`VideoSink`] frames [0, 100] (OpenCV's `VIDEOWRITER_PROP_QUALITY`).
pub const VIDEO_SINK_QUALITY: f64 = 90.0;

/// Writes RGB images to an MJPG `.avi` (module docs). The file is created at the first frame,
/// whose size every later frame must have; a sink that was given no frame writes no file.
#[derive(Debug)]
pub struct VideoSink {
    path: PathBuf,
    name: String,
    fps: f64,
    /// The writer and the frame size [px], once the first frame is in.
    writer: Option<(videoio::VideoWriter, u32, u32)>,
    frames: u64,
}

impl VideoSink {
    /// A sink writing `path` (extension `.avi`, any case) at `fps` [1/s] in (0.1, 1000]. Nothing
    /// is written before the first frame.
    pub fn create(path: impl AsRef<Path>, fps: f64) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let name = path.display().to_string();
        if !path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("avi"))
        {
            return Err(source_err(&name, "an MJPG video must be an .avi file"));
        }
        if !valid_fps(fps) {
            return Err(AssessError::invalid(
                "fps",
                format!("must be in (0.1, 1000] (got {fps})"),
            ));
        }
        Ok(Self {
            path,
            name,
            fps,
            writer: None,
            frames: 0,
        })
    }

    /// Appends one frame (converted RGB → BGR for OpenCV). The first frame fixes the video's
    /// size; a frame of another size is an error and is not written.
    pub fn write(&mut self, image: &RgbImage) -> Result<()> {
        let (w, h) = (image.width, image.height);
        let writer = match &mut self.writer {
            Some((writer, w0, h0)) if (*w0, *h0) == (w, h) => writer,
            Some((_, w0, h0)) => {
                return Err(source_err(
                    &self.name,
                    format!(
                        "frame {} is {w} x {h} px, the video {w0} x {h0} px",
                        self.frames
                    ),
                ));
            }
            None => {
                let size = core::Size::new(
                    i32::try_from(w).map_err(|_| source_err(&self.name, "frame too wide"))?,
                    i32::try_from(h).map_err(|_| source_err(&self.name, "frame too high"))?,
                );
                let err = |e: opencv::Error| source_err(&self.name, e.message);
                let fourcc = videoio::VideoWriter::fourcc('M', 'J', 'P', 'G').map_err(err)?;
                let mut writer = videoio::VideoWriter::new_with_backend(
                    &self.name,
                    videoio::CAP_OPENCV_MJPEG,
                    fourcc,
                    self.fps,
                    size,
                    true,
                )
                .map_err(err)?;
                if !writer.is_opened().map_err(err)? {
                    return Err(source_err(
                        &self.name,
                        "OpenCV cannot create the video (is the folder writable?)",
                    ));
                }
                // A request: a backend without the property keeps its default quality.
                let _ = writer.set(videoio::VIDEOWRITER_PROP_QUALITY, VIDEO_SINK_QUALITY);
                &mut self.writer.insert((writer, w, h)).0
            }
        };
        let bgr = bgr_mat(image).map_err(|e| source_err(&self.name, e.to_string()))?;
        writer
            .write(&bgr)
            .map_err(|e| source_err(&self.name, e.message))?;
        self.frames += 1;
        Ok(())
    }

    /// The frame size fixed by the first frame (width, height) [px].
    pub fn size(&self) -> Option<(u32, u32)> {
        self.writer.as_ref().map(|(_, w, h)| (*w, *h))
    }

    /// Frames written so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Closes the file (writes the AVI index). Without a frame there is no file.
    pub fn finish(mut self) -> Result<()> {
        match self.writer.take() {
            Some((mut writer, _, _)) => writer
                .release()
                .map_err(|e| source_err(&self.name, e.message)),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_uses_positions_while_they_increase_then_the_frame_rate() {
        let mut c = FrameClock::new(10.0);
        assert_eq!(c.next(Some(0.0)), 0.0);
        assert_eq!(c.next(Some(40.0)), 0.04);
        // A stalled position switches to 1/fps steps for good.
        assert!((c.next(Some(40.0)) - 0.14).abs() < 1e-12);
        assert!((c.next(Some(500.0)) - 0.24).abs() < 1e-12);
        let mut c = FrameClock::new(25.0);
        assert_eq!(c.next(None), 0.0);
        assert!((c.next(Some(1000.0)) - 0.04).abs() < 1e-12);
        let mut c = FrameClock::new(25.0);
        assert_eq!(c.next(Some(f64::NAN)), 0.0);
    }
}
