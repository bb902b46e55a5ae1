//! Rotated regions of interest and the crops fed to the models.
//!
//! The geometry follows MediaPipe's calculators, in `f32` and in their order of operations,
//! because the landmark models are sensitive to the exact crop:
//! - [`NormRect`] is MediaPipe's `NormalizedRect` (centre, size as fractions of the image,
//!   rotation clockwise in the image);
//! - [`rect_from_box`] / [`rect_from_alignment`] are `DetectionsToRectsCalculator` and
//!   `AlignmentPointsRectsCalculator`;
//! - [`NormRect::transformed`] is `RectTransformationCalculator`;
//! - [`crop_to_tensor`] is the OpenCV path of `ImageToTensorCalculator`: the rotated
//!   rectangle's corners → perspective transform → `warpPerspective` (bilinear, fixed point)
//!   on the 8-bit image → float with an affine value range.

use opencv::core::{Mat, Point2f, RotatedRect, Scalar, Size, Size2f, Vec3b};
use opencv::prelude::*;
use opencv::{core, imgproc};

use super::detect::Detection;
use super::frame::RgbImage;
use crate::{AssessError, Result};

/// A rotated rectangle in image pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Roi {
    /// Centre x [px].
    pub cx: f64,
    /// Centre y [px].
    pub cy: f64,
    /// Width [px].
    pub width: f64,
    /// Height [px].
    pub height: f64,
    /// Rotation, clockwise in the image (y down) [rad].
    pub rotation: f64,
}

/// MediaPipe's `NormalizedRect`: centre and size as fractions of the image width/height.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormRect {
    /// Centre x / image width [-].
    pub cx: f32,
    /// Centre y / image height [-].
    pub cy: f32,
    /// Width / image width [-].
    pub width: f32,
    /// Height / image height [-].
    pub height: f32,
    /// Rotation, clockwise in the image [rad].
    pub rotation: f32,
}

/// Wraps an angle to [-π, π) [rad] (MediaPipe's `NormalizeRadians`).
pub(crate) fn normalize_radians(angle: f32) -> f32 {
    use std::f32::consts::PI;
    angle - 2.0 * PI * ((angle - (-PI)) / (2.0 * PI)).floor()
}

/// The rotation that brings the vector from point `a` to point `b` (pixels) to
/// `target` [rad] (0: pointing right, π/2: pointing up in the image).
pub(crate) fn rotation_between(a: [f32; 2], b: [f32; 2], target: f32) -> f32 {
    normalize_radians(target - (-(b[1] - a[1])).atan2(b[0] - a[0]))
}

/// `DetectionsToRectsCalculator`: the detection's box as a rect, rotated so that keypoint
/// `start` → `end` points at `target_deg` [deg]. `image` is (width, height) [px].
pub(crate) fn rect_from_box(
    d: &Detection,
    image: (u32, u32),
    start: usize,
    end: usize,
    target_deg: f32,
) -> Option<NormRect> {
    let (w, h) = (image.0 as f32, image.1 as f32);
    let a = d.keypoints.get(start)?;
    let b = d.keypoints.get(end)?;
    Some(NormRect {
        cx: d.xmin + d.width / 2.0,
        cy: d.ymin + d.height / 2.0,
        width: d.width,
        height: d.height,
        rotation: rotation_between(
            [a[0] * w, a[1] * h],
            [b[0] * w, b[1] * h],
            std::f32::consts::PI * target_deg / 180.0,
        ),
    })
}

/// `AlignmentPointsRectsCalculator`: a square centred on keypoint `start` with side twice
/// the distance to keypoint `end`, rotated so that `start` → `end` points at `target_deg`.
pub(crate) fn rect_from_alignment(
    d: &Detection,
    image: (u32, u32),
    start: usize,
    end: usize,
    target_deg: f32,
) -> Option<NormRect> {
    let a = d.keypoints.get(start)?;
    let b = d.keypoints.get(end)?;
    rect_from_points([a[0], a[1]], [b[0], b[1]], image, target_deg)
}

