//! The landmark pipeline: pose (33), face mesh (468) and hands (21 each) for one person, the
//! operator, with ROI tracking between frames.
//!
//! Per model, as in MediaPipe's graphs:
//! - **detectors** (pose, face, palm) see the whole image letterboxed to their input, give SSD
//!   boxes with keypoints (decoded, weighted NMS, letterbox removed);
//! - a detection becomes a rotated ROI; **landmark models** see that ROI cropped to their
//!   input, and their landmarks are projected back to the image;
//! - in [`Mode::Tracking`] the next frame's ROIs come from this frame's landmarks, so the
//!   detectors run only when a landmark model reports its target lost. Hand ROIs come from the
//!   previous hand landmarks; a hand not tracked comes from palm detection (as in mediapipe's
//!   Hands; every `palm_every`-th frame while one is missing), else from the pose's wrist,
//!   index and pinky points. Models can run at staggered rates (`face_every`,
//!   `hand_every`): a skipped model keeps its last landmarks.
//! - in [`Mode::Static`] every frame is independent (MediaPipe's `static_image_mode`): this is
//!   what the photo tests compare against the official mediapipe 0.10.21 output.
//!
//! The pipeline is single-person. Where several people are in view, [`rank_operators`]
//! decides who the operator is: someone where the operator was lost a moment ago, else
//! someone at the operator's station ([`StationView`], from a calibrated workspace), else the
//! nearest person (median depth in the detection box), else the best detector score × body
//! size. Face and hands are then taken from that person.

use std::path::Path;
use std::time::Instant;

use nalgebra::Point3;

use super::anchors::{self, Anchor, AnchorOptions};
use super::detect::{self, DecodeOptions, Detection};
use super::frame::{DepthImage, Extrinsics, Intrinsics, RgbImage};
use super::landmarks::{FaceLandmarks, HandLandmarks, Landmark, Landmarks, PoseLandmarks};
use super::models::Model;
use super::roi::{
    self, Border, CropBuffer, NormRect, RectTransform, crop_to_tensor, rect_from_alignment,
    rect_from_box,
};
use crate::{AssessError, Result};

/// Model variants: MediaPipe's "full" models, or the "lite" ones (faster, less accurate) for
/// pose and hands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    /// pose_landmark_full, palm_detection_full, hand_landmark_full.
    Full,
    /// pose_landmark_lite, palm_detection_lite, hand_landmark_lite.
    Lite,
}

/// How frames relate to each other.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Every frame is independent: all detectors run on every frame.
    Static,
    /// Video: ROIs are tracked from frame to frame; detectors run when tracking is lost.
    Tracking,
}

/// Pipeline settings.
#[derive(Debug, Clone, PartialEq)]
pub struct PipelineConfig {
    /// Model variant for pose and hands (the face models have one variant).
    pub variant: Variant,
    /// Static images or tracking.
    pub mode: Mode,
    /// Minimum detector score [-] (MediaPipe's `min_detection_confidence`, default 0.5).
    pub min_detection_score: f32,
    /// Minimum landmark-model presence score to keep tracking [-] (MediaPipe's
    /// `min_tracking_confidence`, default 0.5).
    pub min_presence_score: f32,
    /// Whether to find hands.
    pub hands: bool,
    /// Whether to find the face mesh.
    pub face: bool,
    /// Run the face landmark model on every n-th frame while tracking (1 = every frame).
    pub face_every: u32,
    /// Run each hand's landmark model on every n-th frame while tracking, the two hands on
    /// alternating frames when 2 (1 = every frame).
    pub hand_every: u32,
    /// While a hand is not tracked, run palm detection on every n-th frame (between them, and
    /// where it finds no palm, the hand's ROI comes from the pose's wrist).
    pub palm_every: u32,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            variant: Variant::Full,
            mode: Mode::Tracking,
            min_detection_score: 0.5,
            min_presence_score: 0.5,
            hands: true,
            face: true,
            face_every: 1,
            hand_every: 1,
            palm_every: 3,
        }
    }
}

impl PipelineConfig {
    /// MediaPipe's static-image settings (full models, detectors on every frame).
    pub fn static_images() -> Self {
        Self {
            mode: Mode::Static,
            ..Self::default()
        }
    }
}

/// Wall time of each stage on the last frame [µs]; 0 for a stage that did not run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StageTimes {
    /// Pose detection [µs].
    pub pose_detection_us: u64,
    /// Pose landmarks [µs].
    pub pose_landmarks_us: u64,
    /// Face detection [µs].
    pub face_detection_us: u64,
    /// Face landmarks [µs].
    pub face_landmarks_us: u64,
    /// Palm detection [µs].
    pub palm_detection_us: u64,
    /// Hand landmarks, both hands [µs].
    pub hand_landmarks_us: u64,
    /// The whole frame [µs].
    pub total_us: u64,
}

/// How often each model has run since the pipeline was loaded (detectors run only when
/// tracking is lost; landmark models at their staggered rates).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RunCounts {
    /// Frames processed.
    pub frames: u64,
    /// Pose detector runs.
    pub pose_detector: u64,
    /// Face detector runs.
    pub face_detector: u64,
    /// Palm detector runs.
    pub palm_detector: u64,
    /// Pose landmark model runs.
    pub pose_landmarks: u64,
    /// Face landmark model runs.
    pub face_landmarks: u64,
    /// Hand landmark model runs.
    pub hand_landmarks: u64,
    /// Pose candidates refused because they were not where the operator was lost, within
    /// [`OPERATOR_MEMORY_S`] of losing them (another person never takes over).
    pub others_refused: u64,
}

/// How long after losing the operator only a person where they were may become the operator
/// again [s]. Later, the ranking of [`rank_operators`] alone decides.
pub const OPERATOR_MEMORY_S: f64 = 1.0;

/// Pose candidates tried in turn on one detection, best first, until one has its landmarks
/// present ([`PipelineConfig::min_presence_score`]).
const MAX_CANDIDATES: usize = 3;

/// Where the operator's body was last seen: the pose's auxiliary landmark 33 (body centre)
/// [px], its body scale 2·|aux34 − aux33| [px] and the frame time [s].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OperatorMemory {
    /// Body centre [px].
    pub centre: [f64; 2],
    /// Body scale [px].
    pub scale: f64,
    /// Frame time [s].
    pub t: f64,
}

/// The operator's station ([`crate::Station`]) as one frame's camera sees it.
///
/// Made per frame by [`StationView::new`] from the station in the camera frame and that
/// frame's intrinsics, and given to the pipeline with [`Pipeline::set_station`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StationView {
    /// The station's position in the camera frame [m] (z > 0, in front of the camera).
    pub camera_m: Point3<f64>,
    /// How far from it a person still counts as at the station [m].
    pub radius_m: f64,
    /// The station projected into the image [px].
    pub centre_px: [f64; 2],
    /// The frame's intrinsics (to lift a detection box centre with its depth).
    pub intrinsics: Intrinsics,
}

impl StationView {
    /// The station at `camera_m` [m] (camera frame) with `radius_m` [m], seen with
    /// `intrinsics`; `None` when it is not in front of the camera (z ≤ 0.05 m), where it cannot
    /// tell anyone apart.
    pub fn new(camera_m: Point3<f64>, radius_m: f64, intrinsics: Intrinsics) -> Option<Self> {
        if !(camera_m.z > 0.05 && radius_m > 0.0) {
            return None;
        }
        let (u, v) = intrinsics.project(&camera_m)?;
        Some(Self {
            camera_m,
            radius_m,
            centre_px: [u, v],
            intrinsics,
        })
    }

    /// The workspace's `station` seen by a camera with `extrinsics` and `intrinsics`; `None`
    /// as for [`StationView::new`].
    pub fn from_workspace(
        station: &crate::Station,
        extrinsics: &Extrinsics,
        intrinsics: Intrinsics,
    ) -> Option<Self> {
        let world = Point3::from(station.position());
        let camera = extrinsics.world_from_camera.inverse_transform_point(&world);
        Self::new(camera, station.radius(), intrinsics)
    }

    /// Whether a detection box, with its median depth `z` [m] when valid, is at the station,
    /// and how far from it:
    /// - with depth: the box centre lifted to `z` is within `radius_m` of the station (3-D
    ///   distance [m]);
    /// - without: the box contains the station's projection (image distance of the box centre
    ///   to it [px]).
    fn place(&self, d: &Detection, size: (u32, u32), z: Option<f64>) -> (bool, f64) {
        let (w, h) = (f64::from(size.0), f64::from(size.1));
        let (x0, y0) = (f64::from(d.xmin) * w, f64::from(d.ymin) * h);
        let (x1, y1) = (x0 + f64::from(d.width) * w, y0 + f64::from(d.height) * h);
        let (u, v) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        match z {
            Some(z) => {
                let dist = (self.intrinsics.deproject(u, v, z) - self.camera_m).norm();
                (dist <= self.radius_m, dist)
            }
            None => {
                let [cu, cv] = self.centre_px;
                let inside = (x0..=x1).contains(&cu) && (y0..=y1).contains(&cv);
                (inside, (u - cu).hypot(v - cv))
            }
        }
    }
}

