//! Camera frames, intrinsics and extrinsics: the plain data every source produces.
//!
//! Conventions: images are row-major RGB8; pixel (u, v) has its centre at (u + 0.5, v + 0.5) in
//! MediaPipe's continuous coordinates, and at (u, v) in the pinhole model below (OpenCV's and
//! librealsense's convention). The camera frame is x right, y down, z forward (optical axis).

use nalgebra::{Isometry3, Point3, Vector3};

/// An 8-bit RGB image, row-major, 3 bytes per pixel, no padding.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbImage {
    /// Width [px].
    pub width: u32,
    /// Height [px].
    pub height: u32,
    /// `width * height * 3` bytes, R, G, B.
    pub data: Vec<u8>,
}

impl RgbImage {
    /// A black image of the given size [px].
    pub fn black(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            data: vec![0; width as usize * height as usize * 3],
        }
    }

    /// Reads an image file (any format OpenCV decodes: PNG, JPEG, ...) as RGB. A missing,
    /// empty, truncated or undecodable file is an [`AssessError::Source`](crate::AssessError::Source) naming it.
    pub fn read(path: &std::path::Path) -> crate::Result<Self> {
        use opencv::core::Mat;
        use opencv::imgcodecs;
        use opencv::prelude::*;
        let err = |message: String| crate::AssessError::Source {
            source_name: path.display().to_string(),
            message,
        };
        let bytes = std::fs::read(path).map_err(|e| err(format!("cannot read: {e}")))?;
        let buf = Mat::from_slice(&bytes).map_err(|e| err(e.message))?;
        let bgr = imgcodecs::imdecode(&buf, imgcodecs::IMREAD_COLOR).map_err(|e| err(e.message))?;
        if bgr.empty() {
            return Err(err("not a decodable image (empty or truncated?)".into()));
        }
        super::source::capture::rgb_from_decoded(&bgr, &path.display().to_string())
    }

    /// Whether the buffer holds exactly `width * height * 3` bytes and the image is not empty.
    pub fn is_well_formed(&self) -> bool {
        self.width > 0
            && self.height > 0
            && self.data.len() == self.width as usize * self.height as usize * 3
    }
}

/// A depth image aligned to the colour image (same size and pixel grid).
#[derive(Debug, Clone, PartialEq)]
pub struct DepthImage {
    /// Width [px].
    pub width: u32,
    /// Height [px].
    pub height: u32,
    /// Raw depth units, row-major; 0 means "no depth".
    pub data: Vec<u16>,
    /// Metres per depth unit [m] (0.001 for the D435i default).
    pub scale_m: f64,
}

impl DepthImage {
    /// Depth at pixel (u, v) [m], or `None` when outside the image or invalid (0).
    pub fn depth_m(&self, u: u32, v: u32) -> Option<f64> {
        if u >= self.width || v >= self.height {
            return None;
        }
        let raw = *self
            .data
            .get(v as usize * self.width as usize + u as usize)?;
        (raw != 0).then(|| f64::from(raw) * self.scale_m)
    }
}

/// Pinhole intrinsics of the colour camera (no distortion: the D435i colour stream is
/// rectified to Brown–Conrady with zero coefficients by librealsense).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Image width [px].
    pub width: u32,
    /// Image height [px].
    pub height: u32,
    /// Focal length along x [px].
    pub fx: f64,
    /// Focal length along y [px].
    pub fy: f64,
    /// Principal point x [px].
    pub cx: f64,
    /// Principal point y [px].
    pub cy: f64,
}

impl Intrinsics {
    /// Intrinsics from a horizontal field of view [deg], square pixels, centred principal point.
    /// Used for webcams and image folders without calibration (the D435i colour camera has
    /// about 69°).
    pub fn from_hfov(width: u32, height: u32, hfov_deg: f64) -> Self {
        let f = f64::from(width) / 2.0 / (hfov_deg.to_radians() / 2.0).tan();
        Self {
            width,
            height,
            fx: f,
            fy: f,
            cx: f64::from(width) / 2.0,
            cy: f64::from(height) / 2.0,
        }
    }

    /// The 3-D point [m] in the camera frame seen at pixel (u, v) [px] at depth z [m].
    pub fn deproject(&self, u: f64, v: f64, z: f64) -> Point3<f64> {
        Point3::new((u - self.cx) / self.fx * z, (v - self.cy) / self.fy * z, z)
    }

    /// The pixel (u, v) [px] where a camera-frame point [m] projects; `None` behind the camera.
    pub fn project(&self, p: &Point3<f64>) -> Option<(f64, f64)> {
        (p.z > 1e-9).then(|| (self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy))
    }

    /// The unit ray [-] in the camera frame through pixel (u, v) [px].
    pub fn ray(&self, u: f64, v: f64) -> Vector3<f64> {
        Vector3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0).normalize()
    }
}

/// Camera-to-workspace extrinsics: `world_from_camera` maps camera-frame points [m] to the
/// workspace frame (z up) [m]. Written by `hrc-adapt calibrate`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extrinsics {
    /// The rigid transform workspace ← camera.
    pub world_from_camera: Isometry3<f64>,
}

impl Extrinsics {
    /// The identity: the workspace frame is the camera frame (uncalibrated; z is then the
    /// optical axis, not up).
    pub fn identity() -> Self {
        Self {
            world_from_camera: Isometry3::identity(),
        }
    }

    /// A camera-frame point [m] in the workspace frame [m].
    pub fn point_to_world(&self, p: &Point3<f64>) -> Point3<f64> {
        self.world_from_camera * p
    }

    /// A camera-frame direction [-] in the workspace frame [-].
    pub fn dir_to_world(&self, d: &Vector3<f64>) -> Vector3<f64> {
        self.world_from_camera.rotation * d
    }
}

/// One frame from a [`FrameSource`](super::FrameSource).
#[derive(Debug, Clone)]
pub struct CameraFrame {
    /// Camera timestamp [s] (device clock for cameras and `.bag` files, frame index / fps for
    /// video files, file order / nominal fps for image folders). Strictly increasing.
    pub t: f64,
    /// Frame number from the source, 0-based.
    pub index: u64,
    /// The colour image.
    pub color: RgbImage,
    /// Depth aligned to `color`, when the source has depth.
    pub depth: Option<DepthImage>,
    /// Colour intrinsics.
    pub intrinsics: Intrinsics,
}
