//! Landmarks → head, upper-body and hand cues in the workspace frame [m].
//!
//! - **Head** (with depth): the face-mesh points are lifted to 3-D with the depth image and
//!   MediaPipe's canonical face model is fitted to them (weighted Umeyama/Kabsch, one round of
//!   outlier rejection). The head position is the canonical model's origin (inside the head,
//!   behind the nose) and the facing vector its +z axis (out of the face). Without usable
//!   depth: OpenCV's `solvePnP` of the canonical model against the 2-D points with the colour
//!   intrinsics; the cue is then flagged [`CueQuality::Image2d`].
//! - **Upper body**: the shoulder midpoint, and the chest normal
//!   (left − right shoulder) × (shoulder midpoint − hip midpoint), or with the hips out of view
//!   (shoulder midpoint − nose) rotated into the same cross product with lower confidence.
//!   Shoulder depth is sampled 15 % of the way in toward the other shoulder, so the patch
//!   lands on the body rather than the background behind the outline.
//! - **Hands**: the palm centre (mean of the wrist and the four knuckles) in 3-D from a
//!   median depth patch, else the wrist; hands are assigned left/right by the nearest pose
//!   wrist, else by the model's handedness. With no hand landmarks, the pose wrist stands in
//!   with half its visibility as confidence.
//! - **Confidence** per cue: landmark score × share of valid depth × temporal consistency
//!   (1 while the cue moves slower than `max_speed_m_s`, falling as v_max / v beyond).
//! - **Smoothing**: a One-Euro filter on head and body position and facing. Hand positions are
//!   *not* filtered here, because the assessor filters them itself ([`spec`](crate::spec) §7) and
//!   the hand speed it computes must not be filtered twice.
//!
//! Without depth (a webcam), body and hand depth come from the head's PnP distance (or from an
//! assumed shoulder width), so positions are rough: the frame is flagged
//! [`CueQuality::Image2d`].

use std::path::Path;

use nalgebra::{Point3, Vector3};

use super::frame::{DepthImage, Extrinsics, Intrinsics};
use super::geometry::{self, fit_similarity};
use super::landmarks::{HandLandmarks, Landmark, Landmarks, PoseLandmarks};
use crate::filter::OneEuro3;
use crate::{AssessError, BodyCue, CueFrame, HandCue, HeadCue, OneEuroConfig, Result, Vec3};

/// Whether a frame's cues are metric 3-D (from depth) or estimated from the image alone.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CueQuality {
    /// Positions from the depth image.
    Depth3d,
    /// No usable depth: positions estimated from the image (PnP, assumed sizes); 2-D-only.
    Image2d,
}

impl CueQuality {
    /// Name as written in logs.
    pub fn name(self) -> &'static str {
        match self {
            CueQuality::Depth3d => "depth",
            CueQuality::Image2d => "2d",
        }
    }
}

/// Cue-extraction settings.
#[derive(Debug, Clone, PartialEq)]
pub struct CueConfig {
    /// Half-size of the depth median patch [px] (2 → 5 × 5).
    pub depth_patch_radius_px: u32,
    /// Valid depth range [m].
    pub depth_range_m: (f64, f64),
    /// Speed above which a cue's temporal consistency falls [m/s].
    pub max_speed_m_s: f64,
    /// One-Euro filter of head and body positions (units: m).
    pub position_filter: OneEuroConfig,
    /// One-Euro filter of head and body facing vectors (units: unit vector).
    pub facing_filter: OneEuroConfig,
    /// Shoulder width assumed to estimate depth without a depth image [m].
    pub assumed_shoulder_width_m: f64,
    /// Minimum visibility of a pose landmark to be used [-].
    pub min_visibility: f64,
}

impl Default for CueConfig {
    fn default() -> Self {
        Self {
            depth_patch_radius_px: 2,
            depth_range_m: (0.2, 4.0),
            max_speed_m_s: 3.0,
            position_filter: OneEuroConfig {
                min_cutoff_hz: 1.0,
                beta: 0.5,
                d_cutoff_hz: 1.0,
            },
            facing_filter: OneEuroConfig {
                min_cutoff_hz: 1.5,
                beta: 0.3,
                d_cutoff_hz: 1.0,
            },
            assumed_shoulder_width_m: 0.38,
            min_visibility: 0.5,
        }
    }
}