/// [`rect_from_alignment`] on two normalised points.
pub(crate) fn rect_from_points(
    centre: [f32; 2],
    scale_point: [f32; 2],
    image: (u32, u32),
    target_deg: f32,
) -> Option<NormRect> {
    let (w, h) = (image.0 as f32, image.1 as f32);
    let (xc, yc) = (centre[0] * w, centre[1] * h);
    let (xs, ys) = (scale_point[0] * w, scale_point[1] * h);
    let size = ((xs - xc) * (xs - xc) + (ys - yc) * (ys - yc)).sqrt() * 2.0;
    let rect = NormRect {
        cx: xc / w,
        cy: yc / h,
        width: size / w,
        height: size / h,
        rotation: rotation_between(
            [xc, yc],
            [xs, ys],
            std::f32::consts::PI * target_deg / 180.0,
        ),
    };
    rect.is_usable().then_some(rect)
}

/// How [`NormRect::transformed`] scales and shifts a rect (`RectTransformationCalculatorOptions`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RectTransform {
    /// Width scale [-].
    pub scale_x: f32,
    /// Height scale [-].
    pub scale_y: f32,
    /// Shift along the rect's own x, in rect widths [-].
    pub shift_x: f32,
    /// Shift along the rect's own y, in rect heights [-].
    pub shift_y: f32,
    /// Make the rect square with the longer side (in pixels) before scaling.
    pub square_long: bool,
}

impl NormRect {
    /// Whether all values are finite and the size positive.
    pub fn is_usable(&self) -> bool {
        [self.cx, self.cy, self.width, self.height, self.rotation]
            .iter()
            .all(|v| v.is_finite())
            && self.width > 0.0
            && self.height > 0.0
    }

    /// `RectTransformationCalculator` for an image of (width, height) [px].
    pub fn transformed(&self, t: &RectTransform, image: (u32, u32)) -> NormRect {
        let (iw, ih) = (image.0 as f32, image.1 as f32);
        let mut r = *self;
        let (mut width, mut height) = (r.width, r.height);
        let rotation = r.rotation;
        if rotation == 0.0 {
            r.cx += width * t.shift_x;
            r.cy += height * t.shift_y;
        } else {
            let x_shift = (iw * width * t.shift_x * rotation.cos()
                - ih * height * t.shift_y * rotation.sin())
                / iw;
            let y_shift = (iw * width * t.shift_x * rotation.sin()
                + ih * height * t.shift_y * rotation.cos())
                / ih;
            r.cx += x_shift;
            r.cy += y_shift;
        }
        if t.square_long {
            let long_side = (width * iw).max(height * ih);
            width = long_side / iw;
            height = long_side / ih;
        }
        r.width = width * t.scale_x;
        r.height = height * t.scale_y;
        r
    }

    /// The rect in pixels.
    pub(crate) fn to_pixels(self, image: (u32, u32)) -> Roi {
        let (iw, ih) = (f64::from(image.0), f64::from(image.1));
        Roi {
            cx: f64::from(self.cx) * iw,
            cy: f64::from(self.cy) * ih,
            width: f64::from(self.width) * iw,
            height: f64::from(self.height) * ih,
            rotation: f64::from(self.rotation),
        }
    }

    /// The whole image, unrotated.
    pub fn full_image() -> NormRect {
        NormRect {
            cx: 0.5,
            cy: 0.5,
            width: 1.0,
            height: 1.0,
            rotation: 0.0,
        }
    }

    /// Maps a point normalised to the crop ([0, 1]² over the rect) back to the image,
    /// normalised (`LandmarkProjectionCalculator`).
    pub fn project(&self, x: f32, y: f32) -> [f32; 2] {
        let (x, y) = (x - 0.5, y - 0.5);
        let (s, c) = self.rotation.sin_cos();
        let nx = c * x - s * y;
        let ny = s * x + c * y;
        [nx * self.width + self.cx, ny * self.height + self.cy]
    }
}

