//! Overlays on an [`RgbImage`] for the monitoring view and the calibration check: landmarks and
//! skeletons, a head ray, projected workspace areas (the confirmed one highlighted), coordinate
//! axes and text lines.
//!
//! Drawing goes through OpenCV's `imgproc` on a `Mat` that borrows the image's buffer (no copy).
//! Colours are given as `[r, g, b]`. Every function clips what falls outside the image (or behind
//! the camera) and never panics on such input; non-finite coordinates are skipped. Errors are
//! [`AssessError::Vision`] (a malformed image buffer, or OpenCV failing).
//!
//! Pixel conventions: projected points use the pinhole convention of [`Intrinsics`] (pixel (u, v)
//! centred at (u, v)); [`Landmark`]s are in MediaPipe's continuous coordinates (pixel centre at
//! (u + 0.5, v + 0.5)) and are shifted by half a pixel before drawing.

use nalgebra::{Isometry3, Point3};
use opencv::boxed_ref::BoxedRefMut;
use opencv::core::{Mat, Point, Rect, Scalar, Vec3b};
use opencv::imgproc;

use super::frame::{Extrinsics, Intrinsics, RgbImage};
use super::landmarks::{Landmark, Landmarks};
use crate::{AreaId, AssessError, Result, Vec3, Workspace};

/// An RGB colour, `[r, g, b]`.
pub type Colour = [u8; 3];

/// Red.
pub const RED: Colour = [230, 40, 40];
/// Green.
pub const GREEN: Colour = [40, 200, 60];
/// Blue.
pub const BLUE: Colour = [50, 90, 255];
/// Yellow (the confirmed area).
pub const YELLOW: Colour = [255, 220, 0];
/// Cyan (areas not confirmed).
pub const CYAN: Colour = [0, 220, 230];
/// Magenta (the head ray).
pub const MAGENTA: Colour = [230, 0, 200];
/// Orange (the left hand).
pub const ORANGE: Colour = [255, 140, 0];
/// White.
pub const WHITE: Colour = [255, 255, 255];

/// MediaPipe's 35 pose skeleton connections (landmark index pairs of BlazePose's 33).
pub const POSE_CONNECTIONS: [(usize, usize); 35] = [
    (0, 1),
    (1, 2),
    (2, 3),
    (3, 7),
    (0, 4),
    (4, 5),
    (5, 6),
    (6, 8),
    (9, 10),
    (11, 12),
    (11, 13),
    (13, 15),
    (15, 17),
    (15, 19),
    (15, 21),
    (17, 19),
    (12, 14),
    (14, 16),
    (16, 18),
    (16, 20),
    (16, 22),
    (18, 20),
    (11, 23),
    (12, 24),
    (23, 24),
    (23, 25),
    (24, 26),
    (25, 27),
    (26, 28),
    (27, 29),
    (28, 30),
    (29, 31),
    (30, 32),
    (27, 31),
    (28, 32),
];

/// MediaPipe's 21 hand skeleton connections (landmark index pairs of the 21 hand landmarks).
pub const HAND_CONNECTIONS: [(usize, usize); 21] = [
    (0, 1),
    (1, 2),
    (2, 3),
    (3, 4),
    (0, 5),
    (5, 6),
    (6, 7),
    (7, 8),
    (5, 9),
    (9, 10),
    (10, 11),
    (11, 12),
    (9, 13),
    (13, 14),
    (14, 15),
    (15, 16),
    (13, 17),
    (0, 17),
    (17, 18),
    (18, 19),
    (19, 20),
];

/// Pose landmarks with visibility or presence below this [-] are not drawn.
pub const MIN_VISIBILITY: f64 = 0.5;

/// Nearest distance in front of the camera [m] that a projected segment is clipped to.
const NEAR_M: f64 = 0.01;

/// Projects workspace-frame points [m] into the colour image [px] of a calibrated camera.
#[derive(Debug, Clone, Copy)]
pub struct Projector {
    intrinsics: Intrinsics,
    camera_from_world: Isometry3<f64>,
}

impl Projector {
    /// A projector for a camera with these intrinsics and extrinsics.
    pub fn new(intrinsics: Intrinsics, extrinsics: &Extrinsics) -> Self {
        Self {
            intrinsics,
            camera_from_world: extrinsics.world_from_camera.inverse(),
        }
    }