/// One frame's cues with what the assessor does not need but the log and overlay do.
#[derive(Debug, Clone, PartialEq)]
pub struct PerceivedCues {
    /// The cues in the workspace frame (robot context left at its default: the caller sets
    /// C and G).
    pub frame: CueFrame,
    /// Whether positions came from depth.
    pub quality: CueQuality,
    /// Head position in the camera frame [m], for overlays.
    pub head_camera: Option<(Point3<f64>, Vector3<f64>)>,
    /// RMS residual of the canonical-face fit [m] (depth only).
    pub head_fit_rms_m: Option<f64>,
}

/// The 468 points of MediaPipe's canonical face model [m].
pub fn load_canonical_face(path: &Path) -> Result<Vec<Point3<f64>>> {
    let text = crate::error::read_text(path)?;
    let mut points = Vec::with_capacity(468);
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') || line.starts_with("index") {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let parse = |i: usize| -> Result<f64> {
            fields
                .get(i)
                .and_then(|s| s.parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(|| AssessError::Csv {
                    path: path.to_path_buf(),
                    line: n as u64 + 1,
                    column: i + 1,
                    message: format!("expected `index,x,y,z` numbers, found `{line}`"),
                })
        };
        let index = parse(0)? as usize;
        if index != points.len() {
            return Err(AssessError::Csv {
                path: path.to_path_buf(),
                line: n as u64 + 1,
                column: 1,
                message: format!("index {index} out of order (expected {})", points.len()),
            });
        }
        // The model is in centimetres.
        points.push(Point3::new(parse(1)?, parse(2)?, parse(3)?) * 0.01);
    }
    if points.len() != 468 {
        return Err(AssessError::InvalidValue {
            key: path.display().to_string(),
            rule: format!("the canonical face has 468 points, found {}", points.len()),
        });
    }
    Ok(points)
}

/// Temporal-consistency state of one cue.
#[derive(Debug, Clone, Copy, Default)]
struct Track {
    last: Option<(f64, Point3<f64>)>,
}

impl Track {
    /// The consistency factor of a new observation, and remembers it.
    fn factor(&mut self, t: f64, p: Point3<f64>, max_speed: f64) -> f64 {
        let f = match self.last {
            Some((t0, p0)) if t > t0 && t - t0 < 0.5 => {
                let v = (p - p0).norm() / (t - t0);
                if v <= max_speed { 1.0 } else { max_speed / v }
            }
            _ => 1.0,
        };
        self.last = Some((t, p));
        f
    }
}

/// A One-Euro-filtered position and facing, reset after a gap.
#[derive(Debug, Clone, Copy)]
struct Smoother {
    position: OneEuro3,
    facing: OneEuro3,
    last_t: Option<f64>,
}

impl Smoother {
    fn new(cfg: &CueConfig) -> Self {
        Self {
            position: OneEuro3::new(cfg.position_filter),
            facing: OneEuro3::new(cfg.facing_filter),
            last_t: None,
        }
    }

    fn apply(&mut self, t: f64, p: Vec3, f: Vec3) -> (Vec3, Vec3) {
        let dt = match self.last_t {
            Some(t0) if t > t0 && t - t0 < 0.5 => t - t0,
            _ => {
                self.position.reset();
                self.facing.reset();
                0.0
            }
        };
        self.last_t = Some(t);
        let p = Vec3::from(self.position.filter(p.into(), dt));
        let f = Vec3::from(self.facing.filter(f.normalize().into(), dt));
        (p, f)
    }
}

/// The state of a cue with a position and a facing (head, body): temporal consistency and
/// One-Euro smoothing, in the workspace frame.
#[derive(Debug, Clone, Copy)]
struct OrientedCue {
    track: Track,
    smooth: Smoother,
}

impl OrientedCue {
    fn new(cfg: &CueConfig) -> Self {
        Self {
            track: Track::default(),
            smooth: Smoother::new(cfg),
        }
    }

    /// A camera-frame observation (point [m], facing, confidence) → smoothed workspace
    /// position [m], facing and confidence scaled by temporal consistency.
    fn observe(
        &mut self,
        t: f64,
        (p, f, c): (Point3<f64>, Vector3<f64>, f64),
        extrinsics: &Extrinsics,
        max_speed: f64,
    ) -> (Vec3, Vec3, f64) {
        let pw = extrinsics.point_to_world(&p);
        let fw = extrinsics.dir_to_world(&f);
        let consistency = self.track.factor(t, pw, max_speed);
        let (ps, fs) = self.smooth.apply(t, pw.coords, fw);
        (ps, fs, (c * consistency).clamp(0.0, 1.0))
    }
}