/// Pads a pixel-space ROI to the tensor's aspect ratio (letterboxing, `PadRoi`); returns the
/// padded ROI (width, height) [px] and the padding fractions (left, top, right, bottom) [-].
pub(crate) fn pad_to_aspect(width: f32, height: f32, tensor: (u32, u32)) -> ((f32, f32), [f32; 4]) {
    let tensor_aspect = tensor.1 as f32 / tensor.0 as f32;
    let roi_aspect = height / width;
    if tensor_aspect > roi_aspect {
        let v = (1.0 - roi_aspect / tensor_aspect) / 2.0;
        ((width, width * tensor_aspect), [0.0, v, 0.0, v])
    } else {
        let hpad = (1.0 - tensor_aspect / roi_aspect) / 2.0;
        ((height / tensor_aspect, height), [hpad, 0.0, hpad, 0.0])
    }
}

/// Border handling of a crop outside the image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Border {
    /// Black outside the image (detectors).
    Zero,
    /// Edge pixels repeated (landmark models).
    Replicate,
}

/// A reusable crop: the 8-bit warp buffer and the float tensor (NHWC, RGB).
#[derive(Debug)]
pub(crate) struct CropBuffer {
    width: u32,
    height: u32,
    pixels: Vec<u8>,
    /// The tensor values, `height * width * 3` floats.
    pub tensor: Vec<f32>,
}

impl CropBuffer {
    /// A buffer for a `width` × `height` model input [px].
    pub(crate) fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize * 3;
        Self {
            width,
            height,
            pixels: vec![0; n],
            tensor: vec![0.0; n],
        }
    }

    /// The 8-bit crop of the last [`crop_to_tensor`] (RGB, row-major); read by the unit tests.
    #[cfg(test)]
    pub(crate) fn pixels(&self) -> &[u8] {
        &self.pixels
    }
}

fn cv(operation: &'static str) -> impl Fn(opencv::Error) -> AssessError {
    move |e| AssessError::Vision {
        operation,
        message: e.message,
    }
}

