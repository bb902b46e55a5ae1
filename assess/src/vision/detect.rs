//! SSD detection decoding and weighted non-maximum suppression, as MediaPipe's
//! `TensorsToDetectionsCalculator` and `NonMaxSuppressionCalculator` (algorithm WEIGHTED,
//! overlap IoU) do it. Arithmetic is in `f32`, in MediaPipe's order, so boxes match its output.

use super::anchors::Anchor;

/// Decoding parameters of one detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct DecodeOptions {
    /// Values per box: 4 box values + 2 per keypoint.
    pub num_coords: usize,
    /// Keypoints per box.
    pub num_keypoints: usize,
    /// Box and keypoint scale: the model input size [px].
    pub scale: f32,
    /// Minimum score after the sigmoid [-].
    pub min_score: f32,
}

/// A detection in coordinates normalised to the detector input (before letterbox removal)
/// or to the image (after).
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    /// Score after the sigmoid [-].
    pub score: f32,
    /// Box left [-].
    pub xmin: f32,
    /// Box top [-].
    pub ymin: f32,
    /// Box width [-].
    pub width: f32,
    /// Box height [-].
    pub height: f32,
    /// Keypoints (x, y) [-].
    pub keypoints: Vec<[f32; 2]>,
}

impl Detection {
    /// Box area [-²].
    pub fn area(&self) -> f32 {
        self.width * self.height
    }

    /// Intersection over union with another box [-].
    pub fn iou(&self, other: &Detection) -> f32 {
        let x0 = self.xmin.max(other.xmin);
        let y0 = self.ymin.max(other.ymin);
        let x1 = (self.xmin + self.width).min(other.xmin + other.width);
        let y1 = (self.ymin + self.height).min(other.ymin + other.height);
        if x1 <= x0 || y1 <= y0 {
            return 0.0;
        }
        let inter = (x1 - x0) * (y1 - y0);
        let union = self.area() + other.area() - inter;
        if union > 0.0 { inter / union } else { 0.0 }
    }

    /// Maps a detection from the letterboxed detector input back to the image, given the
    /// padding fractions (left, top, right, bottom) [-] (`DetectionLetterboxRemoval`).
    pub fn remove_letterbox(&mut self, padding: [f32; 4]) {
        let [left, top, right, bottom] = padding;
        let sx = 1.0 - left - right;
        let sy = 1.0 - top - bottom;
        self.xmin = (self.xmin - left) / sx;
        self.ymin = (self.ymin - top) / sy;
        self.width /= sx;
        self.height /= sy;
        for k in &mut self.keypoints {
            k[0] = (k[0] - left) / sx;
            k[1] = (k[1] - top) / sy;
        }
    }
}

/// Decodes raw SSD outputs: `boxes` holds `anchors.len() * num_coords` values (x, y, w, h
/// then keypoint x, y pairs, in input pixels relative to the anchor), `scores` one logit per
/// anchor. Returns every box whose sigmoid score reaches `min_score`, in anchor order.
/// Mismatched lengths give no detections.
pub(crate) fn decode(
    boxes: &[f32],
    scores: &[f32],
    anchors: &[Anchor],
    options: &DecodeOptions,
) -> Vec<Detection> {
    let n = anchors.len();
    if boxes.len() != n * options.num_coords
        || scores.len() != n
        || options.num_coords < 4 + 2 * options.num_keypoints
    {
        return Vec::new();
    }
    let s = options.scale;
    let mut out = Vec::new();
    for ((anchor, raw), &logit) in anchors
        .iter()
        .zip(boxes.chunks_exact(options.num_coords))
        .zip(scores)
    {
        // Score clipping at ±100 then the sigmoid.
        let score = 1.0 / (1.0 + (-logit.clamp(-100.0, 100.0)).exp());
        if score < options.min_score || score.is_nan() {
            continue;
        }
        let cx = raw[0] / s + anchor.cx;
        let cy = raw[1] / s + anchor.cy;
        let w = raw[2] / s;
        let h = raw[3] / s;
        let keypoints = raw[4..4 + 2 * options.num_keypoints]
            .chunks_exact(2)
            .map(|k| [k[0] / s + anchor.cx, k[1] / s + anchor.cy])
            .collect();
        out.push(Detection {
            score,
            xmin: cx - w / 2.0,
            ymin: cy - h / 2.0,
            width: (cx + w / 2.0) - (cx - w / 2.0),
            height: (cy + h / 2.0) - (cy - h / 2.0),
            keypoints,
        });
    }
    out
}