/// MediaPipe's One-Euro filter as its `LandmarksSmoothingCalculator` applies it (not the
/// classic one of `crate::filter`): values in pixels, the derivative scaled by 1 / object size
/// [1/px], the rate from the frame timestamps. Used on the pose's two auxiliary landmarks,
/// which MediaPipe always smooths (min cutoff 0.01 Hz, β 10, derivative cutoff 1 Hz) so that
/// the tracked pose ROI is steady.
#[derive(Debug, Clone, Copy, Default)]
struct MpOneEuro {
    x: Option<(f64, f64)>,
    dx: Option<f64>,
}

impl MpOneEuro {
    const MIN_CUTOFF: f64 = 0.01;
    const BETA: f64 = 10.0;
    const D_CUTOFF: f64 = 1.0;

    fn alpha(cutoff: f64, rate_hz: f64) -> f64 {
        let te = 1.0 / rate_hz;
        let tau = 1.0 / (2.0 * std::f64::consts::PI * cutoff);
        1.0 / (1.0 + tau / te)
    }

    /// Filters `value` [px] at `rate_hz` with `value_scale` [1/px].
    fn apply(&mut self, value: f64, rate_hz: f64, value_scale: f64) -> f64 {
        let dvalue = self
            .x
            .map_or(0.0, |(raw, _)| (value - raw) * value_scale * rate_hz);
        let a_d = Self::alpha(Self::D_CUTOFF, rate_hz);
        let edvalue = match self.dx {
            Some(prev) => a_d * dvalue + (1.0 - a_d) * prev,
            None => dvalue,
        };
        self.dx = Some(edvalue);
        let a = Self::alpha(Self::MIN_CUTOFF + Self::BETA * edvalue.abs(), rate_hz);
        let out = match self.x {
            Some((_, prev)) => a * value + (1.0 - a) * prev,
            None => value,
        };
        self.x = Some((value, out));
        out
    }
}

/// Sigmoid.
fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

fn micros(since: Instant) -> u64 {
    u64::try_from(since.elapsed().as_micros()).unwrap_or(u64::MAX)
}

/// A detector: model, anchors, decoding and its input value range.
#[derive(Debug)]
struct Detector {
    model: Model,
    anchors: Vec<Anchor>,
    decode: DecodeOptions,
    range: (f32, f32),
    crop: CropBuffer,
    boxes_out: usize,
    scores_out: usize,
}

impl Detector {
    fn load(
        dir: &Path,
        name: &str,
        anchor_options: &AnchorOptions,
        num_keypoints: usize,
        range: (f32, f32),
        min_score: f32,
    ) -> Result<Self> {
        let model = Model::load(dir, name)?;
        let anchors = anchors::generate(anchor_options);
        let (w, h) = model.input_size();
        if (w, h) != (anchor_options.input_width, anchor_options.input_height) {
            return Err(AssessError::Model {
                path: model.path().to_path_buf(),
                message: format!(
                    "input is {w}×{h}; the detector expects {}×{}",
                    anchor_options.input_width, anchor_options.input_height
                ),
            });
        }
        let num_coords = 4 + 2 * num_keypoints;
        // The outputs are told apart by size: boxes N·coords, scores N.
        let sizes = model.output_sizes();
        let find = |n: usize| -> Result<usize> {
            sizes
                .iter()
                .position(|&s| s == n)
                .ok_or_else(|| AssessError::Model {
                    path: model.path().to_path_buf(),
                    message: format!("no output with {n} values (sizes {sizes:?})"),
                })
        };
        let boxes_out = find(anchors.len() * num_coords)?;
        let scores_out = find(anchors.len())?;
        Ok(Self {
            crop: CropBuffer::new(w, h),
            decode: DecodeOptions {
                num_coords,
                num_keypoints,
                scale: w as f32,
                min_score,
            },
            model,
            anchors,
            range,
            boxes_out,
            scores_out,
        })
    }

    /// Runs on the whole image (letterboxed) and returns NMS'd detections normalised to the
    /// image, best first.
    fn detect(&mut self, image: &RgbImage) -> Result<Vec<Detection>> {
        let (iw, ih) = (image.width as f32, image.height as f32);
        let ((pw, ph), padding) = roi::pad_to_aspect(iw, ih, self.model.input_size());
        let full = roi::Roi {
            cx: f64::from(iw) / 2.0,
            cy: f64::from(ih) / 2.0,
            width: f64::from(pw),
            height: f64::from(ph),
            rotation: 0.0,
        };
        crop_to_tensor(image, &full, self.range, Border::Zero, &mut self.crop)?;
        self.model.run(&self.crop.tensor)?;
        let raw = detect::decode(
            self.model.output(self.boxes_out),
            self.model.output(self.scores_out),
            &self.anchors,
            &self.decode,
        );
        let mut dets = detect::weighted_nms(raw, 0.3);
        for d in &mut dets {
            d.remove_letterbox(padding);
        }
        Ok(dets)
    }
}

/// A landmark model and where its outputs are.
#[derive(Debug)]
struct LandmarkModel {
    model: Model,
    crop: CropBuffer,
    landmarks_out: usize,
    flag_out: usize,
    /// Extra score output (hand: handedness).
    extra_out: Option<usize>,
    /// Heatmap output (pose: 64 × 64 × 39 logits) for landmark refinement.
    heatmap_out: Option<usize>,
    values_per_landmark: usize,
    range: (f32, f32),
}

impl LandmarkModel {
    fn load(
        dir: &Path,
        name: &str,
        landmarks: (&str, usize),
        flag: &str,
        extra: Option<&str>,
    ) -> Result<Self> {
        let model = Model::load(dir, name)?;
        let (w, h) = model.input_size();
        Ok(Self {
            crop: CropBuffer::new(w, h),
            landmarks_out: model.output_index(landmarks.0)?,
            flag_out: model.output_index(flag)?,
            extra_out: extra.map(|e| model.output_index(e)).transpose()?,
            heatmap_out: None,
            values_per_landmark: landmarks.1,
            model,
            range: (0.0, 1.0),
        })
    }

    /// Runs on `rect`; returns the raw landmark values (input pixels, refined from the
    /// heatmap where the model has one) and the flag and extra outputs.
    fn run(&mut self, image: &RgbImage, rect: &NormRect) -> Result<(Vec<f32>, f32, Option<f32>)> {
        let roi = rect.to_pixels((image.width, image.height));
        crop_to_tensor(image, &roi, self.range, Border::Replicate, &mut self.crop)?;
        self.model.run(&self.crop.tensor)?;
        let flag = self
            .model
            .output(self.flag_out)
            .first()
            .copied()
            .unwrap_or(0.0);
        let extra = self
            .extra_out
            .and_then(|i| self.model.output(i).first().copied());
        let mut raw = self.model.output(self.landmarks_out).to_vec();
        if let Some(h) = self.heatmap_out {
            let (w, hh) = self.model.input_size();
            refine_from_heatmap(
                &mut raw,
                self.values_per_landmark,
                (w as f32, hh as f32),
                self.model.output(h),
                (64, 64),
                9,
                0.5,
            );
        }
        Ok((raw, flag, extra))
    }

    /// Projects raw landmarks (input pixels) back to the image, in pixels.
    fn project(
        &self,
        raw: &[f32],
        rect: &NormRect,
        image: (u32, u32),
        scores: bool,
    ) -> Vec<Landmark> {
        let (w, h) = self.model.input_size();
        let (iw, ih) = (f64::from(image.0), f64::from(image.1));
        raw.chunks_exact(self.values_per_landmark)
            .map(|v| {
                let [x, y] = rect.project(v[0] / w as f32, v[1] / h as f32);
                let z = v[2] / w as f32 * rect.width;
                let (visibility, presence) = if scores && v.len() >= 5 {
                    (f64::from(sigmoid(v[3])), f64::from(sigmoid(v[4])))
                } else {
                    (1.0, 1.0)
                };
                Landmark {
                    x: f64::from(x) * iw,
                    y: f64::from(y) * ih,
                    z: f64::from(z) * iw,
                    visibility,
                    presence,
                }
            })
            .collect()
    }
}