/// Turns landmarks into cues, frame by frame (it keeps filter and consistency state).
#[derive(Debug)]
pub struct CueExtractor {
    config: CueConfig,
    extrinsics: Extrinsics,
    canonical: Vec<Point3<f64>>,
    head_cue: OrientedCue,
    body_cue: OrientedCue,
    hand_tracks: [Track; 2],
    scratch: Vec<f64>,
}

impl CueExtractor {
    /// An extractor with the canonical face (468 points [m], [`load_canonical_face`]).
    pub fn new(
        config: CueConfig,
        extrinsics: Extrinsics,
        canonical: Vec<Point3<f64>>,
    ) -> Result<Self> {
        if canonical.len() != 468 {
            return Err(AssessError::invalid(
                "canonical_face",
                format!("needs 468 points, got {}", canonical.len()),
            ));
        }
        Ok(Self {
            head_cue: OrientedCue::new(&config),
            body_cue: OrientedCue::new(&config),
            config,
            extrinsics,
            canonical,
            hand_tracks: [Track::default(); 2],
            scratch: Vec::with_capacity(64),
        })
    }

    /// The extrinsics in use.
    pub fn extrinsics(&self) -> &Extrinsics {
        &self.extrinsics
    }

    /// Cues of one frame at camera time `t` [s].
    pub fn extract(
        &mut self,
        t: f64,
        landmarks: &Landmarks,
        depth: Option<&DepthImage>,
        intrinsics: &Intrinsics,
    ) -> PerceivedCues {
        let depth = depth.filter(|d| d.width == intrinsics.width && d.height == intrinsics.height);
        let mut frame = CueFrame::empty(t);
        let mut quality = if depth.is_some() {
            CueQuality::Depth3d
        } else {
            CueQuality::Image2d
        };
        let mut head_camera = None;
        let mut head_fit_rms_m = None;

        // Head.
        let head = landmarks.face.as_ref().and_then(|face| {
            let fitted = depth.and_then(|d| self.head_from_depth(&face.points, d, intrinsics));
            match fitted {
                Some((p, f, valid, rms)) => {
                    head_fit_rms_m = Some(rms);
                    let fit = if rms <= 0.01 { 1.0 } else { 0.01 / rms };
                    Some((p, f, face.score * valid * fit))
                }
                None => {
                    quality = CueQuality::Image2d;
                    self.head_from_pnp(&face.points, intrinsics)
                        .map(|(p, f)| (p, f, face.score * 0.8))
                }
            }
        });
        if let Some((p, f, c)) = head {
            head_camera = Some((p, f));
            let (position, facing, confidence) =
                self.head_cue
                    .observe(t, (p, f, c), &self.extrinsics, self.config.max_speed_m_s);
            frame.head = Some(HeadCue {
                position,
                facing,
                confidence,
            });
        }

        // A depth stand-in without a depth image: the head's distance, else the shoulder
        // width.
        let fallback_z = head_camera.map(|(p, _)| p.z).or_else(|| {
            landmarks
                .pose
                .as_ref()
                .and_then(|p| self.z_from_shoulders(p, intrinsics))
        });

        // Upper body.
        if let Some(pose) = landmarks.pose.as_ref()
            && let Some((p, f, c, q)) = self.body(pose, depth, intrinsics, fallback_z)
        {
            if q == CueQuality::Image2d {
                quality = CueQuality::Image2d;
            }
            let (position, facing, confidence) =
                self.body_cue
                    .observe(t, (p, f, c), &self.extrinsics, self.config.max_speed_m_s);
            frame.body = Some(BodyCue {
                position,
                facing,
                confidence,
            });
        }

        // Hands.
        let hands = self.hands(landmarks, depth, intrinsics, fallback_z);
        for (slot, hand) in hands.into_iter().enumerate() {
            if let Some((p, c)) = hand {
                let pw = self.extrinsics.point_to_world(&p);
                let consistency = self.hand_tracks[slot].factor(t, pw, self.config.max_speed_m_s);
                frame.hands[slot] = Some(HandCue {
                    position: pw.coords,
                    confidence: (c * consistency).clamp(0.0, 1.0),
                });
            }
        }
        PerceivedCues {
            frame,
            quality,
            head_camera,
            head_fit_rms_m,
        }
    }