    /// The colour intrinsics.
    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// The pixel (u, v) [px] of a workspace point [m]; `None` behind (or within 1 cm of) the
    /// camera plane. The pixel may lie outside the image.
    pub fn pixel(&self, p: &Vec3) -> Option<(f64, f64)> {
        let c = self.camera_from_world * Point3::from(*p);
        if c.z < NEAR_M {
            return None;
        }
        self.intrinsics.project(&c)
    }

    /// The image segment [px] of the workspace segment a–b [m], clipped to the part in front of
    /// the camera (z ≥ 1 cm); `None` when all of it is behind.
    pub fn segment(&self, a: &Vec3, b: &Vec3) -> Option<((f64, f64), (f64, f64))> {
        let mut ca = self.camera_from_world * Point3::from(*a);
        let mut cb = self.camera_from_world * Point3::from(*b);
        if ca.z < NEAR_M && cb.z < NEAR_M {
            return None;
        }
        if ca.z < NEAR_M {
            ca = cb + (ca - cb) * ((cb.z - NEAR_M) / (cb.z - ca.z));
        } else if cb.z < NEAR_M {
            cb = ca + (cb - ca) * ((ca.z - NEAR_M) / (ca.z - cb.z));
        }
        Some((self.intrinsics.project(&ca)?, self.intrinsics.project(&cb)?))
    }
}

/// Runs `f` on a `Mat` (CV_8UC3, channels R, G, B) that borrows the image's pixels.
fn with_mat<R>(
    img: &mut RgbImage,
    f: impl FnOnce(&mut BoxedRefMut<'_, Mat>) -> opencv::Result<R>,
) -> Result<R> {
    if !img.is_well_formed() {
        return Err(AssessError::Vision {
            operation: "draw",
            message: format!(
                "malformed image: {} x {} px with {} bytes",
                img.width,
                img.height,
                img.data.len()
            ),
        });
    }
    let (rows, cols) = (to_i32(img.height)?, to_i32(img.width)?);
    let mut mat =
        Mat::new_rows_cols_with_bytes_mut::<Vec3b>(rows, cols, &mut img.data).map_err(cv_err)?;
    f(&mut mat).map_err(cv_err)
}

fn to_i32(v: u32) -> Result<i32> {
    i32::try_from(v).map_err(|_| AssessError::Vision {
        operation: "draw",
        message: format!("image side {v} px is too large"),
    })
}

fn cv_err(e: opencv::Error) -> AssessError {
    AssessError::Vision {
        operation: "draw",
        message: e.to_string(),
    }
}

fn scalar(c: Colour) -> Scalar {
    Scalar::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2]), 255.0)
}

/// Fixed-point shift for sub-pixel drawing (OpenCV's `shift`): coordinates × 16.
const SHIFT: i32 = 4;

fn fixed(p: (f64, f64)) -> Point {
    // Callers clip to the image (± a margin) first, so the products fit i32 comfortably.
    Point::new((p.0 * 16.0).round() as i32, (p.1 * 16.0).round() as i32)
}