/// MediaPipe's `RefineLandmarksFromHeatmapCalculator` (the pose graph uses a 9 × 9 kernel and
/// minimum confidence 0.5; with 7 × 7 the photo tests differ from mediapipe by up to 17 px,
/// with 9 × 9 by under 1 px): each landmark whose heatmap channel
/// (sigmoid of the logits, HWC layout) peaks at ≥ `min_confidence` within a `kernel` × `kernel`
/// window around it moves to the confidence-weighted mean of the window's cells. `raw` holds
/// landmarks in input pixels, `values` per landmark; `input` is the input size [px].
/// A landmark outside the heatmap (column or row outside it) is kept as it is, as in
/// refine_landmarks_from_heatmap_calculator.cc:126–129 at v0.10.21 (which checks the row
/// against the height; ours compared the column a second time, so a landmark just below the
/// crop was refined from the heatmap's last rows).
pub fn refine_from_heatmap(
    raw: &mut [f32],
    values: usize,
    input: (f32, f32),
    heatmap: &[f32],
    (hm_h, hm_w): (usize, usize),
    kernel: usize,
    min_confidence: f32,
) {
    let n = raw.len() / values.max(1);
    if values < 2 || hm_h == 0 || hm_w == 0 || !heatmap.len().is_multiple_of(hm_h * hm_w) {
        return;
    }
    let channels = heatmap.len() / (hm_h * hm_w);
    let offset = (kernel as i64 - 1) / 2;
    for (lm, v) in raw
        .chunks_exact_mut(values)
        .enumerate()
        .take(n.min(channels))
    {
        let x = v[0] / input.0;
        let y = v[1] / input.1;
        let col = (x * hm_w as f32) as i64;
        let row = (y * hm_h as f32) as i64;
        if col < 0 || col >= hm_w as i64 || row < 0 || row >= hm_h as i64 {
            continue;
        }
        let (c0, c1) = ((col - offset).max(0), (col + offset + 1).min(hm_w as i64));
        let (r0, r1) = ((row - offset).max(0), (row + offset + 1).min(hm_h as i64));
        let (mut sum, mut wc, mut wr, mut max) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for r in r0..r1 {
            for c in c0..c1 {
                let idx = (hm_w * channels) * r as usize + channels * c as usize + lm;
                let conf = heatmap.get(idx).map_or(0.0, |&l| sigmoid(l));
                sum += conf;
                max = max.max(conf);
                wc += c as f32 * conf;
                wr += r as f32 * conf;
            }
        }
        if max >= min_confidence && sum > 0.0 {
            v[0] = wc / hm_w as f32 / sum * input.0;
            v[1] = wr / hm_h as f32 / sum * input.1;
        }
    }
}

/// Landmarks normalised to the image, as the ROI calculators want them.
fn normalised(points: &[Landmark], image: (u32, u32)) -> Vec<[f32; 2]> {
    let (iw, ih) = (image.0 as f64, image.1 as f64);
    points
        .iter()
        .map(|p| [(p.x / iw) as f32, (p.y / ih) as f32])
        .collect()
}

const POSE_ROI: RectTransform = RectTransform {
    scale_x: 1.25,
    scale_y: 1.25,
    shift_x: 0.0,
    shift_y: 0.0,
    square_long: true,
};
const FACE_ROI: RectTransform = RectTransform {
    scale_x: 1.5,
    scale_y: 1.5,
    shift_x: 0.0,
    shift_y: 0.0,
    square_long: true,
};
const PALM_ROI: RectTransform = RectTransform {
    scale_x: 2.6,
    scale_y: 2.6,
    shift_x: 0.0,
    shift_y: -0.5,
    square_long: true,
};
const HAND_TRACK_ROI: RectTransform = RectTransform {
    scale_x: 2.0,
    scale_y: 2.0,
    shift_x: 0.0,
    shift_y: -0.1,
    square_long: true,
};
const HAND_FROM_POSE_ROI: RectTransform = RectTransform {
    scale_x: 2.0,
    scale_y: 2.0,
    shift_x: 0.0,
    shift_y: -0.1,
    square_long: true,
};

/// The face ROI from face landmarks (`face_landmarks_to_roi`): landmark bounding box, rotated
/// by the eye corners 33 → 263 to 0°.
pub fn face_rect_from_landmarks(points: &[[f32; 2]], image: (u32, u32)) -> Option<NormRect> {
    let d = bbox_detection(points)?;
    let (a, b) = (*points.get(33)?, *points.get(263)?);
    let (w, h) = (image.0 as f32, image.1 as f32);
    let rect = NormRect {
        cx: d.xmin + d.width / 2.0,
        cy: d.ymin + d.height / 2.0,
        width: d.width,
        height: d.height,
        rotation: roi::rotation_between([a[0] * w, a[1] * h], [b[0] * w, b[1] * h], 0.0),
    };
    rect.is_usable().then(|| rect.transformed(&FACE_ROI, image))
}

fn bbox_detection(points: &[[f32; 2]]) -> Option<Detection> {
    let first = points.first()?;
    let (mut x0, mut y0, mut x1, mut y1) = (first[0], first[1], first[0], first[1]);
    for p in points {
        x0 = x0.min(p[0]);
        y0 = y0.min(p[1]);
        x1 = x1.max(p[0]);
        y1 = y1.max(p[1]);
    }
    Some(Detection {
        score: 1.0,
        xmin: x0,
        ymin: y0,
        width: x1 - x0,
        height: y1 - y0,
        keypoints: Vec::new(),
    })
}

/// The hand ROI from hand landmarks (`HandLandmarksToRectCalculator` + transform): rotation
/// from the wrist to the middle of the index/middle/ring knuckles, bounding box of the palm
/// and lower finger joints in that rotated frame.
pub fn hand_rect_from_landmarks(points: &[[f32; 2]], image: (u32, u32)) -> Option<NormRect> {
    const SUBSET: [usize; 12] = [0, 1, 2, 3, 5, 6, 9, 10, 13, 14, 17, 18];
    if points.len() < 21 {
        return None;
    }
    let (w, h) = (image.0 as f32, image.1 as f32);
    let p = |i: usize| points[i];
    let (x0, y0) = (p(0)[0] * w, p(0)[1] * h);
    let x1 = ((p(5)[0] + p(13)[0]) / 2.0 + p(9)[0]) / 2.0 * w;
    let y1 = ((p(5)[1] + p(13)[1]) / 2.0 + p(9)[1]) / 2.0 * h;
    let rotation = roi::rotation_between([x0, y0], [x1, y1], std::f32::consts::FRAC_PI_2);
    let reverse = roi::normalize_radians(-rotation);
    let (mut min_x, mut min_y, mut max_x, mut max_y) = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
    for &i in &SUBSET {
        min_x = min_x.min(p(i)[0]);
        max_x = max_x.max(p(i)[0]);
        min_y = min_y.min(p(i)[1]);
        max_y = max_y.max(p(i)[1]);
    }
    let acx = (max_x + min_x) / 2.0;
    let acy = (max_y + min_y) / 2.0;
    let (mut min_x, mut min_y, mut max_x, mut max_y) = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
    let (sr, cr) = reverse.sin_cos();
    for &i in &SUBSET {
        let ox = (p(i)[0] - acx) * w;
        let oy = (p(i)[1] - acy) * h;
        let px = ox * cr - oy * sr;
        let py = ox * sr + oy * cr;
        min_x = min_x.min(px);
        max_x = max_x.max(px);
        min_y = min_y.min(py);
        max_y = max_y.max(py);
    }
    let pcx = (max_x + min_x) / 2.0;
    let pcy = (max_y + min_y) / 2.0;
    let (s, c) = rotation.sin_cos();
    let cx = pcx * c - pcy * s + w * acx;
    let cy = pcx * s + pcy * c + h * acy;
    let rect = NormRect {
        cx: cx / w,
        cy: cy / h,
        width: (max_x - min_x) / w,
        height: (max_y - min_y) / h,
        rotation,
    };
    rect.is_usable()
        .then(|| rect.transformed(&HAND_TRACK_ROI, image))
}

/// A hand ROI from the pose's wrist, index and pinky landmarks (MediaPipe Holistic's
/// `HandDetectionsFromPoseToRectsCalculator`): centred on the estimated middle knuckle, side
/// twice its distance to the wrist, rotated wrist → knuckle to 90°, then scaled 2.0 with
/// shift −0.1 like the hand-landmark tracking ROI. (Holistic scales by 2.7 because it refines
/// the crop with a re-crop model we don't have; fed straight to the landmark model, 2.7 gave
/// landmarks 15 px from mediapipe's palm-detection path on `pose_sitting.jpg`, 2.0 gives
/// 3.7 px, and tracking then converges to mediapipe's within a frame.)
pub fn hand_rect_from_pose(
    wrist: [f32; 2],
    index: [f32; 2],
    pinky: [f32; 2],
    image: (u32, u32),
) -> Option<NormRect> {
    let middle = [
        (2.0 * index[0] + pinky[0]) / 3.0,
        (2.0 * index[1] + pinky[1]) / 3.0,
    ];
    let (w, h) = (image.0 as f32, image.1 as f32);
    let dx = (middle[0] - wrist[0]) * w;
    let dy = (middle[1] - wrist[1]) * h;
    let size = (dx * dx + dy * dy).sqrt() * 2.0;
    let rect = NormRect {
        cx: middle[0],
        cy: middle[1],
        width: size / w,
        height: size / h,
        rotation: roi::rotation_between(
            [wrist[0] * w, wrist[1] * h],
            [middle[0] * w, middle[1] * h],
            std::f32::consts::FRAC_PI_2,
        ),
    };
    rect.is_usable()
        .then(|| rect.transformed(&HAND_FROM_POSE_ROI, image))
}