    /// Head position and facing (camera frame), share of valid points, fit RMS [m].
    fn head_from_depth(
        &mut self,
        points: &[Landmark],
        depth: &DepthImage,
        intr: &Intrinsics,
    ) -> Option<(Point3<f64>, Vector3<f64>, f64, f64)> {
        let mut model = Vec::with_capacity(points.len());
        let mut observed = Vec::with_capacity(points.len());
        for (lm, m) in points.iter().zip(&self.canonical) {
            if let Some(p) = geometry::lift(
                depth,
                intr,
                lm.x,
                lm.y,
                1,
                self.config.depth_range_m,
                &mut self.scratch,
            ) {
                model.push(*m);
                observed.push(p);
            }
        }
        let valid = observed.len() as f64 / points.len().max(1) as f64;
        if observed.len() < 30 {
            return None;
        }
        // Depth at the face outline often hits the background: drop points far from the
        // median depth, fit, drop large residuals, fit again.
        let mut zs: Vec<f64> = observed.iter().map(|p| p.z).collect();
        zs.sort_by(f64::total_cmp);
        let z_med = zs[zs.len() / 2];
        let mut weights: Vec<f64> = observed
            .iter()
            .map(|p| if (p.z - z_med).abs() < 0.10 { 1.0 } else { 0.0 })
            .collect();
        let first = fit_similarity(&model, &observed, &weights, true)?;
        let mut residuals: Vec<f64> = model
            .iter()
            .zip(&observed)
            .map(|(m, o)| (first.apply(m) - o).norm())
            .collect();
        let mut sorted = residuals.clone();
        sorted.sort_by(f64::total_cmp);
        let cut = (3.0 * sorted[sorted.len() / 2]).max(0.01);
        for (w, r) in weights.iter_mut().zip(&mut residuals) {
            if *r > cut {
                *w = 0.0;
            }
        }
        let fit = fit_similarity(&model, &observed, &weights, true)?;
        // A face 0.6–1.6 times the canonical size; anything else is a bad fit.
        if !(0.6..=1.6).contains(&fit.scale) {
            return None;
        }
        let position = fit.apply(&Point3::origin());
        let facing = fit.rotation * Vector3::z();
        Some((position, facing, valid.min(1.0), fit.rms))
    }

    /// Head pose from the 2-D points alone (`solvePnP`, canonical model, no distortion).
    fn head_from_pnp(
        &self,
        points: &[Landmark],
        intr: &Intrinsics,
    ) -> Option<(Point3<f64>, Vector3<f64>)> {
        let (r, t) = pnp(&self.canonical, points, intr)?;
        let position = Point3::from(t);
        let facing = r * Vector3::z();
        Some((position, facing))
    }

    fn z_from_shoulders(&self, pose: &PoseLandmarks, intr: &Intrinsics) -> Option<f64> {
        let (l, r) = (&pose.points[11], &pose.points[12]);
        let px = (l.x - r.x).hypot(l.y - r.y);
        (px > 5.0).then(|| intr.fx * self.config.assumed_shoulder_width_m / px)
    }

    fn point3(
        &mut self,
        u: f64,
        v: f64,
        depth: Option<&DepthImage>,
        intr: &Intrinsics,
        fallback_z: Option<f64>,
        radius: u32,
    ) -> Option<(Point3<f64>, CueQuality)> {
        if let Some(d) = depth {
            return geometry::lift(
                d,
                intr,
                u,
                v,
                radius,
                self.config.depth_range_m,
                &mut self.scratch,
            )
            .map(|p| (p, CueQuality::Depth3d));
        }
        fallback_z.map(|z| (intr.deproject(u, v, z), CueQuality::Image2d))
    }