/// Weighted non-maximum suppression: repeatedly takes the best remaining box, and replaces it
/// by the score-weighted mean (box corners and keypoints) of every remaining box that overlaps
/// it by more than `iou_threshold` (itself included), keeping the best box's score. Output is
/// in descending score order.
pub(crate) fn weighted_nms(mut detections: Vec<Detection>, iou_threshold: f32) -> Vec<Detection> {
    // Stable sort by descending score, as MediaPipe's std::sort on (index, score) pairs with a
    // strict comparator (ties keep no particular order there; stable here).
    detections.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut remaining: Vec<usize> = (0..detections.len()).collect();
    let mut out = Vec::new();
    while let Some(&best_index) = remaining.first() {
        let best = &detections[best_index];
        let (candidates, rest): (Vec<usize>, Vec<usize>) = remaining
            .iter()
            .partition(|&&i| detections[i].iou(best) > iou_threshold);
        let mut merged = best.clone();
        if !candidates.is_empty() {
            let mut total = 0.0f32;
            let (mut x0, mut y0, mut x1, mut y1) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
            let mut keypoints = vec![[0.0f32; 2]; best.keypoints.len()];
            for &i in &candidates {
                let d = &detections[i];
                total += d.score;
                x0 += d.xmin * d.score;
                y0 += d.ymin * d.score;
                x1 += (d.xmin + d.width) * d.score;
                y1 += (d.ymin + d.height) * d.score;
                for (acc, k) in keypoints.iter_mut().zip(&d.keypoints) {
                    acc[0] += k[0] * d.score;
                    acc[1] += k[1] * d.score;
                }
            }
            merged.xmin = x0 / total;
            merged.ymin = y0 / total;
            merged.width = x1 / total - merged.xmin;
            merged.height = y1 / total - merged.ymin;
            for k in &mut keypoints {
                k[0] /= total;
                k[1] /= total;
            }
            merged.keypoints = keypoints;
        }
        out.push(merged);
        if rest.len() == remaining.len() {
            break;
        }
        remaining = rest;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(score: f32, xmin: f32, ymin: f32, w: f32, h: f32) -> Detection {
        Detection {
            score,
            xmin,
            ymin,
            width: w,
            height: h,
            keypoints: vec![[xmin, ymin]],
        }
    }

    #[test]
    fn decode_applies_anchor_offsets_and_sigmoid() {
        // One anchor at (0.5, 0.25), scale 100: raw box (10, -5, 20, 40) → centre
        // (0.5 + 0.1, 0.25 − 0.05) = (0.6, 0.2), size 0.2 × 0.4; keypoint (30, 0) → (0.8, 0.25).
        // Logit 0 → score 0.5 (kept at min 0.5); logit −1 → 0.269 (dropped).
        let anchors = [Anchor { cx: 0.5, cy: 0.25 }, Anchor { cx: 0.5, cy: 0.25 }];
        let boxes = [
            10.0, -5.0, 20.0, 40.0, 30.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0,
        ];
        let opts = DecodeOptions {
            num_coords: 6,
            num_keypoints: 1,
            scale: 100.0,
            min_score: 0.5,
        };
        let d = decode(&boxes, &[0.0, -1.0], &anchors, &opts);
        assert_eq!(d.len(), 1);
        assert!((d[0].xmin - 0.5).abs() < 1e-6);
        assert!((d[0].ymin - 0.0).abs() < 1e-6);
        assert!((d[0].width - 0.2).abs() < 1e-6);
        assert!((d[0].height - 0.4).abs() < 1e-6);
        assert!((d[0].keypoints[0][0] - 0.8).abs() < 1e-6);
        assert_eq!(d[0].score, 0.5);
        // Wrong lengths: nothing, no panic.
        assert!(decode(&boxes[..5], &[0.0, -1.0], &anchors, &opts).is_empty());
    }

    #[test]
    fn weighted_nms_merges_overlaps_by_score() {
        // Boxes A (0.9) and B (0.6) overlap with IoU 0.6; C is apart. Merged A∪B corners:
        // xmin = (0.9·0 + 0.6·0.1)/1.5 = 0.04, width = (0.9·1 + 0.6·1.1)/1.5 − 0.04 = 1.0.
        let a = det(0.9, 0.0, 0.0, 1.0, 1.0);
        let b = det(0.6, 0.1, 0.0, 1.0, 1.0);
        let c = det(0.7, 5.0, 5.0, 1.0, 1.0);
        assert!(a.iou(&b) > 0.3);
        let out = weighted_nms(vec![b, c, a], 0.3);
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].score, 0.9);
        assert!((out[0].xmin - 0.04).abs() < 1e-6);
        assert!((out[0].width - 1.0).abs() < 1e-6);
        assert!((out[0].keypoints[0][0] - 0.04).abs() < 1e-6);
        assert_eq!(out[1].score, 0.7);
        assert_eq!(out[1].xmin, 5.0);
    }

    #[test]
    fn letterbox_removal_inverts_the_padding() {
        // Padding 0.125 top and bottom: y 0.125 → 0, height 0.75 → 1.
        let mut d = det(1.0, 0.25, 0.125, 0.5, 0.75);
        d.remove_letterbox([0.0, 0.125, 0.0, 0.125]);
        assert!((d.ymin - 0.0).abs() < 1e-6);
        assert!((d.height - 1.0).abs() < 1e-6);
        assert!((d.xmin - 0.25).abs() < 1e-6);
        assert!((d.keypoints[0][1] - 0.0).abs() < 1e-6);
    }
}