/// Tracking state of one hand slot.
#[derive(Debug, Clone, Default)]
struct HandTrack {
    rect: Option<NormRect>,
    last: Option<HandLandmarks>,
}

/// The landmark pipeline. Construct once ([`Pipeline::load`]), then call
/// [`Pipeline::process`] per frame.
#[derive(Debug)]
pub struct Pipeline {
    config: PipelineConfig,
    pose_detector: Detector,
    pose_model: LandmarkModel,
    face_detector: Detector,
    face_model: LandmarkModel,
    palm_detector: Detector,
    hand_model: LandmarkModel,
    pose_rect: Option<NormRect>,
    face_rect: Option<NormRect>,
    last_face: Option<FaceLandmarks>,
    hands: [HandTrack; 2],
    frame: u64,
    times: StageTimes,
    runs: RunCounts,
    /// Smoothing of the pose's auxiliary landmarks 33, 34 (x, y each).
    aux_filters: [MpOneEuro; 4],
    /// Where the operator was last seen.
    operator: Option<OperatorMemory>,
    /// The operator's station in this frame's image, when the workspace gives one.
    station: Option<StationView>,
    /// Time of the previous frame [s].
    last_t: Option<f64>,
    /// Time of the current frame [s].
    now: f64,
}

impl Pipeline {
    /// Loads the models from `dir` (see [`super::models::model_dir`]).
    pub fn load(dir: &Path, config: PipelineConfig) -> Result<Self> {
        let (pose_lm, palm, hand_lm) = match config.variant {
            Variant::Full => (
                "pose_landmark_full",
                "palm_detection_full",
                "hand_landmark_full",
            ),
            Variant::Lite => (
                "pose_landmark_lite",
                "palm_detection_lite",
                "hand_landmark_lite",
            ),
        };
        let min = config.min_detection_score;
        Ok(Self {
            pose_detector: Detector::load(
                dir,
                "pose_detection",
                &anchors::POSE_DETECTION,
                4,
                (-1.0, 1.0),
                min,
            )?,
            pose_model: {
                let mut m = LandmarkModel::load(dir, pose_lm, ("Identity", 5), "Identity_1", None)?;
                m.heatmap_out = Some(m.model.output_index("Identity_3")?);
                m
            },
            face_detector: Detector::load(
                dir,
                "face_detection_short_range",
                &anchors::FACE_DETECTION,
                6,
                (-1.0, 1.0),
                min,
            )?,
            face_model: LandmarkModel::load(
                dir,
                "face_landmark",
                ("conv2d_21", 3),
                "conv2d_31",
                None,
            )?,
            palm_detector: Detector::load(dir, palm, &anchors::PALM_DETECTION, 7, (0.0, 1.0), min)?,
            hand_model: LandmarkModel::load(
                dir,
                hand_lm,
                ("Identity", 3),
                "Identity_1",
                Some("Identity_2"),
            )?,
            config,
            pose_rect: None,
            operator: None,
            station: None,
            face_rect: None,
            last_face: None,
            hands: [HandTrack::default(), HandTrack::default()],
            frame: 0,
            times: StageTimes::default(),
            runs: RunCounts::default(),
            aux_filters: [MpOneEuro::default(); 4],
            last_t: None,
            now: 0.0,
        })
    }

    /// The settings.
    pub fn config(&self) -> &PipelineConfig {
        &self.config
    }

    /// How often each model has run.
    pub fn run_counts(&self) -> RunCounts {
        self.runs
    }

    /// Stage times of the last frame.
    pub fn stage_times(&self) -> StageTimes {
        self.times
    }

    /// Runs only the face detector on the whole image: every face found, best first,
    /// normalised to the image (for operator selection and diagnostics).
    pub fn detect_faces(&mut self, image: &RgbImage) -> Result<Vec<Detection>> {
        if !image.is_well_formed() {
            return Ok(Vec::new());
        }
        self.face_detector.detect(image)
    }

    /// Runs only the pose detector on the whole image: every person found, best first.
    pub fn detect_people(&mut self, image: &RgbImage) -> Result<Vec<Detection>> {
        if !image.is_well_formed() {
            return Ok(Vec::new());
        }
        self.pose_detector.detect(image)
    }

    /// Forgets all tracking state (the next frame runs the detectors).
    pub fn reset(&mut self) {
        self.pose_rect = None;
        self.operator = None;
        self.aux_filters = [MpOneEuro::default(); 4];
        self.face_rect = None;
        self.last_face = None;
        self.hands = [HandTrack::default(), HandTrack::default()];
    }

    /// [`Pipeline::process_at`] for frames at a nominal 30 fps (the frame counter gives the
    /// time).
    pub fn process(&mut self, image: &RgbImage, depth: Option<&DepthImage>) -> Result<Landmarks> {
        let t = self.last_t.map_or(0.0, |t| t + 1.0 / 30.0);
        self.process_at(t, image, depth)
    }

    /// Sets the operator's station for the frames that follow (made per frame, as the
    /// intrinsics can change with the frame size); `None`: no station is known.
    pub fn set_station(&mut self, station: Option<StationView>) {
        self.station = station;
    }

    /// The operator's station in use.
    pub fn station(&self) -> Option<&StationView> {
        self.station.as_ref()
    }

    /// Finds the operator's landmarks on the frame taken at camera time `t` [s] (used to
    /// smooth the tracked pose ROI; must increase). `depth`, aligned to `image`, and the
    /// station ([`Pipeline::set_station`]) are used to choose the operator. An empty or
    /// malformed image gives empty landmarks and resets tracking.
    pub fn process_at(
        &mut self,
        t: f64,
        image: &RgbImage,
        depth: Option<&DepthImage>,
    ) -> Result<Landmarks> {
        let start = Instant::now();
        if self.last_t.is_some_and(|last| t.is_nan() || t <= last) {
            // Time going backwards or standing still: a new sequence.
            self.reset();
        }
        self.now = t;
        self.times = StageTimes::default();
        let mut out = Landmarks::default();
        if !image.is_well_formed() {
            self.reset();
            return Ok(out);
        }
        if self.config.mode == Mode::Static {
            self.reset();
        }
        out.pose = self.pose(image, depth)?;
        if self.config.face {
            out.face = self.face(image, depth, out.pose.as_ref())?;
        }
        if self.config.hands {
            out.hands = self.hands(image, out.pose.as_ref())?;
        }
        self.frame += 1;
        self.runs.frames += 1;
        self.last_t = Some(t);
        self.times.total_us = micros(start);
        Ok(out)
    }

    /// The operator's pose: tracked from the previous frame's ROI, or, when there is none or
    /// it lost the person, detected: the candidates of [`rank_operators`] in turn (at most
    /// [`MAX_CANDIDATES`]) until one has its landmarks present.
    fn pose(
        &mut self,
        image: &RgbImage,
        depth: Option<&DepthImage>,
    ) -> Result<Option<PoseLandmarks>> {
        let size = (image.width, image.height);
        // Tracked; when the tracked region lost the person, detect again at once.
        if let Some(rect) = self.pose_rect
            && let Some(p) = self.pose_in(image, &rect, size)?
        {
            return Ok(Some(p));
        }
        let t = Instant::now();
        let dets = self.pose_detector.detect(image)?;
        self.runs.pose_detector += 1;
        self.times.pose_detection_us += micros(t);
        let recent = self
            .operator
            .filter(|o| self.now - o.t <= OPERATOR_MEMORY_S);
        let ranked = rank_operators(&dets, size, depth, recent.as_ref(), self.station.as_ref());
        self.runs.others_refused += (dets.len() - ranked.len()) as u64;
        for &i in ranked.iter().take(MAX_CANDIDATES) {
            let Some(r) = rect_from_alignment(&dets[i], size, 0, 1, 90.0) else {
                continue;
            };
            let rect = r.transformed(&POSE_ROI, size);
            if let Some(p) = self.pose_in(image, &rect, size)? {
                return Ok(Some(p));
            }
        }
        Ok(None)
    }