    /// Shoulder midpoint, chest normal, confidence and quality (camera frame).
    fn body(
        &mut self,
        pose: &PoseLandmarks,
        depth: Option<&DepthImage>,
        intr: &Intrinsics,
        fallback_z: Option<f64>,
    ) -> Option<(Point3<f64>, Vector3<f64>, f64, CueQuality)> {
        let p = &pose.points;
        let vis = self.config.min_visibility;
        let (l, r) = (&p[11], &p[12]);
        if l.visibility < vis || r.visibility < vis {
            return None;
        }
        let r_px = self.config.depth_patch_radius_px;
        // Sample 15 % inward from each shoulder.
        let inward =
            |a: &Landmark, b: &Landmark| (a.x + 0.15 * (b.x - a.x), a.y + 0.15 * (b.y - a.y));
        let (lu, lv) = inward(l, r);
        let (ru, rv) = inward(r, l);
        let (lp, q1) = self.point3(lu, lv, depth, intr, fallback_z, r_px)?;
        let (rp, q2) = self.point3(ru, rv, depth, intr, fallback_z, r_px)?;
        let mid = Point3::from((lp.coords + rp.coords) / 2.0);
        let across = lp - rp;
        let hips_visible = p[23].visibility >= vis && p[24].visibility >= vis;
        let (up, conf_factor) = if hips_visible {
            let hu = (p[23].x + p[24].x) / 2.0;
            let hv = (p[23].y + p[24].y) / 2.0;
            match self.point3(hu, hv, depth, intr, fallback_z, r_px) {
                Some((h, _)) => (mid - h, 1.0),
                None => (self.up_from_nose(p, mid, intr)?, 0.7),
            }
        } else {
            (self.up_from_nose(p, mid, intr)?, 0.7)
        };
        let normal = across.cross(&up);
        if normal.norm() < 1e-6 || !normal.iter().all(|v| v.is_finite()) {
            return None;
        }
        let score = pose.score * l.visibility.min(r.visibility);
        let quality = if q1 == CueQuality::Depth3d && q2 == CueQuality::Depth3d {
            CueQuality::Depth3d
        } else {
            CueQuality::Image2d
        };
        Some((mid, normal.normalize(), score * conf_factor, quality))
    }

    /// "Up" from the shoulder midpoint to the nose, with the nose lifted at the shoulders'
    /// depth: its own depth lies in front of the torso plane and would tilt the normal down.
    fn up_from_nose(
        &self,
        p: &[Landmark; 33],
        mid: Point3<f64>,
        intr: &Intrinsics,
    ) -> Option<Vector3<f64>> {
        let nose = &p[0];
        if nose.visibility < self.config.min_visibility {
            return None;
        }
        let n = intr.deproject(nose.x, nose.y, mid.z);
        let up = n - mid;
        (up.norm() > 1e-6).then_some(up)
    }

    /// Up to two hands: (camera-frame point, confidence) per slot [left, right].
    fn hands(
        &mut self,
        landmarks: &Landmarks,
        depth: Option<&DepthImage>,
        intr: &Intrinsics,
        fallback_z: Option<f64>,
    ) -> [Option<(Point3<f64>, f64)>; 2] {
        let mut out: [Option<(Point3<f64>, f64)>; 2] = [None, None];
        let pose = landmarks.pose.as_ref();
        let mut assigned: [Option<&HandLandmarks>; 2] = [None, None];
        for hand in &landmarks.hands {
            let slot = match pose {
                Some(p) => {
                    let d = |i: usize| {
                        (p.points[i].x - hand.points[0].x).hypot(p.points[i].y - hand.points[0].y)
                    };
                    if d(15) <= d(16) { 0 } else { 1 }
                }
                None => usize::from(hand.right_hand >= 0.5),
            };
            let slot = if assigned[slot].is_some() {
                1 - slot
            } else {
                slot
            };
            if assigned[slot].is_none() {
                assigned[slot] = Some(hand);
            }
        }
        let radius = self.config.depth_patch_radius_px + 1;
        for slot in 0..2 {
            if let Some(hand) = assigned[slot] {
                let palm = [0usize, 5, 9, 13, 17];
                let u = palm.iter().map(|&i| hand.points[i].x).sum::<f64>() / 5.0;
                let v = palm.iter().map(|&i| hand.points[i].y).sum::<f64>() / 5.0;
                let lifted = self
                    .point3(u, v, depth, intr, fallback_z, radius)
                    .map(|(p, _)| (p, 1.0))
                    .or_else(|| {
                        let w = &hand.points[0];
                        self.point3(w.x, w.y, depth, intr, fallback_z, radius)
                            .map(|(p, _)| (p, 0.8))
                    });
                if let Some((p, f)) = lifted {
                    out[slot] = Some((p, hand.score * f));
                }
            } else if let Some(p) = pose {
                let w = &p.points[15 + slot];
                if w.visibility >= self.config.min_visibility
                    && let Some((pt, _)) = self.point3(w.x, w.y, depth, intr, fallback_z, radius)
                {
                    out[slot] = Some((pt, 0.5 * w.visibility * p.score));
                }
            }
        }
        out
    }
}