/// Crops `roi` (pixels; rotation about its centre) out of `image` into `out`, resampled with
/// OpenCV's bilinear `warpPerspective`, and scales the values to [range.0, range.1].
pub(crate) fn crop_to_tensor(
    image: &RgbImage,
    roi: &Roi,
    range: (f32, f32),
    border: Border,
    out: &mut CropBuffer,
) -> Result<()> {
    if !image.is_well_formed() {
        return Err(AssessError::Vision {
            operation: "crop",
            message: format!(
                "image buffer of {} bytes does not hold {}×{} RGB pixels",
                image.data.len(),
                image.width,
                image.height
            ),
        });
    }
    let src = Mat::new_rows_cols_with_bytes::<Vec3b>(
        image.height as i32,
        image.width as i32,
        &image.data,
    )
    .map_err(cv("crop"))?;
    let rect = RotatedRect::new(
        Point2f::new(roi.cx as f32, roi.cy as f32),
        Size2f::new(roi.width as f32, roi.height as f32),
        (roi.rotation * 180.0 / std::f64::consts::PI) as f32,
    )
    .map_err(cv("crop"))?;
    let mut corners = Mat::default();
    imgproc::box_points(rect, &mut corners).map_err(cv("crop"))?;
    let (w, h) = (out.width as f32, out.height as f32);
    let dst_corners: [Point2f; 4] = [
        Point2f::new(0.0, h),
        Point2f::new(0.0, 0.0),
        Point2f::new(w, 0.0),
        Point2f::new(w, h),
    ];
    let dst_points = Mat::from_slice(&dst_corners).map_err(cv("crop"))?;
    let src_points = corners.reshape(2, 4).map_err(cv("crop"))?;
    let m = imgproc::get_perspective_transform(&src_points, &dst_points, core::DECOMP_LU)
        .map_err(cv("crop"))?;
    let mut dst = Mat::new_rows_cols_with_bytes_mut::<Vec3b>(
        out.height as i32,
        out.width as i32,
        &mut out.pixels,
    )
    .map_err(cv("crop"))?;
    let border_mode = match border {
        Border::Zero => core::BORDER_CONSTANT,
        Border::Replicate => core::BORDER_REPLICATE,
    };
    imgproc::warp_perspective(
        &src,
        &mut dst,
        &m,
        Size::new(out.width as i32, out.height as i32),
        imgproc::INTER_LINEAR,
        border_mode,
        Scalar::default(),
    )
    .map_err(cv("crop"))?;
    let scale = (range.1 - range.0) / 255.0;
    for (t, &p) in out.tensor.iter_mut().zip(&out.pixels) {
        *t = f32::from(p) * scale + range.0;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::PI;

    #[test]
    fn rotation_targets() {
        // A vector pointing up in the image (y decreasing) already is at 90°.
        assert!(rotation_between([0.0, 10.0], [0.0, 0.0], PI / 2.0).abs() < 1e-6);
        // Pointing right with target 90°: rotate by +90° (clockwise in the image).
        assert!((rotation_between([0.0, 0.0], [1.0, 0.0], PI / 2.0) - PI / 2.0).abs() < 1e-6);
        assert!((normalize_radians(3.0 * PI) + PI).abs() < 1e-5);
    }

    #[test]
    fn transform_square_long_and_shift() {
        // 100 × 50 px image, rect 0.2 × 0.4 (20 × 20 px) unrotated: square_long keeps 20 px,
        // scale 2 → 0.4 × 0.8; shift_y −0.5 moves the centre up by half the height (0.2).
        let r = NormRect {
            cx: 0.5,
            cy: 0.5,
            width: 0.2,
            height: 0.4,
            rotation: 0.0,
        };
        let t = RectTransform {
            scale_x: 2.0,
            scale_y: 2.0,
            shift_x: 0.0,
            shift_y: -0.5,
            square_long: true,
        };
        let o = r.transformed(&t, (100, 50));
        assert!((o.width - 0.4).abs() < 1e-6 && (o.height - 0.8).abs() < 1e-6);
        assert!((o.cy - 0.3).abs() < 1e-6);
        // Rotated by 90°: the shift along the rect's y moves the centre along image x.
        let rr = NormRect {
            rotation: PI / 2.0,
            ..r
        };
        let o = rr.transformed(&t, (100, 50));
        // x_shift = −(50·0.4·(−0.5)·1)/100 = +0.1.
        assert!((o.cx - 0.6).abs() < 1e-6 && (o.cy - 0.5).abs() < 1e-6);
    }

    #[test]
    fn letterbox_padding() {
        // A 200 × 100 image into a square tensor: pad 0.25 top and bottom.
        let ((w, h), pad) = pad_to_aspect(200.0, 100.0, (128, 128));
        assert_eq!((w, h), (200.0, 200.0));
        assert_eq!(pad, [0.0, 0.25, 0.0, 0.25]);
    }

    #[test]
    fn projection_inverts_the_crop() {
        let r = NormRect {
            cx: 0.4,
            cy: 0.6,
            width: 0.2,
            height: 0.2,
            rotation: PI / 2.0,
        };
        // The crop's centre is the rect centre; its top-centre (0.5, 0) lies at +x in the
        // image for a 90° clockwise rotation: (0.4 + 0.1, 0.6).
        assert_eq!(r.project(0.5, 0.5), [0.4, 0.6]);
        let p = r.project(0.5, 0.0);
        assert!((p[0] - 0.5).abs() < 1e-6 && (p[1] - 0.6).abs() < 1e-6);
    }

    #[test]
    fn crop_of_an_unrotated_full_image_is_the_image() {
        // A 4 × 4 gradient cropped to 4 × 4 with the identity ROI is reproduced exactly.
        let mut img = RgbImage::black(4, 4);
        for (i, p) in img.data.iter_mut().enumerate() {
            *p = (i * 5) as u8;
        }
        let roi = NormRect::full_image().to_pixels((4, 4));
        let mut buf = CropBuffer::new(4, 4);
        crop_to_tensor(&img, &roi, (0.0, 1.0), Border::Zero, &mut buf).unwrap();
        assert_eq!(buf.pixels(), &img.data[..]);
        assert!((buf.tensor[3] - 15.0 / 255.0).abs() < 1e-6);
        // A malformed image is an error, not a panic.
        let bad = RgbImage {
            width: 4,
            height: 4,
            data: vec![0; 5],
        };
        assert!(crop_to_tensor(&bad, &roi, (0.0, 1.0), Border::Zero, &mut buf).is_err());
    }
}
