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
    (t0 <= t1).then_some((
        (a.0 + t0 * dx, a.1 + t0 * dy),
        (a.0 + t1 * dx, a.1 + t1 * dy),
    ))
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
    let scale = text_scale(img);
    text_at_scale(img, s, origin, colour, scale)
}

/// Like [`text`], with capital letters about `height` [px] tall (at least 4 px).
pub fn text_with_height(
    img: &mut RgbImage,
    s: &str,
    origin: (f64, f64),
    colour: Colour,
    height: f64,
) -> Result<()> {
    // Hershey simplex capitals are 22 px tall at scale 1.
    let scale = if height.is_finite() {
        height.max(4.0) / 22.0
    } else {
        1.0
    };
    text_at_scale(img, s, origin, colour, scale)
}

fn text_at_scale(
    img: &mut RgbImage,
    s: &str,
    origin: (f64, f64),
    colour: Colour,
    scale: f64,
) -> Result<()> {
    if !(origin.0.is_finite() && origin.1.is_finite()) {
        return Ok(());
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::landmarks::{HandLandmarks, PoseLandmarks};
    use crate::vision::roi::Roi;

    fn img() -> RgbImage {
        RgbImage::black(200, 100)
    }

    fn px(img: &RgbImage, u: u32, v: u32) -> [u8; 3] {
        let i = ((v * img.width + u) * 3) as usize;
        [img.data[i], img.data[i + 1], img.data[i + 2]]
    }

    /// A camera at the workspace origin looking along +x, z up (image x = -y, image y = -z).
    fn projector() -> Projector {
        let r = nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_columns(&[
            -Vec3::y(),
            -Vec3::z(),
            Vec3::x(),
        ]));
        let e = Extrinsics {
            world_from_camera: Isometry3::from_parts(
                nalgebra::Translation3::identity(),
                nalgebra::UnitQuaternion::from_rotation_matrix(&r),
            ),
        };
        Projector::new(Intrinsics::from_hfov(200, 100, 90.0), &e)
    }

    #[test]
    fn line_draws_its_pixels_in_rgb_order() {
        let mut im = img();
        line(&mut im, (10.0, 50.0), (190.0, 50.0), RED, 3).expect("line");
        assert_eq!(px(&im, 100, 50), RED);
        assert_eq!(px(&im, 100, 20), [0, 0, 0]);
    }

    #[test]
    fn out_of_image_and_non_finite_input_is_ignored() {
        let mut im = img();
        line(&mut im, (-500.0, -10.0), (-100.0, -300.0), RED, 3).expect("outside");
        line(&mut im, (f64::NAN, 0.0), (10.0, 10.0), RED, 3).expect("nan");
        line(&mut im, (-1e300, 20.0), (1e300, 80.0), RED, 1).expect("absurd: no panic");
        let absurd = im.data.chunks(3).filter(|p| p != &[0, 0, 0]).count();
        assert!(absurd < 50, "{absurd}");
        im = img();
        line(&mut im, (-1e7, 50.0), (1e7, 50.0), RED, 3).expect("far ends");
        dot(&mut im, (1e9, 1e9), 5, RED).expect("far dot");
        dot(&mut im, (f64::INFINITY, 3.0), 5, RED).expect("inf dot");
        text(&mut im, "far away", (1e12, -1e12), WHITE).expect("far text");
        // Only the long horizontal line, clipped to the image, was drawn.
        let changed = im.data.chunks(3).filter(|p| p != &[0, 0, 0]).count();
        assert!((3 * 200..=8 * 200).contains(&changed), "{changed}");
        assert_eq!(px(&im, 100, 50), RED);
        let mut small = RgbImage {
            width: 10,
            height: 10,
            data: vec![0; 5],
        };
        assert!(line(&mut small, (0.0, 0.0), (5.0, 5.0), RED, 1).is_err());
    }

    #[test]
    fn segment_behind_the_camera_is_clipped() {
        let p = projector();
        // From 1 m ahead to 1 m behind, 0.2 m up: the visible half ends at the top edge.
        let seg = p
            .segment(&Vec3::new(1.0, 0.0, 0.2), &Vec3::new(-1.0, 0.0, 0.2))
            .expect("half visible");
        assert!((seg.0.0 - 100.0).abs() < 1e-9 && (seg.0.1 - 30.0).abs() < 1e-9);
        assert!(seg.1.1 < -1000.0, "towards the top, far out: {:?}", seg.1);
        assert!(
            p.segment(&Vec3::new(-1.0, 0.0, 0.0), &Vec3::new(-2.0, 0.0, 0.0))
                .is_none()
        );
        assert!(p.pixel(&Vec3::new(-1.0, 0.0, 0.0)).is_none());
    }

    #[test]
    fn head_ray_areas_and_axes_land_where_projected() {
        let p = projector();
        let mut im = img();
        // Head 2 m ahead, looking to its left (+y): the ray runs left from the centre.
        head_ray(&mut im, &p, &Vec3::new(2.0, 0.0, 0.0), &Vec3::y(), 0.5).expect("ray");
        assert_eq!(px(&im, 90, 50), MAGENTA);
        assert_eq!(px(&im, 110, 50), [0, 0, 0]);
        // Behind the camera: nothing, no error.
        let before = im.clone();
        head_ray(&mut im, &p, &Vec3::new(-2.0, 0.0, 0.0), &Vec3::y(), 0.5).expect("behind");
        assert_eq!(im, before);

        let ws = Workspace::from_toml_str(
            r#"
            [[area]]
            name = "left"
            min_m = [2.0, 0.3, -0.2]
            max_m = [2.4, 0.7, 0.2]
            [[area]]
            name = "right"
            min_m = [2.0, -0.7, -0.2]
            max_m = [2.4, -0.3, 0.2]
            "#,
        )
        .expect("workspace");
        let mut im = img();
        areas(&mut im, &p, &ws, Some(AreaId(1))).expect("areas");
        // Near vertical edges at u = 100 ∓ 100 * 0.3 / 2 = 85 (left) and 115 (right), v = 50.
        assert_eq!(px(&im, 85, 50), CYAN);
        assert_eq!(px(&im, 115, 50), YELLOW);

        let mut im = img();
        let at = Isometry3::translation(2.0, 0.0, 0.0);
        axes(&mut im, &p, &at, 0.4).expect("axes");
        assert_eq!(px(&im, 100, 40), BLUE, "z up");
        assert_eq!(px(&im, 90, 50), GREEN, "y left");
    }

    #[test]
    fn landmarks_draw_skeletons_and_skip_invisible_points() {
        let mut points = [Landmark {
            visibility: 1.0,
            presence: 1.0,
            ..Landmark::default()
        }; 33];
        points[11].x = 60.5;
        points[11].y = 40.5;
        points[12].x = 140.5;
        points[12].y = 40.5;
        points[13] = Landmark {
            x: 60.5,
            y: 90.5,
            visibility: 0.1,
            ..points[13]
        };
        let roi = Roi {
            cx: 0.0,
            cy: 0.0,
            width: 1.0,
            height: 1.0,
            rotation: 0.0,
        };
        let mut hand = [Landmark::default(); 21];
        for (i, p) in hand.iter_mut().enumerate() {
            p.x = 20.5 + i as f64;
            p.y = 80.5;
        }
        let lm = Landmarks {
            pose: Some(PoseLandmarks {
                points,
                score: 1.0,
                roi,
            }),
            face: None,
            hands: vec![HandLandmarks {
                points: hand,
                score: 1.0,
                right_hand: 0.9,
                roi,
            }],
        };
        let mut im = img();
        landmarks(&mut im, &lm).expect("draw");
        assert_eq!(px(&im, 100, 40), WHITE, "shoulder line");
        assert_eq!(px(&im, 60, 65), [0, 0, 0], "invisible elbow: no upper arm");
        assert_eq!(px(&im, 30, 80), GREEN, "right hand");
    }

    #[test]
    fn text_lines_write_top_left() {
        let mut im = RgbImage::black(300, 200);
        im.data.iter_mut().for_each(|b| *b = 90);
        text_lines(&mut im, &["AED 0.42", "HRC-CWL 0.61"], WHITE).expect("text");
        let top = im.data[..300 * 60 * 3].iter().filter(|&&b| b != 90).count();
        let bottom = im.data[300 * 120 * 3..]
            .iter()
            .filter(|&&b| b != 90)
            .count();
        assert!(top > 200, "{top}");
        assert_eq!(bottom, 0);
    }
}