    /// The pose landmarks in `rect`, or `None` when the person is not present there (the
    /// tracked ROI is then dropped). On success, the next frame's ROI (tracking) and the
    /// operator's memory are updated.
    fn pose_in(
        &mut self,
        image: &RgbImage,
        rect: &NormRect,
        size: (u32, u32),
    ) -> Result<Option<PoseLandmarks>> {
        let t = Instant::now();
        let (raw, flag, _) = self.pose_model.run(image, rect)?;
        self.runs.pose_landmarks += 1;
        self.times.pose_landmarks_us += micros(t);
        if flag < self.config.min_presence_score || raw.len() < 39 * 5 {
            self.pose_rect = None;
            // MediaPipe resets its auxiliary-landmark filters here (a frame without landmarks,
            // landmarks_smoothing_calculator.cc:56–60 at v0.10.21); doing so too was tried and
            // reverted: it made the enter-leave scene worse (docs/calibration/
            // mediapipe_graph_check.md).
            return Ok(None);
        }
        let all = self.pose_model.project(&raw, rect, size, true);
        // Auxiliary landmarks 33 (body centre) and 34 (scale), smoothed, give the next ROI.
        self.pose_rect = if self.config.mode == Mode::Tracking {
            let aux = self.smooth_aux(&all, size);
            rect_from_points_opt(&aux, 0, 1, size).map(|r| r.transformed(&POSE_ROI, size))
        } else {
            None
        };
        if let (Some(c), Some(s)) = (all.get(33), all.get(34)) {
            self.operator = Some(OperatorMemory {
                centre: [c.x, c.y],
                scale: body_scale(c, s),
                t: self.now,
            });
        }
        let mut points = [Landmark::default(); 33];
        points.copy_from_slice(&all[..33]);
        Ok(Some(PoseLandmarks {
            points,
            score: f64::from(flag),
            roi: rect.to_pixels(size),
        }))
    }

    /// The auxiliary landmarks 33 and 34, smoothed as MediaPipe does, normalised.
    fn smooth_aux(&mut self, all: &[Landmark], size: (u32, u32)) -> Vec<[f32; 2]> {
        let (Some(a), Some(b)) = (all.get(33), all.get(34)) else {
            return Vec::new();
        };
        let rate = match self.last_t {
            Some(last) if self.now > last => 1.0 / (self.now - last),
            _ => 30.0,
        };
        // Object scale [px]: as mediapipe 0.10.21's compiled pose graph takes it, from the
        // crop the two auxiliary landmarks define: a square centred on aux 33 whose side is
        // twice the distance to aux 34, so (width + height) / 2 = 2·|aux34 − aux33| (not the
        // bounding box of the 33 body landmarks, which moved our crop centre 3.6 px from
        // mediapipe's on moving video; issue 13).
        let scale = body_scale(a, b);
        if scale < 1e-6 {
            return normalised(&[*a, *b], size);
        }
        let vs = 1.0 / scale;
        let f = &mut self.aux_filters;
        let pts = [
            Landmark {
                x: f[0].apply(a.x, rate, vs),
                y: f[1].apply(a.y, rate, vs),
                ..*a
            },
            Landmark {
                x: f[2].apply(b.x, rate, vs),
                y: f[3].apply(b.y, rate, vs),
                ..*b
            },
        ];
        normalised(&pts, size)
    }

    fn face(
        &mut self,
        image: &RgbImage,
        depth: Option<&DepthImage>,
        pose: Option<&PoseLandmarks>,
    ) -> Result<Option<FaceLandmarks>> {
        let size = (image.width, image.height);
        let tracking = self.config.mode == Mode::Tracking;
        if tracking
            && self.face_rect.is_some()
            && self.config.face_every > 1
            && !self.frame.is_multiple_of(u64::from(self.config.face_every))
        {
            return Ok(self.last_face.clone());
        }
        for attempt in 0..2 {
            let rect = match self.face_rect {
                Some(r) => r,
                None => {
                    let t = Instant::now();
                    let dets = self.face_detector.detect(image)?;
                    self.runs.face_detector += 1;
                    self.times.face_detection_us += micros(t);
                    let chosen = match pose {
                        // The face nearest the operator's nose.
                        Some(p) => nearest_to(&dets, size, [p.points[0].x, p.points[0].y]),
                        None => rank_operators(&dets, size, depth, None, self.station.as_ref())
                            .first()
                            .and_then(|&i| dets.get(i)),
                    };
                    let Some(d) = chosen else {
                        self.last_face = None;
                        return Ok(None);
                    };
                    let Some(r) = rect_from_box(d, size, 0, 1, 0.0) else {
                        return Ok(None);
                    };
                    r.transformed(&FACE_ROI, size)
                }
            };
            let t = Instant::now();
            let (raw, flag, _) = self.face_model.run(image, &rect)?;
            self.runs.face_landmarks += 1;
            self.times.face_landmarks_us += micros(t);
            let score = sigmoid(flag);
            if score < self.config.min_presence_score || raw.len() < 468 * 3 {
                let was_tracking = self.face_rect.take().is_some();
                self.last_face = None;
                if was_tracking && attempt == 0 {
                    continue;
                }
                return Ok(None);
            }
            let points = self.face_model.project(&raw, &rect, size, false);
            self.face_rect = if tracking {
                face_rect_from_landmarks(&normalised(&points, size), size)
            } else {
                None
            };
            let face = FaceLandmarks {
                points,
                score: f64::from(score),
                roi: rect.to_pixels(size),
            };
            self.last_face = Some(face.clone());
            return Ok(Some(face));
        }
        Ok(None)
    }

    fn hands(
        &mut self,
        image: &RgbImage,
        pose: Option<&PoseLandmarks>,
    ) -> Result<Vec<HandLandmarks>> {
        let size = (image.width, image.height);
        let tracking = self.config.mode == Mode::Tracking;
        // Candidate ROIs per slot (0: the person's left hand, 1: right): tracked; for a hand
        // not tracked, palm detection (as mediapipe's Hands, which detects palms while fewer
        // hands than wanted are tracked; here on every `palm_every`-th frame), else the
        // pose's wrist.
        let rects: [Option<NormRect>; 2] = [self.hands[0].rect, self.hands[1].rect];
        let mut from_pose: [Option<NormRect>; 2] = [None, None];
        if tracking && let Some(p) = pose {
            for (slot, (wrist, index, pinky)) in
                [(15, 19, 17), (16, 20, 18)].into_iter().enumerate()
            {
                if rects[slot].is_none() && p.points[wrist].visibility > 0.5 {
                    let n = |i: usize| {
                        [
                            (p.points[i].x / f64::from(size.0)) as f32,
                            (p.points[i].y / f64::from(size.1)) as f32,
                        ]
                    };
                    from_pose[slot] = hand_rect_from_pose(n(wrist), n(index), n(pinky), size);
                }
            }
        }
        let missing = rects.iter().filter(|r| r.is_none()).count();
        let palm_due = !tracking
            || self
                .frame
                .is_multiple_of(u64::from(self.config.palm_every.max(1)));
        let near = |a: &NormRect, b: &NormRect| {
            ((a.cx - b.cx) * size.0 as f32).hypot((a.cy - b.cy) * size.1 as f32)
                < 0.5 * a.width.max(b.width) * size.0 as f32
        };
        let mut from_palms: Vec<NormRect> = Vec::new();
        if missing > 0 && palm_due {
            let t = Instant::now();
            let dets = self.palm_detector.detect(image)?;
            self.runs.palm_detector += 1;
            self.times.palm_detection_us += micros(t);
            for d in dets.iter().take(2) {
                if let Some(r) = rect_from_box(d, size, 0, 2, 90.0) {
                    let r = r.transformed(&PALM_ROI, size);
                    // Skip palms already covered by a tracked hand.
                    if !rects.iter().flatten().any(|t| near(t, &r)) {
                        from_palms.push(r);
                    }
                }
            }
        }
        // A pose ROI where a palm was detected gives way to the palm's.
        for r in &mut from_pose {
            if r.is_some_and(|r| from_palms.iter().any(|p| near(p, &r))) {
                *r = None;
            }
        }
        let mut found: Vec<HandLandmarks> = Vec::new();
        let t = Instant::now();
        // Tracked slots first, then palm candidates, then the pose's.
        let mut jobs: Vec<(Option<usize>, NormRect)> = Vec::new();
        for (slot, r) in rects.iter().enumerate() {
            if let Some(r) = r {
                jobs.push((Some(slot), *r));
            }
        }
        for r in from_palms {
            jobs.push((None, r));
        }
        for (slot, r) in from_pose.iter().enumerate() {
            if let Some(r) = r {
                jobs.push((Some(slot), *r));
            }
        }
        let mut next: [HandTrack; 2] = [HandTrack::default(), HandTrack::default()];
        for (slot, rect) in jobs {
            if found.len() == 2 {
                break;
            }
            // Staggered rate: a tracked hand skipped this frame keeps its last landmarks.
            if let Some(s) = slot
                && tracking
                && self.config.hand_every > 1
                && self.hands[s].last.is_some()
                && !(self.frame + s as u64).is_multiple_of(u64::from(self.config.hand_every))
            {
                if let Some(last) = self.hands[s].last.clone() {
                    next[s] = self.hands[s].clone();
                    found.push(last);
                }
                continue;
            }
            let (raw, flag, handed) = self.hand_model.run(image, &rect)?;
            self.runs.hand_landmarks += 1;
            if flag < self.config.min_presence_score || raw.len() < 21 * 3 {
                continue;
            }
            let all = self.hand_model.project(&raw, &rect, size, false);
            let mut points = [Landmark::default(); 21];
            points.copy_from_slice(&all[..21]);
            // MediaPipe's handedness output assumes a mirrored (selfie) image: its score is
            // the probability of a right hand in the mirror, i.e. a left hand in an
            // unmirrored camera image.
            let right_hand = 1.0 - f64::from(handed.unwrap_or(0.5));
            let hand = HandLandmarks {
                points,
                score: f64::from(flag),
                right_hand,
                roi: rect.to_pixels(size),
            };
            // The same hand found twice (two ROIs on one hand): keep the first. Someone else's
            // hand is neither reported nor tracked (tracking it would hold a slot the
            // operator's hand needs).
            if found.iter().any(|h| same_hand(h, &hand))
                || pose.is_some_and(|p| !belongs_to(&hand, p, size))
            {
                continue;
            }
            let s = slot.unwrap_or(if right_hand >= 0.5 { 1 } else { 0 });
            if next[s].last.is_none() {
                next[s] = HandTrack {
                    rect: if tracking {
                        hand_rect_from_landmarks(&normalised(&hand.points, size), size)
                    } else {
                        None
                    },
                    last: Some(hand.clone()),
                };
            }
            found.push(hand);
        }
        self.times.hand_landmarks_us += micros(t);
        self.hands = next;
        Ok(found)
    }
}