/// `solvePnP` (iterative, from the EPnP start) of the canonical face [m] against the face
/// landmarks [px]: rotation and translation of the model in the camera frame.
pub fn pnp(
    canonical: &[Point3<f64>],
    points: &[Landmark],
    intr: &Intrinsics,
) -> Option<(nalgebra::Rotation3<f64>, Vector3<f64>)> {
    use opencv::core::{Mat, Point2d, Point3d, Vector};
    use opencv::prelude::*;
    let n = canonical.len().min(points.len());
    if n < 6 {
        return None;
    }
    let object: Vector<Point3d> = canonical[..n]
        .iter()
        .map(|p| Point3d::new(p.x, p.y, p.z))
        .collect();
    let image: Vector<Point2d> = points[..n].iter().map(|p| Point2d::new(p.x, p.y)).collect();
    let k = Mat::from_slice_2d(&[
        [intr.fx, 0.0, intr.cx],
        [0.0, intr.fy, intr.cy],
        [0.0, 0.0, 1.0],
    ])
    .ok()?;
    let dist = Mat::zeros(4, 1, opencv::core::CV_64F).ok()?.to_mat().ok()?;
    let mut rvec = Mat::default();
    let mut tvec = Mat::default();
    let ok = opencv::calib3d::solve_pnp(
        &object,
        &image,
        &k,
        &dist,
        &mut rvec,
        &mut tvec,
        false,
        opencv::calib3d::SOLVEPNP_EPNP,
    )
    .ok()?;
    if !ok {
        return None;
    }
    let _ = opencv::calib3d::solve_pnp(
        &object,
        &image,
        &k,
        &dist,
        &mut rvec,
        &mut tvec,
        true,
        opencv::calib3d::SOLVEPNP_ITERATIVE,
    )
    .ok()?;
    let rv = Vector3::new(
        *rvec.at::<f64>(0).ok()?,
        *rvec.at::<f64>(1).ok()?,
        *rvec.at::<f64>(2).ok()?,
    );
    let tv = Vector3::new(
        *tvec.at::<f64>(0).ok()?,
        *tvec.at::<f64>(1).ok()?,
        *tvec.at::<f64>(2).ok()?,
    );
    if !rv.iter().chain(tv.iter()).all(|v| v.is_finite()) || tv.z <= 0.0 {
        return None;
    }
    Some((nalgebra::Rotation3::new(rv), tv))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::landmarks::{FaceLandmarks, HandLandmarks, PoseLandmarks};
    use crate::vision::models::model_dir;
    use crate::vision::roi::Roi;
    use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion};

    const INTR: Intrinsics = Intrinsics {
        width: 640,
        height: 480,
        fx: 615.0,
        fy: 615.0,
        cx: 320.0,
        cy: 240.0,
    };

    fn canonical() -> Vec<Point3<f64>> {
        load_canonical_face(&model_dir().join("canonical_face_model.csv")).unwrap()
    }

    fn roi() -> Roi {
        Roi {
            cx: 0.0,
            cy: 0.0,
            width: 1.0,
            height: 1.0,
            rotation: 0.0,
        }
    }

    fn lm(p: &Point3<f64>) -> Landmark {
        let (u, v) = INTR.project(p).unwrap();
        Landmark {
            x: u,
            y: v,
            z: 0.0,
            visibility: 1.0,
            presence: 1.0,
        }
    }

    /// A depth image at `far` [m] with each point's depth written into a (2r+1)² patch around
    /// its pixel.
    fn depth_of(points: &[Point3<f64>], far: f64, r: i64) -> DepthImage {
        let mut data = vec![(far * 1000.0) as u16; 640 * 480];
        for p in points {
            let (u, v) = INTR.project(p).unwrap();
            for y in v as i64 - r..=v as i64 + r {
                for x in u as i64 - r..=u as i64 + r {
                    if (0..640).contains(&x) && (0..480).contains(&y) {
                        data[y as usize * 640 + x as usize] = (p.z * 1000.0).round() as u16;
                    }
                }
            }
        }
        DepthImage {
            width: 640,
            height: 480,
            data,
            scale_m: 0.001,
        }
    }

    /// A head turned 30° to its left and 10° down, 0.9 m in front of the camera. The canonical
    /// face is y up, z out of the face; the camera is y down, z forward, so a frontal head is
    /// the rotation diag(1, −1, −1) (180° about x).
    fn head_pose() -> (Rotation3<f64>, nalgebra::Vector3<f64>) {
        let frontal = Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let turn = Rotation3::from_euler_angles(10f64.to_radians(), 30f64.to_radians(), 0.0);
        (turn * frontal, Vector3::new(0.05, -0.1, 0.9))
    }

    fn face_landmarks(canon: &[Point3<f64>]) -> (Landmarks, Vec<Point3<f64>>) {
        let (r, t) = head_pose();
        let cam: Vec<Point3<f64>> = canon
            .iter()
            .map(|q| Point3::from(r * q.coords + t))
            .collect();
        let face = FaceLandmarks {
            points: cam.iter().map(lm).collect(),
            score: 0.9,
            roi: roi(),
        };
        (
            Landmarks {
                face: Some(face),
                ..Default::default()
            },
            cam,
        )
    }

    #[test]
    fn head_pose_from_depth_recovers_a_known_head() {
        let canon = canonical();
        let (landmarks, cam) = face_landmarks(&canon);
        // Background 2.5 m: patches at the face outline partly hit it (outlier rejection).
        let depth = depth_of(&cam, 2.5, 1);
        let mut x = CueExtractor::new(CueConfig::default(), Extrinsics::identity(), canon).unwrap();
        let c = x.extract(0.0, &landmarks, Some(&depth), &INTR);
        assert_eq!(c.quality, CueQuality::Depth3d);
        let head = c.frame.head.unwrap();
        let (r, t) = head_pose();
        let want_facing = r * Vector3::z();
        let angle = head.facing.normalize().angle(&want_facing).to_degrees();
        // Depth is quantised to 1 mm and patches overlap: a few degrees, a few mm.
        assert!(angle < 3.0, "facing off by {angle:.2}°");
        assert!(
            (head.position - t).norm() < 0.01,
            "position {:?}",
            head.position
        );
        assert!(c.head_fit_rms_m.unwrap() < 0.005);
        assert!(head.confidence > 0.5 && head.confidence <= 0.9);
        // The facing points toward the camera side (−z) and to the head's left (+x in the
        // image for a person facing the camera), by construction of the turn.
        assert!(want_facing.z < 0.0);
    }

    #[test]
    fn head_pose_without_depth_uses_pnp_and_is_flagged_2d() {
        let canon = canonical();
        let (landmarks, _) = face_landmarks(&canon);
        let mut x = CueExtractor::new(CueConfig::default(), Extrinsics::identity(), canon).unwrap();
        let c = x.extract(0.0, &landmarks, None, &INTR);
        assert_eq!(c.quality, CueQuality::Image2d);
        let head = c.frame.head.unwrap();
        let (r, t) = head_pose();
        let angle = head
            .facing
            .normalize()
            .angle(&(r * Vector3::z()))
            .to_degrees();
        // Exact projections: PnP recovers the pose to numerical precision.
        assert!(angle < 0.1, "facing off by {angle:.3}°");
        assert!((head.position - t).norm() < 1e-3);
    }

    fn pose_at(points: &[(usize, Point3<f64>)]) -> PoseLandmarks {
        let mut p = [Landmark::default(); 33];
        for (i, q) in points {
            p[*i] = lm(q);
        }
        PoseLandmarks {
            points: p,
            score: 0.95,
            roi: roi(),
        }
    }

    #[test]
    fn torso_and_hands_from_a_known_body() {
        // A person facing the camera at 1.2 m: their left shoulder (11) on the image's right
        // (+x), hips 0.3 m below the shoulders (+y is down; inside the image). Chest normal:
        // (L − R) × (S_mid − H_mid) = (0.38, 0, 0) × (0, −0.3, 0) = (0, 0, −0.114) → toward the
        // camera.
        let z = 1.2;
        let l = Point3::new(0.19, 0.0, z);
        let r = Point3::new(-0.19, 0.0, z);
        let pose = pose_at(&[
            (11, l),
            (12, r),
            (23, Point3::new(0.15, 0.3, z)),
            (24, Point3::new(-0.15, 0.3, z)),
            (15, Point3::new(0.25, 0.3, 0.9)),
            (16, Point3::new(-0.25, 0.3, 0.9)),
            (0, Point3::new(0.0, -0.25, z - 0.1)),
        ]);
        // The left hand's palm at 0.9 m; its 21 landmarks sit on one pixel cluster.
        let palm = Point3::new(0.25, 0.3, 0.9);
        let mut hp = [Landmark::default(); 21];
        for (i, p) in hp.iter_mut().enumerate() {
            *p = lm(&Point3::new(
                palm.x + 0.002 * (i % 3) as f64,
                palm.y,
                palm.z,
            ));
        }
        let hand = HandLandmarks {
            points: hp,
            score: 0.8,
            right_hand: 0.1,
            roi: roi(),
        };
        // Depth: the torso plane at 1.2 m, the hand patch at 0.9 m.
        let mut depth = depth_of(&[], z, 0);
        let (hu, hv) = INTR.project(&palm).unwrap();
        for y in hv as usize - 6..=hv as usize + 6 {
            for x in hu as usize - 6..=hu as usize + 6 {
                depth.data[y * 640 + x] = 900;
            }
        }
        let landmarks = Landmarks {
            pose: Some(pose),
            face: None,
            hands: vec![hand],
        };
        // Camera 1.5 m up, looking along world +x, tilted so that camera z is world +x:
        // world = R · camera + t with camera x → world −y, camera y → world −z.
        let rot = Rotation3::from_matrix_unchecked(nalgebra::Matrix3::new(
            0.0, 0.0, 1.0, //
            -1.0, 0.0, 0.0, //
            0.0, -1.0, 0.0,
        ));
        let ext = Extrinsics {
            world_from_camera: Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 1.5),
                UnitQuaternion::from_rotation_matrix(&rot),
            ),
        };
        let mut x = CueExtractor::new(CueConfig::default(), ext, canonical()).unwrap();
        let c = x.extract(0.0, &landmarks, Some(&depth), &INTR);
        let body = c.frame.body.unwrap();
        // Shoulder midpoint (0, 0, 1.2) in the camera → world (1.2, 0, 1.5).
        assert!((body.position - Vector3::new(1.2, 0.0, 1.5)).norm() < 0.01);
        // Chest normal (0, 0, −1) in the camera → world (−1, 0, 0): facing the camera.
        let f = body.facing.normalize();
        assert!(
            f.angle(&Vector3::new(-1.0, 0.0, 0.0)).to_degrees() < 1.0,
            "{f:?}"
        );
        assert!((body.confidence - 0.95).abs() < 1e-9);
        // The hand is nearest the pose's left wrist (15) → slot 0 (left); at 0.9 m.
        let h = c.frame.hands[0].unwrap();
        let want = ext.point_to_world(&Point3::new(0.25 + 0.002, 0.3, 0.9));
        assert!(
            (Point3::from(h.position) - want).norm() < 0.01,
            "{:?}",
            h.position
        );
        // The right hand has no landmarks: the pose's right wrist stands in, half confidence.
        let rh = c.frame.hands[1].unwrap();
        assert!((rh.confidence - 0.5 * 0.95).abs() < 1e-9);
    }

    #[test]
    fn a_jump_faster_than_max_speed_lowers_confidence() {
        let mut t = Track::default();
        assert_eq!(t.factor(0.0, Point3::origin(), 3.0), 1.0);
        // 0.05 m in 1/30 s = 1.5 m/s: consistent.
        assert_eq!(t.factor(1.0 / 30.0, Point3::new(0.05, 0.0, 0.0), 3.0), 1.0);
        // 0.5 m in 1/30 s = 15 m/s: factor 3 / 15 = 0.2.
        let f = t.factor(2.0 / 30.0, Point3::new(0.55, 0.0, 0.0), 3.0);
        assert!((f - 0.2).abs() < 1e-9);
        // After a gap (> 0.5 s) the cue starts afresh.
        assert_eq!(t.factor(5.0, Point3::new(9.0, 0.0, 0.0), 3.0), 1.0);
    }

    #[test]
    fn canonical_face_file_errors_name_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.csv");
        std::fs::write(&p, "index,x,y,z\n0,1,2,3\n1,1,x,3\n").unwrap();
        let e = load_canonical_face(&p).unwrap_err().to_string();
        assert!(e.contains(":3:3"), "{e}");
        std::fs::write(&p, "index,x,y,z\n0,1,2,3\n").unwrap();
        let e = load_canonical_face(&p).unwrap_err().to_string();
        assert!(e.contains("468"), "{e}");
    }
}