/// Clips the segment a–b to the rectangle [x0, x1] × [y0, y1] (Liang–Barsky); `None` when it
/// misses the rectangle or a coordinate is not finite.
fn clip_segment(
    a: (f64, f64),
    b: (f64, f64),
    (x0, y0, x1, y1): (f64, f64, f64, f64),
) -> Option<((f64, f64), (f64, f64))> {
    if ![a.0, a.1, b.0, b.1].iter().all(|v| v.is_finite()) {
        return None;
    }
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
    for (p, q) in [
        (-dx, a.0 - x0),
        (dx, x1 - a.0),
        (-dy, a.1 - y0),
        (dy, y1 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then(|| {
        (
            (a.0 + t0 * dx, a.1 + t0 * dy),
            (a.0 + t1 * dx, a.1 + t1 * dy),
        )
    })
}

/// The drawable rectangle of an image [px], with a margin for line thickness.
fn bounds(img: &RgbImage) -> (f64, f64, f64, f64) {
    let m = 8.0;
    (
        -m,
        -m,
        f64::from(img.width) - 1.0 + m,
        f64::from(img.height) - 1.0 + m,
    )
}

/// Draws a line between two image points [px] (anti-aliased, `thickness` [px]); the part
/// outside the image is clipped away.
pub fn line(
    img: &mut RgbImage,
    a: (f64, f64),
    b: (f64, f64),
    colour: Colour,
    thickness: u32,
) -> Result<()> {
    let Some((a, b)) = clip_segment(a, b, bounds(img)) else {
        return Ok(());
    };
    let t = thickness.clamp(1, 64) as i32;
    with_mat(img, |m| {
        imgproc::line(
            m,
            fixed(a),
            fixed(b),
            scalar(colour),
            t,
            imgproc::LINE_AA,
            SHIFT,
        )
    })
}

/// Draws a filled disc of `radius` [px] at an image point [px]; nothing when it is outside.
pub fn dot(img: &mut RgbImage, p: (f64, f64), radius: u32, colour: Colour) -> Result<()> {
    let (x0, y0, x1, y1) = bounds(img);
    let r = f64::from(radius.clamp(1, 64));
    if !(p.0.is_finite() && p.1.is_finite())
        || p.0 < x0 - r
        || p.0 > x1 + r
        || p.1 < y0 - r
        || p.1 > y1 + r
    {
        return Ok(());
    }
    let radius = (r * 16.0) as i32;
    with_mat(img, |m| {
        imgproc::circle(
            m,
            fixed(p),
            radius,
            scalar(colour),
            imgproc::FILLED,
            imgproc::LINE_AA,
            SHIFT,
        )
    })
}

/// Text height scale for an image: Hershey simplex at 0.5 for 480 rows, growing with the image.
fn text_scale(img: &RgbImage) -> f64 {
    (f64::from(img.height) / 960.0).clamp(0.4, 2.0)
}

/// Draws one line of text with its baseline starting at `origin` [px], on a dark box for
/// legibility. Text outside the image is clipped.
pub fn text(img: &mut RgbImage, s: &str, origin: (f64, f64), colour: Colour) -> Result<()> {
    if !(origin.0.is_finite() && origin.1.is_finite()) {
        return Ok(());
    }
    let scale = text_scale(img);
    let thickness = if scale > 1.0 { 2 } else { 1 };
    let (x0, y0, x1, y1) = bounds(img);
    let org = Point::new(
        origin.0.clamp(x0 - 4096.0, x1 + 4096.0) as i32,
        origin.1.clamp(y0 - 4096.0, y1 + 4096.0) as i32,
    );
    with_mat(img, |m| {
        let mut baseline = 0;
        let size = imgproc::get_text_size(
            s,
            imgproc::FONT_HERSHEY_SIMPLEX,
            scale,
            thickness,
            &mut baseline,
        )?;
        let pad = 3;
        let bg = Rect::new(
            org.x - pad,
            org.y - size.height - pad,
            size.width + 2 * pad,
            size.height + baseline + 2 * pad,
        );
        imgproc::rectangle(m, bg, Scalar::all(0.0), imgproc::FILLED, imgproc::LINE_8, 0)?;
        imgproc::put_text(
            m,
            s,
            org,
            imgproc::FONT_HERSHEY_SIMPLEX,
            scale,
            scalar(colour),
            thickness,
            imgproc::LINE_AA,
            false,
        )
    })
}

/// Draws text lines (indicator values, status) stacked from the top-left corner.
pub fn text_lines<S: AsRef<str>>(img: &mut RgbImage, lines: &[S], colour: Colour) -> Result<()> {
    let step = 30.0 * text_scale(img) + 8.0;
    for (k, s) in lines.iter().enumerate() {
        text(img, s.as_ref(), (8.0, step * (k as f64 + 1.0)), colour)?;
    }
    Ok(())
}

/// The drawing position [px] of a landmark (half a pixel left and up of MediaPipe's continuous
/// coordinates).
fn landmark_px(l: &Landmark) -> (f64, f64) {
    (l.x - 0.5, l.y - 0.5)
}

fn skeleton(
    img: &mut RgbImage,
    points: &[Landmark],
    connections: &[(usize, usize)],
    visible: impl Fn(&Landmark) -> bool,
    colour: Colour,
    thickness: u32,
    radius: u32,
) -> Result<()> {
    for &(i, j) in connections {
        if let (Some(a), Some(b)) = (points.get(i), points.get(j))
            && visible(a)
            && visible(b)
        {
            line(img, landmark_px(a), landmark_px(b), colour, thickness)?;
        }
    }
    for p in points.iter().filter(|p| visible(p)) {
        dot(img, landmark_px(p), radius, colour)?;
    }
    Ok(())
}

/// Draws the landmarks: the pose skeleton (points with visibility and presence ≥
/// [`MIN_VISIBILITY`]) in white, hands with their skeletons (right hand green, left orange) and
/// the face mesh as small cyan dots. Line widths grow with the image size.
pub fn landmarks(img: &mut RgbImage, lm: &Landmarks) -> Result<()> {
    let w = (img.height / 360).max(1);
    if let Some(face) = &lm.face {
        for p in &face.points {
            dot(img, landmark_px(p), 1, CYAN)?;
        }
    }
    if let Some(pose) = &lm.pose {
        skeleton(
            img,
            &pose.points,
            &POSE_CONNECTIONS,
            |p| p.visibility >= MIN_VISIBILITY && p.presence >= MIN_VISIBILITY,
            WHITE,
            w * 2,
            w * 3,
        )?;
    }
    for hand in &lm.hands {
        let colour = if hand.right_hand >= 0.5 {
            GREEN
        } else {
            ORANGE
        };
        skeleton(
            img,
            &hand.points,
            &HAND_CONNECTIONS,
            |_| true,
            colour,
            w,
            w * 2,
        )?;
    }
    Ok(())
}

/// Draws a projected 3-D segment a–b (workspace frame [m]); the part behind the camera or
/// outside the image is clipped away.
pub fn segment_3d(
    img: &mut RgbImage,
    proj: &Projector,
    a: &Vec3,
    b: &Vec3,
    colour: Colour,
    thickness: u32,
) -> Result<()> {
    match proj.segment(a, b) {
        Some((pa, pb)) => line(img, pa, pb, colour, thickness),
        None => Ok(()),
    }
}

/// Draws the head ray: from the head position along the facing direction for `length_m` [m]
/// (workspace frame), with a dot at the head.
pub fn head_ray(
    img: &mut RgbImage,
    proj: &Projector,
    head: &Vec3,
    facing: &Vec3,
    length_m: f64,
) -> Result<()> {
    let n = facing.norm();
    if !(n.is_finite() && n > 1e-9 && length_m.is_finite()) {
        return Ok(());
    }
    let tip = head + facing * (length_m / n);
    segment_3d(img, proj, head, &tip, MAGENTA, 3)?;
    if let Some(p) = proj.pixel(head) {
        dot(img, p, 5, MAGENTA)?;
    }
    Ok(())
}

/// The 12 edges of a box, as corner index pairs of [`crate::AreaBox::corners`] (bit 0: x,
/// bit 1: y, bit 2: z).
const BOX_EDGES: [(usize, usize); 12] = [
    (0, 1),
    (2, 3),
    (4, 5),
    (6, 7),
    (0, 2),
    (1, 3),
    (4, 6),
    (5, 7),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
];

/// Draws every workspace area as its projected box edges with its name at the top centre; the
/// `confirmed` area is drawn thick in yellow and labelled `[name]`, the others thin in cyan.
pub fn areas(
    img: &mut RgbImage,
    proj: &Projector,
    workspace: &Workspace,
    confirmed: Option<AreaId>,
) -> Result<()> {
    for (i, area) in workspace.areas().iter().enumerate() {
        let is_confirmed = confirmed == Some(AreaId(i));
        let (colour, thickness) = if is_confirmed { (YELLOW, 4) } else { (CYAN, 2) };
        let corners = area.shape.corners();
        for (a, b) in BOX_EDGES {
            if let (Some(a), Some(b)) = (corners.get(a), corners.get(b)) {
                segment_3d(img, proj, a, b, colour, thickness)?;
            }
        }
        let top: Vec3 = corners.iter().skip(4).sum::<Vec3>() / 4.0;
        if let Some(p) = proj.pixel(&top) {
            let label = if is_confirmed {
                format!("[{}]", area.name)
            } else {
                area.name.clone()
            };
            text(img, &label, (p.0 - 20.0, p.1 - 8.0), colour)?;
        }
    }
    Ok(())
}

/// Draws the axes of a frame placed at `world_from_frame` (x red, y green, z blue), each
/// `length_m` [m] long.
pub fn axes(
    img: &mut RgbImage,
    proj: &Projector,
    world_from_frame: &Isometry3<f64>,
    length_m: f64,
) -> Result<()> {
    let o = world_from_frame.translation.vector;
    for (axis, colour) in [(Vec3::x(), RED), (Vec3::y(), GREEN), (Vec3::z(), BLUE)] {
        let tip = world_from_frame * Point3::from(axis * length_m);
        segment_3d(img, proj, &o, &tip.coords, colour, 3)?;
    }
    Ok(())
}