fn rect_from_points_opt(
    norm: &[[f32; 2]],
    a: usize,
    b: usize,
    size: (u32, u32),
) -> Option<NormRect> {
    roi::rect_from_points(*norm.get(a)?, *norm.get(b)?, size, 90.0)
}

/// Whether a hand may belong to the person of `pose` on an image of `size` [px]: its wrist
/// lies within 0.6 shoulder widths of one of the pose's wrists, or the pose does not know
/// where one of its wrists is. The pose knows a wrist it sees (visibility > 0.5) and a wrist
/// it places outside the image (a person cut off by the frame); a wrist inside the image that
/// it does not see is a guess. So a hand is someone else's, and dropped, only where the pose
/// knows both its wrists and neither is near the hand.
///
/// On `two_children.jpeg` the boy's wrists lie below the image and the girl's hand on his
/// shoulder is dropped (`tests/vision_robustness.rs`); on a photo of a lone hand, mediapipe's
/// pose model, as ours, reports a "pose" with unseen wrists in the image far from the hand,
/// and the hand is kept (`tests/vision_scenes.rs`, the hand-exit scene).
pub fn belongs_to(hand: &HandLandmarks, pose: &PoseLandmarks, size: (u32, u32)) -> bool {
    let p = &pose.points;
    let shoulders = (p[11].x - p[12].x).hypot(p[11].y - p[12].y);
    let w = &hand.points[0];
    let inside = |l: &Landmark| {
        (0.0..f64::from(size.0)).contains(&l.x) && (0.0..f64::from(size.1)).contains(&l.y)
    };
    [&p[15], &p[16]].iter().any(|pw| {
        let unknown = pw.visibility <= 0.5 && inside(pw);
        unknown || (pw.x - w.x).hypot(pw.y - w.y) <= 0.6 * shoulders.max(1.0)
    })
}

/// Whether two hand landmark sets are the same hand (wrists closer than a quarter of the
/// wrist–middle-knuckle length).
fn same_hand(a: &HandLandmarks, b: &HandLandmarks) -> bool {
    let d = |p: &Landmark, q: &Landmark| (p.x - q.x).hypot(p.y - q.y);
    let scale = d(&a.points[0], &a.points[9]).max(1.0);
    d(&a.points[0], &b.points[0]) < 0.25 * scale && d(&a.points[9], &b.points[9]) < 0.25 * scale
}

/// The detection nearest a pixel.
fn nearest_to(dets: &[Detection], size: (u32, u32), p: [f64; 2]) -> Option<&Detection> {
    let dist = |d: &Detection| {
        let cx = f64::from(d.xmin + d.width / 2.0) * f64::from(size.0);
        let cy = f64::from(d.ymin + d.height / 2.0) * f64::from(size.1);
        (cx - p[0]).hypot(cy - p[1])
    };
    dets.iter().min_by(|a, b| dist(a).total_cmp(&dist(b)))
}

/// The body scale of the pose's auxiliary landmarks 33 (`centre`) and 34 (`scale_point`) [px]:
/// the side of the square crop they define, 2·|aux34 − aux33|, as mediapipe 0.10.21 takes it.
fn body_scale(centre: &Landmark, scale_point: &Landmark) -> f64 {
    2.0 * (scale_point.x - centre.x).hypot(scale_point.y - centre.y)
}

/// The operator among several detections: the first of [`rank_operators`] with no memory.
pub fn choose_operator<'a>(
    dets: &'a [Detection],
    size: (u32, u32),
    depth: Option<&DepthImage>,
) -> Option<&'a Detection> {
    rank_operators(dets, size, depth, None, None)
        .first()
        .and_then(|&i| dets.get(i))
}

/// The detections that may be the operator, best first (indices into `dets`).
///
/// The rule:
/// 1. With `recent` (the operator was lost less than [`OPERATOR_MEMORY_S`] ago): only the
///    candidates whose box centre is within one body scale of where the operator was, nearest
///    first. Anyone else is refused: a person walking by does not take over.
/// 2. With `station` (a calibrated workspace with the operator's station): the candidates at
///    the station first, nearest to it first; then the others by rules 3 and 4. A box with
///    valid depth is at the station when its centre, lifted to the box's median depth, is
///    within the station's radius; a box without, when it contains the station's projection
///    (see [`StationView`]). Someone nearer the camera but away from the station (a person
///    walking between) is not preferred over the person at it.
/// 3. With depth valid inside the box (`depth`, aligned to the image): the nearest person
///    first (median depth of the box), then those without valid depth.
/// 4. Otherwise, and among equal depths: by detector score × body size, the square root of
///    the box area [px]. The score dominates when the boxes are about equally large (as
///    mediapipe, which takes the highest-scoring detection), and a clearly larger (nearer)
///    body wins over a slightly better score.
pub fn rank_operators(
    dets: &[Detection],
    size: (u32, u32),
    depth: Option<&DepthImage>,
    recent: Option<&OperatorMemory>,
    station: Option<&StationView>,
) -> Vec<usize> {
    let (w, h) = (f64::from(size.0), f64::from(size.1));
    let centre = |d: &Detection| {
        [
            f64::from(d.xmin + d.width / 2.0) * w,
            f64::from(d.ymin + d.height / 2.0) * h,
        ]
    };
    let key = |d: &Detection| {
        let area_px = f64::from(d.width) * w * f64::from(d.height) * h;
        f64::from(d.score) * area_px.max(0.0).sqrt()
    };
    struct Candidate {
        i: usize,
        /// At the station: 0 judged with depth, 1 without, 2 not at it (or no station); and
        /// the distance to it ([m] with depth, [px] without, see [`StationView`]).
        station: (u8, f64),
        /// Median box depth [m]; +∞ without valid depth.
        z: f64,
        /// Detector score × √(box area [px²]).
        key: f64,
    }
    let mut order: Vec<Candidate> = dets
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let z = depth.and_then(|depth| box_median_depth(d, size, depth));
            let station = match station.map(|s| s.place(d, size, z)) {
                Some((true, dist)) => (if z.is_some() { 0 } else { 1 }, dist),
                _ => (2, 0.0),
            };
            Candidate {
                i,
                station,
                z: z.unwrap_or(f64::INFINITY),
                key: key(d),
            }
        })
        .collect();
    if let Some(o) = recent {
        let dist = |i: usize| {
            let c = centre(&dets[i]);
            (c[0] - o.centre[0]).hypot(c[1] - o.centre[1])
        };
        order.retain(|c| dist(c.i) <= o.scale.max(1.0));
        order.sort_by(|a, b| dist(a.i).total_cmp(&dist(b.i)));
        return order.into_iter().map(|c| c.i).collect();
    }
    order.sort_by(|a, b| {
        (a.station.0.cmp(&b.station.0))
            .then(a.station.1.total_cmp(&b.station.1))
            .then(a.z.total_cmp(&b.z))
            .then(b.key.total_cmp(&a.key))
    });
    order.into_iter().map(|c| c.i).collect()
}

/// Median valid depth [m] on a grid of up to 15 × 15 samples inside a detection box.
fn box_median_depth(d: &Detection, size: (u32, u32), depth: &DepthImage) -> Option<f64> {
    if depth.width != size.0 || depth.height != size.1 {
        return None;
    }
    let mut samples = Vec::with_capacity(225);
    for j in 0..15 {
        for i in 0..15 {
            let x = (d.xmin + d.width * (i as f32 + 0.5) / 15.0) * size.0 as f32;
            let y = (d.ymin + d.height * (j as f32 + 0.5) / 15.0) * size.1 as f32;
            if x >= 0.0
                && y >= 0.0
                && let Some(z) = depth.depth_m(x as u32, y as u32)
            {
                samples.push(z);
            }
        }
    }
    if samples.len() < 5 {
        return None;
    }
    samples.sort_by(f64::total_cmp);
    samples.get(samples.len() / 2).copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A detection with its box [px] on a 640 × 480 image.
    fn det(score: f32, x: f32, y: f32, w: f32, h: f32) -> Detection {
        Detection {
            score,
            xmin: x / 640.0,
            ymin: y / 480.0,
            width: w / 640.0,
            height: h / 480.0,
            keypoints: Vec::new(),
        }
    }

    const SIZE: (u32, u32) = (640, 480);

    /// Issue 13's two failures of "the largest box": boxes of 5471 and 5472 px² (a man and a
    /// woman) and of 2638 and 2639 px² (two riders, the larger one with score 0.55). Both go to
    /// the higher detector score, as mediapipe's: 0.9 · √5471 = 66.6 > 0.6 · √5472 = 44.4.
    #[test]
    fn nearly_equal_boxes_go_to_the_higher_score() {
        let dets = [
            det(0.6, 300.0, 10.0, 72.0, 76.0),
            det(0.9, 10.0, 10.0, 5471.0 / 76.0, 76.0),
        ];
        assert_eq!(rank_operators(&dets, SIZE, None, None, None), [1, 0]);
        let riders = [
            det(0.55, 0.0, 0.0, 2639.0 / 50.0, 50.0),
            det(0.90, 300.0, 0.0, 52.76, 50.0),
        ];
        assert_eq!(rank_operators(&riders, SIZE, None, None, None), [1, 0]);
        assert!(std::ptr::eq(
            choose_operator(&riders, SIZE, None).unwrap(),
            &riders[1]
        ));
    }

    /// A clearly larger body wins over a slightly better score: 0.8 · √(200·300) = 196 >
    /// 0.9 · √(100·150) = 110.
    #[test]
    fn a_clearly_larger_body_wins_over_a_slightly_better_score() {
        let dets = [
            det(0.9, 0.0, 0.0, 100.0, 150.0),
            det(0.8, 300.0, 0.0, 200.0, 300.0),
        ];
        assert_eq!(rank_operators(&dets, SIZE, None, None, None), [1, 0]);
    }

    /// Depth in three bands (columns 0–199 at 1.5 m, 200–399 at 0.9 m, none beyond) and a
    /// person in each: at 1.5 m (score 0.99), at 0.9 m (0.60), without depth (0.99).
    fn three_depth_bands() -> (DepthImage, [Detection; 3]) {
        let mut data = vec![0u16; 640 * 480];
        for (i, d) in data.iter_mut().enumerate() {
            *d = match i % 640 {
                0..200 => 1500,
                200..400 => 900,
                _ => 0, // no depth
            };
        }
        let depth = DepthImage {
            width: 640,
            height: 480,
            data,
            scale_m: 0.001,
        };
        let dets = [
            det(0.99, 10.0, 10.0, 150.0, 200.0),  // 1.5 m
            det(0.60, 220.0, 10.0, 150.0, 200.0), // 0.9 m
            det(0.99, 450.0, 10.0, 150.0, 200.0), // no depth
        ];
        (depth, dets)
    }

    /// With depth, the nearest person first, whatever the scores; a box without valid depth
    /// comes after those with it.
    #[test]
    fn with_depth_the_nearest_comes_first() {
        let (depth, dets) = three_depth_bands();
        assert_eq!(
            rank_operators(&dets, SIZE, Some(&depth), None, None),
            [1, 0, 2]
        );
    }

    const INTRINSICS: Intrinsics = Intrinsics {
        width: 640,
        height: 480,
        fx: 500.0,
        fy: 500.0,
        cx: 320.0,
        cy: 240.0,
    };

    /// Rule 2 without depth, worked by hand: the station at (−0.47, −0.26, 2.0) m projects to
    /// (320 + 500·(−0.47)/2, 240 + 500·(−0.26)/2) = (202.5, 175) px, inside the second box
    /// (150..250, 100..300) only. That person ranks first although the first one has the better
    /// score × size (0.9·√(200·300) = 220 > 0.5·√(100·200) = 71); the third (0.8·√(100·150)
    /// = 98), not at the station either, follows by score × size.
    #[test]
    fn without_depth_the_box_holding_the_station_comes_first() {
        let station = StationView::new(Point3::new(-0.47, -0.26, 2.0), 0.6, INTRINSICS).unwrap();
        assert!((station.centre_px[0] - 202.5).abs() < 1e-9);
        assert!((station.centre_px[1] - 175.0).abs() < 1e-9);
        let dets = [
            det(0.9, 400.0, 100.0, 200.0, 300.0),
            det(0.5, 150.0, 100.0, 100.0, 200.0),
            det(0.8, 0.0, 300.0, 100.0, 150.0),
        ];
        assert_eq!(rank_operators(&dets, SIZE, None, None, None), [0, 2, 1]);
        assert_eq!(
            rank_operators(&dets, SIZE, None, None, Some(&station)),
            [1, 0, 2]
        );
        // Behind the camera, or at the camera, a station tells no one apart.
        assert_eq!(
            StationView::new(Point3::new(0.0, 0.0, -1.0), 0.6, INTRINSICS),
            None
        );
        assert_eq!(
            StationView::new(Point3::new(0.0, 0.0, 0.0), 0.6, INTRINSICS),
            None
        );
    }

    /// The workspace's station seen by the camera, worked by hand: the camera sits at
    /// (1, 0, 0) m in the workspace, axes aligned; the station at (1, 0.5, 2) m is (0, 0.5, 2) m
    /// in the camera frame and projects to (320 + 500·0/2, 240 + 500·0.5/2) = (320, 365) px.
    #[test]
    fn a_workspace_station_is_seen_through_the_extrinsics() {
        let extrinsics = Extrinsics {
            world_from_camera: nalgebra::Isometry3::translation(1.0, 0.0, 0.0),
        };
        let st = crate::Station::new(crate::Vec3::new(1.0, 0.5, 2.0), 0.4).unwrap();
        let view = StationView::from_workspace(&st, &extrinsics, INTRINSICS).unwrap();
        assert!((view.camera_m - Point3::new(0.0, 0.5, 2.0)).norm() < 1e-12);
        assert!((view.centre_px[0] - 320.0).abs() < 1e-9);
        assert!((view.centre_px[1] - 365.0).abs() < 1e-9);
        assert_eq!(view.radius_m, 0.4);
        // Behind the camera: none.
        let behind = crate::Station::new(crate::Vec3::new(1.0, 0.0, -2.0), 0.4).unwrap();
        assert_eq!(
            StationView::from_workspace(&behind, &extrinsics, INTRINSICS),
            None
        );
    }

    /// Rule 2 with depth, worked by hand (fx = fy = 500, principal point (320, 240)): the box
    /// at 1.5 m, centre (85, 110) px, lifts to ((85 − 320)/500·1.5, (110 − 240)/500·1.5, 1.5) =
    /// (−0.705, −0.39, 1.5) m, 0.011 m from the station (−0.7, −0.4, 1.5) m: at it. The box at
    /// 0.9 m, centre (295, 110) px, lifts to (−0.045, −0.234, 0.9) m, √(0.655² + 0.166² + 0.6²)
    /// = 0.90 m away, beyond the 0.6 m radius. The person at the station ranks first although
    /// the other is nearer the camera (rule 3 alone gives the opposite order).
    #[test]
    fn with_depth_the_person_at_the_station_beats_a_nearer_one() {
        // The person at 1.5 m is at the station; the one at 0.9 m is 0.90 m from it; the
        // station is not in the box of the one without depth.
        let (depth, dets) = three_depth_bands();
        let station = StationView::new(Point3::new(-0.7, -0.4, 1.5), 0.6, INTRINSICS).unwrap();
        let near = station.place(&dets[0], SIZE, Some(1.5));
        assert!(near.0 && (near.1 - 0.0112).abs() < 1e-3, "{near:?}");
        let far = station.place(&dets[1], SIZE, Some(0.9));
        assert!(!far.0 && (far.1 - 0.9036).abs() < 1e-3, "{far:?}");
        assert_eq!(
            rank_operators(&dets, SIZE, Some(&depth), None, None),
            [1, 0, 2]
        );
        assert_eq!(
            rank_operators(&dets, SIZE, Some(&depth), None, Some(&station)),
            [0, 1, 2]
        );
        // A station no one is at leaves the order to rules 3 and 4.
        let empty = StationView::new(Point3::new(2.0, 2.0, 3.0), 0.3, INTRINSICS).unwrap();
        assert_eq!(
            rank_operators(&dets, SIZE, Some(&depth), None, Some(&empty)),
            [1, 0, 2]
        );
    }

    /// Within OPERATOR_MEMORY_S of losing the operator, only a candidate where they were (box
    /// centre within one body scale) may become the operator; another person is refused even
    /// with a better score and a larger box.
    #[test]
    fn a_person_walking_by_does_not_take_over() {
        let was = OperatorMemory {
            centre: [100.0, 200.0],
            scale: 120.0,
            t: 0.0,
        };
        let passer = det(0.99, 300.0, 0.0, 300.0, 400.0); // centre (450, 200): 350 px away
        let operator = det(0.60, 40.0, 120.0, 100.0, 150.0); // centre (90, 195): 11 px away
        let dets = [passer.clone(), operator];
        assert_eq!(rank_operators(&dets, SIZE, None, Some(&was), None), [1]);
        assert_eq!(
            rank_operators(&[passer], SIZE, None, Some(&was), None),
            Vec::<usize>::new()
        );
        // Without the memory the passer ranks first.
        assert_eq!(rank_operators(&dets, SIZE, None, None, None), [0, 1]);
    }

    /// A pose with shoulders at (200, 100) and (300, 100) (width 100 px) and wrists at
    /// `left`/`right` [px] with visibilities `vis` [-]; and a hand with its wrist at `at` [px].
    fn pose_and_hand(
        left: [f64; 2],
        right: [f64; 2],
        vis: [f64; 2],
        at: [f64; 2],
    ) -> (PoseLandmarks, HandLandmarks) {
        let roi = roi::Roi {
            cx: 0.0,
            cy: 0.0,
            width: 1.0,
            height: 1.0,
            rotation: 0.0,
        };
        let lm = |x: f64, y: f64, visibility: f64| Landmark {
            x,
            y,
            visibility,
            ..Landmark::default()
        };
        let mut points = [lm(0.0, 0.0, 1.0); 33];
        points[11] = lm(300.0, 100.0, 1.0);
        points[12] = lm(200.0, 100.0, 1.0);
        points[15] = lm(left[0], left[1], vis[0]);
        points[16] = lm(right[0], right[1], vis[1]);
        let mut hand = [lm(0.0, 0.0, 1.0); 21];
        hand[0] = lm(at[0], at[1], 1.0);
        (
            PoseLandmarks {
                points,
                score: 1.0,
                roi,
            },
            HandLandmarks {
                points: hand,
                score: 1.0,
                right_hand: 0.5,
                roi,
            },
        )
    }

    #[test]
    fn a_hand_near_a_seen_wrist_belongs_and_one_far_from_both_does_not() {
        let (l, r) = ([320.0, 250.0], [180.0, 250.0]);
        // 59 px from the left wrist: within 0.6 × 100 px.
        let (pose, hand) = pose_and_hand(l, r, [0.9, 0.9], [320.0, 309.0]);
        assert!(belongs_to(&hand, &pose, SIZE));
        // 61 px from the left wrist, farther from the right one: someone else's.
        let (pose, hand) = pose_and_hand(l, r, [0.9, 0.9], [320.0, 311.0]);
        assert!(!belongs_to(&hand, &pose, SIZE));
    }

    #[test]
    fn a_far_hand_may_be_the_one_of_an_unseen_wrist_in_the_image() {
        let (l, r) = ([320.0, 250.0], [180.0, 250.0]);
        let far = [600.0, 400.0];
        for vis in [[0.5, 0.9], [0.9, 0.5], [0.1, 0.2]] {
            let (pose, hand) = pose_and_hand(l, r, vis, far);
            assert!(belongs_to(&hand, &pose, SIZE), "{vis:?}");
        }
        let (pose, hand) = pose_and_hand(l, r, [0.51, 0.51], far);
        assert!(!belongs_to(&hand, &pose, SIZE));
    }

    #[test]
    fn unseen_wrists_outside_the_image_are_known_to_be_elsewhere() {
        // Both wrists below the 480 px image (and one left of it), unseen: a hand in view far
        // from both is someone else's; near one (in the image's margin) it may be his.
        let (l, r) = ([320.0, 700.0], [-40.0, 600.0]);
        let (pose, hand) = pose_and_hand(l, r, [0.1, 0.1], [320.0, 300.0]);
        assert!(!belongs_to(&hand, &pose, SIZE));
        let (pose, hand) = pose_and_hand(l, r, [0.1, 0.1], [10.0, 470.0]);
        assert!(!belongs_to(&hand, &pose, SIZE));
        let (pose, hand) = pose_and_hand(l, r, [0.1, 0.1], [320.0, 470.0]);
        assert!(!belongs_to(&hand, &pose, SIZE));
        let (pose, hand) = pose_and_hand([320.0, 520.0], r, [0.1, 0.1], [320.0, 470.0]);
        assert!(belongs_to(&hand, &pose, SIZE));
        // One wrist in the image, unseen: unknown, so the hand is kept.
        let (pose, hand) = pose_and_hand([320.0, 479.0], r, [0.1, 0.1], [320.0, 300.0]);
        assert!(belongs_to(&hand, &pose, SIZE));
    }

    /// MediaPipe's One-Euro filter (`util/filtering/one_euro_filter.cc` at v0.10.21) on a worked
    /// example computed by hand: 30 Hz, object scale 100 px (value scale 0.01 /px), the aux
    /// filter's min cutoff 0.01 Hz, β 10, derivative cutoff 1 Hz; values 200, 210, 210 px.
    /// - frame 0: no previous raw value, so dvalue = 0 and the output is the input, 200;
    /// - frame 1: dvalue = (210 − 200) · 0.01 · 30 = 3.0 /s; α_d = 1 / (1 + τ/Te) with
    ///   τ = 1/(2π · 1) = 0.159155, Te = 1/30: α_d = 1 / 5.774648 = 0.173171; edvalue =
    ///   0.173171 · 3 = 0.519512; cutoff = 0.01 + 10 · 0.519512 = 5.205122 Hz;
    ///   α = 1 / (1 + 30 / (2π · 5.205122)) = 0.521567; out = 200 + 0.521567 · 10 = 205.2157;
    /// - frame 2: dvalue = 0 (raw 210 again); edvalue = 0.826829 · 0.519512 = 0.429548;
    ///   cutoff = 4.305479 Hz; α = 0.474165; out = 205.2157 + 0.474165 · (210 − 205.2157)
    ///   = 207.4842.
    ///
    /// And a fresh filter (as mediapipe's after a reset on a frame without landmarks) passes
    /// its first value unfiltered, where one with history pulls it back.
    #[test]
    fn mp_one_euro_matches_a_worked_example_and_a_fresh_filter_passes_its_first_value() {
        let mut f = MpOneEuro::default();
        let out: Vec<f64> = [200.0, 210.0, 210.0]
            .iter()
            .map(|&v| f.apply(v, 30.0, 0.01))
            .collect();
        assert!((out[0] - 200.0).abs() < 1e-9, "{out:?}");
        assert!((out[1] - 205.2157).abs() < 1e-3, "{out:?}");
        assert!((out[2] - 207.4842).abs() < 1e-3, "{out:?}");
        // Without a reset, a jump to 400 px is still pulled back toward the old position...
        let mut kept = f;
        assert!(kept.apply(400.0, 30.0, 0.01) < 399.0);
        // ...by a fresh one it is not.
        let mut fresh = MpOneEuro::default();
        assert_eq!(fresh.apply(400.0, 30.0, 0.01), 400.0);
    }

    /// The heatmap range check (refine_landmarks_from_heatmap_calculator.cc:123–129 at
    /// v0.10.21), worked by hand: 64 × 64 heatmap, 256 × 256 input, one channel confident
    /// (logit 10, sigmoid 0.99995) everywhere. A landmark at (128, 258) px has column
    /// ⌊128/256 · 64⌋ = 32 and row ⌊258/256 · 64⌋ = 64 = the height: outside, kept as it is.
    /// One at (128, 250) px (row 62) is inside: with kernel 7 (offset 3) its window is rows
    /// 59–63 (clipped at 63) and columns 29–35, so with equal weights it moves to column mean
    /// 32 → 32/64 · 256 = 128 px and row mean (59+…+63)/5 = 61 → 61/64 · 256 = 244 px.
    #[test]
    fn heatmap_refinement_leaves_landmarks_below_the_heatmap_alone() {
        let heatmap = vec![10.0f32; 64 * 64];
        let mut below = vec![128.0f32, 258.0, 0.0];
        refine_from_heatmap(&mut below, 3, (256.0, 256.0), &heatmap, (64, 64), 7, 0.5);
        assert_eq!(below, [128.0, 258.0, 0.0]);
        let mut inside = vec![128.0f32, 250.0, 0.0];
        refine_from_heatmap(&mut inside, 3, (256.0, 256.0), &heatmap, (64, 64), 7, 0.5);
        assert!((inside[0] - 128.0).abs() < 1e-3, "{inside:?}");
        assert!((inside[1] - 244.0).abs() < 1e-3, "{inside:?}");
    }
}
